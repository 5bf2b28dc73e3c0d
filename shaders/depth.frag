#version 430
// depth.frag -- the mesh's depth extent per pixel, for fusion with a ray-cast volume.
//
// In:  the same fan varyings as tet.frag (tet.vert, fan_varyings.glsl), u_near, u_far.
// Out: f_extent = (front depth, -back depth) of this fragment's segment, eye depth along
//      the view axis, clipped to the clipping range. Blended with MIN, the target ends
//      with the nearest front and the farthest back over all tets at each pixel.
// NEAR_CROSSING 1: only the fans on the exact path (near-plane tets among them), the others
// discarded; 0: only the others. The renderer draws every fan with the second and the range
// of exact ones with the first (MIN needs no order): the exact branch, merely present,
// slowed llvmpipe's whole pass threefold, and a block whose fragments are all discarded
// at the start costs little.

#include "common.glsl"
#if NEAR_CROSSING
#include "exact.glsl"
#endif

noperspective in vec4 v_segment;
noperspective in vec2 v_ray;
flat in int v_exact_tet;

#include "fan_varyings.glsl"

out vec2 f_extent;

void main() {
    vec2 ray;
    vec4 segment;
    fan_varyings(ray, segment);
    float zf, zb;
#if NEAR_CROSSING
    if (v_exact_tet < 0) discard;  // drawn by the other variant
    // Tets on the exact path (near-plane tets among them): the ray's own segment.
    vec4 seg = exact_ray_segment(v_exact_tet, ray, u_near, u_far);
    if (seg.y <= seg.x) discard;
    zf = seg.x;
    zb = seg.y;
#else
    if (v_exact_tet >= 0) discard;  // drawn by the other variant
    zf = segment.x;
    zb = segment.z;
#if PERSPECTIVE_CORRECT
    if (u_perspective == 1) {
        zf = 1.0 / zf;
        zb = 1.0 / zb;
    }
#endif
#endif
    if (zb <= u_near || zf >= u_far) discard;
    f_extent = vec2(max(zf, u_near), -min(zb, u_far));
}

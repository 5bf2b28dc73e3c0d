#version 430
// depth.frag -- the mesh's depth extent per pixel, for fusion with a ray-cast volume.
//
// In:  the same fan varyings as tet.frag (tet.vert), u_near, u_far.
// Out: f_extent = (front depth, -back depth) of this fragment's segment, eye depth along
//      the view axis, clipped to the clipping range. Blended with MIN, the target ends
//      with the nearest front and the farthest back over all tets at each pixel.

#include "common.glsl"

noperspective in vec4 v_segment;
flat in int v_exact_tet;

out vec2 f_extent;

void main() {
    float zf, zb;
    if (v_exact_tet >= 0) {
        // Near-plane tets: the segment may start at the near plane; a conservative extent
        // from the tet's vertex depths is enough for ray limits.
        ivec4 id = tets[v_exact_tet];
        zf = 1e30; zb = -1e30;
        for (int k = 0; k < 4; ++k) {
            float z = -(u_view * vec4(points[id[k]].xyz, 1.0)).z;
            zf = min(zf, z); zb = max(zb, z);
        }
    } else {
        zf = v_segment.x;
        zb = v_segment.z;
#if PERSPECTIVE_CORRECT
        if (u_perspective == 1) {
            zf = 1.0 / zf;
            zb = 1.0 / zb;
        }
#endif
    }
    if (zb <= u_near || zf >= u_far) discard;
    f_extent = vec2(max(zf, u_near), -min(zb, u_far));
}

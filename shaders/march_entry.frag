#version 430
// march_entry.frag -- the nearest entry of each pixel's ray into the mesh, kept by the depth
// test (LESS) on the exact ray parameter.
//
// NEAR_CELLS 1: the ray's point on the near plane lies inside tet v_id: the ray starts
// there, at t = u_near (depth 0, ahead of every face). NEAR_CELLS 0: boundary face v_id
// (slot 4 * tet + k) faces the ray; it is an entry at t = the exact ray-plane parameter if
// t lies in the clipping range and, when PEEL is 1 (a later layer of a non-convex mesh), if
// the ray left the mesh in the last march pass and t is not before where it left (minus a
// rounding tolerance) nor the face it entered by last. RIM 1: as NEAR_CELLS 0 for a face
// drawn as a rectangle round its projection, whose fragments are kept only where the
// pixel's ray meets the triangle v_c0..2 (Moller-Trumbore, float32; tetvr.marching.rim_faces).
// Out: f_entry: 4 * tet + k for a face, -2 - tet for a cut cell; gl_FragDepth: t mapped to
// [0, 1] over the clipping range.

#include "march_common.glsl"

flat in int v_id;
#if RIM
flat in vec3 v_c0;
flat in vec3 v_c1;
flat in vec3 v_c2;
#endif
layout(location = 0) out int f_entry;

#if PEEL
uniform sampler2D u_state;   // march.frag's f_state: (t where the ray left, status)
uniform isampler2D u_last;   // march.frag's f_last: the entry slot of the last march
#endif
uniform float u_tolerance;   // length: rounding allowance of the peel and the inside test

void main() {
    vec3 o, d;
    pixel_ray(gl_FragCoord.xy, o, d);
#if NEAR_CELLS
    vec3 p = o + u_near * d;
    for (int k = 0; k < 4; ++k) {
        vec4 plane = face_plane(v_id, k);
        if (dot(plane.xyz, p) + plane.w > u_tolerance) discard;
    }
    f_entry = -2 - v_id;
    gl_FragDepth = 0.0;
#else
#if RIM
    vec3 e1 = v_c1 - v_c0, e2 = v_c2 - v_c0;
    vec3 p = cross(d, e2);
    float det = dot(e1, p);
    if (det == 0.0) discard;  // the ray runs in the face's plane: it enters elsewhere
    vec3 s = o - v_c0;
    float u = dot(s, p) / det;
    float v = dot(d, cross(s, e1)) / det;
    if (u < 0.0 || v < 0.0 || u + v > 1.0) discard;
#endif
    int tet = v_id >> 2;
    vec4 plane = face_plane(tet, v_id & 3);
    if (dot(plane.xyz, d) >= 0.0) discard;  // faces away: rays leave the mesh here
    float t = plane_t(plane, o, d);
    if (t < u_near || t >= u_far) discard;
#if PEEL
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec2 state = texelFetch(u_state, px, 0).xy;
    if (state.y != STATUS_REENTER || v_id == texelFetch(u_last, px, 0).r) discard;
    if (t < state.x - u_tolerance * length(d)) discard;
#endif
    f_entry = v_id;
    gl_FragDepth = (t - u_near) / (u_far - u_near);
#endif
}

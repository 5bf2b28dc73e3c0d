#version 430
// march_entry.frag -- the nearest entry of each pixel's ray into the mesh, kept by the depth
// test (LESS) on the exact ray parameter. Locals are precise (march.frag says why).
//
// NEAR_CELLS 1: the ray's point on the near plane lies inside tet v_id: the ray starts
// there, at t = u_near (depth 0, ahead of every face). NEAR_CELLS 0: boundary face v_id
// (slot 4 * tet + k) faces the ray; it is an entry at t = the exact ray-plane parameter if
// t lies in the clipping range and, when PEEL is 1 (a later layer of a non-convex mesh), if
// the ray left the mesh in the last march pass and t is not before where it left (minus a
// rounding tolerance) nor the face it entered by last. RIM 1: as NEAR_CELLS 0 for a face
// drawn as a rectangle round its projection (tetvr.mesh.records.rim_faces), whose fragments
// are kept only where the pixel's ray, in float64, enters the triangle v_c0..2 (wound
// counter-clockwise seen from outside; its edges by the reference's tie rule, edge_inside).
// LIST 1 (the first layer's faces, not PEEL): every face that passes is also listed for the
// pixel, (t's float bits, v_id), up to LIST_LENGTH of them (u_list: entry i of pixel (x, y)
// at (x, y + i * height); u_count their number, counted on past the length: u_overflow
// counts the pixels that overflowed), for march.frag to pick the next entry from.
// Out: f_entry: 4 * tet + k for a face, -2 - tet for a cut cell; gl_FragDepth: t mapped to
// [0, 1] over the clipping range.

#include "march_common.glsl"

flat in int v_id;
#if RIM
flat in dvec3 v_c0;
flat in dvec3 v_c1;
flat in dvec3 v_c2;
uniform dmat4 u_inv_view_d;   // u_inv_view in float64
uniform dvec2 u_ray_scale_d;  // u_ray_scale in float64

// pixel_ray in float64: a pixel centre's coordinates are exact in float32.
void pixel_ray_d(vec2 xy, out dvec3 o_obj, out dvec3 d_obj) {
    precise dvec2 r = (dvec2(xy) / dvec2(u_viewport) * 2.0LF - 1.0LF) * u_ray_scale_d;
#if PERSPECTIVE
    o_obj = u_inv_view_d[3].xyz;
    d_obj = dmat3(u_inv_view_d) * dvec3(r, -1.0LF);
#else
    o_obj = (u_inv_view_d * dvec4(r, 0.0LF, 1.0LF)).xyz;
    d_obj = dmat3(u_inv_view_d) * dvec3(0.0LF, 0.0LF, -1.0LF);
#endif
}

// Whether the ray (o, d), entering the face, passes on the inner side of its edge (p, q)
// (counter-clockwise seen from outside). A ray through the edge itself is given the side
// the reference gives it (tetvr.reference.segments): its origin moved by (e, e^2, e^3)
// along the eye's x, y and z for an infinitesimal e, so that of two faces sharing the
// edge exactly one takes the ray, and a ray in the plane of a face seen edge-on is in the
// mesh exactly where the reference has it.
bool edge_inside(dvec3 p, dvec3 q, dvec3 o, dvec3 d) {
    precise double e = dot(d, cross(p - o, q - o));
    precise dvec3 turn = cross(q - p, d);  // the edge function changes by -dot(axis, turn) per unit move
    for (int i = 0; i < 3 && e == 0.0LF; ++i) e = -dot(u_inv_view_d[i].xyz, turn);
    return e < 0.0LF;
}
#endif
layout(location = 0) out int f_entry;

#if PEEL
uniform sampler2D u_state;   // march.frag's f_state: (t where the ray left, status)
uniform isampler2D u_last;   // march.frag's f_last: the entry slot of the last march
#endif
uniform float u_tolerance;   // length: rounding allowance of the peel and the inside test
#if LIST
layout(binding = COUNT_IMAGE, r32ui) restrict uniform uimage2D u_count;
layout(binding = LIST_IMAGE, rg32i) restrict writeonly uniform iimage2D u_list;
layout(std430, binding = OVERFLOW_BUFFER) restrict buffer Overflow { uint u_overflow; };
#endif

void main() {
    precise vec3 o, d;
    pixel_ray(gl_FragCoord.xy, o, d);
#if NEAR_CELLS
    precise vec3 p = o + u_near * d;
    for (int k = 0; k < 4; ++k) {
        precise vec4 plane = face_plane(v_id, k);
        // A rounding's allowance across the faces the tet shares (a point on one is in
        // either tet, so no ray falls between them), none on the mesh's boundary: a ray
        // running almost along a boundary face a rounding outside it would otherwise start
        // in the mesh, and cross a long chord the reference does not.
        precise float allowance = tet_link(v_id, k).x < 0 ? 0.0 : u_tolerance;
        if (dot(plane.xyz, p) + plane.w > allowance) discard;
    }
    f_entry = -2 - v_id;
    gl_FragDepth = 0.0;
#else
#if RIM
    precise dvec3 od, dd;
    pixel_ray_d(gl_FragCoord.xy, od, dd);
    precise dvec3 e1 = v_c1 - v_c0, e2 = v_c2 - v_c0;
    precise dvec3 p = cross(dd, e2);
    precise double det = dot(e1, p);  // -d . (e1 x e2): positive where the ray enters
    if (!(det > 0.0LF)) discard;  // faces away, or the ray runs in its plane
    if (!(edge_inside(v_c0, v_c1, od, dd) && edge_inside(v_c1, v_c2, od, dd) && edge_inside(v_c2, v_c0, od, dd)))
        discard;
    precise dvec3 s = od - v_c0, q = cross(s, e1);
    precise float t = float(dot(e2, q) / det);
#else
    precise vec4 plane = face_plane(v_id >> 2, v_id & 3);
    if (dot(plane.xyz, d) >= 0.0) discard;  // faces away: rays leave the mesh here
    precise float t = plane_t(plane, o, d);
#endif
    if (t >= u_far) discard;
    if (t < u_near) {
        // A face behind the near plane: the ray starts past it, inside the mesh, where the
        // near plane's cells take it (NEAR_CELLS). Those give the boundary no allowance, so
        // a point on the near plane a rounding inside a boundary face may be in none of
        // them: the face within a rounding behind the near plane takes the ray, at u_near.
        precise vec4 near_plane = face_plane(v_id >> 2, v_id & 3);
        if (dot(near_plane.xyz, o + u_near * d) + near_plane.w < -u_tolerance) discard;
        t = u_near;
    }
#if PEEL
    ivec2 px = ivec2(gl_FragCoord.xy);
    precise vec2 state = texelFetch(u_state, px, 0).xy;
    if (state.y != STATUS_REENTER || v_id == texelFetch(u_last, px, 0).r) discard;
    if (t < state.x - u_tolerance * length(d)) discard;
#endif
#if LIST
    ivec2 at = ivec2(gl_FragCoord.xy);
    uint i = imageAtomicAdd(u_count, at, 1u);
    if (i < uint(LIST_LENGTH)) imageStore(u_list, ivec2(at.x, at.y + int(i) * int(u_viewport.y)),
                                          ivec4(floatBitsToInt(t), v_id, 0, 0));
    else if (i == uint(LIST_LENGTH)) atomicAdd(u_overflow, 1u);
#endif
    f_entry = v_id;
    gl_FragDepth = (t - u_near) / (u_far - u_near);
#endif
}

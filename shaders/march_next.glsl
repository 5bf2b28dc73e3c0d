// march_next.glsl -- where a ray that left the mesh enters it again (march.frag's last
// step): the next entry from the pixel's list, the boundary faces beside the one it left
// by, and the checks on both. Needs march.frag's across(), cross2(), suspect() and f_last.
// Locals are precise (march.frag says why).

#if LIST
layout(binding = COUNT_IMAGE, r32ui) restrict readonly uniform uimage2D u_count;
layout(binding = LIST_IMAGE, rg32i) restrict readonly uniform iimage2D u_list;
layout(std430, binding = MORE_BUFFER) restrict buffer More { uint u_more; };
#endif
// Each boundary face's neighbours on the boundary (slots 4 * tet + k, -1 after the last).
layout(binding = NEIGHBORS_IMAGE, rgba32i) restrict readonly uniform iimage2D u_neighbors;
uniform float u_tolerance;
// Where a ray leaves the mesh within this fraction of its face's weights of one of the
// face's edges, the boundary faces beside it are tested for an entry (LIST, below): seen
// across the ray, the ray is as close to them as to that edge; elsewhere the rasteriser
// listed any face the ray enters beside it, and every ray's last exit would pay for the test.
#define NEAR_EDGE 0.02

// Whether the ray enters the mesh through boundary face s (slot 4 * tet + k), and where: its
// plane faces the ray and the ray, seen across it, passes inside its triangle -- decided with
// the points as the walk sees them (across), so that for an edge the face shares with the
// one the ray left by, the two decisions are made on the same numbers.
bool enters(int s, vec3 o, vec3 d, vec3 ow, vec3 e1, vec3 e2, float inv_dd, out float t) {
    int tet = s >> 2, k = s & 3;
    precise vec4 plane = face_plane(tet, k);
    precise float den = dot(plane.xyz, d);
    t = 0.0;
    if (den >= 0.0) return false;  // faces away: rays leave the mesh there
    t = -(dot(plane.xyz, o) + plane.w) / den;
    ivec4 ids = tet_ids(tet);
    precise vec2 a = across(point_record(ids[(k + 1) & 3]).xyz - ow, e1, e2, d, inv_dd).xy;
    precise vec2 b = across(point_record(ids[(k + 2) & 3]).xyz - ow, e1, e2, d, inv_dd).xy;
    precise vec2 c = across(point_record(ids[(k + 3) & 3]).xyz - ow, e1, e2, d, inv_dd).xy;
    precise vec3 E = vec3(cross2(b, c), cross2(c, a), cross2(a, b));
    return (min(E.x, min(E.y, E.z)) >= 0.0 || max(E.x, max(E.y, E.z)) <= 0.0) && E != vec3(0.0);
}

// The nearest of the boundary faces nb (slots, -1 after the last) but entry that the ray
// enters at t >= t_min, ties to the lower slot: its slot, or -1; t_nb its t.
int nearest_beside(ivec4 nb, int entry, float t_min, vec3 o, vec3 d, vec3 ow, vec3 e1, vec3 e2, float inv_dd,
                   out float t_nb) {
    int best = -1;
    t_nb = 3.0e38;
    for (int i = 0; i < 4 && nb[i] >= 0; ++i) {
        precise float t;
        if (nb[i] != entry && enters(nb[i], o, d, ow, e1, e2, inv_dd, t) && t >= t_min
                && (t < t_nb || (t == t_nb && nb[i] < best))) {
            t_nb = t;
            best = nb[i];
        }
    }
    return best;
}

// A ray that left the mesh (STATUS_REENTER) at t_out, having entered this pass at t_entry
// by face slot entry, by the boundary face whose link is link (link.y: its row of
// u_neighbors), beside one of its edges if near_edge: its status after this pass. With
// LIST it picks the next entry (f_last); else it leaves that to the next peel pass.
float next_entry(ivec2 px, int entry, ivec4 link, bool near_edge, float t_entry, float t_out, vec3 o, vec3 d,
                 precise vec3 ow, vec3 e1, vec3 e2, float inv_dd, float per_t) {
    precise float t_min = t_out - u_tolerance * per_t;  // as march_entry.frag's peel
    // The faces beside the one it left by: where the ray leaves beside a fold of the
    // surface and enters again at once, the rasteriser may not have drawn the face it
    // enters by for this pixel (its hit within a snapping step of the face's edge).
    ivec4 nb = near_edge ? imageLoad(u_neighbors, ivec2(link.y & ((1 << ITEMS_ROW_SHIFT) - 1),
                                                        link.y >> ITEMS_ROW_SHIFT)) : ivec4(-1);
    precise float t_nb;
    int beside = nearest_beside(nb, entry, t_min, o, d, ow, e1, e2, inv_dd, t_nb);
#if LIST
    uint n = min(imageLoad(u_count, px).x, uint(LIST_LENGTH));
    precise float t_next = 3.0e38;
    // A loop over all LIST_LENGTH slots, not up to n: with the count varying between
    // the pixels a shader invocation runs together, llvmpipe (Mesa 22) ended a loop
    // bounded by n after the first pixel's count, and a ray lost the entry it re-enters by.
    for (int i = 0; i < LIST_LENGTH; ++i) {
        if (uint(i) < n) {
            ivec2 e = imageLoad(u_list, ivec2(px.x, px.y + i * int(u_viewport.y))).xy;
            precise float t = intBitsToFloat(e.x);
            bool nearer = t < t_next || (t == t_next && e.y < f_last);
            if (e.y != entry && t >= t_min && nearer) {
                t_next = t;
                f_last = e.y;
            }
        }
    }
    if (beside >= 0 && (t_nb < t_next || (t_nb == t_next && beside < f_last))) {
        t_next = t_nb;
        f_last = beside;
    }
    // A walk that made no way (it left the mesh where it entered) and would enter again
    // where it left: faces that coincide, entered in turn without end (flat slivers at
    // the hull, each face an entry). Traced again instead of walked pass after pass.
    if (f_last >= 0 && (t_out - t_entry) * per_t < u_slack && (t_next - t_out) * per_t < u_slack) {
        suspect(px);
        f_last = -1;
    }
    if (f_last < 0) return STATUS_DONE;
    atomicAdd(u_more, 1u);
    return STATUS_REENTER;
#else
    // Without a list the next peel pass finds the next entry, among the faces the rasteriser
    // drew for the pixel, which may leave out the one beside: a ray that would enter a face
    // beside the one it left by, within a rounding of where it left, is traced again.
    if (beside >= 0 && (t_nb - t_out) * per_t < u_slack) suspect(px);
    return STATUS_REENTER;
#endif
}

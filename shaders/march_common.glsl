// march_common.glsl -- what the tet-marching ray caster's passes share: the per-tet
// records (tetvr/mesh/records.py) read with imageLoad, and each pixel's ray. Locals are
// precise, as in every march pass (march.frag says why).
//
// Coordinate spaces: *_obj mesh coordinates relative to the mesh's bounding-box centre (as
// the records), eye space as in common.glsl. Ray parameter t = eye depth along the view axis
// (the ray's direction has eye z = -1), so the clipping range compares with t directly and
// a segment's world length is (t1 - t0) * length(d).
// Records (images, bound read-only to units PLANES_IMAGE ... POINTS_IMAGE): u_planes (RGBA32F) holds RECORD_TEXELS texels per tet, 2^TETS_ROW_SHIFT tets a row:
// texels 0..3 the face planes (n, w), n . x_obj + w < 0 inside, n the outward unit normal;
// texel 4 the scalar (g, c), s = g . x_obj + c. Slot k of a tet is its k-th point in
// increasing welded id (points at the same coordinates count as one), face k the face opposite it. u_links (RGBA32I), four texels a tet,
// 2^LINKS_ROW_SHIFT tets a row: across face k, (4 * neighbour + its face there, -1 on the
// boundary; the neighbour's point opposite that face; its cell scalar's float bits; 1 where
// the point field jumps at the face: duplicated nodes whose copies carry other values).
// u_ids (RGBA32I) the tets' point ids and u_points (RGBA32F) the points (position relative
// to the eye, written per view; scalar), 2^ITEMS_ROW_SHIFT a row.
// Defines: PERSPECTIVE, TETS_ROW_SHIFT, LINKS_ROW_SHIFT, ITEMS_ROW_SHIFT (powers of two:
// llvmpipe has no vector integer division, a shift and a mask are one instruction per
// lane; tetvr.gl.raymarch chooses them), PLANES_IMAGE, IDS_IMAGE, LINKS_IMAGE, POINTS_IMAGE.

#define RECORD_TEXELS 5
#define STATUS_DONE 0.0
#define STATUS_REENTER 1.0   // the ray left the mesh: look for the next entry (peel)
#define NO_ENTRY (-1)        // the entry target where no face or cut cell was drawn

layout(binding = PLANES_IMAGE, rgba32f) restrict readonly uniform image2D u_planes;
layout(binding = IDS_IMAGE, rgba32i) restrict readonly uniform iimage2D u_ids;
layout(binding = LINKS_IMAGE, rgba32i) restrict readonly uniform iimage2D u_links;
layout(binding = POINTS_IMAGE, rgba32f) restrict readonly uniform image2D u_points;
uniform mat4 u_inv_view;    // eye -> obj
uniform vec2 u_ray_scale;   // NDC -> eye x, y per unit depth (perspective) or eye x, y (parallel)
uniform vec2 u_viewport;    // pixels
uniform float u_near;
uniform float u_far;

// The texel of tet's record: add k for face k's plane, 4 for its scalar.
ivec2 tet_record(int tet) {
    return ivec2((tet & ((1 << TETS_ROW_SHIFT) - 1)) * RECORD_TEXELS, tet >> TETS_ROW_SHIFT);
}

vec4 face_plane(int tet, int k) {
    return imageLoad(u_planes, tet_record(tet) + ivec2(k, 0));
}

vec4 tet_scalar(int tet) {
    return imageLoad(u_planes, tet_record(tet) + ivec2(4, 0));
}

// The tet's four point ids, increasing, slot k opposite face k.
ivec4 tet_ids(int tet) {
    return imageLoad(u_ids, ivec2(tet & ((1 << ITEMS_ROW_SHIFT) - 1), tet >> ITEMS_ROW_SHIFT));
}

// A point's (position relative to the eye, scalar); tetvr.gl.raymarch writes them per view.
vec4 point_record(int p) {
    return imageLoad(u_points, ivec2(p & ((1 << ITEMS_ROW_SHIFT) - 1), p >> ITEMS_ROW_SHIFT));
}

// The link across the tet's face k (see Records above).
ivec4 tet_link(int tet, int k) {
    return imageLoad(u_links, ivec2(((tet & ((1 << LINKS_ROW_SHIFT) - 1)) << 2) + k, tet >> LINKS_ROW_SHIFT));
}


// The ray through the centre of the pixel at window position xy, in obj space.
void pixel_ray(vec2 xy, out vec3 o_obj, out vec3 d_obj) {
    precise vec2 r = (xy / u_viewport * 2.0 - 1.0) * u_ray_scale;
#if PERSPECTIVE
    o_obj = u_inv_view[3].xyz;
    d_obj = mat3(u_inv_view) * vec3(r, -1.0);
#else
    o_obj = (u_inv_view * vec4(r, 0.0, 1.0)).xyz;
    d_obj = mat3(u_inv_view) * vec3(0.0, 0.0, -1.0);
#endif
}

// The origin of the ray through window position xy relative to the eye, in obj axes
// (the eye itself in perspective).
vec3 ray_from_eye(vec2 xy) {
#if PERSPECTIVE
    return vec3(0.0);
#else
    precise vec2 r = (xy / u_viewport * 2.0 - 1.0) * u_ray_scale;
    return mat3(u_inv_view) * vec3(r, 0.0);
#endif
}

// Where the ray meets a plane (n, w); the ray must not be parallel to it.
float plane_t(vec4 plane, vec3 o, vec3 d) {
    return -(dot(plane.xyz, o) + plane.w) / dot(plane.xyz, d);
}

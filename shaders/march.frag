#version 430
// march.frag -- the tet-marching ray caster (Weiler et al. 2003): from its entry, each
// pixel's ray walks from tet to tet through shared faces, integrating one exact segment per
// tet by a lookup in the pre-integration table (lookup.glsl), composited front to back.
//
// In:  u_entry (march_entry.frag: 4 * tet + k or -2 - tet; after a peel, NO_ENTRY where
//      none: the first layer's pass runs only where an entry was drawn), and, after the
//      first layer (FIRST 0), the last march's f_color, f_state and f_last.
//      Records and rays: march_common.glsl.
// Runs where the depth test passes (early, before the shader: tetvr.gl.raymarch draws it
// at the far end of the depth range against the entry depths, or against the pixels a
// mark pass left for it), so that pixels no ray enters cost nothing.
// Out: f_color premultiplied RGBA so far; f_state = (t where the walk stopped, status:
//      STATUS_REENTER if the ray left the mesh and may enter again, else STATUS_DONE);
//      f_last the entry this pass started from (the next peel skips it); with LIST, the
//      entry the next pass starts from instead.
// LIST 1: instead of a peel pass, where the ray left the mesh this pass picks its next entry
// from the faces the first entry pass listed for the pixel (march_entry.frag: by the peel's
// rule, the nearest not before where the ray left, less a rounding, nor the face it entered
// by; ties to the lower slot), leaves it in f_last and counts the pixel in u_more; the next
// pass starts there. (tetvr.gl.raymarch uses the list where no pixel's overflowed.) The
// boundary faces beside the one it left by are candidates too (u_neighbors, tested as the
// walk sees them): the rasteriser may leave out a face the ray enters within a snapping step
// of its edge, and beside a fold of the surface that face is where the ray goes on. Without
// LIST a ray that would enter such a face at once is traced again (march_next.glsl).
// JUMPS 1: the point field jumps at some faces (duplicated nodes whose copies carry other values,
// link.w): crossing one, the walk takes the scalars of the tet it enters.
// MULTIPLICITY 1: the mesh repeats cells (tetvr.mesh.copies keeps each once, u_copies says how
// many times): a tet's segment is composited once per copy.
// Defines: CELL_DATA 1 (the records' scalars are cell constants: g = (0, c), and the scalar
// is not carried across faces), FIRST (the first layer), EXTENT 1 (instead of colour, f_color = (eye depth of
// the first entry, of the last exit, segments walked, 0): the ray limits for fusion with a
// volume, and the segment count the benchmarks divide by; no table lookups).
// The walk: the first tet (where the ray enters, or starts at the near plane) is left by
// the nearest of its face planes the ray points out of. From then on, by points (Marmitt &
// Slusallek 2006; tetvr.mesh.records): the ray holds the triangle it came in by, seen in the
// plane across the ray about the ray's origin; the signs of three 2D cross products with
// the tet's fourth point choose the face it leaves by, and the same products weigh the
// exit's t and scalar. A step reads one link (the next tet, its face, the point across
// it) and one point; the triangle it carries is about the ray whatever the rounding. The
// scalar is carried from face to face (it is continuous: point data is linear in each
// tet; cell data comes with the link).
// With clip planes or a ray limit (window.glsl: CLIP_PLANES, RAY_LIMIT) the walk still
// starts at the entry, but only each segment's part inside the pixel's window is
// composited (its scalars from the tet's linear field at the cut), and it stops at the
// window's far end.
// INTEGRATION_EXACT 1: no table; each segment is cut where its scalar crosses a control
// point of the transfer function and each cut integrated in closed form and by quadrature
// (raycast_exact.glsl, the reference's model in float32).
// Every local of the walk's arithmetic here and in march_next.glsl, march_entry.frag and
// march_common.glsl is precise: no fused multiply-adds, no reordering. NVIDIA's compiler
// fuses where it likes, differently at each use, so that a point seen from two tets, or a
// ray's origin in the entry pass and in the march, could differ in the last bit; a ray in
// the plane of a face (a slab's face-on diagonals) then lost the tie rule (side()) and the
// pixel (0.7 off on an H200, where `precise` on every local made it exact).

#include "march_common.glsl"
#include "window.glsl"
#if INTEGRATION_EXACT
#include "tf_points.glsl"
#include "raycast_exact.glsl"
#else
#include "lookup.glsl"
#endif

layout(early_fragment_tests) in;  // the depth test chooses the pixels: before the shader runs

uniform isampler2D u_entry;
#if !FIRST
uniform sampler2D u_color_in;
uniform sampler2D u_state_in;
uniform isampler2D u_last_in;
#endif
// An entry face whose unit normal meets the ray's direction at a cosine below this is
// taken as seen edge-on.
#define GRAZING 1.0e-4

#if INTEGRATION_EXACT
// The transfer function's interval of the last segment's end: the next segment mostly
// starts in it (the scalar is continuous), which spares its search.
TFInterval tf_last;
bool tf_known = false;

// The segment from scalar s0 to s1 over world length len, exactly (raycast_exact.glsl).
vec4 segment(float s0, float s1, float len) {
    TFInterval a = tf_known && tf_holds(tf_last, s0) ? tf_last : tf_interval(s0);
    TFInterval b = tf_holds(a, s1) ? a : tf_interval(s1);
    tf_last = b;
    tf_known = true;
    return integrate_piece(s0, tf_in(a, s0), a.i, s1, tf_in(b, s1), b.i, len);
}
#else
vec4 segment(float s0, float s1, float len) {
    return lookup_segment(s0, s1, len);
}
#endif

uniform int u_max_steps;      // bound on tets per ray and layer (a walk caught by rounding)
// Most tets a ray walks by face planes before it walks by points (see main).
#define PLANE_STEPS 8
// The walk goes by points from the first tet where the ray enters by a face whose points,
// seen across the ray, weigh each at least this share: clear of the face's edges by more
// than a rounding (on an edge the reference's tie rule decides, which the walk by planes
// keeps).
#define CLEAR_ENTRY 1.0e-3
uniform float u_opaque;       // stop once alpha reaches this (early ray termination)

#if MULTIPLICITY
// Each tet's number of copies (x): the mesh repeats cells, which tetvr.mesh.copies keeps once.
layout(binding = COPIES_IMAGE, rgba32i) restrict readonly uniform iimage2D u_copies;
int g_copies = 1;
#define COPIES_OF(t) g_copies = imageLoad(u_copies, ivec2((t) & ((1 << ITEMS_ROW_SHIFT) - 1), (t) >> ITEMS_ROW_SHIFT)).x
#else
#define COPIES_OF(t)
#endif

// The frame's check of itself: the pixels whose walk went wrong (a step bound reached, no
// face ahead of the ray, an exit behind its entry) are counted and listed (the first
// SUSPECT_LENGTH), for tetvr.gl.selfcheck to trace again on the CPU.
layout(std430, binding = SUSPECT_BUFFER) restrict buffer Suspect { uint u_suspects; uint u_suspect[]; };
uniform float u_slack;  // length an exit may lie behind its entry by rounding alone

bool g_suspect = false;  // this ray listed already

void suspect(ivec2 px) {
    if (g_suspect) return;
    g_suspect = true;
    uint i = atomicAdd(u_suspects, 1u);
    if (i < uint(SUSPECT_LENGTH)) u_suspect[i] = uint(px.y) * uint(u_viewport.x) + uint(px.x);
}

layout(location = 0) out vec4 f_color;
layout(location = 1) out vec2 f_state;
layout(location = 2) out int f_last;

// The part of a segment from (t_in, s_in) to (t_out, s_out) that is kept, composited into
// acc; true where the ray stops there (the far end of its window, or opaque). On return
// t_out is where the segment ended (cut at the far end) and s_out the scalar there.
bool composite(inout vec4 acc, float t_in, float s_in, inout float t_out, inout float s_out, vec2 win, float per_t) {
    bool at_far = t_out >= win.y;
    if (at_far) {
        // The scalar is linear along the segment (within one tet).
        precise float t_far = win.y;
        s_out = t_out > t_in ? s_in + (s_out - s_in) * ((t_far - t_in) / (t_out - t_in)) : s_out;
        t_out = t_far;
    }
#if RAY_WINDOW
    // The part of the segment in front of the window's near end is not composited.
    precise float t_a = max(t_in, win.x);
    bool shown = t_out > t_a;
    precise float s_a = t_a > t_in && t_out > t_in ? s_in + (s_out - s_in) * ((t_a - t_in) / (t_out - t_in)) : s_in;
#else
    precise float t_a = t_in, s_a = s_in;
    const bool shown = true;
#endif
#if EXTENT
    if (shown) {
        acc.x = min(acc.x, t_a);
        acc.y = max(acc.y, t_out);
    }
    acc.z += 1.0;
    return at_far;
#else
    if (shown) {
        precise vec4 seg = segment(s_a, s_out, (t_out - t_a) * per_t);
#if MULTIPLICITY
        // A cell the mesh holds several times: composited once per copy, as the reference does.
        for (int i = 1; i < g_copies; ++i) acc += (1.0 - acc.a) * seg;
#endif
        acc += (1.0 - acc.a) * seg;
    }
    return at_far || acc.a >= u_opaque;
#endif
}

// A point at r from the ray's origin, seen across the ray: (its place in the plane across
// the ray, axes e1 and e2; its ray parameter t).
vec3 across(vec3 r, vec3 e1, vec3 e2, vec3 d, float inv_dd) {
    precise vec3 a = vec3(dot(r, e1), dot(r, e2), dot(r, d) * inv_dd);
    return a;
}

// e(p, q): the turn from p to q about the origin of the plane across the ray; precise, so
// e(p, q) = -e(q, p) exactly.
float cross2(vec2 p, vec2 q) {
    precise float e = p.x * q.y - p.y * q.x;
    return e;
}

// The values v at a face's points weighed by w (where the ray passes among them, each >= 0),
// or otherwise where the weights are all 0.
float weighed(vec3 w, vec3 v, float otherwise) {
    precise float sum = w.x + w.y + w.z;
    return sum > 0.0 ? dot(w, v) / sum : otherwise;
}

// The eye's x and y axes seen across the ray (set in main).
vec2 g_eye_x, g_eye_y;

// The side of the ray that the edge from p to q passes, where e(p, q) = f is 0 (the ray
// in the plane of the edge): the side it passes the ray moved by (e, e^2) along the eye's
// x and y for an infinitesimal e, the reference's rule (tetvr.reference.segments), so that
// a ray in a face's plane is in the tet the reference gives it to, and a ray in a boundary
// face's plane is in the mesh exactly where the reference has it.
float side(float f, vec2 p, vec2 q) {
    precise vec2 e = q - p;
    precise float x = -cross2(g_eye_x, e), y = -cross2(g_eye_y, e);
    return f != 0.0 ? f : (x != 0.0 ? x : y);
}

#include "march_next.glsl"

// Face k of a tet (its point ids: ids) seen across the ray: its points' slots (k + 1, k + 2,
// k + 3, in an order that turns counter-clockwise about the ray), their places p, ts and
// scalars ss, and the edge values E (E.x = e(pb, pc), E.y = e(pc, pa), E.z = e(pa, pb)):
// all >= 0 where the triangle holds the ray.
void face_across(ivec4 ids, int k, vec3 ow, vec3 e1, vec3 e2, vec3 d, float inv_dd, out int sa, out int sb,
                 out int sc, out vec2 pa, out vec2 pb, out vec2 pc, out vec3 ts, out vec3 ss, out vec3 E) {
    sa = (k + 1) & 3; sb = (k + 2) & 3; sc = (k + 3) & 3;
    precise vec4 qa = point_record(ids[sa]), qb = point_record(ids[sb]), qc = point_record(ids[sc]);
    precise vec3 a = across(qa.xyz - ow, e1, e2, d, inv_dd), b = across(qb.xyz - ow, e1, e2, d, inv_dd),
         c = across(qc.xyz - ow, e1, e2, d, inv_dd);
    pa = a.xy;
    pb = b.xy;
    pc = c.xy;
    ts = vec3(a.z, b.z, c.z);
    ss = vec3(qa.w, qb.w, qc.w);
    E = vec3(cross2(pb, pc), cross2(pc, pa), cross2(pa, pb));
    if (E.x + E.y + E.z < 0.0) {  // clockwise about the ray: swap b and c
        int i = sb; sb = sc; sc = i;
        precise vec2 p = pb; pb = pc; pc = p;
        ts = ts.xzy;
        ss = ss.xzy;
        E = -E.xzy;
    }
}

// The slot in the next tet of the point in slot s of this one, the ray going from face k
// here to face f there: the records list each tet's points in increasing id, so the three
// points of a face come in the same order in both tets.
int next_slot(int s, int k, int f) {
    int i = s - int(s > k);
    return i + int(i >= f);
}

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
#if FIRST
#if EXTENT
    precise vec4 acc = vec4(3.0e38, -3.0e38, 0.0, 0.0);
#else
    precise vec4 acc = vec4(0.0);
#endif
    f_last = -1;
    f_state = vec2(0.0, STATUS_DONE);
#else
    precise vec4 acc = texelFetch(u_color_in, px, 0);
    precise vec2 state = texelFetch(u_state_in, px, 0).xy;
    f_last = texelFetch(u_last_in, px, 0).r;
    f_state = vec2(state.x, STATUS_DONE);
    if (state.y != STATUS_REENTER) {
        f_color = acc;
        return;
    }
#endif
    f_color = acc;
#if LIST && !FIRST
    int entry = f_last;  // picked by the last pass
    f_last = -1;
#else
    int entry = texelFetch(u_entry, px, 0).r;
    if (entry == NO_ENTRY) return;  // no (further) entry
    f_last = entry;
#endif

#if RAY_WINDOW
    precise vec2 win = ray_window((gl_FragCoord.xy / u_viewport * 2.0 - 1.0) * u_ray_scale, px, u_near, u_far);
    if (win.y <= win.x) return;  // nothing of this ray is kept
#else
    precise vec2 win = vec2(u_near, u_far);
#endif
    precise vec3 o, d;
    pixel_ray(gl_FragCoord.xy, o, d);
    precise float per_t = length(d);  // world length per unit of t
    // The plane across the ray (axes e1, e2) in which the walk by points sees the points.
    precise vec3 dn = normalize(d);
    precise vec3 e1 = normalize(abs(dn.x) < 0.6 ? vec3(0.0, -dn.z, dn.y) : vec3(-dn.y, dn.x, 0.0));
    precise vec3 e2 = cross(dn, e1);
    precise float inv_dd = 1.0 / dot(d, d);
    precise vec3 ow = ray_from_eye(gl_FragCoord.xy);
    int tet, face;
    precise float t_in;
    bool faced = false;  // the ray enters by a face it does not see edge-on
    if (entry >= 0) {
        tet = entry >> 2;
        face = entry & 3;
        precise vec4 entry_plane = face_plane(tet, face);
        precise float entry_den = dot(entry_plane.xyz, d);
        faced = entry_den < -GRAZING * per_t;
        if (faced) {
            t_in = max(-(dot(entry_plane.xyz, o) + entry_plane.w) / entry_den, u_near);
        } else {
            // The face it was drawn for is seen almost edge-on, where a rounding moves the
            // t of its plane far. The face's points, seen across the ray, give it as the
            // walk gives an exit (a face two bricks share: one t for both): the depths of
            // the points weighed by where the ray passes among them, a t within the face's
            // own depth span whatever the rounding. Where the eye is in the face's plane,
            // so that the points lie on a line through the ray, they say nothing, and the
            // last of the other planes the ray enters by gives t.
            ivec4 ids = tet_ids(tet);
            precise vec3 a = across(point_record(ids[(face + 1) & 3]).xyz - ow, e1, e2, d, inv_dd);
            precise vec3 b = across(point_record(ids[(face + 2) & 3]).xyz - ow, e1, e2, d, inv_dd);
            precise vec3 c = across(point_record(ids[(face + 3) & 3]).xyz - ow, e1, e2, d, inv_dd);
            precise vec3 E = vec3(cross2(b.xy, c.xy), cross2(c.xy, a.xy), cross2(a.xy, b.xy));
            precise vec3 w = max(E.x + E.y + E.z < 0.0 ? -E : E, 0.0);
            precise float sum = w.x + w.y + w.z;
            if (sum > 0.0) {
                t_in = max(dot(w, vec3(a.z, b.z, c.z)) / sum, u_near);
            } else {
                t_in = u_near;
                for (int k = 0; k < 4; ++k) {
                    precise vec4 plane = face_plane(tet, k);
                    precise float den = dot(plane.xyz, d);
                    if (k != face && den < 0.0) t_in = max(t_in, -(dot(plane.xyz, o) + plane.w) / den);
                }
            }
        }
    } else {
        // The ray starts inside the tet, at the near plane: it leaves by a face it points
        // out of, so the face it points into most stands for "the face it came in by"
        // (every tet has one: its faces' area-weighted normals sum to zero).
        tet = -2 - entry;
        face = 0;
        precise float most = 3.0e38;
        for (int k = 0; k < 4; ++k) {
            precise float den = dot(face_plane(tet, k).xyz, d);
            if (den < most) { most = den; face = k; }
        }
        t_in = u_near;
    }
#if EXTENT && !RAY_WINDOW
    acc.x = min(acc.x, t_in);
#endif
    COPIES_OF(tet);
    precise float t_entry = t_in;  // where this pass's walk entered the mesh

    // The walk by points (Marmitt & Slusallek 2006) sees the points in the plane across the
    // ray, the ray at its origin: the face the ray came in by is a triangle (a, b, c)
    // about the origin, counter-clockwise; the tet's fourth point n makes a face with each
    // of its edges, and the signs of e(a, n), e(b, n), e(c, n) say which one the ray leaves
    // by. The edge values e of that face are the exit's barycentric weights (its t and its
    // scalar) and carry over to the next triangle, so the walk always holds a triangle
    // about the ray, whatever the rounding. A step reads the link across the exit face
    // and the point it leads to.
    g_eye_x = vec2(dot(u_inv_view[0].xyz, e1), dot(u_inv_view[0].xyz, e2));
    g_eye_y = vec2(dot(u_inv_view[1].xyz, e1), dot(u_inv_view[1].xyz, e2));
    int sa, sb, sc;
    precise vec2 pa, pb, pc;
    precise vec3 ts, ss, E;

    // Where the face the ray enters by holds it as seen across it, the walk goes by points
    // from the first tet on. Else by face planes until then: the first tet (which a ray
    // starting at the near plane entered by no face) is left by the nearest of the three
    // faces other than the one it came in by whose plane the ray points out of; and so is
    // each next tet until the face the ray leaves by holds the ray as seen across it (the
    // rasteriser may give a grazing ray an entry it misses by a rounding; the walk by
    // planes finds its way back). A plane's t is rounding where the tet is a sliver seen
    // face-on (its four faces nearly in one plane): the nearest exit plane is then any of
    // three, and a walk by planes from a sliver at the boundary went astray (a Delaunay
    // mesh's hull); the points' signs decide it as the reference does.
    precise vec4 g = tet_scalar(tet);
    precise float s_in = dot(g.xyz, o + t_in * d) + g.w;
    precise float t_out = t_in, s_out = s_in;
    precise float status = STATUS_DONE;
    bool by_points = false;
    bool near_edge = true;  // where the ray left the mesh: beside an edge of that face (see LIST below)
    ivec4 link;
    int k = 0;
    bool ended = false;  // the walk stopped as it should: opaque, at its window's end, out of the mesh
    bool missed = false;  // the ray's first point lies outside the tet it was given (see below)
    if (faced) {
        ivec4 ids = tet_ids(tet);
        face_across(ids, face, ow, e1, e2, d, inv_dd, sa, sb, sc, pa, pb, pc, ts, ss, E);
#if !CELL_DATA
        // The scalar where the ray enters, from the face's points weighed by where it passes
        // among them: the tet's gradient is the scalar's change over the tet's height, which
        // in a flat sliver makes its float32 rounding large.
        s_in = weighed(max(E, 0.0), ss, s_in);
        s_out = s_in;
#endif
        if (min(E.x, min(E.y, E.z)) > CLEAR_ENTRY * (E.x + E.y + E.z)) {
            // As if the ray came from a tet across the entry face (next_slot(s, f, f) = s):
            // the walk's first step takes this tet, its fourth point and its cell scalar.
            by_points = true;
            k = face;
            link = ivec4(4 * tet + face, ids[face], floatBitsToInt(g.w), 0);
        }
    }
    for (int step = 0; !by_points && step < PLANE_STEPS && step < u_max_steps; ++step) {
        precise float t_exit = 3.0e38;
        int exit_face = -1;
        precise vec4 t_ahead = vec4(-1.0);  // the t of each face the ray points out of, else -1
        for (int j = 1; j < 4; ++j) {
            int kk = (face + j) & 3;
            precise vec4 plane = face_plane(tet, kk);
            precise float den = dot(plane.xyz, d);
            if (den > 0.0) {
                precise float t = -(dot(plane.xyz, o) + plane.w) / den;
                t_ahead[kk] = max(t, 0.0);
                if (t < t_exit) { t_exit = t; exit_face = kk; }
            }
            // The entry point must lie inside the tet's other faces: a face the rasteriser
            // gave a pixel its triangle does not cover (a sliver seen almost edge-on, a
            // face of zero area) puts it on the face's plane away from the tet. Measured as
            // a distance, which rounding moves by far less than u_slack at any angle.
            if (step == 0) missed = missed || dot(plane.xyz, o + t_in * d) + plane.w > u_slack;
        }
        if (exit_face < 0) break;  // no face ahead: only rounding on a degenerate ray does this
        // The exit face's three points, in slots k + 1, k + 2, k + 3.
        ivec4 ids = tet_ids(tet);
        face_across(ids, exit_face, ow, e1, e2, d, inv_dd, sa, sb, sc, pa, pb, pc, ts, ss, E);
        // Where the nearest plane's face does not hold the ray seen across it but another
        // face ahead does, within a rounding of that plane, that face is the exit: a flat
        // sliver's planes nearly coincide, and the nearest of them is rounding (entered
        // beside an edge, a ray took the face into the next tet where it leaves the mesh,
        // and crossed that tet from outside). Further on, the nearest plane stays: a ray
        // along an edge is held by the faces that share it, whichever is the exit.
        for (int j = 1; j < 4 && min(E.x, min(E.y, E.z)) < 0.0; ++j) {
            int kk = (face + j) & 3;
            if (kk == exit_face || t_ahead[kk] < 0.0 || (t_ahead[kk] - t_exit) * per_t > u_slack) continue;
            int qa, qb, qc;
            precise vec2 ua, ub, uc;
            precise vec3 uts, uss, uE;
            face_across(ids, kk, ow, e1, e2, d, inv_dd, qa, qb, qc, ua, ub, uc, uts, uss, uE);
            if (min(uE.x, min(uE.y, uE.z)) >= 0.0) {
                exit_face = kk;
                t_exit = t_ahead[kk];
                sa = qa; sb = qb; sc = qc;
                pa = ua; pb = ub; pc = uc;
                ts = uts; ss = uss; E = uE;
            }
        }
        t_out = max(t_exit, t_in);
        s_out = dot(g.xyz, o + t_out * d) + g.w;
#if !CELL_DATA
        // Where the exit face holds the ray, the scalar from its points, as at the entry.
        if (min(E.x, min(E.y, E.z)) >= 0.0) s_out = weighed(E, ss, s_out);
#endif
        ended = composite(acc, t_in, s_in, t_out, s_out, win, per_t);
        if (ended) break;
        k = exit_face;
        link = tet_link(tet, k);
        ended = link.x < 0;
        if (link.x < 0) {
            // Out of the mesh by a face the ray clearly does not pass through, seen across
            // it: the nearest of planes that nearly coincide (a sliver at the hull seen
            // face-on, entered beside an edge), where a face into the mesh was the exit.
            // The ray would lose its chord through the mesh: traced again.
            if (min(E.x, min(E.y, E.z)) < -CLEAR_ENTRY * (abs(E.x) + abs(E.y) + abs(E.z))) suspect(px);
            status = STATUS_REENTER;
            break;
        }
        if (min(E.x, min(E.y, E.z)) >= 0.0 || step == PLANE_STEPS - 1) {
            by_points = true;
            break;
        }
        tet = link.x >> 2;
        COPIES_OF(tet);
        face = link.x & 3;
        t_in = t_out;
        g = tet_scalar(tet);
#if CELL_DATA
        s_in = g.w;
#else
#if JUMPS
        // Duplicated nodes whose copies differ (link.w): the field jumps, take this tet's.
        s_in = link.w != 0 ? dot(g.xyz, o + t_in * d) + g.w : s_out;
#else
        s_in = s_out;
#endif
#endif
    }
    if (by_points) {
        status = STATUS_DONE;
        ended = false;
        bool astray = false;
        for (int step = 1; step < u_max_steps; ++step) {
            // Into the next tet by its face f: the slots there of the triangle's points.
            int f = link.x & 3;
            sa = next_slot(sa, k, f);
            sb = next_slot(sb, k, f);
            sc = next_slot(sc, k, f);
            tet = link.x >> 2;
            COPIES_OF(tet);
            t_in = t_out;
#if CELL_DATA
            s_in = intBitsToFloat(link.z);  // the field jumps at the face: each cell's own constant
#else
            s_in = s_out;
#if JUMPS
            if (link.w != 0) {
                // Duplicated nodes whose copies differ: the field jumps at the face, so the
                // triangle's scalars and the entry's are this tet's copies (same weights).
                ivec4 ids = tet_ids(tet);
                ss = vec3(point_record(ids[sa]).w, point_record(ids[sb]).w, point_record(ids[sc]).w);
                s_in = weighed(max(E, 0.0), ss, ss.x);
            }
#endif
#endif
            precise vec4 qn = point_record(link.y);  // the point across face f
            precise vec3 n = across(qn.xyz - ow, e1, e2, d, inv_dd);
            precise vec2 pn = n.xy;
            precise float tn = n.z;
            precise float fa = cross2(pa, pn), fb = cross2(pb, pn), fc = cross2(pc, pn);
            precise float sa_ = side(fa, pa, pn), sb_ = side(fb, pb, pn), sc_ = side(fc, pc, pn);
            // Out by (b, c, n) if e(b, n) <= 0 < e(c, n); by (c, a, n) if e(c, n) <= 0 < e(a, n);
            // else by (a, b, n). The next triangle keeps the counter-clockwise turn. Where
            // a point lies exactly on the ray's line, side() breaks the tie as the reference does.
            bool drop_a = sb_ <= 0.0 && sc_ > 0.0;
            bool drop_b = !drop_a && sc_ <= 0.0 && sa_ > 0.0;
            k = drop_a ? sa : (drop_b ? sb : sc);  // the exit face: opposite the point left behind
            E = drop_a ? vec3(fc, -fb, E.x) : (drop_b ? vec3(fa, -fc, E.y) : vec3(fb, -fa, E.z));
            int s0 = drop_a ? sb : (drop_b ? sc : sa);
            int s1 = drop_a ? sc : (drop_b ? sa : sb);
            precise vec2 p0 = drop_a ? pb : (drop_b ? pc : pa);
            precise vec2 p1 = drop_a ? pc : (drop_b ? pa : pb);
            ts = vec3(drop_a ? ts.yz : (drop_b ? ts.zx : ts.xy), tn);
            ss = vec3(drop_a ? ss.yz : (drop_b ? ss.zx : ss.xy), qn.w);
            sa = s0; sb = s1; sc = f;
            pa = p0; pb = p1; pc = pn;
            precise vec3 w = max(E, 0.0);
            precise float sum = w.x + w.y + w.z;
            precise float t_w = sum > 0.0 ? dot(w, ts) / sum : t_in;
            t_out = max(t_w, t_in);
#if CELL_DATA
            s_out = s_in;
#else
            s_out = sum > 0.0 ? dot(w, ss) / sum : s_in;
#endif
            // The exit behind the entry: not this tet's (a face seen edge-on, whose points'
            // weights are rounding, or a walk gone astray): traced again (tetvr.gl.selfcheck).
            astray = astray || (t_in - t_w) * per_t > u_slack;
            // A walk gone astray may circle for the rest of the step bound (the mesh's cell
            // count): stop it here; the ray is traced again on the CPU.
            if (astray) break;
            ended = composite(acc, t_in, s_in, t_out, s_out, win, per_t);
            if (ended) break;
            link = tet_link(tet, k);
            if (link.x < 0) {
                ended = true;
                status = STATUS_REENTER;
                // Its place on the face it leaves by, from the weights of that face's points.
                near_edge = min(w.x, min(w.y, w.z)) <= NEAR_EDGE * sum;
                break;
            }
        }
        if (astray || !ended) suspect(px);  // an exit behind its entry, or the step bound reached
        if (status == STATUS_REENTER) {
            // Out of the mesh by face k: where, by its plane, as the next entry pass finds
            // the faces it may enter by (march_entry.frag), so that a face that coincides
            // with the one left is found again at the same t. (After the loop: llvmpipe
            // would read the plane at every step, for every lane.)
            precise vec4 plane = face_plane(tet, k);
            precise float den = dot(plane.xyz, d);
            if (den > 0.0) t_out = max(-(dot(plane.xyz, o) + plane.w) / den, t_in);
            // A face the ray meets almost edge-on (or not at all) is one it may have left
            // by a rounding: seen across the ray, its sliver holds the ray where a face
            // beside it, inside the mesh, should; the ray would lose the chord after it.
            if (den < GRAZING * per_t) suspect(px);
        }
    } else if (!ended) {
        suspect(px);  // no face ahead, or the step bound reached
    }
    if (missed) suspect(px);  // an entry outside its tet
#if LIST
    f_last = -1;
#endif
    if (status == STATUS_REENTER)
        status = next_entry(px, entry, link, near_edge, t_entry, t_out, o, d, ow, e1, e2, inv_dd, per_t);
    f_color = acc;
    f_state = vec2(t_out, status);
}

#version 430
// march.frag -- the tet-marching ray caster (Weiler et al. 2003): from its entry, each
// pixel's ray walks from tet to tet through shared faces, integrating one exact segment per
// tet by a lookup in the pre-integration table (lookup.glsl), composited front to back.
//
// In:  u_entry_depth / u_entry (march_entry.frag: depth 1 where no entry; 4 * tet + k or
//      -2 - tet), and, after the first layer (FIRST 0), the last march's f_color, f_state
//      and f_last. Records and rays: march_common.glsl.
// Out: f_color premultiplied RGBA so far; f_state = (t where the walk stopped, status:
//      STATUS_REENTER if the ray left the mesh and may enter again, else STATUS_DONE);
//      f_last the entry this pass started from (the next peel skips it).
// Defines: CELL_DATA 1 (the records' scalars are cell constants: g = (0, c), and the scalar
// is not carried across faces), FIRST (the first layer), EXTENT 1 (instead of colour, f_color = (eye depth of
// the first entry, of the last exit, segments walked, 0): the ray limits for fusion with a
// volume, and the segment count the benchmarks divide by; no table lookups).
// The walk leaves each tet by the nearest of the three faces other than the one it came in
// by whose plane the ray points out of; the scalar is carried from face to face (it is
// continuous: point data is linear in each tet; cell data is read per tet), so each step reads three planes, the
// scalar record and the mates.
// With clip planes or a ray limit (window.glsl: CLIP_PLANES, RAY_LIMIT) the walk still
// starts at the entry, but only each segment's part inside the pixel's window is
// composited (its scalars from the tet's linear field at the cut), and it stops at the
// window's far end.
// INTEGRATION_EXACT 1: no table; each segment is cut where its scalar crosses a control
// point of the transfer function and each cut integrated in closed form and by quadrature
// (raycast_exact.glsl, the reference's model in float32).

#include "march_common.glsl"
#include "window.glsl"
#if INTEGRATION_EXACT
#include "tf_points.glsl"
#include "raycast_exact.glsl"
#else
#include "lookup.glsl"
#endif

uniform sampler2D u_entry_depth;
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
uniform float u_opaque;       // stop once alpha reaches this (early ray termination)

layout(location = 0) out vec4 f_color;
layout(location = 1) out vec2 f_state;
layout(location = 2) out int f_last;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
#if FIRST
#if EXTENT
    vec4 acc = vec4(3.0e38, -3.0e38, 0.0, 0.0);
#else
    vec4 acc = vec4(0.0);
#endif
    f_last = -1;
    f_state = vec2(0.0, STATUS_DONE);
#else
    vec4 acc = texelFetch(u_color_in, px, 0);
    vec2 state = texelFetch(u_state_in, px, 0).xy;
    f_last = texelFetch(u_last_in, px, 0).r;
    f_state = vec2(state.x, STATUS_DONE);
    if (state.y != STATUS_REENTER) {
        f_color = acc;
        return;
    }
#endif
    f_color = acc;
    if (texelFetch(u_entry_depth, px, 0).r >= 1.0) return;  // no (further) entry
    int entry = texelFetch(u_entry, px, 0).r;
    f_last = entry;

#if RAY_WINDOW
    vec2 win = ray_window((gl_FragCoord.xy / u_viewport * 2.0 - 1.0) * u_ray_scale, px, u_near, u_far);
    if (win.y <= win.x) return;  // nothing of this ray is kept
    float far = win.y;
#else
    float far = u_far;
#endif
    vec3 o, d;
    pixel_ray(gl_FragCoord.xy, o, d);
    float per_t = length(d);  // world length per unit of t
    int tet, face;
    float t_in;
    if (entry >= 0) {
        tet = entry >> 2;
        face = entry & 3;
        vec4 entry_plane = face_plane(tet, face);
        float entry_den = dot(entry_plane.xyz, d);
        if (entry_den < -GRAZING * per_t) {
            t_in = max(-(dot(entry_plane.xyz, o) + entry_plane.w) / entry_den, u_near);
        } else {
            // The face it was drawn for is seen edge-on (the eye in its plane), where its
            // plane says nothing of where the ray comes in: the last of the other planes
            // it enters by does. (Only then: a plane almost along the ray gives a t that
            // rounding moves far, and the faces shared by bricks must give both bricks one t.)
            t_in = u_near;
            for (int k = 0; k < 4; ++k) {
                vec4 plane = face_plane(tet, k);
                float den = dot(plane.xyz, d);
                if (k != face && den < 0.0) t_in = max(t_in, -(dot(plane.xyz, o) + plane.w) / den);
            }
        }
    } else {
        // The ray starts inside the tet, at the near plane: it leaves by a face it points
        // out of, so the face it points into most stands for "the face it came in by"
        // (every tet has one: its faces' area-weighted normals sum to zero).
        tet = -2 - entry;
        face = 0;
        float most = 3.0e38;
        for (int k = 0; k < 4; ++k) {
            float den = dot(face_plane(tet, k).xyz, d);
            if (den < most) { most = den; face = k; }
        }
        t_in = u_near;
    }
    vec4 g = tet_scalar(tet);
    float s_in = dot(g.xyz, o + t_in * d) + g.w;
#if EXTENT && !RAY_WINDOW
    acc.x = min(acc.x, t_in);
#endif
    float status = STATUS_DONE;
    float t_out = t_in;
    for (int step = 0; step < u_max_steps; ++step) {
        float t_exit = 3.0e38;
        int exit_face = -1;
        // The three faces other than the one the ray came in by: three fetches for every
        // lane alike (a skipped iteration would still be fetched for the other lanes).
        ivec2 rec = tet_record(tet);
        for (int j = 1; j < 4; ++j) {
            int k = (face + j) & 3;
            vec4 plane = texelFetch(u_planes, rec + ivec2(k, 0), 0);
            float den = dot(plane.xyz, d);
            if (den > 0.0) {
                float t = -(dot(plane.xyz, o) + plane.w) / den;
                if (t < t_exit) { t_exit = t; exit_face = k; }
            }
        }
        if (exit_face < 0) break;  // no face ahead: only rounding on a degenerate ray does this
        t_out = max(t_exit, t_in);
        bool at_far = t_out >= far;
        if (at_far) t_out = far;
        float s_out = dot(g.xyz, o + t_out * d) + g.w;
#if RAY_WINDOW
        // The part of the segment in front of the window's near end is not composited.
        float t_a = max(t_in, win.x);
        bool shown = t_out > t_a;
        float s_a = t_a > t_in ? dot(g.xyz, o + t_a * d) + g.w : s_in;
#else
        float t_a = t_in, s_a = s_in;
        const bool shown = true;
#endif
#if EXTENT
        if (shown) {
            acc.x = min(acc.x, t_a);
            acc.y = max(acc.y, t_out);
        }
        acc.z += 1.0;
        if (at_far) break;
#else
        if (shown) acc += (1.0 - acc.a) * segment(s_a, s_out, (t_out - t_a) * per_t);
        if (at_far || acc.a >= u_opaque) break;
#endif
        int mate = tet_mates(tet)[exit_face];
        if (mate < 0) {
            status = STATUS_REENTER;
            break;
        }
        tet = mate >> 2;
        face = mate & 3;
        t_in = t_out;
        g = tet_scalar(tet);
#if CELL_DATA
        s_in = g.w;  // the field jumps at the face: each cell's own constant
#else
        s_in = s_out;
#endif
    }
    f_color = acc;
    f_state = vec2(t_out, status);
}

#version 430
// raycast.frag -- casts one ray per pixel through an image volume and writes its colour.
//
// Spaces: *_eye    camera at the origin looking down -z (world units, rigid);
//         *_local  world minus the volume's centre (keeps float32 precise far from 0);
//         *_idx    voxel index space: voxel (i, j, k) at (i, j, k); the box is [0, n-1].
// The ray of the pixel centre at NDC (x, y) is, as in Camera.rays,
//   parallel:    o_eye = (x k.x, y k.y, 0), d_eye = (0, 0, -1)
//   perspective: o_eye = 0,                d_eye = (x k.x, y k.y, -1)
// so the ray parameter t is eye depth; one unit of t is |d_eye| world units.
// The ray is integrated over [max(entry, near, t_start), min(exit, far, t_end)], also
// clipped to the world clip box when u_use_clip_box is 1; t_start / t_end come per pixel
// from u_limits when u_use_limits is 1 (for fusion with the tet mesh).
// Samples: the entry, then entry + first + i * step, then the exit (first = step, or a
// seeded random fraction of it with u_jitter 1), and besides them every point where the
// ray crosses a voxel-index plane (x, y or z integer). So every piece between two samples
// lies inside one voxel cell, where the trilinear field is a smooth cubic along the ray:
// taking it as linear errs by h^2/8 |s''| instead of h/4 times the jump in slope at the
// cell's faces, and a maximum at a voxel that the ray passes through is sampled exactly.
// Every piece is integrated with its true length, so the integrated interval does not
// depend on the sampling: INTEGRATION_EXACT 1 cuts it at the transfer function's control
// points and integrates each cut exactly (raycast_exact.glsl); 0 looks it up in the
// pre-integration table (lookup.glsl).
//
// RAYCAST_MODE (a define): 0 emission-absorption, 1 maximum intensity, 2 mean intensity
// ("xray"), 3 first hit of u_iso, Blinn-Phong shaded (headlight).
// In:  the uniforms below, lookup.glsl's table, raycast_sample.glsl's volume and TF.
// Out: f_color, premultiplied RGBA (no blending; the fragment writes the final pixel).

#include "lookup.glsl"
#include "raycast_sample.glsl"
#if RAYCAST_MODE == 0 && INTEGRATION_EXACT
#include "raycast_exact.glsl"
#endif

uniform vec2 u_inv_viewport;     // 1 / (width, height)
uniform int u_perspective;       // 1 perspective, 0 parallel
uniform vec2 u_k;                // NDC -> eye scale (times depth in perspective)
uniform mat4 u_eye_to_index;
uniform mat4 u_eye_to_local;
uniform vec3 u_box_hi;           // (nx, ny, nz) - 1
uniform vec2 u_clip_range;       // camera near, far (eye depth)
uniform int u_use_clip_box;
uniform vec3 u_clip_lo;          // clip box, local coordinates
uniform vec3 u_clip_hi;
uniform int u_use_limits;
uniform sampler2D u_limits;      // RG: t_start, t_end per pixel (row 0 at the bottom)
uniform float u_step;            // world units
uniform int u_max_steps;
uniform float u_termination_tolerance;  // stop once 1 - alpha <= this (0: never early)
uniform int u_jitter;
uniform uint u_seed;
uniform float u_iso;
uniform float u_iso_opacity;
uniform vec4 u_shading;          // ambient, diffuse, specular, shininess
uniform mat3 u_gradient_to_local;  // inverse transpose of index -> world

out vec4 f_color;

#define ISO_REFINE_STEPS 8

// Parameter interval of o + t d inside [lo, hi] (slab method); empty if x >= y.
vec2 slab(vec3 o, vec3 d, vec3 lo, vec3 hi) {
    vec2 r = vec2(-3.0e38, 3.0e38);
    for (int a = 0; a < 3; ++a) {
        if (d[a] == 0.0) {
            if (o[a] < lo[a] || o[a] > hi[a]) return vec2(1.0, 0.0);
        } else {
            float ta = (lo[a] - o[a]) / d[a];
            float tb = (hi[a] - o[a]) / d[a];
            r.x = max(r.x, min(ta, tb));
            r.y = min(r.y, max(ta, tb));
        }
    }
    return r;
}

// PCG hash (Jarzynski & Olano 2020): a reproducible random number per pixel and seed.
uint pcg(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

float jitter01() {  // in (0, 1]
    uvec2 p = uvec2(gl_FragCoord.xy);
    uint h = pcg(p.x ^ pcg(p.y ^ pcg(u_seed)));
    return (float(h >> 8u) + 1.0) * (1.0 / 16777216.0);
}

void main() {
    vec2 ndc = 2.0 * gl_FragCoord.xy * u_inv_viewport - 1.0;
    vec3 o_eye = u_perspective == 1 ? vec3(0.0) : vec3(ndc * u_k, 0.0);
    vec3 d_eye = u_perspective == 1 ? vec3(ndc * u_k, -1.0) : vec3(0.0, 0.0, -1.0);
    vec3 o_idx = (u_eye_to_index * vec4(o_eye, 1.0)).xyz;
    vec3 d_idx = (u_eye_to_index * vec4(d_eye, 0.0)).xyz;

    vec2 range = slab(o_idx, d_idx, vec3(0.0), u_box_hi);
    range = vec2(max(range.x, u_clip_range.x), min(range.y, u_clip_range.y));
    if (u_use_clip_box == 1) {
        vec3 o_local = (u_eye_to_local * vec4(o_eye, 1.0)).xyz;
        vec3 d_local = (u_eye_to_local * vec4(d_eye, 0.0)).xyz;
        vec2 c = slab(o_local, d_local, u_clip_lo, u_clip_hi);
        range = vec2(max(range.x, c.x), min(range.y, c.y));
    }
    if (u_use_limits == 1) {
        vec2 lim = texelFetch(u_limits, ivec2(gl_FragCoord.xy), 0).rg;
        range = vec2(max(range.x, lim.x), min(range.y, lim.y));
    }
    f_color = vec4(0.0);
    if (!(range.y > range.x)) return;  // missed (also catches NaN)

    float world_per_t = length(d_eye);
    float dt = u_step / world_per_t;
    float len = range.y - range.x;
    // Offsets are measured from the entry point, which keeps them small and precise.
    vec3 p0_idx = o_idx + range.x * d_idx;
    float first = u_jitter == 1 ? jitter01() * dt : dt;

    // Offsets of the next voxel-index plane crossed along each axis, counted from the
    // entry (plane_first + m * plane_dt, not summed, so they do not drift); 3e38: never.
    vec3 plane_dt = vec3(3.0e38), plane_first = vec3(3.0e38);
    for (int a = 0; a < 3; ++a) {
        if (d_idx[a] != 0.0) {
            float next = d_idx[a] > 0.0 ? floor(p0_idx[a]) + 1.0 : ceil(p0_idx[a]) - 1.0;
            plane_dt[a] = 1.0 / abs(d_idx[a]);
            plane_first[a] = (next - p0_idx[a]) / d_idx[a];
        }
    }
    vec3 plane_m = vec3(0.0);
    float k_reg = 0.0;

    float off_prev = 0.0;
    float s_prev = scalar_at(p0_idx);
#if RAYCAST_MODE == 0
    vec4 acc = vec4(0.0);
#if INTEGRATION_EXACT
    TFInterval interval = tf_interval(s_prev);
    vec4 v_prev = tf_in(interval, s_prev);
    int i_prev = interval.i;
#endif
#elif RAYCAST_MODE == 1
    float s_max = s_prev;
#elif RAYCAST_MODE == 2
    float s_sum = 0.0;
#elif RAYCAST_MODE == 3
    bool hit = false;
    float off_a = 0.0, off_b = 0.0, s_a = 0.0, s_b = 0.0;
#endif
    for (int i = 0; i < u_max_steps; ++i) {
        float off_reg = first + k_reg * dt;
        vec3 off_plane = plane_first + plane_m * plane_dt;
        float off_next = min(min(off_reg, min(off_plane.x, min(off_plane.y, off_plane.z))), len);
        k_reg += off_reg <= off_next ? 1.0 : 0.0;
        plane_m += vec3(lessThanEqual(off_plane, vec3(off_next)));
        float s_next = scalar_at(p0_idx + off_next * d_idx);
#if RAYCAST_MODE == 0
#if INTEGRATION_EXACT
        if (!tf_holds(interval, s_next)) interval = tf_interval(s_next);
        vec4 v_next = tf_in(interval, s_next);
        int i_next = interval.i;
        vec4 piece = integrate_piece(s_prev, v_prev, i_prev, s_next, v_next, i_next, (off_next - off_prev) * world_per_t);
        v_prev = v_next;
        i_prev = i_next;
#else
        vec4 piece = lookup_segment(s_prev, s_next, (off_next - off_prev) * world_per_t);
#endif
        acc += (1.0 - acc.a) * piece;
        // Early ray termination as an error bound: colours are <= 1, so the rest of the ray
        // could add at most 1 - alpha to any channel (tetvr.reference.volume stops alike).
        if (1.0 - acc.a <= u_termination_tolerance) break;
#elif RAYCAST_MODE == 1
        s_max = max(s_max, s_next);
#elif RAYCAST_MODE == 2
        s_sum += 0.5 * (s_prev + s_next) * (off_next - off_prev);
#elif RAYCAST_MODE == 3
        if ((s_prev < u_iso) != (s_next < u_iso)) {
            hit = true;
            off_a = off_prev; s_a = s_prev; off_b = off_next; s_b = s_next;
            break;
        }
#endif
        if (off_next >= len) break;
        off_prev = off_next;
        s_prev = s_next;
    }

#if RAYCAST_MODE == 0
    f_color = acc;
#elif RAYCAST_MODE == 1
    f_color = classify(s_max);
#elif RAYCAST_MODE == 2
    f_color = classify(s_sum / len);
#elif RAYCAST_MODE == 3
    if (!hit) return;
    // Bisection on the trilinear field, then a linear interpolation (as the reference).
    bool below_a = s_a < u_iso;
    for (int k = 0; k < ISO_REFINE_STEPS; ++k) {
        float off_m = 0.5 * (off_a + off_b);
        float s_m = scalar_at(p0_idx + off_m * d_idx);
        if ((s_m < u_iso) == below_a) { off_a = off_m; s_a = s_m; } else { off_b = off_m; s_b = s_m; }
    }
    float ds = s_b - s_a;
    float f = ds != 0.0 ? clamp((u_iso - s_a) / ds, 0.0, 1.0) : 0.5;
    vec3 p_idx = p0_idx + (off_a + f * (off_b - off_a)) * d_idx;
    vec3 g_idx = 0.5 * vec3(scalar_at(p_idx + vec3(1, 0, 0)) - scalar_at(p_idx - vec3(1, 0, 0)),
                            scalar_at(p_idx + vec3(0, 1, 0)) - scalar_at(p_idx - vec3(0, 1, 0)),
                            scalar_at(p_idx + vec3(0, 0, 1)) - scalar_at(p_idx - vec3(0, 0, 1)));
    vec3 g = u_gradient_to_local * g_idx;
    vec3 view = -normalize(mat3(u_eye_to_local) * d_eye);
    float ndv = length(g) > 0.0 ? abs(dot(normalize(g), view)) : 0.0;
    vec3 c = color_at(u_iso);
    vec3 shaded = c * (u_shading.x + u_shading.y * ndv) + u_shading.z * pow(ndv, u_shading.w);
    f_color = vec4(clamp(shaded, 0.0, 1.0) * u_iso_opacity, u_iso_opacity);
#endif
}

#version 430
// classify.comp -- per-tet projective classification (Shirley & Tuchman 1990), computed on
// the GPU on every view change as in IPTINT (Marroquim et al. 2008), after the sort: one
// invocation per drawing position, which writes that tet's fan as finished vertices, so
// the draw is a pass-through vertex shader over a plain vertex buffer (tet.vert). llvmpipe
// shades vertices on one thread, where pulling the fans and points from storage buffers
// per vertex cost about a fifth of the frame's CPU time; a compute pass runs on every
// core. Frames got 11-20 % faster at 512x512 (105k-215k tets), with bit-identical images:
// the arithmetic is the same, only the stage moved.
//
// In:  Order (drawing position -> tet), Points, Tets (common.glsl), u_view, u_proj, u_near,
//      u_far, u_perspective, the table's u_lookup (lookup.glsl), u_offset, u_count.
// Out: Fans: FAN_VERTICES vertices per drawing position p - u_offset (the renderer binds the
//      range of this dispatch), each a FanVertex (common.glsl): NDC position, v_exact_tet,
//      v_segment. Vertex 0 is the thick vertex, 1..4 the silhouette in cyclic order (a
//      3-vertex silhouette repeats its first vertex in slot 4). Class 1: one vertex
//      projects inside the triangle of the other three; it is the thick vertex and the ray
//      through it leaves by the opposite face. Class 2: two opposite edges cross in
//      projection; the thick vertex is the crossing, on both edges. All 3D points on the
//      ray are found with perspective-correct weights, so the front and back points and
//      their scalars are exact.
//      v_segment = (1/w_f, t_f/w_f, 1/w_b, t_b/w_b), w the eye depth of the front and back
//      points and t their scalars as table texture coordinates (table_st in lookup.glsl,
//      affine in the scalar): both points lie on one plane per fan triangle, where 1/w and
//      t/w are affine in screen space, so interpolating them linearly and dividing is
//      perspective-correct (Kraus et al. 2004). Parallel projections (and
//      PERSPECTIVE_CORRECT 0) store (w_f, t_f, w_b, t_b), interpolated linearly.
//      ExactCount: incremented once per tet on the exact path, and the first and last
//      drawing positions (u_offset counted in) of such tets.

#include "common.glsl"
#include "lookup.glsl"

layout(local_size_x = 64) in;
layout(std430, binding = 2) writeonly buffer Fans { uvec4 fan_words[]; };  // 2 per FanVertex
layout(std430, binding = 3) readonly buffer Order { uint order[]; };
// How many fans take the exact path, and the first and last drawing positions among them:
// the renderer draws the fans between those with tet.frag's exact branch compiled in and
// the others without (present, the branch slows llvmpipe's fragment stage up to threefold
// even where no fragment takes it). The renderer sets first_exact to ~0u before a run.
layout(std430, binding = 4) buffer ExactCount { uint n_exact; uint first_exact; uint last_exact; };

uniform int u_offset;  // drawing position of this dispatch's first tet (fan vertex 0 of the range)
uniform int u_count;   // drawing positions in this draw: positions from u_count on are left alone
uniform vec2 u_half_px;  // NDC -> pixels: half the viewport size
// The exact path's rectangle, fanned from its centre: slot 0 the centre, 1..4 the corners,
// as weights of its lower and upper corner. A uniform (never set: its initial value), not a
// constant, so that mix() rounds as for any weight: with a constant 1 the compiler gives the
// upper corner exactly, 1 ulp away from a + 1 (b - a), and moves the rectangle's edge.
uniform vec2 u_rect_corner[FAN_VERTICES] = vec2[FAN_VERTICES](vec2(0.5), vec2(0.0, 0.0), vec2(1.0, 0.0),
                                                              vec2(1.0, 1.0), vec2(0.0, 1.0));

// The longest segment any ray can cut from the tet being classified: its longest edge
// (a tet's diameter), with a margin for rounding. tet.frag drops fragments beyond it.
float g_chord = 0.0;

// Fan vertex `slot` of the tet at local drawing position p.
void put(int p, int slot, vec2 ndc, int exact_tet, vec4 segment) {
    int v = 2 * (FAN_VERTICES * p + slot);
    fan_words[v] = uvec4(floatBitsToUint(ndc), uint(exact_tet), floatBitsToUint(g_chord));
    fan_words[v + 1] = floatBitsToUint(segment);
}

// A fan vertex at one point in eye space (a silhouette vertex: front = back) or on the
// thick vertex's ray (front and back points), with their scalars.
void put_point(int p, int slot, vec3 front_eye, float sf, vec3 back_eye, float sb) {
    vec4 clip = u_proj * vec4(front_eye, 1.0);
    float wf = -front_eye.z, wb = -back_eye.z;
    vec2 st = table_st(vec2(sf, sb));
    vec4 segment = vec4(wf, st.x, wb, st.y);
#if PERSPECTIVE_CORRECT
    if (u_perspective == 1) segment = vec4(1.0 / wf, st.x / wf, 1.0 / wb, st.y / wb);
#endif
    put(p, slot, clip.xy / clip.w, -1, segment);
}

float cross2(vec2 a, vec2 b) { return a.x * b.y - a.y * b.x; }

// The fan of a tet intersected exactly per fragment (tet.frag): the screen rectangle
// bounding its part beyond the near plane (its vertices there, and where its edges cross
// the plane), clamped to the viewport.
void exact_fan(int p, int t, vec2 p_ndc[4], vec3 p_eye[4]) {
    vec2 lo = vec2(1e30), hi = vec2(-1e30);
    for (int a = 0; a < 4; ++a) {
        float da = -p_eye[a].z - u_near;
        if (da >= 0.0) {
            lo = min(lo, p_ndc[a]); hi = max(hi, p_ndc[a]);
        }
        for (int b = a + 1; b < 4; ++b) {
            float db = -p_eye[b].z - u_near;
            if ((da < 0.0) != (db < 0.0)) {
                vec3 q = mix(p_eye[a], p_eye[b], da / (da - db));
                vec4 c = u_proj * vec4(q, 1.0);
                vec2 n = c.xy / c.w;
                lo = min(lo, n); hi = max(hi, n);
            }
        }
    }
    // One pixel of margin: the rectangle must cover every pixel centre inside the tet.
    vec2 pad = 1.0 / u_half_px;
    vec4 rect = vec4(clamp(lo - pad, -1.0, 1.0), clamp(hi + pad, -1.0, 1.0));
    for (int slot = 0; slot < FAN_VERTICES; ++slot) put(p, slot, mix(rect.xy, rect.zw, u_rect_corner[slot]), t, vec4(0.0));
    atomicAdd(n_exact, 1u);
    atomicMin(first_exact, uint(p + u_offset));
    atomicMax(last_exact, uint(p + u_offset));
}

void main() {
    int p = int(gl_GlobalInvocationID.x);  // drawing position, relative to u_offset
    if (p + u_offset >= u_count) return;
    int t = int(order[p + u_offset]);
    ivec4 id = mesh_tet(t);
    vec3 p_eye[4];
    vec2 p_ndc[4];
    float w[4];
    float s[4];
    bool behind = false;   // some vertex nearer than the near plane
    bool culled = true;    // every vertex nearer than the near plane
    bool beyond = true;    // every vertex farther than the far plane
    for (int k = 0; k < 4; ++k) {
        vec4 q = mesh_point(id[k]);
        p_eye[k] = (u_view * vec4(q.xyz, 1.0)).xyz;
        vec4 clip = u_proj * vec4(p_eye[k], 1.0);
        w[k] = clip.w;
        behind = behind || -p_eye[k].z < u_near;
        culled = culled && -p_eye[k].z < u_near;
        beyond = beyond && -p_eye[k].z > u_far;
        p_ndc[k] = clip.xy / clip.w;
        s[k] = q.w;
    }
    for (int a = 0; a < 3; ++a)
        for (int b = a + 1; b < 4; ++b) g_chord = max(g_chord, distance(p_eye[a], p_eye[b]));
    g_chord *= 1.0 + 1.0e-4;
    if (culled || beyond) {
        // Wholly outside the clipping range (FAN_CLIPPED): every vertex at one point
        // outside the view, nothing to draw.
        for (int slot = 0; slot < FAN_VERTICES; ++slot) put(p, slot, vec2(2.0), -1, vec4(0.0));
        return;
    }
    // A vertex projecting far outside the viewport (a tet beside the eye) makes triangles
    // the GL clips at its guard band, and the clipped vertices' screen-linear attributes
    // lose the segment (alpha off by up to 0.07 at 64x64 from a vertex at 1/30 of the view
    // depth). Such tets take the exact path of near-plane tets (FAN_NEAR): the rectangle is
    // then the bounding box of the vertices' projections, clamped to the viewport.
    bool huge = false;
    for (int k = 0; k < 4; ++k) huge = huge || any(greaterThan(abs(p_ndc[k]), vec2(EXACT_NDC)));
    if (behind || huge) {
        exact_fan(p, t, p_ndc, p_eye);
        return;
    }

    // Class 1: the vertex lying most inside the triangle of the other three.
    int best = 0;
    float best_score = -1e30;
    vec3 best_bary = vec3(0.0);
    for (int k = 0; k < 4; ++k) {
        int a = (k + 1) & 3, b = (k + 2) & 3, c = (k + 3) & 3;
        float area = cross2(p_ndc[b] - p_ndc[a], p_ndc[c] - p_ndc[a]);
        vec3 bary;
        if (abs(area) < 1e-30) {
            bary = vec3(-1.0);
        } else {
            bary.x = cross2(p_ndc[b] - p_ndc[k], p_ndc[c] - p_ndc[k]) / area;
            bary.y = cross2(p_ndc[c] - p_ndc[k], p_ndc[a] - p_ndc[k]) / area;
            bary.z = 1.0 - bary.x - bary.y;
        }
        float score = min(bary.x, min(bary.y, bary.z));
        if (score > best_score) { best_score = score; best = k; best_bary = bary; }
    }

    // Class 2: the pair of opposite edges whose projections cross most clearly.
    const ivec4 pairs[3] = ivec4[3](ivec4(0, 1, 2, 3), ivec4(0, 2, 1, 3), ivec4(0, 3, 1, 2));
    int best_pair = 0;
    float pair_score = -1e30;
    vec2 pair_param = vec2(0.5);
    for (int q = 0; q < 3; ++q) {
        ivec4 e = pairs[q];
        vec2 r = p_ndc[e.y] - p_ndc[e.x];
        vec2 d = p_ndc[e.w] - p_ndc[e.z];
        float den = cross2(r, d);
        if (abs(den) < 1e-30) continue;
        vec2 ac = p_ndc[e.z] - p_ndc[e.x];
        float ta = cross2(ac, d) / den;  // screen parameter on edge x->y
        float tc = cross2(ac, r) / den;  // screen parameter on edge z->w
        float score = min(min(ta, 1.0 - ta), min(tc, 1.0 - tc));
        if (score > pair_score) { pair_score = score; best_pair = q; pair_param = vec2(ta, tc); }
    }

    vec3 p0, p1;
    float s0, s1;
    ivec4 silhouette;  // local vertex numbers, in cyclic order
    if (best_score >= 0.0 || best_score >= pair_score) {
        // Class 1 (also the fallback for degenerate projections); FAN_TRIANGLE.
        int k = best;
        int a = (k + 1) & 3, b = (k + 2) & 3, c = (k + 3) & 3;
        vec3 bary = clamp(best_bary, 0.0, 1.0);
        bary /= max(bary.x + bary.y + bary.z, 1e-30);
        // Perspective-correct: screen-space weights divided by w, renormalised.
        vec3 pw = bary / vec3(w[a], w[b], w[c]);
        pw /= (pw.x + pw.y + pw.z);
        p0 = p_eye[k];
        s0 = s[k];
        p1 = pw.x * p_eye[a] + pw.y * p_eye[b] + pw.z * p_eye[c];
        s1 = pw.x * s[a] + pw.y * s[b] + pw.z * s[c];
        silhouette = ivec4(a, b, c, a);
    } else {
        ivec4 e = pairs[best_pair];
        vec2 ts = clamp(pair_param, 0.0, 1.0);
        // Screen parameter -> parameter along the 3D edge.
        float ua = ts.x * w[e.x] / ((1.0 - ts.x) * w[e.y] + ts.x * w[e.x]);
        float uc = ts.y * w[e.z] / ((1.0 - ts.y) * w[e.w] + ts.y * w[e.z]);
        p0 = mix(p_eye[e.x], p_eye[e.y], ua);
        s0 = mix(s[e.x], s[e.y], ua);
        p1 = mix(p_eye[e.z], p_eye[e.w], uc);
        s1 = mix(s[e.z], s[e.w], uc);
        // Silhouette in cyclic order: x, z, y, w (the crossing edges are its diagonals).
        silhouette = ivec4(e.x, e.z, e.y, e.w);
    }
    // The thick vertex: the nearer point (larger eye z) is the front.
    if (p0.z >= p1.z) put_point(p, 0, p0, s0, p1, s1);
    else put_point(p, 0, p1, s1, p0, s0);
    for (int slot = 1; slot < FAN_VERTICES; ++slot) {
        int k = silhouette[slot - 1];
        put_point(p, slot, p_eye[k], s[k], p_eye[k], s[k]);
    }
}

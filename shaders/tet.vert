#version 430
// tet.vert -- expands each tet's fan into 4 triangles (12 vertices, pulled by gl_VertexID;
// no vertex attributes). Triangle i is (thick vertex, silhouette[i], silhouette[i+1]);
// a 3-vertex silhouette leaves the 4th triangle degenerate.
//
// In:  Fans, Order (back-to-front tet ids), Points, u_view, u_proj, u_perspective.
// Out: noperspective v_segment = (1/w_f, s_f/w_f, 1/w_b, s_b/w_b), w the eye depth of the
//      front and back points: both lie on one plane per fan triangle, where 1/w and s/w
//      are affine in screen space, so interpolating them linearly and dividing is
//      perspective-correct (Kraus et al. 2004). The front and back points lie on the
//      pixel's ray, so their depths and scalars are all the fragment needs. Parallel
//      projections (and PERSPECTIVE_CORRECT 0) interpolate (w_f, s_f, w_b, s_b) linearly.

#include "common.glsl"

layout(std430, binding = 2) readonly buffer Fans { TetFan fans[]; };
layout(std430, binding = 3) readonly buffer Order { uint order[]; };

noperspective out vec4 v_segment;
flat out int v_exact_tet;  // >= 0: intersect the ray with this tet exactly in tet.frag

void main() {
    uint tet = order[gl_VertexID / 12];
    int corner = gl_VertexID % 12;
    int tri = corner / 3;
    int k = corner % 3;
    TetFan fan = fans[tet];
    int count = fan.ids.w < 0 ? 3 : 4;
    v_exact_tet = -1;
    if (fan.ids.w == -2) {
        gl_Position = vec4(2.0, 2.0, 0.0, 1.0);
        v_segment = vec4(0.0);
        return;
    }
    if (fan.ids.x < 0) {
        // Crosses the near plane: the screen rectangle classify.comp bounded it by
        // (corners 0-5; fan.front = (x_lo, y_lo, x_hi, y_hi) in NDC), the rest degenerate.
        const ivec2 quad[6] = ivec2[6](ivec2(0, 0), ivec2(1, 0), ivec2(1, 1), ivec2(0, 0), ivec2(1, 1), ivec2(0, 1));
        vec2 xy = corner < 6 ? mix(fan.front.xy, fan.front.zw, vec2(quad[min(corner, 5)])) : vec2(2.0);
        gl_Position = vec4(xy, 0.0, 1.0);
        v_exact_tet = -1 - fan.ids.x;
        v_segment = vec4(0.0);
        return;
    }
    if (tri >= count) {
        // Not drawn: every corner at one point outside the view gives no fragments.
        gl_Position = vec4(2.0, 2.0, 0.0, 1.0);
        v_segment = vec4(0.0);
        return;
    }
    vec3 front_eye, back_eye;
    float sf, sb;
    if (k == 0) {
        front_eye = fan.front.xyz; sf = fan.front.w;
        back_eye = fan.back.xyz;   sb = fan.back.w;
    } else {
        int v = fan.ids[(tri + k - 1) % count];
        vec4 p = points[v];
        front_eye = (u_view * vec4(p.xyz, 1.0)).xyz;
        back_eye = front_eye;
        sf = p.w; sb = p.w;
    }
    vec4 clip = u_proj * vec4(front_eye, 1.0);
    gl_Position = vec4(clip.xy / clip.w, 0.0, 1.0);
    float wf = -front_eye.z, wb = -back_eye.z;
#if PERSPECTIVE_CORRECT
    if (u_perspective == 1) {
        v_segment = vec4(1.0 / wf, sf / wf, 1.0 / wb, sb / wb);
        return;
    }
#endif
    v_segment = vec4(wf, sf, wb, sb);
}

#version 430
// tet.vert -- the vertices of each tet's fan, pulled by gl_VertexID (no vertex attributes).
//
// Indexed draw: the tet at drawing position p owns vertices 5p .. 5p + 4 -- 0 the thick
// vertex, 1..4 its silhouette in cyclic order -- and the index pattern (0,1,2) (0,2,3)
// (0,3,4) (0,4,1) fans them into 4 triangles. The draw's post-transform vertex cache
// (GPUs and llvmpipe alike) shades each of the 5 once instead of 12 corners: on llvmpipe
// this cut the tet draw by a fifth (10k tets) to a third (100k). A 3-vertex silhouette
// repeats its first vertex in slot 4, which leaves the 4th triangle degenerate.
//
// In:  Fans, Order (back-to-front tet ids), Points, u_view, u_proj, u_perspective, u_first.
// Out: noperspective v_segment = (1/w_f, t_f/w_f, 1/w_b, t_b/w_b), w the eye depth of the
//      front and back points and t their scalars as table texture coordinates (table_st
//      in lookup.glsl, affine in the scalar): both points lie on one plane per fan
//      triangle, where 1/w and t/w are affine in screen space, so interpolating them
//      linearly and dividing is perspective-correct (Kraus et al. 2004). The front and
//      back points lie on the pixel's ray, so their depths and scalars are all the
//      fragment needs. Parallel projections (and PERSPECTIVE_CORRECT 0) interpolate
//      (w_f, t_f, w_b, t_b) linearly.

#include "common.glsl"
#include "lookup.glsl"

layout(std430, binding = 2) readonly buffer Fans { TetFan fans[]; };
layout(std430, binding = 3) readonly buffer Order { uint order[]; };

uniform int u_first;  // drawing position of this draw call's first tet (index value 0)
// NDC -> the pixel's ray: eye-space x, y per unit depth in perspective, eye-space x, y in
// parallel projection (1 / the projection's x and y scale).
uniform vec2 u_ray_scale;

noperspective out vec4 v_segment;
noperspective out vec2 v_ray;  // the ray of the fragment's pixel (see u_ray_scale): affine in
                               // screen space, so interpolating it is exact
flat out int v_exact_tet;  // >= 0: intersect the ray with this tet exactly in tet.frag

void emit(vec2 ndc) {
    gl_Position = vec4(ndc, 0.0, 1.0);
    v_ray = ndc * u_ray_scale;
}

void main() {
    uint tet = order[u_first + gl_VertexID / 5];
    int slot = gl_VertexID % 5;
    TetFan fan = fans[tet];
    v_exact_tet = -1;
    v_segment = vec4(0.0);
    if (fan.ids.w == FAN_CLIPPED) {
        // Wholly outside the clipping range: every vertex at one point outside the view.
        emit(vec2(2.0));
        return;
    }
    if (fan.ids.w == FAN_NEAR) {
        // Crosses the near plane: the screen rectangle classify.comp bounded it by
        // (fan.front = (x_lo, y_lo, x_hi, y_hi) in NDC), fanned from its centre.
        const vec2 corner[5] = vec2[5](vec2(0.5), vec2(0.0, 0.0), vec2(1.0, 0.0), vec2(1.0, 1.0), vec2(0.0, 1.0));
        emit(mix(fan.front.xy, fan.front.zw, corner[slot]));
        v_exact_tet = -1 - fan.ids.x;
        return;
    }
    vec3 front_eye, back_eye;
    float sf, sb;
    if (slot == 0) {
        front_eye = fan.front.xyz; sf = fan.front.w;
        back_eye = fan.back.xyz;   sb = fan.back.w;
    } else {
        vec4 p = points[fan.ids[slot == 4 && fan.ids.w == FAN_TRIANGLE ? 0 : slot - 1]];
        front_eye = (u_view * vec4(p.xyz, 1.0)).xyz;
        back_eye = front_eye;
        sf = p.w; sb = p.w;
    }
    vec4 clip = u_proj * vec4(front_eye, 1.0);
    emit(clip.xy / clip.w);
    float wf = -front_eye.z, wb = -back_eye.z;
    vec2 st = table_st(vec2(sf, sb));
#if PERSPECTIVE_CORRECT
    if (u_perspective == 1) {
        v_segment = vec4(1.0 / wf, st.x / wf, 1.0 / wb, st.y / wb);
        return;
    }
#endif
    v_segment = vec4(wf, st.x, wb, st.y);
}

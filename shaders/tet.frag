#version 430
// tet.frag -- integrates the ray segment through one tet at one pixel by a lookup in the
// 3D pre-integration table (Kraus et al. 2004), and emits premultiplied RGBA for
// back-to-front "over" blending (ONE, ONE_MINUS_SRC_ALPHA) into an RGBA32F target.
//
// In:  v_segment, v_ray (or their values computed here: fan_varyings.glsl), v_exact_tet (see
//      tet.vert); u_near, u_far.
// Out: f_color, premultiplied.
// The segment is clipped to the near and far planes here, per fragment, so tets that
// cross them are cut rather than dropped; with clip planes or a ray limit (window.glsl)
// to the pixel's window instead. Defines (one program per combination):
// PERSPECTIVE, PERSPECTIVE_CORRECT, CLIP_RANGE (some point lies outside the clipping
// range, or a window is given), NEAR_CROSSING (some point lies before the near plane),
// CLIP_PLANES, RAY_LIMIT (window.glsl). llvmpipe pays for a runtime branch even when no
// fragment takes it, so view-wide cases are compiled in.

#include "common.glsl"
#include "lookup.glsl"
#include "exact.glsl"
#include "window.glsl"

noperspective in vec4 v_segment;
noperspective in vec2 v_ray;  // eye-space x/depth, y/depth of the pixel's ray in perspective,
                              // its eye-space x, y in parallel projection
flat in int v_exact_tet;
flat in float v_chord;  // the longest segment the tet holds (its longest edge)

#include "fan_varyings.glsl"

out vec4 f_color;

// The ray of this pixel through one tet, exactly (exact.glsl).
void exact_segment(int tet, vec2 ray, vec2 win) {
    vec4 seg = exact_ray_segment(tet, ray, win.x, win.y);  // (t0, t1, sf, sb)
    if (seg.y <= seg.x) discard;
#if PERSPECTIVE
    float per_depth = length(vec3(ray, 1.0));
#else
    const float per_depth = 1.0;
#endif
    f_color = lookup_segment(seg.z, seg.w, (seg.y - seg.x) * per_depth);
}

void main() {
    vec2 ray;
    vec4 segment;
    fan_varyings(ray, segment);
#if RAY_WINDOW
    vec2 win = ray_window(ray, ivec2(gl_FragCoord.xy), u_near, u_far);
    if (win.y <= win.x) discard;
#else
    vec2 win = vec2(u_near, u_far);
#endif
#if NEAR_CROSSING
    // Compiled in only for views where some point lies before the near plane: the
    // extra code halves the speed of llvmpipe's fragment stage even when not taken.
    if (v_exact_tet >= 0) {
        exact_segment(v_exact_tet, ray, win);
        return;
    }
#endif
    // Front and back depth (along the view axis) and scalar, as a table texture
    // coordinate (tet.vert), of this pixel's segment.
    float zf = segment.x, sf = segment.y, zb = segment.z, sb = segment.w;
    // World length per unit of depth along this pixel's ray.
#if PERSPECTIVE
#if PERSPECTIVE_CORRECT
    zf = 1.0 / zf; sf *= zf; zb = 1.0 / zb; sb *= zb;
#endif
    float per_depth = sqrt(1.0 + dot(ray, ray));
#else
    const float per_depth = 1.0;
#endif
#if CLIP_RANGE
    // Compiled in only for views where some point lies outside the clipping range, or
    // with a window (window.glsl).
    if (zb <= win.x || zf >= win.y) discard;
    if (zf < win.x) {
        sf = mix(sf, sb, (win.x - zf) / (zb - zf));
        zf = win.x;
    }
    if (zb > win.y) {
        sb = mix(sf, sb, (win.y - zf) / (zb - zf));
        zb = win.y;
    }
#endif
    // Rounding can order a flat segment's ends the wrong way: its length is 0, not negative.
    float d = max(zb - zf, 0.0) * per_depth;
    // A fan triangle of almost zero area (a face edge-on through the eye, an edge along the
    // ray) may be rasterised at a pixel whose centre lies just outside it, where its
    // attributes extrapolate: a segment longer than the tet holds, or 1/w through zero and
    // not finite. Such a fragment is outside the tet, and is dropped.
    if (!(d <= v_chord) || isnan(sf + sb)) discard;
    f_color = lookup_table(vec2(sf, sb), d);
}

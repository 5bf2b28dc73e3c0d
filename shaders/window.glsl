// window.glsl -- the part of a pixel's ray that is kept: the clipping range, cut by clip
// planes (tetvr/core/clip.py) and by a per-pixel limit (an opaque surface's depth).
//
// Coordinate space: eye space; t is eye depth. A perspective ray is x = t (r, -1), a
// parallel one x = (r, 0) + t (0, 0, -1), r as tet.vert's v_ray.
// Defines: PERSPECTIVE; CLIP_PLANES k > 0 (u_clip: k planes n . x + w >= 0 kept, eye
// space); RAY_LIMIT 1 (u_limit: R32F, per pixel the eye depth where rays stop, 3e38 none).
// Same arithmetic as tetvr.core.clip.ray_window.

#ifndef CLIP_PLANES
#define CLIP_PLANES 0
#endif
#ifndef RAY_LIMIT
#define RAY_LIMIT 0
#endif
#define RAY_WINDOW (CLIP_PLANES > 0 || RAY_LIMIT)

#if CLIP_PLANES > 0
uniform vec4 u_clip[CLIP_PLANES];
#endif
#if RAY_LIMIT
uniform sampler2D u_limit;
#endif

// (lo, hi): the eye depths between which the ray through window pixel px with eye ray r is
// kept; lo >= hi where none of it is.
vec2 ray_window(vec2 r, ivec2 px, float near, float far) {
    vec2 win = vec2(near, far);
#if CLIP_PLANES > 0
    for (int k = 0; k < CLIP_PLANES; ++k) {
        vec4 p = u_clip[k];
#if PERSPECTIVE
        float a = p.w, b = dot(p.xy, r) - p.z;
#else
        float a = dot(p.xy, r) + p.w, b = -p.z;
#endif
        if (b > 0.0) win.x = max(win.x, -a / b);
        else if (b < 0.0) win.y = min(win.y, -a / b);
        else if (a < 0.0) win.y = -3.0e38;
    }
#endif
#if RAY_LIMIT
    win.y = min(win.y, texelFetch(u_limit, px, 0).r);
#endif
    return win;
}

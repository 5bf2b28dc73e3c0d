#version 430
// surface.frag -- the pixel's ray against one triangle of the opaque surfaces, exactly
// (Moller-Trumbore, as tetvr.core.surface.moller_trumbore), lit by a headlight.
//
// In:  flat v_tri; SurfaceTriangles (surface.vert); u_view (obj -> eye), u_ray_scale,
//      u_viewport, u_near, u_far.
// Out: f_color: the shaded colour, alpha 1; f_depth: the hit's eye depth t (the far end of
//      the tets' ray window, window.glsl's u_limit); gl_FragDepth: t mapped to [0, 1]
//      across the clipping range, so the depth test keeps the nearest hit.
// Defines: PERSPECTIVE.

layout(std430, binding = 6) readonly buffer SurfaceTriangles { vec4 tri_data[]; };

uniform mat4 u_view;
uniform vec2 u_ray_scale;
uniform vec2 u_viewport;
uniform float u_near;
uniform float u_far;

flat in int v_tri;

layout(location = 0) out vec4 f_color;
layout(location = 1) out float f_depth;

void main() {
    vec2 r = (gl_FragCoord.xy / u_viewport * 2.0 - 1.0) * u_ray_scale;
#if PERSPECTIVE
    vec3 o = vec3(0.0), d = vec3(r, -1.0);
#else
    vec3 o = vec3(r, 0.0), d = vec3(0.0, 0.0, -1.0);
#endif
    int base = 6 * v_tri;
    vec4 a = tri_data[base], b = tri_data[base + 1], c = tri_data[base + 2];
    vec3 p0 = (u_view * vec4(a.xyz, 1.0)).xyz;
    vec3 e1 = (u_view * vec4(b.xyz, 1.0)).xyz - p0;
    vec3 e2 = (u_view * vec4(c.xyz, 1.0)).xyz - p0;
    vec3 q = cross(d, e2);
    float det = dot(q, e1);
    if (det == 0.0) discard;  // the ray lies in the triangle's plane
    float inv = 1.0 / det;
    vec3 s = o - p0;
    float b1 = dot(s, q) * inv;
    vec3 rr = cross(s, e1);
    float b2 = dot(rr, d) * inv;
    float t = dot(rr, e2) * inv;
    float b0 = 1.0 - b1 - b2;
    if (b1 < 0.0 || b2 < 0.0 || b0 < 0.0 || !(t >= u_near && t <= u_far)) discard;
    vec4 n0 = tri_data[base + 3], n1 = tri_data[base + 4], n2 = tri_data[base + 5];
    vec3 n = mat3(u_view) * (b0 * n0.xyz + b1 * n1.xyz + b2 * n2.xyz);
    float ndv = abs(dot(n, d)) / max(length(n) * length(d), 1.0e-30);
    float ambient = b.w;
    f_color = vec4(vec3(n0.w, n1.w, n2.w) * (ambient + (1.0 - ambient) * ndv), 1.0);
    f_depth = t;
    gl_FragDepth = clamp((t - u_near) / (u_far - u_near), 0.0, 1.0);
}

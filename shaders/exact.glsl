// exact.glsl -- one pixel's ray through one tet, intersected exactly per fragment.
//
// For the tets whose fan cannot be trusted (classify.comp): those crossing the near plane,
// those with a vertex projecting far outside the viewport, and those with a fan triangle
// too thin for the rasteriser. Needs common.glsl (mesh_point, mesh_tet, u_view, u_near,
// u_far) and the PERSPECTIVE define.
// In:  the tet id, the pixel's ray (tet.vert's v_ray: eye x, y per unit depth in
//      perspective, eye x, y in parallel projection).
// Out: (t0, t1, s0, s1): the eye depths where the ray enters and leaves the tet, cut to
//      the window (near, far) (the clipping range, or window.glsl's ray_window), and the
//      scalars there; t1 <= t0 where the ray misses it.

vec4 exact_ray_segment(int tet, vec2 ray, float near, float far) {
    ivec4 id = mesh_tet(tet);
    vec3 p[4];
    float s[4];
    for (int k = 0; k < 4; ++k) {
        vec4 q = mesh_point(id[k]);
        p[k] = (u_view * vec4(q.xyz, 1.0)).xyz;
        s[k] = q.w;
    }
#if PERSPECTIVE
    vec3 o = vec3(0.0), d = vec3(ray, -1.0);
#else
    vec3 o = vec3(ray, 0.0), d = vec3(0.0, 0.0, -1.0);
#endif
    float t0 = near, t1 = far;
    for (int k = 0; k < 4; ++k) {
        vec3 a = p[(k + 1) & 3], b = p[(k + 2) & 3], c = p[(k + 3) & 3];
        vec3 n = cross(b - a, c - a);
        if (dot(n, p[k] - a) > 0.0) n = -n;  // outward
        float den = dot(n, d), num = dot(n, a - o);
        if (den < 0.0) t0 = max(t0, num / den);
        else if (den > 0.0) t1 = min(t1, num / den);
        else if (num < 0.0) return vec4(1.0, 0.0, 0.0, 0.0);  // parallel to the face, outside
    }
    if (t1 <= t0) return vec4(t0, t0, 0.0, 0.0);
    mat3 e = mat3(p[1] - p[0], p[2] - p[0], p[3] - p[0]);
    mat3 inv = inverse(e);
    vec3 ds = vec3(s[1] - s[0], s[2] - s[0], s[3] - s[0]);
    float sf = s[0] + dot(inv * (o + t0 * d - p[0]), ds);
    float sb = s[0] + dot(inv * (o + t1 * d - p[0]), ds);
    return vec4(t0, t1, sf, sb);
}

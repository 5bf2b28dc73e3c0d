#version 430
// surface.vert -- a screen rectangle around each triangle of the opaque surfaces, for
// surface.frag to intersect its pixels' rays with the triangle exactly.
//
// Non-indexed draw, 6 vertices per triangle (two triangles of its rectangle): the
// triangle's projected bounding box grown by one pixel, so that every pixel whose centre
// the triangle covers gets a fragment whatever the rasteriser's sampling rules. A
// triangle reaching nearer than the near plane in perspective (its projection unbounded)
// gets the whole viewport; one wholly before the near plane or beyond the far plane
// gets nothing.
//
// In:  SurfaceTriangles (binding 6): per triangle 6 vec4, (p0, p1, p2) obj-space positions
//      (p1.w the ambient share), (n0, n1, n2) world-space shading normals (w the RGB colour).
//      u_view (obj -> eye), u_proj, u_viewport, u_near, u_far.
// Out: flat v_tri, the triangle.
// Defines: PERSPECTIVE.

layout(std430, binding = 6) readonly buffer SurfaceTriangles { vec4 tri_data[]; };

uniform mat4 u_view;
uniform mat4 u_proj;
uniform vec2 u_viewport;
uniform float u_near;
uniform float u_far;

flat out int v_tri;

void main() {
    int tri = gl_VertexID / 6;
    int k = gl_VertexID - 6 * tri;
    v_tri = tri;
    vec2 lo = vec2(3.0e38), hi = vec2(-3.0e38);
    int before = 0, beyond = 0;
    for (int i = 0; i < 3; ++i) {
        vec3 p = (u_view * vec4(tri_data[6 * tri + i].xyz, 1.0)).xyz;
        before += int(-p.z < u_near);
        beyond += int(-p.z > u_far);
        vec4 c = u_proj * vec4(p, 1.0);
        vec2 ndc = c.xy / max(c.w, 1.0e-30);
        lo = min(lo, ndc);
        hi = max(hi, ndc);
    }
    if (before == 3 || beyond == 3) {
        gl_Position = vec4(2.0, 2.0, 0.0, 1.0);  // every corner at one point: no area
        return;
    }
#if PERSPECTIVE
    if (before > 0) {
        lo = vec2(-1.0);
        hi = vec2(1.0);
    }
#endif
    vec2 px = 2.0 / u_viewport;
    lo = clamp(lo - px, -1.0 - px, 1.0 + px);
    hi = clamp(hi + px, -1.0 - px, 1.0 + px);
    // Corners (lo.x, lo.y) (hi.x, lo.y) (hi.x, hi.y) | (lo.x, lo.y) (hi.x, hi.y) (lo.x, hi.y).
    bool right = k == 1 || k == 2 || k == 4;
    bool top = k == 2 || k == 4 || k == 5;
    gl_Position = vec4(right ? hi.x : lo.x, top ? hi.y : lo.y, 0.0, 1.0);
}

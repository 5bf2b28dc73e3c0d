#version 430
// tet.vert -- passes through the fan vertices classify.comp wrote, in drawing order.
//
// Indexed draw: the tet at drawing position p owns vertices 5p .. 5p + 4 -- 0 the thick
// vertex, 1..4 its silhouette in cyclic order -- and the index pattern (0,1,2) (0,2,3)
// (0,3,4) (0,4,1) fans them into 4 triangles. The draw's post-transform vertex cache
// (GPUs and llvmpipe alike) shades each of the 5 once instead of 12 corners. A 3-vertex
// silhouette repeats its first vertex in slot 4, which leaves the 4th triangle degenerate.
// All the per-vertex arithmetic is done in classify.comp, which runs on every core; this
// stage runs on llvmpipe's single draw thread, where pulling the fans and points from
// storage buffers here cost 19-29 % of the process's CPU time (issue 17).
//
// In:  a FanVertex (common.glsl) as vertex attributes: in_ndc, in_exact, in_segment;
//      u_ray_scale.
// Out: gl_Position = (in_ndc, 0, 1);
//      noperspective v_segment (see classify.comp): front and back depth and scalar
//      (table texture coordinate) of the thick vertex's ray, or of a silhouette vertex;
//      noperspective v_ray: the ray of the fragment's pixel (see u_ray_scale): affine in
//      screen space, so interpolating it is exact;
//      flat v_exact_tet: >= 0, intersect the ray with this tet exactly in tet.frag;
//      flat v_chord: the longest segment the tet holds.

in vec2 in_ndc;
in int in_exact;
in float in_chord;
in vec4 in_segment;

// NDC -> the pixel's ray: eye-space x, y per unit depth in perspective, eye-space x, y in
// parallel projection (1 / the projection's x and y scale).
uniform vec2 u_ray_scale;

noperspective out vec4 v_segment;
noperspective out vec2 v_ray;
flat out int v_exact_tet;
flat out float v_chord;

void main() {
    gl_Position = vec4(in_ndc, 0.0, 1.0);
    v_ray = in_ndc * u_ray_scale;
    v_segment = in_segment;
    v_exact_tet = in_exact;
    v_chord = in_chord;
}

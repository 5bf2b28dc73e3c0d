#version 430
// floor.frag -- the trivial shader of the fill-rate floor benchmark: same triangles, same
// blending, a constant colour instead of the table lookup.
noperspective in vec4 v_segment;
flat in int v_exact_tet;
out vec4 f_color;
void main() { f_color = vec4(0.001, 0.001, 0.001, 0.001); }

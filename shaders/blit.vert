#version 330
// blit.vert -- the desktop viewer's full-window quad (tetvr view).
// In:  in_pos, NDC corners of the quad.  Out: v_uv in [0, 1]^2.
in vec2 in_pos;
out vec2 v_uv;
void main() {
    v_uv = in_pos * 0.5 + 0.5;
    gl_Position = vec4(in_pos, 0.0, 1.0);
}

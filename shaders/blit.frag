#version 330
// blit.frag -- shows the rendered frame (already composited over the background, RGB, row 0
// at the top, hence the flip) in the desktop viewer's window.
uniform sampler2D u_image;
in vec2 v_uv;
out vec4 f_color;
void main() {
    f_color = vec4(texture(u_image, vec2(v_uv.x, 1.0 - v_uv.y)).rgb, 1.0);
}

#version 430
// march_mark.frag -- between two march passes that take their entries from the list (LIST
// in march.frag): copies the last pass's colour, state and next entry to the targets the
// next pass writes, and marks with depth 0 the pixels whose ray goes on (STATUS_REENTER),
// 1 the rest. The next march pass, drawn at depth 1 with the test "greater", then runs only
// where a ray goes on, and keeps these copies everywhere else.

#include "march_common.glsl"

uniform sampler2D u_color_in;
uniform sampler2D u_state_in;
uniform isampler2D u_last_in;

layout(location = 0) out vec4 f_color;
layout(location = 1) out vec2 f_state;
layout(location = 2) out int f_last;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    f_color = texelFetch(u_color_in, px, 0);
    f_state = texelFetch(u_state_in, px, 0).xy;
    f_last = texelFetch(u_last_in, px, 0).r;
    gl_FragDepth = f_state.y == STATUS_REENTER ? 0.0 : 1.0;
}

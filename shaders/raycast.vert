#version 430
// raycast.vert -- one triangle that covers the whole viewport; the ray caster's work is
// all in raycast.frag, one ray per fragment.
//
// In:  gl_VertexID 0..2 (no vertex attributes, an empty vertex array).
// Out: gl_Position in clip space: (-1,-1), (3,-1), (-1,3), which covers [-1,1]^2; at depth
//      1 (the far end of the depth range) with AT_FAR 1, else 0.5.

void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
#if defined(AT_FAR) && AT_FAR
    gl_Position = vec4(p, 1.0, 1.0);
#else
    gl_Position = vec4(p, 0.0, 1.0);
#endif
}

#version 430
// march_entry.vert -- where rays enter the mesh: its boundary faces (NEAR_CELLS 0), or the
// screen rectangles of the cells the near plane cuts (NEAR_CELLS 1; tetvr.marching).
//
// In:  in_pos: a boundary face corner (obj) or a rectangle corner (NDC); in_id: the face's
//      slot 4 * tet + k, or the cut tet's id.
// Out: v_id (flat), gl_Position.

uniform mat4 u_view;   // obj -> eye
uniform mat4 u_proj;   // eye -> clip

#if NEAR_CELLS
in vec2 in_pos;
#else
in vec3 in_pos;
#endif
in int in_id;
flat out int v_id;

void main() {
    v_id = in_id;
#if NEAR_CELLS
    gl_Position = vec4(in_pos, 0.0, 1.0);
#else
    gl_Position = u_proj * (u_view * vec4(in_pos, 1.0));
#endif
}

#version 430
// march_entry.vert -- where rays enter the mesh: its boundary faces (NEAR_CELLS 0), the
// screen rectangles of the cells the near plane cuts (NEAR_CELLS 1), or those of the boundary
// faces next to faces seen edge-on (RIM 1; tetvr.mesh.records.rim_faces).
//
// In:  in_pos: a boundary face corner (obj) or a rectangle corner (NDC); in_id: the face's
//      slot 4 * tet + k, or the cut tet's id; RIM 1: in_c0..2, the face's corners (obj, float64).
// Out: v_id (flat), gl_Position; RIM 1: v_c0..2 (flat).

uniform mat4 u_view;   // obj -> eye
uniform mat4 u_proj;   // eye -> clip

#if NEAR_CELLS || RIM
in vec2 in_pos;
#else
in vec3 in_pos;
#endif
in int in_id;
flat out int v_id;
#if RIM
in dvec3 in_c0;
in dvec3 in_c1;
in dvec3 in_c2;
flat out dvec3 v_c0;
flat out dvec3 v_c1;
flat out dvec3 v_c2;
#endif

void main() {
    v_id = in_id;
#if RIM
    v_c0 = in_c0;
    v_c1 = in_c1;
    v_c2 = in_c2;
#endif
#if NEAR_CELLS || RIM
    gl_Position = vec4(in_pos, 0.0, 1.0);
#else
    gl_Position = u_proj * (u_view * vec4(in_pos, 1.0));
#endif
}

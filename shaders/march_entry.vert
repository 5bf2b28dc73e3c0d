#version 430
// march_entry.vert -- where rays enter the mesh: its boundary faces (NEAR_CELLS 0), or the
// screen rectangles of the cells the near plane cuts (NEAR_CELLS 1; tetvr.marching).
//
// In:  in_pos: a boundary face corner (obj) or a rectangle corner (NDC); in_next, in_prev:
//      the face's other corners in order (obj); in_id: the face's slot 4 * tet + k, or the
//      cut tet's id.
// Out: v_id (flat), gl_Position.
// A face is drawn grown by DILATE_PX on every side (its corners moved out along their
// bisectors, each edge parallel to itself): the rasteriser snaps corners to 1/256 pixel,
// so without it a pixel whose centre lies inside the face by less than that may get no
// fragment (a ray grazing a corner of the mesh would miss it). The fragment stage decides
// exactly, in float32, whether the ray meets the face (march_entry.frag).

uniform mat4 u_view;   // obj -> eye
uniform mat4 u_proj;   // eye -> clip
uniform vec2 u_viewport;

#define DILATE_PX (1.0 / 64.0)
#define MAX_SHIFT_PX 2.0   // a corner's shift at most (very acute corners grow less)

#if NEAR_CELLS
in vec2 in_pos;
#else
in vec3 in_pos;
in vec3 in_next;
in vec3 in_prev;
#endif
in int in_id;
flat out int v_id;

#if !NEAR_CELLS
float cross2(vec2 a, vec2 b) { return a.x * b.y - a.y * b.x; }
#endif

void main() {
    v_id = in_id;
#if NEAR_CELLS
    gl_Position = vec4(in_pos, 0.0, 1.0);
#else
    vec4 c0 = u_proj * (u_view * vec4(in_pos, 1.0));
    vec4 c1 = u_proj * (u_view * vec4(in_next, 1.0));
    vec4 c2 = u_proj * (u_view * vec4(in_prev, 1.0));
    gl_Position = c0;
    if (c0.w > 0.0 && c1.w > 0.0 && c2.w > 0.0) {  // else GL clips it as it is
        vec2 half_px = 0.5 * u_viewport;
        vec2 p0 = c0.xy / c0.w * half_px, p1 = c1.xy / c1.w * half_px, p2 = c2.xy / c2.w * half_px;
        float area2 = cross2(p1 - p0, p2 - p0);
        if (abs(area2) > 1.0e-12) {  // a face seen exactly edge-on covers no pixel centre
            float s = sign(area2);
            vec2 e_next = normalize(p1 - p0), e_prev = normalize(p0 - p2);
            // Outward unit normals of the two edges at this corner; the corner moves to
            // where the edges moved out by DILATE_PX meet.
            vec2 n_next = s * vec2(e_next.y, -e_next.x), n_prev = s * vec2(e_prev.y, -e_prev.x);
            vec2 shift = (n_next + n_prev) * (DILATE_PX / max(1.0 + dot(n_next, n_prev), 1.0e-6));
            float len = length(shift);
            if (len > MAX_SHIFT_PX) shift *= MAX_SHIFT_PX / len;
            gl_Position.xy += shift / half_px * c0.w;
        }
    }
#endif
}

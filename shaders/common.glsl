// common.glsl -- shared declarations for the projected-tetrahedra pipeline.
//
// Coordinate spaces: *_obj  mesh coordinates relative to the mesh centre (float32-safe),
//                    *_eye  camera at the origin looking down -z (world units, rigid),
//                    *_ndc  normalized device coordinates.
// Mesh buffers (uploaded once per mesh):
//   binding 0  Points  vec4(xyz_obj, scalar)
//   binding 1  Tets    ivec4 vertex ids
// Per view (written by classify.comp, read by tet.vert):
//   binding 2  Fans    one TetFan per tet
//   binding 3  Order   uint tet ids, back to front

// TetFan.ids.w markers: a vertex id (>= 0) for a 4-vertex silhouette, else one of these.
// They are distinct from each other and from every vertex id, whatever the tet's index.
#define FAN_TRIANGLE (-1)  // 3-vertex silhouette (ids.xyz)
#define FAN_CLIPPED (-2)   // wholly outside the clipping range: nothing to draw
#define FAN_NEAR (-3)      // crosses the near plane (or the eye plane), where its projection is
                           // unbounded: drawn as the screen rectangle bounding its part beyond
                           // the near plane (front = (x_lo, y_lo, x_hi, y_hi) in NDC), whose
                           // fragments intersect their ray with the tet exactly; ids.x = -1 - tet

// Tets with a vertex projecting beyond this NDC bound take the exact per-fragment path
// (classify.comp); tetvr.gl.renderer.EXACT_NDC is the same bound for the CPU's check.
#define EXACT_NDC 8.0

struct TetFan {
    ivec4 ids;     // silhouette vertices in cyclic order, ids.w a vertex id or a FAN_* marker
    vec4 front;    // thick vertex, front point: xyz_eye, scalar
    vec4 back;     // thick vertex, back point:  xyz_eye, scalar
};

layout(std430, binding = 0) readonly buffer Points { vec4 points[]; };
layout(std430, binding = 1) readonly buffer Tets { ivec4 tets[]; };

uniform mat4 u_view;        // obj -> eye
uniform mat4 u_proj;        // eye -> clip
uniform int u_perspective;  // 1: perspective projection, 0: parallel
uniform float u_near;       // clipping range, eye depth
uniform float u_far;

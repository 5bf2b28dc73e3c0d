// common.glsl -- shared declarations for the projected-tetrahedra pipeline.
//
// Coordinate spaces: *_obj  mesh coordinates relative to the mesh centre (float32-safe),
//                    *_eye  camera at the origin looking down -z (world units, rigid),
//                    *_ndc  normalized device coordinates.
// Mesh buffers (uploaded once per mesh; a chunked mesh's Tets per chunk, in drawing order):
//   binding 0  Points  vec4(xyz_obj, scalar)
//   binding 1  Tets    ivec4 vertex ids
// Per view:
//   binding 2  Fans    written by classify.comp, drawn as a plain vertex buffer (tet.vert):
//                      FAN_VERTICES FanVertex per tet, in drawing order
//   binding 3  Order   uint tet ids, back to front (drawing position -> tet)
//   binding 4  ExactCount  how many tets take the exact path, the first and last of them

// How classify.comp treats a tet (its fan's kind).
#define FAN_TRIANGLE (-1)  // 3-vertex silhouette: slot 4 repeats slot 1 (a degenerate 4th triangle)
#define FAN_CLIPPED (-2)   // wholly outside the clipping range: nothing to draw (every vertex
                           // at one point outside the view)
#define FAN_NEAR (-3)      // crosses the near plane (or the eye plane), where its projection is
                           // unbounded: drawn as the screen rectangle bounding its part beyond
                           // the near plane, fanned from its centre, whose fragments intersect
                           // their ray with the tet exactly (v_exact_tet = the tet)

// Tets with a vertex projecting beyond this NDC bound take the exact per-fragment path
// (classify.comp), which counts them so that the renderer compiles that path in only when needed.
#define EXACT_NDC 8.0

// One fan vertex (32 bytes, two uvec4; tetvr.gl.renderer._FAN_VERTEX_BYTES, _FAN_ATTRIBUTES):
//   uvec4(floatBitsToUint(ndc.xy), uint(exact_tet), floatBitsToUint(chord)), floatBitsToUint(segment)
// with exact_tet >= 0 for the exact path, else -1, chord the longest segment the tet holds
// (tet.vert's v_chord), and segment tet.vert's v_segment.
#define FAN_VERTICES 5

layout(std430, binding = 0) readonly buffer Points { vec4 points[]; };
layout(std430, binding = 1) readonly buffer Tets { ivec4 tets[]; };
// The mesh's reads, in one place (classify.comp, exact.glsl). On llvmpipe, texelFetch from
// 2D textures (RGBA32F points, RGBA32I tets, 4096 wide) gave the same bits and made
// classify.comp 20-45 % faster (2-4 % of a frame), the exact per-fragment path -3 to +15 %
// slower (views from inside, on a shared machine): not adopted yet, as it needs the mesh
// as textures in the renderer (a second copy, or the exact path on textures too).
vec4 mesh_point(int i) { return points[i]; }
ivec4 mesh_tet(int i) { return tets[i]; }

uniform mat4 u_view;        // obj -> eye
uniform mat4 u_proj;        // eye -> clip
uniform int u_perspective;  // 1: perspective projection, 0: parallel
uniform float u_near;       // clipping range, eye depth
uniform float u_far;

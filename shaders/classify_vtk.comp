#version 430
// classify_vtk.comp -- VTK parity (RenderSettings optics="vtk"): each tet's fan built as
// VTK's projected tetrahedra build it (vtkOpenGLProjectedTetrahedraMapper::ProjectTetrahedra,
// VTK 9.x; Wylie et al. 2002), step for step, defects included, so that tetvr's parity
// image is ParaView's "Projected tetra" picture. Compiled only for optics="vtk"; the
// default path's classify.comp does not contain any of this. What VTK does, and so this:
//   * colour and opacity are classified at the vertices (VertexColors: RGBA8, truncated
//     as VTK truncates, tetvr.optics.model.vtk_vertex_rgba8) and interpolated, not the scalar;
//   * the two opposite edges are chosen by the signs of three face orientations at
//     vertex 0; where their projections cross (parameter alpha on the first, beta on the
//     second) the tet is class 2, else class 1 with the first edge's far end thick;
//   * the thick vertex's colour is truncated to 8 bits again; its opacity is the mean of
//     the two ends, with VTK's class-2 bug (the second edge's opacity taken at alpha, not beta);
//   * all of it is interpolated in screen space (NDC, w = 1), also the back point's
//     colour and opacity on the face behind a class-1 thick vertex;
//   * its thickness is the eye-space distance between the thick vertex's two ends: in a
//     parallel view exactly (linear in NDC z), in perspective through VTK's table of
//     2048 square roots over [0, max_edge^2], indexed by truncation (rounded down; below
//     max_edge / 45 it is 0);
//   * a tet with any vertex nearer than the near plane (or behind the eye) is dropped,
//     as is one with every vertex off one side of the view or beyond the far plane.
//
// In:  Order (drawing position -> tet), Points, Tets (common.glsl), VertexColors (one
//      packed RGBA8 per point of the points buffer), u_view, u_proj, u_inv_proj,
//      u_linear_depth, u_sqrt_bias, u_unit_distance, u_offset, u_count.
// Out: Fans (common.glsl's FanVertex, as classify.comp writes them): vertex 0 the thick
//      vertex, 1..4 the silhouette (a class-1 fan repeats vertex 1 in slot 4), each with
//      its NDC position; the exact-tet word holds the NDC depth's bits instead (VTK's
//      vertex z: the class-2 crossing takes the first edge's, so each triangle lies in a
//      face of the tet), the chord word the thickness over the unit distance and the
//      segment word (r, g, b, opacity), colours as 8-bit values / 255 (vtk_pt.vert).

#include "common.glsl"

layout(local_size_x = 64) in;
layout(std430, binding = 2) writeonly buffer Fans { uvec4 fan_words[]; };  // 2 per FanVertex
layout(std430, binding = 3) readonly buffer Order { uint order[]; };
layout(std430, binding = 5) readonly buffer VertexColors { uint vertex_rgba8[]; };

uniform int u_offset;  // drawing position of this dispatch's first tet
uniform int u_count;   // drawing positions in this draw
uniform mat4 u_inv_proj;       // clip -> eye, the float inverse of the projection (VTK's)
uniform float u_linear_depth;  // parallel views: eye distance per unit of NDC z; 0 in perspective
uniform float u_sqrt_bias;     // 2047 / max_edge^2: squared distance -> index of VTK's sqrt table
uniform float u_unit_distance;

const int SQRT_TABLE_SIZE = 2048;

// Fan vertex `slot` of the tet at local drawing position p (colour as 8-bit values).
void put_vtk(int p, int slot, vec3 ndc, vec3 color8, float opacity, float thickness) {
    int v = 2 * (FAN_VERTICES * p + slot);
    fan_words[v] = uvec4(floatBitsToUint(ndc), floatBitsToUint(thickness));
    fan_words[v + 1] = floatBitsToUint(vec4(color8 / 255.0, opacity));
}

// vtkOpenGLProjectedTetrahedraMapper::GetCorrectedDepth: the eye-space distance between
// two points on the ray through NDC (x, y), at NDC depths z1 and z2.
float corrected_depth(float x, float y, float z1, float z2) {
    if (u_linear_depth > 0.0) return abs(u_linear_depth * (z1 - z2));
    vec4 e1 = u_inv_proj * vec4(x, y, z1, 1.0);
    vec4 e2 = u_inv_proj * vec4(x, y, z2, 1.0);
    vec3 d = e1.xyz / e1.w - e2.xyz / e2.w;
    int i = min(int(dot(d, d) * u_sqrt_bias), SQRT_TABLE_SIZE - 1);
    return sqrt(float(i) / u_sqrt_bias);
}

// (unsigned char)(x) of a value that is in [0, 255] but for rounding.
vec3 uchar3(vec3 x) { return clamp(trunc(x), 0.0, 255.0); }

void main() {
    int p = int(gl_GlobalInvocationID.x);  // drawing position, relative to u_offset
    if (p + u_offset >= u_count) return;
    ivec4 id = mesh_tet(int(order[p + u_offset]));
    vec3 P[4];  // NDC
    vec3 C[4];  // colour, 0..255
    float T[4]; // opacity
    for (int k = 0; k < 4; ++k) {
        vec4 clip = u_proj * (u_view * vec4(mesh_point(id[k]).xyz, 1.0));
        // Behind the eye: VTK puts the point "very far behind us", which drops the tet.
        P[k] = clip.w > 0.0 ? clip.xyz / clip.w : vec3(clip.xy, -3.4e38);
        uint c = vertex_rgba8[id[k]];
        C[k] = vec3(float(c & 0xFFu), float((c >> 8) & 0xFFu), float((c >> 16) & 0xFFu));
        T[k] = float(c >> 24) / 255.0;
    }
    vec3 lo = min(min(P[0], P[1]), min(P[2], P[3]));
    vec3 hi = max(max(P[0], P[1]), max(P[2], P[3]));
    if (any(greaterThan(lo, vec3(1.0))) || any(lessThan(hi.xy, vec2(-1.0))) || lo.z < -1.0) {
        for (int slot = 0; slot < FAN_VERTICES; ++slot) put_vtk(p, slot, vec3(2.0, 2.0, 0.0), vec3(0.0), 0.0, 0.0);
        return;
    }

    // The two opposite edges: one joins two faces that both face the viewer or both face away.
    vec2 v1 = P[1].xy - P[0].xy, v2 = P[2].xy - P[0].xy, v3 = P[3].xy - P[0].xy;
    float face_dir1 = v3.x * v2.y - v3.y * v2.x;
    float face_dir2 = v1.x * v3.y - v1.y * v3.x;
    float face_dir3 = v2.x * v1.y - v2.y * v1.x;
    ivec4 seg;  // (first edge, second edge)
    if (face_dir1 * face_dir2 >= 0.0 && (face_dir1 != 0.0 || face_dir2 != 0.0)) seg = ivec4(0, 3, 1, 2);
    else if (face_dir1 * face_dir3 >= 0.0) seg = ivec4(0, 2, 1, 3);
    else seg = ivec4(0, 1, 2, 3);
    vec3 A = P[seg.y] - P[seg.x];
    vec3 B = P[seg.w] - P[seg.z];
    vec3 Cv = P[seg.z] - P[seg.x];
    float denominator = A.x * B.y - A.y * B.x;
    if (denominator == 0.0) {  // VTK skips the tet
        for (int slot = 0; slot < FAN_VERTICES; ++slot) put_vtk(p, slot, vec3(2.0, 2.0, 0.0), vec3(0.0), 0.0, 0.0);
        return;
    }
    float alpha = (B.y * Cv.x - B.x * Cv.y) / denominator;
    float beta = (A.y * Cv.x - A.x * Cv.y) / denominator;

    if (alpha >= 0.0 && alpha <= 1.0) {
        // Class 2: a fifth vertex where the edges cross.
        vec3 X = P[seg.x] + alpha * A;
        float depth = corrected_depth(X.x, X.y, X.z, P[seg.z].z + beta * B.z);
        vec3 color = uchar3(0.5 * (C[seg.x] + alpha * (C[seg.y] - C[seg.x]) + C[seg.z] + beta * (C[seg.w] - C[seg.z])));
        // VTK's opacity line uses alpha for the second edge too (its colour line has beta).
        float opacity = 0.5 * (T[seg.x] + alpha * (T[seg.y] - T[seg.x]) + T[seg.z] + alpha * (T[seg.w] - T[seg.z]));
        put_vtk(p, 0, X, color, opacity, depth / u_unit_distance);
        ivec4 ring = ivec4(seg.x, seg.z, seg.y, seg.w);
        for (int slot = 1; slot < FAN_VERTICES; ++slot) {
            int k = ring[slot - 1];
            put_vtk(p, slot, P[k], C[k], T[k], 0.0);
        }
        return;
    }
    // Class 1: the first edge's far end (after the flip) is the thick vertex.
    if (alpha <= 0.0) {
        seg.xy = seg.yx;
        alpha = 1.0 - alpha;
    }
    float edgez = P[seg.z].z + beta * B.z;
    float pointz = P[seg.x].z;
    float facez = (edgez + (alpha - 1.0) * pointz) / alpha;
    float depth = corrected_depth(P[seg.y].x, P[seg.y].y, P[seg.y].z, facez);
    vec3 edgec = C[seg.z] + beta * (C[seg.w] - C[seg.z]);
    vec3 facec = (edgec + (alpha - 1.0) * C[seg.x]) / alpha;
    vec3 color = uchar3(0.5 * (facec + C[seg.y]));
    float edgea = T[seg.z] + beta * (T[seg.w] - T[seg.z]);
    float facea = (edgea + (alpha - 1.0) * T[seg.x]) / alpha;
    float opacity = 0.5 * (facea + T[seg.y]);
    put_vtk(p, 0, P[seg.y], color, opacity, depth / u_unit_distance);
    ivec4 ring = ivec4(seg.x, seg.z, seg.w, seg.x);
    for (int slot = 1; slot < FAN_VERTICES; ++slot) {
        int k = ring[slot - 1];
        put_vtk(p, slot, P[k], C[k], T[k], 0.0);
    }
}

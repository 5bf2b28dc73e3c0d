// lookup.glsl -- the pre-integrated segment integral, read from the 3D table.
//
// Table: sampler3D with width = thickness slice (slice 0 = zero thickness, slices 1..K =
// d_min * base^(k-1)), height = front scalar, depth = back scalar (the slice varies fastest:
// a trilinear fetch then reads nearby memory; tetvr.gl.util.table_texture), linear
// filtering (filter.glsl; TABLE_CUBIC 1: Catmull-Rom across slices instead). TABLE_NORMALIZED 1: RGB = colour per unit alpha, A = mean extinction, so
// alpha = 1 - exp(-d A) is exact in d; 0: premultiplied RGBA (Kraus et al. 2004).
// TABLE_WARP 1: the scalar nodes are uneven (tetvr.optics.tablewarp): table_st gives x, the cells
// from the first node, and u_warp (u_warp_cells x 3, RGBA32F, no filtering) the node index
// (row 0) and, for TABLE_NORMALIZED, the mean extinction from the optical depth per cell
// (row 1) or the opacity per node (row 2) instead of the table's A, which cannot follow
// -ln(1 - a) near opacity 1.
// TABLE_STEPS 1: the transfer function steps at some nodes (tetvr.optics.tablesteps): segments
// are cut at the nodes they cross (lookup_steps.glsl, u_steps). Not with TABLE_WARP.
// Returns premultiplied RGBA.

// The per-fragment arithmetic is reduced to multiply-adds by constants that
// PreintegrationTable.gl_uniforms() derives once per table.

#include "filter.glsl"

uniform sampler3D u_table;
uniform vec2 u_scalar_range;   // scalars of the first and last table node
uniform float u_optical_scale; // stored A * u_optical_scale = extinction / ln 2 (for exp2)
uniform vec3 u_table_size;     // (N, N, K + 1): front scalar, back scalar, slice
uniform vec2 u_lookup;         // scalar -> texel coordinate: scale, offset (table_st)
uniform vec4 u_slices;         // x = d / d_min -> texture z: 1 / d_min, then for x < 1: z = x * y + z,
uniform float u_slices_log;    // else z = log2(x) * u_slices.w + u_slices_log
#if defined(TABLE_WARP) && TABLE_WARP
uniform sampler2D u_warp;      // per cell: (split x, node index there, nodes per cell below, above)
uniform int u_warp_cells;

// Table texture coordinates of the scalars at x cells from the first node: a cell holds at
// most one node, so the node index is linear on each side of the cell's split, exactly.
vec2 warp_st(vec2 x) {
    ivec2 c = clamp(ivec2(floor(x)), 0, u_warp_cells - 1);
    vec4 a = texelFetch(u_warp, ivec2(c.x, 0), 0);
    vec4 b = texelFetch(u_warp, ivec2(c.y, 0), 0);
    vec2 index = vec2(a.y, b.y) + (x - vec2(a.x, b.x)) * mix(vec2(a.w, b.w), vec2(a.z, b.z), lessThan(x, vec2(a.x, b.x)));
    return (clamp(index, 0.0, u_table_size.x - 1.0) + 0.5) / u_table_size.x;
}

// Mean extinction from x.x to x.y (node coordinates st, warp_st): the difference of the
// optical depth P (linear in each cell; P_hi + P_lo, so that nearby cells' difference keeps
// float32's precision) over x; within a cell, where that quotient would divide the rounding
// of x (~5e-4 cells at 8192) by a tiny dx, the extinction at the middle, exactly, from the
// opacity at the nodes (row 2: opacity, 1 / unit distance, 1 for tau = a / u).
float warp_extinction(vec2 x, vec2 st) {
    float dx = x.y - x.x;
    if (abs(dx) >= 1.0) {
        ivec2 c = clamp(ivec2(floor(x)), 0, u_warp_cells - 1);
        vec4 a = texelFetch(u_warp, ivec2(c.x, 1), 0);
        vec4 b = texelFetch(u_warp, ivec2(c.y, 1), 0);
        float dp = (b.x - a.x) + (b.y - a.y) + (x.y - float(c.y)) * b.z - (x.x - float(c.x)) * a.z;
        return dp / dx;
    }
    float index = 0.5 * (st.x + st.y) * u_table_size.x - 0.5;
    int i = clamp(int(floor(index)), 0, int(u_table_size.x) - 2);
    vec4 n0 = texelFetch(u_warp, ivec2(i, 2), 0);
    vec4 n1 = texelFetch(u_warp, ivec2(i + 1, 2), 0);
    float opacity = mix(n0.x, n1.x, clamp(index - float(i), 0.0, 1.0));
    return n0.z > 0.5 ? opacity * n0.y : -log(1.0 - opacity) * n0.y;
}
#endif
// Texture coordinate of the fractional thickness slice of a segment of world length d: slice
// 0 is zero thickness, slice k >= 1 is d_min * base^(k - 1), linear below d_min; z is
// (slice + 0.5) / (K + 1). Beyond the thickest slice (z > (K + 0.5) / (K + 1)) the texture
// clamps to that slice.
float slice_z(float d) {
    float x = d * u_slices.x;
    return x < 1.0 ? x * u_slices.y + u_slices.z : log2(x) * u_slices.w + u_slices_log;
}

#if defined(TABLE_CUBIC) && TABLE_CUBIC
// Catmull-Rom along the thickness axis: the first of the four slices read (k0 - 1, clamped
// by the caller) and their weights, for slice coordinate z.
vec4 catmull_rom(float z, out float k0) {
    float slice = z * u_table_size.z - 0.5;
    k0 = floor(slice);
    float f = slice - k0;
    return 0.5 * vec4(((-f + 2.0) * f - 1.0) * f, (3.0 * f - 5.0) * f * f + 2.0,
                      ((-3.0 * f + 4.0) * f + 1.0) * f, (f - 1.0) * f * f);
}
#endif

#if defined(TABLE_STEPS) && TABLE_STEPS
#include "lookup_steps.glsl"
#endif

// Texture coordinates of a (front, back) scalar pair (with TABLE_WARP: cells, see warp_st): node i sits at texel centre
// (i + 0.5) / N. No clamp is needed: the texture clamps to its edge texels, and those are
// the first and last nodes, which is what a scalar beyond the table's range should read.
// Affine in the scalars, so tet.vert applies it per vertex (one multiply-add less per
// fragment: 5-7 % of the draw on llvmpipe at 10k tets).
vec2 table_st(vec2 s) {
    return s * u_lookup.x + u_lookup.y;
}

// The segment with texture coordinates st (table_st) and world length d.
vec4 lookup_table(vec2 st, float d) {
#if defined(TABLE_STEPS) && TABLE_STEPS
    return lookup_steps(st, d);
#endif
#if defined(TABLE_WARP) && TABLE_WARP
    vec2 cells = st;
    st = warp_st(cells);
#endif
    float z = slice_z(d);
#if defined(TABLE_CUBIC) && TABLE_CUBIC
    // Four slices, each read at its texel centre.
    float k0;
    vec4 w = catmull_rom(z, k0);
    vec4 t = vec4(0.0);
    for (int i = 0; i < 4; ++i) {
        float k = clamp(k0 + float(i - 1), 0.0, u_table_size.z - 1.0);
        t += w[i] * trilinear(u_table, vec3((k + 0.5) / u_table_size.z, st));
    }
    t = max(t, 0.0);  // Catmull-Rom can overshoot the nodes
#if TABLE_NORMALIZED
    t.rgb = min(t.rgb, 1.0);
#endif
#else
    vec4 t = trilinear(u_table, vec3(z, st));
#endif
#if TABLE_NORMALIZED
    // Linear filtering stays within the nodes' colours, which the table keeps in [0, 1].
#if defined(TABLE_WARP) && TABLE_WARP
    float alpha = 1.0 - exp(-d * warp_extinction(cells, st));
#else
    float alpha = 1.0 - exp2(-d * t.a * u_optical_scale);
#endif
    return vec4(t.rgb * alpha, alpha);
#else
    return vec4(min(t.rgb, vec3(t.a)), min(t.a, 1.0));
#endif
}

// The segment from scalar sf to scalar sb with world length d.
vec4 lookup_segment(float sf, float sb, float d) {
    return lookup_table(table_st(vec2(sf, sb)), d);
}

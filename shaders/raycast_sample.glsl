// raycast_sample.glsl -- reading the volume and the transfer function.
//
// Volume: sampler3D, width x height x depth = nx x ny x nz, one channel, linear filter,
// clamped to the edge. Voxel (i, j, k) sits at texel centre ((i, j, k) + 0.5) / n, so a
// point p_idx in index space reads texture((p_idx + 0.5) / n): trilinear interpolation
// (filter.glsl), clamped to the box [0, n-1] like the CPU reference; INTERPOLATION_CUBIC 1
// reconstructs with the cubic B-spline instead. The texture holds
// the raw values (8/16-bit normalized or float); scalar = texel * u_value_scale.
// Transfer function: tf_points.glsl.

#include "filter.glsl"

uniform sampler3D u_volume;
uniform vec3 u_inv_dims;       // 1 / (nx, ny, nz)
uniform float u_value_scale;

float texel_at(vec3 p_idx) {
    return trilinear(u_volume, (p_idx + 0.5) * u_inv_dims).r;
}

#if INTERPOLATION_CUBIC
// Uniform cubic B-spline from 8 trilinear fetches (Sigg & Hadwiger 2005, GPU Gems 2
// ch. 20): per axis the 4 tap weights are merged pairwise into 2 linear fetches placed
// between taps (i-1, i) and (i+1, i+2). Clamp-to-edge repeats the edge voxel, which is
// what the CPU reference does with its taps.
float scalar_at(vec3 p_idx) {
    vec3 i = floor(p_idx);
    vec3 t = p_idx - i;
    vec3 t2 = t * t;
    vec3 t3 = t2 * t;
    vec3 w0 = (1.0 - 3.0 * t + 3.0 * t2 - t3) / 6.0;
    vec3 w1 = (4.0 - 6.0 * t2 + 3.0 * t3) / 6.0;
    vec3 w2 = (1.0 + 3.0 * t + 3.0 * t2 - 3.0 * t3) / 6.0;
    vec3 w3 = t3 / 6.0;
    vec3 g0 = w0 + w1;
    vec3 g1 = w2 + w3;
    vec3 h0 = i - 1.0 + w1 / g0;
    vec3 h1 = i + 1.0 + w3 / g1;
    float v = g0.z * (g0.y * (g0.x * texel_at(vec3(h0.x, h0.y, h0.z)) + g1.x * texel_at(vec3(h1.x, h0.y, h0.z)))
                    + g1.y * (g0.x * texel_at(vec3(h0.x, h1.y, h0.z)) + g1.x * texel_at(vec3(h1.x, h1.y, h0.z))))
            + g1.z * (g0.y * (g0.x * texel_at(vec3(h0.x, h0.y, h1.z)) + g1.x * texel_at(vec3(h1.x, h0.y, h1.z)))
                    + g1.y * (g0.x * texel_at(vec3(h0.x, h1.y, h1.z)) + g1.x * texel_at(vec3(h1.x, h1.y, h1.z))));
    return v * u_value_scale;
}
#else
float scalar_at(vec3 p_idx) {
    return texel_at(p_idx) * u_value_scale;
}
#endif

#include "tf_points.glsl"

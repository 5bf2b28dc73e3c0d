// raycast_sample.glsl -- reading the volume and the 1D transfer function.
//
// Volume: sampler3D, width x height x depth = nx x ny x nz, one channel, linear filter,
// clamped to the edge. Voxel (i, j, k) sits at texel centre ((i, j, k) + 0.5) / n, so a
// point p_idx in index space reads texture((p_idx + 0.5) / n): hardware trilinear
// interpolation, clamped to the box [0, n-1] like the CPU reference. The texture holds
// the raw values (8/16-bit normalized or float); scalar = texel * u_value_scale + u_value_offset.
// Transfer function: sampler2D of u_tf_size x 1 RGBA = (colour, opacity) at
// u_tf_size evenly spaced scalars over u_scalar_range (declared by lookup.glsl).

uniform sampler3D u_volume;
uniform vec3 u_inv_dims;       // 1 / (nx, ny, nz)
uniform float u_value_scale;
uniform float u_value_offset;
uniform sampler2D u_tf;
uniform float u_tf_size;

float scalar_at(vec3 p_idx) {
    return texture(u_volume, (p_idx + 0.5) * u_inv_dims).r * u_value_scale + u_value_offset;
}

// Premultiplied (c a, a) of the transfer function at scalar s.
vec4 classify(float s) {
    float x = clamp((s - u_scalar_range.x) / (u_scalar_range.y - u_scalar_range.x), 0.0, 1.0);
    vec4 ca = texture(u_tf, vec2((x * (u_tf_size - 1.0) + 0.5) / u_tf_size, 0.5));
    return vec4(ca.rgb * ca.a, ca.a);
}

// Colour (not premultiplied) of the transfer function at scalar s.
vec3 color_at(float s) {
    float x = clamp((s - u_scalar_range.x) / (u_scalar_range.y - u_scalar_range.x), 0.0, 1.0);
    return texture(u_tf, vec2((x * (u_tf_size - 1.0) + 0.5) / u_tf_size, 0.5)).rgb;
}

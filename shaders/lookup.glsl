// lookup.glsl -- the pre-integrated segment integral, read from the 3D table.
//
// Table: sampler3D with width = front scalar, height = back scalar, depth = thickness
// slice (slice 0 = zero thickness, slices 1..K = u_d_min * u_log_base^(k-1)), linear
// filtering. TABLE_NORMALIZED 1: RGB = colour per unit alpha, A = mean extinction, so
// alpha = 1 - exp(-d A) is exact in d; 0: premultiplied RGBA (Kraus et al. 2004).
// Returns premultiplied RGBA.

uniform sampler3D u_table;
uniform vec2 u_scalar_range;   // scalars of the first and last table node
uniform float u_d_min;         // thickness of slice 1
uniform float u_inv_log_base;  // 1 / ln(base)
uniform float u_alpha_scale;   // stored A * u_alpha_scale = extinction (uint8 tables)
uniform vec3 u_table_size;     // (N, N, K + 1)

vec4 lookup_segment(float sf, float sb, float d) {
    vec2 s = clamp((vec2(sf, sb) - u_scalar_range.x) / (u_scalar_range.y - u_scalar_range.x), 0.0, 1.0);
    float slice = d < u_d_min ? d / u_d_min : 1.0 + log(d / u_d_min) * u_inv_log_base;
    slice = clamp(slice, 0.0, u_table_size.z - 1.0);
    // Node i sits at texel centre (i + 0.5) / size.
    vec3 coord = (vec3(s * (u_table_size.xy - 1.0), slice) + 0.5) / u_table_size;
    vec4 t = texture(u_table, coord);
#if TABLE_NORMALIZED
    float alpha = 1.0 - exp(-d * t.a * u_alpha_scale);
    return vec4(t.rgb * alpha, alpha);
#else
    return t;
#endif
}

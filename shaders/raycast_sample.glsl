// raycast_sample.glsl -- reading the volume and the transfer function.
//
// Volume: sampler3D, width x height x depth = nx x ny x nz, one channel, linear filter,
// clamped to the edge. Voxel (i, j, k) sits at texel centre ((i, j, k) + 0.5) / n, so a
// point p_idx in index space reads texture((p_idx + 0.5) / n): hardware trilinear
// interpolation, clamped to the box [0, n-1] like the CPU reference; INTERPOLATION_CUBIC 1
// reconstructs with the cubic B-spline instead. The texture holds
// the raw values (8/16-bit normalized or float); scalar = texel * u_value_scale.
// Transfer function: its control points (the union of the colour and opacity points,
// ascending), one texel each in u_tf_points: row 0 (scalar, opacity, 0, 0), row 1
// (r, g, b, 0); both maps are linear between two points and constant beyond the ends,
// so tf_at evaluates it exactly, as TransferFunction.evaluate does.

uniform sampler3D u_volume;
uniform vec3 u_inv_dims;       // 1 / (nx, ny, nz)
uniform float u_value_scale;
uniform sampler2D u_tf_points;
uniform int u_tf_count;

float texel_at(vec3 p_idx) {
    return texture(u_volume, (p_idx + 0.5) * u_inv_dims).r;
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

vec4 tf_point(int k) {
    return vec4(texelFetch(u_tf_points, ivec2(k, 1), 0).rgb, texelFetch(u_tf_points, ivec2(k, 0), 0).y);
}

// One interval between control points: i = the number of points <= its scalars; it holds
// the scalars lo <= s < hi (lo = -3e38 below the first point, hi = 3e38 from the last on),
// where the transfer function runs linearly from v_lo to v_hi (constant beyond the ends).
// A ray's samples mostly stay in one interval, so keeping it spares the search.
struct TFInterval { int i; float lo, hi; vec4 v_lo, v_hi; };

TFInterval tf_interval(float s) {
    int lo = 0, hi = u_tf_count;
    while (lo < hi) {
        int mid = (lo + hi) >> 1;
        if (texelFetch(u_tf_points, ivec2(mid, 0), 0).x <= s) lo = mid + 1; else hi = mid;
    }
    TFInterval t;
    t.i = lo;
    int i0 = max(lo - 1, 0), i1 = min(lo, u_tf_count - 1);
    t.lo = lo == 0 ? -3.0e38 : texelFetch(u_tf_points, ivec2(i0, 0), 0).x;
    t.hi = lo == u_tf_count ? 3.0e38 : texelFetch(u_tf_points, ivec2(i1, 0), 0).x;
    t.v_lo = tf_point(i0);
    t.v_hi = tf_point(i1);
    return t;
}

bool tf_holds(TFInterval t, float s) {
    return s >= t.lo && s < t.hi;
}

// The transfer function at s inside t (tf_holds(t, s)).
vec4 tf_in(TFInterval t, float s) {
    bool inner = t.i > 0 && t.i < u_tf_count && t.hi > t.lo;
    return mix(t.v_lo, t.v_hi, inner ? clamp((s - t.lo) / (t.hi - t.lo), 0.0, 1.0) : 0.0);
}

// The transfer function at scalar s: (r, g, b, a).
vec4 tf_at(float s) {
    return tf_in(tf_interval(s), s);
}

// Premultiplied (c a, a) of the transfer function at scalar s.
vec4 classify(float s) {
    vec4 ca = tf_at(s);
    return vec4(ca.rgb * ca.a, ca.a);
}

// Colour (not premultiplied) of the transfer function at scalar s.
vec3 color_at(float s) {
    return tf_at(s).rgb;
}

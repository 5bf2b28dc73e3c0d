// tf_points.glsl -- the transfer function itself, for integration without a table.
//
// Its control points (the union of the colour and opacity points, ascending), one texel
// each in u_tf_points: row 0 (scalar, opacity, 0, 0), row 1 (r, g, b, 0); both maps are
// linear between two points and constant beyond the ends, so tf_at evaluates it exactly,
// as TransferFunction.evaluate does (tetvr.gl.util.tf_points_texture).

uniform sampler2D u_tf_points;
uniform int u_tf_count;

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

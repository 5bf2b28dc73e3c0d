// raycast_exact.glsl -- the emission-absorption integral of one piece of a ray, without a
// table: the piece is cut where its scalar crosses a transfer-function control point, so
// that colour and opacity are linear on every cut, and each cut is integrated in closed
// form (optical depth) and by 3-point Gauss-Legendre quadrature (colour), as
// tetvr.optics.model.integrate_pieces does in float64 (the same exact model, tau = -ln(1 - a) / u).
//
// In:  raycast_sample.glsl's transfer function (tf_interval, tf_point: its control points);
//      u_inv_unit_distance: 1 / the transfer function's unit distance.
// Out: integrate_piece (premultiplied RGBA of a piece seen from its front).

uniform float u_inv_unit_distance;

#define MAX_OPACITY (1.0 - 1e-6)
// A cut is integrated in equal parts of optical depth <= SUB_THETA whose 1 - a changes
// by at most 2x (as the reference), at most MAX_PARTS of them.
#define SUB_THETA 0.5
#define MAX_PARTS 16

// The bracket of tetvr.optics.model.mean_neg_log: mean of -ln x over [x0, x0 (1 + d)] is
// -ln x0 - bracket(d); by its series where float32 would cancel (to d^7: < 2e-10 for |d| < 0.1).
float bracket(float d) {
    return abs(d) < 0.1
        ? d * (1.0 / 2.0 - d * (1.0 / 6.0 - d * (1.0 / 12.0 - d * (1.0 / 20.0 - d * (1.0 / 30.0 - d * (1.0 / 42.0 - d / 56.0))))))
        : ((1.0 + d) * log(1.0 + d) - d) / d;
}

float mean_neg_log(float x0, float x1) {
    return -log(x0) - bracket(x1 / x0 - 1.0);
}

// 1 - exp(-t), accurate for small t (GLSL has no expm1).
float one_minus_exp(float t) {
    return t < 1e-3 ? t * (1.0 - t * (0.5 - t * (1.0 / 6.0))) : 1.0 - exp(-t);
}

// One part, colour linear from c0 to c1 and transmittance per unit distance 1 - a from
// x0 to x1, k = its length / unit distance, theta = its optical depth (k mean_neg_log).
// I = c0 (1 - T(L)) + (c1 - c0) int_0^1 (T(xi) - T(L)) dxi, the colour integral by parts
// (tetvr.optics.model.integrate_pieces) written so that no two O(1) terms cancel when the part
// is faint; with constant opacity the integral is closed form, else 3-point
// Gauss-Legendre (the part's optical depth is at most SUB_THETA and its 1 - a within
// 2x: the error is below float32's).
vec4 integrate_part(vec3 c0, vec3 c1, float x0, float x1, float k, float theta) {
    float a = one_minus_exp(theta);
    float tail;
    if (x0 == x1) {
        // int_0^1 exp(-xi theta) - exp(-theta) = a / theta - (1 - a); its series below 0.01.
        tail = theta < 0.01 ? theta * (0.5 - theta * (1.0 / 3.0 - theta * (1.0 / 8.0 - theta / 30.0)))
                            : a / theta - (1.0 - a);
    } else {
        const vec3 gx = vec3(0.1127016654, 0.5, 0.8872983346);
        const vec3 gw = vec3(5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0);
        float nl0 = -log(x0), d = x1 / x0 - 1.0;
        tail = 0.0;
        for (int q = 0; q < 3; ++q) {
            float before = gx[q] * k * (nl0 - bracket(gx[q] * d));
            tail += gw[q] * exp(-before) * one_minus_exp(max(theta - before, 0.0));
        }
    }
    return vec4(c0 * a + (c1 - c0) * tail, a);
}

// A cut on which colour and opacity are linear: in parts (see SUB_THETA), composited.
vec4 integrate_cut(vec4 v0, vec4 v1, float len) {
    if (v0.a == 0.0 && v1.a == 0.0) return vec4(0.0);  // transparent: most of a sparse transfer function
    float x0 = 1.0 - min(v0.a, MAX_OPACITY), x1 = 1.0 - min(v1.a, MAX_OPACITY);
    float k = len * u_inv_unit_distance;
    float theta = k * mean_neg_log(x0, x1);
    float ratio = x1 / x0;
    if (theta <= SUB_THETA && ratio <= 2.0 && ratio >= 0.5) return integrate_part(v0.rgb, v1.rgb, x0, x1, k, theta);
    int n = int(clamp(max(ceil(theta / SUB_THETA), ceil(abs(log2(ratio)))), 1.0, float(MAX_PARTS)));
    vec4 acc = vec4(0.0);
    vec3 ca = v0.rgb;
    float xa = x0;
    for (int p = 1; p <= n; ++p) {
        float f = float(p) / float(n);
        vec3 cb = mix(v0.rgb, v1.rgb, f);
        float xb = mix(x0, x1, f);
        acc += (1.0 - acc.a) * integrate_part(ca, cb, xa, xb, k / float(n), k / float(n) * mean_neg_log(xa, xb));
        ca = cb;
        xa = xb;
    }
    return acc;
}

// The piece from scalar s0 (transfer function v0, interval i0: TFInterval) to s1 (v1, i1)
// over world length len, cut at the control points it crosses, in ray order.
vec4 integrate_piece(float s0, vec4 v0, int i0, float s1, vec4 v1, int i1, float len) {
    if (i0 == i1) return integrate_cut(v0, v1, len);
    vec4 acc = vec4(0.0);
    float s_a = s0;
    vec4 v_a = v0;
    float per_s = len / (s1 - s0);
    // Rising: the points i0 .. i1 - 1 lie in (s0, s1]; falling: i0 - 1 down to i1 in (s1, s0].
    int step_k = i1 > i0 ? 1 : -1;
    int k = i1 > i0 ? i0 : i0 - 1;
    int last = i1 > i0 ? i1 - 1 : i1;
    for (;;) {
        float s_b = texelFetch(u_tf_points, ivec2(k, 0), 0).x;
        vec4 v_b = tf_point(k);
        acc += (1.0 - acc.a) * integrate_cut(v_a, v_b, (s_b - s_a) * per_s);
        s_a = s_b;
        v_a = v_b;
        if (k == last) break;
        k += step_k;
    }
    acc += (1.0 - acc.a) * integrate_cut(v_a, v1, (s1 - s_a) * per_s);
    return acc;
}

#version 430
// table_runs.comp -- the off-diagonal entries of a pre-integration table with even nodes,
// "normalized" float32 (tetvr.optics.preintegrate: the run recurrence of _fill_runs and the
// encoding of _encoded, the same arithmetic in double precision).
//
// One invocation per (run length n, thickness slice k, direction): along the diagonal
// sb - sf = +-n of slice k every entry is a run of n bins, each crossed in length
// thick[k] / n, and the run from node i follows from the one from node i + 1 by
// compositing bin i in front and removing bin i + n from the back:
//     W_i = c_i + t_i * (W_{i+1} - T(i+1 .. i+n-1) * c_{i+n}).
// The invocations of one (k, direction) are independent: N - 1 of them, each walking
// the N - 1 front nodes in turn (the recurrence is sequential along a diagonal).
// Direction 0 runs forwards (sb > sf); direction 1 on the mirrored axis (sb < sf: the
// bins reversed, each with its colours swapped).
//
// In:  u_bins: per bin m, (colour at its start, mean extinction), (colour at its end, 0);
//      u_prefixes (i): the optical depth per unit length over bins < i; u_thicks (k): the
//      thickness of slice k + 1; all doubles, each as two uints. u_count: the bins (N - 1).
// Out: u_out[(sb * N + sf) * (K + 1) + k + 1]: slice k + 1's entry (front sf, back sb), in
//      the table texture's layout (tetvr.gl.util.table_texture: the slice fastest), as the
//      table stores it: RGB the colour per unit alpha (clamped to [0, 1]), A the mean
//      extinction (at most MAX_STORED_TAU). The diagonal (sf == sb) is not written.
// Doubles, not floats: a thin bin's colour is a difference of terms of order one whose
// result is of the order of its optical depth, and float32 leaves ~1e-7 of each term in
// it, 5e-6 over a run of 512 bins (measured); the CPU build's float64 leaves 1e-16.
// GLSL has no double exp, so dexpm1() reduces by ln 2 and sums the Taylor series.
// Each bin's colour for the invocation's step length is computed once: kept in a ring of
// RING entries (a power of two, at least the bins: tetvr.gl.tablebuild), it is read again
// when the bin leaves the run n steps later; and the run's opacity comes from the
// transmittances already at hand, e^(a + b) - 1 = (e^a - 1) + (e^b - 1) + (e^a - 1)(e^b - 1),
// which keeps its precision where both are small (a thin run), as expm1 does.

layout(local_size_x = 64) in;

// The inputs are images of doubles as pairs of uints (llvmpipe's imageLoad is ~7x faster
// than its storage-buffer loads here).
layout(binding = 0, rgba32ui) restrict readonly uniform uimage2D u_bins;  // 4 texels a bin
layout(binding = 1, rg32ui) restrict readonly uniform uimage2D u_prefixes;
layout(binding = 2, rg32ui) restrict readonly uniform uimage2D u_thicks;
layout(std430, binding = 3) restrict writeonly buffer Out { vec4 u_out[]; };
uniform int u_count;

dvec4 load_bin(int b, int part) {
    uvec4 lo = imageLoad(u_bins, ivec2(4 * b + 2 * part, 0)), hi = imageLoad(u_bins, ivec2(4 * b + 2 * part + 1, 0));
    return dvec4(packDouble2x32(lo.xy), packDouble2x32(lo.zw), packDouble2x32(hi.xy), packDouble2x32(hi.zw));
}

#define u_prefix(j) packDouble2x32(imageLoad(u_prefixes, ivec2(j, 0)).xy)

#define MAX_STORED_TAU 1.0e30LF
const double LN2 = 0.6931471805599453094LF;

// e^x - 1 for |x| <= ln 2 / 2, by its Taylor series to x^11 (the next term is below 3e-14
// of the sum; the table keeps float32).
double expm1_series(double x) {
    double s = 1.0LF / 39916800.0LF;  // 1 / 11!
    s = s * x + 1.0LF / 3628800.0LF;
    s = s * x + 1.0LF / 362880.0LF;
    s = s * x + 1.0LF / 40320.0LF;
    s = s * x + 1.0LF / 5040.0LF;
    s = s * x + 1.0LF / 720.0LF;
    s = s * x + 1.0LF / 120.0LF;
    s = s * x + 1.0LF / 24.0LF;
    s = s * x + 1.0LF / 6.0LF;
    s = s * x + 0.5LF;
    s = s * x + 1.0LF;
    return s * x;
}

// e^x - 1 for x <= 0, to ~3e-14 relative (x = k ln 2 + r, |r| <= ln 2 / 2), accurate near 0.
double dexpm1(double x) {
    if (x >= -0.5LF * LN2) return expm1_series(x);
    if (x < -700.0LF) return -1.0LF;  // e^x below 1e-304: nothing the table keeps
    double k = round(x * (1.0LF / LN2));
    return ldexp(1.0LF + expm1_series(x - k * LN2), int(k)) - 1.0LF;
}

// The premultiplied colour of bin b crossed from its start to its end (forwards; the
// mirrored axis crosses it from its end to its start) in length `step`, and e^-(its optical
// depth) - 1.
dvec3 bin_colour(int b, double step, bool forwards, out double em1) {
    dvec4 p = load_bin(b, 0), q = load_bin(b, 1);
    dvec3 c0 = forwards ? p.xyz : q.xyz, c1 = forwards ? q.xyz : p.xyz;
    double th = p.w * step;
    em1 = dexpm1(-th);
    double t = 1.0LF + em1;
    double phi = th > 1.0e-12LF ? -em1 / th : 1.0LF - 0.5LF * th;
    return th > 0.0LF ? c0 - c1 * t + (c1 - c0) * phi : dvec3(0.0LF);
}

void main() {
    int nb = u_count, nodes = u_count + 1;
    int n = int(gl_GlobalInvocationID.x) + 1, k = int(gl_GlobalInvocationID.y);
    bool forwards = gl_GlobalInvocationID.z == 0u;
    if (n > nb) return;
    double thick = packDouble2x32(imageLoad(u_thicks, ivec2(k, 0)).xy), step = thick / double(n);
    dvec3 w = dvec3(0.0LF);
    dvec3 ring[RING];  // bin i's colour at i % RING
    double em1;
    double run = 0.0LF;  // e^-(the optical depth of the bins from node i on in the run) - 1
    for (int i = nb - 1; i >= 0; --i) {
        if (i + n <= nb - 1) {
            // The bin leaving the run at its back, behind bins i+1 .. i+n-1.
            double between = forwards ? u_prefix(i + n) - u_prefix(i + 1) : u_prefix(nb - i - 1) - u_prefix(nb - i - n);
            run = dexpm1(-step * between);
            w -= (1.0LF + run) * ring[(i + n) & (RING - 1)];
        }
        dvec3 c = bin_colour(forwards ? i : nb - 1 - i, step, forwards, em1);
        ring[i & (RING - 1)] = c;
        w = w * (1.0LF + em1) + c;
        run = em1 + run + em1 * run;  // through bin i
        if (i + n <= nb) {
            int sf = forwards ? i : nb - i, sb = forwards ? i + n : nb - i - n;
            double mean = abs(u_prefix(sb) - u_prefix(sf)) / double(n);
            double alpha = -run;
            dvec3 chroma = alpha > 1.0e-300LF ? clamp(max(w, 0.0LF) / alpha, 0.0LF, 1.0LF) : dvec3(0.0LF);
            u_out[(sb * nodes + sf) * (int(gl_NumWorkGroups.y) + 1) + k + 1] = vec4(vec3(chroma), float(min(mean, MAX_STORED_TAU)));
        }
    }
}

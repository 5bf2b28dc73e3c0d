// lookup_steps.glsl -- the lookup in a table whose transfer function steps at its nodes
// (TABLE_STEPS 1; tetvr.optics.tablesteps): each segment is cut at the nodes it crosses.
//
// Needs lookup.glsl's table uniforms (u_table, u_table_size, u_slices, u_slices_log,
// u_optical_scale) and its TABLE_CUBIC define; only with TABLE_NORMALIZED 1 (alpha exact in the
// thickness: a premultiplied table's interpolated alpha would err on the short pieces), not
// with TABLE_WARP.
// In:  u_steps, each bin's 2 x 2 corner block (sampler3D, linear filtering): width 2 (N - 1),
//      texel 2 i + u the front node i + u of bin i; height 2, texel v the back node i + v;
//      depth K + 1 thickness slices as the table's. Its diagonal holds the constant-scalar
//      segment at each end of the bin on the bin's side of the step there, which the table's
//      own diagonal (the mean of the two sides) cannot.
// Out: lookup_steps(st, d), premultiplied RGBA of the segment with table coordinates st
//      (table_st) and world length d: the run between the first and the last node it
//      reaches, read at those nodes, and the partial bin at each end, read in its corner
//      block, composited front to back. A segment that crosses no node is one read in its
//      bin's block; one from node to node is the table's entry.

#if !TABLE_NORMALIZED || (defined(TABLE_WARP) && TABLE_WARP)
#error "TABLE_STEPS needs TABLE_NORMALIZED 1 and no TABLE_WARP"
#endif

uniform sampler3D u_steps;

// The entry at texture coordinates xy of u_table (run) or u_steps, slice coordinate z.
vec4 steps_fetch(bool run, vec2 xy, float z) {
#if defined(TABLE_CUBIC) && TABLE_CUBIC
    // Catmull-Rom along the thickness axis, as lookup_table.
    float k0;
    vec4 w = catmull_rom(z, k0);
    vec4 t = vec4(0.0);
    for (int i = 0; i < 4; ++i) {
        float k = (clamp(k0 + float(i - 1), 0.0, u_table_size.z - 1.0) + 0.5) / u_table_size.z;
        t += w[i] * (run ? trilinear(u_table, vec3(k, xy)) : trilinear(u_steps, vec3(xy, k)));
    }
    t = max(t, 0.0);
    t.rgb = min(t.rgb, 1.0);
    return t;
#else
    return run ? trilinear(u_table, vec3(z, xy)) : trilinear(u_steps, vec3(xy, z));
#endif
}

// The table's entry from node ab.x to node ab.y at slice coordinate z: two texels, mixed
// along the slices (a filtered fetch would read eight, four of them with weight 0).
vec4 steps_run(ivec2 ab, float z) {
#if defined(TABLE_CUBIC) && TABLE_CUBIC
    return steps_fetch(true, (vec2(ab) + 0.5) / u_table_size.x, z);
#else
    float slice = clamp(z * u_table_size.z - 0.5, 0.0, u_table_size.z - 1.0);
    int k = min(int(slice), int(u_table_size.z) - 2);
    return mix(texelFetch(u_table, ivec3(k, ab), 0), texelFetch(u_table, ivec3(k + 1, ab), 0), slice - float(k));
#endif
}

// Premultiplied RGBA of a piece of length d whose entry is t (colour per unit alpha, extinction).
vec4 steps_rgba(vec4 t, float d) {
    float alpha = 1.0 - exp2(-d * t.a * u_optical_scale);
    return vec4(t.rgb * alpha, alpha);
}

// The piece from fractional node p.x to p.y within bin i, of length d.
vec4 steps_bin(vec2 p, float i, float d) {
    vec2 uv = clamp(p - i, 0.0, 1.0);
    vec2 xy = vec2((2.0 * i + 0.5 + uv.x) / (2.0 * u_table_size.x - 2.0), 0.5 * (0.5 + uv.y));
    return steps_rgba(steps_fetch(false, xy, slice_z(d)), d);
}

vec4 lookup_steps(vec2 st, float d) {
    float n = u_table_size.x;
    vec2 f = clamp(st * n - 0.5, 0.0, n - 1.0);
    bool up = f.y >= f.x;
    // Within one bin: no node strictly between the ends; the segment is all front piece.
    bool within = up ? ceil(f.y) - 1.0 < floor(f.x) + 1.0 : floor(f.y) + 1.0 > ceil(f.x) - 1.0;
    // Else the first and the last node the segment reaches, along the ray: the run between
    // them is the table's entry (all of a segment from node to node), the ends partial bins.
    float a = up ? ceil(f.x) : floor(f.x);
    float b = up ? floor(f.y) : ceil(f.y);
    float per = d / max(abs(f.y - f.x), 1.0e-30);
    // One code path for both (lanes that differ run it once, not both branches).
    vec2 front = within ? f : vec2(f.x, a);
    float front_bin = within ? min(floor(min(f.x, f.y)), n - 2.0) : (up ? a - 1.0 : a);
    vec4 acc = vec4(0.0);
    if (within || a != f.x) acc = steps_bin(front, front_bin, within ? d : abs(a - f.x) * per);
    if (!within) {
        float run_d = abs(b - a) * per;
        acc += (1.0 - acc.a) * steps_rgba(steps_run(ivec2(a, b), slice_z(run_d)), run_d);
        if (b != f.y) acc += (1.0 - acc.a) * steps_bin(vec2(b, f.y), up ? b : b - 1.0, abs(f.y - b) * per);
    }
    return acc;
}

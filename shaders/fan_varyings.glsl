// fan_varyings.glsl -- a fan fragment's varyings (tet.vert's v_ray and v_segment) at its
// pixel's centre.
//
// INTERPOLATE_IN_SHADER 0: as the rasteriser interpolates them. 1: computed here, from the
// three fan vertices of the fragment's triangle, which classify.comp wrote (Fans, binding 2,
// bound from the draw batch's first fan): for GLs whose rasteriser interpolates from
// vertex positions snapped to its sub-pixel grid (tetvr.gl.interpolation measures it). There
// a fan of a tet a few pixels wide moves its thick vertex's segment by up to 1/512 pixel
// times its slope: several 1/255 in the pixels of thin or opaque tets. The draw's triangle i
// is triangle i & 3 of the fan of its tet i >> 2 (projected.py's index pattern: thick vertex
// 0 and silhouette vertices k + 1, (k + 1) % 4 + 1).
//
// Needs u_ray_scale (tet.vert) and u_half_px (NDC -> pixels).

uniform vec2 u_ray_scale;

#if defined(INTERPOLATE_IN_SHADER) && INTERPOLATE_IN_SHADER
layout(std430, binding = 2) readonly buffer Fans { uvec4 fan_words[]; };
uniform vec2 u_half_px;

// Twice the signed area of the triangle (o, p, q).
float fan_turn(vec2 o, vec2 p, vec2 q) {
    precise float e = (p.x - o.x) * (q.y - o.y) - (p.y - o.y) * (q.x - o.x);
    return e;
}
#endif

void fan_varyings(out vec2 ray, out vec4 segment) {
#if defined(INTERPOLATE_IN_SHADER) && INTERPOLATE_IN_SHADER
    vec2 ndc = gl_FragCoord.xy / u_half_px - 1.0;
    ray = ndc * u_ray_scale;
    int v0 = 2 * FAN_VERTICES * (gl_PrimitiveID >> 2), k = gl_PrimitiveID & 3;
    int v1 = v0 + 2 * (k + 1), v2 = v0 + 2 * (((k + 1) & 3) + 1);
    vec2 a = uintBitsToFloat(fan_words[v0].xy), b = uintBitsToFloat(fan_words[v1].xy),
         c = uintBitsToFloat(fan_words[v2].xy);
    // Barycentric weights of the pixel's centre; the rasteriser gives no fragment to a
    // triangle of zero area.
    vec3 w = vec3(fan_turn(ndc, b, c), fan_turn(ndc, c, a), fan_turn(ndc, a, b));
    segment = (w.x * uintBitsToFloat(fan_words[v0 + 1]) + w.y * uintBitsToFloat(fan_words[v1 + 1])
               + w.z * uintBitsToFloat(fan_words[v2 + 1])) / (w.x + w.y + w.z);
#else
    ray = v_ray;
    segment = v_segment;
#endif
}

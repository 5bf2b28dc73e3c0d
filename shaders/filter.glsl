// filter.glsl -- trilinear filtering of a 3D texture, by the texture unit or in the shader.
//
// Some GPUs' texture units weigh the eight texels of a linear fetch with 8-bit fractions
// (NVIDIA's: CUDA documents it for linear filtering, for every texel format), which errs by
// up to 1/512 of the step between neighbouring texels, whatever their precision: on an
// opaque transfer function's table, several 1/255 in a pixel. With FILTER_IN_SHADER 1 the
// shader reads the eight texels and weighs them in float32, as a texture unit with exact
// weights does; tetvr.gl.filtering decides per GL, by a probe, which one it needs.
// Clamp to the edge, no mipmaps, as the textures filtered here are made.

#ifndef FILTER_GLSL
#define FILTER_GLSL
vec4 trilinear(sampler3D tex, vec3 coord) {
#if defined(FILTER_IN_SHADER) && FILTER_IN_SHADER
    ivec3 size = textureSize(tex, 0);
    vec3 p = coord * vec3(size) - 0.5;
    vec3 f = floor(p);
    vec3 w = p - f;
    ivec3 a = clamp(ivec3(f), ivec3(0), size - 1);
    ivec3 b = clamp(ivec3(f) + 1, ivec3(0), size - 1);
    vec4 x00 = mix(texelFetch(tex, a, 0), texelFetch(tex, ivec3(b.x, a.y, a.z), 0), w.x);
    vec4 x10 = mix(texelFetch(tex, ivec3(a.x, b.y, a.z), 0), texelFetch(tex, ivec3(b.xy, a.z), 0), w.x);
    vec4 x01 = mix(texelFetch(tex, ivec3(a.xy, b.z), 0), texelFetch(tex, ivec3(b.x, a.y, b.z), 0), w.x);
    vec4 x11 = mix(texelFetch(tex, ivec3(a.x, b.yz), 0), texelFetch(tex, b, 0), w.x);
    return mix(mix(x00, x10, w.y), mix(x01, x11, w.y), w.z);
#else
    return textureLod(tex, coord, 0.0);
#endif
}
#endif

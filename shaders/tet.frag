#version 430
// tet.frag -- integrates the ray segment through one tet at one pixel by a lookup in the
// 3D pre-integration table (Kraus et al. 2004), and emits premultiplied RGBA for
// back-to-front "over" blending (ONE, ONE_MINUS_SRC_ALPHA) into an RGBA32F target.
//
// In:  v_front, v_back, v_scalar (see tet.vert); u_near, u_far (clipping range, > 0).
// Out: f_color, premultiplied.
// The segment is clipped to the near and far planes here, per fragment, so tets that
// cross them are cut rather than dropped.

#include "lookup.glsl"

noperspective in vec4 v_front;
noperspective in vec4 v_back;
noperspective in vec2 v_scalar;

uniform float u_near;
uniform float u_far;

out vec4 f_color;

void main() {
    vec3 pf = v_front.xyz / v_front.w;
    vec3 pb = v_back.xyz / v_back.w;
    float sf = v_scalar.x / v_front.w;
    float sb = v_scalar.y / v_back.w;
    // Depths along the view axis: -z.
    float zf = -pf.z, zb = -pb.z;
    if (zb <= u_near || zf >= u_far) discard;
    if (zf < u_near) {
        float f = (u_near - zf) / (zb - zf);
        pf = mix(pf, pb, f); sf = mix(sf, sb, f);
    }
    if (zb > u_far) {
        float f = (u_far - zf) / (zb - zf);
        pb = mix(pf, pb, f); sb = mix(sf, sb, f);
    }
    f_color = lookup_segment(sf, sb, length(pb - pf));
}

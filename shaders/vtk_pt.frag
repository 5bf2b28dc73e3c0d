#version 430
// vtk_pt.frag -- VTK parity (optics="vtk"): VTK's vtkglProjectedTetrahedraFS, the product of
// the interpolated opacity and thickness in one exponential, premultiplied for the
// renderer's (ONE, ONE_MINUS_SRC_ALPHA) blend, which then equals VTK's
// (SRC_ALPHA, ONE_MINUS_SRC_ALPHA) on colour and (ONE, ONE_MINUS_SRC_ALPHA) on alpha.
// With opaque surfaces (SURFACE_DEPTH 1) the fragment is first depth-tested as VTK tests it
// against the opaque geometry's depth buffer (GL_LEQUAL, depth writes off): kept whole if
// its depth (the fan triangle's, gl_FragCoord.z) is at most the surface's, else dropped.
//
// In:  v_color, v_opacity, v_thickness (vtk_pt.vert); SURFACE_DEPTH: u_limit (R32F, per
//      pixel the nearest surface's eye depth, 3e38 none; tetvr.gl.surfaces), u_proj.
// Out: f_color, premultiplied RGBA.
// Defines: SURFACE_DEPTH.

#ifndef SURFACE_DEPTH
#define SURFACE_DEPTH 0
#endif

noperspective in vec3 v_color;
noperspective in float v_opacity;
noperspective in float v_thickness;

#if SURFACE_DEPTH
uniform sampler2D u_limit;
uniform mat4 u_proj;
#endif

out vec4 f_color;

void main() {
#if SURFACE_DEPTH
    float t = texelFetch(u_limit, ivec2(gl_FragCoord.xy), 0).r;
    if (t < 3.0e38) {
        vec4 clip = u_proj * vec4(0.0, 0.0, -t, 1.0);  // the surface's point on this pixel's ray
        if (gl_FragCoord.z > 0.5 * clip.z / clip.w + 0.5) discard;
    }
#endif
    float opacity = 1.0 - exp(-1.0 * v_opacity * v_thickness);
    if (opacity <= 0.0) discard;
    f_color = vec4(v_color * opacity, opacity);
}

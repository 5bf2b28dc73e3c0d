#version 430
// vtk_pt.frag -- VTK parity (optics="vtk"): VTK's vtkglProjectedTetrahedraFS, the product of
// the interpolated opacity and thickness in one exponential, premultiplied for the
// renderer's (ONE, ONE_MINUS_SRC_ALPHA) blend, which then equals VTK's
// (SRC_ALPHA, ONE_MINUS_SRC_ALPHA) on colour and (ONE, ONE_MINUS_SRC_ALPHA) on alpha.
//
// In:  v_color, v_opacity, v_thickness (vtk_pt.vert).
// Out: f_color, premultiplied RGBA.

noperspective in vec3 v_color;
noperspective in float v_opacity;
noperspective in float v_thickness;

out vec4 f_color;

void main() {
    float opacity = 1.0 - exp(-1.0 * v_opacity * v_thickness);
    if (opacity <= 0.0) discard;
    f_color = vec4(v_color * opacity, opacity);
}

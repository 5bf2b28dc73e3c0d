#version 430
// vtk_pt.vert -- VTK parity (optics="vtk"): passes through the fan vertices that
// classify_vtk.comp wrote, as VTK's vtkglProjectedTetrahedraVS does: position in NDC with
// w = 1, so colour, opacity and thickness are interpolated linearly in screen space, and
// depth too: GL clips the fan at the near and far planes as it clips VTK's, and
// vtk_pt.frag depth-tests it against the opaque surfaces.
//
// In:  a FanVertex (common.glsl) as vertex attributes: in_ndc, in_exact (here the bits of
//      the NDC depth), in_chord (the thickness over the unit distance; 0 but at the thick
//      vertex), in_segment (r, g, b, opacity).
// Out: gl_Position = (in_ndc, depth, 1); noperspective v_color, v_opacity, v_thickness.

in vec2 in_ndc;
in int in_exact;
in float in_chord;
in vec4 in_segment;

noperspective out vec3 v_color;
noperspective out float v_opacity;
noperspective out float v_thickness;

void main() {
    gl_Position = vec4(in_ndc, intBitsToFloat(in_exact), 1.0);
    v_color = in_segment.rgb;
    v_opacity = in_segment.a;
    v_thickness = in_chord;
}

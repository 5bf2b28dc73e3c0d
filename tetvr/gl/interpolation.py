"""Whether a GL's rasteriser interpolates varyings exactly enough, or the fan shaders must
interpolate themselves.

A rasteriser snaps vertex positions to its sub-pixel grid (8 bits on common GPUs) to decide
coverage. Mesa's llvmpipe sets up the attributes' planes from the unsnapped float positions;
a rasteriser that sets them up from the snapped ones moves every attribute by up to 1/512
pixel times its slope. Projected tetrahedra's fan triangles carry the thickness of a tet's
segment, zero on its silhouette and largest at the thick vertex: on tets a few pixels wide
that is a relative error of a few 1e-4 in thickness, several 1/255 in the pixels of opaque
or thin tets. Where :func:`interpolate_in_shader` says so, ``shaders/fan_varyings.glsl``
computes the fragment's values from its triangle's three fan vertices in float32 instead.
The probe draws one triangle with off-grid corners whose varying is its corners' window
position, and measures, at every covered pixel, how far the interpolated value lies from
the pixel's centre.

``TETVR_INTERPOLATE`` (``"shader"`` or ``"rasteriser"``) overrides the probe (tests run
the shader's interpolation on llvmpipe with it).
"""

from __future__ import annotations

import weakref
from typing import Any

import numpy as np

from tetvr.gl.context import current_in_thread
from tetvr.gl.filtering import PROBE_BINDING, filter_in_shader, shader_override

__all__ = ["exactness_defines", "interpolate_in_shader", "interpolation_error", "probe_interpolation", "INTERPOLATE_ENV",
           "EXACT_ENOUGH_PX"]

#: The environment variable that overrides the probe: "shader" or "rasteriser".
INTERPOLATE_ENV = "TETVR_INTERPOLATE"
#: The largest error of the probe, in pixels, that counts as interpolation from float
#: positions: float32 rounding at 64 pixels is ~1e-5; snapping to 1/256 pixel up to 2e-3.
EXACT_ENOUGH_PX = 2.0e-4
#: The probe's target, pixels a side.
PROBE_SIZE = 64

_VERTEX = """
#version 430
uniform vec2 u_size;
// Corners off any power-of-two sub-pixel grid.
const vec2 corners[3] = vec2[3](vec2(-0.91234567, -0.87654321), vec2(0.83117117, -0.61913913),
                                vec2(-0.31771771, 0.93313313));
noperspective out vec2 v_window;
void main() {
    vec2 ndc = corners[gl_VertexID];
    v_window = (ndc * 0.5 + 0.5) * u_size;
    gl_Position = vec4(ndc, 0.0, 1.0);
}
"""

_FRAGMENT = f"""
#version 430
noperspective in vec2 v_window;
layout(std430, binding = {PROBE_BINDING}) buffer Out {{ uint error_bits; uint covered; }};
out vec4 f_color;
void main() {{
    vec2 e = abs(v_window - gl_FragCoord.xy);
    atomicMax(error_bits, floatBitsToUint(max(e.x, e.y)));  // non-negative floats order as their bits
    atomicAdd(covered, 1u);
    f_color = vec4(0.0);
}}
"""

_errors: "weakref.WeakKeyDictionary[Any, float]" = weakref.WeakKeyDictionary()


def probe_interpolation(ctx: Any) -> float:
    """The largest distance, in pixels, between a pixel's centre and the window position
    ``ctx``'s rasteriser interpolates there from a triangle's corners. Uses its own target
    and the probe's storage binding; the framebuffer bound before (the default one if none) is
    bound again."""
    with current_in_thread(ctx):
        previous = ctx.fbo
        target = ctx.renderbuffer((PROBE_SIZE, PROBE_SIZE), 4, dtype="f1")
        fbo = ctx.framebuffer(color_attachments=[target])
        out = ctx.buffer(reserve=8)
        prog = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        vao = ctx.vertex_array(prog, [])
        try:
            out.write(b"\0" * 8)
            out.bind_to_storage_buffer(PROBE_BINDING)
            prog["u_size"].value = (float(PROBE_SIZE), float(PROBE_SIZE))
            fbo.use()
            vao.render(vertices=3)
            ctx.memory_barrier()
            error_bits, covered = np.frombuffer(out.read(), dtype=np.uint32)
        finally:
            # Bound again before the probe's own is released: moderngl binds its last bound
            # framebuffer again after making one, which must not be a deleted one.
            (previous if previous is not None else ctx.detect_framebuffer(0)).use()
            for obj in (vao, prog, out, fbo, target):
                obj.release()
    if covered == 0:
        raise RuntimeError("the interpolation probe's triangle covered no pixel: the GL drew nothing")
    return float(np.array([error_bits], dtype=np.uint32).view(np.float32)[0])


def interpolate_in_shader(ctx: Any) -> bool:
    """Whether the fan shaders on ``ctx`` compute their varyings themselves
    (``INTERPOLATE_IN_SHADER``): where its rasteriser's interpolation errs by more than
    :data:`EXACT_ENOUGH_PX`, or where ``TETVR_INTERPOLATE=shader``. Probed once per context."""
    forced = shader_override(INTERPOLATE_ENV, "rasteriser")
    return forced if forced is not None else interpolation_error(ctx) > EXACT_ENOUGH_PX


def interpolation_error(ctx: Any) -> float:
    """:func:`probe_interpolation` of ``ctx``, probed once per context."""
    error = _errors.get(ctx)
    if error is None:
        error = _errors[ctx] = probe_interpolation(ctx)
    return error


def exactness_defines(ctx: Any) -> dict[str, int]:
    """The defines that have the shaders on ``ctx`` do what its GL does inexactly: 3D textures'
    linear filtering (``FILTER_IN_SHADER``, :mod:`tetvr.gl.filtering`) and the fans'
    interpolation (``INTERPOLATE_IN_SHADER``)."""
    return {"FILTER_IN_SHADER": int(filter_in_shader(ctx)), "INTERPOLATE_IN_SHADER": int(interpolate_in_shader(ctx))}

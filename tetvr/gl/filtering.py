"""Whether a GL's texture units filter exactly enough, or the shaders must filter themselves.

Some GPUs' texture units weigh the texels of a linear fetch with 8-bit fractions (NVIDIA's:
CUDA's programming guide says so of its linear filtering, for every texel format). A
trilinear fetch of the pre-integration table or of a CT volume then errs by up to 1/512 of
the step between neighbouring texels, whatever the texels' own precision: on an opaque
transfer function's table, several 1/255 in a pixel. ``shaders/filter.glsl`` filters in
the shader instead (eight ``texelFetch``, float32 weights) where :func:`filter_in_shader`
says so: a probe that samples a two-texel ramp at 1,021 points between the texel centres and
compares with the exact line. Mesa's llvmpipe weighs in float: it filters in the texture
unit.

``TETVR_FILTER`` (``"shader"`` or ``"texture"``) overrides the probe (tests run the shader's
filtering on llvmpipe with it).
"""

from __future__ import annotations

import os
import weakref
from typing import Any

import numpy as np

from tetvr.gl.context import current_in_thread

__all__ = ["filter_in_shader", "filter_error", "probe_error", "shader_override", "FILTER_ENV", "EXACT_ENOUGH"]

#: The environment variable that overrides the probe: "shader" or "texture".
FILTER_ENV = "TETVR_FILTER"
#: The largest error of the probe's ramp (0 to 1) that counts as exact weights: float32
#: weights err by ~1e-7; 8-bit ones by up to 2e-3.
EXACT_ENOUGH = 1e-5
#: Points the probe samples between the two texel centres.
PROBE_POINTS = 1021
#: The texture unit and storage binding the probe uses: none that the renderers bind (units
#: 0-11, bindings 0-6), so that a probe of a context in use leaves their bindings as they were.
PROBE_UNIT, PROBE_BINDING = 15, 7

_PROBE = f"""
#version 430
layout(local_size_x = 64) in;
uniform sampler3D u_ramp;
uniform int u_count;
layout(std430, binding = {PROBE_BINDING}) buffer Out {{ float v[]; }};
void main() {{
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    float t = float(i) / float(u_count - 1);
    // Texel centres at x = 0.25 and 0.75 of a 2-texel-wide texture.
    v[i] = textureLod(u_ramp, vec3(0.25 + 0.5 * t, 0.5, 0.5), 0.0).r;
}}
"""

_errors: "weakref.WeakKeyDictionary[Any, float]" = weakref.WeakKeyDictionary()


def probe_error(ctx: Any) -> float:
    """The largest error of ``ctx``'s linear filtering along a 0-to-1 ramp between two texel
    centres (float32 texels), against the exact line."""
    import moderngl

    with current_in_thread(ctx):
        tex = ctx.texture3d((2, 1, 1), 1, np.array([0.0, 1.0], dtype=np.float32).tobytes(), dtype="f4")
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        out = ctx.buffer(reserve=4 * PROBE_POINTS)
        prog = ctx.compute_shader(_PROBE)
        try:
            tex.use(PROBE_UNIT)
            prog["u_ramp"].value = PROBE_UNIT
            prog["u_count"].value = PROBE_POINTS
            out.bind_to_storage_buffer(PROBE_BINDING)
            prog.run(group_x=(PROBE_POINTS + 63) // 64)
            got = np.frombuffer(out.read(), dtype=np.float32)
        finally:
            for obj in (prog, out, tex):
                obj.release()
    want = np.linspace(0.0, 1.0, PROBE_POINTS)
    return float(np.abs(got - want).max())


def filter_in_shader(ctx: Any) -> bool:
    """Whether the shaders on ``ctx`` filter 3D textures themselves (``FILTER_IN_SHADER``):
    where its texture units' linear filtering errs by more than :data:`EXACT_ENOUGH`, or
    where ``TETVR_FILTER=shader``. Probed once per context, when its first program is
    made (the probe's texture unit and storage binding are none a renderer uses, so a
    frame under way keeps its bindings)."""
    forced = shader_override(FILTER_ENV, "texture")
    return forced if forced is not None else filter_error(ctx) > EXACT_ENOUGH


def shader_override(env: str, other: str) -> bool | None:
    """What the environment variable ``env`` says of a probe's decision: True for
    ``"shader"``, False for ``other``, None where it is unset; any other value is refused
    with a ``ValueError`` naming the variable and the value."""
    forced = os.environ.get(env, "").strip().lower()
    if forced in ("shader", other):
        return forced == "shader"
    if forced:
        raise ValueError(f"{env} must be 'shader' or '{other}', got {forced!r}")
    return None


def filter_error(ctx: Any) -> float:
    """:func:`probe_error` of ``ctx``, probed once per context."""
    error = _errors.get(ctx)
    if error is None:
        error = _errors[ctx] = probe_error(ctx)
    return error

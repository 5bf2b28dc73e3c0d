"""tetvr.gl.filtering and shaders/filter.glsl: the shader's own trilinear filtering, used
where a GL's texture units weigh texels with 8-bit fractions (NVIDIA's GPUs).

llvmpipe filters exactly in its texture units, so here the shader's filtering is forced
(``TETVR_FILTER=shader``) and must give the texture unit's images: the table's lookups in
every variant (linear and Catmull-Rom slices, warped nodes, a stepped map, 8-bit) for both
methods, and the CT caster's trilinear and cubic samples. On a GL whose texture unit is not
exact the two differ by its error: on an H200 (bench/device_check.sh) the probe's error is
1/512, the shader filters there, and the images differed by 1e-5 to 7e-4.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import tetvr
from tetvr import Camera, RenderSettings
from tetvr.gl.filtering import EXACT_ENOUGH, FILTER_ENV, filter_in_shader, probe_error
from tetvr.mesh import synthetic
from tetvr.render import default_transfer_function

from .test_discretized_maps import _paraview_map

pytestmark = pytest.mark.gl

#: Shader against texture unit on llvmpipe, where both filter in float32: the same
#: arithmetic up to the order of the multiply-adds.
SAME = 2e-6
#: An 8-bit table's texels are unorm8, which llvmpipe's texture unit filters in fixed point
#: (0.91/255 from the shader's float32 weights here).
SAME_UINT8 = 1.5 / 255


@pytest.fixture(scope="module")
def texture_error():
    """This GL's linear filtering error (the probe's): where it is not exact (an NVIDIA GPU:
    1/512), the texture unit's images differ from the shader's by up to about that much."""
    from tetvr.gl.context import create_context

    ctx = create_context()
    try:
        return probe_error(ctx)
    finally:
        ctx.release()


def _bar(exact_bar: float, texture_error: float) -> float:
    return exact_bar if texture_error <= EXACT_ENOUGH else max(exact_bar, 2.0 * texture_error)


@pytest.fixture(scope="module")
def scene():
    mesh = synthetic.cube(5)
    return mesh, Camera.fit(mesh, direction=(0.6, -0.5, -1.0)), default_transfer_function(mesh, opacity=0.9)


def test_the_probe_says_what_this_gl_does():
    """llvmpipe's linear filtering is exact to float32: the probe's error ~1e-7 and the
    texture unit filters; whatever the GL, the decision follows the error."""
    from tetvr.gl.context import create_context

    ctx = create_context()
    try:
        error = probe_error(ctx)
        assert filter_in_shader(ctx) == (error > EXACT_ENOUGH)
        if "llvmpipe" in ctx.info["GL_RENDERER"]:
            assert error < 1e-6 and not filter_in_shader(ctx)
        else:  # pragma: no cover - only on a GPU
            assert error < 1e-6 or error > 1e-4  # float weights or 8-bit ones, nothing between
    finally:
        ctx.release()


def test_a_bad_override_is_refused(scene, monkeypatch):
    mesh, camera, tf = scene
    monkeypatch.setenv(FILTER_ENV, "bilinear")
    with tetvr.Renderer() as r:
        with pytest.raises(ValueError, match=r"TETVR_FILTER must be 'shader' or 'texture', got 'bilinear'"):
            r.render(mesh, camera, tf, size=(8, 8))
        monkeypatch.delenv(FILTER_ENV)
        assert r.render(mesh, camera, tf, size=(8, 8))[..., 3].max() > 0


@pytest.mark.parametrize("method", ["raymarch", "projected"])
@pytest.mark.parametrize("variant", [{}, {"table_filter": "cubic"}, {"table_warp": "on"}, {"table_dtype": "uint8"},
                                     "stepped"], ids=["linear", "cubic", "warp", "uint8", "stepped"])
def test_the_shader_filters_the_table_as_the_texture_unit(scene, texture_error, monkeypatch, method, variant):
    mesh, camera, tf = scene
    stepped = variant == "stepped"
    if stepped:  # a map that steps at its nodes: the lookup cut at them (lookup_steps.glsl)
        tf, variant = dataclasses.replace(_paraview_map(mesh.scalar_range, bands=16), unit_distance=0.2), {}
    images = {}
    for where in ("texture", "shader"):
        monkeypatch.setenv(FILTER_ENV, where)
        with tetvr.Renderer(RenderSettings(method=method, **variant)) as renderer:
            images[where] = renderer.render(mesh, camera, tf, size=(48, 48))
            assert (renderer.table(mesh, tf).steps is not None) == stepped
    assert images["texture"][..., 3].max() > 0.3
    bar = _bar(SAME_UINT8 if variant.get("table_dtype") == "uint8" else SAME, texture_error)
    assert np.abs(images["shader"] - images["texture"]).max() < bar


@pytest.mark.parametrize("interpolation", ["linear", "cubic"])
def test_the_shader_filters_the_volume_as_the_texture_unit(texture_error, monkeypatch, interpolation):
    from tetvr import TransferFunction
    from tetvr.gl.raycaster import Raycaster
    from tetvr.reference.volume import RaycastSettings
    from tetvr.volume.volume import Volume

    n = 12
    x = np.linspace(-1.0, 1.0, n)
    data = np.exp(-4.0 * (x[:, None, None] ** 2 + x[None, :, None] ** 2 + x[None, None, :] ** 2)).astype(np.float32)
    vol = Volume.from_array(data, spacing=(1.0, 1.0, 1.0))
    tf = TransferFunction(color=((0.0, 0.1, 0.2, 0.9), (1.0, 1.0, 0.8, 0.1)), opacity=((0.0, 0.0), (0.4, 0.1), (1.0, 0.9)),
                          unit_distance=2.0)
    cam = Camera.fit(vol, direction=(-1.0, -0.5, -0.8))
    settings = RaycastSettings(interpolation=interpolation, termination=1.0)
    images = {}
    for where in ("texture", "shader"):
        monkeypatch.setenv(FILTER_ENV, where)
        rc = Raycaster()
        try:
            images[where] = rc.render(vol, cam, tf, size=(40, 40), settings=settings)
        finally:
            rc.release()
    assert images["texture"][..., 3].max() > 0.3
    assert np.abs(images["shader"] - images["texture"]).max() < _bar(SAME, texture_error)


def test_probing_a_context_in_use_leaves_its_frames_alone(scene, monkeypatch):
    """The probe binds a texture unit and a storage binding that no renderer uses: probing a
    renderer's context between frames (a borrowed context's first program, say) changes
    nothing in the next frame."""
    import tetvr

    monkeypatch.delenv(FILTER_ENV, raising=False)
    mesh, camera, tf = scene
    with tetvr.Renderer(RenderSettings(method="raymarch")) as r:
        before = r.render(mesh, camera, tf, size=(48, 48))
        probe_error(r.ctx)
        after = r.render(mesh, camera, tf, size=(48, 48))
    assert before[..., 3].max() > 0.3 and np.array_equal(before, after)

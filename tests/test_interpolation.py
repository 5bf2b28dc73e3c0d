"""tetvr.gl.interpolation and shaders/fan_varyings.glsl: projected tetrahedra's fan varyings
computed in the shader from the triangle's vertices, used where a GL's rasteriser
interpolates from vertex positions snapped to its sub-pixel grid.

llvmpipe interpolates from the float positions, so here the shader's interpolation is forced
(``TETVR_INTERPOLATE=shader``) and must give the rasteriser's images (perspective, parallel,
without perspective correction, the eye inside, draw batches, the depth extent of fusion).
On a GL whose interpolation is inexact the shader's images must be at least as close to the
exact reference as the rasteriser's.
"""

from __future__ import annotations

import numpy as np
import pytest

import tetvr
from tetvr import Camera, RenderSettings
from tetvr.gl.interpolation import EXACT_ENOUGH_PX, INTERPOLATE_ENV, interpolate_in_shader, probe_interpolation
from tetvr.mesh import synthetic
from tetvr.reference.tets import render_reference
from tetvr.render import default_transfer_function

pytestmark = pytest.mark.gl

#: Shader against rasteriser where both interpolate from float positions: the same planes,
#: rounded otherwise (1.7e-5 on cube(12), 6.9e-5 on bluntfin at 256x256).
SAME = 2e-4
PT = RenderSettings(method="projected")


@pytest.fixture(scope="module")
def rasteriser_error():
    """This GL's interpolation error in pixels (the probe's)."""
    from tetvr.gl.context import create_context

    ctx = create_context()
    try:
        return probe_interpolation(ctx)
    finally:
        ctx.release()


@pytest.fixture(scope="module")
def mesh():
    return synthetic.cube(5)


def _both(monkeypatch, render):
    images = {}
    for where in ("rasteriser", "shader"):
        monkeypatch.setenv(INTERPOLATE_ENV, where)
        images[where] = render()
    return images


def _check(images, rasteriser_error, want=None):
    assert np.all(np.isfinite(images["shader"]))
    if rasteriser_error <= EXACT_ENOUGH_PX:
        assert np.abs(images["shader"] - images["rasteriser"]).max() < SAME
    else:  # pragma: no cover - only on a GPU whose rasteriser interpolates from snapped positions
        assert want is not None
        errors = {k: np.abs(v - want).max() for k, v in images.items()}
        assert errors["shader"] <= errors["rasteriser"] + 1e-5, errors


def test_the_probe_says_what_this_gl_does(monkeypatch):
    """llvmpipe interpolates from float positions: the probe's error ~4e-6 pixel and the
    rasteriser's values are used; whatever the GL, the decision follows the error."""
    from tetvr.gl.context import create_context

    monkeypatch.delenv(INTERPOLATE_ENV, raising=False)
    ctx = create_context()
    try:
        error = probe_interpolation(ctx)
        assert interpolate_in_shader(ctx) == (error > EXACT_ENOUGH_PX)
        if "llvmpipe" in ctx.info["GL_RENDERER"]:
            assert error < 2e-5 and not interpolate_in_shader(ctx)
    finally:
        ctx.release()


def test_a_bad_override_is_refused(mesh, monkeypatch):
    camera, tf = Camera.fit(mesh), default_transfer_function(mesh)
    monkeypatch.setenv(INTERPOLATE_ENV, "nearest")
    with tetvr.Renderer(PT) as r:
        with pytest.raises(ValueError, match=r"TETVR_INTERPOLATE must be 'shader' or 'rasteriser', got 'nearest'"):
            r.render(mesh, camera, tf, size=(8, 8))
        monkeypatch.delenv(INTERPOLATE_ENV)
        assert r.render(mesh, camera, tf, size=(8, 8))[..., 3].max() > 0


@pytest.mark.parametrize("view", ["perspective", "parallel", "uncorrected", "inside"])
def test_the_shader_interpolates_the_fans_as_the_rasteriser(mesh, rasteriser_error, monkeypatch, view):
    settings = RenderSettings(method="projected", perspective_correct=view != "uncorrected")
    if view == "inside":  # near-plane tets on the exact path, the rest on fans
        camera = Camera(position=(0.1, -0.05, 0.2), focal_point=(0.8, 0.3, -0.6), view_angle=70.0,
                        clipping_range=(0.05, 6.0))
    else:
        camera = Camera.fit(mesh, direction=(0.6, -0.5, -1.0), parallel=view == "parallel")
    tf = default_transfer_function(mesh, opacity=0.9)
    with tetvr.Renderer(settings) as r:
        images = _both(monkeypatch, lambda: r.render(mesh, camera, tf, size=(48, 40)))
    assert images["rasteriser"][..., 3].max() > 0.3
    _check(images, rasteriser_error, render_reference(mesh, camera, tf, (48, 40)))


def test_each_draw_batch_reads_its_own_fans(mesh, monkeypatch):
    """gl_PrimitiveID counts from each draw call: the fans are bound from the batch's first."""
    import tetvr.gl.projected as projected

    monkeypatch.setenv(INTERPOLATE_ENV, "shader")
    camera, tf = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0)), default_transfer_function(mesh, opacity=0.9)
    with tetvr.Renderer(PT) as r:
        whole = r.render(mesh, camera, tf, size=(40, 40))
        monkeypatch.setattr(projected, "_DRAW_BATCH", 64)  # cube(5): 750 tets, 12 batches
        batched = r.render(mesh, camera, tf, size=(40, 40))
    assert whole[..., 3].max() > 0.3 and np.array_equal(whole, batched)


@pytest.mark.parametrize("parallel", [False, True])
def test_the_depth_extent_is_interpolated_as_by_the_rasteriser(mesh, rasteriser_error, monkeypatch, parallel):
    camera = Camera.fit(mesh, direction=(-0.4, -0.3, -1.0), parallel=parallel, zoom=1.3)
    with tetvr.Renderer(PT) as r:
        extents = _both(monkeypatch, lambda: np.stack(r.depth_extent(mesh, camera, size=(40, 32))))
    covered = np.isfinite(extents["rasteriser"])
    assert covered.mean() > 0.1 and np.array_equal(covered, np.isfinite(extents["shader"]))
    if rasteriser_error <= EXACT_ENOUGH_PX:
        assert np.abs(extents["shader"][covered] - extents["rasteriser"][covered]).max() < SAME


def test_probing_a_context_in_use_leaves_its_frames_alone(mesh, monkeypatch):
    """The probe draws into its own target and binds again the framebuffer bound before: a
    probe of a renderer's context between frames changes nothing in either method's next frame."""
    monkeypatch.delenv(INTERPOLATE_ENV, raising=False)
    camera, tf = Camera.fit(mesh, direction=(0.6, -0.5, -1.0)), default_transfer_function(mesh, opacity=0.9)
    for method in ("projected", "raymarch"):
        with tetvr.Renderer(RenderSettings(method=method)) as r:
            before = r.render(mesh, camera, tf, size=(48, 48))
            probe_interpolation(r.ctx)
            after = r.render(mesh, camera, tf, size=(56, 48))  # new targets made after the probe
            again = r.render(mesh, camera, tf, size=(48, 48))
        assert before[..., 3].max() > 0.3 and after[..., 3].max() > 0.3 and np.array_equal(before, again)

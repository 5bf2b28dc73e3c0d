"""Tet marching without a table (RenderSettings(integration="exact")) against the reference.

Each segment is cut at the transfer function's control points and integrated in closed
form and by 3-point Gauss-Legendre quadrature (shaders/raycast_exact.glsl), the
reference's model (tetvr.optics.model.integrate_pieces) in float32: what is left is float32
geometry and arithmetic, measured 2e-6..2.3e-5 per pixel here (PSNR 130-142 dB), against
the table's 3e-5..1.6e-3 on the same scenes. So a spiky transfer function is as exact as
a smooth one, and a segment cut in two by a brick plane integrates to what the whole
does: sort-last bricks composite to the single image within float32 rounding (5e-7)
except at a pixel or two per view where a ray grazes a corner (one image's rasterised
entry misses a sliver the other's does not; both within 2.5e-4 of the reference there).
"""

from __future__ import annotations

import numpy as np
import pytest

import tetvr
from tetvr import Camera, Clip, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.cluster.bricks import composite_over, kd_bricks
from tetvr.core.image import psnr
from tetvr.order.method import choose
from tetvr.reference.tets import render_reference

from .conftest import save_failure

SIZE = (64, 64)
MAX_ERROR = 1e-4
MIN_PSNR = 120.0


def _tfs(mesh: tetvr.TetMesh) -> dict[str, TransferFunction]:
    lo, hi = mesh.scalar_range
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    m, w = 0.5 * (lo + hi), 0.01 * (hi - lo)
    return {"smooth": TransferFunction.preset("viridis", (lo, hi), opacity=[(0, 0.2), (0.5, 0.6), (1, 0.9)],
                                              unit_distance=diag / 4),
            "opaque spike": TransferFunction.preset("cool-to-warm", (lo, hi),
                                                    opacity=[(lo, 0.0), (m - w, 0.0), (m, 1.0), (m + w, 0.0),
                                                             (hi, 0.0)], unit_distance=diag / 20)}


@pytest.fixture(scope="module")
def exact():
    with tetvr.Renderer(RenderSettings(integration="exact")) as r:
        yield r
        with r.ctx:
            assert r.ctx.error == "GL_NO_ERROR"


def _check(name, got, want):
    assert np.all(np.isfinite(got))
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    value = psnr(got, want)
    if err.max() > MAX_ERROR or value < MIN_PSNR:
        where = save_failure(f"exact_{name}", got, want)
        pytest.fail(f"{name}: max error {err.max():.3g}, {np.count_nonzero(err > 1 / 255)} pixels beyond 1/255, "
                    f"{value:.1f} dB ({where})")


def test_settings_say_where_exact_integration_applies():
    assert choose(RenderSettings(integration="exact")) == "raymarch"
    assert choose(RenderSettings(integration="exact"), synthetic.cube(2)) == "raymarch"
    with pytest.raises(ValueError, match="tet marching"):
        RenderSettings(integration="exact", method="projected")
    with pytest.raises(ValueError, match="optics='exact'"):
        RenderSettings(integration="exact", optics="linear")
    with pytest.raises(ValueError, match="integration must be one of"):
        RenderSettings(integration="quadrature")
    assert RenderSettings.from_dict(RenderSettings(integration="exact").to_dict()).integration == "exact"


@pytest.mark.gl
@pytest.mark.parametrize("view", ["perspective", "parallel", "inside"])
def test_exact_integration_matches_the_reference(exact, view):
    mesh = synthetic.cube(6)
    lo, hi = mesh.bounds
    c = 0.5 * (lo + hi)
    if view == "inside":
        cam = Camera(position=tuple(c + 0.1 * (hi - lo)), focal_point=tuple(c - (hi - lo)), view_up=(0, 0, 1),
                     view_angle=60, clipping_range=(0.01, 10))
    else:
        cam = Camera.fit(mesh, parallel=view == "parallel")
    for name, tf in _tfs(mesh).items():
        want = render_reference(mesh, cam, tf, SIZE)
        assert want[..., 3].max() > 0.1
        _check(f"{view}_{name}", exact.render(mesh, cam, tf, size=SIZE), want)


@pytest.mark.gl
def test_exact_integration_with_cell_data_and_a_clip(exact):
    rng = np.random.default_rng(1)
    mesh = synthetic.cube(5)
    cells = mesh.with_cell_scalars(rng.uniform(*mesh.scalar_range, mesh.n_tets), "c")
    cam = Camera.fit(mesh)
    tf = _tfs(mesh)["smooth"]
    _check("cell_data", exact.render(cells, cam, tf, size=SIZE), render_reference(cells, cam, tf, SIZE))
    clip = Clip.plane(mesh.bounds.mean(axis=0), (1, 0.2, 0.1))
    _check("clip", exact.render(mesh, cam, tf, size=SIZE, clip=clip), render_reference(mesh, cam, tf, SIZE, clip=clip))


@pytest.mark.gl
@pytest.mark.parametrize("view", ["perspective", "parallel", "inside"])
def test_cut_bricks_composite_to_the_single_image(exact, view):
    """Interlocking rings (non-convex) cut into 2, 4 and 8 bricks: the composite equals the
    single image to 1e-5 at all but two pixels, where one of the two misses a corner the
    other catches (each within 2.5e-4 of the reference; measured: 1 or 2 pixels, 1.4e-5 to
    2.4e-4 apart, the single image the further from the reference at all but one)."""
    from tests.test_distributed import _scene

    mesh = synthetic.interlocking_rings()
    camera, tf = _scene(mesh, view)
    size = (64, 48)
    whole = exact.render(mesh, camera, tf, size=size)
    ref = render_reference(mesh, camera, tf, size)
    for n in (2, 4, 8):
        tree = kd_bricks(mesh, n)
        assert tree.n_cut > 0
        parts = {b.index: exact.render(tree.brick_mesh(b), camera, tf, size=size) for b in tree.bricks()}
        got = composite_over([parts[i] for i in tree.visibility_order(camera)])
        apart = np.abs(got - whole).max(axis=-1)
        assert np.count_nonzero(apart > 1e-5) <= 2, (n, np.sort(apart.ravel())[-4:])
        for img in (got, whole):
            off = np.abs(img - ref).max(axis=-1)
            assert off.max() <= 2.5e-4 and np.count_nonzero(off > 1e-5) <= 2, (n, np.sort(off.ravel())[-4:])

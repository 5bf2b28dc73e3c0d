"""Culling (tetvr.order.cull): what it drops adds nothing to the image.

The GPU comparison is bit for bit: a culled cell either rasterises no fragment (outside
the frustum) or looks up table entries that are exactly zero (transparent, with the
table-filtering margin), and the centroid sort is stable, so the remaining cells are drawn
in the same order. The reference comparison allows 1e-6: dropping zero-length or
zero-opacity segments changes the order of the float sums in compositing, nothing more.
"""

from __future__ import annotations

import numpy as np
import pytest

from tetvr import Camera, TransferFunction
from tetvr.mesh import synthetic
from tetvr.order.cull import (
    CullStats,
    gpu_scalar_margin,
    outside_view,
    submesh,
    transparent_cells,
    visible_cells,
    zero_opacity,
)
from tetvr.reference.tets import render_reference
from tetvr.reference.segments import ray_segments

SIZE = (64, 48)


@pytest.fixture(autouse=True)
def _raise_on_float_errors():
    with np.errstate(all="raise"):
        yield


def _scene(*, parallel: bool, ramp_at: float = 0.4537):
    mesh = synthetic.cube(9)
    lo, hi = mesh.scalar_range
    # Zero opacity below a ramp that starts between the table's nodes, and a gap above.
    opacity = [(0.0, 0.0), (ramp_at, 0.0), (ramp_at + 0.01, 0.9), (0.8, 0.9), (0.81, 0.0), (1.0, 0.0)]
    tf = TransferFunction.preset("viridis", (lo, hi), opacity=opacity, unit_distance=0.2)
    camera = Camera.fit(mesh, direction=(-1.0, -0.5, -0.8), zoom=3.5, parallel=parallel)
    return mesh, tf, camera


def test_zero_opacity_matches_dense_sampling():
    rng = np.random.default_rng(0)
    tf = TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)),
                          opacity=((0.1, 0.0), (0.3, 0.0), (0.35, 0.5), (0.5, 0.0), (0.7, 0.0), (0.7001, 0.2), (0.9, 0.0)))
    lo = rng.uniform(-0.2, 1.2, 1000)
    hi = lo + rng.exponential(0.1, 1000)
    got = zero_opacity(tf, lo, hi)
    t = np.linspace(0, 1, 2001)
    samples = lo[:, None] + t[None, :] * (hi - lo)[:, None]
    _, a = tf.evaluate(samples)
    bp = np.array([p[0] for p in tf.opacity])
    inner = (bp[None, :] > lo[:, None]) & (bp[None, :] < hi[:, None])
    _, a_bp = tf.evaluate(bp)
    want = (a.max(axis=1) == 0) & ~np.any(inner & (a_bp[None, :] > 0), axis=1)
    assert np.array_equal(got, want)
    assert 0 < got.sum() < got.size


@pytest.mark.parametrize("parallel", [False, True])
def test_culled_cells_meet_no_ray(parallel):
    mesh, _, camera = _scene(parallel=parallel)
    out = outside_view(mesh, camera, size=SIZE)
    assert 0 < out.sum() < mesh.n_tets
    seg = ray_segments(mesh, camera, SIZE)
    assert not np.any(out[seg.tet]), "a cell culled as outside the view is crossed by a pixel ray"
    # Without the image size the left and right planes are not tested: fewer culled.
    assert outside_view(mesh, camera).sum() <= out.sum()


@pytest.mark.parametrize("parallel", [False, True])
def test_reference_image_unchanged_by_culling(parallel):
    mesh, tf, camera = _scene(parallel=parallel)
    ids, stats = visible_cells(mesh, camera, tf, size=SIZE)
    assert stats.n_outside_view > 0 and stats.n_transparent > 0
    assert stats.n_visible == ids.shape[0] == mesh.n_tets - stats.n_outside_view - stats.n_transparent
    full = render_reference(mesh, camera, tf, SIZE)
    part = render_reference(submesh(mesh, ids), camera, tf, SIZE)
    assert full[..., 3].max() > 0.5
    assert np.abs(full - part).max() < 1e-6


@pytest.mark.gl
@pytest.mark.parametrize("parallel", [False, True])
def test_gpu_image_bit_identical_with_only_visible_cells(renderer, parallel):
    mesh, tf, camera = _scene(parallel=parallel)
    margin = gpu_scalar_margin(mesh, tf, renderer.settings)
    ids, stats = visible_cells(mesh, camera, tf, size=SIZE, scalar_margin=margin)
    print(f"parallel={parallel}: {stats}")
    assert stats.n_outside_view > 0 and stats.n_transparent > 0
    full = renderer.render(mesh, camera, tf, size=SIZE)
    part = renderer.render(submesh(mesh, ids), camera, tf, size=SIZE)
    assert full[..., 3].max() > 0.5
    assert np.array_equal(full, part)


def test_margin_keeps_cells_whose_table_lookups_reach_the_ramp():
    mesh, tf, _ = _scene(parallel=True)
    margin = gpu_scalar_margin(mesh, tf)
    exact = transparent_cells(mesh, tf)
    padded = transparent_cells(mesh, tf, scalar_margin=margin)
    assert np.all(exact >= padded) and exact.sum() > padded.sum()


def test_submesh_keeps_what_sets_the_table():
    mesh, tf, camera = _scene(parallel=True)
    ids, _ = visible_cells(mesh, camera, tf, size=SIZE)
    sub = submesh(mesh, ids[::-1])
    assert sub.n_tets == ids.shape[0] and np.array_equal(sub.tets, mesh.tets[ids])
    assert sub.max_edge == mesh.max_edge and sub.scalar_range == mesh.scalar_range
    assert sub.points is mesh.points
    with pytest.raises(ValueError, match="nothing to render"):
        submesh(mesh, [])
    with pytest.raises(ValueError, match="cell ids"):
        submesh(mesh, [mesh.n_tets])


def test_options_and_validation():
    mesh, tf, camera = _scene(parallel=False)
    ids, stats = visible_cells(mesh, camera, tf, frustum=False, opacity=False)
    assert ids.shape[0] == mesh.n_tets and stats == CullStats(mesh.n_tets, 0, 0, mesh.n_tets, stats.seconds)
    assert stats.fraction_culled == 0.0
    with pytest.raises(ValueError, match="scalar_margin"):
        visible_cells(mesh, camera, tf, scalar_margin=-1.0)
    with pytest.raises(TypeError, match="camera must be a Camera"):
        visible_cells(mesh, None, tf)  # type: ignore[arg-type]


def test_renderer_cull_setting_keeps_the_image():
    """RenderSettings(cull=True): fewer cells drawn, the same image bit for bit."""
    import tetvr
    from tetvr import Camera, RenderSettings, TransferFunction
    from tetvr.mesh import synthetic

    mesh = synthetic.cube(6)
    tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=[(0, 0), (0.45, 0), (0.7, 0.8), (1, 0.9)],
                                 unit_distance=0.3)
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0), zoom=2.0)
    for sort in ("centroid", "mpvonc"):
        with tetvr.Renderer(RenderSettings(sort=sort, method="projected")) as a, \
                tetvr.Renderer(RenderSettings(sort=sort, cull=True, method="projected")) as b:
            full = a.render(mesh, cam, tf, size=(64, 64))
            culled = b.render(mesh, cam, tf, size=(64, 64))
            assert b.last_stats.n_culled > mesh.n_tets // 4
            assert np.array_equal(full, culled)

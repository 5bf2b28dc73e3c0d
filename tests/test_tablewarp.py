"""Warped pre-integration tables (tetvr.optics.tablewarp, issue 22 item 3): nodes where the
transfer function varies, the warp texture's node index, the entries at uneven nodes, the
"auto" choice, and isosurface-like transfer functions on the GPU against the reference."""

from __future__ import annotations

import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.optics import preintegrate
from tetvr.optics.preintegrate import build_table
from tetvr.optics.table import check_table_size, table_build_bytes
from tetvr.optics.tablesize import choose_table_size
from tetvr.optics.tablewarp import WARP_CELLS, warp_cells, warped_nodes

from .conftest import save_failure

SPIKES = [(0.0, 0.0), (0.49, 0.0), (0.5, 0.9), (0.51, 0.0), (0.69, 0.0), (0.7, 0.9), (0.71, 0.0), (1.0, 0.0)]


def _spiky(lo=0.0, hi=1.0, unit_distance=0.05):
    return TransferFunction.preset("cool-to-warm", (lo, hi), opacity=SPIKES, unit_distance=unit_distance)


def _quadrature(tf, s0, s1, d, n=40000):
    """Premultiplied RGBA of a segment by midpoint compositing of n steps (independent of the table)."""
    s = s0 + (s1 - s0) * (np.arange(n) + 0.5) / n
    c, a = tf.evaluate(s)
    step = -np.log1p(-np.clip(a, 0.0, 1 - 1e-6)) / tf.unit_distance * (d / n)
    before = np.exp(-np.concatenate([[0.0], np.cumsum(step)[:-1]]))
    return np.r_[(before * -np.expm1(-step)) @ c, -np.expm1(-step.sum())]


def test_nodes_hold_every_control_point_and_crowd_the_spikes():
    tf = _spiky()
    x = warped_nodes(tf, (0.0, 1.0), 128)
    assert x[0] == 0.0 and x[-1] == 1.0 and np.all(np.diff(x) >= 1.0 / WARP_CELLS * (1 - 1e-9))
    assert np.isin([0.49, 0.5, 0.51, 0.69, 0.7, 0.71], x).all()
    assert 128 <= x.size <= 128 + 8
    # Graded: a third of the nodes within 0.05 of a spike (a tenth of the range), and the
    # spacing grows with the distance from it (a segment running into a spike changes with
    # its front scalar on the scale of its own span) instead of jumping to the coarse one.
    near = np.min(np.abs(x[:, None] - np.array([0.5, 0.7])[None]), axis=1) < 0.05
    assert near.sum() > x.size / 3
    gap = np.diff(x)[np.searchsorted(x, [0.52, 0.56, 0.6]) - 1]
    assert gap[0] < gap[1] < gap[2]


def test_warp_texture_gives_the_exact_node_index():
    """lookup.glsl's arithmetic, in float32 as the GPU does it, against np.interp."""
    tf = _spiky(-3.0, 5.0)
    lo, hi = -3.0, 5.0
    nodes = warped_nodes(tf, (lo, hi), 96)
    w = warp_cells(nodes)
    rng = np.random.default_rng(7)
    s = np.concatenate([rng.uniform(lo - 1, hi + 1, 20000), nodes, nodes + 1e-7, nodes - 1e-7])
    x = ((s - lo) * (WARP_CELLS / (hi - lo))).astype(np.float32)
    c = np.clip(np.floor(x).astype(np.int64), 0, WARP_CELLS - 1)
    t = w[c]
    index = t[:, 1] + (x - t[:, 0]) * np.where(x < t[:, 0], t[:, 2], t[:, 3])
    index = np.clip(index, 0, nodes.size - 1)
    want = np.interp(s, nodes, np.arange(nodes.size))
    assert np.abs(index - want).max() < 2e-3  # float32 of x ~ 8192 cells: 1e-3 cell at most


def test_uneven_entries_match_quadrature():
    tf = _spiky()
    table = build_table(tf, (0.0, 1.0), 0.5, n_bins=40, n_slices=3, log_base=4.0, warp=True, encoding="premultiplied")
    x = table.nodes
    assert x is not None and table.n_bins == x.size
    pairs = [(0, x.size - 1), (x.size - 1, 0), (5, 30), (30, 5), (17, 18), (18, 17), (3, 3)]
    for k in (1, 3):
        for i, j in pairs:
            want = _quadrature(tf, x[i], x[j], table.thicknesses[k])
            np.testing.assert_allclose(table.data[k, j, i], want, atol=2e-4, err_msg=f"slice {k}, nodes {i} -> {j}")


def test_even_nodes_through_the_uneven_build_are_the_even_table(monkeypatch):
    """Two different algorithms (sliding window, per-front matrix products): the same table
    to float64 rounding (1e-14 measured), so float32 storage makes them (nearly) identical."""
    tf = _spiky()
    even = build_table(tf, (0.0, 1.0), 1.0, n_bins=48, n_slices=4)
    monkeypatch.setattr(preintegrate, "warped_nodes", lambda tf, rng, n: np.linspace(rng[0], rng[1], n))
    uneven = build_table(tf, (0.0, 1.0), 1.0, n_bins=48, n_slices=4, warp=True)
    np.testing.assert_allclose(uneven.data, even.data, rtol=0, atol=1e-6)


def test_lookup_beats_eight_times_the_even_nodes():
    """On segments in and around the spikes, 128 warped nodes err less than 1024 even ones."""
    tf = _spiky()
    rng = np.random.default_rng(3)
    sf, sb = rng.uniform(0.4, 0.8, (2, 200))
    d = np.exp(rng.uniform(np.log(1e-3), 0.0, 200))
    want = np.array([_quadrature(tf, *a, n=8000) for a in zip(sf, sb, d)])
    warped = build_table(tf, (0.0, 1.0), 1.0, n_bins=128, n_slices=8, log_base=1.5, warp=True)
    even = build_table(tf, (0.0, 1.0), 1.0, n_bins=1024, n_slices=8, log_base=1.5)
    e_w = np.abs(warped.lookup(sf, sb, d) - want).max()
    e_e = np.abs(even.lookup(sf, sb, d) - want).max()
    assert e_w < 0.03 and e_w < e_e, (e_w, e_e)


def test_auto_warps_spiky_transfer_functions_only():
    mesh = synthetic.cube(4)
    lo, hi = mesh.scalar_range
    smooth = TransferFunction.preset("viridis", (lo, hi), opacity=0.3)
    spiky = _spiky(lo, hi, 0.1)
    assert not choose_table_size(smooth, mesh, warp="auto").warp
    assert choose_table_size(spiky, mesh, warp="auto").warp
    assert not choose_table_size(spiky, mesh, warp="off").warp
    assert not RenderSettings(table_scalar_bins=256, table_thickness_slices=8).table_warp == "on"


def test_sizes_are_refused_before_anything_is_allocated():
    with pytest.raises(ValueError, match="table_scalar_bins=2048 with table_thickness_slices=64"):
        RenderSettings(table_scalar_bins=2048, table_thickness_slices=64)
    with pytest.raises(ValueError, match="table_warp"):
        RenderSettings(table_warp="yes")
    with pytest.raises(ValueError, match="optics='vtk'"):
        RenderSettings(table_warp="on", optics="vtk")
    assert table_build_bytes(128, 8, warp=True) >= 128 * 128 * 9 * 113  # measured with tracemalloc
    with pytest.raises(ValueError, match="n_bins=2048 with n_slices=64"):
        check_table_size(2048, 64, warp=True)
    with pytest.raises(ValueError, match="n_bins=2048 with n_slices=64"):
        build_table(_spiky(), (0.0, 1.0), 1.0, n_bins=2048, n_slices=64, warp=True)


def test_isosurface_like_tf_on_the_gpu_meets_the_bar(renderer):
    """Two opacity spikes 1 % of the range wide on a 1296-tet cube, 64x64, default settings
    (a warped table): max error 6.5e-4 and no pixel beyond 1/255 measured (87.7 dB; with
    even nodes, table_warp="off": 0.025, 615 pixels, 50.0 dB). Bars: 0.002, no pixel."""
    from tetvr.reference.tets import render_reference

    mesh = synthetic.cube(6)
    lo, hi = mesh.scalar_range
    cam = Camera.fit(mesh, direction=(-0.4, -0.3, -1.0))
    tf = _spiky(lo, hi, 0.1)
    ref = render_reference(mesh, cam, tf, (64, 64))
    img = renderer.render(mesh, cam, tf, size=(64, 64))
    assert renderer.table(mesh, tf).nodes is not None  # the default chose a warped table
    d = np.abs(img[..., :3].astype(np.float64) - ref[..., :3]).max(axis=-1)
    assert np.isfinite(img).all()
    if d.max() > 0.002 or np.sum(d > 1 / 255) > 0:
        save_failure(f"spiky_tf_{renderer.settings.method}", img, ref)
    assert d.max() <= 0.002 and np.sum(d > 1 / 255) == 0, (float(d.max()), int(np.sum(d > 1 / 255)))


def test_an_opaque_spike_is_followed_where_no_even_table_can():
    """Opacity 1 at the peak: extinction -ln(1 - a) is log-singular there, and a table's A
    interpolated between nodes misses it by a constant however close they are. A warped
    table takes alpha from the optical depth per cell and, within a cell, from the opacity
    at the nodes: constant-scalar segments at the peak are exact up to the float32 opacity
    (measured 2e-4 against 0.63 for 1024 even nodes), segments in and around the spike
    within 0.02 (measured 0.012; even: 0.13)."""
    tf = TransferFunction.preset("cool-to-warm", (0.0, 1.0), opacity=[(0, 0), (0.497, 0), (0.5, 1.0), (0.503, 0), (1, 0)],
                                 unit_distance=0.05)
    warped = build_table(tf, (0.0, 1.0), 1.0, n_bins=128, n_slices=8, log_base=1.5, warp=True)
    even = build_table(tf, (0.0, 1.0), 1.0, n_bins=1024, n_slices=8, log_base=1.5)
    d = np.array([0.001, 0.01, 0.05, 0.2])
    at_peak = np.full(d.shape, 0.5)
    want = np.array([_quadrature(tf, 0.5, 0.5, x, n=10) for x in d])
    e_w = np.abs(warped.lookup(at_peak, at_peak, d) - want).max()
    e_e = np.abs(even.lookup(at_peak, at_peak, d) - want).max()
    assert e_w < 1e-3 and e_e > 0.1, (e_w, e_e)
    rng = np.random.default_rng(5)
    sf, sb = rng.uniform(0.49, 0.51, (2, 150))
    dd = np.exp(rng.uniform(np.log(1e-3), np.log(0.3), 150))
    want = np.array([_quadrature(tf, *a, n=20000) for a in zip(sf, sb, dd)])
    e_w = np.abs(warped.lookup(sf, sb, dd) - want).max()
    e_e = np.abs(even.lookup(sf, sb, dd) - want).max()
    assert e_w < 0.02 and e_e > 5 * e_w, (e_w, e_e)


@pytest.fixture(scope="module")
def pipe_flow_opaque_spikes():
    """Pipe flow (170k tets, ../shared) seen from outside with two opaque spikes 0.3 % of the
    range wide at the field's 50th and 80th percentiles, and its reference image at 64x64."""
    import warnings

    import tetvr
    from tetvr.reference.tets import render_reference

    from .conftest import shared_file

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # dropped zero-volume tets are reported, not errors
        mesh = tetvr.read(shared_file("tets/pipe_flow_init_flow.vtu"), "Velocity")
    lo, hi = mesh.scalar_range
    centres = [(v - lo) / (hi - lo) for v in np.quantile(mesh.scalars, [0.5, 0.8])]
    opacity = [(0.0, 0.0)]
    for c in centres:
        opacity += [(c - 0.003, 0.0), (c, 1.0), (c + 0.003, 0.0)]
    opacity.append((1.0, 0.0))
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    tf = TransferFunction.preset("cool-to-warm", mesh.scalar_range, opacity=opacity, unit_distance=diag / 20)
    cam = Camera.fit(mesh, direction=(-1.0, -0.5, -0.7), zoom=1.2)
    return mesh, cam, tf, render_reference(mesh, cam, tf, (64, 64))


def test_opaque_spikes_on_pipe_flow(renderer, pipe_flow_opaque_spikes):
    """Real data, defaults: measured 86.0 dB / max 0.0029 (projected tetrahedra) and 94.4 dB /
    max 0.0008 (tet marching), no pixel beyond 1/255; even nodes (table_warp="off"): 52.5 dB,
    max 0.038, 368 pixels. Bars: max 0.006, no pixel beyond 1/255."""
    mesh, cam, tf, ref = pipe_flow_opaque_spikes
    img = renderer.render(mesh, cam, tf, size=(64, 64))
    d = np.abs(img[..., :3].astype(np.float64) - ref[..., :3]).max(axis=-1)
    assert np.isfinite(img).all()
    if d.max() > 0.006 or np.sum(d > 1 / 255):
        save_failure(f"pipe_opaque_spikes_{renderer.settings.method}", img, ref)
    assert d.max() <= 0.006 and np.sum(d > 1 / 255) == 0, (float(d.max()), int(np.sum(d > 1 / 255)))

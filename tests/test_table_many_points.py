"""Transfer functions of many control points and with steps, and the pre-integration table.

A table's size is set by its bins, never by the control points: a warped table holds at
most ``max_warped_nodes(N)`` nodes however many points the map has (thousands of opacity
spikes, a 256-point matplotlib map, a 4096-band discretized map), what may be too big is
refused before any node is placed, and a map too long to hold is refused before it is read.
A discretized map (ParaView's default: 256 bands of 8-bit colours, each edge a step 1e-9 of
the range wide) gets a node on every step, each bin integrating its band exactly, with an
even table instead of a slow warped one.
"""

from __future__ import annotations

import dataclasses
import tracemalloc

import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.optics import preintegrate
from tetvr.optics.preintegrate import build_table, table_for
from tetvr.optics.table import STEP_GAP, step_positions, table_scalar_range
from tetvr.optics.tablesize import choose_table_size, resolve, segment_sample
from tetvr.optics.tablewarp import max_warped_nodes, warped_nodes
from tetvr.optics.transfer import MAX_CONTROL_POINTS
from tetvr.reference.integrate import integrate_segments

from .conftest import save_failure


def _spikes(lo: float, hi: float, count: int, peak: float = 0.9) -> tuple[tuple[float, float], ...]:
    """``count`` opacity spikes side by side over [lo, hi], each three points (0, peak, 0)."""
    x = np.linspace(lo, hi, 3 * count + 2)
    return ((float(x[0]), 0.0),) + tuple((float(x[i]), peak if i % 3 == 2 else 0.0) for i in range(1, x.size))


def _discretized(tf: TransferFunction, n: int = 256) -> TransferFunction:
    """``tf``'s colour map as ParaView's discretized lookup table holds it (tetvr.scene.paraview):
    ``n`` bands of 8-bit colours over its range, band i taking the colour at lo + i (hi - lo) / (n - 1),
    each edge a step from 1e-9 of the range below it."""
    lo, hi = tf.color[0][0], tf.color[-1][0]
    colours = np.floor(255.0 * tf.evaluate(lo + (hi - lo) * np.arange(n) / (n - 1))[0] + 0.5) / 255.0
    edges = lo + (hi - lo) * np.arange(n + 1) / n
    eps = 1e-9 * (hi - lo)
    rows = [(lo, *colours[0])]
    for i in range(1, n):
        rows += [(edges[i] - eps, *colours[i - 1]), (edges[i], *colours[i])]
    rows.append((hi, *colours[-1]))
    return dataclasses.replace(tf, color=tuple(rows))


# ---------------------------------------------------------------- refused before any work
class _Huge:
    """A sequence that says it is long and fails the test if anything reads it."""

    def __len__(self) -> int:
        return MAX_CONTROL_POINTS + 1

    def __getitem__(self, i):
        raise AssertionError("the control points were read before their count was checked")

    def __array__(self, *args, **kwargs):
        raise AssertionError("the control points were converted before their count was checked")


@pytest.mark.parametrize("field", ["color", "opacity"])
def test_a_map_too_long_to_hold_is_refused_before_it_is_read(field):
    maps = {"color": ((0, 0, 0, 0), (1, 1, 1, 1)), "opacity": ((0, 0.5), (1, 0.5)), field: _Huge()}
    with pytest.raises(ValueError, match=rf"{field} has 4,194,305 control points, more than the 4,194,304 a transfer "
                                         r"function holds \(they would take ~0\.\d GiB as Python numbers\); resample"):
        TransferFunction(**maps)


def test_table_memory_is_refused_before_any_node_is_placed(monkeypatch):
    """The memory check takes the most nodes the table may get (a warped table's control
    points included) and runs before the nodes are placed."""
    asked = []

    def refuse(need, what):
        asked.append((need, what))
        raise MemoryError(what)

    def no_nodes(*args, **kwargs):
        raise AssertionError("nodes were placed before the memory check")

    monkeypatch.setattr(preintegrate, "check_memory", refuse)
    monkeypatch.setattr(preintegrate, "warped_nodes", no_nodes)
    tf = TransferFunction.preset("viridis", (0.0, 1.0), opacity=_spikes(0.0, 1.0, 1000))
    with pytest.raises(MemoryError, match="building a 162 x 162 x 5 pre-integration table"):
        build_table(tf, (0.0, 1.0), 1.0, n_bins=128, n_slices=4, warp=True)
    assert asked[0][0] == preintegrate.table_build_bytes(128, 4, warp=True) == 128 * 162 * 162 * 5


# ---------------------------------------------------------------- bounded by the bins
def test_warped_nodes_are_bounded_by_the_bins_not_the_control_points():
    """1000 spikes (3,001 control points) used to put every point on a node: a 3,130-node
    table, minutes and GiB of build. The nodes stay within N + N/4 + 2, and the control
    points that get nodes are those the table would miss most: one tall spike among
    999 faint ones keeps its three points."""
    assert max_warped_nodes(128) == 162
    tf = TransferFunction.preset("viridis", (0.0, 1.0), opacity=_spikes(0.0, 1.0, 1000))
    assert warped_nodes(tf, (0.0, 1.0), 128).size <= 162
    faint = np.array(_spikes(0.0, 1.0, 1000, peak=0.01))
    faint[1501:1504, 1] = (0.0, 0.9, 0.0)  # spike 500 (points 1501..1503) is tall
    tall = TransferFunction.preset("viridis", (0.0, 1.0), opacity=tuple(map(tuple, faint)))
    nodes = warped_nodes(tall, (0.0, 1.0), 128)
    assert nodes.size <= 162 and np.isin(faint[1501:1504, 0], nodes).all()


def test_a_thousand_spikes_get_a_bounded_auto_table():
    mesh = synthetic.cube(4)
    lo, hi = mesh.scalar_range
    tf = TransferFunction.preset("viridis", (lo, hi), opacity=_spikes(lo, hi, 1000), unit_distance=0.1)
    size = resolve(RenderSettings(), tf, mesh)
    assert size.warp  # no even table meets the tolerance
    assert warped_nodes(tf, table_scalar_range(mesh.scalar_range, tf), size.n_bins).size <= max_warped_nodes(size.n_bins)
    table = table_for(tf, mesh.scalar_range, mesh.max_edge, n_bins=size.n_bins, n_slices=size.n_slices,
                      log_base=size.log_base, align_nodes=True, warp=size.warp)
    assert table.n_bins <= max_warped_nodes(size.n_bins)


def test_many_control_points_build_in_memory_of_their_own_size():
    """200,000 random opacity points: the size decision and the table hold arrays of the
    points' size, not of points x candidate spacings (the alignment's cost matrix took 26-51
    times the points) nor a table of one node per point (7,693 x 7,693 x 9: refused at
    63.5 GiB after the work before it)."""
    mesh = synthetic.cube(4)
    lo, hi = mesh.scalar_range
    x = np.linspace(lo, hi, 200_000)
    tf = TransferFunction(color=((lo, 0, 0, 1), (hi, 1, 0, 0)), unit_distance=0.1,
                          opacity=np.column_stack([x, np.random.default_rng(7).random(x.size) * 0.5]))
    segment_sample(mesh)
    tracemalloc.start()
    try:
        size = resolve(RenderSettings(), tf, mesh)
        table = table_for(tf, mesh.scalar_range, mesh.max_edge, n_bins=size.n_bins, n_slices=size.n_slices,
                          log_base=size.log_base, align_nodes=True, warp=size.warp)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    bound = 128 << 20  # measured ~50 MiB; the points alone are 3.2 MB
    assert table.n_bins <= max(max_warped_nodes(size.n_bins), size.n_bins)
    assert peak < bound, f"{peak / 2**20:.0f} MiB"


def test_a_many_band_map_gets_a_table_of_its_bins():
    """A 4096-band discretized map (ParaView allows 16,384) once sized an 8161 x 8161 x 9
    table (71.5 GiB): "auto" chose a warped table of 128 nodes, and every band edge became
    a node. Its steps cannot all sit on evenly spaced nodes within the bound, so it gets
    the warped table, of at most max_warped_nodes(128) nodes."""
    mesh = synthetic.cube(4)
    tf = _discretized(TransferFunction.preset("cool-to-warm", mesh.scalar_range, opacity=0.3, unit_distance=0.2), 4096)
    size = resolve(RenderSettings(), tf, mesh)
    table = table_for(tf, mesh.scalar_range, mesh.max_edge, n_bins=size.n_bins, n_slices=size.n_slices,
                      log_base=size.log_base, align_nodes=True, warp=size.warp)
    assert table.n_bins <= max(max_warped_nodes(size.n_bins), size.n_bins + size.n_bins // 2)
    assert table.data.nbytes < 16 << 20


# ---------------------------------------------------------------- steps on nodes
def test_bands_between_step_nodes_are_integrated_exactly():
    """Four constant bands, a node on each edge: a segment from node to node (one band, two,
    or all four) is its exact integral, where the nodes' colours read linearly used to blur
    each band into the next (up to half the jump between bands off)."""
    bands = [(k / 4 + d, *(0.2 + 0.2 * k, 0.9 - 0.2 * k, 0.5)) for k in range(4) for d in (0.0, 0.25 - 1e-9)]
    tf = TransferFunction(color=bands, opacity=((0.0, 0.3), (0.5, 0.8), (1.0, 0.4)), unit_distance=0.5)
    table = build_table(tf, (0.0, 1.0), 2.0, n_bins=5, n_slices=6, log_base=1.5)
    sf = np.array([0.25, 0.5, 0.25, 0.0, 1.0, 0.75])
    sb = np.array([0.5, 0.25, 0.75, 1.0, 0.0, 0.25])
    d = table.thicknesses[np.array([6, 3, 6, 5, 4, 6])]  # on slices: no thickness interpolation
    rgb, theta = integrate_segments(sf, sb, d, tf)
    want = np.column_stack([rgb, -np.expm1(-theta)])
    np.testing.assert_allclose(table.lookup(sf, sb, d), want, atol=2e-6)


def test_a_discretized_map_puts_its_steps_on_nodes():
    """ParaView's default discretized map over the default colour range (80 % of the cube's
    field range): "auto" chose a warped table (377 nodes, 24 s here) that smeared each band
    edge over a bin; now an even table whose nodes hold all 255 steps (324 nodes for 256
    bins), and the estimate sees the bands exact."""
    mesh = synthetic.cube(8)
    tf = _discretized(TransferFunction.preset("cool-to-warm", mesh))
    size = resolve(RenderSettings(), tf, mesh)
    assert not size.warp and size.scalar_error < 5e-5, size
    table = table_for(tf, mesh.scalar_range, mesh.max_edge, n_bins=size.n_bins, n_slices=size.n_slices,
                      log_base=size.log_base, align_nodes=True)
    assert size.n_bins < table.n_bins <= size.n_bins + size.n_bins // 2
    nodes = np.linspace(*table.scalar_range, table.n_bins)
    steps = step_positions(tf, nodes[-1] - nodes[0])
    assert steps.size == 255
    assert np.abs(nodes[np.searchsorted(nodes, steps - 0.5 * table.node_spacing)] - steps).max() < STEP_GAP
    uniform = choose_table_size(tf, mesh, n_bins=size.n_bins, n_slices=size.n_slices, align_nodes=False)
    assert size.scalar_error < uniform.scalar_error / 10, (size, uniform)


@pytest.mark.gl
def test_a_discretized_map_renders_near_its_reference(renderer):
    """cube(8) at 64x64 under ParaView's default discretized map against the exact reference.
    Measured: 115.4 dB (projected), 123.3 dB (tet marching), max 1.0e-4, no pixel beyond
    1/255 (the smooth map: 101.7 dB, max 3.1e-4); with one interpolated lookup per segment
    instead of the cut at the nodes (tests/test_discretized_maps.py), 80.5 dB, max 1.9e-3;
    with a warped table: 61.1 dB, max 4.4e-3, 5 pixels beyond. Bar: max 2.5e-3, none beyond 1/255."""
    from tetvr.reference.tets import render_reference

    mesh = synthetic.cube(8)
    tf = _discretized(TransferFunction.preset("cool-to-warm", mesh))
    camera = Camera.fit(mesh)
    want = render_reference(mesh, camera, tf, (64, 64))
    got = renderer.render(mesh, camera, tf, size=(64, 64))
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    assert want[..., 3].max() > 0.5
    if not (err.max() <= 2.5e-3 and not np.any(err > 1 / 255)):
        where = save_failure(f"discretized_{renderer.settings.method}", got, want)
        pytest.fail(f"max {err.max():.2e}, {int((err > 1 / 255).sum())} pixels > 1/255 (images in {where})")
    assert renderer.table(mesh, tf).nodes is None  # even nodes, steps on them


# ---------------------------------------------------------------- the viewer's edits
@pytest.mark.gl
def test_edits_under_a_map_of_many_colour_points_keep_the_table_small():
    """The viewer's case without the browser: one Renderer, a 256-point colour map (as
    matplotlib's, here viridis at k/255) and an opacity peak dragged from edit to edit. Each
    edit is a new transfer function, and "auto" warps it: the warped table held a node for
    every colour point (380 nodes, 23 s per edit here), now at most 162 (2-3 s, as for a
    9-point map). An unchanged transfer function, the same object or an equal one, reuses
    the table."""
    from tetvr import Renderer

    mesh = synthetic.cube(8)
    base = TransferFunction.preset("viridis", mesh)
    lo, hi = base.domain
    t = np.linspace(0.0, 1.0, 256)
    rgb = TransferFunction.preset("viridis", (0.0, 1.0)).evaluate(t)[0]
    color = tuple((lo + (hi - lo) * x, *c) for x, c in zip(t, rgb))
    with Renderer() as renderer:
        for peak_t, peak_a in ((0.45, 0.2), (0.42, 0.6)):
            points = ((0, 0), (0.25, 0.05625), (peak_t, peak_a), (0.5, 0.02), (0.75, 0.506), (1, 0.9))
            tf = TransferFunction(color=color, opacity=tuple((lo + (hi - lo) * a, b) for a, b in points),
                                  unit_distance=base.unit_distance)
            table = renderer.table(mesh, tf)
            assert table.nodes is not None and table.n_bins <= max_warped_nodes(128), table.n_bins
            assert renderer.table(mesh, tf) is table
            assert renderer.table(mesh, dataclasses.replace(tf)) is table

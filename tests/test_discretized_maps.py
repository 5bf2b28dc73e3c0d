"""Discretized colour maps: bands of constant colour, each edge a step on a table node.

ParaView saves its colour maps discretized by default (256 bands of 8-bit colours, each edge
a step 1e-9 of the range wide; ``tetvr.scene.paraview``). The table puts a node on every
step and integrates each band exactly (``tests/test_table_many_points.py``); a lookup between
nodes then cuts the segment at the nodes it crosses (``tetvr.optics.tablesteps``,
``shaders/lookup_steps.glsl``), where one trilinear fetch blended the two bands beside a
step. The maps here are the checked-in state's (``tests/data/post_volume.pvsm``: ParaView's
"Cool to Warm", Diverging, and an edited four-point opacity function) moved onto the mesh's
field, made as ParaView's state makes them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.core.image import psnr
from tetvr.mesh import synthetic
from tetvr.optics.preintegrate import table_for
from tetvr.optics.tablesteps import cut_at_nodes
from tetvr.reference.integrate import integrate_segments
from tetvr.scene.paraview import read_state, state_transfer_function

from .conftest import save_failure

STATE = Path(__file__).resolve().parent / "data" / "post_volume.pvsm"


def _paraview_map(scalar_range: tuple[float, float], *, bands: int = 256, discretize: bool = True,
                  unit_distance: float = 0.05) -> TransferFunction:
    """The state's colour map and opacity function over ``scalar_range``, ``bands`` bands
    (or continuous, ``discretize=False``)."""
    st = read_state(STATE)
    lo, hi = scalar_range
    a, b = st.rgb_points[0][0], st.rgb_points[-1][0]

    def moved(rows: tuple[tuple[float, ...], ...]) -> tuple[tuple[float, ...], ...]:
        return tuple((lo + (p[0] - a) * (hi - lo) / (b - a), *p[1:]) for p in rows)

    st = dataclasses.replace(st, rgb_points=moved(st.rgb_points), opacity_points=moved(st.opacity_points),
                             discretize=discretize, n_table_values=bands)
    return state_transfer_function(st, unit_distance=unit_distance)


# ---------------------------------------------------------------- the table (no GL)
def test_cut_at_nodes_splits_a_segment_where_it_crosses_nodes():
    fi = np.array([2.5, 5.5, 3.0, 5.25, 2.25, 3.0, 4.5, 4.0, 7.0, 4.0])
    fj = np.array([5.5, 2.5, 5.5, 4.75, 2.75, 3.0, 5.0, 3.5, 9.0, 3.0])  # 9: clamped to the last node, 7
    (p0, q0, b0, s0), (p1, q1, b1, s1), (p2, q2, b2, s2) = cut_at_nodes(fi, fj, 8)
    assert (b0[:4].tolist(), b2[:4].tolist()) == ([2, 5, 2, 5], [5, 2, 5, 4])
    assert (q0[:4].tolist(), p2[:4].tolist()) == ([3.0, 5.0, 3.0, 5.0], [5.0, 3.0, 5.0, 5.0])
    assert (p1[:3].tolist(), q1[:3].tolist()) == ([3.0, 5.0, 3.0], [5.0, 3.0, 5.0])
    np.testing.assert_allclose(s0[:2], 1 / 6, rtol=1e-15)
    # From a node: no front piece; across one node: no run.
    assert s0[2] == 0 and s1[2] == 0.8 and s1[3] == 0 and s0[3] == s2[3] == 0.5
    # Crossing no node (ends on nodes included): all front piece, in its bin.
    np.testing.assert_array_equal(s0[4:], 1.0)
    np.testing.assert_array_equal(s1[4:] + s2[4:], 0.0)
    assert b0[4:].tolist() == [2, 3, 4, 3, 6, 3]
    np.testing.assert_allclose(s0 + s1 + s2, 1.0, rtol=0, atol=1e-15)


@pytest.mark.parametrize("bands", [256, 32])
def test_lookups_beside_band_edges_match_the_integral(bands):
    """Segments within three bins of the diagonal (both ends by the same few band edges),
    looked up as the GPU does (PreintegrationTable.lookup) in the table the renderer builds,
    against the exact integral. The opacity is a ramp, linear in every bin, so that what is
    measured is the steps alone (an opacity point between nodes errs as in any table). One
    trilinear fetch erred by up to 2.7/255 (256 bands) and 16.8/255 (32 bands); cut at the
    nodes, measured 0.03/255 and 0.05/255 (the continuous map's table: 0.19/255). Bar: 0.25/255."""
    tf = dataclasses.replace(_paraview_map((0.0, 1.0), bands=bands, unit_distance=0.2), opacity=((0.0, 0.2), (1.0, 0.9)))
    table = table_for(tf, (0.0, 1.0), 0.5, n_bins=256, n_slices=8, log_base=2.0, align_nodes=True)
    assert table.steps is not None and table.nodes is None
    lo, hi = table.scalar_range
    h = (hi - lo) / (table.n_bins - 1)
    rng = np.random.default_rng(7)
    n = 40_000
    sf = rng.uniform(0.0, 1.0, n)
    sb = np.clip(sf + rng.uniform(-3.0, 3.0, n) * h * rng.uniform(0.0, 1.0, n) ** 2, 0.0, 1.0)
    d = table.d_max * 10.0 ** rng.uniform(-3.0, 0.0, n)
    rgb, theta = integrate_segments(sf, sb, d, tf)
    want = np.column_stack([rgb, -np.expm1(-theta)])
    err = np.abs(table.lookup(sf, sb, d) - want).max(axis=-1)
    assert err.max() <= 0.25 / 255, f"max {err.max() * 255:.2f}/255 at {sf[err.argmax()]}, {sb[err.argmax()]}"


def test_only_normalized_tables_of_stepped_maps_cut_segments():
    """The cut is compiled in (TABLE_STEPS) only for a table that has steps on its nodes and
    the "normalized" encoding (alpha exact in the thickness; a premultiplied table's alpha,
    interpolated across slices, errs on the short pieces): a continuous map's table is as it was."""
    smooth = table_for(_paraview_map((0.0, 1.0), discretize=False), (0.0, 1.0), 0.5, align_nodes=True)
    assert smooth.steps is None
    stepped = table_for(_paraview_map((0.0, 1.0)), (0.0, 1.0), 0.5, align_nodes=True, encoding="premultiplied")
    assert stepped.steps is None
    eight_bit = table_for(_paraview_map((0.0, 1.0)), (0.0, 1.0), 0.5, align_nodes=True, dtype="uint8")
    assert eight_bit.steps is not None and eight_bit.steps.dtype == np.uint8
    assert eight_bit.steps.shape == (eight_bit.n_slices + 1, 2, 2 * (eight_bit.n_bins - 1), 4)


# ---------------------------------------------------------------- pictures (GL)
def _errors(got: np.ndarray, want: np.ndarray) -> tuple[float, float, int]:
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    return psnr(got, want), float(err.max()), int((err > 1 / 255).sum())


@pytest.mark.gl
@pytest.mark.parametrize("bands", [256, 32])
def test_a_discretized_map_renders_as_close_as_a_continuous_one(renderer, bands):
    """cube(8) at 64x64 (Camera.fit, opaque: unit distance 0.05) under the state's map with
    ``bands`` bands, against the exact reference. Measured with one trilinear fetch (both
    methods): 75.5 dB, max 1.01/255, 1 pixel beyond 1/255 (256 bands); 68.5 dB, max 3.47/255,
    11 pixels (32 bands). Cut at the nodes: 114 and 110 dB, max 0.01/255 (the continuous
    map: 93.1 dB, max 0.05/255). Bar: max 0.25/255, no pixel beyond 1/255, and within 3 dB of
    the continuous map's PSNR or better."""
    from tetvr.reference.tets import render_reference

    mesh = synthetic.cube(8)
    camera = Camera.fit(mesh)
    found = {}
    for discretize in (False, True):
        tf = _paraview_map(mesh.scalar_range, bands=bands, discretize=discretize)
        want = render_reference(mesh, camera, tf, (64, 64))
        got = renderer.render(mesh, camera, tf, size=(64, 64))
        assert want[..., 3].max() > 0.9
        found[discretize] = (*_errors(got, want), got, want)
    smooth_db = found[False][0]
    value, worst, beyond, got, want = found[True]
    if not (worst <= 0.25 / 255 and beyond == 0 and value >= smooth_db - 3.0):
        where = save_failure(f"discretized_{bands}_{renderer.settings.method}", got, want)
        pytest.fail(f"{value:.1f} dB (continuous map {smooth_db:.1f} dB), max {worst * 255:.2f}/255, {beyond} "
                    f"pixels > 1/255 (images in {where})")
    table = renderer.table(mesh, _paraview_map(mesh.scalar_range, bands=bands))
    assert table.steps is not None and table.nodes is None


@pytest.mark.gl
@pytest.mark.parametrize("settings", [dict(table_filter="cubic"), dict(table_dtype="uint8")], ids=["cubic", "uint8"])
def test_the_cut_lookup_with_other_table_settings(renderer, settings):
    """The cut lookup with Catmull-Rom slices and with an 8-bit table, the camera inside the
    mesh (projected tetrahedra: the per-fragment exact path for the tets across the near
    plane; tet marching: the walk from the near plane). Measured (both methods; one
    trilinear fetch -> cut at the nodes): cubic 108.5 -> 125.7-127.8 dB, max 0.01/255 (the
    continuous map: 105.7 dB); uint8 63.4 -> 64.5 dB, max 1.05/255 with 1 pixel beyond
    1/255 -> 0.89/255 (the continuous map's 8-bit table: 63.5 dB, max 0.88/255, where the
    texture unit filters on llvmpipe; 65.5 dB where the shader filters, tetvr.gl.filtering,
    the cut lookup staying at 64.5). Bars: cubic 115 dB and no pixel beyond 1/255; uint8
    within 1.5 dB of the continuous map, no pixel beyond 1/255."""
    from tetvr.reference.tets import render_reference

    mesh = synthetic.cube(6)
    fit = Camera.fit(mesh, direction=(0.6, -0.5, -1.0))
    inside = np.array(fit.focal_point) + 0.3 * (np.array(fit.position) - np.array(fit.focal_point))
    camera = dataclasses.replace(fit, position=tuple(float(v) for v in inside), clipping_range=None)
    before = renderer.settings
    renderer.settings = RenderSettings(method=before.method, **settings)
    try:
        found = {}
        for discretize in (False, True):
            tf = _paraview_map(mesh.scalar_range, discretize=discretize)
            want = render_reference(mesh, camera, tf, (48, 48))
            got = renderer.render(mesh, camera, tf, size=(48, 48))
            found[discretize] = (*_errors(got, want), got, want)
        assert renderer.table(mesh, tf).steps is not None
    finally:
        renderer.settings = before
    value, worst, beyond, got, want = found[True]
    smooth_db, smooth_worst = found[False][:2]
    ok = beyond == 0 and (value >= 115.0 if "table_filter" in settings else value >= smooth_db - 1.5)
    if not ok:
        where = save_failure(f"discretized_{'_'.join(settings.values())}_{before.method}", got, want)
        pytest.fail(f"{value:.1f} dB (continuous {smooth_db:.1f} dB, max {smooth_worst * 255:.2f}/255), max "
                    f"{worst * 255:.2f}/255, {beyond} pixels > 1/255 (images in {where})")

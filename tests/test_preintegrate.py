"""The 3D pre-integration table against brute-force quadrature of the same segments."""

from __future__ import annotations

import numpy as np
import pytest

from tetvr import TransferFunction
from tetvr.optics import model as optics
from tetvr.optics.preintegrate import build_table, table_for

TF = TransferFunction(
    color=((0.0, 1.0, 0.0, 0.0), (0.3, 0.0, 1.0, 0.0), (0.7, 0.0, 0.0, 1.0), (1.0, 1.0, 1.0, 1.0)),
    opacity=((0.0, 0.0), (0.4, 0.8), (0.6, 0.1), (1.0, 0.5)),
    unit_distance=0.2,
)


def brute_segment(tf: TransferFunction, sf: float, sb: float, d: float, n: int = 4000) -> np.ndarray:
    """Premultiplied RGBA of a segment by n exact linear pieces, composited front to back."""
    s = np.linspace(sf, sb, n + 1)
    c, a = tf.evaluate(s)
    rgb, th = optics.integrate_pieces(c[:-1], c[1:], a[:-1], a[1:], np.full(n, d / n), tf.unit_distance)
    before = np.exp(-np.concatenate([[0.0], np.cumsum(th)[:-1]]))
    return np.append((rgb * before[:, None]).sum(axis=0), -np.expm1(-th.sum()))


@pytest.fixture(autouse=True)
def _strict():
    with np.errstate(all="raise", under="ignore"):
        yield


@pytest.mark.parametrize("encoding", ["normalized", "premultiplied"])
def test_nodes_match_quadrature(encoding):
    # Node spacing 1/255 puts the TF control points (0.3, 0.4, 0.6, 0.7) within half a bin of a node.
    table = build_table(TF, (0.0, 1.0), 1.0, encoding=encoding)
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(60):
        i, j = rng.integers(0, 256, 2)
        k = int(rng.integers(1, 17))
        d = table.thicknesses[k]
        want = brute_segment(TF, i / 255, j / 255, d)
        got = table.lookup(np.array(i / 255), np.array(j / 255), np.array(d))
        worst = max(worst, float(np.abs(got - want).max()))
    assert worst < 5e-4, worst


def test_normalized_lookup_between_nodes_and_slices():
    table = build_table(TF, (0.0, 1.0), 1.0)
    rng = np.random.default_rng(2)
    errs = []
    for _ in range(100):
        sf, sb = rng.random(2)
        d = float(np.exp(rng.uniform(np.log(1e-5), 0.0)))
        errs.append(np.abs(table.lookup(np.array(sf), np.array(sb), np.array(d)) - brute_segment(TF, sf, sb, d)).max())
    assert np.median(errs) < 1e-5 and max(errs) < 1e-2, (np.median(errs), max(errs))


def test_normalized_beats_premultiplied_between_slices():
    """The reason for the default: premultiplied RGBA is convex in log-thickness."""
    norm = build_table(TF, (0.0, 1.0), 1.0, encoding="normalized")
    prem = build_table(TF, (0.0, 1.0), 1.0, encoding="premultiplied")
    d = np.sqrt(norm.thicknesses[8] * norm.thicknesses[9])  # halfway between two slices in log
    s = np.array(0.5)
    want = brute_segment(TF, 0.5, 0.5, d)
    assert abs(norm.lookup(s, s, d)[3] - want[3]) < 0.2 * abs(prem.lookup(s, s, d)[3] - want[3])


def test_zero_thickness_is_transparent_and_thin_limit_is_linear():
    table = build_table(TF, (0.0, 1.0), 1.0)
    assert np.all(table.lookup(np.array([0.2, 0.9]), np.array([0.5, 0.1]), np.array([0.0, 0.0])) == 0.0)
    d = table.d_min / 4
    got = table.lookup(np.array(0.5), np.array(0.5), np.array(d))
    want = brute_segment(TF, 0.5, 0.5, d)
    np.testing.assert_allclose(got, want, atol=1e-7)


def test_uint8_table_is_close_to_float():
    f = build_table(TF, (0.0, 1.0), 1.0, n_bins=64, n_slices=8)
    u = build_table(TF, (0.0, 1.0), 1.0, n_bins=64, n_slices=8, dtype="uint8")
    assert u.data.dtype == np.uint8
    s = np.linspace(0, 1, 50)
    d = np.full(50, 0.3)
    assert np.abs(f.lookup(s, s[::-1], d) - u.lookup(s, s[::-1], d)).max() < 0.02


def test_table_is_cached_and_covers_data_outside_tf_domain():
    a = table_for(TF, (-0.5, 2.0), 1.0, n_bins=32, n_slices=4)
    b = table_for(TF, (-0.5, 2.0), 1.0, n_bins=32, n_slices=4)
    assert a is b
    assert a.scalar_range == (-0.5, 2.0)
    # Outside the domain the TF is clamped: a segment at 2.0 looks like one at 1.0.
    want = brute_segment(TF, 1.0, 1.0, 0.5)
    np.testing.assert_allclose(a.lookup(np.array(2.0), np.array(2.0), np.array(0.5)), want, atol=1e-4)


@pytest.mark.parametrize("bad", [dict(scalar_range=(1.0, 1.0)), dict(d_max=0.0), dict(encoding="x"), dict(dtype="f16")])
def test_bad_arguments(bad):
    kw = dict(scalar_range=(0.0, 1.0), d_max=1.0)
    kw.update(bad)
    with pytest.raises(ValueError):
        build_table(TF, kw.pop("scalar_range"), kw.pop("d_max"), **kw)


@pytest.mark.parametrize("n_bins", [2, 3, 9])
def test_every_entry_exact_where_the_tf_is_linear_between_nodes(n_bins):
    # Colour control points on the nodes and constant opacity: within every bin the table's
    # model (linear colour, constant extinction) is the transfer function itself, so each
    # entry, both directions and every run length up to the full range, is exact.
    pts = np.linspace(0.0, 1.0, n_bins)
    rng = np.random.default_rng(n_bins)
    tf = TransferFunction(color=tuple((float(x), *map(float, rng.random(3))) for x in pts),
                          opacity=((0.0, 0.6), (1.0, 0.6)), unit_distance=0.3)
    table = build_table(tf, (0.0, 1.0), 2.0, n_bins=n_bins, n_slices=3, encoding="premultiplied")
    worst = 0.0
    for k in range(1, 4):
        d = table.thicknesses[k]
        for i in range(n_bins):
            for j in range(n_bins):
                want = brute_segment(tf, pts[i], pts[j], d, n=840)  # 840: pieces end on every node
                worst = max(worst, float(np.abs(table.data[k, j, i] - want).max()))
    assert worst < 1e-6, worst  # float32 storage

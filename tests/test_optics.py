"""The optical model (tetvr.optics.model) against brute-force quadrature and closed forms."""

from __future__ import annotations

from decimal import Decimal, localcontext

import numpy as np
import pytest

from tetvr.optics.model import MAX_OPACITY, extinction, integrate_pieces, mean_neg_log, piece_optical_depth


@pytest.fixture(autouse=True)
def _strict_floats():
    with np.errstate(all="raise"):
        yield


def march_piece(c0, c1, a0, a1, length, u, n=200_000):
    """Brute-force emission-absorption along one piece: exact exponential per step.

    Colour and opacity are held at their midpoint value on each step. The opacity runs
    linearly between its clamped end values (the convention of integrate_pieces). Where
    ``1 - a`` gets small, the extinction ``-ln(1 - a)`` is steep, so geometric nodes in
    ``1 - a`` are added to the uniform ones; the result then converges to ~1e-10
    (checked by doubling ``n``).
    """
    c0, c1 = np.asarray(c0, float), np.asarray(c1, float)
    a0, a1 = min(a0, MAX_OPACITY), min(a1, MAX_OPACITY)
    f = np.linspace(0.0, 1.0, n + 1)
    if a0 != a1:
        x = np.geomspace(1.0 - MAX_OPACITY, 1.0, 20_000)
        fx = ((1.0 - x) - a0) / (a1 - a0)
        f = np.unique(np.concatenate([f, fx[(fx > 0) & (fx < 1)]]))
    mid = 0.5 * (f[1:] + f[:-1])
    step = -np.log1p(-(a0 + (a1 - a0) * mid)) / u * np.diff(f) * length
    theta = np.cumsum(step)
    weight = -np.expm1(-step) * np.exp(-(theta - step))
    rgb = (weight[:, None] * (c0 + (c1 - c0) * mid[:, None])).sum(axis=0)
    return rgb, theta[-1]


def _random_pieces(rng, n, a_max):
    a = rng.uniform(0.0, a_max, (n, 2))
    return rng.random((n, 3)), rng.random((n, 3)), a[:, 0], a[:, 1], rng.uniform(0.01, 30.0, n), rng.uniform(0.1, 2.0, n)


def test_integrate_pieces_matches_fine_quadrature():
    rng = np.random.default_rng(7)
    c0, c1, a0, a1, length, u = _random_pieces(rng, 8, 0.8)
    # Hand-picked hard cases: very opaque constant slabs, long pieces, optical depth far
    # past the cut-off of 40, a thin piece, a transparent one.
    extra = [
        (0.999, 0.999, 5.0, 1.0),
        (MAX_OPACITY, MAX_OPACITY, 0.5, 1.0),
        (0.5, 0.5, 100.0, 1.0),
        (0.2, 0.8, 0.3, 0.01),
        (0.05, 0.7, 50.0, 2.0),
        (0.3, 0.6, 1e-4, 1.0),
        (0.0, 0.0, 2.0, 1.0),
    ]
    for a0_, a1_, l_, u_ in extra:
        c0 = np.vstack([c0, rng.random(3)])
        c1 = np.vstack([c1, rng.random(3)])
        a0, a1 = np.append(a0, a0_), np.append(a1, a1_)
        length, u = np.append(length, l_), np.append(u, u_)
    for i in range(length.shape[0]):
        rgb, theta = integrate_pieces(c0[i : i + 1], c1[i : i + 1], a0[i : i + 1], a1[i : i + 1], length[i : i + 1], u[i])
        want_rgb, want_theta = march_piece(c0[i], c1[i], a0[i], a1[i], length[i], u[i])
        # Documented bound 1e-7; the brute force itself is good to ~1e-10.
        np.testing.assert_allclose(rgb[0], want_rgb, rtol=0, atol=1e-7, err_msg=f"piece {i}")
        np.testing.assert_allclose(theta[0], want_theta, rtol=1e-8, atol=1e-12, err_msg=f"piece {i}")


def test_integrate_pieces_opacity_ramp_to_one():
    c0, c1 = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    for length in (0.1, 0.3, 1.0):
        rgb, _ = integrate_pieces(c0[None], c1[None], np.array([1.0]), np.array([0.0]), np.array([length]), 1.0)
        want, _ = march_piece(c0, c1, 1.0, 0.0, length, 1.0)
        np.testing.assert_allclose(rgb[0], want, rtol=0, atol=1e-7)


def _mean_neg_log_decimal(x0: float, x1: float) -> float:
    """Mean of -ln x over [x0, x1] from the antiderivative x - x ln x, at 60 digits."""
    with localcontext() as ctx:
        ctx.prec = 60
        a, b = Decimal(x0), Decimal(x1)
        if a == b:
            return float(-a.ln())
        return float(((b - b * b.ln()) - (a - a * a.ln())) / (b - a))


@pytest.mark.parametrize("x0", [0.3, 1e-6, 0.999])
def test_mean_neg_log_near_equal_arguments(x0):
    for d in (1e-2, 1e-4, 2e-5, 1e-8, 1e-12, 0.0, -1e-12, -1e-8, -2e-5, -1e-4, -1e-2):
        x1 = x0 * (1.0 + d)
        if x1 >= 1.0:
            continue
        got = float(mean_neg_log(np.array([x0]), np.array([x1]))[0])
        want = _mean_neg_log_decimal(x0, x1)
        assert got == pytest.approx(want, rel=1e-13, abs=1e-15), (x0, d)


def test_mean_neg_log_is_symmetric():
    rng = np.random.default_rng(3)
    x0, x1 = rng.uniform(1e-6, 1.0, 100), rng.uniform(1e-6, 1.0, 100)
    np.testing.assert_allclose(mean_neg_log(x0, x1), mean_neg_log(x1, x0), rtol=1e-13)


@pytest.mark.parametrize("a", [0.0, 0.01, 0.3, 0.9, 0.999, 1.0])
@pytest.mark.parametrize("u", [0.01, 1.0, 7.5])
def test_constant_slab_of_unit_thickness_has_the_tf_opacity(a, u):
    c = np.array([[0.2, 0.5, 0.9]])
    rgb, theta = integrate_pieces(c, c, np.array([a]), np.array([a]), np.array([u]), u)
    alpha = -np.expm1(-theta[0])
    want = min(a, MAX_OPACITY)
    assert alpha == pytest.approx(want, rel=1e-14, abs=1e-15)
    np.testing.assert_allclose(rgb[0], c[0] * want, rtol=1e-12, atol=1e-15)


def test_slab_alpha_follows_beer_lambert_in_thickness():
    a, u = 0.4, 2.0
    length = np.array([0.0, 0.5, 2.0, 4.0, 9.0])
    theta = piece_optical_depth(np.full(5, a), np.full(5, a), length, u)
    np.testing.assert_allclose(1.0 - np.exp(-theta), 1.0 - (1.0 - a) ** (length / u), rtol=1e-14, atol=1e-16)


def test_extinction_is_finite_at_full_opacity():
    tau = extinction(np.array([0.0, 0.5, 1.0, 2.0]), 0.5)
    assert np.all(np.isfinite(tau))
    assert tau[0] == 0.0
    assert tau[2] == tau[3] == pytest.approx(-np.log(1.0 - MAX_OPACITY) / 0.5)


def test_zero_length_and_empty_pieces():
    c = np.array([[1.0, 1.0, 1.0]])
    rgb, theta = integrate_pieces(c, c, np.array([0.7]), np.array([0.2]), np.array([0.0]), 1.0)
    assert theta[0] == 0.0 and np.all(rgb == 0.0)
    rgb, theta = integrate_pieces(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0), 1.0)
    assert rgb.shape == (0, 3) and theta.shape == (0,)

"""The optical model shared by every renderer in tetvr.

About this technique
--------------------
tetvr renders with the emission–absorption model (Max 1995). Along a viewing ray
parameterised by distance ``t`` from where it enters the data, with extinction
``tau(t)`` and emitted colour ``c(t)``::

    I     = integral_0^L  c(t) tau(t) exp(-Theta(t)) dt,   Theta(t) = integral_0^t tau
    alpha = 1 - exp(-Theta(L))

and the pixel holds premultiplied ``(I, alpha)``. The transfer function gives an
*opacity* ``a`` rather than an extinction; it is converted with the unit distance ``u``::

    tau = -ln(1 - a) / u            (a clamped to MAX_OPACITY < 1)

so a slab of thickness ``u`` at constant opacity ``a`` has alpha exactly ``a``: the
convention of ParaView's image-data ray caster. The tetrahedra, the CT ray caster, the
pre-integration table and the CPU reference all use these functions, so they agree by
construction.

Exact pieces
------------
Between two transfer-function control points both ``c`` and ``a`` are linear in the
scalar, and the scalar is linear along a ray inside a tetrahedron, so on such a *piece*
``c`` and ``a`` are linear in ``t``. Then

* the optical depth has a closed form (the mean of ``-ln x`` over an interval), and
* by parts, ``I = c0 - c1 T(L) + c' integral_0^L T(t) dt`` with ``T = exp(-Theta)``,
  a smooth monotone function in [0, 1] that Gauss–Legendre quadrature integrates to
  near machine precision once the piece is cut into sub-pieces of optical depth <= 1/2.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "MAX_OPACITY",
    "extinction",
    "mean_neg_log",
    "piece_optical_depth",
    "integrate_pieces",
    "OPTICS",
    "integrate_linear_pieces",
    "vtk_segments",
    "vtk_vertex_rgba8",
]

#: Conventions from transfer-function opacity to light transport (``RenderSettings.optics``):
#: ``"exact"`` tau = -ln(1 - a)/u, integrated exactly (tetvr's model, ParaView's image data);
#: ``"linear"`` tau = a/u, integrated exactly (the extinction of VTK's unstructured mappers);
#: ``"vtk"`` tau = a/u with a segment's colour the mean of its two end colours, unattenuated
#: inside the segment (the fragment formula of VTK's projected tetrahedra). See docs/paraview.md.
OPTICS = ("exact", "linear", "vtk")

#: Opacities are clamped below 1 so that extinction stays finite: -ln(1e-6) = 13.8 per u.
MAX_OPACITY = 1.0 - 1e-6

# Gauss-Legendre nodes/weights on [0, 1]; 6 nodes are exact for degree-11 polynomials.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(6)
_GL_X = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W
# Sub-pieces carry at most this optical depth; beyond _THETA_CUT the light is gone.
_SUB_THETA = 0.5
_THETA_CUT = 40.0
_MAX_SUB = int(np.ceil(_THETA_CUT / _SUB_THETA))
# Pieces are also cut where the transmittance per unit length, 1 - a, changes by 2x.
_MAX_X_RATIO = 2.0

Array = NDArray[np.float64]


def extinction(opacity: Array | float, unit_distance: float) -> Array:
    """Extinction coefficient ``tau = -ln(1 - a) / u`` with ``a`` clamped to MAX_OPACITY."""
    a = np.clip(np.asarray(opacity, dtype=np.float64), 0.0, MAX_OPACITY)
    return -np.log1p(-a) / unit_distance


def mean_neg_log(x0: Array, x1: Array) -> Array:
    """Mean of ``-ln x`` over ``[x0, x1]`` (x > 0), stable when ``x0 ~ x1``.

    With ``r = x1/x0`` the mean is ``-ln x0 - ((1+d) ln(1+d) - d)/d``, ``d = r - 1``;
    the bracket is evaluated by its series near ``d = 0``.
    """
    x0 = np.asarray(x0, dtype=np.float64)
    x1 = np.asarray(x1, dtype=np.float64)
    d = x1 / x0 - 1.0
    small = np.abs(d) < 1e-4
    d_safe = np.where(small, 1.0, d)
    exact = ((1.0 + d_safe) * np.log1p(d_safe) - d_safe) / d_safe
    series = d * (0.5 - d * (1.0 / 6.0 - d / 12.0))
    return -np.log(x0) - np.where(small, series, exact)


def piece_optical_depth(a0: Array, a1: Array, length: Array, unit_distance: float) -> Array:
    """Optical depth of a piece of given length where opacity runs linearly a0 -> a1."""
    x0 = 1.0 - np.clip(a0, 0.0, MAX_OPACITY)
    x1 = 1.0 - np.clip(a1, 0.0, MAX_OPACITY)
    return np.asarray(length) * mean_neg_log(x0, x1) / unit_distance


def _theta_partial(x0: Array, x1: Array, frac: Array, length: Array, u: float) -> Array:
    """Optical depth from the start of a piece to fraction ``frac`` of it."""
    xf = x0 + (x1 - x0) * frac
    return frac * length * mean_neg_log(x0, xf) / u


def integrate_pieces(
    c0: Array, c1: Array, a0: Array, a1: Array, length: Array, unit_distance: float
) -> tuple[Array, Array]:
    """Integrate pieces on which colour and opacity run linearly along the ray.

    Parameters
    ----------
    c0, c1 : (n, 3) colour at the front and back of each piece.
    a0, a1 : (n,) opacity at the front and back (clamped to MAX_OPACITY).
    length : (n,) length of each piece in world units.
    unit_distance : the transfer function's unit distance ``u``.

    Returns
    -------
    rgb : (n, 3) premultiplied emitted colour of each piece, as seen from its front.
    theta : (n,) optical depth of each piece; its alpha is ``1 - exp(-theta)``.

    Notes
    -----
    The optical depth is exact. Pieces are first cut where ``1 - a`` changes by 2x (the
    extinction is steep as ``a -> 1``); on each, the colour uses
    ``I = c0 - c1 T(L) + c' int T``, with ``int T`` by 6-point Gauss–Legendre on
    sub-pieces of optical depth <= 1/2 (those past optical depth 40 are dropped: their
    weight is below 4e-18), and the cuts are composited front to back. Measured against
    fine quadrature the colour is within 1e-9 (``tests/test_optics.py``).
    """
    c0 = np.asarray(c0, dtype=np.float64)
    c1 = np.asarray(c1, dtype=np.float64)
    length = np.asarray(length, dtype=np.float64)
    n = length.shape[0]
    if n == 0:
        return np.zeros((0, 3)), np.zeros(0)
    part, c_a, c_b, a_a, a_b, sub_len = _split_at_transmittance_ratio(
        c0, c1, np.asarray(a0, dtype=np.float64), np.asarray(a1, dtype=np.float64), length)
    rgb, theta = _integrate_smooth(c_a, c_b, a_a, a_b, sub_len, unit_distance)
    if part.shape[0] == n:
        return rgb, theta
    # Composite the cuts of each piece front to back (they are contiguous, in ray order).
    total = np.bincount(part, weights=theta, minlength=n)
    before = np.cumsum(theta) - theta
    start = np.cumsum(np.bincount(part, minlength=n)) - np.bincount(part, minlength=n)
    w = np.exp(-(before - before[start][part]))
    out = np.stack([np.bincount(part, weights=rgb[:, c] * w, minlength=n) for c in range(3)], axis=1)
    return out.astype(np.float64), total.astype(np.float64)


def integrate_linear_pieces(
    c0: Array, c1: Array, a0: Array, a1: Array, length: Array, unit_distance: float
) -> tuple[Array, Array]:
    """:func:`integrate_pieces` for VTK's convention ``tau = a / u`` (optics ``"linear"``).

    With ``a`` linear along the piece, ``tau`` is linear too, so the optical depth
    ``L (a0 + a1) / (2u)`` is exact, and so is the fraction of the piece where it reaches
    a given value (a quadratic). The colour is ``I = c0 - c1 T(L) + c' int T`` with
    ``int T`` by 6-point Gauss–Legendre on sub-pieces of optical depth <= 1/2, cut at
    equal optical depth by that closed form; those past optical depth 40 are dropped.
    ``tau`` is bounded by ``1/u``, so no cut by transmittance ratio is needed.

    Examples
    --------
    >>> rgb, theta = integrate_linear_pieces(np.ones((1, 3)), np.ones((1, 3)), np.array([0.5]),
    ...                                      np.array([0.5]), np.array([1.0]), 1.0)
    >>> round(float(theta[0]), 12), round(float(rgb[0, 0]), 12)  # 1 - exp(-0.5)
    (0.5, 0.393469340287)
    """
    c0 = np.asarray(c0, dtype=np.float64)
    c1 = np.asarray(c1, dtype=np.float64)
    a0 = np.clip(np.asarray(a0, dtype=np.float64), 0.0, 1.0)
    a1 = np.clip(np.asarray(a1, dtype=np.float64), 0.0, 1.0)
    length = np.asarray(length, dtype=np.float64)
    u = float(unit_distance)
    n = length.shape[0]
    if n == 0:
        return np.zeros((0, 3)), np.zeros(0)
    theta = length * (a0 + a1) / (2.0 * u)
    n_sub = np.clip(np.ceil(np.minimum(theta, _THETA_CUT) / _SUB_THETA), 1, _MAX_SUB).astype(np.int64)
    piece = np.repeat(np.arange(n), n_sub)
    k = np.arange(piece.shape[0]) - np.repeat(np.cumsum(n_sub) - n_sub, n_sub)
    # Optical depth at fraction f: qa f^2 + qb f, with qb = L a0 / u and qa = L (a1 - a0) / (2u).
    qb = (length * a0 / u)[piece]
    qa = (length * (a1 - a0) / (2.0 * u))[piece]
    cut = np.minimum(theta, _THETA_CUT)[piece]

    def frac_at(q: Array) -> Array:
        target = q * cut
        root = np.sqrt(np.maximum(qb * qb + 4.0 * qa * target, 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            f = np.where(target > 0, 2.0 * target / (qb + root), 0.0)
        return np.clip(np.nan_to_num(f, nan=0.0), 0.0, 1.0)

    ns = n_sub[piece].astype(np.float64)
    f_lo = frac_at(k / ns)
    f_hi = np.where((k == n_sub[piece] - 1) & (theta[piece] <= _THETA_CUT), 1.0, frac_at((k + 1) / ns))
    frac = f_lo[:, None] + (f_hi - f_lo)[:, None] * _GL_X[None, :]
    t_vals = np.exp(-(qa[:, None] * frac + qb[:, None]) * frac)
    sub_int = (t_vals @ _GL_W) * (f_hi - f_lo) * length[piece]
    int_t = np.bincount(piece, weights=sub_int, minlength=n)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(length[:, None] > 0, (c1 - c0) / length[:, None], 0.0)
    rgb = c0 - c1 * np.exp(-theta)[:, None] + slope * int_t[:, None]
    rgb *= (theta > 0)[:, None]  # a transparent piece emits nothing
    return np.clip(rgb, 0.0, None), theta


def vtk_segments(
    c0: Array, c1: Array, a0: Array, a1: Array, length: Array, unit_distance: float
) -> tuple[Array, Array]:
    """A segment as VTK's projected tetrahedra colour it (optics ``"vtk"``).

    ``vtkOpenGLProjectedTetrahedraMapper`` gives the fragment the mean of the front and
    back colours and opacities (interpolated from the vertices, with the thick vertex
    holding the average of its two ends) and the fragment shader computes
    ``alpha = 1 - exp(-a_mean * d / u)``; the blend weights the mean colour by that alpha.
    So ``theta = L (a0 + a1) / (2u)`` (exact for ``tau = a/u``) but the colour ignores the
    attenuation inside the segment: ``rgb = (c0 + c1) / 2 * alpha``.

    Examples
    --------
    >>> rgb, theta = vtk_segments(np.array([[1.0, 0, 0]]), np.array([[0.0, 0, 1]]), np.array([0.2]),
    ...                           np.array([0.6]), np.array([1.0]), 1.0)
    >>> float(theta[0]), np.round(rgb[0], 6).tolist()
    (0.4, [0.16484, 0.0, 0.16484])
    """
    c0 = np.asarray(c0, dtype=np.float64)
    c1 = np.asarray(c1, dtype=np.float64)
    a0 = np.clip(np.asarray(a0, dtype=np.float64), 0.0, 1.0)
    a1 = np.clip(np.asarray(a1, dtype=np.float64), 0.0, 1.0)
    theta = np.asarray(length, dtype=np.float64) * (a0 + a1) / (2.0 * float(unit_distance))
    return 0.5 * (c0 + c1) * (-np.expm1(-theta))[:, None], theta


def vtk_vertex_rgba8(tf: Any, scalars: NDArray[np.floating[Any]]) -> NDArray[np.uint8]:
    """Colour and opacity at the vertices as VTK's projected tetrahedra store them.

    ``vtkProjectedTetrahedraMapper::MapScalarsToColors`` evaluates the colour and opacity
    functions at every point's scalar and keeps 8 bits by truncation,
    ``(unsigned char)(v * 255.9999)``; the parity renderer (optics ``"vtk"``) interpolates
    these, as VTK does, rather than the scalar.

    Parameters
    ----------
    tf : a :class:`tetvr.TransferFunction`.
    scalars : (n,) point (or cell) values.

    Returns
    -------
    (n, 4) uint8 RGBA.

    Examples
    --------
    >>> from tetvr import TransferFunction
    >>> tf = TransferFunction(color=((0, 0, 0, 0), (1, 1, 1, 1)), opacity=((0, 0.0), (1, 1.0)))
    >>> vtk_vertex_rgba8(tf, np.array([0.5, 1.0])).tolist()
    [[127, 127, 127, 127], [255, 255, 255, 255]]
    """
    rgb, opacity = tf.evaluate(np.asarray(scalars, dtype=np.float64))
    rgba = np.concatenate([rgb, opacity[:, None]], axis=1)
    return (np.clip(rgba, 0.0, 1.0) * 255.9999).astype(np.uint8)


def _integrate_smooth(
    c0: Array, c1: Array, a0: Array, a1: Array, length: Array, unit_distance: float
) -> tuple[Array, Array]:
    """integrate_pieces for pieces on which 1 - a changes by at most 2x."""
    c0 = np.asarray(c0, dtype=np.float64)
    c1 = np.asarray(c1, dtype=np.float64)
    length = np.asarray(length, dtype=np.float64)
    u = float(unit_distance)
    x0 = 1.0 - np.clip(a0, 0.0, MAX_OPACITY)
    x1 = 1.0 - np.clip(a1, 0.0, MAX_OPACITY)
    theta = length * mean_neg_log(x0, x1) / u
    n = length.shape[0]
    if n == 0:
        return np.zeros((0, 3)), np.zeros(0)

    # Sub-pieces: as many as the optical depth needs (capped where light is gone).
    n_sub = np.clip(np.ceil(np.minimum(theta, _THETA_CUT) / _SUB_THETA), 1, _MAX_SUB).astype(np.int64)
    piece = np.repeat(np.arange(n), n_sub)
    start = np.cumsum(n_sub) - n_sub
    k = np.arange(piece.shape[0]) - start[piece]
    # Cut sub-pieces at equal optical depth when it is large, so each carries <= 1/2;
    # positions of equal theta are found by bisection on the closed form.
    f_lo = _frac_at_theta(x0[piece], x1[piece], length[piece], u, theta[piece], k / n_sub[piece])
    f_hi = _frac_at_theta(x0[piece], x1[piece], length[piece], u, theta[piece], (k + 1) / n_sub[piece])
    last = k == n_sub[piece] - 1
    f_hi = np.where(last & (theta[piece] <= _THETA_CUT), 1.0, f_hi)

    frac = f_lo[:, None] + (f_hi - f_lo)[:, None] * _GL_X[None, :]
    t_vals = np.exp(-_theta_partial(x0[piece, None], x1[piece, None], frac, length[piece, None], u))
    sub_int = (t_vals @ _GL_W) * (f_hi - f_lo) * length[piece]
    int_t = np.bincount(piece, weights=sub_int, minlength=n)

    t_end = np.exp(-theta)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(length[:, None] > 0, (c1 - c0) / length[:, None], 0.0)
    rgb = c0 - c1 * t_end[:, None] + slope * int_t[:, None]
    # Zero-length or transparent pieces emit nothing; guard rounding to tiny negatives.
    return np.clip(rgb, 0.0, None), theta


def _split_at_transmittance_ratio(
    c0: Array, c1: Array, a0: Array, a1: Array, length: Array
) -> tuple[NDArray[np.int64], Array, Array, Array, Array, Array]:
    """Cut pieces so that ``1 - a`` changes by at most a factor _MAX_X_RATIO on each.

    Sub-pieces cut only by optical depth meet ``tau = -ln(1 - a) / u``, whose derivative
    ``a' / (1 - a)`` is huge where the opacity ramps towards 1: a piece with opacity
    1 -> 0 was 4.5e-5 off in colour. Cutting at geometric steps of ``1 - a`` (opacity
    still linear on every sub-piece, at most log2(1e6) = 20 cuts) brings that below 1e-10.

    Returns, per sub-piece in ray order: index of its piece, front and back colour,
    front and back opacity (clamped), length.
    """
    a0 = np.clip(a0, 0.0, MAX_OPACITY)
    a1 = np.clip(a1, 0.0, MAX_OPACITY)
    x0, x1 = 1.0 - a0, 1.0 - a1
    n_cut = np.ceil(np.abs(np.log(x1 / x0)) / math.log(_MAX_X_RATIO) - 1e-9).astype(np.int64)
    n_sub = np.maximum(n_cut, 1)
    if np.all(n_sub == 1):
        return np.arange(length.shape[0], dtype=np.int64), c0, c1, a0, a1, length
    part = np.repeat(np.arange(length.shape[0], dtype=np.int64), n_sub)
    j = np.arange(part.shape[0], dtype=np.int64) - np.repeat(np.cumsum(n_sub) - n_sub, n_sub)
    ns = n_sub[part].astype(np.float64)
    xa, xb = x0[part], x1[part]
    same = xa == xb
    ratio = xb / xa

    def frac(q: Array) -> tuple[Array, Array]:
        # Fraction along the piece where 1 - a = xa * ratio**q, and the opacity there.
        x = xa * ratio**q
        f = np.where(same, q, (x - xa) / np.where(same, 1.0, xb - xa))
        return np.clip(f, 0.0, 1.0), 1.0 - x

    f_lo, o_lo = frac(j / ns)
    f_hi, o_hi = frac((j + 1) / ns)
    # The ends keep their exact values.
    first, last = j == 0, j == n_sub[part] - 1
    f_lo, o_lo = np.where(first, 0.0, f_lo), np.where(first, a0[part], o_lo)
    f_hi, o_hi = np.where(last, 1.0, f_hi), np.where(last, a1[part], o_hi)
    dc = (c1 - c0)[part]
    c_lo = c0[part] + dc * f_lo[:, None]
    c_hi = c0[part] + dc * f_hi[:, None]
    return part, c_lo, c_hi, o_lo, o_hi, (f_hi - f_lo) * length[part]


def _frac_at_theta(
    x0: Array, x1: Array, length: Array, u: float, theta: Array, q: Array
) -> Array:
    """Fraction ``f`` of a piece where the optical depth reaches ``q * min(theta, cut)``.

    Optical depth is monotone in ``f``; 40 bisection steps give ~1e-12 precision.
    """
    target = q * np.minimum(theta, _THETA_CUT)
    lo = np.zeros_like(target)
    hi = np.ones_like(target)
    trivial = (q <= 0) | ((q >= 1) & (theta <= _THETA_CUT))
    uniform = np.minimum(theta, _THETA_CUT) <= _SUB_THETA  # one sub-piece: no search needed
    if np.all(trivial | uniform):
        return np.where(q >= 1, 1.0, np.where(q <= 0, 0.0, q))
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        below = _theta_partial(x0, x1, mid, length, u) < target
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    f = 0.5 * (lo + hi)
    return np.where(q <= 0, 0.0, np.where((q >= 1) & (theta <= _THETA_CUT), 1.0, f))

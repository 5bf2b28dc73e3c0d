"""Integrating ray segments and compositing them into pixels: the optics half of the CPU reference.

Steps 4-5 of :mod:`tetvr.reference.tets` (Williams, Max & Stein 1998): the scalar is
linear along a segment, so each segment is cut at the transfer function's breakpoints,
colour and opacity are then linear on every piece, and
:func:`tetvr.optics.model.integrate_pieces` integrates each piece exactly; pieces and
segments are composited front to back per pixel: colour ``sum_k rgb_k exp(-sum_{j<k}
theta_j)``, alpha ``1 - exp(-sum_k theta_k)``. The volume reference
(:mod:`tetvr.reference.volume`) integrates and composites its samples with the same two
functions.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from tetvr.optics.model import _SUB_THETA, OPTICS, integrate_linear_pieces, integrate_pieces, piece_optical_depth, vtk_segments
from tetvr.optics.transfer import TransferFunction

__all__ = ["composite", "integrate_segments"]

# Sub-pieces evaluated per integrate_pieces call: bounds its (n_sub, 6) temporaries.
_SUB_BUDGET = 1 << 20

Float = NDArray[np.float64]
Int = NDArray[np.int64]


def integrate_segments(
    scalar_in: Float, scalar_out: Float, length_world: Float, tf: TransferFunction, *, optics: str = "exact"
) -> tuple[Float, Float]:
    """Integrate segments along which the scalar runs linearly.

    Each segment is cut where the scalar crosses a transfer-function breakpoint, so that
    colour and opacity are linear on every piece; the pieces are integrated exactly
    (:func:`tetvr.optics.model.integrate_pieces`) and composited front to back.

    Parameters
    ----------
    scalar_in, scalar_out : (n,) scalar at the front and back of each segment.
    length_world : (n,) length of each segment in world units.
    tf : the transfer function.
    optics : "exact" (``tau = -ln(1 - a)/u``), "linear" (``tau = a/u``, integrated exactly)
        or "vtk" (VTK's projected-tetrahedra segment: mean end colour, not cut at
        breakpoints); see :data:`tetvr.optics.model.OPTICS` and docs/paraview.md.

    Returns
    -------
    rgb : (n, 3) premultiplied colour of each segment, as seen from its front.
    theta : (n,) optical depth of each segment.

    Examples
    --------
    >>> tf = TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)), opacity=((0, 0.5), (1, 0.5)))
    >>> rgb, theta = integrate_segments(np.array([0.0]), np.array([1.0]), np.array([1.0]), tf)
    >>> float(1 - np.exp(-theta[0]))  # a slab of one unit distance has the TF opacity
    0.5
    """
    s_in = np.asarray(scalar_in, dtype=np.float64).reshape(-1)
    s_out = np.asarray(scalar_out, dtype=np.float64).reshape(-1)
    length = np.asarray(length_world, dtype=np.float64).reshape(-1)
    if not s_in.shape == s_out.shape == length.shape:
        raise ValueError(
            f"scalar_in, scalar_out and length_world must have the same length, got "
            f"{s_in.shape[0]}, {s_out.shape[0]}, {length.shape[0]}"
        )
    n = s_in.shape[0]
    if optics not in OPTICS:
        raise ValueError(f"optics must be one of {OPTICS}, got {optics!r}")
    if optics == "vtk":  # one formula per segment, from its two ends only
        c_in, o_in = tf.evaluate(s_in)
        c_out, o_out = tf.evaluate(s_out)
        return vtk_segments(c_in, c_out, o_in, o_out, length, tf.unit_distance)
    seg, s_a, s_b, piece_len = _split_at_breakpoints(s_in, s_out, length, tf.breakpoints)
    c_a, o_a = tf.evaluate(s_a)
    c_b, o_b = tf.evaluate(s_b)
    rgb, theta = _integrate_batched(c_a, c_b, o_a, o_b, piece_len, tf.unit_distance,
                                    integrate_linear_pieces if optics == "linear" else integrate_pieces)
    # Pieces are in ray order inside each segment, segments contiguous.
    excl = _exclusive_group_cumsum(theta, seg)
    w = np.exp(-excl)
    seg_rgb = np.empty((n, 3))
    for c in range(3):
        seg_rgb[:, c] = np.bincount(seg, weights=rgb[:, c] * w, minlength=n)
    seg_theta = np.bincount(seg, weights=theta, minlength=n).astype(np.float64, copy=False)
    return seg_rgb, seg_theta


def _split_at_breakpoints(
    s_in: Float, s_out: Float, length: Float, bp: Float
) -> tuple[Int, Float, Float, Float]:
    """Cut segments at the breakpoints strictly between their end scalars.

    Returns, per piece in ray order: segment index, scalar at its front and back, and
    world length.
    """
    n = s_in.shape[0]
    lo = np.minimum(s_in, s_out)
    hi = np.maximum(s_in, s_out)
    first = np.searchsorted(bp, lo, side="right")  # first breakpoint > lo
    last = np.searchsorted(bp, hi, side="left")  # first breakpoint >= hi
    n_inner = np.maximum(last - first, 0)
    n_piece = n_inner + 1
    seg = np.repeat(np.arange(n, dtype=np.int64), n_piece)
    k = np.arange(seg.shape[0], dtype=np.int64) - np.repeat(np.cumsum(n_piece) - n_piece, n_piece)
    s0, s1, inner = s_in[seg], s_out[seg], n_inner[seg]
    rising = s1 >= s0

    def breakpoint_(j: Int) -> Float:
        # The j-th breakpoint met along the ray (indices only used where 0 <= j < inner).
        idx = np.where(rising, first[seg] + j, last[seg] - 1 - j)
        return bp[np.clip(idx, 0, bp.shape[0] - 1)]

    head, tail = k == 0, k == inner
    s_a = np.where(head, s0, breakpoint_(k - 1))
    s_b = np.where(tail, s1, breakpoint_(k))
    # Fractions along the segment; a segment that is not cut keeps its exact length.
    ds = np.where(s1 == s0, 1.0, s1 - s0)
    f_a = np.where(head, 0.0, np.clip((s_a - s0) / ds, 0.0, 1.0))
    f_b = np.where(tail, 1.0, np.clip((s_b - s0) / ds, 0.0, 1.0))
    return seg, s_a, s_b, (f_b - f_a) * length[seg]


def _integrate_batched(
    c0: Float, c1: Float, a0: Float, a1: Float, length: Float, u: float,
    integrate: Callable[..., tuple[Float, Float]] = integrate_pieces,
) -> tuple[Float, Float]:
    """integrate_pieces in batches that bound its sub-piece temporaries.

    Thin pieces (one sub-piece) go in batches of their own: integrate_pieces then skips
    its bisection search, which is the costly part. Results are per piece, unaffected
    by the batching.
    """
    n = length.shape[0]
    rgb = np.zeros((n, 3))
    theta = np.zeros(n)
    est = piece_optical_depth(a0, a1, length, u)
    # As integrate_pieces counts them (past optical depth 40 it drops the rest).
    n_sub = np.clip(np.ceil(np.minimum(est, 40.0) / _SUB_THETA), 1, None)
    for group in (np.nonzero(est <= _SUB_THETA)[0], np.nonzero(est > _SUB_THETA)[0]):
        ends = np.cumsum(n_sub[group])
        start = 0
        while start < group.shape[0]:
            base = ends[start - 1] if start else 0.0
            stop = max(int(np.searchsorted(ends, base + _SUB_BUDGET, side="right")), start + 1)
            idx = group[start:stop]
            rgb[idx], theta[idx] = integrate(c0[idx], c1[idx], a0[idx], a1[idx], length[idx], u)
            start = stop
    return rgb, theta


def _exclusive_group_cumsum(values: Float, group: Int) -> Float:
    """Sum of the earlier values of the same group, for sorted (contiguous) groups.

    The running sum is reset at each group start rather than taken globally and
    differenced, so its rounding error scales with one group's total, not the image's;
    what rounding leaves at a group start is then removed, so each group starts at 0.
    """
    x = values.copy()
    if x.shape[0] == 0:
        return x
    is_start = np.r_[True, group[1:] != group[:-1]]
    starts = np.nonzero(is_start)[0]
    totals = np.add.reduceat(values, starts)
    x[starts[1:]] -= totals[:-1]
    run = np.cumsum(x) - values
    return run - run[starts][np.cumsum(is_start) - 1]


def composite(pixel: Int, t_in: Float, rgb: Float, theta: Float, n_pixels: int) -> Float:
    """Composite segments front to back into pixels.

    Parameters
    ----------
    pixel : (n,) pixel of each segment.
    t_in : (n,) depth of its front; segments of a pixel are composited in this order.
    rgb : (n, 3) premultiplied colour of each segment, as seen from its front.
    theta : (n,) optical depth of each segment.
    n_pixels : number of pixels.

    Returns
    -------
    (n_pixels, 4) float64 premultiplied RGBA; pixels without segments are 0.

    Examples
    --------
    >>> composite(np.array([0, 0]), np.array([2.0, 1.0]), np.array([[0.0, 0, 0], [0.5, 0, 0]]),
    ...           np.array([0.0, np.log(2)]), 1).round(6).tolist()
    [[0.5, 0.0, 0.0, 0.5]]
    """
    pixel = np.asarray(pixel, dtype=np.int64)
    order = np.lexsort((t_in, pixel))
    pixel, rgb, theta = pixel[order], rgb[order], theta[order]
    w = np.exp(-_exclusive_group_cumsum(theta, pixel))
    out = np.empty((n_pixels, 4))
    for c in range(3):
        out[:, c] = np.bincount(pixel, weights=rgb[:, c] * w, minlength=n_pixels)
    out[:, 3] = -np.expm1(-np.bincount(pixel, weights=theta, minlength=n_pixels))
    return out

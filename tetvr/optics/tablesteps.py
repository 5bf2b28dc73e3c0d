"""Lookups in a table whose transfer function steps at its nodes: segments cut at the nodes.

About this technique
--------------------
A transfer function with steps (ParaView's discretized colour maps: 256 bands of constant
colour) gets a table node on every step where it can (:func:`tetvr.optics.table.aligned_nodes`),
and each bin is integrated with the sides of the steps it lies between
(:func:`tetvr.optics.preintegrate.build_table`), so an entry between two nodes is exact. A
lookup between the nodes is not: the integral of a segment from scalar ``sf`` to ``sb``
is continuous away from the diagonal ``sf = sb``, but where both ends near the same node
its colour depends on the direction it comes from (how much of the segment lies in each
band), and the diagonal entry can hold only one value (the mean of the two sides). The
trilinear fetch of Engel et al. (2001) then blends the bands of every segment that lies
within a bin or two of a step: on ParaView's default map, up to 2.5/255 for one segment
(0.17/255 for the same map continuous), and images 15-20 dB further from the reference.

Instead, as for any segment cut in pieces and composited front to back (the table's own
incremental build, Lum et al. 2004), a segment is cut at the nodes it crosses
(:func:`cut_at_nodes`):

* the *run* between the first and the last node it reaches, read at those two nodes (no
  interpolation along the scalar axes, only along the thickness axis; a segment from node
  to node is all run, the table's own entry);
* the partial bin at each end, read within its bin from a 2 x 2 block of corners: the two
  off-diagonal entries of the bin (a segment across the whole bin, both ways) and the
  constant-scalar values at its two ends *on the bin's side* of each step
  (:func:`corner_blocks`). Within a bin the transfer function is continuous, so the
  bilinear fetch errs there as it does for a continuous map.

The shader does the same (``shaders/lookup_steps.glsl``, ``TABLE_STEPS``): three fetches
instead of one, compiled in only for such tables; :func:`lookup_cut` is its CPU model.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["corner_blocks", "cut_at_nodes", "lookup_cut", "trilinear", "STEPS_UNIT"]

#: The texture unit of a stepped table's corner blocks (``shaders/lookup_steps.glsl``'s u_steps).
STEPS_UNIT = 11

Float = NDArray[np.float64]
#: A piece's premultiplied RGBA from (front node coordinate, back node coordinate, bin or
#: -1 for a run between nodes, world length).
PieceLookup = Callable[[Float, Float, NDArray[np.int64], Float], Float]


def corner_blocks(data: NDArray[np.generic], start: NDArray[np.generic], end: NDArray[np.generic]) -> NDArray[np.generic]:
    """The 2 x 2 corner block of every bin, ``(K + 1, 2, 2 (N - 1), RGBA)``, texel
    ``[k, v, 2 i + u]`` the entry for front node ``i + u`` and back node ``i + v``.

    ``data`` is the table (``[k, back, front, RGBA]``); ``start`` and ``end`` (``(K + 1,
    N - 1, RGBA)``, encoded as the table) are each bin's constant-scalar entries at its first
    and last node, on the bin's side of a step there.

    >>> data = np.arange(3 * 3 * 4, dtype=np.float32).reshape(1, 3, 3, 4)
    >>> block = corner_blocks(data, -np.ones((1, 2, 4), np.float32), -2 * np.ones((1, 2, 4), np.float32))
    >>> block[0, :, :, 0].tolist()  # bin 0: corners -1, front 1 back 0 (4), front 0 back 1 (12), -2
    [[-1.0, 4.0, -1.0, 20.0], [12.0, -2.0, 28.0, -2.0]]
    """
    k1, n = data.shape[0], data.shape[1]
    i = np.arange(n - 1)
    block = np.empty((k1, 2, 2 * (n - 1), data.shape[3]), dtype=data.dtype)
    block[:, 0, 0::2] = start
    block[:, 0, 1::2] = data[:, i, i + 1]  # front i + 1, back i
    block[:, 1, 0::2] = data[:, i + 1, i]  # front i, back i + 1
    block[:, 1, 1::2] = end
    return block


def cut_at_nodes(fi: Float, fj: Float, n_nodes: int) -> list[tuple[Float, Float, NDArray[np.int64], Float]]:
    """A segment from fractional node ``fi`` to ``fj`` (clamped to the nodes) cut at the
    nodes it crosses: front piece, run, back piece, each ``(p, q, bin, share)``, ``p`` and
    ``q`` its ends (fractional nodes), ``bin`` the bin it lies in (-1: the run, from the
    first to the last node the segment reaches, its ends included) and ``share`` its part of
    the segment's length (0: no such piece; from node to node a segment is all run, read at
    the table's own entry). A segment that crosses no node is all front piece.

    >>> [(float(p[0]), float(q[0]), int(b[0]), float(s[0])) for p, q, b, s in
    ...  cut_at_nodes(np.array([2.5]), np.array([5.5]), 8)]
    [(2.5, 3.0, 2, 0.16666666666666666), (3.0, 5.0, -1, 0.6666666666666666), (5.0, 5.5, 5, 0.16666666666666666)]
    """
    fi = np.clip(np.asarray(fi, dtype=np.float64), 0.0, n_nodes - 1.0)
    fj = np.clip(np.asarray(fj, dtype=np.float64), 0.0, n_nodes - 1.0)
    up = fj >= fi
    # Within one bin: no node strictly between the ends.
    within = np.where(up, np.ceil(fj) - 1.0 < np.floor(fi) + 1.0, np.floor(fj) + 1.0 > np.ceil(fi) - 1.0)
    # The first and the last node the segment reaches, along the ray.
    a = np.where(up, np.ceil(fi), np.floor(fi))
    b = np.where(up, np.floor(fj), np.ceil(fj))
    span = np.abs(fj - fi)
    per = np.where(within, 0.0, 1.0 / np.where(span > 0, span, 1.0))
    last = n_nodes - 2.0

    def bin_of(x: Float) -> NDArray[np.int64]:
        return np.clip(x, 0.0, last).astype(np.int64)  # type: ignore[no-any-return]

    single = np.floor(np.minimum(fi, fj))
    front = (fi, np.where(within, fj, a), bin_of(np.where(within, single, np.where(up, a - 1.0, a))),
             np.where(within, 1.0, np.abs(a - fi) * per))
    run = (a, b, np.full(fi.shape, -1, np.int64), np.abs(b - a) * per)
    back = (b, fj, bin_of(np.where(up, b, b - 1.0)), np.abs(fj - b) * per)
    return [front, run, back]


def lookup_cut(fi: Float, fj: Float, d: Float, n_nodes: int, piece: PieceLookup) -> Float:
    """Premultiplied RGBA of segments from fractional node ``fi`` to ``fj`` of world length
    ``d``: the pieces of :func:`cut_at_nodes`, each looked up by ``piece``, composited front
    to back (pieces of no length are skipped)."""
    out = np.zeros(np.shape(fi) + (4,))
    for p, q, where, share in cut_at_nodes(fi, fj, n_nodes):
        rgba = piece(p, q, where, d * share)
        rgba = np.where((share > 0)[..., None], rgba, 0.0)
        out += (1.0 - out[..., 3:]) * rgba
    return out


def trilinear(texels: NDArray[np.generic], x: Float, y: Float, k: Float) -> Float:
    """``texels`` (``[k, y, x, RGBA]``) interpolated at fractional texel indices, as a
    linear texture fetch clamped to the edge reads it (float64; uint8 scaled to [0, 1])."""
    data = texels.astype(np.float64)
    if texels.dtype == np.uint8:
        data /= 255.0
    out = np.zeros(np.shape(x) + (4,))
    lo = [np.clip(np.floor(c), 0, size - 1).astype(int) for c, size in zip((k, y, x), data.shape[:3])]
    hi = [np.minimum(c + 1, size - 1) for c, size in zip(lo, data.shape[:3])]
    w = [np.clip(c - c0, 0.0, 1.0) for c, c0 in zip((k, y, x), lo)]
    for kk, wk in ((lo[0], 1 - w[0]), (hi[0], w[0])):
        for yy, wy in ((lo[1], 1 - w[1]), (hi[1], w[1])):
            for xx, wx in ((lo[2], 1 - w[2]), (hi[2], w[2])):
                out += (wk * wy * wx)[..., None] * data[kk, yy, xx]
    return out

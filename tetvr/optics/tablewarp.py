"""Where a warped pre-integration table puts its scalar nodes, and how the GPU finds them.

About this technique
--------------------
A pre-integration table (Kraus, Qiao & Ebert 2004) takes the transfer function as linear
between its scalar nodes, and the GPU interpolates its entries between them. With nodes
evenly spaced, a narrow feature (an opacity spike a few hundredths of the range wide: an
isosurface-like transfer function) falls between a few nodes, its control points are cut
off, and the image errs by percents however the thickness axis is cut. Placing every node
evenly finely enough costs N^2 (2048 bins: seconds of build, GiB of memory).

A *warped* table puts its nodes where the transfer function changes, as adaptive meshing
places mesh nodes by equidistributing a monitor function: half of the nodes evenly over the
range, half by the variation of the opacity and the opacity-weighted colour, and every
control point of the transfer function on a node. Between two nodes the transfer function
is then exactly linear, as the table assumes (:func:`tetvr.optics.preintegrate.build_table` with
``warp=True`` builds the entries at these nodes). The build's work grows with the cube of
the node count, so only N / 4 control points get nodes of their own: where a map has more
(a 256-point colour map, thousands of spikes, a discretized map's band edges), those the
table would miss most (:func:`max_warped_nodes` bounds the count).

The GPU finds a scalar's fractional node index through a small texture of ``cells`` equal
cells over the table's range (:func:`warp_cells`): no node spacing is narrower than a cell,
so a cell holds at most one node, and each texel stores that node's position and index and
the slopes (nodes per cell) on both sides of it: ``index = n + (x - split) * slope``, exact
for nodes anywhere, not only on cell boundaries (``shaders/lookup.glsl``, ``TABLE_WARP``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tetvr.optics.model import MAX_OPACITY, mean_neg_log
from tetvr.optics.transfer import TransferFunction

__all__ = ["warped_nodes", "warp_cells", "extinction_cells", "node_opacity_cells", "warp_extinction", "max_warped_nodes",
           "WARP_CELLS", "WARP_EVEN_SHARE", "WARP_EXTRA_NODES"]

#: Cells of the warp texture over the table's scalar range: the narrowest node spacing.
WARP_CELLS = 8192
#: The share of the nodes spread evenly over the range (the rest follow the transfer
#: function's variation): keeps the smooth stretches, where thick segments still bend the
#: integral, from being left with too few nodes.
WARP_EVEN_SHARE = 0.5
#: Control points that get a node of their own, at most N // WARP_EXTRA_NODES of them
#: (those the table would miss most, :func:`_fixed_points`), on top of the N placed by
#: variation: the build's work grows with the cube of the node count, so a map of 256 colour
#: points (a matplotlib colour map) or thousands of opacity spikes must not set it.
WARP_EXTRA_NODES = 4


def max_warped_nodes(n_bins: int) -> int:
    """The most nodes :func:`warped_nodes` returns for ``n_bins``.

    >>> max_warped_nodes(128)
    162
    """
    return int(n_bins) + int(n_bins) // WARP_EXTRA_NODES + 2


def _variation_per_cell(tf: TransferFunction, lo: float, hi: float, cells: int) -> NDArray[np.float64]:
    """Total variation, per cell of ``cells`` over [lo, hi], of the opacity plus the
    largest of the opacity-weighted colour channels (control points inside a cell count)."""
    s = np.union1d(np.linspace(lo, hi, cells + 1), np.clip(tf.breakpoints, lo, hi))
    color, opacity = tf.evaluate(s)
    g = np.column_stack([opacity, color * opacity[:, None]])
    dv = np.abs(np.diff(g, axis=0))
    v = dv[:, 0] + dv[:, 1:].max(axis=1)
    mid = 0.5 * (s[1:] + s[:-1])
    cell = np.clip(((mid - lo) / (hi - lo) * cells).astype(np.int64), 0, cells - 1)
    return np.bincount(cell, weights=v, minlength=cells).astype(np.float64)


def warped_nodes(tf: TransferFunction, scalar_range: tuple[float, float], n_bins: int, *,
                 cells: int = WARP_CELLS, even_share: float = WARP_EVEN_SHARE) -> NDArray[np.float64]:
    """About ``n_bins`` node scalars over ``scalar_range``, ascending, the first and last
    at its ends, dense where the transfer function varies, every control point inside the
    range on a node, and no two nodes closer than one of ``cells`` cells.

    The count is ``n_bins`` or a few more (control points are added where no node is
    within a cell; where there are more than ``n_bins // WARP_EXTRA_NODES``, those whose
    loss would cost most), at most :func:`max_warped_nodes`, fewer only where the cells
    cannot hold that many.

    Examples
    --------
    >>> tf = TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)),
    ...                       opacity=((0, 0), (0.5, 0), (0.501, 0.9), (0.502, 0), (1, 0)))
    >>> x = warped_nodes(tf, (0.0, 1.0), 64)
    >>> bool(np.isin([0.5, 0.501, 0.502], x).all()), int(np.sum((x > 0.49) & (x < 0.51)))
    (True, 20)
    """
    lo, hi = float(scalar_range[0]), float(scalar_range[1])
    n = int(n_bins)
    if n < 2 or not hi > lo:
        raise ValueError(f"warped_nodes needs n_bins >= 2 and lo < hi, got {n_bins!r} over {scalar_range!r}")
    cells = int(cells)
    v = _variation_per_cell(tf, lo, hi, cells)
    # A segment from sf into a feature changes with sf on the scale of its own scalar span
    # |sb - sf|, so the nodes thin out with the distance to the feature, graded (spacing
    # proportional to the distance): the variation spread by the kernel 1 / (distance + 1 cell).
    kernel = 1.0 / (np.abs(np.arange(-cells + 1, cells, dtype=np.float64)) + 1.0)
    size = 1 << int(np.ceil(np.log2(3 * cells)))
    graded = np.fft.irfft(np.fft.rfft(v, size) * np.fft.rfft(kernel, size), size)[cells - 1: 2 * cells - 1]
    graded = np.maximum(graded, 0.0)
    total = float(graded.sum())
    rho = np.full(cells, 1.0 / cells)
    if total > 0:
        rho = even_share * rho + (1.0 - even_share) * graded / total
    # At most one node per cell: cap each cell's share at one node spacing of the
    # cumulative, handing the excess to the uncapped cells (water filling).
    cap = 1.0 / max(n - 1, 1)
    for _ in range(64):
        over = rho > cap
        excess = float((rho[over] - cap).sum())
        if excess <= 1e-15 * cap:
            break
        rho[over] = cap
        free = ~over & (rho < cap)
        if not free.any():
            break
        rho[free] += excess * rho[free] / rho[free].sum()
    cum = np.concatenate([[0.0], np.cumsum(rho)])
    cum /= cum[-1]
    x_free = np.interp(np.linspace(0.0, 1.0, n), cum, np.arange(cells + 1.0))
    # Control points inside the range, and the two ends, are fixed nodes (in cell units).
    fixed = np.unique(np.concatenate([[0.0, float(cells)], _fixed_points(tf, lo, hi, n, cells)]))
    xs = np.concatenate([fixed, x_free])
    is_fixed = np.concatenate([np.ones(fixed.size, bool), np.zeros(x_free.size, bool)])
    order = np.lexsort((~is_fixed, xs))
    xs, is_fixed = xs[order], is_fixed[order]
    # A free node within a cell of a fixed one gives way; then, left to right, any node
    # within a cell of the last kept one (two control points closer than a cell: the first).
    d_fixed = np.min(np.abs(xs[:, None] - fixed[None, :]), axis=1)
    keep_mask = is_fixed | (d_fixed >= 1.0)
    xs, is_fixed = xs[keep_mask], is_fixed[keep_mask]
    kept = [0]
    for k in range(1, xs.size):
        if xs[k] - xs[kept[-1]] >= 1.0:
            kept.append(k)
        elif is_fixed[k] and not is_fixed[kept[-1]]:
            kept[-1] = k
    x = xs[kept]
    if x[-1] != cells:  # the last node always ends the range
        x[-1] = cells
    nodes = lo + (hi - lo) * x / cells
    nodes[0], nodes[-1] = lo, hi
    return nodes


def _fixed_points(tf: TransferFunction, lo: float, hi: float, n: int, cells: int) -> NDArray[np.float64]:
    """The control points inside ``(lo, hi)`` that get nodes, in cells from ``lo``: all of
    them up to ``n // WARP_EXTRA_NODES``; beyond, one per run of points closer than a cell
    (its first), and of those the ones the table would miss most: the largest gap, in
    opacity or opacity-weighted colour, between the point's value and the chord over its
    neighbours, each taken at most one node spacing away (a step: about half its jump; a
    spike's foot: half its height; a kink between far points: half its change of slope
    times the spacing; a point of a smooth colour map: next to nothing)."""
    bp = tf.breakpoints
    x = (bp[(bp > lo) & (bp < hi)] - lo) / (hi - lo) * cells
    most = n // WARP_EXTRA_NODES
    if x.size <= most:
        return x
    x = x[np.concatenate([[True], np.diff(x) >= 1.0])]  # one per run (warped_nodes' loop then decides)
    if x.size <= most:
        return x
    s = lo + (hi - lo) * x / cells
    h = (hi - lo) / max(n - 1, 1)
    around = np.concatenate([[lo], s, [hi]])
    below = np.minimum(s - around[:-2], h)
    above = np.minimum(around[2:] - s, h)

    def weighted(at: NDArray[np.float64]) -> NDArray[np.float64]:
        color, opacity = tf.evaluate(at)
        return np.column_stack([opacity, color * opacity[:, None]])

    w = (above / np.maximum(below + above, 1e-300))[:, None]  # the chord's weight on the point below
    chord = w * weighted(s - below) + (1.0 - w) * weighted(s + above)
    harm = np.abs(weighted(s) - chord).max(axis=1)
    keep = np.sort(np.argpartition(-harm, most - 1)[:most]) if most > 0 else np.empty(0, np.int64)
    return x[keep]


def warp_cells(nodes: NDArray[np.float64], cells: int = WARP_CELLS) -> NDArray[np.float32]:
    """The warp texture of ``nodes`` (from :func:`warped_nodes` with the same ``cells``):
    ``(cells, 4)`` float32, per cell ``(split, index, slope below, slope above)`` in cell
    units, so that ``index + (x - split) * slope`` is the fractional node index of the
    scalar at ``x`` cells from the first node (``shaders/lookup.glsl``).

    >>> w = warp_cells(np.array([0.0, 0.25, 1.0]), cells=4)
    >>> w.tolist()  # node 1 splits cell 1; slopes 1/1 and 1/3 node per cell
    [[0.0, 0.0, 1.0, 1.0], [1.0, 1.0, 1.0, 0.3333333432674408], [2.0, 1.3333333730697632, 0.3333333432674408, 0.3333333432674408], [3.0, 1.6666666269302368, 0.3333333432674408, 0.3333333432674408]]
    """
    nodes = np.asarray(nodes, dtype=np.float64)
    lo, hi = float(nodes[0]), float(nodes[-1])
    x = (nodes - lo) / (hi - lo) * cells
    if np.any(np.diff(x) < 1.0 - 1e-9):
        raise ValueError(f"nodes closer than one of {cells} cells cannot share the warp texture")
    slope = 1.0 / np.diff(x)  # nodes per cell, bin by bin
    j = np.arange(cells, dtype=np.float64)
    index = np.interp(j, x, np.arange(x.size, dtype=np.float64))
    bin_of = np.clip(np.searchsorted(x, j, side="right") - 1, 0, slope.size - 1)
    out = np.column_stack([j, index, slope[bin_of], slope[bin_of]])
    # Cells holding a node (other than at their start) split at it.
    inner = x[1:-1]
    c = np.floor(inner).astype(np.int64)
    k = np.arange(1, x.size - 1)
    out[c, 0] = inner
    out[c, 1] = k
    out[c, 2] = slope[k - 1]
    out[c, 3] = slope[k]
    return out.astype(np.float32)


def extinction_cells(tf: TransferFunction, scalar_range: tuple[float, float], cells: int = WARP_CELLS, *,
                     optics: str = "exact") -> NDArray[np.float32]:
    """The optical depth of a warped table, per cell: ``(cells, 4)`` float32 rows of
    ``(P_hi, P_lo, mean extinction, 0)``, ``P = P_hi + P_lo`` the extinction summed over the
    cells before (in extinction x cells), exact for the piecewise-linear opacity
    (``optics="exact"``: tau = -ln(1 - a) / u; ``"linear"``: a / u).

    A segment's mean extinction is then ``(P(x_b) - P(x_f)) / (x_b - x_f)`` with P linear
    in each cell: exact where both ends lie on cell boundaries, and off by no more than
    the extinction varies within one of 8192 cells elsewhere. The table interpolates its
    mean extinction between nodes instead, which cannot follow -ln(1 - a) where the opacity
    nears 1 (an opaque spike): there the chord between two nodes misses the logarithm by a
    constant, however close the nodes (``shaders/lookup.glsl`` reads these rows with
    ``TABLE_WARP``; the table's own colour is kept). Two floats hold P so that nearby cells'
    difference keeps float32's relative precision however large P grows over the range.

    >>> tf = TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)), opacity=((0, 0.5), (1, 0.5)))
    >>> (extinction_cells(tf, (0.0, 1.0), cells=4)[:, [0, 2]].astype(float).round(4) + 0.0).tolist()
    [[0.0, 0.6931], [0.6931, 0.6931], [1.3863, 0.6931], [2.0794, 0.6931]]
    """
    lo, hi = float(scalar_range[0]), float(scalar_range[1])
    u = tf.unit_distance
    s = np.union1d(np.linspace(lo, hi, cells + 1), np.clip(tf.breakpoints, lo, hi))
    _, opacity = tf.evaluate(s)
    if optics == "exact":
        clear = 1.0 - np.clip(opacity, 0.0, MAX_OPACITY)
        mean = mean_neg_log(clear[:-1], clear[1:]) / u
    else:
        tau = np.clip(opacity, 0.0, 1.0) / u
        mean = 0.5 * (tau[:-1] + tau[1:])
    x = (s - lo) / (hi - lo) * cells
    cell = np.clip(np.floor(0.5 * (x[1:] + x[:-1])).astype(np.int64), 0, cells - 1)
    per_cell = np.bincount(cell, weights=mean * np.diff(x), minlength=cells)  # = mean extinction (cells are 1 wide)
    prefix = np.concatenate([[0.0], np.cumsum(per_cell)[:-1]])
    p_hi = prefix.astype(np.float32)
    p_lo = (prefix - p_hi.astype(np.float64)).astype(np.float32)
    return np.column_stack([p_hi, p_lo, per_cell.astype(np.float32), np.zeros(cells, np.float32)])


def node_opacity_cells(tf: TransferFunction, nodes: NDArray[np.float64], cells: int = WARP_CELLS, *,
                       optics: str = "exact") -> NDArray[np.float32]:
    """Row 2 of a warped table's warp texture: per node (the rest zero) its opacity, clamped
    as the optics clamp it, ``1 / unit_distance`` and 1 for ``tau = a / u`` (``"linear"``)
    or 0 for ``tau = -ln(1 - a) / u``: the extinction of a segment within one cell, at its
    middle, exactly (the opacity is linear between nodes)."""
    _, opacity = tf.evaluate(nodes)
    out = np.zeros((cells, 4), np.float32)
    out[: nodes.size, 0] = np.clip(opacity, 0.0, MAX_OPACITY if optics == "exact" else 1.0)
    out[: nodes.size, 1] = 1.0 / tf.unit_distance
    out[: nodes.size, 2] = 0.0 if optics == "exact" else 1.0
    return out


def warp_extinction(texels: NDArray[np.float32], xf: NDArray[np.float64], xb: NDArray[np.float64],
                    node_opacity: NDArray[np.float32] | None = None, index_f: NDArray[np.float64] | None = None,
                    index_b: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """Mean extinction of segments from ``xf`` to ``xb`` (cells from the first node) by
    :func:`extinction_cells`' rows, and within a cell by :func:`node_opacity_cells`' at the
    middle node coordinate, as ``shaders/lookup.glsl`` computes it."""
    rows = texels.astype(np.float64)
    cells = rows.shape[0]

    def prefix(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        c = np.clip(np.floor(x), 0, cells - 1).astype(np.int64)
        return rows[c, 0] + rows[c, 1] + (x - c) * rows[c, 2], rows[c, 2]

    pf, tf_ = prefix(np.asarray(xf, dtype=np.float64))
    pb, _ = prefix(np.asarray(xb, dtype=np.float64))
    dx = np.asarray(xb, dtype=np.float64) - xf
    thin = tf_
    if node_opacity is not None and index_f is not None and index_b is not None:
        n = int(np.count_nonzero(node_opacity[:, 1]))
        mid = 0.5 * (np.asarray(index_f) + np.asarray(index_b))
        i = np.clip(np.floor(mid).astype(np.int64), 0, n - 2)
        a = node_opacity[i, 0] + np.clip(mid - i, 0.0, 1.0) * (node_opacity[i + 1, 0].astype(np.float64) - node_opacity[i, 0])
        thin = (a if node_opacity[0, 2] > 0.5 else -np.log1p(-a)) * float(node_opacity[0, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(np.abs(dx) >= 1.0, (pb - pf) / np.where(dx != 0, dx, 1.0), thin)

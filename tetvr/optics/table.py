"""The pre-integration table as an object: its layout, its lookups, its cost and its scalar axis.

:class:`PreintegrationTable` holds a built table (:func:`tetvr.optics.preintegrate.build_table`,
whose module notes describe the technique and the two encodings) and models the GPU's
lookup in it. Beside it: what a table may cost before it is built
(:func:`table_build_bytes`, :func:`check_table_size`, :func:`check_unit_distance`), and
where its scalar nodes lie (:func:`table_scalar_range`, :func:`aligned_scalar_range`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.optics.tablesteps import STEPS_UNIT, lookup_cut, trilinear
from tetvr.optics.tablewarp import WARP_CELLS, max_warped_nodes, warp_cells, warp_extinction
from tetvr.optics.transfer import TransferFunction

__all__ = ["PreintegrationTable", "table_scalar_range", "aligned_scalar_range", "aligned_nodes", "fewest_spacings",
           "step_positions", "node_limits", "interpolate_limits", "STEP_GAP", "STEP_EXTRA_NODES", "MAX_STEP_NODES",
           "table_build_bytes", "check_table_size", "check_unit_distance", "ALIGN_MIN_FRACTION",
           "ALIGN_MIN_RAMP_BINS", "MAX_TABLE_BUILD_BYTES", "MAX_THICKNESS_SPAN", "MIN_UNIT_DISTANCE",
           "TABLE_BUILD_BYTES_PER_ENTRY", "TABLE_BUILD_BYTES_PER_ENTRY_WARPED"]

#: Peak bytes :func:`~tetvr.optics.preintegrate.build_table` holds per table entry
#: (N * N * (K + 1)): the float64 working arrays of the run recurrence and of the encoding.
#: Measured with tracemalloc at 128-512 bins and 8-32 slices: 107-127 bytes.
TABLE_BUILD_BYTES_PER_ENTRY = 128
#: ... and of a warped table (``warp=True``): 113-121 bytes measured the same way at 128-192
#: nodes and 8-22 slices (its per-front-node temporaries are O(N^2 K), below the table's own).
TABLE_BUILD_BYTES_PER_ENTRY_WARPED = 128
#: The largest table build allowed, whatever memory the machine has: 8 GiB, ~67M entries
#: (1024 x 1024 x 64; the benchmark sweep's largest, 1024 x 1024 x 49, takes 6.1 GiB and
#: ~5 s), whose float32 texture is 1 GiB. 2048 bins x 256 slices would need 138 GiB.
MAX_TABLE_BUILD_BYTES = 8 << 30
#: The largest ratio d_max / d_min = log_base ** (K - 1) of a thickness axis. The GPU
#: takes 1 / d_min in float32 (``u_slices``): with the thinnest mesh it accepts
#: (extent 1e-13, ``tetvr.order.precision.GPU_EXTENT_RANGE``) that is 1e37, below float32's 3.4e38.
#: Beyond ~1e308 d_min itself underflows to 0. The "auto" axis spans at most 1e6.
MAX_THICKNESS_SPAN = 1e24
#: The smallest transfer-function unit distance: extinction ``-ln(1 - a) / u`` reaches
#: 13.8 / u (opacity capped at 1 - 1e-6), and the table's prefix sums add up to 4096 bins
#: of it; from 1e-300 that stays below float64's 1.8e308 (a subnormal u made it inf, and
#: inf * 0 NaN images and table sizes).
MIN_UNIT_DISTANCE = 1e-300


def table_build_bytes(n_bins: int, n_slices: int, *, warp: bool = False) -> int:
    """Peak memory of :func:`~tetvr.optics.preintegrate.build_table` for ``n_bins`` x
    ``n_bins`` x ``n_slices + 1`` entries, in bytes (an upper bound of what was measured);
    with ``warp``, for the most nodes a warped table of ``n_bins`` may hold
    (:func:`~tetvr.optics.tablewarp.max_warped_nodes`).

    >>> table_build_bytes(256, 16) / 2**20
    136.0
    """
    per_entry = TABLE_BUILD_BYTES_PER_ENTRY_WARPED if warp else TABLE_BUILD_BYTES_PER_ENTRY
    nodes = max_warped_nodes(n_bins) if warp else int(n_bins)
    return per_entry * nodes ** 2 * (int(n_slices) + 1)


def check_table_size(n_bins: int, n_slices: int, log_base: float | None = None, *, warp: bool = False,
                     names: tuple[str, str, str] = ("n_bins", "n_slices", "log_base")) -> None:
    """Refuse a table too big to build (:data:`MAX_TABLE_BUILD_BYTES`) or whose
    thickness axis spans more than :data:`MAX_THICKNESS_SPAN`, with a ``ValueError`` naming
    the sizes (``names``: how the caller calls the three arguments)."""
    need = table_build_bytes(n_bins, n_slices, warp=warp)
    if need > MAX_TABLE_BUILD_BYTES:
        n = max_warped_nodes(n_bins) if warp else n_bins
        raise ValueError(
            f"{names[0]}={n_bins} with {names[1]}={n_slices} is a {'warped table of up to ' if warp else ''}"
            f"{n} x {n} x {n_slices + 1} {'' if warp else 'table '}({n * n * (n_slices + 1):,} entries) whose build "
            f"needs {need / 2**30:.3g} GiB, more than the {MAX_TABLE_BUILD_BYTES / 2**30:g} GiB allowed; use fewer "
            "bins or slices")
    if log_base is not None and n_slices > 1:
        # In logarithms: log_base ** (K - 1) itself may overflow.
        exponent = (n_slices - 1) * math.log10(float(log_base))
        if exponent > math.log10(MAX_THICKNESS_SPAN):
            raise ValueError(
                f"{names[2]}={log_base!r} with {names[1]}={n_slices}: the thickness axis would span "
                f"{names[2]} ** ({names[1]} - 1) = 1e{exponent:.0f} (thickest over thinnest slice), more than "
                f"{MAX_THICKNESS_SPAN:g}; use a smaller {names[2]} or fewer slices")


def check_unit_distance(unit_distance: float, name: str = "unit_distance") -> float:
    """``unit_distance`` as a float if the optics can use it: positive, finite and at
    least :data:`MIN_UNIT_DISTANCE`, else ``ValueError`` naming the value."""
    u = float(unit_distance)
    if not (math.isfinite(u) and u >= MIN_UNIT_DISTANCE):
        raise ValueError(
            f"{name} must be a finite number of at least {MIN_UNIT_DISTANCE:g} (world units), got {unit_distance!r}: "
            "below, the extinction -ln(1 - opacity) / unit_distance overflows float64; scale the mesh and the "
            "unit distance up together")
    return u


@dataclasses.dataclass(frozen=True, eq=False)
class PreintegrationTable:
    """A built table and how to index it.

    Attributes
    ----------
    data : (K+1, N, N, 4) float32 or uint8; axes (thickness slice, sb, sf, RGBA), the
        layout of an OpenGL 3D texture of width sf, height sb and depth thickness.
    scalar_range : scalars at the first and last node of both scalar axes.
    thicknesses : (K+1,) thickness of each slice (slice 0 is 0).
    log_base : ratio between slices 1..K.
    encoding : "normalized" or "premultiplied".
    alpha_scale : for "normalized", the factor that turns the stored A into extinction
        (1 for float32; max extinction for uint8, whose A is stored divided by it).
    nodes : (N,) scalars of the nodes of a warped table (:mod:`tetvr.optics.tablewarp`), or
        None where they are evenly spaced over ``scalar_range``.
    extinction : (2, cells, 4) float32: a warped table's optical depth per scalar cell
        (:func:`tetvr.optics.tablewarp.extinction_cells`) and opacity per node
        (:func:`tetvr.optics.tablewarp.node_opacity_cells`): a "normalized" warped table takes its
        segments' mean extinction from them rather than from the interpolated A.
    steps : ``(K+1, 2, 2 (N-1), 4)``, same dtype as ``data``: where the transfer function
        steps at some nodes (:func:`node_limits`; "normalized" only), each bin's 2 x 2 corner block, its
        diagonal on the bin's side of the steps (:func:`tetvr.optics.tablesteps.corner_blocks`);
        lookups then cut segments at the nodes (:mod:`tetvr.optics.tablesteps`). Else None.
    """

    data: NDArray[np.generic]
    scalar_range: tuple[float, float]
    thicknesses: NDArray[np.float64]
    log_base: float
    encoding: str
    alpha_scale: float = 1.0
    nodes: NDArray[np.float64] | None = None
    extinction: NDArray[np.float32] | None = None
    steps: NDArray[np.generic] | None = None

    @property
    def n_bins(self) -> int:
        return int(self.data.shape[1])

    @property
    def node_spacing(self) -> float:
        """Scalar distance between adjacent nodes of the scalar axes (the widest, if warped)."""
        if self.nodes is not None:
            return float(np.diff(self.nodes).max())
        return (self.scalar_range[1] - self.scalar_range[0]) / (self.n_bins - 1)

    def node_coordinate(self, scalars: NDArray[np.float64]) -> NDArray[np.float64]:
        """Fractional node index of scalars, clamped to the table (the GPU does the same)."""
        lo, hi = self.scalar_range
        s = np.asarray(scalars, dtype=np.float64)
        if self.nodes is not None:
            return np.interp(s, self.nodes, np.arange(self.n_bins, dtype=np.float64))
        return np.clip((s - lo) / (hi - lo), 0, 1) * (self.n_bins - 1)

    def warp_texels(self) -> NDArray[np.float32] | None:
        """The warp texture of a warped table, else None: ``(3, cells, 4)``, row 0 the node
        index (:func:`tetvr.optics.tablewarp.warp_cells`), rows 1 and 2 :attr:`extinction`."""
        if self.nodes is None or self.extinction is None:
            return None
        return np.concatenate([warp_cells(self.nodes)[None], self.extinction])

    def cell_coordinate(self, scalars: NDArray[np.float64]) -> NDArray[np.float64]:
        """Scalars in cells of a warped table's warp texture from its first node (as table_st)."""
        lo, hi = self.scalar_range
        return (np.asarray(scalars, dtype=np.float64) - lo) * (WARP_CELLS / (hi - lo))

    @property
    def n_slices(self) -> int:
        """K, the number of non-zero thickness slices."""
        return int(self.data.shape[0]) - 1

    @property
    def d_min(self) -> float:
        return float(self.thicknesses[1])

    @property
    def d_max(self) -> float:
        return float(self.thicknesses[-1])

    def gl_uniforms(self) -> dict[str, Any]:
        """The uniforms ``shaders/lookup.glsl`` reads this table with (texture unit 0)."""
        lo, hi = self.scalar_range
        n = self.n_bins
        # Even nodes: node i at texel centre (i + 0.5) / N. Warped: x = cells from the first
        # node, which the warp texture (unit 8) turns into the fractional node index.
        scale = WARP_CELLS / (hi - lo) if self.nodes is not None else (n - 1) / ((hi - lo) * n)
        offset = -lo * scale if self.nodes is not None else 0.5 / n - lo * scale
        k1 = self.n_slices + 1
        return dict(
            u_table=0, u_scalar_range=(lo, hi), u_optical_scale=self.alpha_scale / math.log(2.0),
            u_table_size=(n, n, k1), u_warp=8, u_warp_cells=WARP_CELLS, u_steps=STEPS_UNIT,
            u_lookup=(scale, offset),
            # Texture z of the fractional slice s is (s + 0.5) / (K + 1); s = x below
            # x = d / d_min = 1, s = 1 + log2(x) / log2(base) above (the texture clamps it to K).
            u_slices=(1.0 / self.d_min, 1.0 / k1, 0.5 / k1, 1.0 / (math.log2(self.log_base) * k1)),
            u_slices_log=1.5 / k1,
        )

    def slice_coordinate(self, thickness: NDArray[np.float64]) -> NDArray[np.float64]:
        """Fractional slice index of a thickness (the GPU does the same in GLSL)."""
        d = np.asarray(thickness, dtype=np.float64)
        with np.errstate(divide="ignore"):
            log_w = 1.0 + np.log(np.maximum(d, 1e-300) / self.d_min) / math.log(self.log_base)
        w = np.where(d < self.d_min, d / self.d_min, log_w)
        return np.clip(w, 0.0, float(self.n_slices))

    def lookup(self, sf: NDArray[np.float64], sb: NDArray[np.float64], thickness: NDArray[np.float64]) -> NDArray[np.float64]:
        """Premultiplied RGBA of segments, by trilinear interpolation as the GPU does it.

        A CPU model of the shader's lookup, used in tests to separate table error from
        rasterisation error. A table with :attr:`steps` cuts each segment at the nodes
        (:func:`tetvr.optics.tablesteps.lookup_cut`).
        """
        n = self.n_bins
        fi = self.node_coordinate(sf)
        fj = self.node_coordinate(sb)
        if self.steps is not None:
            return lookup_cut(fi, fj, np.asarray(thickness, dtype=np.float64), n, self._piece)
        fk = self.slice_coordinate(thickness)
        data = self.data.astype(np.float64)
        if self.data.dtype == np.uint8:
            data /= 255.0
        out = np.zeros(fi.shape + (4,))
        i0 = np.minimum(np.floor(fi).astype(int), n - 2)
        j0 = np.minimum(np.floor(fj).astype(int), n - 2)
        k0 = np.minimum(np.floor(fk).astype(int), max(self.n_slices - 1, 0))
        wi, wj, wk = fi - i0, fj - j0, fk - k0
        for dk, wk_ in ((0, 1 - wk), (1, wk)):
            for dj, wj_ in ((0, 1 - wj), (1, wj)):
                for di, wi_ in ((0, 1 - wi), (1, wi)):
                    out += (wk_ * wj_ * wi_)[..., None] * data[np.minimum(k0 + dk, self.n_slices), j0 + dj, i0 + di]
        d = np.asarray(thickness, dtype=np.float64)
        if self.encoding == "normalized":
            tau = out[..., 3] * self.alpha_scale
            if self.extinction is not None:
                tau = warp_extinction(self.extinction[0], self.cell_coordinate(sf), self.cell_coordinate(sb),
                                      self.extinction[1], fi, fj)
            alpha = -np.expm1(-d * tau)
            return np.concatenate([out[..., :3] * alpha[..., None], alpha[..., None]], axis=-1)
        return out

    def _piece(self, p: NDArray[np.float64], q: NDArray[np.float64], where: NDArray[np.int64],
               d: NDArray[np.float64]) -> NDArray[np.float64]:
        """Premultiplied RGBA of pieces of a stepped table's segments (:func:`lookup_cut`):
        a run between nodes (``where`` -1) from the table, a piece within bin ``where`` from
        its corner block, as ``shaders/lookup_steps.glsl`` reads them."""
        assert self.steps is not None
        fk = self.slice_coordinate(d)
        i = np.maximum(where, 0)
        run = trilinear(self.data, p, q, fk)
        block = trilinear(self.steps, 2 * i + np.clip(p - i, 0.0, 1.0), np.clip(q - i, 0.0, 1.0), fk)
        t = np.where((where < 0)[..., None], run, block)
        alpha = -np.expm1(-d * t[..., 3] * self.alpha_scale)
        return np.concatenate([t[..., :3] * alpha[..., None], alpha[..., None]], axis=-1)


def table_scalar_range(data_range: tuple[float, float], tf: TransferFunction) -> tuple[float, float]:
    """The scalar span of a table (and of the ray caster's transfer-function texture).

    The union of the data range and the transfer function's domain, so no segment is
    clamped at the table's edge (clamping a scalar that crosses the edge would bend the
    linear ramp the table assumes); an empty span is padded to a tiny positive one.

    >>> tf = TransferFunction.preset("grayscale", (0, 1))
    >>> table_scalar_range((-0.5, 0.5), tf)
    (-0.5, 1.0)
    """
    lo = min(float(data_range[0]), tf.domain[0])
    hi = max(float(data_range[1]), tf.domain[1])
    if hi <= lo:
        pad = max(abs(lo) * 1e-6, 1e-12)
        lo, hi = lo - pad, hi + pad
    return lo, hi


#: Aligned nodes (:func:`aligned_scalar_range`) may widen the node spacing by at most
#: 1 / ALIGN_MIN_FRACTION (11 %): the interpolation error of a smooth stretch grows with the
#: square of the spacing, while a control point between nodes errs with its first power.
ALIGN_MIN_FRACTION = 0.9
#: ... and only where every ramp between adjacent control points (of the colour or of the
#: opacity map) spans at least this many node spacings. Below that the image error depends
#: on where the nodes fall in a way neither the bound below nor the table's error on the
#: sampled segments predicts: the bluntfin mesh's opacity peak (ramps 7.7 spacings wide at
#: 256 bins) rendered at 58-68 dB over spacings m = 234..255, the bound picking 59.7 dB
#: against 67.8 dB for even nodes; at 512 bins (15 spacings) its pick was the best of the
#: range (75.6 dB, even nodes 67.5 dB). A node on a step spreads it over two bins.
ALIGN_MIN_RAMP_BINS = 10.0


#: Elements of :func:`aligned_scalar_range`'s cost matrix (candidate spacings x control
#: points) evaluated at once.
_COST_CHUNK = 1 << 20


def fewest_spacings(n_bins: int) -> int:
    """The fewest node spacings :func:`aligned_scalar_range` may put over the range
    (its widest spacing is ``(hi - lo) / fewest_spacings(n_bins)``)."""
    return max(1, math.ceil(ALIGN_MIN_FRACTION * (n_bins - 1)))


def _slope_jumps(x: NDArray[np.float64], y: NDArray[np.float64], at: NDArray[np.float64]) -> NDArray[np.float64]:
    """|slope on the right - slope on the left| of the piecewise-linear map through the
    points (x ascending, y of shape (len(x), channels); flat beyond the ends) at ``at``,
    the largest over the channels (0 where ``at`` is not one of the x)."""
    slopes = np.diff(y, axis=0) / np.diff(x)[:, None]
    flat = np.zeros((1, y.shape[1]))
    padded = np.concatenate([flat, slopes, flat])  # padded[j] ends at x[j], padded[j + 1] starts there
    left, right = np.searchsorted(x, at, side="left"), np.searchsorted(x, at, side="right")
    return np.abs(padded[right] - padded[left]).max(axis=1)


def aligned_scalar_range(scalar_range: tuple[float, float], tf: TransferFunction, n_bins: int) -> tuple[float, float]:
    """The scalars of the first and last of ``n_bins`` nodes placed so that the transfer
    function's control points fall on nodes, as far as that pays.

    Between two nodes a table takes the transfer function as linear, so a control point
    at fraction f of the way between two nodes h apart is cut off by up to
    ``D * h * f * (1 - f)``, with D its jump in slope (the larger of the colour map's, over
    the channels, and the opacity map's): the largest scalar-axis error of smooth colour
    maps, whose points sit at k/8 or k/16 of the range while uniform nodes sit at k/(N-1).
    Here the first node stays at ``scalar_range[0]`` and the spacing is ``(hi - lo) / m``,
    m in ``ALIGN_MIN_FRACTION * (N-1) .. N-1``, with m minimising the sum of that bound
    over the control points (ties to the finer spacing); the last N-1-m nodes lie beyond
    ``hi``, where the transfer function is clamped anyway. Uniform spacing
    (``scalar_range`` itself) is kept when no m does better, or when a ramp between
    adjacent control points spans fewer than ``ALIGN_MIN_RAMP_BINS`` spacings (steps,
    spikes and other features a few bins wide, where the placement is a lottery).

    Measured against the exact reference (``bench/speed_accuracy.py``, auto table size):
    camera inside a cube 97.7 -> 110.2 dB (viridis at k/8, 256 bins); the bluntfin and
    combustor CFD meshes 67.5 -> 75.7 and 86.6 -> 88.8 dB (512 bins, an opacity peak at
    data quantiles, ramps 15 spacings wide, over a cool-to-warm map).

    >>> tf = TransferFunction.preset("viridis", (0.0, 1.0), opacity=0.5)
    >>> lo, hi = aligned_scalar_range((0.0, 1.0), tf, 256)
    >>> lo, round(hi * 248, 9)  # 248 spacings per unit: k/8 is node 31 k
    (0.0, 255.0)
    """
    lo, hi = (float(v) for v in scalar_range)
    n = int(n_bins)
    if n < 3 or not hi > lo:
        return lo, hi
    color, opacity = tf.point_arrays
    cx, ox = (color[:, 0] - lo) / (hi - lo), (opacity[:, 0] - lo) / (hi - lo)
    narrowest = min(float(np.diff(x).min()) if x.size > 1 else 1.0 for x in (cx, ox))
    if narrowest * (n - 1) < ALIGN_MIN_RAMP_BINS:  # no spacing can pass the test below: no work
        return lo, hi
    u = np.unique(np.concatenate([cx, ox]))
    jump = _slope_jumps(cx, color[:, 1:], u) + _slope_jumps(ox, opacity[:, 1:], u)
    ms = np.arange(n - 1, fewest_spacings(n) - 1, -1, dtype=np.float64)  # finest first
    cost = np.empty_like(ms)
    rows = max(1, _COST_CHUNK // max(u.size, 1))  # memory O(points), however many points
    for i in range(0, ms.size, rows):
        x = u[None, :] * ms[i:i + rows, None]
        f = np.abs(x - np.round(x))  # distance to the nearest node, in spacings (rounding: ~1e-13 on one)
        cost[i:i + rows] = (jump[None, :] * f * (1.0 - f)).sum(axis=1) / ms[i:i + rows]
    # Costs equal up to rounding are a tie, which goes to the finest spacing (the first).
    best = int(np.argmax(cost <= cost.min() + 1e-9 * (jump.sum() / ms[0])))
    m = float(ms[best])
    if best == 0 or narrowest * m < ALIGN_MIN_RAMP_BINS:
        return lo, hi
    return lo, lo + (n - 1) * (hi - lo) / m



#: Consecutive control points of one map (colour or opacity) closer than this fraction of a
#: table's scalar span make a *step*: a jump no node spacing resolves (ParaView's discretized
#: colour maps put the two sides of each band edge 1e-9 of the range apart). A table with a
#: node on a step takes each bin's ends from the step's sides (:func:`node_limits`), so
#: the bands are exact and only the interpolation between entries across the step is left.
STEP_GAP = 1e-6
#: Nodes that :func:`aligned_nodes` may add to N (N // STEP_EXTRA_NODES at most) to put
#: every step on a node: 256 bands over the table's whole range need 257 or 513 nodes, over
#: the default colour range (the 1st to 99.5th percentile of the field, ~80 % of its range
#: on the synthetic cubes) 325 or 649.
STEP_EXTRA_NODES = 2
#: ... and never beyond this many nodes (unless N is more): the 3D texture side every
#: OpenGL 4.3 holds (``GL_MAX_3D_TEXTURE_SIZE`` >= 2048), which the renderers check N against.
MAX_STEP_NODES = 2048


def step_positions(tf: TransferFunction, span: float) -> NDArray[np.float64]:
    """The scalars of the transfer function's steps (:data:`STEP_GAP` of ``span``), each the
    middle of its run of close control points, ascending.

    >>> tf = TransferFunction(color=((0, 0, 0, 0), (0.5 - 1e-9, 0, 0, 0), (0.5, 1, 1, 1), (1, 1, 1, 1)),
    ...                       opacity=((0, 0.5), (1, 0.5)))
    >>> step_positions(tf, 1.0).round(6).tolist()
    [0.5]
    """
    found = []
    for rows in tf.point_arrays:
        x = rows[:, 0]
        close = np.diff(x) < STEP_GAP * span
        if not close.any():
            continue
        # Runs of close gaps: from a close gap after a wide one to the last close one.
        edge = np.diff(np.concatenate([[False], close, [False]]).astype(np.int8))
        first, last = np.nonzero(edge == 1)[0], np.nonzero(edge == -1)[0]
        found.append(0.5 * (x[first] + x[last]))
    return np.unique(np.concatenate(found)) if found else np.empty(0)


def node_limits(tf: TransferFunction, nodes: NDArray[np.float64], tol: float
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] | None:
    """The colour and opacity just below and just above each node, ``(colour_below,
    colour_above, opacity_below, opacity_above)``, where a node sits on a step: with two
    or more control points of a map within ``tol`` of a node, below is the first one's value
    and above the last one's; elsewhere both are the value at the node. None where no
    node sits on a step (then both sides are ``tf.evaluate(nodes)``)."""
    spans = []
    for rows in tf.point_arrays:
        x = rows[:, 0]
        first = np.searchsorted(x, nodes - tol, side="left")
        last = np.searchsorted(x, nodes + tol, side="right") - 1
        spans.append((first, last, last > first))
    if not any(on.any() for _, _, on in spans):
        return None
    color, opacity = tf.evaluate(nodes)
    sides = []
    for (first, last, on), at, rows in zip(spans, (color, opacity[:, None]), tf.point_arrays):
        below, above = at.copy(), at.copy()
        below[on], above[on] = rows[first[on], 1:], rows[last[on], 1:]
        sides += [below, above]
    return sides[0], sides[1], sides[2][:, 0], sides[3][:, 0]


def interpolate_limits(s: NDArray[np.float64], nodes: NDArray[np.float64], below: NDArray[np.float64],
                       above: NDArray[np.float64]) -> NDArray[np.float64]:
    """Values at ``s`` linear in each bin from ``above`` at its first node to ``below`` at
    its last (:func:`node_limits`), clamped at the ends: what a table holds between nodes.

    >>> interpolate_limits(np.array([0.25, 0.75]), np.array([0.0, 0.5, 1.0]), np.array([0.0, 0.0, 1.0]),
    ...                    np.array([0.0, 1.0, 1.0])).tolist()
    [0.0, 1.0]
    """
    j = np.clip(np.searchsorted(nodes, s, side="right") - 1, 0, nodes.size - 2)
    t = np.clip((s - nodes[j]) / (nodes[j + 1] - nodes[j]), 0.0, 1.0)
    if below.ndim > 1:
        t = t[..., None]
    return above[j] * (1.0 - t) + below[j + 1] * t  # type: ignore[no-any-return]


def aligned_nodes(scalar_range: tuple[float, float], tf: TransferFunction, n_bins: int
                  ) -> tuple[float, float, int]:
    """The first and last scalar node and the node count of an aligned table of about ``n_bins`` nodes.

    Where the transfer function has steps (:func:`step_positions`) and evenly spaced nodes
    can hold them all, with at most ``n_bins // STEP_EXTRA_NODES`` nodes more (and at most
    :data:`MAX_STEP_NODES` in all, unless ``n_bins`` is more) and a spacing no
    wider than :func:`aligned_scalar_range`'s, the nodes are such a lattice, the fewest of at
    least ``n_bins`` nodes (it may start a rounding below the range; lookups clamp there as
    at the end); elsewhere they are :func:`aligned_scalar_range`'s ``n_bins`` nodes.

    >>> bands = [(k / 4 + d, k / 4, k / 4, k / 4) for k in range(4) for d in (0.0, 0.25 - 1e-9)]
    >>> tf = TransferFunction(color=bands, opacity=((0, 0.5), (1, 0.5)))  # four bands of 1/4
    >>> lo, hi, n = aligned_nodes((0.0, 1.0), tf, 256)
    >>> lo, round(hi, 6), n  # a node on every band edge k / 4
    (0.0, 1.0, 257)
    """
    lo, hi = (float(v) for v in scalar_range)
    n = int(n_bins)
    lattice = _step_lattice(lo, hi, tf, n) if n >= 3 and hi > lo else None
    if lattice is not None:
        return lattice
    lo, hi = aligned_scalar_range((lo, hi), tf, n)
    return lo, hi, n


def _step_lattice(lo: float, hi: float, tf: TransferFunction, n: int) -> tuple[float, float, int] | None:
    """:func:`aligned_nodes`' lattice through every step, or None."""
    span = hi - lo
    steps = step_positions(tf, span)
    most = max(n, min(n + n // STEP_EXTRA_NODES, MAX_STEP_NODES))
    if steps.size == 0 or steps.size > most:
        return None
    widest, tol = span / fewest_spacings(n), 0.25 * STEP_GAP * span
    # Spacings that put every step on a node: the steps' span over j (one step: any spacing).
    reach = float(steps[-1] - steps[0])
    candidates = [reach / j for j in range(most, 0, -1)] if steps.size > 1 else [span / (n - 1)]
    fits = []
    for h in candidates:
        if h > widest:
            break
        k = (steps - steps[0]) / h
        if np.abs(k - np.round(k)).max() * h > tol:
            continue
        # Nodes from the first step down to the range's start and up to its end (one within
        # rounding of an end is on it).
        below = math.ceil((steps[0] - lo - tol) / h)
        count = below + math.ceil((hi - steps[0] - tol) / h) + 1
        if count <= most:
            first = float(steps[0]) - below * h
            # A step within rounding of the range's start: the lattice starts there.
            fits.append((lo if abs(first - lo) <= tol else first, h, count))
    if not fits:
        return None
    # The fewest nodes of at least n (else the most): the n-node table, its steps on nodes.
    first, h, count = min(fits, key=lambda f: (f[2] < n, abs(f[2] - n)))
    return first, first + (count - 1) * h, count

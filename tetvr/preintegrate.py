"""The 3D pre-integration table: (front scalar, back scalar, thickness) -> RGBA.

About this technique
--------------------
Pre-integration (Engel, Kraus & Ertl 2001) tabulates the emission–absorption integral
of a ray segment whose scalar runs linearly from ``sf`` to ``sb`` over a length ``d``.
Kraus, Qiao & Ebert (2004) put the thickness on a *logarithmic* axis, so that the thin
segments that dominate a fine mesh are sampled as well as the thick ones: slice ``k`` of
``K`` holds thickness ``d_k = d_max * base**(k - K + 1)``, and an extra slice 0 holds
thickness zero, so that segments thinner than ``d_0`` interpolate linearly to zero
(as in Holeček's thesis).

Building one slice costs O(N^2) (Lum, Wilson & Ma 2004 made the table incremental). We
use an exact incremental scheme: along each diagonal ``sb - sf = n`` of a slice, every
entry is a run of ``n`` scalar bins, each crossed in length ``d/n``, and the entry for
``sf = i`` follows from the entry for ``i + 1`` by compositing bin ``i`` in front and
removing bin ``i + n`` from the back::

    W_i = c_i + t_i * (W_{i+1} - T(i+1 .. i+n-1) * c_{i+n})

where ``c_m``/``t_m`` are the premultiplied colour and transmittance of bin ``m`` and
``T`` the transmittance between, from prefix sums of optical depth. Every step multiplies
earlier rounding by ``t_i <= 1``, so the recurrence is stable. The optical depth of an
entry is exact from a prefix sum (Engel 2001). The only approximation is inside one bin,
where the transfer function is taken as linear between the table's nodes and the
extinction as its exact bin mean; with 256 bins this is below 1e-4 (``tests``).

Encodings
---------
``premultiplied``
    RGBA as in Kraus et al. The GPU interpolates it linearly in log-thickness, which
    errs by up to ~6 % of alpha between slices with base 2 (alpha ~ tau*d is convex in
    log d).
``normalized`` (default)
    RGB holds the colour per unit alpha, ``C / alpha``, and A the mean extinction
    ``Theta / d``. Alpha is then exact in ``d`` (``1 - exp(-d A)``) and only the colour,
    which varies slowly with thickness, is interpolated across slices. Slice 0 holds
    the thin limit ``int c tau / int tau``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .image import check_memory
from .optics import MAX_OPACITY, OPTICS, mean_neg_log
from .tablewarp import WARP_CELLS, extinction_cells, node_opacity_cells, warp_cells, warp_extinction, warped_nodes
from .transfer import TransferFunction

__all__ = ["PreintegrationTable", "build_table", "table_for", "table_scalar_range", "aligned_scalar_range",
           "fewest_spacings", "table_build_bytes", "check_table_size", "check_unit_distance",
           "MAX_TABLE_BUILD_BYTES", "MAX_THICKNESS_SPAN", "MIN_UNIT_DISTANCE"]

# Largest extinction (per world unit) stored in a "normalized" table. A tiny unit distance
# gives extinctions past float32's range: stored as inf, the shader's d * inf at d = 0 is
# NaN. Capped, any segment longer than ~1e-28 is still opaque, which is what inf meant.
_MAX_STORED_TAU = 1e30

#: Peak bytes :func:`build_table` holds per table entry (N * N * (K + 1)): the float64
#: working arrays of the run recurrence and of the encoding. Measured with tracemalloc at
#: 128-512 bins and 8-32 slices: 107-127 bytes.
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
#: (extent 1e-13, ``tetvr.render.GPU_EXTENT_RANGE``) that is 1e37, below float32's 3.4e38.
#: Beyond ~1e308 d_min itself underflows to 0. The "auto" axis spans at most 1e6.
MAX_THICKNESS_SPAN = 1e24
#: The smallest transfer-function unit distance: extinction ``-ln(1 - a) / u`` reaches
#: 13.8 / u (opacity capped at 1 - 1e-6), and the table's prefix sums add up to 4096 bins
#: of it; from 1e-300 that stays below float64's 1.8e308 (a subnormal u made it inf, and
#: inf * 0 NaN images and table sizes).
MIN_UNIT_DISTANCE = 1e-300


def table_build_bytes(n_bins: int, n_slices: int, *, warp: bool = False) -> int:
    """Peak memory of :func:`build_table` for ``n_bins`` x ``n_bins`` x ``n_slices + 1``
    entries, in bytes (an upper bound of what was measured).

    >>> table_build_bytes(256, 16) / 2**20
    136.0
    """
    per_entry = TABLE_BUILD_BYTES_PER_ENTRY_WARPED if warp else TABLE_BUILD_BYTES_PER_ENTRY
    return per_entry * int(n_bins) ** 2 * (int(n_slices) + 1)


def check_table_size(n_bins: int, n_slices: int, log_base: float | None = None, *, warp: bool = False,
                     names: tuple[str, str, str] = ("n_bins", "n_slices", "log_base")) -> None:
    """Refuse a table too big to build (:data:`MAX_TABLE_BUILD_BYTES`) or whose
    thickness axis spans more than :data:`MAX_THICKNESS_SPAN`, with a ``ValueError`` naming
    the sizes (``names``: how the caller calls the three arguments)."""
    need = table_build_bytes(n_bins, n_slices, warp=warp)
    if need > MAX_TABLE_BUILD_BYTES:
        raise ValueError(
            f"{names[0]}={n_bins} with {names[1]}={n_slices} is a {n_bins} x {n_bins} x {n_slices + 1} table "
            f"({n_bins * n_bins * (n_slices + 1):,} entries) whose build needs {need / 2**30:.3g} GiB, more than "
            f"the {MAX_TABLE_BUILD_BYTES / 2**30:g} GiB allowed; use fewer bins or slices")
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
    nodes : (N,) scalars of the nodes of a warped table (:mod:`tetvr.tablewarp`), or
        None where they are evenly spaced over ``scalar_range``.
    extinction : (2, cells, 4) float32: a warped table's optical depth per scalar cell
        (:func:`tetvr.tablewarp.extinction_cells`) and opacity per node
        (:func:`tetvr.tablewarp.node_opacity_cells`): a "normalized" warped table takes its
        segments' mean extinction from them rather than from the interpolated A.
    """

    data: NDArray[np.generic]
    scalar_range: tuple[float, float]
    thicknesses: NDArray[np.float64]
    log_base: float
    encoding: str
    alpha_scale: float = 1.0
    nodes: NDArray[np.float64] | None = None
    extinction: NDArray[np.float32] | None = None

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
        index (:func:`tetvr.tablewarp.warp_cells`), rows 1 and 2 :attr:`extinction`."""
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
            u_table_size=(n, n, k1), u_warp=8, u_warp_cells=WARP_CELLS,
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
        rasterisation error.
        """
        n = self.n_bins
        fi = self.node_coordinate(sf)
        fj = self.node_coordinate(sb)
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
    color, opacity = np.asarray(tf.color, dtype=np.float64), np.asarray(tf.opacity, dtype=np.float64)
    cx, ox = (color[:, 0] - lo) / (hi - lo), (opacity[:, 0] - lo) / (hi - lo)
    narrowest = min(float(np.diff(x).min()) if x.size > 1 else 1.0 for x in (cx, ox))
    u = np.unique(np.concatenate([cx, ox]))
    jump = _slope_jumps(cx, color[:, 1:], u) + _slope_jumps(ox, opacity[:, 1:], u)
    ms = np.arange(n - 1, fewest_spacings(n) - 1, -1, dtype=np.float64)  # finest first
    x = u[None, :] * ms[:, None]
    f = np.abs(x - np.round(x))  # distance to the nearest node, in spacings (rounding: ~1e-13 on one)
    cost = (jump[None, :] * f * (1.0 - f)).sum(axis=1) / ms
    # Costs equal up to rounding are a tie, which goes to the finest spacing (the first).
    best = int(np.argmax(cost <= cost.min() + 1e-9 * (jump.sum() / ms[0])))
    m = float(ms[best])
    if best == 0 or narrowest * m < ALIGN_MIN_RAMP_BINS:
        return lo, hi
    return lo, lo + (n - 1) * (hi - lo) / m


def table_for(
    tf: TransferFunction,
    data_range: tuple[float, float],
    d_max: float,
    *,
    n_bins: int = 256,
    n_slices: int = 16,
    log_base: float = 1.6,
    encoding: str = "normalized",
    dtype: str = "float32",
    optics: str = "exact",
    align_nodes: bool = False,
    warp: bool = False,
) -> PreintegrationTable:
    """The table for a transfer function and a mesh, from a cache keyed by all inputs.

    The scalar axis spans :func:`table_scalar_range`: the union of the data range and
    the transfer function's domain; with ``align_nodes`` its nodes are placed on the
    transfer function's control points where that helps (:func:`aligned_scalar_range`);
    with ``warp`` they are placed where the transfer function varies instead
    (:mod:`tetvr.tablewarp`; ``align_nodes`` does not apply).
    """
    # Thicknesses are rounded up to 7 significant digits so near-equal meshes share a table.
    d_top = float(f"{d_max * (1 + 1e-6):.7g}")
    rng = table_scalar_range(data_range, tf)
    if align_nodes and not warp:
        rng = aligned_scalar_range(rng, tf, n_bins)
    return _cached(tf, rng, d_top, n_bins=n_bins, n_slices=n_slices,
                   log_base=float(log_base), encoding=encoding, dtype=dtype, optics=optics, warp=bool(warp))


def build_table(
    tf: TransferFunction,
    scalar_range: tuple[float, float],
    d_max: float,
    *,
    n_bins: int = 256,
    n_slices: int = 16,
    log_base: float = 1.6,
    encoding: str = "normalized",
    dtype: str = "float32",
    optics: str = "exact",
    warp: bool = False,
) -> PreintegrationTable:
    """Build a pre-integration table (no cache; see :func:`table_for`).

    Parameters
    ----------
    tf : the transfer function.
    scalar_range : scalars of the first and last node.
    d_max : thickness of the last slice; must be at least the thickest segment.
    n_bins : N nodes on each scalar axis.
    n_slices : K non-zero thickness slices, ``d_max * log_base**(k - K + 1)``.
    encoding : "normalized" or "premultiplied" (see the module notes).
    dtype : "float32" or "uint8".
    optics : "exact" (``tau = -ln(1 - a)/u``), "linear" (``tau = a/u``, VTK's unstructured
        mappers) or "vtk" (``tau = a/u`` and the mean of the end colours, unattenuated: the
        fragment formula of VTK's projected tetrahedra); see :data:`tetvr.optics.OPTICS`.
    warp : place the ``n_bins`` nodes where the transfer function varies, every control
        point on a node (:func:`tetvr.tablewarp.warped_nodes`), instead of evenly; the
        table's ``nodes`` then says where they are.

    Examples
    --------
    >>> tf = TransferFunction.preset("grayscale", (0, 1), opacity=0.5)
    >>> build_table(tf, (0, 1), 1.0, n_bins=16, n_slices=4).data.shape
    (5, 16, 16, 4)
    """
    lo, hi = float(scalar_range[0]), float(scalar_range[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ValueError(f"scalar_range must be finite with lo < hi, got {scalar_range!r}")
    if not (math.isfinite(d_max) and d_max > 0):
        raise ValueError(f"d_max must be positive and finite, got {d_max!r}")
    for name, v, least in (("n_bins", n_bins, 2), ("n_slices", n_slices, 1)):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)) or v < least:
            raise ValueError(f"{name} must be an integer of at least {least}, got {v!r}")
    n_bins, n_slices = int(n_bins), int(n_slices)
    if not (math.isfinite(float(log_base)) and float(log_base) > 1.0):
        raise ValueError(f"log_base must be a finite number above 1, got {log_base!r}")
    if encoding not in ("normalized", "premultiplied"):
        raise ValueError(f"encoding must be 'normalized' or 'premultiplied', got {encoding!r}")
    if dtype not in ("float32", "uint8"):
        raise ValueError(f"dtype must be 'float32' or 'uint8', got {dtype!r}")
    check_table_size(n_bins, n_slices, log_base, warp=warp)
    u = check_unit_distance(tf.unit_distance, "the transfer function's unit_distance")
    if warp and optics == "vtk":
        raise ValueError("optics='vtk' (the mean of a segment's end extinctions) has no warped table; use warp=False")
    warped = warped_nodes(tf, (lo, hi), n_bins) if warp else None
    nodes = warped if warped is not None else np.linspace(lo, hi, n_bins)
    n_bins = nodes.size  # a warped table may hold a few more (control points)
    check_memory(table_build_bytes(n_bins, n_slices, warp=warp),
                 f"building a {n_bins} x {n_bins} x {n_slices + 1} pre-integration table")
    width = np.diff(nodes) * ((n_bins - 1) / (hi - lo)) if warped is not None else np.ones(n_bins - 1)
    color, opacity = tf.evaluate(nodes)
    if optics not in OPTICS:
        raise ValueError(f"optics must be one of {OPTICS}, got {optics!r}")
    if optics == "exact":
        x = 1.0 - np.clip(opacity, 0.0, MAX_OPACITY)
        tau_node = -np.log(x) / u
        tau_bin = mean_neg_log(x[:-1], x[1:]) / u  # exact mean extinction over each bin
    else:  # tau = a/u is linear in the scalar between nodes: its bin mean is the midpoint
        tau_node = np.clip(opacity, 0.0, 1.0) / u
        tau_bin = 0.5 * (tau_node[:-1] + tau_node[1:])
    thick = d_max * log_base ** (np.arange(n_slices) - n_slices + 1.0)
    if not thick[0] >= np.finfo(np.float64).tiny:  # lookups divide by it
        raise ValueError(f"the thinnest slice, d_max * log_base ** -(n_slices - 1) = {float(thick[0])!r}, underflows "
                         f"(d_max={d_max!r}, log_base={log_base!r}, n_slices={n_slices}); use fewer slices or a "
                         "smaller log_base, or scale the mesh up")

    # Built as [k, sf, sb] (each step of the run recurrence writes one contiguous row) and
    # stored as [k, sb, sf]; theta and alpha are symmetric in (sf, sb).
    rgb = np.zeros((n_slices, n_bins, n_bins, 3))
    # Optical depth is exact from the prefix sum of the bin means (Engel 2001).
    # Scalars in units of the first bin's width (all bins' when the nodes are even).
    prefix = np.concatenate([[0.0], np.cumsum(tau_bin * width)])  # optical depth over bins < i
    i_idx = np.arange(n_bins)
    pos = np.concatenate([[0.0], np.cumsum(width)])
    span = np.abs(pos[None, :] - pos[:, None]) if warped is not None else np.abs(i_idx[None, :] - i_idx[:, None])
    # [sb, sf], symmetric: the mean over the bins between, or the node's own on the diagonal.
    mean_tau = np.where(span > 0, np.abs(prefix[None, :] - prefix[:, None]) / np.where(span > 0, span, 1),
                        tau_node[None, :])
    if optics == "vtk":  # VTK's PT: the mean of the two ends, not of the segment
        mean_tau = 0.5 * (tau_node[None, :] + tau_node[:, None])
        mean_color = 0.5 * (color[None, :, :] + color[:, None, :])  # [sb, sf, 3]

    if optics == "vtk":
        rgb[:] = mean_color[None] * (-np.expm1(-(thick[:, None, None] * mean_tau[None])))[..., None]
    else:
        # Diagonal: constant scalar, closed form.
        rgb[:, i_idx, i_idx, :] = color[None] * (-np.expm1(-thick[:, None] * tau_node[None]))[..., None]
        # Off-diagonal: the incremental recurrence, forwards (sb > sf) and on the mirrored axis.
        if warped is None:
            _fill_runs(rgb, color, tau_bin, thick)
        else:
            _fill_runs_uneven(rgb, color, tau_bin, width, thick)
    alpha_scale = 1.0
    if encoding == "normalized" and dtype == "float32" and optics != "vtk":
        # The default, slice by slice straight into float32: each slice's arrays stay in
        # cache (the same values as the general path below, in a third of its time).
        data: NDArray[np.generic] = np.empty((n_slices + 1, n_bins, n_bins, 4), dtype=np.float32)
        data[..., 3] = np.minimum(mean_tau, _MAX_STORED_TAU)
        data[0, ..., :3] = _thin_limit(color, tau_bin * width, tau_node, prefix)
        for k in range(n_slices):
            alpha_k = -np.expm1(-(thick[k] * mean_tau))[..., None]
            with np.errstate(invalid="ignore", divide="ignore"):
                chroma = np.where(alpha_k > 1e-300, rgb[k] / alpha_k, 0.0)
            data[k + 1, ..., :3] = np.clip(chroma, 0.0, 1.0, out=chroma).transpose(1, 0, 2)
        return _finished(data, tf, lo, hi, thick, log_base, encoding, alpha_scale, warped, optics)
    alpha = -np.expm1(-(thick[:, None, None] * mean_tau[None]))
    table = np.zeros((n_slices + 1, n_bins, n_bins, 4))
    if encoding == "premultiplied":
        table[1:, ..., :3] = rgb.transpose(0, 2, 1, 3)
        table[1:, ..., 3] = alpha
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            chroma = np.where(alpha[..., None] > 1e-300, rgb / alpha[..., None], 0.0)
        table[1:, ..., :3] = np.clip(chroma, 0.0, 1.0).transpose(0, 2, 1, 3)
        table[:, ..., 3] = np.minimum(mean_tau, _MAX_STORED_TAU)[None]
        table[0, ..., :3] = mean_color if optics == "vtk" else _thin_limit(color, tau_bin * width, tau_node, prefix)
        if dtype == "uint8":
            alpha_scale = float(max(min(mean_tau.max(), _MAX_STORED_TAU), 1e-300))
            table[..., 3] /= alpha_scale
    if dtype == "uint8":
        data = np.round(np.clip(table, 0.0, 1.0) * 255.0).astype(np.uint8)
    else:
        data = table.astype(np.float32)
    return _finished(data, tf, lo, hi, thick, log_base, encoding, alpha_scale, warped, optics)


def _finished(data: NDArray[np.generic], tf: TransferFunction, lo: float, hi: float, thick: NDArray[np.floating[Any]],
              log_base: float, encoding: str, alpha_scale: float, warped: NDArray[np.float64] | None,
              optics: str) -> PreintegrationTable:
    """The table of :func:`build_table`, read-only, with what its lookups need."""
    data.setflags(write=False)
    thicknesses = np.concatenate([[0.0], thick])
    optical = None
    if warped is not None:
        warped.setflags(write=False)
        optical = np.stack([extinction_cells(tf, (lo, hi), optics=optics),
                            node_opacity_cells(tf, warped, optics=optics)])
        optical.setflags(write=False)
    return PreintegrationTable(data=data, scalar_range=(lo, hi), thicknesses=thicknesses,
                               log_base=float(log_base), encoding=encoding, alpha_scale=alpha_scale, nodes=warped,
                               extinction=optical)


# table_for's cache (called with keywords, so every call shares one key layout).
_cached = functools.lru_cache(maxsize=32)(build_table)


def _fill_runs(rgb: NDArray[np.float64], color: NDArray[np.float64], tau_bin: NDArray[np.float64],
               thick: NDArray[np.floating[Any]]) -> None:
    """Premultiplied colour of every run of bins, for every slice, written in place:
    ``rgb[k, sf, sb]`` for ``sf != sb`` is the segment from node sf to node sb crossed in
    total length ``thick[k]`` (clipped at 0).

    Runs of the same length n share one step length d/n, so each diagonal is a sliding
    window, filled from the last front node down by the stable add-front/remove-back
    recurrence; the recurrence runs once forwards (sb > sf) and once on the mirrored axis.
    """
    n_bins = color.shape[0]
    nb = n_bins - 1
    n = np.arange(1, n_bins)  # run lengths
    step = thick[:, None] / n[None, :]  # [k, n]
    # Per-bin emission and transmittance for each step length, bin first ([m, k, n]) so
    # that each step of the recurrence reads one contiguous block.
    th = tau_bin[:, None, None] * step[None]
    t_bin = np.exp(-th)
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = np.where(th > 1e-12, -np.expm1(-th) / np.where(th > 0, th, 1.0), 1.0 - 0.5 * th)
    emits = th > 0  # a transparent bin emits nothing (guards rounding)
    dc = color[1:] - color[:-1]

    def bin_colours(start: NDArray[np.float64], end: NDArray[np.float64], slope: NDArray[np.float64]) -> NDArray[np.float64]:
        # Emission of each bin crossed from its start node to its end node: [m, 3, k, n].
        out = np.empty((nb, 3, *step.shape))
        for ch in range(3):
            o = out[:, ch]
            np.multiply(end[:, ch, None, None], t_bin, out=o)
            np.subtract(start[:, ch, None, None], o, out=o)
            o += slope[:, ch, None, None] * phi
            o *= emits
        return out

    for forwards in (True, False):
        if forwards:  # front node i, bins i .. i+n-1
            c_bin = bin_colours(color[:-1], color[1:], dc)
            t_run, taus = t_bin, tau_bin
        else:  # mirrored: front node N-1-i, bins N-2-i down to N-1-i-n (the same bins reversed)
            c_bin = bin_colours(color[1:], color[:-1], -dc)[::-1]
            t_run, taus = t_bin[::-1], tau_bin[::-1]
        prefix = np.concatenate([[0.0], np.cumsum(taus)])
        # leaving[i, :, k, j] = c_bin[i + j + 1, :, k, j]: the bin leaving a run of j + 1
        # bins that starts at bin i + 1, a skewed view (read only where i + j + 1 < nb).
        s0, s1, s2, s3 = c_bin.strides
        leaving = np.lib.stride_tricks.as_strided(c_bin[1:], shape=c_bin.shape,
                                                  strides=(s0, s1, s2, s3 + s0), writeable=False)
        w = np.zeros((3, thick.shape[0], nb))  # window sums, one per run length
        w_out = w.transpose(1, 2, 0)  # [k, n, 3]
        for i in range(nb - 1, -1, -1):
            v = nb - 1 - i  # runs that lose a bin at the back; longer ones reach past the end
            if v:
                # Transmittance of bins i+1 .. i+n-1 (those between the front and the leaving bin).
                between = prefix[i + 1: i + 1 + v] - prefix[i + 1]
                t_between = np.exp(-step[:, :v] * between[None, :])
                w[:, :, :v] -= t_between * leaving[i, :, :, :v]
            w *= t_run[i]
            w += c_bin[i]
            if forwards:
                np.maximum(w_out[:, : nb - i], 0.0, out=rgb[:, i, i + 1:, :])
            else:
                f = nb - i  # the front node on the unmirrored axis; sb runs f-1 .. 0
                np.maximum(w_out[:, :f], 0.0, out=rgb[:, f, f - 1::-1, :])


def _fill_runs_uneven(rgb: NDArray[np.float64], color: NDArray[np.float64], tau_bin: NDArray[np.float64],
                      width: NDArray[np.float64], thick: NDArray[np.floating[Any]]) -> None:
    """:func:`_fill_runs` for nodes ``width`` apart (bin by bin, in any unit): ``rgb[k, sf, sb]``.

    A run from node i to node j crosses bin m in length ``q * width[m]``, ``q = thick[k] /
    (x_j - x_i)``, which differs from run to run, so no two runs share their bins' colours
    and the sliding window of the even table does not apply. Instead, front node by front
    node, every run's bins are weighed at once: bin m (colour c0 -> c1, optical depth
    theta) behind transmittance T_m emits ``T_m c0 - T_{m+1} c1 + T_m phi(theta) (c1 - c0)``
    (:func:`_fill_runs`' bin colour), so the colours of all runs from one front node are three
    matrix products of those weights with the bins' colours. The work is ~N^3 K / 3
    exponentials (N^2 K for the even table), which is why warped tables have fewer nodes.
    (Transmittances are running products of the bins', as in the even recurrence.)
    """
    n_bins = color.shape[0]
    nb = n_bins - 1
    for forwards in (True, False):
        if forwards:
            c0, c1, w, taus = color[:-1], color[1:], width, tau_bin
        else:  # mirrored axis: node N-1-i, bins in reverse with their colours swapped
            c0, c1, w, taus = color[:0:-1], color[-2::-1], width[::-1], tau_bin[::-1]
        x = np.concatenate([[0.0], np.cumsum(w)])
        tw = taus * w
        depth = np.concatenate([[0.0], np.cumsum(tw)])  # optical depth per unit q up to each node
        dc = c1 - c0
        for i in range(nb):
            # Runs from node i to nodes i+1 .. N-1 (rows), bins i .. N-2 (columns).
            q = thick[None, :] / (x[i + 1:] - x[i])[:, None]  # [run, k]: length per unit width
            th = q[:, :, None] * tw[None, None, i:]  # [run, k, bin]: each bin's optical depth
            e1 = np.expm1(-th)
            with np.errstate(invalid="ignore", divide="ignore"):
                phi = np.where(th > 1e-12, -e1 / np.where(th > 0, th, 1.0), 1.0 - 0.5 * th)
            e1 += 1.0  # each bin's transmittance
            # Transmittance after each bin, zero past the run's last bin (run r crosses bins 0 .. r).
            # Products of many bins may underflow to subnormals or 0: light gone, not an error.
            with np.errstate(under="ignore"):
                after = np.cumprod(e1, axis=2)
            after *= np.tri(nb - i)[:, None, :]
            before = np.empty_like(after)
            before[..., 0] = 1.0
            before[..., 1:] = after[..., :-1]
            before[..., 1:] *= np.tri(nb - i, k=-1)[:, None, 1:] + np.eye(nb - i)[:, None, 1:]
            acc = before @ c0[i:] - after @ c1[i:] + (before * phi) @ dc[i:]  # [run, k, 3]
            np.maximum(acc, 0.0, out=acc)
            if forwards:
                rgb[:, i, i + 1:, :] = acc.transpose(1, 0, 2)
            else:
                f = nb - i  # the front node on the unmirrored axis; sb runs f-1 .. 0
                rgb[:, f, f - 1::-1, :] = acc.transpose(1, 0, 2)


def _thin_limit(color: NDArray[np.float64], tau_bin: NDArray[np.float64], tau_node: NDArray[np.float64],
                prefix: NDArray[np.float64]) -> NDArray[np.float64]:
    """Colour per unit alpha as thickness -> 0: the extinction-weighted mean colour.

    ``prefix`` is the prefix sum of ``tau_bin`` (``prefix[i]``: the sum over bins < i).
    """
    n_bins = color.shape[0]
    weighted = tau_bin[:, None] * 0.5 * (color[:-1] + color[1:])
    q = np.concatenate([np.zeros((1, 3)), np.cumsum(weighted, axis=0)])
    num = np.abs(q[:, None, :] - q[None, :, :])  # [sb, sf] symmetric
    den = np.abs(prefix[:, None] - prefix[None, :])
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(den[..., None] > 0, num / np.where(den > 0, den, 1.0)[..., None], 0.0)
    i = np.arange(n_bins)
    out[i, i] = np.where(tau_node[:, None] > 0, color, 0.0)
    return np.clip(out, 0.0, 1.0)

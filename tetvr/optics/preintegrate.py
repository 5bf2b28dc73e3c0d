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

import collections
import math
import threading
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from tetvr.core.image import check_memory
from tetvr.optics.model import MAX_OPACITY, OPTICS, mean_neg_log
from tetvr.optics.table import (STEP_GAP, PreintegrationTable, aligned_nodes, check_table_size, check_unit_distance,
                                node_limits, table_build_bytes, table_scalar_range)
from tetvr.optics.tablesteps import corner_blocks
from tetvr.optics.tablewarp import extinction_cells, max_warped_nodes, node_opacity_cells, warped_nodes
from tetvr.optics.transfer import TransferFunction

__all__ = ["build_table", "table_for", "TableRunsBuilder"]


class TableRunsBuilder(Protocol):
    """Builds a "normalized" float32 table's off-diagonal entries elsewhere (the GPU:
    :class:`tetvr.gl.tablebuild.TableRuns`): from each bin's colour at its start and end
    (N - 1 x RGB), its mean extinction, their prefix sum (N) and the K slices'
    thicknesses, it writes ``out[sb, sf, k]`` (N, N, K + 1, RGBA float32, the layout of
    :func:`tetvr.gl.util.table_texture`) for ``sf != sb`` and ``k >= 1`` as
    :func:`build_table` would: :func:`_fill_runs`' colours encoded by :func:`_encoded`
    (what it leaves in slice 0 and on the diagonal is overwritten)."""

    def __call__(self, start: NDArray[np.float64], end: NDArray[np.float64], tau_bin: NDArray[np.float64],
                 prefix: NDArray[np.float64], thick: NDArray[np.float64], out: NDArray[np.float32]) -> None: ...

# Largest extinction (per world unit) stored in a "normalized" table. A tiny unit distance
# gives extinctions past float32's range: stored as inf, the shader's d * inf at d = 0 is
# NaN. Capped, any segment longer than ~1e-28 is still opaque, which is what inf meant.
_MAX_STORED_TAU = 1e30


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
    runs: TableRunsBuilder | None = None,
) -> PreintegrationTable:
    """The table for a transfer function and a mesh, from a cache keyed by all inputs.

    The scalar axis spans :func:`table_scalar_range`: the union of the data range and
    the transfer function's domain; with ``align_nodes`` its nodes are placed on the
    transfer function's steps or control points where that helps
    (:func:`~tetvr.optics.table.aligned_nodes`, which may add a few nodes to put every
    step on one); with ``warp`` they are placed where the transfer function varies instead
    (:mod:`tetvr.optics.tablewarp`; ``align_nodes`` does not apply). ``runs``: where a
    table is built, :func:`build_table`'s ``runs`` (not part of the key: it builds the same table).
    """
    # Thicknesses are rounded up to 7 significant digits so near-equal meshes share a table.
    d_top = float(f"{d_max * (1 + 1e-6):.7g}")
    rng = table_scalar_range(data_range, tf)
    if align_nodes and not warp:
        lo, hi, n_bins = aligned_nodes(rng, tf, n_bins)
        rng = (lo, hi)
    key = (tf, rng, d_top, n_bins, n_slices, float(log_base), encoding, dtype, optics, bool(warp))
    with _cache_lock:
        table = _cache.get(key)
        if table is not None:
            _cache.move_to_end(key)
            return table
    table = build_table(tf, rng, d_top, n_bins=n_bins, n_slices=n_slices, log_base=float(log_base),
                        encoding=encoding, dtype=dtype, optics=optics, warp=bool(warp), runs=runs)
    with _cache_lock:
        _cache[key] = table
        while len(_cache) > _CACHE_SIZE:
            _cache.popitem(last=False)
    return table


def cache_clear() -> None:
    """Forget the tables :func:`table_for` keeps (for timing their build)."""
    with _cache_lock:
        _cache.clear()


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
    runs: TableRunsBuilder | None = None,
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
        fragment formula of VTK's projected tetrahedra); see :data:`tetvr.optics.model.OPTICS`.
    warp : place the ``n_bins`` nodes where the transfer function varies, control points on nodes
        (:func:`tetvr.optics.tablewarp.warped_nodes`; at most :func:`~tetvr.optics.tablewarp.max_warped_nodes`),
        instead of evenly; the table's ``nodes`` then says where they are.
    runs : builds the off-diagonal entries of a "normalized" float32 table with even nodes
        and ``optics`` other than "vtk" (:class:`TableRunsBuilder`: the GPU's
        :class:`tetvr.gl.tablebuild.TableRuns`); None, or any other table: numpy.

    A node on a step of the transfer function (:func:`~tetvr.optics.table.node_limits`) ends the bin
    below it with the step's lower side and starts the bin above with its upper side, so bands of
    constant colour are integrated exactly (and lookups cut segments there: :func:`_step_corners`).

    Examples
    --------
    >>> tf = TransferFunction.preset("grayscale", (0, 1), opacity=0.5)
    >>> build_table(tf, (0, 1), 1.0, n_bins=16, n_slices=4).data.shape
    (5, 16, 16, 4)
    """
    lo, hi, n_bins, n_slices, u = _checked(tf, scalar_range, d_max, n_bins, n_slices, log_base, encoding, dtype, warp,
                                           optics)
    nodes, warped, width = _placed_nodes(tf, lo, hi, n_bins, n_slices, warp)
    n_bins = nodes.size
    color, opacity, ends, stepped = _node_values(tf, nodes, optics)
    tau_node, tau_bin = _extinction(opacity, u, optics, ends[2:])
    thick = _slice_thicknesses(d_max, log_base, n_slices)

    # Optical depth is exact from the prefix sum of the bin means (Engel 2001).
    # Scalars in units of the first bin's width (all bins' when the nodes are even).
    prefix = np.concatenate([[0.0], np.cumsum(tau_bin * width)])  # optical depth over bins < i
    i_idx = np.arange(n_bins)
    pos = np.concatenate([[0.0], np.cumsum(width)])
    span = np.abs(pos[None, :] - pos[:, None]) if warped is not None else np.abs(i_idx[None, :] - i_idx[:, None])
    # [sb, sf], symmetric: the mean over the bins between, or the node's own on the diagonal.
    mean_tau = np.where(span > 0, np.abs(prefix[None, :] - prefix[:, None]) / np.where(span > 0, span, 1),
                        tau_node[None, :])
    if runs is not None and warped is None and optics != "vtk" and encoding == "normalized" and dtype == "float32":
        data, alpha_scale = _built_elsewhere(runs, color, ends, tau_node, tau_bin, prefix, mean_tau, thick), 1.0
    else:
        data, alpha_scale = _built_here(color, ends, tau_node, tau_bin, width, prefix, mean_tau, thick, warped is None,
                                        encoding, dtype, optics)
    steps = _step_corners(data, ends, u, optics, thick, encoding, alpha_scale) if stepped and warped is None else None
    return _finished(data, tf, lo, hi, thick, log_base, encoding, alpha_scale, warped, optics, steps)


def _built_here(color: NDArray[np.float64], ends: tuple[NDArray[np.float64], ...], tau_node: NDArray[np.float64],
                tau_bin: NDArray[np.float64], width: NDArray[np.float64], prefix: NDArray[np.float64],
                mean_tau: NDArray[np.float64], thick: NDArray[np.float64], even: bool, encoding: str, dtype: str,
                optics: str) -> tuple[NDArray[np.generic], float]:
    """:func:`build_table`'s data, built by numpy, and the factor its stored A was divided by (:func:`_encoded`)."""
    n_bins = color.shape[0]
    i_idx = np.arange(n_bins)
    # Built as [k, sf, sb] (each step of the run recurrence writes one contiguous row) and
    # stored as [k, sb, sf]; theta and alpha are symmetric in (sf, sb).
    rgb = np.zeros((thick.size, n_bins, n_bins, 3))
    mean_color: NDArray[np.float64] | None = None
    if optics == "vtk":  # VTK's PT: the mean of the two ends, not of the segment
        mean_tau = 0.5 * (tau_node[None, :] + tau_node[:, None])
        mean_color = 0.5 * (color[None, :, :] + color[:, None, :])  # [sb, sf, 3]
        rgb[:] = mean_color[None] * (-np.expm1(-(thick[:, None, None] * mean_tau[None])))[..., None]
    else:
        # Diagonal: constant scalar, closed form.
        rgb[:, i_idx, i_idx, :] = color[None] * (-np.expm1(-thick[:, None] * tau_node[None]))[..., None]
        # Off-diagonal: the incremental recurrence, forwards (sb > sf) and on the mirrored axis.
        if even:
            _fill_runs(rgb, ends[:2], tau_bin, thick)
        else:
            _fill_runs_uneven(rgb, ends[:2], tau_bin, width, thick)
    # Slice 0's colour in a "normalized" table: the thin limit, or VTK's mean of the end colours.
    thin = None if encoding == "premultiplied" else mean_color if mean_color is not None else _thin_limit(
        color, ends[:2], tau_bin * width, tau_node, prefix)
    return _encoded(rgb, mean_tau, thin, thick, encoding, dtype, optics)


def _checked(tf: TransferFunction, scalar_range: tuple[float, float], d_max: float, n_bins: int, n_slices: int,
             log_base: float, encoding: str, dtype: str, warp: bool, optics: str) -> tuple[float, float, int, int, float]:
    """Check :func:`build_table`'s arguments (a ``ValueError`` names the one refused) and
    return the scalar range, the bin and slice counts and the unit distance as numbers."""
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
    return lo, hi, n_bins, n_slices, u


def _placed_nodes(tf: TransferFunction, lo: float, hi: float, n_bins: int, n_slices: int, warp: bool) -> tuple[
        NDArray[np.float64], NDArray[np.float64] | None, NDArray[np.float64]]:
    """The table's scalar nodes, the warped ones (or None) and each bin's width in units of
    the first's (even: ones), once the memory the largest such table needs is known to be
    there (a warped one may hold a few more nodes, up to max_warped_nodes): refused before
    any work."""
    most = max_warped_nodes(n_bins) if warp else n_bins
    check_memory(table_build_bytes(n_bins, n_slices, warp=warp),
                 f"building a {most} x {most} x {n_slices + 1} pre-integration table")
    warped = warped_nodes(tf, (lo, hi), n_bins) if warp else None
    if warped is None:
        return np.linspace(lo, hi, n_bins), None, np.ones(n_bins - 1)
    return warped, warped, np.diff(warped) * ((warped.size - 1) / (hi - lo))


def _node_values(tf: TransferFunction, nodes: NDArray[np.float64], optics: str) -> tuple[
        NDArray[np.float64], NDArray[np.float64], tuple[NDArray[np.float64], ...], bool]:
    """The colour and opacity at each node, and at the two ends of each bin: ``(colour at
    its start, colour at its end, opacity at its start, opacity at its end)``, the values at
    the nodes but where a node sits on a step (:func:`~tetvr.optics.table.node_limits`):
    there each bin takes the step's side it lies on, and the node itself their mean. Last,
    whether some node sits on a step."""
    color, opacity = tf.evaluate(nodes)
    sides = None
    if optics != "vtk":  # VTK's projected tetrahedra read the colour at the vertices as it is
        sides = node_limits(tf, nodes, STEP_GAP * float(nodes[-1] - nodes[0]))
    if sides is None:
        return color, opacity, (color[:-1], color[1:], opacity[:-1], opacity[1:]), False
    c_below, c_above, o_below, o_above = sides
    return (0.5 * (c_below + c_above), 0.5 * (o_below + o_above),
            (c_above[:-1], c_below[1:], o_above[:-1], o_below[1:]), True)


def _extinction(opacity: NDArray[np.float64], u: float, optics: str,
                ends: tuple[NDArray[np.float64], ...] | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Extinction at each node, and its exact mean over each bin between two nodes (from
    the opacity at each bin's two ends: ``ends``, else the nodes')."""
    if optics not in OPTICS:
        raise ValueError(f"optics must be one of {OPTICS}, got {optics!r}")
    start, end = ends if ends is not None else (opacity[:-1], opacity[1:])
    if optics == "exact":
        tau_node = -np.log(1.0 - np.clip(opacity, 0.0, MAX_OPACITY)) / u
        # The exact mean extinction over each bin.
        tau_bin = mean_neg_log(1.0 - np.clip(start, 0.0, MAX_OPACITY), 1.0 - np.clip(end, 0.0, MAX_OPACITY)) / u
    else:  # tau = a/u is linear in the scalar between nodes: its bin mean is the midpoint
        tau_node = np.clip(opacity, 0.0, 1.0) / u
        tau_bin = 0.5 * (np.clip(start, 0.0, 1.0) / u + np.clip(end, 0.0, 1.0) / u)
    return tau_node, tau_bin


def _slice_thicknesses(d_max: float, log_base: float, n_slices: int) -> NDArray[np.float64]:
    """Thickness of slices 1..K, ``d_max * log_base**(k - K + 1)``; refused where the thinnest underflows."""
    thick = d_max * log_base ** (np.arange(n_slices) - n_slices + 1.0)
    if not thick[0] >= np.finfo(np.float64).tiny:  # lookups divide by it
        raise ValueError(f"the thinnest slice, d_max * log_base ** -(n_slices - 1) = {float(thick[0])!r}, underflows "
                         f"(d_max={d_max!r}, log_base={log_base!r}, n_slices={n_slices}); use fewer slices or a "
                         "smaller log_base, or scale the mesh up")
    return thick


def _encoded(rgb: NDArray[np.float64], mean_tau: NDArray[np.float64], thin: NDArray[np.float64] | None,
             thick: NDArray[np.float64], encoding: str, dtype: str, optics: str) -> tuple[NDArray[np.generic], float]:
    """The table's data, in the encoding and dtype asked for, and the factor its stored A
    was divided by: from the premultiplied colour ``rgb[k, sf, sb]`` of slices 1..K, the
    mean extinction ``mean_tau[sb, sf]`` and (``"normalized"``) slice 0's colour ``thin[sb, sf]``."""
    n_slices, n_bins = rgb.shape[0], rgb.shape[1]
    alpha_scale = 1.0
    if encoding == "normalized" and dtype == "float32" and optics != "vtk":
        # The default, slice by slice straight into float32: each slice's arrays stay in
        # cache (the same values as the general path below, in a third of its time).
        data: NDArray[np.generic] = np.empty((n_slices + 1, n_bins, n_bins, 4), dtype=np.float32)
        data[..., 3] = np.minimum(mean_tau, _MAX_STORED_TAU)
        data[0, ..., :3] = thin
        for k in range(n_slices):
            alpha_k = -np.expm1(-(thick[k] * mean_tau))[..., None]
            with np.errstate(invalid="ignore", divide="ignore"):
                chroma = np.where(alpha_k > 1e-300, rgb[k] / alpha_k, 0.0)
            data[k + 1, ..., :3] = np.clip(chroma, 0.0, 1.0, out=chroma).transpose(1, 0, 2)
        return data, alpha_scale
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
        table[0, ..., :3] = thin
        if dtype == "uint8":
            alpha_scale = float(max(min(mean_tau.max(), _MAX_STORED_TAU), 1e-300))
            table[..., 3] /= alpha_scale
    if dtype == "uint8":
        data = np.round(np.clip(table, 0.0, 1.0) * 255.0).astype(np.uint8)
    else:
        data = table.astype(np.float32)
    return data, alpha_scale


def _step_corners(data: NDArray[np.generic], ends: tuple[NDArray[np.float64], ...], u: float, optics: str,
                  thick: NDArray[np.float64], encoding: str, alpha_scale: float) -> NDArray[np.generic] | None:
    """A "normalized" table's corner blocks (:func:`~tetvr.optics.tablesteps.corner_blocks`)
    from each bin's colour and opacity at its ends (``ends``, on the bin's side of the steps),
    from which lookups read the pieces of a segment cut at the nodes
    (:mod:`tetvr.optics.tablesteps`); None for a "premultiplied" table (whose alpha,
    interpolated across slices, would err on the short pieces: it keeps the one lookup)."""
    if encoding != "normalized":
        return None
    start, end = (_encoded_constant(c, _extinction(o, u, optics)[0], thick, data.dtype, alpha_scale)
                  for c, o in ((ends[0], ends[2]), (ends[1], ends[3])))
    return corner_blocks(data, start, end)


def _encoded_constant(color: NDArray[np.float64], tau: NDArray[np.float64], thick: NDArray[np.float64],
                      dtype: Any, alpha_scale: float) -> NDArray[np.generic]:
    """Entries ``(K + 1, M, RGBA)`` of constant-scalar segments of colour ``color`` and
    extinction ``tau`` (M of each), encoded as :func:`_encoded` encodes a "normalized"
    table's diagonal."""
    alpha = -np.expm1(-thick[:, None] * tau[None, :])[..., None]  # [k, m, 1]
    out = np.zeros((thick.size + 1, tau.size, 4))
    out[1:, :, :3] = np.clip(np.where(alpha > 1e-300, color[None], 0.0), 0.0, 1.0)  # (colour * alpha) / alpha
    out[0, :, :3] = np.clip(np.where(tau[:, None] > 0, color, 0.0), 0.0, 1.0)
    out[..., 3] = np.minimum(tau, _MAX_STORED_TAU)[None] / alpha_scale
    if dtype == np.uint8:
        return np.round(np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)
    return out.astype(dtype)


def _finished(data: NDArray[np.generic], tf: TransferFunction, lo: float, hi: float, thick: NDArray[np.floating[Any]],
              log_base: float, encoding: str, alpha_scale: float, warped: NDArray[np.float64] | None,
              optics: str, steps: NDArray[np.generic] | None = None) -> PreintegrationTable:
    """The table of :func:`build_table`, read-only, with what its lookups need."""
    data.setflags(write=False)
    if steps is not None:
        steps.setflags(write=False)
    thicknesses = np.concatenate([[0.0], thick])
    optical = None
    if warped is not None:
        warped.setflags(write=False)
        optical = np.stack([extinction_cells(tf, (lo, hi), optics=optics),
                            node_opacity_cells(tf, warped, optics=optics)])
        optical.setflags(write=False)
    return PreintegrationTable(data=data, scalar_range=(lo, hi), thicknesses=thicknesses,
                               log_base=float(log_base), encoding=encoding, alpha_scale=alpha_scale, nodes=warped,
                               extinction=optical, steps=steps)


# table_for's cache: the last _CACHE_SIZE tables, by their inputs.
_CACHE_SIZE = 32
_cache: "collections.OrderedDict[tuple[Any, ...], PreintegrationTable]" = collections.OrderedDict()
_cache_lock = threading.Lock()


def _built_elsewhere(runs: TableRunsBuilder, color: NDArray[np.float64], ends: tuple[NDArray[np.float64], ...],
                     tau_node: NDArray[np.float64], tau_bin: NDArray[np.float64], prefix: NDArray[np.float64],
                     mean_tau: NDArray[np.float64], thick: NDArray[np.float64]) -> NDArray[np.float32]:
    """A "normalized" float32 table's data, its off-diagonal entries from ``runs`` and the
    rest as :func:`_encoded` writes it: slice 0 the thin limit, and on the diagonal (a
    constant scalar) the node's colour and extinction. Built in the texture's layout
    [back, front, slice] and returned as a view [slice, back, front]."""
    n_bins = color.shape[0]
    texels = np.empty((n_bins, n_bins, thick.size + 1, 4), dtype=np.float32)
    runs(ends[0], ends[1], tau_bin, prefix, thick, texels)
    texels[:, :, 0, :3] = _thin_limit(color, ends[:2], tau_bin, tau_node, prefix)
    texels[:, :, 0, 3] = np.minimum(mean_tau, _MAX_STORED_TAU)
    i = np.arange(n_bins)
    alpha = -np.expm1(-tau_node[:, None] * thick[None])  # [node, k]
    texels[i, i, 1:, :3] = np.clip(np.where(alpha[..., None] > 1e-300, color[:, None], 0.0), 0.0, 1.0)
    texels[i, i, 1:, 3] = np.minimum(tau_node, _MAX_STORED_TAU)[:, None]
    return np.moveaxis(texels, 2, 0)


def _fill_runs(rgb: NDArray[np.float64], ends: tuple[NDArray[np.float64], ...], tau_bin: NDArray[np.float64],
               thick: NDArray[np.floating[Any]]) -> None:
    """Premultiplied colour of every run of bins, for every slice, written in place:
    ``rgb[k, sf, sb]`` for ``sf != sb`` is the segment from node sf to node sb crossed in
    total length ``thick[k]`` (clipped at 0); ``ends``: each bin's colour at its start and end.

    Runs of the same length n share one step length d/n, so each diagonal is a sliding
    window, filled from the last front node down by the stable add-front/remove-back
    recurrence; the recurrence runs once forwards (sb > sf) and once on the mirrored axis.
    """
    start, end = ends
    nb = start.shape[0]
    n = np.arange(1, nb + 1)  # run lengths
    step = thick[:, None] / n[None, :]  # [k, n]
    # Per-bin emission and transmittance for each step length, bin first ([m, k, n]) so
    # that each step of the recurrence reads one contiguous block.
    th = tau_bin[:, None, None] * step[None]
    t_bin = np.exp(-th)
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = np.where(th > 1e-12, -np.expm1(-th) / np.where(th > 0, th, 1.0), 1.0 - 0.5 * th)
    emits = th > 0  # a transparent bin emits nothing (guards rounding)
    dc = end - start

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
            c_bin = bin_colours(start, end, dc)
            t_run, taus = t_bin, tau_bin
        else:  # mirrored: front node N-1-i, bins N-2-i down to N-1-i-n (the same bins reversed)
            c_bin = bin_colours(end, start, -dc)[::-1]
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


def _fill_runs_uneven(rgb: NDArray[np.float64], ends: tuple[NDArray[np.float64], ...], tau_bin: NDArray[np.float64],
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
    start, end = ends
    nb = start.shape[0]
    for forwards in (True, False):
        if forwards:
            c0, c1, w, taus = start, end, width, tau_bin
        else:  # mirrored axis: node N-1-i, bins in reverse with their colours swapped
            c0, c1, w, taus = end[::-1], start[::-1], width[::-1], tau_bin[::-1]
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


def _thin_limit(color: NDArray[np.float64], ends: tuple[NDArray[np.float64], ...], tau_bin: NDArray[np.float64],
                tau_node: NDArray[np.float64], prefix: NDArray[np.float64]) -> NDArray[np.float64]:
    """Colour per unit alpha as thickness -> 0: the extinction-weighted mean colour.

    ``color`` is the colour at each node, ``ends`` each bin's at its start and end, and
    ``prefix`` the prefix sum of ``tau_bin`` (``prefix[i]``: the sum over bins < i).
    """
    n_bins = color.shape[0]
    weighted = tau_bin[:, None] * 0.5 * (ends[0] + ends[1])
    q = np.concatenate([np.zeros((1, 3)), np.cumsum(weighted, axis=0)])
    num = np.abs(q[:, None, :] - q[None, :, :])  # [sb, sf] symmetric
    den = np.abs(prefix[:, None] - prefix[None, :])
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(den[..., None] > 0, num / np.where(den > 0, den, 1.0)[..., None], 0.0)
    i = np.arange(n_bins)
    out[i, i] = np.where(tau_node[:, None] > 0, color, 0.0)
    return np.clip(out, 0.0, 1.0)

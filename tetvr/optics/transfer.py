"""Transfer functions: scalar -> (RGB colour, opacity), piecewise linear.

Colour and opacity have separate control points (as in ParaView's colour map and
opacity map). Scalars below the first or above the last control point take the end
values (VTK's clamping). Positions are in the scalar's own units.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.volume.volume import Volume

__all__ = ["paraview_unit_distance", "TransferFunction", "PRESETS", "DEFAULT_OPACITY_RAMP", "DEFAULT_PERCENTILES", "DEFAULT_UNIT_FRACTION",
           "robust_range", "field_range", "default_unit_distance", "point_weights", "MAX_CONTROL_POINTS"]

# ---- the default rule: one place, used by preset(mesh), render(), the scene JSON and the CLI ----
#: Percentiles (of the field, weighted by the volume each point stands for) that span the
#: default colour and opacity range: a few extreme cells (a shock, a singular corner)
#: do not squeeze the rest of the field into one colour.
DEFAULT_PERCENTILES = (1.0, 99.5)
#: The default opacity ramp, ``(t, a)`` across the range: quadratic, so the bulk of the
#: field (often near its low end: free stream, ambient) stays a faint context and high
#: values stand out. Below the range is transparent; above it, as opaque as the top, 0.9:
#: an opacity of 1 is an infinite extinction, which the pre-integration table can only
#: approximate (0.1 of alpha off on a stress field's hot spot at the top 1.0, 1.6e-3 at 0.9).
DEFAULT_OPACITY_RAMP: tuple[tuple[float, float], ...] = tuple((t, 0.9 * t * t) for t in (0.0, 0.25, 0.5, 0.75, 1.0))
#: The default unit distance as a fraction of the bounding-box diagonal: the picture
#: looks the same whether the mesh is measured in metres or micrometres.
DEFAULT_UNIT_FRACTION = 1.0 / 20.0
#: Control points closer than this fraction of a map's span are refused: the slope between
#: them overflows (5e-324 apart gave a 16-25 dB picture without an error).
MIN_RELATIVE_GAP = 1e-12
#: The most control points a colour or opacity map may hold: a map is kept as Python
#: numbers (``_POINT_BYTES`` per point and column, ~0.7 GB at this count for a colour map), and
#: everything the renderer derives from it is O(points) at most (the table's size does not
#: depend on it). A ParaView state holds at most 32,768 colour points.
MAX_CONTROL_POINTS = 1 << 22
#: Bytes a control point takes as a tuple of Python floats, per column, plus the tuple.
_POINT_BYTES = (32, 48)


def point_weights(points: ArrayLike, tets: ArrayLike) -> NDArray[np.float64]:
    """The volume each point stands for: a quarter of the volume of every tet around it
    (the lumped mass), so that statistics of a point field do not favour refined regions.

    >>> point_weights([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]]).tolist()
    [0.041666666666666664, 0.041666666666666664, 0.041666666666666664, 0.041666666666666664]
    """
    p = np.asarray(points, dtype=np.float64)
    t = np.asarray(tets, dtype=np.int64)
    vol = np.empty(t.shape[0])
    for start in range(0, t.shape[0], 1 << 18):  # in blocks: the corners take 96 bytes a tet
        q = p[t[start:start + (1 << 18)]]
        vol[start:start + q.shape[0]] = np.abs(np.einsum("ij,ij->i", np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]),
                                                         q[:, 3] - q[:, 0])) / 6.0
    return np.bincount(t.ravel(), weights=np.repeat(vol / 4.0, 4), minlength=p.shape[0]).astype(np.float64)


def field_range(mesh: Any) -> tuple[float, float]:
    """The default scalar range of a mesh's or a volume's field: :func:`robust_range` of
    the values that are rendered, each weighted by the volume it stands for (the points'
    lumped volumes; the cells' volumes for cell data; a :class:`~tetvr.volume.volume.Volume`'s
    voxels equally, each standing for one voxel of the grid).

    >>> field_range(Volume.from_array(np.arange(1000.0).reshape(10, 10, 10)))
    (9.5, 994.5)
    """
    if isinstance(mesh, Volume):
        return robust_range(mesh.data)
    cells = getattr(mesh, "cell_scalars", None)
    if cells is None:
        return robust_range(mesh.scalars, point_weights(mesh.points, mesh.tets))
    q = np.asarray(mesh.points)[np.asarray(mesh.tets, dtype=np.int64)]
    vol = np.abs(np.einsum("ij,ij->i", np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), q[:, 3] - q[:, 0]))
    return robust_range(cells, vol)


def weighted_percentiles(values: ArrayLike, weights: ArrayLike | None, percentiles: Sequence[float]) -> list[float]:
    """The ``percentiles`` (0..100) of ``values``, each weighted by ``weights`` (``None``:
    equally): the value at which the cumulative weight, taken at each value's midpoint,
    passes ``q``.

    >>> weighted_percentiles([0.0, 1.0, 2.0, 3.0], [1, 1, 1, 5], [50])
    [2.5]
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if weights is None:
        # Equal weights: numpy's "hazen" percentiles are this rule, by partition instead
        # of a sort (0.08 s instead of 3 s for a 256^3 volume).
        return [float(x) for x in np.percentile(v, list(percentiles), method="hazen")]
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    if not w.sum() > 0:
        w = np.ones_like(v)
    order = np.argsort(v, kind="stable")
    v, w = v[order], w[order]
    cum = (np.cumsum(w) - 0.5 * w) / w.sum()
    return [float(np.interp(q / 100.0, cum, v)) for q in percentiles]


def robust_range(values: ArrayLike, weights: ArrayLike | None = None,
                 percentiles: tuple[float, float] = DEFAULT_PERCENTILES) -> tuple[float, float]:
    """The ``percentiles`` of ``values`` (weighted by ``weights``), widened to the full
    range where they coincide (a field that is mostly one value), and to a small interval
    above a constant field, so that ``lo < hi`` always.

    >>> [round(v, 2) for v in robust_range(np.r_[np.linspace(0, 1, 1001), 1000.0])]  # not set by an outlier
    [0.01, 1.0]
    >>> robust_range([3.0, 3.0, 3.0])
    (3.0, 3.003)
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise ValueError("robust_range needs finite values")
    w = None if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    if w is not None and (w.shape != v.shape or np.any(w < 0) or not np.all(np.isfinite(w))):
        raise ValueError(f"weights must be finite, non-negative and one per value, got shape {w.shape}")
    lo, hi = weighted_percentiles(v, w, percentiles)
    if not hi > lo:
        lo, hi = float(v.min()), float(v.max())
    # As render's _tf_range: a range the GPU's float32 scalars can resolve.
    if hi - lo <= 1e-5 * max(abs(lo), abs(hi)):
        hi = lo + max(abs(lo), 1.0) * 1e-3
    return lo, hi


def default_unit_distance(bounds: ArrayLike) -> float:
    """:data:`DEFAULT_UNIT_FRACTION` of the diagonal of ``bounds`` (a ``(2, 3)`` box).

    >>> default_unit_distance([(0, 0, 0), (3, 4, 0)])
    0.25
    """
    lo, hi = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    return max(float(np.linalg.norm(hi - lo)) * DEFAULT_UNIT_FRACTION, 1e-30)

# Colour presets sampled on [0, 1]: (position, r, g, b).
PRESETS: dict[str, tuple[tuple[float, float, float, float], ...]] = {
    "viridis": (  # matplotlib's viridis at k/8
        (0.0, 0.267004, 0.004874, 0.329415),
        (0.125, 0.278826, 0.175490, 0.483397),
        (0.25, 0.229739, 0.322361, 0.545706),
        (0.375, 0.172719, 0.448791, 0.557885),
        (0.5, 0.127568, 0.566949, 0.550556),
        (0.625, 0.157851, 0.683765, 0.501686),
        (0.75, 0.369214, 0.788888, 0.382914),
        (0.875, 0.678489, 0.863742, 0.189503),
        (1.0, 0.993248, 0.906157, 0.143936),
    ),
    "cool-to-warm": (
        (0.0, 0.231373, 0.298039, 0.752941),
        (0.5, 0.865003, 0.865003, 0.865003),
        (1.0, 0.705882, 0.015686, 0.149020),
    ),
    "grayscale": ((0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0, 1.0)),
    "hot": (
        (0.0, 0.0416, 0.0, 0.0),
        (0.365, 1.0, 0.0, 0.0),
        (0.746, 1.0, 1.0, 0.0),
        (1.0, 1.0, 1.0, 1.0),
    ),
}


def _few(values: NDArray[np.float64], most: int = 8) -> str:
    """Up to ``most`` values of an array for a message (a map may hold millions)."""
    shown = values.ravel()[:most].tolist()
    return f"{shown}" if values.size <= most else f"{shown[:-1]} ... ({values.size:,} values)"


def _points(value: ArrayLike, width: int, name: str) -> tuple[tuple[tuple[float, ...], ...], NDArray[np.float64]]:
    """The rows of a colour (``width`` 4) or opacity (2) map, checked, as tuples of Python
    floats and as a read-only array."""
    rows = "(x, r, g, b)" if width == 4 else "(x, a)"
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{name} must be a sequence of {rows} rows, got {value!r}")
    count = len(value) if hasattr(value, "__len__") else 0
    if count > MAX_CONTROL_POINTS:  # before anything is converted
        need = count * (_POINT_BYTES[0] * width + _POINT_BYTES[1])
        raise ValueError(f"{name} has {count:,} control points, more than the {MAX_CONTROL_POINTS:,} a transfer "
                         f"function holds (they would take ~{need / 2**30:.1f} GiB as Python numbers); resample the "
                         "map onto fewer points (np.interp onto a finer grid where it changes)")
    try:
        arr = np.array(value, dtype=np.float64)  # a copy: the caller's array is not ours to freeze
    except (TypeError, ValueError) as exc:  # ragged rows, non-numbers
        raise ValueError(f"{name} must be a sequence of {rows} rows of numbers, got {value!r} ({exc})") from None
    if arr.ndim != 2 or arr.shape[1] != width or arr.shape[0] < 1:
        raise ValueError(f"{name} must be a sequence of {rows} rows, got an array of shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or Inf: {_few(arr[~np.all(np.isfinite(arr), axis=1)])}")
    x = arr[:, 0]
    with np.errstate(over="ignore"):  # an overflowing difference is still positive
        dx = np.diff(x)
        span = x[-1] - x[0]
    if np.any(dx < 0):
        raise ValueError(f"{name} positions must be sorted ascending, got {_few(x)}")
    if np.any(dx == 0):
        raise ValueError(f"{name} has duplicate positions {_few(x[np.nonzero(dx == 0)[0]])}")
    if not np.isfinite(span):
        raise ValueError(f"{name} positions span more than float64 can hold: {x[0]} .. {x[-1]}")
    close = np.nonzero(dx < MIN_RELATIVE_GAP * span)[0]
    if close.size:
        i = int(close[0])
        raise ValueError(f"{name} positions {float(x[i])!r} and {float(x[i + 1])!r} are {dx[i]:.3g} apart, closer than "
                         f"{MIN_RELATIVE_GAP:g} of the function's span ({span:.3g}), where the slopes between them "
                         "are not finite; make a step a short ramp")
    vals = arr[:, 1:]
    if np.any(vals < 0) or np.any(vals > 1):
        raise ValueError(f"{name} values must lie in [0, 1], got {vals.min()} .. {vals.max()}")
    arr.setflags(write=False)
    return tuple(map(tuple, arr.tolist())), arr  # tolist: Python floats, ~5x faster than float() per value


@dataclasses.dataclass(frozen=True)
class TransferFunction:
    """Piecewise-linear colour and opacity over a scalar.

    Parameters
    ----------
    color : rows of ``(x, r, g, b)``, ``x`` ascending, components in [0, 1].
    opacity : rows of ``(x, a)``, ``x`` ascending, ``a`` in [0, 1]: the opacity of a slab
        of thickness ``unit_distance`` (see :mod:`tetvr.optics.model`).
    unit_distance : world-space length ``u`` over which opacity ``a`` is reached.

    Examples
    --------
    >>> tf = TransferFunction.preset("viridis", (0.0, 1.0), opacity=0.5, unit_distance=0.1)
    >>> tf.evaluate([0.0, 1.0])[1].tolist()
    [0.5, 0.5]
    """

    color: tuple[tuple[float, float, float, float], ...]
    opacity: tuple[tuple[float, float], ...]
    unit_distance: float = 1.0

    def __post_init__(self) -> None:
        color, self_color = _points(self.color, 4, "color")
        opacity, self_opacity = _points(self.opacity, 2, "opacity")
        object.__setattr__(self, "color", color)
        object.__setattr__(self, "opacity", opacity)
        # The same rows as arrays, for evaluate() (not fields: equality and hash stay the rows').
        object.__setattr__(self, "_arrays", (self_color, self_opacity))
        bp = np.unique(np.concatenate([self_color[:, 0], self_opacity[:, 0]]))
        bp.setflags(write=False)
        object.__setattr__(self, "_breakpoints", bp)
        try:
            u = float(self.unit_distance)
        except (TypeError, ValueError):
            raise ValueError(f"unit_distance must be a positive finite number, got {self.unit_distance!r}") from None
        if isinstance(self.unit_distance, (bool, np.bool_, str, bytes)) or not np.isfinite(u) or u <= 0:
            raise ValueError(f"unit_distance must be a positive finite number, got {self.unit_distance!r}")
        object.__setattr__(self, "unit_distance", u)

    def __hash__(self) -> int:
        # The fields' hash, computed once: tables and size decisions are cached by the
        # function, and a map of a million points takes ~0.4 s to hash.
        cached = self.__dict__.get("_hash")
        if cached is None:
            cached = hash((self.color, self.opacity, self.unit_distance))
            object.__setattr__(self, "_hash", cached)
        return cached  # type: ignore[no-any-return]

    @classmethod
    def preset(
        cls,
        name: str,
        scalar_range: Any = None,
        *,
        opacity: float | Sequence[tuple[float, float]] | None = None,
        unit_distance: float | None = None,
        mesh: Any = None,
    ) -> "TransferFunction":
        """A named colour map stretched over ``scalar_range``.

        Parameters
        ----------
        name : one of :data:`PRESETS` (see :func:`tetvr.optics.colormaps.colormap` for matplotlib's).
        scalar_range : ``(lo, hi)``; or a :class:`~tetvr.TetMesh` or :class:`~tetvr.Volume`,
            passed as ``mesh``.
        opacity : a constant, or ``(t, a)`` rows with ``t`` in [0, 1] across the range.
            Default: :data:`DEFAULT_OPACITY_RAMP` with a mesh, else a constant 0.5.
        unit_distance : world length over which ``a`` is reached. Default:
            :func:`default_unit_distance` of the mesh's bounds with a mesh, else 1.0
            (in the mesh's own units: give a mesh, or a length, for meshes far from unit size).
        mesh : the mesh or volume the function is for: the range defaults to the
            :func:`robust_range` of its field (:func:`field_range`, weighted by volume) and the
            unit distance to its size.

        Examples
        --------
        >>> from tetvr.mesh import synthetic
        >>> tf = TransferFunction.preset("viridis", synthetic.cube(2))  # the default rule
        >>> tf.opacity[-1][1], round(tf.unit_distance, 4)
        (0.9, 0.1268)
        """
        if mesh is None and (isinstance(scalar_range, Volume)
                             or all(hasattr(scalar_range, a) for a in ("points", "tets", "scalars", "bounds"))):
            mesh, scalar_range = scalar_range, None
        if mesh is not None:
            if scalar_range is None:
                scalar_range = field_range(mesh)
            if unit_distance is None:
                unit_distance = default_unit_distance(mesh.bounds)
            if opacity is None:
                opacity = DEFAULT_OPACITY_RAMP
        if scalar_range is None:
            raise ValueError("scalar_range is needed: (lo, hi), or a mesh to take it from")
        opacity = 0.5 if opacity is None else opacity
        unit_distance = 1.0 if unit_distance is None else unit_distance
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}")
        try:
            lo, hi = (float(v) for v in scalar_range)
        except (TypeError, ValueError):
            raise ValueError(f"scalar_range must be two numbers (lo, hi), got {scalar_range!r}") from None
        with np.errstate(over="ignore"):
            finite = bool(np.isfinite(lo) and np.isfinite(hi) and np.isfinite(np.float64(hi) - lo))
        if not finite or hi <= lo:
            raise ValueError(f"scalar_range must be finite with lo < hi, got {scalar_range!r}")
        color = tuple((lo + (hi - lo) * p, r, g, b) for p, r, g, b in PRESETS[name])
        try:
            if np.isscalar(opacity):
                op: tuple[tuple[float, float], ...] = ((lo, float(opacity)), (hi, float(opacity)))  # type: ignore[arg-type]
            else:
                op = tuple((lo + (hi - lo) * float(t), float(a)) for t, a in opacity)  # type: ignore[union-attr]
        except (TypeError, ValueError):
            raise ValueError(f"opacity must be a number or (t, a) rows with t in [0, 1], got {opacity!r}") from None
        return cls(color=color, opacity=op, unit_distance=unit_distance)

    @property
    def domain(self) -> tuple[float, float]:
        """Smallest and largest control-point position over colour and opacity."""
        xs = self.breakpoints
        return float(xs[0]), float(xs[-1])

    @property
    def point_arrays(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The colour rows ``(n, 4)`` and the opacity rows ``(m, 2)`` as read-only arrays."""
        return self._arrays  # type: ignore[no-any-return]  # set in __post_init__

    @property
    def breakpoints(self) -> NDArray[np.float64]:
        """Sorted union of all control-point positions: between two, both maps are linear."""
        return self._breakpoints  # type: ignore[no-any-return]  # set in __post_init__, read-only

    def evaluate(self, scalars: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Colour ``(n, 3)`` and opacity ``(n,)`` at the given scalars (clamped at the ends)."""
        s = np.asarray(scalars, dtype=np.float64)
        c, o = self.point_arrays
        rgb = np.stack([np.interp(s, c[:, 0], c[:, k]) for k in (1, 2, 3)], axis=-1)
        return rgb, np.interp(s, o[:, 0], o[:, 1])

    def to_dict(self) -> dict[str, Any]:
        return {
            "color": [list(p) for p in self.color],
            "opacity": [list(p) for p in self.opacity],
            "unit_distance": self.unit_distance,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "TransferFunction":
        known = {"color", "opacity", "unit_distance"}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown transfer-function keys {sorted(unknown)}; expected {sorted(known)}")
        missing = {"color", "opacity"} - set(data)
        if missing:
            raise ValueError(f"transfer function is missing keys {sorted(missing)}")
        # __post_init__ checks the shapes and turns the rows into tuples.
        return cls(color=data["color"], opacity=data["opacity"], unit_distance=data.get("unit_distance", 1.0))

    def digest(self) -> str:
        """A stable hash of the function, used to cache pre-integration tables."""
        return hashlib.sha1(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()[:16]

    def log_scaled(self, *, color: bool = True, opacity: bool = True, tolerance: float = 1e-4) -> "TransferFunction":
        """The same control points interpolated in ``log10`` of the scalar (ParaView's
        "Use Log Scale"), as a piecewise-linear function of the scalar itself.

        Between two control points ``x0 < x1`` the value is linear in ``log x``. The field
        is not changed (it stays linear in each cell, which the renderer and the reference
        integrate exactly); the curve is followed by linear pieces between geometrically
        spaced points, as many as keep it within ``tolerance`` of the curve (a colour
        change of 1 over three decades takes ~90 pieces at the default 1e-4). Every
        control point must be positive; scalars below the first point still take its value.

        Examples
        --------
        >>> tf = TransferFunction(color=((1, 0, 0, 0), (100, 1, 1, 1)), opacity=((1, 0.5), (100, 0.5)))
        >>> round(float(tf.log_scaled().evaluate([10.0])[0][0, 0]), 4)  # halfway in log10
        0.5
        """
        if not (isinstance(tolerance, (int, float)) and 0 < tolerance < 1):
            raise ValueError(f"tolerance must be a number in (0, 1), got {tolerance!r}")
        return dataclasses.replace(
            self,
            color=_log_pieces(self.color, tolerance, "color") if color else self.color,
            opacity=_log_pieces(self.opacity, tolerance, "opacity") if opacity else self.opacity)


def _log_pieces(rows: Any, tolerance: float, name: str) -> Any:
    """Control points ``rows`` (x, values...) interpolated linearly in log x, as linear
    pieces in x: on [a, a e^r] the chord of a function linear in ln x strays from it by
    at most ~|change| r / 8, so a segment spanning ln(x1/x0) = L with a change dv needs
    n = sqrt(dv L / (8 tolerance)) pieces of ratio e^(L/n)."""
    arr = np.asarray(rows, dtype=np.float64)
    if np.any(arr[:, 0] <= 0):
        raise ValueError(f"a log scale needs positive {name} control points, got positions from {arr[0, 0]!r} "
                         f"(ParaView refuses a log scale over a range reaching 0 too); shift the field or the range")
    out = [arr[:1]]
    for a, b in zip(arr[:-1], arr[1:]):
        span = math.log(b[0] / a[0])
        change = float(np.max(np.abs(b[1:] - a[1:])))
        n = min(4096, max(1, math.ceil(math.sqrt(change * span / (8.0 * tolerance)))))
        t = np.arange(1, n + 1) / n
        xs = a[0] * np.exp(span * t)
        xs[-1] = b[0]  # the control point itself, exactly
        out.append(np.column_stack([xs, a[1:] + np.outer(t, b[1:] - a[1:])]))
    pts = np.concatenate(out)
    keep = np.concatenate([[True], np.diff(pts[:, 0]) > 0])  # rounding may merge the tiniest pieces
    return tuple(tuple(float(v) for v in row) for row in pts[keep])


def paraview_unit_distance(bounds: Any, n_cells: int) -> float:
    """ParaView's default ``ScalarOpacityUnitDistance``: the bounding-box diagonal divided
    by the cube root of the number of cells (``vtkSMBoundsDomain``, mode
    ``approximate_cell_length``), the diagonal alone without cells.

    ParaView counts the cells of the dataset it shows: for a mesh of hexahedra that tetvr
    splits into tets, pass the file's cell count.

    >>> paraview_unit_distance([(0, 0, 0), (3, 4, 0)], 125)
    1.0
    """
    lo, hi = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    diag = float(np.linalg.norm(hi - lo))
    if not (isinstance(n_cells, (int, np.integer)) and n_cells >= 0):
        raise ValueError(f"n_cells must be a non-negative integer, got {n_cells!r}")
    unit = diag / np.cbrt(float(n_cells)) if n_cells > 0 else diag
    return max(float(unit), 1e-30)

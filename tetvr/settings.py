"""Method settings of the GPU renderer: one frozen value object, usable as a cache key."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Literal

import numpy as np

from tetvr.optics.model import OPTICS
from tetvr.optics.table import check_table_size
from tetvr.optics.tablesize import AUTO_BINS, DEFAULT_TOLERANCE

__all__ = ["PARITY_SETTINGS", "RenderSettings", "SORT_METHODS", "TABLE_ENCODINGS", "TABLE_DTYPES", "TABLE_WARPS"]

#: Visibility orderings (see :mod:`tetvr.order.sort`).
SORT_METHODS = ("auto", "centroid", "mpvo", "mpvonc", "xmpvo", "none")
#: How the pre-integration table is stored and looked up (see :mod:`tetvr.optics.preintegrate`).
TABLE_ENCODINGS = ("normalized", "premultiplied")
TABLE_DTYPES = ("float32", "uint8")
#: Whether the table's scalar nodes are warped to the transfer function (see tetvr.optics.tablewarp).
TABLE_WARPS = ("auto", "on", "off")
#: Interpolation of the table along its thickness axis.
TABLE_FILTERS = ("linear", "cubic")
#: Storage of the compositing target.
FRAMEBUFFERS = ("float32", "uint8")
#: The two GPU methods (see :mod:`tetvr.order.method`): projected tetrahedra or tet marching.
METHODS = ("auto", "projected", "raymarch")
#: How a ray--tet segment is integrated: a pre-integration table lookup, or exactly.
INTEGRATIONS = ("table", "exact")


@dataclasses.dataclass(frozen=True)
class RenderSettings:
    """How the projected-tetrahedra renderer trades speed for accuracy.

    Parameters
    ----------
    sort : visibility order of the cells: ``"auto"`` (default: up to 100k cells, where a
        graph sort costs little next to drawing, ``"mpvonc"`` for convex meshes and
        ``"xmpvo"`` for the others; ``"centroid"`` beyond), ``"centroid"`` (back to front
        by centroid distance; fast, wrong where large cells overlap small ones),
        ``"mpvo"`` (Williams' MPVO: exact for convex meshes), ``"mpvonc"`` (MPVO with
        Williams' non-convex heuristic; cycles are broken and counted), ``"xmpvo"``
        (MPVONC plus edges from rays through the boundary, right between separate and
        interlocking parts; see :mod:`tetvr.order.boundary`) or ``"none"`` (input order; only
        for measurements).
    table_scalar_bins : N, samples of the scalar axis of the pre-integration table, or
        ``"auto"`` (default): 256 or 512, whichever the scene needs (:mod:`tetvr.optics.tablesize`
        estimates each size's error from the transfer function and the mesh's cells).
    table_thickness_slices : K, thickness slices on the logarithmic axis, or ``"auto"``
        (default): 8, 15, 22, 29 or 43 slices, the fewest the scene needs (most scenes: 8;
        thick, strongly absorbing segments across colour changes: more), spanning
        thicknesses from d_max / span to d_max with the span the optical depth of the
        thickest segment at the largest extinction, at least 8
        (:func:`tetvr.optics.tablesize.auto_span`).
    table_log_base : ratio between consecutive thickness slices when K is given (not used
        by ``"auto"`` slices). 1.6 spans d_max / 1150 to d_max with 16 slices; measured
        against the reference it beats base 2 (a 33000x span) by up to 8 dB where colour
        changes along thick opaque segments (``bench/speed_accuracy.py``).
    table_tolerance : the RMS per-segment error (premultiplied RGBA) an ``"auto"`` table
        size aims for; the cheapest table estimated within it is used (if none is, the
        most accurate auto size; with ``table_warp="auto"`` a warped one), within a margin
        of 2.5 below it where one is, else the most accurate within it (the errors of the
        segments along a ray add up: :mod:`tetvr.optics.tablesize`). The default 5e-5 (an 8-bit step is 3.9e-3) is not
        met on CFD meshes with spiky transfer functions (see ``table_warp``).
    table_align_nodes : place the table's scalar nodes so that the transfer function's
        control points, the sharpest kinks first, fall on nodes
        (:func:`tetvr.optics.table.aligned_scalar_range`; default ``True``), rather than
        evenly over the range (``False``, the former behaviour): a control point between
        nodes is cut off by the table's linear ramp between them. Even nodes are kept
        where a ramp spans fewer than ten of them (there placement is a lottery).
    table_warp : ``"auto"`` (default), ``"on"`` or ``"off"``: a *warped* table, whose scalar
        nodes are dense where the transfer function varies and lie on its control points
        (:mod:`tetvr.optics.tablewarp`), instead of evenly spaced ones. ``"auto"`` takes one where
        the scene's estimated error (:mod:`tetvr.optics.tablesize`) says no even table meets the
        tolerance: isosurface-like transfer functions, whose narrow spikes fall between even
        nodes (on the bluntfin and pipe-flow meshes 35-64 dB even, 62-97 dB warped;
        docs/limits.md). Both GPU methods read it through a small texture that gives the
        node index and, for the "normalized" encoding, the exact optical depth per scalar
        cell (an opaque spike's -ln(1 - a) is log-singular, which no table interpolates).
        Not with ``optics="vtk"``.
    table_dtype : ``"float32"`` or ``"uint8"`` storage of the table.
    table_encoding : ``"normalized"`` stores colour/alpha and optical depth per unit
        length, so that alpha is exact in the thickness and only the (slowly varying)
        colour is interpolated across slices; ``"premultiplied"`` stores premultiplied
        RGBA as in Kraus et al. 2004 and interpolates it linearly in log-thickness.
    table_filter : ``"linear"`` or ``"cubic"`` (Catmull–Rom over four slices)
        interpolation along the log-thickness axis.
    perspective_correct : interpolate front/back scalars and thickness
        perspective-correctly (Kraus et al. 2004) rather than linearly in screen space.
    cull : drop cells outside the view, or whose scalars map to zero opacity, before
        drawing (:mod:`tetvr.order.cull`; the image is unchanged, the count is in the stats).
    framebuffer : ``"float32"`` compositing target, or ``"uint8"`` (what 8-bit
        renderers such as VTK's do; for measuring what float compositing buys).
    method : the GPU method: ``"projected"`` (projected tetrahedra: every cell classified,
        sorted and rasterised), ``"raymarch"`` (tet marching: every pixel's ray walks the
        cells it crosses, one exact segment each, in visibility order by construction; no
        sort) or ``"auto"`` (default: the one :func:`tetvr.order.method.choose` expects to be
        faster for the scene; see docs/methods.md). Both read the same table and return
        the same premultiplied image; ``sort``, ``cull`` and ``perspective_correct`` apply
        to projected tetrahedra only.
    integration : ``"table"`` (default: each segment is one lookup in the pre-integration
        table) or ``"exact"`` (tet marching only, ``optics="exact"``): no table; each
        segment is cut at the transfer function's control points it crosses and every cut
        integrated in closed form (optical depth) and by quadrature (colour), the
        reference's model in float32 (shaders/raycast_exact.glsl, shared with the volume
        ray caster). No table error at all, so any transfer function, spikes included, is
        as exact as a smooth one, and a segment cut in two (sort-last bricks) integrates to
        what the whole does; each segment costs more than a lookup (docs/methods.md).
    optics : how transfer-function opacity becomes light (:data:`tetvr.optics.model.OPTICS`):
        ``"exact"`` (``tau = -ln(1 - a)/u``, the default), ``"linear"`` (``tau = a/u``, the
        convention of VTK's unstructured-grid mappers, integrated exactly) or ``"vtk"``
        (``tau = a/u`` and the mean of a segment's end colours, VTK's projected-tetrahedra
        fragment formula). On the GPU ``"vtk"`` is VTK parity: projected tetrahedra drawn with
        VTK's own steps (colours classified at the vertices in 8 bits, its thick vertex, its
        perspective thickness table, screen-linear interpolation, its drawing order with
        ``sort="auto"``; :mod:`tetvr.gl.vtkpt`), so the table settings and
        ``perspective_correct`` do not apply to it; the CPU reference computes the formula on
        exact geometry. ``tetvr.settings.PARITY_SETTINGS``; see docs/paraview.md.

    Examples
    --------
    >>> RenderSettings(table_scalar_bins=128).table_scalar_bins
    128
    >>> RenderSettings().table_thickness_slices
    'auto'
    """

    sort: Literal["auto", "centroid", "mpvo", "mpvonc", "xmpvo", "none"] = "auto"
    table_scalar_bins: int | Literal["auto"] = "auto"
    table_thickness_slices: int | Literal["auto"] = "auto"
    table_log_base: float = 1.6
    table_tolerance: float = DEFAULT_TOLERANCE
    table_align_nodes: bool = True
    table_warp: Literal["auto", "on", "off"] = "auto"
    table_dtype: Literal["float32", "uint8"] = "float32"
    table_encoding: Literal["normalized", "premultiplied"] = "normalized"
    table_filter: Literal["linear", "cubic"] = "linear"
    perspective_correct: bool = True
    framebuffer: Literal["float32", "uint8"] = "float32"
    cull: bool = False
    optics: Literal["exact", "linear", "vtk"] = "exact"
    method: Literal["auto", "projected", "raymarch"] = "auto"
    integration: Literal["table", "exact"] = "table"

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        if self.integration not in INTEGRATIONS:
            raise ValueError(f"integration must be one of {INTEGRATIONS}, got {self.integration!r}")
        if self.integration == "exact":
            if self.method == "projected":
                raise ValueError("integration='exact' is tet marching's (method='raymarch' or 'auto'); projected "
                                 "tetrahedra integrate through the table")
            if self.optics != "exact":
                raise ValueError(f"integration='exact' integrates optics='exact' (tau = -ln(1 - a)/u), got "
                                 f"optics={self.optics!r}")
        if self.sort not in SORT_METHODS:
            raise ValueError(f"sort must be one of {SORT_METHODS}, got {self.sort!r}")
        if self.table_encoding not in TABLE_ENCODINGS:
            raise ValueError(f"table_encoding must be one of {TABLE_ENCODINGS}, got {self.table_encoding!r}")
        if self.table_filter not in TABLE_FILTERS:
            raise ValueError(f"table_filter must be one of {TABLE_FILTERS}, got {self.table_filter!r}")
        if self.framebuffer not in FRAMEBUFFERS:
            raise ValueError(f"framebuffer must be one of {FRAMEBUFFERS}, got {self.framebuffer!r}")
        if self.optics not in OPTICS:
            raise ValueError(f"optics must be one of {OPTICS}, got {self.optics!r}")
        if self.table_warp not in TABLE_WARPS:
            raise ValueError(f"table_warp must be one of {TABLE_WARPS}, got {self.table_warp!r}")
        if self.table_warp == "on" and self.optics == "vtk":
            raise ValueError("table_warp='on' needs the optical depth of a segment, which optics='vtk' (the mean of its "
                             "end extinctions) does not use; use table_warp='auto' or 'off' with it")
        if self.table_dtype not in TABLE_DTYPES:
            raise ValueError(f"table_dtype must be one of {TABLE_DTYPES}, got {self.table_dtype!r}")
        for name, lo, hi in (("table_scalar_bins", 2, 2048), ("table_thickness_slices", 1, 256)):
            v = getattr(self, name)
            if isinstance(v, str) and v == "auto":
                continue
            if not isinstance(v, (int, np.integer)) or isinstance(v, (bool, np.bool_)) or not lo <= v <= hi:
                raise ValueError(f"{name} must be \"auto\" or an integer in [{lo}, {hi}], got {v!r}")
            object.__setattr__(self, name, int(v))
        tol = self.table_tolerance
        if (isinstance(tol, (str, bytes, bool, np.bool_)) or not isinstance(tol, (int, float, np.number))
                or not math.isfinite(float(tol)) or not 0 < float(tol) <= 1):
            raise ValueError(f"table_tolerance must be a number in (0, 1], got {tol!r}")
        object.__setattr__(self, "table_tolerance", float(tol))
        if not isinstance(self.cull, (bool, np.bool_)):
            raise ValueError(f"cull must be True or False, got {self.cull!r}")
        if not isinstance(self.table_align_nodes, (bool, np.bool_)):
            raise ValueError(f"table_align_nodes must be True or False, got {self.table_align_nodes!r}")
        object.__setattr__(self, "table_align_nodes", bool(self.table_align_nodes))
        if not isinstance(self.perspective_correct, (bool, np.bool_)):
            raise ValueError(f"perspective_correct must be True or False, got {self.perspective_correct!r}")
        if isinstance(self.table_log_base, (str, bytes)):
            raise ValueError(f"table_log_base must be a number, got {self.table_log_base!r}")
        if not (1.0 < float(self.table_log_base) <= 100.0):
            raise ValueError(f"table_log_base must be in (1, 100], got {self.table_log_base!r}")
        object.__setattr__(self, "table_log_base", float(self.table_log_base))
        object.__setattr__(self, "perspective_correct", bool(self.perspective_correct))
        # Memory and arithmetic, before any frame: the build's peak memory of explicit sizes,
        # and the span of an explicit thickness axis (base ** (K - 1) overflows past ~1e308).
        # An "auto" axis takes sizes whose tables stay small (see tetvr.optics.tablesize).
        n, k = self.table_scalar_bins, self.table_thickness_slices
        if k != "auto":
            check_table_size(n if n != "auto" else min(AUTO_BINS), int(k), self.table_log_base,
                             names=("table_scalar_bins", "table_thickness_slices", "table_log_base"))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "RenderSettings":
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - names
        if unknown:
            raise ValueError(f"unknown settings keys {sorted(unknown)}; expected some of {sorted(names)}")
        return cls(**data)


#: tetvr's VTK parity: ``optics="vtk"`` on the GPU draws VTK's projected tetrahedra with
#: VTK's own steps (:mod:`tetvr.gl.vtkpt`: 8-bit vertex colours, its thick vertex and
#: class-2 opacity, its perspective thickness table, screen-linear interpolation, its
#: drawing order). VTK composites in a float target (``UseFloatingPointFrameBuffer``, on by
#: default) and rounds to 8 bits once, when it copies to the window: so the target stays
#: float here and :func:`tetvr.apps.vtkcompare.compare` rounds the final image
#: (:func:`~tetvr.apps.vtkcompare.quantize8`). What remains
#: different is listed in docs/paraview.md ("What parity does not reproduce").
PARITY_SETTINGS = RenderSettings(optics="vtk", perspective_correct=False)

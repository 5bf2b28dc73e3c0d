"""Ray casting of image volumes on the CPU: the reference the GPU ray caster is measured against.

About this technique
--------------------
Direct volume rendering by ray casting (Levoy 1988, "Display of surfaces from volume
data"), with the emission–absorption model of :mod:`tetvr.optics.model` (Max 1995). The GPU
ray caster (:mod:`tetvr.gl.raycaster`) marches each pixel ray in fixed world steps and
looks each step up in a pre-integrated table (Engel, Kraus & Ertl 2001); this module
computes the same image the slow, exact way:

1. The pixel rays are :meth:`tetvr.core.camera.Camera.rays` (ray parameter ``t`` = eye
   depth). Each is clipped to the volume's box (the slab method in index space, so the
   box may be oriented by the direction matrix), to the camera's clipping range, to an
   optional world clip box, and to the caller's per-pixel limits ``[t_start, t_end]``.
2. The remaining interval is cut into pieces no longer than ``fine_step`` (world units;
   default 1/8 of the smallest voxel spacing), and also where the ray crosses a
   voxel-index plane, so that every piece lies inside one voxel cell; the volume is
   sampled at the pieces' ends, trilinearly (or with the cubic B-spline, as the settings say).
3. The scalar is taken as linear on each piece; every piece is cut at the transfer
   function's breakpoints and integrated exactly by
   :func:`tetvr.reference.integrate.integrate_segments` (closed-form optical depth, colour to
   ~1e-7), then composited front to back.

What remains is the linearisation of the trilinear field (a smooth cubic along a ray
inside one cell) over one fine piece: ``|ds| <= h^2/8 max|s''|`` with ``h`` = 1/8 voxel
(without the cuts at the voxel planes a piece across a cell face errs by ``h/4`` times
the jump in slope there, first order in ``h``). The other modes use the same samples:
``mip`` the largest (exact where the ray passes through a voxel-centred peak: it crosses
the voxel's three planes there), ``xray`` the length-weighted mean (trapezoid rule), ``isosurface``
the first sign change of ``s - iso``, refined by bisection on the trilinear field and
shaded with Blinn–Phong from central-difference gradients, as the shader does.

Early ray termination (an error bound, ``termination_tolerance``; 0: the full integral)
stops a ray here by the GPU's rule. Jitter, a GPU acceleration, is ignored.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.checks import check_instances
from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.core.image import check_memory, image_size
from tetvr.optics.table import check_table_size, check_unit_distance
from tetvr.reference.integrate import composite, integrate_segments
from tetvr.optics.raycast_size import AUTO_BINS, auto_bins, auto_integration, auto_step
from tetvr.optics.transfer import TransferFunction
from tetvr.volume.volume import Volume

__all__ = [
    "RAYCAST_MODES",
    "TERMINATION_TOLERANCE",
    "INTERPOLATIONS",
    "INTEGRATIONS",
    "RaycastSettings",
    "normalize_ray_limits",
    "volume_ray_intervals",
    "render_volume_reference",
    "shade_blinn_phong",
]

#: Rendering modes of the volume ray caster (the GPU maps each to a shader define).
RAYCAST_MODES = ("emission_absorption", "mip", "xray", "isosurface")

#: How the volume is reconstructed between voxels.
INTERPOLATIONS = ("linear", "cubic")

#: How the GPU integrates emission-absorption between two samples: ``"exact"`` cuts the
#: piece at the transfer function's control points and integrates each cut in closed form
#: (no table), ``"table"`` looks it up in a pre-integration table.
INTEGRATIONS = ("auto", "exact", "table")

#: Default ``termination_tolerance``: 1/8 of half an 8-bit step (docs/limits.md: measured).
TERMINATION_TOLERANCE = 2.0**-12

#: Bisection steps that refine an isosurface hit inside the step that brackets it.
ISO_REFINE_STEPS = 8
#: Bytes per pixel :func:`render_volume_reference` holds whatever the volume: the rays
#: and their intervals in world and index space, the slab test's temporaries and the
#: float64 and float32 images (measured: 162).
_BYTES_PER_PIXEL = 176

Float = NDArray[np.float64]


def _float(value: Any, name: str, lo: float, hi: float, *, lo_open: bool = False) -> float:
    v = float(value)
    if not math.isfinite(v) or v > hi or v < lo or (lo_open and v == lo):
        bracket = "(" if lo_open else "["
        raise ValueError(f"{name} must be in {bracket}{lo}, {hi}], got {value!r}")
    return v


@dataclasses.dataclass(frozen=True)
class RaycastSettings:
    """How the volume ray caster samples, integrates and shades.

    Parameters
    ----------
    mode : ``"emission_absorption"`` (default; pre-integrated, the tets' optical model),
        ``"mip"`` (maximum intensity projection), ``"xray"`` (mean intensity along the
        ray) or ``"isosurface"`` (first hit of ``iso_value``, Blinn–Phong shaded).
        ``mip`` and ``xray`` map the scalar they find through the transfer function:
        premultiplied ``(c a, a)``.
    step : distance between regular samples in world units (the ray is also sampled
        where it crosses a voxel-index plane), or ``"auto"`` (default; ``None`` means the
        same): sized from the smallest voxel spacing and, for emission-absorption, the
        transfer function's opacity (:func:`tetvr.optics.raycast_size.auto_step`).
    termination_tolerance : early ray termination as an error bound: an emission-absorption
        ray (GPU and reference alike) stops once ``1 - alpha`` is at most this. Colours are
        at most 1, so the rest of the ray could add at most ``1 - alpha`` to any channel: the
        stop darkens a pixel by at most this. Default 2**-12; 0: the full integral.
    termination : compatibility alias (old saved settings): ``termination=a`` sets the
        tolerance ``1 - a``; not stored, read back as ``1 - termination_tolerance``.
    jitter : offset every ray's first sample by a random fraction of a step (seeded by
        ``seed`` and the pixel, so images are reproducible); trades wood-grain artefacts
        for noise. The integrated interval is unchanged.
    seed : seed of the jitter.
    iso_value : the isosurface's scalar; ``None``: the middle of the data range.
    iso_opacity : alpha of the isosurface.
    shading : Blinn–Phong ``(ambient, diffuse, specular, shininess)``, headlight.
    clip_box : ``((xmin, ymin, zmin), (xmax, ymax, zmax))`` in world units, or ``None``.
    interpolation : ``"linear"`` (trilinear, default) or ``"cubic"`` (cubic B-spline
        from 8 linear fetches, Sigg & Hadwiger 2005: smoother, ~8x the texture reads).
    integration : how emission-absorption integrates a piece between two samples:
        ``"table"`` looks it up in a pre-integration table (Engel et al. 2001; one texture
        read per piece, but a control point between two table nodes is smoothed);
        ``"exact"`` cuts it where the scalar crosses a transfer-function control point
        and integrates each cut in closed form and by quadrature (the model of
        :mod:`tetvr.optics.model`, no table, exact for any transfer function however spiky;
        2-5x the table's frame time on llvmpipe); ``"auto"`` (default): the table where
        its estimated error is within tolerance, else exact
        (:func:`tetvr.optics.raycast_size.auto_integration`).
    table_scalar_bins, table_thickness_slices : size of the pre-integration table (its
        top slice is the step; thinner slices serve the shorter pieces). Bins
        ``"auto"`` (default): 256 or 512 as the transfer function and the data need
        (:func:`tetvr.optics.raycast_size.auto_bins`); the nodes are aligned on the transfer
        function's control points where that pays.
    tf_samples : not used any more (every mode evaluates the transfer function exactly at
        its control points); kept so that saved settings load.

    Examples
    --------
    >>> RaycastSettings(mode="mip", step=0.25).mode
    'mip'
    """

    mode: Literal["emission_absorption", "mip", "xray", "isosurface"] = "emission_absorption"
    step: float | Literal["auto"] | None = "auto"
    termination_tolerance: float = TERMINATION_TOLERANCE
    termination: dataclasses.InitVar[float | None] = None
    jitter: bool = False
    seed: int = 0
    iso_value: float | None = None
    iso_opacity: float = 1.0
    shading: tuple[float, float, float, float] = (0.2, 0.7, 0.3, 32.0)
    clip_box: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    interpolation: Literal["linear", "cubic"] = "linear"
    integration: Literal["auto", "exact", "table"] = "auto"
    table_scalar_bins: int | Literal["auto"] = "auto"
    table_thickness_slices: int = 8
    tf_samples: int = 1024

    def __post_init__(self, termination: float | None) -> None:
        if self.mode not in RAYCAST_MODES:
            raise ValueError(f"mode must be one of {RAYCAST_MODES}, got {self.mode!r}")
        if self.step is None or isinstance(self.step, str):
            if self.step not in (None, "auto"):
                raise ValueError(f"step must be \"auto\" or a positive number of world units, got {self.step!r}")
            object.__setattr__(self, "step", "auto")
        else:
            step = float(self.step)
            if not (math.isfinite(step) and step > 0):
                raise ValueError(f"step must be a positive number of world units, got {self.step!r}")
            object.__setattr__(self, "step", step)
        tolerance = float(self.termination_tolerance)
        if termination is not None:  # 15 digits: 0.998 is the tolerance 0.002 (one cache key), not 0.0020...018
            tolerance = float(f"{1.0 - _float(termination, 'termination', 0.0, 1.0, lo_open=True):.15g}")
        if not 0.0 <= tolerance < 1.0:  # also NaN; at 1 every ray would stop after its first piece
            raise ValueError(f"termination_tolerance must be in [0, 1), got {self.termination_tolerance!r}")
        object.__setattr__(self, "termination_tolerance", tolerance)
        object.__setattr__(self, "termination", 1.0 - tolerance)  # the read-only alias, not a field
        object.__setattr__(self, "jitter", bool(self.jitter))
        if not isinstance(self.seed, (int, np.integer)) or isinstance(self.seed, bool) or not 0 <= int(self.seed) < 2**32:
            raise ValueError(f"seed must be an integer in [0, 2**32), got {self.seed!r}")
        object.__setattr__(self, "seed", int(self.seed))
        if self.iso_value is not None:
            iso = float(self.iso_value)
            if not math.isfinite(iso):
                raise ValueError(f"iso_value must be finite, got {self.iso_value!r}")
            object.__setattr__(self, "iso_value", iso)
        object.__setattr__(self, "iso_opacity", _float(self.iso_opacity, "iso_opacity", 0.0, 1.0))
        sh = tuple(float(v) for v in self.shading)
        if len(sh) != 4 or not all(math.isfinite(v) and v >= 0 for v in sh):
            raise ValueError(f"shading must be (ambient, diffuse, specular, shininess) >= 0, got {self.shading!r}")
        object.__setattr__(self, "shading", sh)
        if self.clip_box is not None:
            box = np.asarray(self.clip_box, dtype=np.float64)
            if box.shape != (2, 3) or not np.all(np.isfinite(box)) or np.any(box[0] > box[1]):
                raise ValueError(f"clip_box must be ((xmin, ymin, zmin), (xmax, ymax, zmax)) with min <= max, "
                                 f"got {self.clip_box!r}")
            object.__setattr__(self, "clip_box", tuple(tuple(float(v) for v in row) for row in box))
        if self.interpolation not in INTERPOLATIONS:
            raise ValueError(f"interpolation must be one of {INTERPOLATIONS}, got {self.interpolation!r}")
        if self.integration not in INTEGRATIONS:
            raise ValueError(f"integration must be one of {INTEGRATIONS}, got {self.integration!r}")
        for name, lo, hi in (("table_scalar_bins", 2, 4096), ("table_thickness_slices", 1, 64), ("tf_samples", 2, 16384)):
            v = getattr(self, name)
            if name == "table_scalar_bins" and v == "auto":
                continue
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or not lo <= v <= hi:
                auto = '"auto" or ' if name == "table_scalar_bins" else ""
                raise ValueError(f"{name} must be {auto}an integer in [{lo}, {hi}], got {v!r}")
            object.__setattr__(self, name, int(v))
        # The ray caster's table has log base 2 (Raycaster.table): 2 ** 63 stays within the span.
        bins = max(AUTO_BINS) if self.table_scalar_bins == "auto" else self.table_scalar_bins
        check_table_size(bins, self.table_thickness_slices, 2.0,
                         names=("table_scalar_bins", "table_thickness_slices", "log_base"))

    def step_for(self, volume: Volume, tf: TransferFunction) -> float:
        """The world step used for ``volume`` and ``tf`` (``tf`` sizes an "auto" step)."""
        if self.step is None or self.step == "auto":  # __post_init__ made None "auto"
            return auto_step(volume, tf, self.mode)
        return float(self.step)

    def bins_for(self, volume: Volume, tf: TransferFunction) -> int:
        """The table's scalar bins for ``volume`` and ``tf``."""
        return int(self.table_scalar_bins) if self.table_scalar_bins != "auto" else auto_bins(volume, tf)

    def integration_for(self, volume: Volume, tf: TransferFunction) -> str:
        """``"table"`` or ``"exact"``: how emission-absorption is integrated for ``volume`` and ``tf``."""
        if self.integration != "auto":
            return self.integration
        return auto_integration(volume, tf, self.table_scalar_bins)

    def iso_for(self, volume: Volume) -> float:
        """The isosurface value used for ``volume``."""
        if self.iso_value is not None:
            return float(self.iso_value)
        lo, hi = volume.scalar_range
        return 0.5 * (lo + hi)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "RaycastSettings":
        names = {f.name for f in dataclasses.fields(cls)} | {"termination"}  # the alias of old files
        unknown = set(data) - names
        if unknown:
            raise ValueError(f"unknown ray-cast settings keys {sorted(unknown)}; expected some of {sorted(names)}")
        return cls(**data)  # __post_init__ turns JSON lists into tuples


def normalize_ray_limits(t_start: ArrayLike | None, t_end: ArrayLike | None, size: tuple[int, int]) -> tuple[Float, Float]:
    """Per-pixel ray limits as ``(H, W)`` float64 arrays with ``-inf``/``inf`` for "unlimited".

    ``None`` or NaN entries mean unlimited. The caller's arrays are not modified.
    """
    return _ray_limits(t_start, t_end, *image_size(size), size)


def _ray_limits(t_start: ArrayLike | None, t_end: ArrayLike | None, width: int, height: int,
                size: Any) -> tuple[Float, Float]:
    """:func:`normalize_ray_limits` for a checked size (``size`` as given, for messages)."""
    out = []
    for name, arr, free in (("t_start", t_start, -np.inf), ("t_end", t_end, np.inf)):
        if arr is None:
            out.append(np.full((height, width), free))
            continue
        a = np.asarray(arr, dtype=np.float64)
        if a.shape != (height, width):
            raise ValueError(f"{name} must have shape (H, W) = {(height, width)} to match size {size!r}, got {a.shape}")
        out.append(np.where(np.isnan(a), free, a))
    return out[0], out[1]


def _slab(o: Float, d: Float, lo: Float, hi: Float) -> tuple[Float, Float]:
    """Parameter interval of rays ``o + t d`` (n, 3) inside the box [lo, hi] (slab method)."""
    t0 = np.full(o.shape[0], -np.inf)
    t1 = np.full(o.shape[0], np.inf)
    for a in range(3):
        da = d[:, a]
        flat = da == 0
        with np.errstate(divide="ignore", invalid="ignore"):
            ta = (lo[a] - o[:, a]) / da
            tb = (hi[a] - o[:, a]) / da
        near = np.where(flat, -np.inf, np.minimum(ta, tb))
        far = np.where(flat, np.inf, np.maximum(ta, tb))
        outside = flat & ((o[:, a] < lo[a]) | (o[:, a] > hi[a]))
        t0 = np.maximum(t0, np.where(outside, np.inf, near))
        t1 = np.minimum(t1, np.where(outside, -np.inf, far))
    return t0, t1


@dataclasses.dataclass(frozen=True)
class RayIntervals:
    """Pixel rays and the part of each that is integrated (row-major, row 0 at the top).

    ``origins``/``directions`` are world space with ``t`` = eye depth; ``t0 < t1`` where a
    ray has something to integrate (else ``t0 >= t1``); ``*_index`` are the same rays in
    the volume's index space.
    """

    origins: Float
    directions: Float
    origins_index: Float
    directions_index: Float
    t0: Float
    t1: Float

    @property
    def hit(self) -> NDArray[np.bool_]:
        return self.t1 > self.t0

    @property
    def world_per_t(self) -> Float:
        return np.linalg.norm(self.directions, axis=1)


def volume_ray_intervals(
    volume: Volume,
    camera: Camera,
    size: tuple[int, int],
    *,
    clip_box: Any = None,
    t_start: ArrayLike | None = None,
    t_end: ArrayLike | None = None,
) -> RayIntervals:
    """Where each pixel ray is integrated: ``[max(entry, near, t_start), min(exit, far, t_end)]``,
    further clipped to ``clip_box`` (world) if given."""
    return _ray_intervals(volume, camera, *image_size(size), clip_box=clip_box, t_start=t_start, t_end=t_end)


def _ray_intervals(volume: Volume, camera: Camera, width: int, height: int, *, clip_box: Any,
                   t_start: ArrayLike | None, t_end: ArrayLike | None) -> RayIntervals:
    """:func:`volume_ray_intervals` for a checked size."""
    o, d = camera.rays(width, height)
    m = volume.world_to_index
    o_idx = o @ m[:3, :3].T + m[:3, 3]
    d_idx = d @ m[:3, :3].T
    hi = np.asarray(volume.dims, dtype=np.float64) - 1.0
    t0, t1 = _slab(o_idx, d_idx, np.zeros(3), hi)
    near, far = resolve_clipping_range(camera, volume.bounds).near_far()
    t0 = np.maximum(t0, near)
    t1 = np.minimum(t1, far)
    if clip_box is not None:
        box = np.asarray(clip_box, dtype=np.float64)
        c0, c1 = _slab(o, d, box[0], box[1])
        t0, t1 = np.maximum(t0, c0), np.minimum(t1, c1)
    start, end = _ray_limits(t_start, t_end, width, height, (width, height))
    t0 = np.maximum(t0, start.reshape(-1))
    t1 = np.minimum(t1, end.reshape(-1))
    return RayIntervals(o, d, o_idx, d_idx, t0, t1)


def shade_blinn_phong(color: Float, normal: Float, view: Float, shading: tuple[float, float, float, float]) -> Float:
    """Two-sided Blinn–Phong with a headlight (light = view direction, so H = V).

    ``color`` (n, 3), unit ``normal`` and ``view`` (n, 3) (towards the eye). Returns (n, 3) in [0, 1].
    """
    ka, kd, ks, shininess = shading
    ndv = np.abs(np.sum(normal * view, axis=1))
    out = color * (ka + kd * ndv)[:, None] + (ks * ndv**shininess)[:, None]
    return np.clip(out, 0.0, 1.0)


def render_volume_reference(
    volume: Volume,
    camera: Camera,
    tf: TransferFunction,
    size: tuple[int, int],
    *,
    settings: RaycastSettings | None = None,
    t_start: ArrayLike | None = None,
    t_end: ArrayLike | None = None,
    fine_step: float | None = None,
    budget: int = 1 << 20,
) -> NDArray[np.float32]:
    """Render a volume on the CPU, as exactly as is practical.

    Parameters
    ----------
    volume, camera, tf : the scene.
    size : ``(width, height)`` in pixels.
    settings : the mode, iso value, shading, clip box and termination tolerance (0: the
        full integral); step, jitter and table sizes are GPU settings and are ignored.
    t_start, t_end : optional ``(H, W)`` eye-depth limits per pixel (NaN/inf: none).
    fine_step : length of the pieces in world units; default 1/8 of the smallest spacing.
    budget : samples processed at once (bounds memory).

    Returns
    -------
    (H, W, 4) float32 premultiplied RGBA, row 0 at the top.

    Examples
    --------
    >>> vol = Volume.from_array(np.linspace(0, 1, 8)[None, None, :].repeat(8, 0).repeat(8, 1))
    >>> tf = TransferFunction.preset("grayscale", (0, 1), opacity=0.5, unit_distance=7.0)
    >>> cam = Camera(position=(-10, 3.5, 3.5), focal_point=(0, 3.5, 3.5), view_up=(0, 0, 1),
    ...              parallel_projection=True, parallel_scale=1.0)
    >>> float(render_volume_reference(vol, cam, tf, (1, 1))[0, 0, 3]).__round__(6)  # a 7-unit slab at a = 0.5
    0.5
    """
    check_instances(volume=(volume, Volume), camera=(camera, Camera), tf=(tf, TransferFunction))
    if settings is not None and not isinstance(settings, RaycastSettings):
        raise TypeError(f"settings must be a RaycastSettings or None, got {type(settings).__name__}")
    s = settings if settings is not None else RaycastSettings()
    width, height = image_size(size)
    check_unit_distance(tf.unit_distance, "the transfer function's unit_distance")
    check_memory(width * height * _BYTES_PER_PIXEL, f"a {width}x{height} volume reference image")
    fine = float(fine_step) if fine_step is not None else float(volume.spacing.min()) / 8.0
    if not (math.isfinite(fine) and fine > 0):
        raise ValueError(f"fine_step must be positive, got {fine_step!r}")
    rays = _ray_intervals(volume, camera, width, height, clip_box=s.clip_box, t_start=t_start, t_end=t_end)
    n_pix = width * height
    out = np.zeros((n_pix, 4))
    idx = np.nonzero(rays.hit)[0]
    if idx.size:
        wpt = rays.world_per_t
        n_piece = np.maximum(np.ceil((rays.t1[idx] - rays.t0[idx]) * wpt[idx] / fine - 1e-9), 1).astype(np.int64)
        n_cross = _plane_crossings(rays, idx)[1].sum(axis=1)
        ends = np.cumsum(n_piece + n_cross + 1)
        start = 0
        while start < idx.size:
            base = ends[start - 1] if start else 0
            stop = max(int(np.searchsorted(ends, base + budget, side="right")), start + 1)
            rows = idx[start:stop]
            out[rows] = _march(volume, tf, s, rays, rows, n_piece[start:stop], wpt)
            start = stop
    return out.reshape(height, width, 4).astype(np.float32)


class _Samples(NamedTuple):
    """The fine samples of a batch of rays, and the pieces between them (in ray order)."""

    rows: NDArray[np.int64]  # pixel of each ray of the batch
    t: Float  # sample positions (eye depth), ray after ray
    scalar: Float  # the field there
    first: NDArray[np.int64]  # index of each ray's first sample
    piece: NDArray[np.int64]  # index of the sample at the front of each piece
    piece_ray: NDArray[np.int64]  # ray (in the batch) of each piece
    length: Float  # world length of each piece


def _plane_crossings(rays: RayIntervals, rows: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Per ray of ``rows`` and index axis: the first integer strictly past the entry in
    the ray's direction along that axis, and how many integers lie strictly between the
    entry and the exit ((n, 3) each)."""
    o, d = rays.origins_index[rows], rays.directions_index[rows]
    x0 = o + rays.t0[rows][:, None] * d
    x1 = o + rays.t1[rows][:, None] * d
    lo, hi = np.minimum(x0, x1), np.maximum(x0, x1)
    first = np.floor(lo).astype(np.int64) + 1
    count = np.maximum(np.ceil(hi).astype(np.int64) - first, 0)
    return first, count


def _march(volume: Volume, tf: TransferFunction, s: RaycastSettings, rays: RayIntervals, rows: NDArray[np.int64],
           n_piece: NDArray[np.int64], wpt: Float) -> Float:
    """The pixels ``rows``: sample finely, then integrate or reduce as the mode says.

    The samples are the ``n_piece + 1`` evenly spaced ones and every point where the ray
    crosses a voxel-index plane, so that every piece lies inside one voxel cell (where
    the trilinear field is smooth) and a maximum at a voxel the ray passes is sampled.
    """
    n_rays = rows.shape[0]
    t0, t1 = rays.t0[rows], rays.t1[rows]
    o_idx, d_idx = rays.origins_index[rows], rays.directions_index[rows]
    ray_even = np.repeat(np.arange(n_rays), n_piece + 1)
    k = np.arange(ray_even.shape[0]) - np.repeat(np.cumsum(n_piece + 1) - (n_piece + 1), n_piece + 1)
    t_even = t0[ray_even] + (t1 - t0)[ray_even] * (k / n_piece[ray_even])
    t_even[np.cumsum(n_piece + 1) - 1] = t1  # the exact exit
    rays_t, ts = [ray_even], [t_even]
    plane0, count = _plane_crossings(rays, rows)
    for a in range(3):
        r = np.repeat(np.arange(n_rays), count[:, a])
        if r.size == 0:
            continue
        m = np.arange(r.shape[0]) - np.repeat(np.cumsum(count[:, a]) - count[:, a], count[:, a])
        plane = (plane0[r, a] + m).astype(np.float64)
        tc = (plane - o_idx[r, a]) / d_idx[r, a]
        rays_t.append(r)
        ts.append(np.clip(tc, t0[r], t1[r]))
    ray, t = np.concatenate(rays_t), np.concatenate(ts)
    order = np.lexsort((t, ray))
    ray, t = ray[order], t[order]
    n_samp = np.bincount(ray, minlength=n_rays)
    first = np.cumsum(n_samp) - n_samp
    n_piece = n_samp - 1
    scal = volume.sample_index(o_idx[ray] + t[:, None] * d_idx[ray], interpolation=s.interpolation)
    starts_piece = np.ones(ray.shape[0], dtype=bool)
    starts_piece[first + n_piece] = False  # the last sample of a ray starts no piece
    piece = np.nonzero(starts_piece)[0]
    length = (t[piece + 1] - t[piece]) * wpt[rows][ray[piece]]
    samples = _Samples(rows, t, scal, first, piece, ray[piece], length)
    return _MODES[s.mode](volume, tf, s, rays, samples)


def _emission_absorption(volume: Volume, tf: TransferFunction, s: RaycastSettings, rays: RayIntervals,
                         x: _Samples) -> Float:
    rgb, theta = integrate_segments(x.scalar[x.piece], x.scalar[x.piece + 1], x.length, tf)
    keep: slice | NDArray[np.bool_] = slice(None)
    if s.termination_tolerance > 0:  # raycast.frag's stop: a piece counts while the transmittance before it > tol
        stop = -math.log(s.termination_tolerance)
        capped = np.minimum(theta, stop + 1.0)  # changes no answer; keeps the sums finite and small
        before = np.cumsum(capped) - capped  # pieces are in ray order, front to back
        first = np.diff(x.piece_ray, prepend=-1) != 0
        keep = before - before[first][np.cumsum(first) - 1] < stop
    return composite(x.piece_ray[keep], x.t[x.piece][keep], rgb[keep], theta[keep], x.rows.shape[0])


def _classified(tf: TransferFunction, value: Float) -> Float:
    c, a = tf.evaluate(value)
    return np.concatenate([c * a[:, None], a[:, None]], axis=1)


def _mip(volume: Volume, tf: TransferFunction, s: RaycastSettings, rays: RayIntervals, x: _Samples) -> Float:
    return _classified(tf, np.maximum.reduceat(x.scalar, x.first))


def _xray(volume: Volume, tf: TransferFunction, s: RaycastSettings, rays: RayIntervals, x: _Samples) -> Float:
    n = x.rows.shape[0]
    mean_s = 0.5 * (x.scalar[x.piece] + x.scalar[x.piece + 1])
    total = np.bincount(x.piece_ray, weights=x.length, minlength=n)
    acc = np.bincount(x.piece_ray, weights=mean_s * x.length, minlength=n)
    return _classified(tf, np.where(total > 0, acc / np.where(total > 0, total, 1.0), x.scalar[x.first]))


def _isosurface(volume: Volume, tf: TransferFunction, s: RaycastSettings, rays: RayIntervals, x: _Samples) -> Float:
    iso = s.iso_for(volume)
    out = np.zeros((x.rows.shape[0], 4))
    crosses = (x.scalar[x.piece] < iso) != (x.scalar[x.piece + 1] < iso)
    cand = x.piece[crosses]
    if cand.size == 0:
        return out
    cand_ray = x.piece_ray[crosses]
    # The first crossing of each ray: candidates are in ray order.
    keep = np.r_[True, cand_ray[1:] != cand_ray[:-1]]
    cand, hit_ray = cand[keep], cand_ray[keep]
    o_idx = rays.origins_index[x.rows][hit_ray]
    d_idx = rays.directions_index[x.rows][hit_ray]
    t_hit = _refine(volume, o_idx, d_idx, x.t[cand], x.t[cand + 1], x.scalar[cand], x.scalar[cand + 1], iso,
                    s.interpolation)
    p = o_idx + t_hit[:, None] * d_idx
    normal = _normals(volume, p, s.interpolation)
    view = -rays.directions[x.rows][hit_ray]
    view /= np.linalg.norm(view, axis=1)[:, None]
    color, _ = tf.evaluate(np.full(hit_ray.shape[0], iso))
    shaded = shade_blinn_phong(color, normal, view, s.shading)
    out[hit_ray, :3] = shaded * s.iso_opacity
    out[hit_ray, 3] = s.iso_opacity
    return out


#: Mode -> what the reference does with a batch of fine samples (the GPU's table is
#: :data:`tetvr.gl.raycaster.MODES`).
_MODES: dict[str, Callable[[Volume, TransferFunction, RaycastSettings, RayIntervals, _Samples], Float]] = {
    "emission_absorption": _emission_absorption,
    "mip": _mip,
    "xray": _xray,
    "isosurface": _isosurface,
}
assert tuple(_MODES) == RAYCAST_MODES


def _refine(volume: Volume, o_idx: Float, d_idx: Float, ta: Float, tb: Float, sa: Float, sb: Float, iso: float,
            interpolation: str) -> Float:
    """Bisection on the reconstructed field inside a bracketing step, then a final linear
    interpolation (the shader does the same)."""
    below_a = sa < iso
    for _ in range(ISO_REFINE_STEPS):
        tm = 0.5 * (ta + tb)
        sm = volume.sample_index(o_idx + tm[:, None] * d_idx, interpolation=interpolation)
        same = (sm < iso) == below_a
        ta, sa = np.where(same, tm, ta), np.where(same, sm, sa)
        tb, sb = np.where(same, tb, tm), np.where(same, sb, sm)
    ds = sb - sa
    f = np.where(ds != 0, (iso - sa) / np.where(ds != 0, ds, 1.0), 0.5)
    return ta + np.clip(f, 0.0, 1.0) * (tb - ta)


def _normals(volume: Volume, p_idx: Float, interpolation: str) -> Float:
    """Unit world-space gradients by central differences of one voxel in index space."""
    g_idx = np.empty_like(p_idx)
    for a in range(3):
        e = np.zeros(3)
        e[a] = 1.0
        g_idx[:, a] = 0.5 * (volume.sample_index(p_idx + e, interpolation=interpolation)
                             - volume.sample_index(p_idx - e, interpolation=interpolation))
    # d s / d x_world = A^-T d s / d ijk, A = direction * spacing.
    g = g_idx @ volume.world_to_index[:3, :3]
    norm = np.linalg.norm(g, axis=1)
    return np.where(norm[:, None] > 0, g / np.where(norm > 0, norm, 1.0)[:, None], 0.0)

"""Clip planes and boxes for meshes: the part of each ray that is kept.

About this technique
--------------------
A clip is an intersection of half-spaces (a plane keeps one side; a box is six planes),
so along any ray the kept part is one interval of the ray parameter. Both GPU methods and
the CPU reference cut each ray--tet segment to that interval per pixel, exactly as they
cut it to the camera's clipping range: a tet the clip crosses renders the part of it that
is kept, and the field at the cut is the tet's linear field there. Nothing is re-meshed,
so a clip costs no preprocessing and moves freely from frame to frame (VTK's
``vtkVolumeMapper`` clipping planes and ParaView's volume "Clip" behave the same way; the
"Clip" *filter* instead cuts cells into new cells).

The ray parameter is eye depth ``t`` (distance along the view axis), as everywhere in
tetvr: a perspective ray is ``x_eye = t (rx, ry, -1)``, a parallel one
``x_eye = (rx, ry, 0) + t (0, 0, -1)``. :meth:`Clip.eye_planes` gives the planes in eye
space for a camera; :func:`ray_window` evaluates the interval for arrays of rays (the
reference), ``shaders/window.glsl`` the same per fragment.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.camera import Camera

__all__ = ["Clip", "MAX_CLIP_PLANES", "check_clip", "ray_window"]

#: Most half-spaces in one clip (a box and two planes); each costs a few multiply-adds
#: per fragment, compiled in only when a clip is given.
MAX_CLIP_PLANES = 8


def _vector(value: Any, name: str) -> NDArray[np.float64]:
    try:
        v = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be three numbers, got {value!r}") from None
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {tuple(v.tolist())}")
    return v


def _length(n: NDArray[np.float64]) -> float:
    """The length of a finite 3-vector, without overflow or underflow: where its square
    would leave float64's range (components beyond ~1e150 or below ~1e-150), it is scaled
    by its largest component first."""
    with np.errstate(over="ignore", under="ignore"):
        length = float(np.linalg.norm(n))
    if 1e-150 < length < 1e150:
        return length  # as before: the plain norm, bit for bit
    big = float(np.max(np.abs(n)))
    return 0.0 if big == 0.0 else big * float(np.linalg.norm(n / big))


def _unit(n: NDArray[np.float64]) -> NDArray[np.float64] | None:
    """``n`` (finite) scaled to unit length, or None for the zero vector: neither 1e300
    (whose square overflows) nor 1e-200 (whose square underflows to 0) loses the direction."""
    length = _length(n)
    if length == 0.0:
        return None
    if math.isinf(length):  # components near float64's largest: scale first
        n = n / float(np.max(np.abs(n)))
        length = float(np.linalg.norm(n))
    return n / length  # type: ignore[no-any-return]


@dataclasses.dataclass(frozen=True)
class Clip:
    """Half-spaces of world space; the mesh is kept where all of them hold.

    Each plane is ``(nx, ny, nz, w)`` with a unit normal; the kept side is
    ``n . x + w >= 0``, the side the normal points into.

    Examples
    --------
    >>> Clip.plane(origin=(0, 0, 1), normal=(0, 0, 2)).planes  # keeps z >= 1
    ((0.0, 0.0, 1.0, -1.0),)
    >>> len(Clip.box((0, 0, 0), (1, 2, 3)).planes)
    6
    >>> (Clip.plane((0, 0, 0), (1, 0, 0)) & Clip.plane((0, 0, 0), (0, 1, 0))).planes[1]
    (0.0, 1.0, 0.0, 0.0)
    """

    planes: tuple[tuple[float, float, float, float], ...]

    def __post_init__(self) -> None:
        try:
            arr = np.asarray(self.planes, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"planes must be rows (nx, ny, nz, w), got {self.planes!r}") from None
        if arr.ndim != 2 or arr.shape[1] != 4 or arr.shape[0] == 0:
            raise ValueError(f"planes must be one or more rows (nx, ny, nz, w), got shape {arr.shape}")
        if arr.shape[0] > MAX_CLIP_PLANES:
            raise ValueError(f"a clip holds at most {MAX_CLIP_PLANES} planes, got {arr.shape[0]}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"planes must be finite, got {arr.tolist()}")
        rows = []
        for i, row in enumerate(arr):
            n = _unit(row[:3])
            if n is None:
                raise ValueError(f"plane {i} has a zero normal: {row.tolist()}; give a normal that is not (0, 0, 0)")
            big = float(np.max(np.abs(row[:3])))
            with np.errstate(over="ignore"):
                length = _length(row[:3])
                # w over the normal's length: a signed distance (scaled as the normal was)
                w = row[3] / length if math.isfinite(length) else row[3] / float(np.linalg.norm(row[:3] / big)) / big
            if not np.isfinite(w):
                raise ValueError(f"plane {i} {row.tolist()} lies beyond float64's range from the origin "
                                 "(w over the normal's length overflows); give a plane nearer the data")
            rows.append((*(float(v) for v in n), float(w)))
        object.__setattr__(self, "planes", tuple(rows))

    # ---- construction ----
    @classmethod
    def plane(cls, origin: ArrayLike, normal: ArrayLike) -> "Clip":
        """Keep the side of the plane through ``origin`` that ``normal`` points into."""
        o, n = _vector(origin, "origin"), _vector(normal, "normal")
        unit = _unit(n)
        if unit is None:
            raise ValueError(f"normal must not be the zero vector, got {tuple(n.tolist())}; give the direction "
                             "the kept side lies in")
        if 1e-150 < _length(n) < 1e150:
            unit = n  # as before, bit for bit: the row is normalised in __post_init__
        with np.errstate(over="ignore", invalid="ignore"):
            w = 0.0 - float(unit @ o)  # +0.0, not -0.0, for a plane through the origin
        if not math.isfinite(w):
            raise ValueError(f"the plane through origin {tuple(o.tolist())} is beyond float64's range from (0, 0, 0) "
                             "(its distance overflows); give an origin nearer the data")
        return cls(((*unit.tolist(), w),))

    @classmethod
    def box(cls, lo: ArrayLike, hi: ArrayLike) -> "Clip":
        """Keep the axis-aligned box ``lo <= x <= hi``."""
        a, b = _vector(lo, "lo"), _vector(hi, "hi")
        if not np.all(a < b):
            raise ValueError(f"a box needs lo < hi on every axis, got lo {a.tolist()}, hi {b.tolist()}")
        rows = []
        for axis in range(3):
            e = [0.0, 0.0, 0.0]
            e[axis] = 1.0
            rows.append((*e, -float(a[axis])))  # x >= lo
            e = [0.0, 0.0, 0.0]
            e[axis] = -1.0
            rows.append((*e, float(b[axis])))  # x <= hi
        return cls(tuple(rows))  # type: ignore[arg-type]

    def __and__(self, other: "Clip") -> "Clip":
        if not isinstance(other, Clip):
            return NotImplemented
        return Clip(self.planes + other.planes)

    # ---- scene files ----
    def to_dict(self) -> dict[str, Any]:
        return {"planes": [list(p) for p in self.planes]}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "Clip":
        """``{"planes": [[nx, ny, nz, w], ...]}``, ``{"plane": {"origin": .., "normal": ..}}``
        or ``{"box": [[xmin, ymin, zmin], [xmax, ymax, zmax]]}``; several keys intersect."""
        if not isinstance(data, dict) or not data:
            raise ValueError(f"a clip must be an object with 'planes', 'plane' and/or 'box', got {data!r}")
        unknown = set(data) - {"planes", "plane", "box"}
        if unknown:
            raise ValueError(f"unknown clip keys {sorted(unknown)}; expected some of ['box', 'plane', 'planes']")
        _refuse_non_numbers(data, "clip")
        rows: list[Any] = []
        if "planes" in data:
            rows += list(data["planes"])
        if "plane" in data:
            p = data["plane"]
            if not isinstance(p, dict) or set(p) != {"origin", "normal"}:
                raise ValueError(f"clip 'plane' must be {{'origin': [x, y, z], 'normal': [x, y, z]}}, got {p!r}")
            rows += cls.plane(p["origin"], p["normal"]).planes
        if "box" in data:
            b = data["box"]
            if not isinstance(b, (list, tuple)) or len(b) != 2:
                raise ValueError(f"clip 'box' must be [[xmin, ymin, zmin], [xmax, ymax, zmax]], got {b!r}")
            rows += cls.box(b[0], b[1]).planes
        return cls(tuple(tuple(r) for r in rows))

    # ---- per view ----
    def eye_planes(self, camera: Camera) -> NDArray[np.float64]:
        """The planes in the camera's eye space, ``(k, 4)``: ``n_eye . x_eye + w_eye >= 0``."""
        view = camera.view_matrix()
        rot, shift = view[:3, :3], view[:3, 3]
        p = np.asarray(self.planes, dtype=np.float64)
        n_eye = p[:, :3] @ rot.T  # x_world = rot^T (x_eye - shift)
        return np.column_stack([n_eye, p[:, 3] - n_eye @ shift])

    def contains(self, points: ArrayLike) -> NDArray[np.bool_]:
        """Whether each world point is kept."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        p = np.asarray(self.planes)
        return np.all(pts @ p[:, :3].T + p[:, 3] >= 0, axis=1)  # type: ignore[no-any-return]


def _refuse_non_numbers(value: Any, where: str) -> None:
    """``ValueError`` naming the key for a string or boolean where a scene file's clip
    holds numbers (numpy would read ``"5"`` as 5 and ``true`` as 1 without a word)."""
    if isinstance(value, dict):
        for k, v in value.items():
            _refuse_non_numbers(v, f"{where} {k!r}")
    elif isinstance(value, (list, tuple)):
        for v in value:
            if isinstance(v, (str, bytes, bool)) or v is None:
                raise ValueError(f"{where} must hold numbers, got {value!r}")
            _refuse_non_numbers(v, where)


def check_clip(clip: Any) -> "Clip | None":
    """``clip`` itself, if it is a :class:`Clip` or None; else a TypeError naming its type."""
    if clip is not None and not isinstance(clip, Clip):
        raise TypeError(f"clip must be a tetvr.Clip or None, got {type(clip).__name__}")
    return clip


def ray_window(planes_eye: NDArray[np.float64], x: NDArray[np.float64], y: NDArray[np.float64], *,
               parallel: bool, near: float, far: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The kept interval ``[lo, hi]`` of eye depth along rays through eye ``(x, y)``
    (perspective: per unit depth), cut to ``[near, far]``; ``lo >= hi`` where nothing is kept.

    Same arithmetic as ``shaders/window.glsl``. Along a ray the plane function is
    ``a + b t``: ``b > 0`` bounds t from below, ``b < 0`` from above, and ``b == 0`` keeps
    the whole ray or none of it.
    """
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    lo = np.full(x.shape, float(near))
    hi = np.full(x.shape, float(far))
    for nx, ny, nz, w in np.asarray(planes_eye, dtype=np.float64):
        if parallel:
            a, b = nx * x + ny * y + w, np.full(x.shape, -nz)
        else:
            a, b = np.full(x.shape, w), nx * x + ny * y - nz
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -a / b
        lo = np.where(b > 0, np.maximum(lo, t), lo)
        hi = np.where(b < 0, np.minimum(hi, t), hi)
        hi = np.where((b == 0) & (a < 0), -math.inf, hi)
    return lo, hi

"""Image volumes (CT, MR, simulation grids): the grid, its placement in the world, sampling.

About this stage
----------------
A :class:`Volume` is a regular grid of scalars placed in world (patient) coordinates by
an *index -> world* affine, the convention of ITK, VTK's ``vtkImageData`` and DICOM::

    x_world = origin + direction @ (spacing * (i, j, k))

``(i, j, k)`` is the voxel index along x, y, z (``data[k, j, i]``), ``direction`` holds the
world direction of each index axis in its *columns*, and values sit at the voxel
centres (VTK's point data). The volume's box is therefore ``[0, n - 1]`` along each index
axis, and trilinear interpolation is defined everywhere inside it. A tet mesh in the same
world coordinates lines up with the volume without any further transform.

Anatomical frames. DICOM, MetaImage and ITK use LPS (x to the patient's left, y
posterior, z superior); NIfTI uses RAS. :func:`read_volume` brings files that declare an
anatomical frame into ``space="LPS"`` (the default) or ``"RAS"`` by flipping x and y;
files without one (VTK, raw, NRRD's ``3D-right-handed``) are taken as they are.

Readers: :mod:`tetvr.io.volume_file` reads NRRD, MetaImage, NIfTI and DICOM through SimpleITK
(ITK's readers), VTK files (``.vti``, legacy structured points) through
:mod:`tetvr.io.volume_vtk`, and raw voxels, into a :class:`Volume`.

Voxel values keep their dtype (int16 CT stays int16; nothing is quantised to 8 bits).
"""

from __future__ import annotations

import dataclasses
import math
from functools import cached_property
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.checks import warn

__all__ = ["Volume", "SPACES"]

#: World frames a volume can be brought into.
SPACES = ("LPS", "RAS")

# x and y flip between LPS and RAS.
_FLIP_XY = np.diag([-1.0, -1.0, 1.0])


def _vec(value: Any, name: str, *, positive: bool = False) -> NDArray[np.float64]:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    if positive and np.any(arr <= 0):
        raise ValueError(f"{name} must be positive along every axis, got {arr.tolist()}")
    return arr


@dataclasses.dataclass(frozen=True, eq=False)
class Volume:
    """A scalar image volume placed in world coordinates.

    Build one with :meth:`Volume.from_array` or a reader (:func:`read_volume`).

    Attributes
    ----------
    data : (nz, ny, nx) array, read-only, native byte order, the file's dtype.
    spacing : (3,) float64, distance between voxel centres along x, y, z (world units).
    origin : (3,) float64, world position of voxel ``(0, 0, 0)``.
    direction : (3, 3) float64, column ``a`` is the world direction (unit length) of index
        axis ``a``; the identity for axis-aligned grids.
    scalar_name : name of the field.
    space : ``"LPS"``, ``"RAS"`` or ``""`` (no anatomical frame declared).

    Examples
    --------
    >>> v = Volume.from_array(np.zeros((4, 3, 2), np.int16), spacing=(0.5, 1, 2), origin=(10, 0, 0))
    >>> v.dims, v.dtype
    ((2, 3, 4), dtype('int16'))
    >>> v.index_to_world @ [1, 2, 3, 1]
    array([10.5,  2. ,  6. ,  1. ])
    """

    data: NDArray[Any]
    spacing: NDArray[np.float64]
    origin: NDArray[np.float64]
    direction: NDArray[np.float64]
    scalar_name: str = "scalars"
    space: str = ""

    def __post_init__(self) -> None:
        data = self.data
        if not isinstance(data, np.ndarray):
            raise TypeError(f"data must be a numpy array, got {type(data).__name__}")
        if data.ndim != 3:
            raise ValueError(f"data must have 3 axes (nz, ny, nx), got shape {data.shape}")
        if min(data.shape) < 1:
            raise ValueError(f"data must have at least one voxel along every axis, got shape {data.shape}")
        if data.dtype.kind not in "iuf":
            raise TypeError(f"data must be integer or floating point, got dtype {data.dtype}")
        if data.dtype.kind == "f" and not np.all(np.isfinite(data)):
            bad = int(np.count_nonzero(~np.isfinite(data)))
            raise ValueError(f"data contain {bad} NaN or Inf values; replace them (e.g. np.nan_to_num) first")
        if data.dtype.byteorder not in ("=", "|"):
            data = data.astype(data.dtype.newbyteorder("="))
        # The volume owns its array (from_array and the readers pass fresh ones).
        data = np.ascontiguousarray(data)
        data.setflags(write=False)
        spacing = _vec(self.spacing, "spacing", positive=True)
        origin = _vec(self.origin, "origin")
        direction = np.asarray(self.direction, dtype=np.float64)
        if direction.shape != (3, 3) or not np.all(np.isfinite(direction)):
            raise ValueError(f"direction must be a finite 3x3 matrix, got {np.asarray(self.direction).tolist()!r}")
        norms = np.linalg.norm(direction, axis=0)
        if np.any(norms == 0):
            raise ValueError(f"direction has a zero column (axis {int(np.argmin(norms))}): {direction.tolist()}")
        direction = direction / norms
        if abs(np.linalg.det(direction)) < 1e-6:
            raise ValueError(f"direction matrix is singular (its axes are coplanar): {direction.tolist()}")
        if self.space not in ("",) + SPACES:
            raise ValueError(f"space must be one of {('',) + SPACES}, got {self.space!r}")
        for arr in (spacing, origin, direction):
            arr.setflags(write=False)
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "spacing", spacing)
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "direction", direction)
        object.__setattr__(self, "scalar_name", str(self.scalar_name))

    @classmethod
    def from_array(
        cls,
        data: ArrayLike,
        *,
        spacing: ArrayLike = (1.0, 1.0, 1.0),
        origin: ArrayLike = (0.0, 0.0, 0.0),
        direction: ArrayLike | None = None,
        scalar_name: str = "scalars",
        space: str = "",
    ) -> "Volume":
        """A volume from a ``(nz, ny, nx)`` array (copied; the caller's array is not kept).

        Examples
        --------
        >>> Volume.from_array(np.arange(8.0).reshape(2, 2, 2)).scalar_range
        (0.0, 7.0)
        """
        arr = np.array(data, copy=True)
        if arr.dtype == np.bool_:
            arr = arr.astype(np.uint8)
        return cls(data=arr, spacing=spacing, origin=origin,  # type: ignore[arg-type]
                   direction=np.eye(3) if direction is None else direction,  # type: ignore[arg-type]
                   scalar_name=scalar_name, space=space)

    # ---- geometry ----
    @property
    def dims(self) -> tuple[int, int, int]:
        """Number of voxels along x, y, z: ``(nx, ny, nz)``."""
        nz, ny, nx = self.data.shape
        return int(nx), int(ny), int(nz)

    @property
    def dtype(self) -> np.dtype[Any]:
        return self.data.dtype

    @cached_property
    def index_to_world(self) -> NDArray[np.float64]:
        """4x4 affine taking ``(i, j, k, 1)`` to world ``(x, y, z, 1)``."""
        m = np.eye(4)
        m[:3, :3] = self.direction * self.spacing[None, :]
        m[:3, 3] = self.origin
        m.setflags(write=False)
        return m

    @cached_property
    def world_to_index(self) -> NDArray[np.float64]:
        """Inverse of :attr:`index_to_world`."""
        m = np.linalg.inv(self.index_to_world).astype(np.float64)
        m.setflags(write=False)
        return m

    @property
    def extent(self) -> NDArray[np.float64]:
        """Size of the box along each index axis in world units, ``spacing * (n - 1)``."""
        return self.spacing * (np.asarray(self.dims, dtype=np.float64) - 1.0)

    @cached_property
    def corners(self) -> NDArray[np.float64]:
        """(8, 3) world positions of the box corners (corner ``c`` has index bits x, y, z)."""
        hi = np.asarray(self.dims, dtype=np.float64) - 1.0
        idx = np.array([[(c & 1) * hi[0], (c >> 1 & 1) * hi[1], (c >> 2 & 1) * hi[2], 1.0] for c in range(8)])
        out: NDArray[np.float64] = (idx @ self.index_to_world.T)[:, :3]
        return out

    @property
    def bounds(self) -> NDArray[np.float64]:
        """(2, 3) world-axis-aligned bounding box of the volume's box: ``[min, max]``."""
        return np.stack([self.corners.min(axis=0), self.corners.max(axis=0)])

    @property
    def center(self) -> NDArray[np.float64]:
        return self.corners.mean(axis=0)

    @property
    def diagonal(self) -> float:
        """Length of the box's diagonal in world units."""
        return float(np.linalg.norm(self.extent))

    @cached_property
    def scalar_range(self) -> tuple[float, float]:
        return float(self.data.min()), float(self.data.max())

    # ---- sampling ----
    @cached_property
    def _samples(self) -> NDArray[np.float64]:
        return self.data.astype(np.float64)

    def sample_index(self, ijk: ArrayLike, *, interpolation: str = "linear") -> NDArray[np.float64]:
        """The field at continuous index positions ``(..., 3)``.

        ``interpolation`` is ``"linear"`` (trilinear, the position clamped to the box) or
        ``"cubic"`` (the uniform cubic B-spline of the voxels, an approximating C2
        reconstruction that smooths noise; taps beyond the edge repeat the edge voxel).
        Both are what the GPU ray caster's texture reads compute.
        """
        p = np.asarray(ijk, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ValueError(f"index positions must have shape (..., 3), got {p.shape}")
        if interpolation == "linear":
            return _trilinear(self._samples, p)
        if interpolation == "cubic":
            return _cubic_bspline(self._samples, p)
        raise ValueError(f"interpolation must be 'linear' or 'cubic', got {interpolation!r}")

    def sample(self, points_world: ArrayLike, *, outside: float = np.nan,
               interpolation: str = "linear") -> NDArray[np.float64]:
        """The field at world points ``(..., 3)`` (see :meth:`sample_index`); ``outside`` beyond the box.

        Examples
        --------
        >>> v = Volume.from_array(np.arange(8.0).reshape(2, 2, 2), spacing=(2, 2, 2))
        >>> v.sample([[1.0, 0.0, 0.0], [9.0, 0.0, 0.0]]).tolist()
        [0.5, nan]
        """
        p = np.asarray(points_world, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3), got {p.shape}")
        m = self.world_to_index
        ijk = p @ m[:3, :3].T + m[:3, 3]
        hi = np.asarray(self.dims, dtype=np.float64) - 1.0
        tol = 1e-9 * np.maximum(hi, 1.0)
        inside = np.all((ijk >= -tol) & (ijk <= hi + tol), axis=-1)
        return np.where(inside, self.sample_index(ijk, interpolation=interpolation), outside)

    # ---- resampling ----
    def downsampled(self, dims: Sequence[int]) -> "Volume":
        """The volume resampled to ``dims = (nx, ny, nz)`` voxels over the same box.

        Each axis is box-filtered over the voxels that fall into one new voxel (no
        aliasing), then linearly resampled at ``n_new`` evenly spaced centres from the
        first to the last voxel, so the box, origin and direction are unchanged and the
        spacing grows to ``extent / (n_new - 1)``. The result is float32 (exact for
        8/16-bit data before filtering).
        """
        new = tuple(int(v) for v in dims)
        if len(new) != 3 or any(n < 1 for n in new):
            raise ValueError(f"dims must be 3 positive integers (nx, ny, nz), got {dims!r}")
        if any(n > o for n, o in zip(new, self.dims)):
            raise ValueError(f"dims {new} must not exceed the volume's dims {self.dims}")
        arr = self.data.astype(np.float32)
        spacing = self.spacing.copy()
        for axis_xyz, n_new in enumerate(new):
            axis = 2 - axis_xyz
            n_old = arr.shape[axis]
            if n_new == n_old:
                continue
            arr = _resample_axis(arr, axis, n_new)
            spacing[axis_xyz] = self.spacing[axis_xyz] * (n_old - 1) / max(n_new - 1, 1)
        return Volume(data=arr, spacing=spacing, origin=self.origin, direction=self.direction,
                      scalar_name=self.scalar_name, space=self.space)

    def fit_size(self, max_size: int) -> "Volume":
        """``self`` if no axis exceeds ``max_size`` voxels, else a downsampled copy, with a warning."""
        max_size = int(max_size)
        if max_size < 2:
            raise ValueError(f"max_size must be at least 2, got {max_size}")
        if max(self.dims) <= max_size:
            return self
        new = tuple(min(n, max_size) for n in self.dims)
        warn(
            f"volume of {self.dims} voxels exceeds the GPU's largest 3D texture ({max_size} per side); "
            f"it is downsampled to {new} (box-filtered, same world box)")
        return self.downsampled(new)

    def in_space(self, space: str) -> "Volume":
        """The same volume with world coordinates in ``space`` ("LPS" or "RAS").

        Only volumes that declare an anatomical frame can be converted.
        """
        if space not in SPACES:
            raise ValueError(f"space must be one of {SPACES}, got {space!r}")
        if self.space == space:
            return self
        if not self.space:
            raise ValueError("this volume declares no anatomical frame; it cannot be converted to " + space)
        return dataclasses.replace(self, origin=_FLIP_XY @ self.origin, direction=_FLIP_XY @ self.direction,
                                   space=space)


def _trilinear(vol: NDArray[np.float64], ijk: NDArray[np.float64]) -> NDArray[np.float64]:
    """Trilinear interpolation of ``vol[k, j, i]`` at ``ijk`` (..., 3), clamped to the box."""
    nz, ny, nx = vol.shape
    shape = ijk.shape[:-1]
    p = ijk.reshape(-1, 3)
    out = np.zeros(p.shape[0])
    for lo, hi in _chunks(p.shape[0], 1 << 20):
        q = p[lo:hi]
        axes = []
        for a, n in enumerate((nx, ny, nz)):
            x = np.clip(q[:, a], 0.0, n - 1.0)
            i0 = np.minimum(np.floor(x).astype(np.int64), max(n - 2, 0))
            w = x - i0
            i1 = np.minimum(i0 + 1, n - 1)
            axes.append((i0, i1, w))
        (x0, x1, wx), (y0, y1, wy), (z0, z1, wz) = axes
        c00 = vol[z0, y0, x0] * (1 - wx) + vol[z0, y0, x1] * wx
        c01 = vol[z0, y1, x0] * (1 - wx) + vol[z0, y1, x1] * wx
        c10 = vol[z1, y0, x0] * (1 - wx) + vol[z1, y0, x1] * wx
        c11 = vol[z1, y1, x0] * (1 - wx) + vol[z1, y1, x1] * wx
        c0 = c00 * (1 - wy) + c01 * wy
        c1 = c10 * (1 - wy) + c11 * wy
        out[lo:hi] = c0 * (1 - wz) + c1 * wz
    return out.reshape(shape)


def _cubic_bspline(vol: NDArray[np.float64], ijk: NDArray[np.float64]) -> NDArray[np.float64]:
    """Uniform cubic B-spline of ``vol[k, j, i]`` at ``ijk`` (..., 3); taps clamped to the box."""
    shape = ijk.shape[:-1]
    p = ijk.reshape(-1, 3)
    out = np.zeros(p.shape[0])
    for lo, hi in _chunks(p.shape[0], 1 << 18):
        taps = []
        for a, n in enumerate(vol.shape[::-1]):
            x = p[lo:hi, a]
            i = np.floor(x)
            t = x - i
            w = np.stack([(1 - t) ** 3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3]) / 6.0
            idx = np.clip(i.astype(np.int64)[None, :] + np.arange(-1, 3)[:, None], 0, n - 1)
            taps.append((idx, w))
        (xi, xw), (yi, yw), (zi, zw) = taps
        acc = np.zeros(hi - lo)
        for c in range(4):
            for b in range(4):
                wzy = zw[c] * yw[b]
                for a in range(4):
                    acc += wzy * xw[a] * vol[zi[c], yi[b], xi[a]]
        out[lo:hi] = acc
    return out.reshape(shape)


def _chunks(n: int, size: int) -> list[tuple[int, int]]:
    return [(s, min(s + size, n)) for s in range(0, n, size)]


def _resample_axis(arr: NDArray[np.float32], axis: int, n_new: int) -> NDArray[np.float32]:
    """Box-filter then linearly resample one axis to ``n_new`` samples spanning the same box."""
    n_old = arr.shape[axis]
    a = np.moveaxis(arr, axis, 0).astype(np.float64)
    if n_new == 1:
        return np.moveaxis(a.mean(axis=0, keepdims=True), 0, axis).astype(np.float32)
    ratio = (n_old - 1) / (n_new - 1)
    width = int(math.ceil(ratio))
    if width > 1:
        # Moving average over `width` samples, centred, edges clamped (cumulative sums).
        half_lo = (width - 1) // 2
        half_hi = width - 1 - half_lo
        padded = np.concatenate([np.repeat(a[:1], half_lo, axis=0), a, np.repeat(a[-1:], half_hi, axis=0)])
        c = np.concatenate([np.zeros((1,) + a.shape[1:]), np.cumsum(padded, axis=0)])
        a = (c[width:] - c[:-width]) / width
    x = np.arange(n_new) * ratio
    i0 = np.minimum(np.floor(x).astype(np.int64), n_old - 2)
    w = (x - i0).reshape((-1,) + (1,) * (a.ndim - 1))
    out = a[i0] * (1 - w) + a[i0 + 1] * w
    return np.moveaxis(out, 0, axis).astype(np.float32)

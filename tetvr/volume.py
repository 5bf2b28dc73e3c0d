"""Image volumes (CT, MR, simulation grids) and the readers that load them.

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

Readers: raw (:func:`read_raw`), NRRD (``.nrrd``, ``.nhdr`` with detached or sliced
data), MetaImage (``.mha``, ``.mhd``), VTK XML image data (``.vti``: ascii, base64,
appended raw, zlib/lzma), legacy VTK structured points (``.vtk``) are parsed here with
numpy only. NIfTI (``.nii``, ``.nii.gz``) and DICOM series need the optional extra
``pip install tetvr[volumes]`` (nibabel, pydicom).

Voxel values keep their dtype (int16 CT stays int16; nothing is quantised to 8 bits).
"""

from __future__ import annotations

import base64
import bz2
import dataclasses
import gzip
import lzma
import math
import os
import re
import warnings
import xml.etree.ElementTree as ET
import zlib
from functools import cached_property
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "Volume",
    "read_volume",
    "read_raw",
    "read_nrrd",
    "read_metaimage",
    "read_vti",
    "read_vtk_structured_points",
    "read_nifti",
    "read_dicom",
    "SPACES",
    "VOLUME_SUFFIXES",
]

#: World frames a volume can be brought into.
SPACES = ("LPS", "RAS")

#: File name endings :func:`read_volume` recognises (a directory is a DICOM series).
VOLUME_SUFFIXES = (".nrrd", ".nhdr", ".mha", ".mhd", ".vti", ".vtk", ".nii", ".nii.gz", ".dcm")

_EXTRA_HINT = "install the optional volume readers with  pip install tetvr[volumes]  (or pip install {pkg})"

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
        warnings.warn(
            f"volume of {self.dims} voxels exceeds the GPU's largest 3D texture ({max_size} per side); "
            f"it is downsampled to {new} (box-filtered, same world box)",
            stacklevel=2,
        )
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


# ---------------------------------------------------------------------------------
# Dispatch
# ---------------------------------------------------------------------------------


def read_volume(path: str | os.PathLike[str], *, space: str = "LPS", scalars: str | None = None) -> Volume:
    """Read a volume, choosing the reader by the file name (a directory is a DICOM series).

    Parameters
    ----------
    path : ``.nrrd``/``.nhdr``, ``.mha``/``.mhd``, ``.vti``, ``.vtk`` (structured points),
        ``.nii``/``.nii.gz``, ``.dcm`` (one slice) or a directory of DICOM slices. Raw files
        carry no geometry: use :func:`read_raw`.
    space : world frame for files that declare an anatomical one: "LPS" (DICOM/ITK,
        default) or "RAS" (NIfTI/Slicer).
    scalars : for VTK files, the name of the array to read (default: the active scalars,
        else the first array; vectors give their magnitude).

    Examples
    --------
    >>> vol = read_volume("../shared/data/volumes/HeadMRVolume.mhd")  # doctest: +SKIP
    >>> vol.dims, vol.spacing.tolist()                                 # doctest: +SKIP
    ((48, 62, 42), [4.0, 4.0, 4.0])
    """
    if space not in SPACES:
        raise ValueError(f"space must be one of {SPACES}, got {space!r}")
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"volume file not found: {str(p)!r}")
    if p.is_dir():
        return read_dicom(p, space=space)
    name = p.name.lower()
    if name.endswith((".nrrd", ".nhdr")):
        return read_nrrd(p, space=space)
    if name.endswith((".mha", ".mhd")):
        return read_metaimage(p, space=space)
    if name.endswith(".vti"):
        return read_vti(p, scalars=scalars)
    if name.endswith(".vtk"):
        return read_vtk_structured_points(p, scalars=scalars)
    if name.endswith((".nii", ".nii.gz")):
        return read_nifti(p, space=space)
    if name.endswith(".dcm"):
        return read_dicom(p, space=space)
    if name.endswith((".raw", ".img", ".bin")):
        raise ValueError(f"{p.name!r} is a raw file without geometry: read it with read_raw(path, dims=..., dtype=...)")
    raise ValueError(f"unrecognised volume file {p.name!r}; expected one of {VOLUME_SUFFIXES} or a DICOM directory")


def _to_space(vol: Volume, space: str) -> Volume:
    return vol.in_space(space) if vol.space and vol.space != space else vol


def _check_file(path: Path, what: str) -> Path:
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {str(path)!r}")
    return path


def _dims(value: Any, name: str = "dims") -> tuple[int, int, int]:
    try:
        dims = tuple(int(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 3 positive integers (nx, ny, nz), got {value!r}") from None
    if len(dims) != 3 or any(d < 1 for d in dims) or tuple(float(v) for v in value) != tuple(map(float, dims)):
        raise ValueError(f"{name} must be 3 positive integers (nx, ny, nz), got {value!r}")
    return dims  # type: ignore[return-value]


def _from_bytes(buf: bytes, dtype: np.dtype[Any], dims: tuple[int, int, int], what: str) -> NDArray[Any]:
    nx, ny, nz = dims
    need = nx * ny * nz * dtype.itemsize
    if len(buf) != need:
        raise ValueError(
            f"{what} holds {len(buf)} bytes of voxel data, but dims {dims} x {dtype.name} "
            f"({dtype.itemsize} bytes) need {need}"
        )
    arr = np.frombuffer(buf, dtype=dtype).reshape(nz, ny, nx)
    return arr.astype(dtype.newbyteorder("="), copy=True)


def _next_line(raw: bytes, pos: int) -> tuple[str, int]:
    """The line of ``raw`` starting at ``pos`` (latin-1, without its ``\\r\\n``), and where the next begins."""
    end = raw.find(b"\n", pos)
    end = len(raw) if end < 0 else end
    return raw[pos:end].decode("latin-1").rstrip("\r"), end + 1


def read_raw(
    path: str | os.PathLike[str],
    *,
    dims: Sequence[int],
    dtype: Any,
    spacing: ArrayLike = (1.0, 1.0, 1.0),
    origin: ArrayLike = (0.0, 0.0, 0.0),
    direction: ArrayLike | None = None,
    byte_order: str = "little",
    header_bytes: int = 0,
    space: str = "",
) -> Volume:
    """Read headerless voxels, x fastest, with the geometry given explicitly.

    The file must hold exactly ``header_bytes + nx*ny*nz*itemsize`` bytes; anything else
    is reported (a wrong size almost always means wrong dims or dtype).

    Examples
    --------
    >>> read_raw("head.raw", dims=(48, 62, 42), dtype="uint8", spacing=(4, 4, 4))  # doctest: +SKIP
    """
    p = _check_file(Path(path), "raw volume file")
    d = _dims(dims)
    try:
        dt = np.dtype(dtype)
    except TypeError:
        raise ValueError(f"dtype {dtype!r} is not a numpy dtype") from None
    if dt.kind not in "iuf":
        raise ValueError(f"dtype must be an integer or float type, got {dt}")
    if byte_order not in ("little", "big"):
        raise ValueError(f"byte_order must be 'little' or 'big', got {byte_order!r}")
    dt = dt.newbyteorder("<" if byte_order == "little" else ">")
    header_bytes = int(header_bytes)
    if header_bytes < 0:
        raise ValueError(f"header_bytes must be >= 0, got {header_bytes}")
    size = p.stat().st_size
    need = header_bytes + int(np.prod(d)) * dt.itemsize
    if size != need:
        raise ValueError(
            f"raw file {p.name!r} has {size} bytes, but dims {d} x {dt.name} ({dt.itemsize} bytes)"
            + (f" + {header_bytes} header bytes" if header_bytes else "") + f" need {need}"
        )
    with open(p, "rb") as f:
        f.seek(header_bytes)
        buf = f.read()
    data = _from_bytes(buf, dt, d, f"raw file {p.name!r}")
    return Volume(data=data, spacing=_vec(spacing, "spacing"), origin=_vec(origin, "origin"),
                  direction=np.eye(3) if direction is None else np.asarray(direction, dtype=np.float64),
                  scalar_name=p.stem, space=space)


# ---------------------------------------------------------------------------------
# NRRD
# ---------------------------------------------------------------------------------

_NRRD_TYPES: dict[np.dtype[Any], tuple[str, ...]] = {
    np.dtype("i1"): ("signed char", "int8", "int8_t"),
    np.dtype("u1"): ("uchar", "unsigned char", "uint8", "uint8_t"),
    np.dtype("i2"): ("short", "short int", "signed short", "signed short int", "int16", "int16_t"),
    np.dtype("u2"): ("ushort", "unsigned short", "unsigned short int", "uint16", "uint16_t"),
    np.dtype("i4"): ("int", "signed int", "int32", "int32_t"),
    np.dtype("u4"): ("uint", "unsigned int", "uint32", "uint32_t"),
    np.dtype("i8"): ("longlong", "long long", "long long int", "signed long long", "signed long long int",
                     "int64", "int64_t"),
    np.dtype("u8"): ("ulonglong", "unsigned long long", "unsigned long long int", "uint64", "uint64_t"),
    np.dtype("f4"): ("float",),
    np.dtype("f8"): ("double",),
}
_NRRD_TYPE: dict[str, np.dtype[Any]] = {name: dt for dt, names in _NRRD_TYPES.items() for name in names}

_NRRD_SPACES = {
    "left-posterior-superior": "LPS", "lps": "LPS",
    "right-anterior-superior": "RAS", "ras": "RAS",
    "left-anterior-superior": "LAS", "las": "LAS",
}


def _nrrd_vector(text: str, what: str) -> NDArray[np.float64] | None:
    text = text.strip()
    if text == "none":
        return None
    m = re.fullmatch(r"\(([^)]*)\)", text)
    if not m:
        raise ValueError(f"NRRD {what}: expected a vector like (1,0,0), got {text!r}")
    return np.asarray([float(v) for v in m.group(1).split(",")], dtype=np.float64)


def read_nrrd(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a NRRD volume (``.nrrd`` attached or ``.nhdr`` detached, incl. slice lists).

    Supports encodings raw, gzip, bzip2 and ascii; ``space directions``/``space origin``
    or ``spacings``; ``data file`` as one name, a printf pattern with ``min max step`` or
    ``LIST``; ``byte skip`` (including -1) and ``line skip``.
    """
    p = _check_file(Path(path), "NRRD file")
    raw = p.read_bytes()
    if not raw.startswith(b"NRRD000"):
        raise ValueError(f"{p.name!r} is not a NRRD file (it does not start with 'NRRD000x')")
    # Header: lines up to the first empty line (attached data follows it) or the end.
    fields: dict[str, str] = {}
    pos = raw.index(b"\n") + 1
    list_files: list[str] | None = None
    while pos < len(raw):
        line, pos = _next_line(raw, pos)
        if list_files is not None:
            if line.strip():
                list_files.append(line.strip())
            continue
        if not line.strip():
            break
        if line.startswith("#"):
            continue
        if ":=" in line and line.find(":=") < (line.find(": ") if ": " in line else len(line)):
            continue  # a key/value pair, not a field
        if ":" not in line:
            raise ValueError(f"NRRD header line {line!r} of {p.name!r} is not 'field: value'")
        key, value = line.split(":", 1)
        key = key.strip().lower()
        value = value.strip()
        if key == "data file" or key == "datafile":
            if value.startswith("LIST"):
                list_files = []
        fields[key] = value
    header_end = pos

    def need(key: str) -> str:
        if key not in fields:
            raise ValueError(f"NRRD file {p.name!r} has no '{key}' field")
        return fields[key]

    ndim = int(need("dimension"))
    sizes = [int(v) for v in need("sizes").split()]
    if len(sizes) != ndim:
        raise ValueError(f"NRRD 'sizes' lists {len(sizes)} values for dimension {ndim}")
    type_name = need("type").lower()
    if type_name not in _NRRD_TYPE:
        raise ValueError(f"NRRD type {type_name!r} of {p.name!r} is not supported (block types are not)")
    dtype = _NRRD_TYPE[type_name]
    encoding = fields.get("encoding", "raw").lower()
    if dtype.itemsize > 1 and encoding not in ("ascii", "text", "txt"):
        endian = need("endian").lower()
        if endian not in ("little", "big"):
            raise ValueError(f"NRRD endian must be little or big, got {endian!r}")
        dtype = dtype.newbyteorder("<" if endian == "little" else ">")
    # A leading axis of length 1 (e.g. 'kinds: scalar domain ...') is a scalar volume too.
    lead = 0
    if ndim == 4 and sizes[0] == 1:
        lead = 1
    elif ndim == 2:
        sizes = sizes + [1]
    elif ndim != 3:
        raise ValueError(f"NRRD {p.name!r} has dimension {ndim} with sizes {sizes}: only scalar 3D volumes are read")
    dims = _dims(sizes[lead:lead + 3], "NRRD sizes")

    # Geometry.
    origin = np.zeros(3)
    direction = np.eye(3)
    spacing = np.ones(3)
    file_space = ""
    if "space" in fields:
        file_space = _NRRD_SPACES.get(fields["space"].strip().lower(), "")
    elif "space dimension" in fields and int(fields["space dimension"]) != 3:
        raise ValueError(f"NRRD space dimension {fields['space dimension']} is not 3")
    if "space directions" in fields:
        vecs = re.findall(r"\([^)]*\)|none", fields["space directions"])
        spatial: list[NDArray[np.float64]] = []
        for text in vecs:
            vec = _nrrd_vector(text, "space directions")
            if vec is not None:
                spatial.append(vec)
        if len(spatial) != min(ndim, 3):
            raise ValueError(f"NRRD space directions {fields['space directions']!r} do not give 3 axes")
        if ndim == 2:
            spatial.append(np.cross(spatial[0], spatial[1]) / np.linalg.norm(np.cross(spatial[0], spatial[1])))
        m = np.stack(spatial, axis=1)
        spacing = np.linalg.norm(m, axis=0)
        if np.any(spacing == 0):
            raise ValueError(f"NRRD space directions contain a zero vector: {fields['space directions']!r}")
        direction = m / spacing
    elif "spacings" in fields:
        vals = [float(v) for v in fields["spacings"].split() if v.lower() != "nan"]
        if len(vals) < 2:
            raise ValueError(f"NRRD spacings {fields['spacings']!r} do not give the spatial axes")
        spacing = np.asarray((vals + [1.0])[:3])
        if np.any(spacing <= 0):
            raise ValueError(f"NRRD spacings must be positive, got {fields['spacings']!r}")
    if "space origin" in fields:
        o = _nrrd_vector(fields["space origin"], "space origin")
        if o is None or o.shape[0] < 2:
            raise ValueError(f"NRRD space origin {fields['space origin']!r} is not a vector")
        origin = np.resize(o, 3) if o.shape[0] == 3 else np.r_[o, 0.0]
    elif "axis mins" in fields:
        mins = [float(v) for v in fields["axis mins"].split() if v.lower() != "nan"]
        if len(mins) >= 3:
            origin = np.asarray(mins[:3])
    if file_space == "LAS":
        # LAS -> LPS flips y.
        flip = np.diag([1.0, -1.0, 1.0])
        origin, direction, file_space = flip @ origin, flip @ direction, "LPS"

    # Data.
    line_skip = int(fields.get("line skip", fields.get("lineskip", "0")))
    byte_skip = int(fields.get("byte skip", fields.get("byteskip", "0")))
    if "data file" in fields or "datafile" in fields:
        spec = fields.get("data file", fields.get("datafile", ""))
        files = _nrrd_data_files(p, spec, list_files)
        chunks = [_nrrd_decode(f.read_bytes(), encoding, line_skip, byte_skip, dtype, dims, f.name, len(files))
                  for f in files]
        buf = (b"\n" if encoding in ("ascii", "text", "txt") else b"").join(chunks)
    else:
        body = raw[header_end:]
        buf = _nrrd_decode(body, encoding, line_skip, byte_skip, dtype, dims, p.name)
    if encoding in ("ascii", "text", "txt"):
        values = np.array(buf.split(), dtype=np.float64)
        if values.size != int(np.prod(dims)):
            raise ValueError(f"NRRD {p.name!r} holds {values.size} ascii values, dims {dims} need {int(np.prod(dims))}")
        data = values.astype(dtype.newbyteorder("=")).reshape(dims[::-1])
    else:
        data = _from_bytes(buf, dtype, dims, f"NRRD data of {p.name!r}")
    vol = Volume(data=data, spacing=spacing, origin=origin, direction=direction, scalar_name=p.stem, space=file_space)
    return _to_space(vol, space)


def _nrrd_data_files(header: Path, spec: str, listed: list[str] | None) -> list[Path]:
    if listed is not None:
        names = listed
    else:
        parts = spec.split()
        if len(parts) >= 4 and "%" in parts[0]:
            lo, hi, step = int(parts[1]), int(parts[2]), int(parts[3])
            if step == 0:
                raise ValueError(f"NRRD data file step is 0 in {spec!r}")
            names = [parts[0] % i for i in range(lo, hi + (1 if step > 0 else -1), step)]
        else:
            names = [spec]
    return _existing_data_files(header, names, "NRRD")


def _nrrd_decode(body: bytes, encoding: str, line_skip: int, byte_skip: int, dtype: np.dtype[Any],
                 dims: tuple[int, int, int], name: str, n_files: int = 1) -> bytes:
    for _ in range(line_skip):
        body = body[body.index(b"\n") + 1:]
    if encoding == "raw":
        out = body
    elif encoding in ("gzip", "gz"):
        out = gzip.decompress(body)
    elif encoding in ("bzip2", "bz2"):
        out = bz2.decompress(body)
    elif encoding in ("ascii", "text", "txt"):
        return body
    else:
        raise ValueError(f"NRRD encoding {encoding!r} of {name!r} is not supported (raw, gzip, bzip2, ascii)")
    if byte_skip == -1:
        size = int(np.prod(dims)) * dtype.itemsize // n_files
        return out[len(out) - size:]
    return out[byte_skip:]


# ---------------------------------------------------------------------------------
# MetaImage
# ---------------------------------------------------------------------------------

_MET_TYPES = {
    "MET_CHAR": "i1", "MET_UCHAR": "u1", "MET_SHORT": "i2", "MET_USHORT": "u2", "MET_INT": "i4",
    "MET_UINT": "u4", "MET_LONG": "i4", "MET_ULONG": "u4", "MET_LONG_LONG": "i8", "MET_ULONG_LONG": "u8",
    "MET_FLOAT": "f4", "MET_DOUBLE": "f8",
}


def read_metaimage(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a MetaImage volume (``.mha`` with local data, ``.mhd`` + data file).

    World coordinates are ITK's: ``TransformMatrix`` lists the direction of index axis
    ``a`` as its ``a``-th triple (ITK's MetaImageIO), ``Offset`` is the first voxel's
    position, and the frame is LPS whatever ``AnatomicalOrientation`` says (as in ITK).
    """
    p = _check_file(Path(path), "MetaImage file")
    raw = p.read_bytes()
    fields: dict[str, str] = {}
    pos = 0
    list_files: list[str] | None = None
    while pos < len(raw):
        line, pos = _next_line(raw, pos)
        line = line.strip()
        if list_files is not None:
            if line:
                list_files.append(line)
            continue
        if not line:
            continue
        if "=" not in line:
            raise ValueError(f"MetaImage header line {line!r} of {p.name!r} is not 'Key = Value'")
        key, value = (s.strip() for s in line.split("=", 1))
        fields[key.lower()] = value
        if key.lower() == "elementdatafile":
            if value.upper().startswith("LIST"):
                list_files = []
                continue
            break  # the data (LOCAL) or nothing follows
    header_end = pos

    def need(key: str) -> str:
        if key.lower() not in fields:
            raise ValueError(f"MetaImage {p.name!r} has no '{key}' field")
        return fields[key.lower()]

    ndims = int(need("NDims"))
    sizes = [int(v) for v in need("DimSize").split()]
    if len(sizes) != ndims:
        raise ValueError(f"MetaImage DimSize {sizes} does not have NDims = {ndims} values")
    if ndims == 2:
        sizes.append(1)
    elif ndims != 3:
        raise ValueError(f"MetaImage {p.name!r} has NDims = {ndims}: only 2D/3D scalar images are read")
    dims = _dims(sizes, "MetaImage DimSize")
    channels = int(fields.get("elementnumberofchannels", "1"))
    if channels != 1:
        raise ValueError(f"MetaImage {p.name!r} has {channels} channels per voxel: only scalar images are read")
    etype = need("ElementType").upper()
    if etype not in _MET_TYPES:
        raise ValueError(f"MetaImage ElementType {etype!r} is not supported; expected one of {sorted(_MET_TYPES)}")
    msb = fields.get("elementbyteordermsb", fields.get("binarydatabyteordermsb", "False")).lower() == "true"
    dtype = np.dtype(_MET_TYPES[etype]).newbyteorder(">" if msb else "<")

    def floats(keys: tuple[str, ...], count: int, default: ArrayLike) -> NDArray[np.float64]:
        for k in keys:
            if k in fields:
                vals = [float(v) for v in fields[k].split()]
                if len(vals) != count:
                    raise ValueError(f"MetaImage {k} has {len(vals)} values, expected {count}: {fields[k]!r}")
                return np.asarray(vals)
        return np.asarray(default, dtype=np.float64)

    spacing = floats(("elementspacing", "elementsize"), ndims, [1.0] * ndims)
    origin = floats(("offset", "origin", "position"), ndims, [0.0] * ndims)
    matrix = floats(("transformmatrix", "rotation", "orientation"), ndims * ndims, np.eye(ndims).ravel())
    if ndims == 2:
        spacing, origin = np.r_[spacing, 1.0], np.r_[origin, 0.0]
        m2 = matrix.reshape(2, 2)
        matrix = np.eye(3)
        matrix[:2, :2] = m2
        matrix = matrix.ravel()
    if np.any(spacing <= 0):
        raise ValueError(f"MetaImage ElementSpacing must be positive, got {spacing.tolist()}")
    direction = matrix.reshape(3, 3).T  # triple a = direction of index axis a

    compressed = fields.get("compresseddata", "False").lower() == "true"
    header_size = int(fields.get("headersize", "0"))
    datafile = need("ElementDataFile")
    if datafile.upper() == "LOCAL":
        chunks = [raw[header_end:]]
    else:
        files = _met_data_files(p, datafile, list_files)
        chunks = [f.read_bytes() for f in files]
    n_bytes = int(np.prod(dims)) * dtype.itemsize
    out = []
    for chunk in chunks:
        if compressed:
            try:
                chunk = zlib.decompress(chunk)
            except zlib.error as exc:
                raise ValueError(f"MetaImage {p.name!r}: compressed data cannot be inflated ({exc})") from None
        if header_size == -1:
            chunk = chunk[len(chunk) - n_bytes // len(chunks):]
        elif header_size:
            chunk = chunk[header_size:]
        out.append(chunk)
    data = _from_bytes(b"".join(out), dtype, dims, f"MetaImage data of {p.name!r}")
    vol = Volume(data=data, spacing=spacing, origin=origin, direction=direction, scalar_name=p.stem, space="LPS")
    return _to_space(vol, space)


def _met_data_files(header: Path, spec: str, listed: list[str] | None) -> list[Path]:
    if listed is not None:
        names = listed
    else:
        parts = spec.split()
        if len(parts) >= 3 and "%" in parts[0]:
            lo, hi = int(parts[1]), int(parts[2])
            step = int(parts[3]) if len(parts) > 3 else 1
            names = [parts[0] % i for i in range(lo, hi + 1, step)]
        else:
            names = [spec]
    return _existing_data_files(header, names, "MetaImage")


def _existing_data_files(header: Path, names: list[str], what: str) -> list[Path]:
    """The data files ``names`` (relative to ``header``'s folder); each must exist."""
    files = [header.parent / n for n in names]
    for f in files:
        if not f.is_file():
            raise FileNotFoundError(f"{what} data file not found: {str(f)!r} (named by {header.name!r})")
    return files


# ---------------------------------------------------------------------------------
# VTK XML image data (.vti)
# ---------------------------------------------------------------------------------

_VTK_TYPES = {
    "Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2", "Int32": "i4", "UInt32": "u4",
    "Int64": "i8", "UInt64": "u8", "Float32": "f4", "Float64": "f8",
    "Char": "i1", "UnsignedChar": "u1", "Short": "i2", "UnsignedShort": "u2", "Int": "i4",
    "UnsignedInt": "u4", "Float": "f4", "Double": "f8",
}


def read_vti(path: str | os.PathLike[str], *, scalars: str | None = None) -> Volume:
    """Read a VTK XML ImageData file (``.vti``): ascii, binary or appended (raw or base64),
    uncompressed, zlib or lzma; several pieces are assembled into the whole extent.

    ``scalars`` names the point-data array (default: the active scalars, else the first).
    Multi-component arrays give their magnitude.
    """
    p = _check_file(Path(path), "VTI file")
    raw = p.read_bytes()
    appended = b""
    app_encoding = "raw"
    start = raw.find(b"<AppendedData")
    xml_bytes = raw
    if start >= 0:
        tag_end = raw.index(b">", start)
        m = re.search(rb'encoding\s*=\s*"([^"]+)"', raw[start:tag_end])
        app_encoding = m.group(1).decode() if m else "raw"
        under = raw.index(b"_", tag_end)
        stop = raw.rfind(b"</AppendedData>")
        appended = raw[under + 1:stop if stop > 0 else len(raw)]
        xml_bytes = raw[:start] + b"</VTKFile>"
    try:
        root = ET.fromstring(xml_bytes)
    except ET.ParseError as exc:
        raise ValueError(f"{p.name!r} is not a readable VTK XML file: {exc}") from None
    if root.tag != "VTKFile" or root.get("type") != "ImageData":
        raise ValueError(f"{p.name!r} is not a VTK ImageData file (VTKFile type={root.get('type')!r})")
    big = root.get("byte_order", "LittleEndian") == "BigEndian"
    header_dt = np.dtype({"UInt32": "u4", "UInt64": "u8"}.get(root.get("header_type", "UInt32"), "u4"))
    header_dt = header_dt.newbyteorder(">" if big else "<")
    compressor = root.get("compressor", "")
    image = root.find("ImageData")
    if image is None:
        raise ValueError(f"{p.name!r} has no <ImageData> element")
    whole = [int(v) for v in image.get("WholeExtent", "").split()]
    if len(whole) != 6:
        raise ValueError(f"{p.name!r}: ImageData WholeExtent {image.get('WholeExtent')!r} is not 6 integers")
    origin = _vec([float(v) for v in image.get("Origin", "0 0 0").split()], "VTI Origin")
    spacing = _vec([float(v) for v in image.get("Spacing", "1 1 1").split()], "VTI Spacing")
    if np.any(spacing <= 0):
        raise ValueError(f"VTI Spacing must be positive, got {spacing.tolist()} in {p.name!r}")
    dvals = [float(v) for v in image.get("Direction", "1 0 0 0 1 0 0 0 1").split()]
    if len(dvals) != 9:
        raise ValueError(f"VTI Direction must have 9 values, got {len(dvals)}")
    direction = np.asarray(dvals).reshape(3, 3)  # vtkImageData's row-major direction matrix
    dims = _dims([whole[1] - whole[0] + 1, whole[3] - whole[2] + 1, whole[5] - whole[4] + 1], "VTI extent")
    out: NDArray[Any] | None = None
    name = scalars
    for piece in image.findall("Piece"):
        ext = [int(v) for v in piece.get("Extent", "").split()]
        pd = piece.find("PointData")
        arrays = [] if pd is None else pd.findall("DataArray")
        if not arrays:
            continue
        if name is None:
            name = pd.get("Scalars") if pd is not None and pd.get("Scalars") else arrays[0].get("Name")
        chosen = [a for a in arrays if a.get("Name") == name]
        if not chosen:
            names = [a.get("Name") for a in arrays]
            raise ValueError(f"{p.name!r} has no point-data array {name!r}; it has {names}")
        arr = _vti_array(chosen[0], appended, app_encoding, header_dt, compressor, big, p.name)
        ncomp = int(chosen[0].get("NumberOfComponents", "1"))
        pdims = (ext[1] - ext[0] + 1, ext[3] - ext[2] + 1, ext[5] - ext[4] + 1)
        npts = int(np.prod(pdims))
        if arr.size != npts * ncomp:
            raise ValueError(f"{p.name!r}: array {name!r} has {arr.size} values, extent {ext} x {ncomp} needs {npts * ncomp}")
        if ncomp > 1:
            arr = np.linalg.norm(arr.reshape(npts, ncomp).astype(np.float64), axis=1).astype(np.float32)
        block = arr.reshape(pdims[::-1])
        if out is None:
            out = np.zeros(dims[::-1], dtype=block.dtype)
        out[ext[4] - whole[4]:ext[5] - whole[4] + 1, ext[2] - whole[2]:ext[3] - whole[2] + 1,
            ext[0] - whole[0]:ext[1] - whole[0] + 1] = block
    if out is None:
        raise ValueError(f"{p.name!r} has no point data to render")
    # Index 0 of the array is extent start, which VTK places at origin + D (e0 * spacing).
    origin = origin + direction @ (spacing * np.asarray(whole[0::2], dtype=np.float64))
    return Volume(data=out, spacing=spacing, origin=origin, direction=direction, scalar_name=name or "scalars")


def _vti_array(el: ET.Element, appended: bytes, app_encoding: str, header_dt: np.dtype[Any], compressor: str,
               big: bool, fname: str) -> NDArray[Any]:
    tname = el.get("type", "")
    if tname not in _VTK_TYPES:
        raise ValueError(f"{fname!r}: DataArray type {tname!r} is not supported")
    dtype = np.dtype(_VTK_TYPES[tname]).newbyteorder(">" if big else "<")
    fmt = el.get("format", "ascii")
    if fmt == "ascii":
        return np.array((el.text or "").split(), dtype=np.float64).astype(dtype.newbyteorder("="))
    if fmt == "binary":
        payload = _vti_blocks_base64((el.text or "").strip().encode(), header_dt, compressor, fname)
    elif fmt == "appended":
        offset = int(el.get("offset", "0"))
        if app_encoding == "base64":
            payload = _vti_blocks_base64(appended[offset:].split(b"<")[0].strip(), header_dt, compressor, fname)
        else:
            payload = _vti_blocks_raw(appended, offset, header_dt, compressor, fname)
    else:
        raise ValueError(f"{fname!r}: DataArray format {fmt!r} is not supported")
    if len(payload) % dtype.itemsize:
        raise ValueError(f"{fname!r}: {len(payload)} bytes of {tname} data is not a whole number of values")
    return np.frombuffer(payload, dtype=dtype).astype(dtype.newbyteorder("="))


def _decompress(block: bytes, compressor: str, fname: str) -> bytes:
    if compressor == "vtkZLibDataCompressor":
        return zlib.decompress(block)
    if compressor == "vtkLZMADataCompressor":
        return lzma.decompress(block)
    raise ValueError(f"{fname!r}: compressor {compressor!r} is not supported (zlib and lzma are)")


def _b64(text: bytes) -> bytes:
    return base64.b64decode(text + b"=" * (-len(text) % 4))


def _vti_blocks_raw(app: bytes, offset: int, hdt: np.dtype[Any], compressor: str, fname: str) -> bytes:
    hs = hdt.itemsize
    if not compressor:
        n = int(np.frombuffer(app, hdt, 1, offset)[0])
        return app[offset + hs:offset + hs + n]
    nblocks = int(np.frombuffer(app, hdt, 1, offset)[0])
    header = np.frombuffer(app, hdt, 3 + nblocks, offset).astype(np.int64)
    pos = offset + (3 + nblocks) * hs
    out = []
    for size in header[3:]:
        out.append(_decompress(app[pos:pos + int(size)], compressor, fname))
        pos += int(size)
    return b"".join(out)


def _vti_blocks_base64(text: bytes, hdt: np.dtype[Any], compressor: str, fname: str) -> bytes:
    hs = hdt.itemsize
    text = re.sub(rb"\s+", b"", text)
    if not compressor:
        # Header and data were encoded as one base64 stream.
        nchar = 4 * math.ceil(hs / 3)
        n = int(np.frombuffer(_b64(text[:nchar])[:hs], hdt)[0])
        try:
            buf = _b64(text[:4 * math.ceil((hs + n) / 3)])
        except ValueError:
            buf = b""
        if len(buf) >= hs + n:
            return buf[hs:hs + n]
        # Some writers encode the header as a base64 stream of its own.
        out = _b64(text[nchar:nchar + 4 * math.ceil(n / 3)])
        if len(out) < n:
            raise ValueError(f"{fname!r}: base64 data holds {len(out)} bytes, its header announces {n}")
        return out[:n]
    # Compressed: the header is base64-encoded on its own, then the blocks.
    nchar1 = 4 * math.ceil(hs / 3)
    nblocks = int(np.frombuffer(_b64(text[:nchar1])[:hs], hdt)[0])
    nchar = 4 * math.ceil((3 + nblocks) * hs / 3)
    header = np.frombuffer(_b64(text[:nchar])[:(3 + nblocks) * hs], hdt).astype(np.int64)
    body = _b64(text[nchar:nchar + 4 * math.ceil(int(header[3:].sum()) / 3)])
    blocks = []
    pos = 0
    for size in header[3:]:
        blocks.append(_decompress(body[pos:pos + int(size)], compressor, fname))
        pos += int(size)
    return b"".join(blocks)


# ---------------------------------------------------------------------------------
# Legacy VTK structured points
# ---------------------------------------------------------------------------------

_LEGACY_TYPES = {
    "unsigned_char": "u1", "char": "i1", "signed_char": "i1", "unsigned_short": "u2", "short": "i2",
    "unsigned_int": "u4", "int": "i4", "unsigned_long": "u8", "long": "i8", "float": "f4", "double": "f8",
    "vtktypeint64": "i8", "vtktypeuint64": "u8", "vtkidtype": "i8",
}


class _Tokens:
    """A cursor over a legacy VTK file: whitespace tokens, lines, and raw binary blocks."""

    def __init__(self, raw: bytes, name: str) -> None:
        self.raw, self.pos, self.name = raw, 0, name

    def line(self) -> str:
        text, self.pos = _next_line(self.raw, self.pos)
        return text

    def token(self) -> str | None:
        m = re.compile(rb"\s*(\S+)").match(self.raw, self.pos)
        if not m:
            self.pos = len(self.raw)
            return None
        self.pos = m.end()
        return m.group(1).decode("latin-1")

    def binary(self, n: int) -> bytes:
        # Binary data starts after the newline that ends the keyword line.
        nl = self.raw.find(b"\n", self.pos)
        self.pos = (nl + 1) if nl >= 0 else self.pos
        if self.pos + n > len(self.raw):
            raise ValueError(f"{self.name!r} ends inside binary data ({n} bytes expected at byte {self.pos})")
        out = self.raw[self.pos:self.pos + n]
        self.pos += n
        return out

    def values(self, n: int, dtype: np.dtype[Any], binary: bool) -> NDArray[Any]:
        if binary:
            big = dtype.newbyteorder(">")
            return np.frombuffer(self.binary(n * dtype.itemsize), big).astype(dtype.newbyteorder("="))
        out = np.empty(n, dtype=np.float64)
        m = re.compile(rb"\s*(\S+)")
        for i in range(n):
            t = m.match(self.raw, self.pos)
            if not t:
                raise ValueError(f"{self.name!r} ends after {i} of {n} ascii values")
            out[i] = float(t.group(1))
            self.pos = t.end()
        return out.astype(dtype)

    def skip_ascii(self, n: int) -> None:
        self.values(n, np.dtype("f8"), False)


def read_vtk_structured_points(path: str | os.PathLike[str], *, scalars: str | None = None) -> Volume:
    """Read a legacy VTK file with ``DATASET STRUCTURED_POINTS`` (ASCII or BINARY).

    ``scalars`` names the point-data array (SCALARS, VECTORS or a FIELD array); the
    default is the first SCALARS array. Vectors give their magnitude.
    """
    p = _check_file(Path(path), "VTK file")
    tok = _Tokens(p.read_bytes(), p.name)
    first = tok.line()
    if not first.startswith("# vtk DataFile"):
        raise ValueError(f"{p.name!r} is not a legacy VTK file (first line {first[:40]!r})")
    tok.line()  # title
    mode = tok.line().strip().upper()
    if mode not in ("ASCII", "BINARY"):
        raise ValueError(f"{p.name!r}: third line must be ASCII or BINARY, got {mode!r}")
    binary = mode == "BINARY"
    kw = tok.token()
    if (kw or "").upper() != "DATASET":
        raise ValueError(f"{p.name!r}: expected DATASET, got {kw!r}")
    kind = (tok.token() or "").upper()
    if kind != "STRUCTURED_POINTS":
        raise ValueError(f"{p.name!r} holds a {kind} dataset; only STRUCTURED_POINTS is a volume")
    dims: tuple[int, int, int] | None = None
    spacing = np.ones(3)
    origin = np.zeros(3)
    direction = np.eye(3)
    found: NDArray[Any] | None = None
    found_name = ""
    section = ""
    n_points = n_cells = 0
    while True:
        t = tok.token()
        if t is None:
            break
        key = t.upper()
        if key == "DIMENSIONS":
            dims = _dims([tok.token(), tok.token(), tok.token()], "VTK DIMENSIONS")
        elif key in ("SPACING", "ASPECT_RATIO"):
            spacing = np.asarray([float(tok.token() or "nan") for _ in range(3)])
        elif key == "ORIGIN":
            origin = np.asarray([float(tok.token() or "nan") for _ in range(3)])
        elif key == "DIRECTION":
            direction = np.asarray([float(tok.token() or "nan") for _ in range(9)]).reshape(3, 3)
        elif key == "METADATA":
            while tok.pos < len(tok.raw) and tok.line().strip() != "":
                pass
        elif key == "POINT_DATA":
            section, n_points = "point", int(tok.token() or 0)
        elif key == "CELL_DATA":
            section, n_cells = "cell", int(tok.token() or 0)
        elif key in ("SCALARS", "VECTORS", "NORMALS", "TENSORS", "TEXTURE_COORDINATES", "COLOR_SCALARS"):
            aname = tok.token() or ""
            n = n_points if section == "point" else n_cells
            if key == "COLOR_SCALARS":
                ncomp = int(tok.token() or 1)
                dt = np.dtype("u1") if binary else np.dtype("f4")
            else:
                tname = (tok.token() or "").lower()
                if tname not in _LEGACY_TYPES:
                    raise ValueError(f"{p.name!r}: data type {tname!r} of {aname!r} is not supported")
                dt = np.dtype(_LEGACY_TYPES[tname])
                ncomp = {"VECTORS": 3, "NORMALS": 3, "TENSORS": 9}.get(key, 1)
                if key == "SCALARS":
                    rest = tok.line().split()
                    ncomp = int(rest[0]) if rest else 1
                    mark = tok.pos
                    if (tok.token() or "").upper() == "LOOKUP_TABLE":
                        tok.token()
                    else:
                        tok.pos = mark
                elif key == "TEXTURE_COORDINATES":
                    ncomp = int(tok.token() or 1)
            vals = tok.values(n * ncomp, dt, binary)
            want = (scalars is None and key == "SCALARS" and found is None) or scalars == aname
            if section == "point" and want and found is None:
                found = vals if ncomp == 1 else np.linalg.norm(vals.reshape(n, ncomp).astype(np.float64), axis=1)
                found_name = aname
        elif key == "LOOKUP_TABLE":
            tok.token()
            n = int(tok.token() or 0)
            tok.values(4 * n, np.dtype("u1") if binary else np.dtype("f4"), binary)
        elif key == "FIELD":
            tok.token()
            n_arrays = int(tok.token() or 0)
            for _ in range(n_arrays):
                aname = tok.token() or ""
                ncomp = int(tok.token() or 1)
                ntup = int(tok.token() or 0)
                tname = (tok.token() or "").lower()
                if tname not in _LEGACY_TYPES:
                    raise ValueError(f"{p.name!r}: field array type {tname!r} is not supported")
                vals = tok.values(ncomp * ntup, np.dtype(_LEGACY_TYPES[tname]), binary)
                if section == "point" and scalars == aname and found is None:
                    found = vals if ncomp == 1 else np.linalg.norm(vals.reshape(ntup, ncomp).astype(np.float64), axis=1)
                    found_name = aname
        else:
            raise ValueError(f"{p.name!r}: unexpected keyword {t!r} at byte {tok.pos}")
    if dims is None:
        raise ValueError(f"{p.name!r} has no DIMENSIONS")
    if not np.all(np.isfinite(spacing)) or np.any(spacing <= 0):
        raise ValueError(f"{p.name!r}: SPACING must be positive, got {spacing.tolist()}")
    if found is None:
        raise ValueError(f"{p.name!r} has no point-data array" + (f" named {scalars!r}" if scalars else ""))
    if found.size != int(np.prod(dims)):
        raise ValueError(f"{p.name!r}: {found.size} point values for DIMENSIONS {dims}")
    return Volume(data=found.reshape(dims[::-1]), spacing=spacing, origin=origin, direction=direction,
                  scalar_name=found_name)


# ---------------------------------------------------------------------------------
# NIfTI and DICOM (optional dependencies)
# ---------------------------------------------------------------------------------


def _optional(module: str, pkg: str, what: str) -> Any:
    try:
        return __import__(module)
    except ImportError as exc:
        raise ImportError(f"reading {what} needs {pkg}, which is not installed; " + _EXTRA_HINT.format(pkg=pkg)) from exc


def read_nifti(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a NIfTI-1/2 volume (``.nii``, ``.nii.gz``) with nibabel (optional dependency).

    The voxel -> RAS affine (sform or qform, as nibabel chooses) gives spacing, direction
    and origin; the scaling ``scl_slope``/``scl_inter`` is applied when present (the data
    then become float). 4D files with one volume are squeezed.
    """
    p = _check_file(Path(path), "NIfTI file")
    nib = _optional("nibabel", "nibabel", "NIfTI files")
    img = nib.load(str(p))
    data = np.asanyarray(img.dataobj)
    while data.ndim > 3 and data.shape[-1] == 1:
        data = data[..., 0]
    if data.ndim == 2:
        data = data[:, :, None]
    if data.ndim != 3:
        raise ValueError(f"NIfTI {p.name!r} has shape {data.shape}: only one 3D scalar volume is read")
    aff = np.asarray(img.affine, dtype=np.float64)
    lin = aff[:3, :3]
    spacing = np.linalg.norm(lin, axis=0)
    if np.any(spacing == 0):
        raise ValueError(f"NIfTI {p.name!r} has a zero voxel size in its affine: {aff.tolist()}")
    vol = Volume(data=np.ascontiguousarray(data.transpose(2, 1, 0)), spacing=spacing, origin=aff[:3, 3],
                 direction=lin / spacing, scalar_name=p.name.split(".")[0], space="RAS")
    return _to_space(vol, space)


def read_dicom(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a DICOM series (a directory of slices) or a single slice, with pydicom.

    Slices are grouped by SeriesInstanceUID (the largest series is read; a warning
    names the others), sorted along the slice normal by ImagePositionPatient, and
    spaced by the median distance between positions. RescaleSlope/Intercept are
    applied (CT values become Hounsfield units; integers stay integers when they can).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"DICOM file or directory not found: {str(p)!r}")
    pydicom = _optional("pydicom", "pydicom", "DICOM series")
    from pydicom.errors import InvalidDicomError

    files = sorted(f for f in p.iterdir() if f.is_file()) if p.is_dir() else [p]
    slices = []
    for f in files:
        try:
            ds = pydicom.dcmread(str(f), force=not p.is_dir())
        except (InvalidDicomError, OSError):
            continue
        if "PixelData" in ds:
            slices.append(ds)
    if not slices:
        raise ValueError(f"no DICOM images found in {str(p)!r}")
    series: dict[str, list[Any]] = {}
    for ds in slices:
        series.setdefault(str(ds.get("SeriesInstanceUID", "")), []).append(ds)
    uid = max(series, key=lambda k: len(series[k]))
    if len(series) > 1:
        others = {k: len(v) for k, v in series.items() if k != uid}
        warnings.warn(f"{str(p)!r} holds {len(series)} series; reading {uid!r} ({len(series[uid])} slices), "
                      f"ignoring {others}", stacklevel=2)
    group = series[uid]
    if int(group[0].get("NumberOfFrames", 1) or 1) > 1:
        raise ValueError(f"{str(p)!r}: multi-frame DICOM images are not supported")
    iop = np.asarray(group[0].get("ImageOrientationPatient", [1, 0, 0, 0, 1, 0]), dtype=np.float64)
    row_dir, col_dir = iop[:3], iop[3:]
    normal = np.cross(row_dir, col_dir)
    if np.linalg.norm(normal) < 1e-6:
        raise ValueError(f"DICOM ImageOrientationPatient {iop.tolist()} is degenerate")
    normal /= np.linalg.norm(normal)
    ipp = np.asarray([ds.get("ImagePositionPatient", [0, 0, i]) for i, ds in enumerate(group)], dtype=np.float64)
    order = np.argsort(ipp @ normal, kind="stable")
    group = [group[i] for i in order]
    ipp = ipp[order]
    ps = [float(v) for v in group[0].get("PixelSpacing", [1.0, 1.0])]
    if len(group) > 1:
        gaps = np.diff(ipp @ normal)
        dz = float(np.median(gaps))
        if gaps.min() <= 1e-6 * max(abs(dz), 1.0):
            raise ValueError(f"DICOM series in {str(p)!r} has {int(np.sum(gaps <= 1e-6 * max(abs(dz), 1.0)))} "
                             f"slice(s) at the position of another (duplicates or several acquisitions)")
        if np.max(np.abs(gaps - dz)) > 1e-3 * max(dz, 1.0) + 1e-4:
            warnings.warn(f"DICOM slice spacing is not uniform ({gaps.min():.4g} .. {gaps.max():.4g}); using {dz:.4g}",
                          stacklevel=2)
        # Along the line through the slice positions (not the normal): a tilted gantry
        # gives a sheared grid, which the direction matrix represents as it is.
        span = ipp[-1] - ipp[0]
        slice_dir = span / np.linalg.norm(span)
        dz = float(np.linalg.norm(span)) / (len(group) - 1)
    else:
        dz = float(group[0].get("SpacingBetweenSlices", group[0].get("SliceThickness", 1.0)) or 1.0)
        slice_dir = normal
    shape = (int(group[0].Rows), int(group[0].Columns))
    try:
        frames = [np.asarray(ds.pixel_array) for ds in group]
    except Exception as exc:
        raise ValueError(f"DICOM pixel data of {str(p)!r} cannot be decoded: {exc}") from exc
    if any(f.shape != shape for f in frames):
        raise ValueError(f"DICOM slices of {str(p)!r} differ in size; expected {shape} for every slice")
    raw = np.stack(frames)
    rescale = [(float(ds.get("RescaleSlope", 1.0) or 1.0), float(ds.get("RescaleIntercept", 0.0) or 0.0))
               for ds in group]
    slope, inter = rescale[0]
    if any(k != slope or b != inter for k, b in rescale):
        data = np.stack([f * k + b for f, (k, b) in zip(frames, rescale)]).astype(np.float32)
    elif slope == int(slope) and inter == int(inter) and raw.dtype.kind in "iu":
        wide = raw.astype(np.int64) * int(slope) + int(inter)
        lo, hi = int(wide.min()), int(wide.max())
        # The stored type if it still holds the values, else the narrowest signed one.
        for cand in (raw.dtype, np.dtype("i2"), np.dtype("i4"), np.dtype("i8")):
            info = np.iinfo(cand)
            if info.min <= lo and hi <= info.max and cand.itemsize >= raw.dtype.itemsize:
                data = wide.astype(cand)
                break
    else:
        data = (raw * slope + inter).astype(np.float32)
    direction = np.stack([row_dir, col_dir, slice_dir], axis=1)
    vol = Volume(data=data, spacing=np.array([ps[1], ps[0], dz]), origin=ipp[0], direction=direction,
                 scalar_name=str(group[0].get("Modality", "dicom")), space="LPS")
    return _to_space(vol, space)

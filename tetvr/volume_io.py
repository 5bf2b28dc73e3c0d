"""Reading image volumes from files: NRRD, MetaImage, VTK (XML image data and legacy
structured points), NIfTI, DICOM and headerless raw voxels.

About this stage
----------------
Each reader turns a file into a :class:`~tetvr.volume.Volume` (the grid, its dtype and
its index -> world placement; see :mod:`tetvr.volume` for the conventions). NRRD
(``.nrrd``, ``.nhdr`` with detached or sliced data), MetaImage (``.mha``, ``.mhd``), VTK
XML image data (``.vti``: ascii, base64, appended raw, zlib/lzma) and legacy VTK
structured points (``.vtk``) are parsed here with numpy only, from their specifications
(teem's NRRD format page, ITK's MetaIO, VTK's file formats). NIfTI (``.nii``,
``.nii.gz``) and DICOM series need the optional extra ``pip install tetvr[volumes]``
(nibabel, pydicom).

Hostile files. A header is a claim, not a fact: every size it declares is checked,
before anything of that size is allocated, against what the file can hold (its bytes;
1032 times its bytes for deflate data, the most deflate can compress) and against this
machine's memory. Compressed data are inflated no further than the declared size (a
4 MB gzip of zeros no longer inflates to 4 GiB before the size check), a pattern of data
file names is counted before a name is built, and pieces of a ``.vti`` must cover the
whole extent: nothing is filled with invented zeros.
"""

from __future__ import annotations

import base64
import bz2
import lzma
import math
import os
import re
import stat
import warnings
import xml.etree.ElementTree as ET
import zlib
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._checks import check_input_file
from .volume import SPACES, Volume, _vec

__all__ = [
    "read_volume",
    "read_raw",
    "read_nrrd",
    "read_metaimage",
    "read_vti",
    "read_vtk_structured_points",
    "read_nifti",
    "read_dicom",
    "VOLUME_SUFFIXES",
]

#: File name endings :func:`read_volume` recognises (a directory is a DICOM series).
VOLUME_SUFFIXES = (".nrrd", ".nhdr", ".mha", ".mhd", ".vti", ".vtk", ".nii", ".nii.gz", ".dcm")

_EXTRA_HINT = "install the optional volume readers with  pip install tetvr[volumes]  (or pip install {pkg})"

# deflate (zlib, gzip) never compresses by more than 1032:1 (RFC 1951's longest match
# costs at least 2 bits per 258 bytes), so deflate data of n bytes hold at most 1032 n.
_DEFLATE_MAX_RATIO = 1032


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
    if _is_dir(p):
        return read_dicom(p, space=space)
    check_input_file(p, "volume file")
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


def _is_dir(p: Path) -> bool:
    try:
        return stat.S_ISDIR(os.stat(p).st_mode)
    except (OSError, ValueError):
        return False  # check_input_file says why


def _to_space(vol: Volume, space: str) -> Volume:
    return vol.in_space(space) if vol.space and vol.space != space else vol


def _check_file(path: Path, what: str) -> Path:
    return Path(check_input_file(path, what))


def _dims(value: Any, name: str = "dims") -> tuple[int, int, int]:
    try:
        dims = tuple(int(v) for v in value)
    except (TypeError, ValueError, OverflowError):
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


def _size_text(nbytes: int) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes} bytes"


def _memory_limit() -> int:
    """This machine's physical memory in bytes: no volume larger than it can be read."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - platforms without sysconf
        return 1 << 40


def _check_declared(dims: Sequence[int], dtype: np.dtype[Any], what: str, *, holds: int | None = None,
                    how: str = "") -> int:
    """The bytes that ``dims`` voxels of ``dtype`` take, if the file can hold them (``holds``
    bytes at most, ``how`` says why) and this machine's memory can; else a ValueError
    naming the declared dimensions. Called before anything of that size is allocated."""
    n = math.prod(int(d) for d in dims) * dtype.itemsize
    declared = f"{what} declares {' x '.join(str(int(d)) for d in dims)} voxels of {dtype.name} ({_size_text(n)})"
    if holds is not None and n > holds:
        raise ValueError(f"{declared}, but its data{how} can hold at most {_size_text(holds)}: "
                         "the header is wrong or the data are truncated")
    limit = _memory_limit()
    if n > limit:
        raise ValueError(f"{declared}, more than this machine's memory ({_size_text(limit)})")
    return n


def _inflate(data: bytes, codec: str, limit: int, what: str) -> bytes:
    """Decompress ``data`` (``zlib``, ``gzip``, ``bz2`` or ``lzma``) to at most ``limit``
    bytes, the size its header declares: a bomb stops there instead of filling memory."""
    def new() -> Any:
        if codec == "zlib":
            return zlib.decompressobj()
        if codec == "gzip":
            return zlib.decompressobj(wbits=31)
        return bz2.BZ2Decompressor() if codec == "bz2" else lzma.LZMADecompressor()

    d = new()
    try:
        out = d.decompress(data, limit + 1)
        # gzip and bzip2 files may hold several members one after the other.
        while codec in ("gzip", "bz2") and d.eof and d.unused_data.strip(b"\x00") and len(out) <= limit:
            rest, d = d.unused_data, new()
            out += d.decompress(rest, limit + 1 - len(out))
    except (zlib.error, OSError, EOFError, lzma.LZMAError, ValueError) as exc:
        raise ValueError(f"{what}: the {codec} data cannot be inflated ({exc})") from None
    if len(out) > limit:
        raise ValueError(f"{what}: the {codec} data inflate to more than the {limit} bytes the header declares "
                         "(a decompression bomb, or a header that understates the size)")
    if not d.eof:
        raise ValueError(f"{what}: the {codec} data end before their end-of-stream marker "
                         f"({len(out)} of {limit} bytes inflated): the file is truncated")
    return out


def _header_int(fields: dict[str, str], key: str, fmt: str, fname: str, *, shown: str | None = None,
                minimum: int | None = None, default: int | None = None) -> int:
    """Field ``key`` of a NRRD/MetaImage header as an integer; errors name the field and the file."""
    shown = shown or key
    if key not in fields:
        if default is not None:
            return default
        raise ValueError(f"{fmt} file {fname!r} has no '{shown}' field")
    try:
        value = int(fields[key])
    except ValueError:
        raise ValueError(f"{fmt} file {fname!r}: field '{shown}' must be an integer, got {fields[key]!r}") from None
    if minimum is not None and value < minimum:
        raise ValueError(f"{fmt} file {fname!r}: field '{shown}' must be >= {minimum}, got {value}")
    return value


def _header_numbers(text: str, key: str, fmt: str, fname: str, kind: type = float) -> list[Any]:
    try:
        return [kind(v) for v in text.replace(",", " ").split()]
    except ValueError:
        what = "integers" if kind is int else "numbers"
        raise ValueError(f"{fmt} file {fname!r}: field '{key}' must be {what}, got {text!r}") from None


def _pattern_names(pattern: str, lo: int, hi: int, step: int, count_needed: int, fmt: str, field: str,
                   fname: str, needed_by: str) -> list[str]:
    """The data file names ``pattern % i`` for i from ``lo`` to ``hi`` by ``step``: counted
    (without building any) against the ``count_needed`` the sizes imply, before they are made."""
    if step == 0:
        raise ValueError(f"{fmt} file {fname!r}: field '{field}' has step 0")
    count = len(range(lo, hi + (1 if step > 0 else -1), step))
    if count != count_needed:
        raise ValueError(f"{fmt} file {fname!r}: field '{field}' names {count} files ({lo} to {hi} by {step}), "
                         f"but {needed_by} need {count_needed}")
    try:
        return [pattern % i for i in range(lo, hi + (1 if step > 0 else -1), step)]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{fmt} file {fname!r}: field '{field}' has a bad file name pattern {pattern!r} ({exc})") from None


def _existing_data_files(header: Path, names: list[str], what: str) -> list[Path]:
    """The data files ``names`` (relative to ``header``'s folder); each must be a regular file."""
    return [Path(check_input_file(header.parent / n, f"{what} data file", named_by=header.name)) for n in names]


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
    need = header_bytes + math.prod(d) * dt.itemsize
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
_NRRD_CODECS = {"gzip": "gzip", "gz": "gzip", "bzip2": "bz2", "bz2": "bz2"}
_NRRD_TEXT = ("ascii", "text", "txt")


def _nrrd_vector(text: str, field: str, fname: str) -> NDArray[np.float64] | None:
    text = text.strip()
    if text == "none":
        return None
    m = re.fullmatch(r"\(([^)]*)\)", text)
    if not m:
        raise ValueError(f"NRRD file {fname!r}: field '{field}': expected a vector like (1,0,0), got {text!r}")
    return np.asarray(_header_numbers(m.group(1), field, "NRRD", fname), dtype=np.float64)


def read_nrrd(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a NRRD volume (``.nrrd`` attached or ``.nhdr`` detached, incl. slice lists).

    Supports encodings raw, gzip, bzip2 and ascii; ``space directions``/``space origin``
    or ``spacings``; ``data file`` as one name, a printf pattern with ``min max step
    [subdim]`` (its count must be the one the sizes imply) or ``LIST``; ``byte skip``
    (-1, data at the end, with raw encoding) and ``line skip``. Header errors name the
    field and the file.
    """
    p = _check_file(Path(path), "NRRD file")
    raw = p.read_bytes()
    if not raw.startswith(b"NRRD000"):
        raise ValueError(f"{p.name!r} is not a NRRD file (it does not start with 'NRRD000x')")
    # Header: lines up to the first empty line (attached data follows it) or the end.
    fields: dict[str, str] = {}
    pos = raw.index(b"\n") + 1 if b"\n" in raw else len(raw)
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
            raise ValueError(f"NRRD file {p.name!r}: header line {line[:80]!r} is not 'field: value'")
        key, value = line.split(":", 1)
        key = key.strip().lower()
        value = value.strip()
        if key == "data file" or key == "datafile":
            if value.startswith("LIST"):
                list_files = []
        fields[key] = value
    header_end = pos
    fname = p.name

    def need(key: str) -> str:
        if key not in fields:
            raise ValueError(f"NRRD file {fname!r} has no '{key}' field")
        return fields[key]

    ndim = _header_int(fields, "dimension", "NRRD", fname, minimum=1)
    sizes = _header_numbers(need("sizes"), "sizes", "NRRD", fname, int)
    if len(sizes) != ndim:
        raise ValueError(f"NRRD file {fname!r}: field 'sizes' lists {len(sizes)} values ({fields['sizes']!r}) "
                         f"for dimension {ndim}")
    if any(s < 1 for s in sizes):
        raise ValueError(f"NRRD file {fname!r}: field 'sizes' must be positive, got {fields['sizes']!r}")
    file_sizes = list(sizes)
    type_name = need("type").lower()
    if type_name not in _NRRD_TYPE:
        raise ValueError(f"NRRD file {fname!r}: field 'type' {type_name!r} is not supported (block types are not)")
    dtype = _NRRD_TYPE[type_name]
    encoding = fields.get("encoding", "raw").lower()
    if encoding not in ("raw",) + _NRRD_TEXT + tuple(_NRRD_CODECS):
        raise ValueError(f"NRRD file {fname!r}: field 'encoding' {encoding!r} is not supported "
                         "(raw, gzip, bzip2, ascii)")
    if dtype.itemsize > 1 and encoding not in _NRRD_TEXT:
        endian = need("endian").lower()
        if endian not in ("little", "big"):
            raise ValueError(f"NRRD file {fname!r}: field 'endian' must be little or big, got {endian!r}")
        dtype = dtype.newbyteorder("<" if endian == "little" else ">")
    # A leading axis of length 1 (e.g. 'kinds: scalar domain ...') is a scalar volume too.
    lead = 0
    if ndim == 4 and sizes[0] == 1:
        lead = 1
    elif ndim == 2:
        sizes = sizes + [1]
    elif ndim != 3:
        raise ValueError(f"NRRD file {fname!r} has dimension {ndim} with sizes {sizes}: only scalar 3D volumes are read")
    dims = _dims(sizes[lead:lead + 3], f"NRRD file {fname!r}: field 'sizes'")
    n_bytes = _check_declared(dims, dtype, f"NRRD file {fname!r}")

    origin, direction, spacing, file_space = _nrrd_geometry(fields, ndim, fname)

    # Data.
    line_skip = _header_int(fields, "line skip" if "line skip" in fields else "lineskip", "NRRD", fname,
                            minimum=0, default=0)
    byte_skip = _header_int(fields, "byte skip" if "byte skip" in fields else "byteskip", "NRRD", fname,
                            minimum=-1, default=0)
    if byte_skip == -1 and encoding != "raw":
        raise ValueError(f"NRRD file {fname!r}: field 'byte skip' -1 is only allowed with raw encoding, "
                         f"not {encoding!r}")
    if "data file" in fields or "datafile" in fields:
        key = "data file" if "data file" in fields else "datafile"
        files = _nrrd_data_files(p, fields[key], key, list_files, file_sizes)
        bodies = [(f.read_bytes(), f.name) for f in files]
    else:
        bodies = [(raw[header_end:], fname)]
    if _NRRD_CODECS.get(encoding) == "gzip":
        # deflate cannot hold more than 1032 times its size: refuse before inflating.
        _check_declared(dims, dtype, f"NRRD file {fname!r}", how=f" ({encoding})",
                        holds=_DEFLATE_MAX_RATIO * sum(len(b) for b, _ in bodies))
    chunks: list[bytes] = []
    got = 0
    for body, name in bodies:
        left = max(n_bytes - got, 0)
        chunk = _nrrd_decode(body, encoding, line_skip, byte_skip, left, n_bytes // len(bodies), name)
        got += len(chunk)
        chunks.append(chunk)
    buf = (b"\n" if encoding in _NRRD_TEXT else b"").join(chunks)
    if encoding in _NRRD_TEXT:
        values = buf.split()
        if len(values) != math.prod(dims):
            raise ValueError(f"NRRD file {fname!r} holds {len(values)} ascii values, dims {dims} need {math.prod(dims)}")
        try:
            data = np.array(values, dtype=np.float64).astype(dtype.newbyteorder("=")).reshape(dims[::-1])
        except ValueError:
            raise ValueError(f"NRRD file {fname!r}: the ascii data hold a value that is not a number") from None
    else:
        data = _from_bytes(buf, dtype, dims, f"NRRD data of {fname!r}")
    vol = Volume(data=data, spacing=spacing, origin=origin, direction=direction, scalar_name=p.stem, space=file_space)
    return _to_space(vol, space)


def _nrrd_geometry(fields: dict[str, str], ndim: int, fname: str) -> tuple[
        NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], str]:
    """``(origin, direction, spacing, space)`` from a NRRD header's fields."""
    origin = np.zeros(3)
    direction = np.eye(3)
    spacing = np.ones(3)
    file_space = ""
    if "space" in fields:
        file_space = _NRRD_SPACES.get(fields["space"].strip().lower(), "")
    elif "space dimension" in fields and _header_int(fields, "space dimension", "NRRD", fname) != 3:
        raise ValueError(f"NRRD file {fname!r}: field 'space dimension' is {fields['space dimension']}, not 3")
    if "space directions" in fields:
        text = fields["space directions"]
        spatial = [v for v in (_nrrd_vector(t, "space directions", fname)
                               for t in re.findall(r"\([^)]*\)|none", text)) if v is not None]
        if len(spatial) != min(ndim, 3) or any(v.shape != spatial[0].shape for v in spatial):
            raise ValueError(f"NRRD file {fname!r}: field 'space directions' {text!r} does not give "
                             f"{min(ndim, 3)} axes of one length")
        if ndim == 2:
            if spatial[0].shape != (3,):
                raise ValueError(f"NRRD file {fname!r}: field 'space directions' {text!r} are not 3D vectors")
            normal = np.cross(spatial[0], spatial[1])
            spatial.append(normal / (np.linalg.norm(normal) or 1.0))
        m = np.stack(spatial, axis=1)
        spacing = np.linalg.norm(m, axis=0)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)) or np.any(spacing == 0):
            raise ValueError(f"NRRD file {fname!r}: field 'space directions' must be 3 finite non-zero 3D vectors, "
                             f"got {text!r}")
        direction = m / spacing
    elif "spacings" in fields:
        vals = [v for v in _header_numbers(fields["spacings"].lower().replace("nan", ""), "spacings", "NRRD", fname)]
        if len(vals) < 2:
            raise ValueError(f"NRRD file {fname!r}: field 'spacings' {fields['spacings']!r} does not give the spatial axes")
        spacing = np.asarray((vals + [1.0])[:3])
        if not np.all(np.isfinite(spacing)) or np.any(spacing <= 0):
            raise ValueError(f"NRRD file {fname!r}: field 'spacings' must be positive, got {fields['spacings']!r}")
    if "space origin" in fields:
        o = _nrrd_vector(fields["space origin"], "space origin", fname)
        if o is None or not 2 <= o.shape[0] <= 3:
            raise ValueError(f"NRRD file {fname!r}: field 'space origin' {fields['space origin']!r} is not a 2D/3D vector")
        origin = o if o.shape[0] == 3 else np.r_[o, 0.0]
    elif "axis mins" in fields:
        mins = _header_numbers(fields["axis mins"].lower().replace("nan", ""), "axis mins", "NRRD", fname)
        if len(mins) >= 3:
            origin = np.asarray(mins[:3])
    if file_space == "LAS":
        # LAS -> LPS flips y.
        flip = np.diag([1.0, -1.0, 1.0])
        origin, direction, file_space = flip @ origin, flip @ direction, "LPS"
    return origin, direction, spacing, file_space


def _nrrd_data_files(header: Path, spec: str, field: str, listed: list[str] | None, sizes: list[int]) -> list[Path]:
    """The detached data files; a pattern's count is checked against the sizes before any name is built."""
    fname = header.name
    if listed is not None:
        names = listed  # one line of the header each: no more than the header holds
    else:
        parts = spec.split()
        if len(parts) >= 4 and "%" in parts[0]:
            lo, hi, step, *sub = _header_numbers(" ".join(parts[1:6]), field, "NRRD", fname, int)
            # teem: the files hold the slabs of axes [subdim, dimension): their count is fixed.
            subdim = sub[0] if sub else len(sizes) - 1
            if not 1 <= subdim <= len(sizes):
                raise ValueError(f"NRRD file {fname!r}: field '{field}' has subdim {subdim}, outside 1..{len(sizes)}")
            names = _pattern_names(parts[0], lo, hi, step, math.prod(sizes[subdim:]), "NRRD", field, fname,
                                   f"sizes {sizes} (one file per slab of axes {subdim}..{len(sizes) - 1})")
        else:
            names = [spec]
    if not names:
        raise ValueError(f"NRRD file {fname!r}: field '{field}' names no data files")
    return _existing_data_files(header, names, "NRRD")


def _nrrd_decode(body: bytes, encoding: str, line_skip: int, byte_skip: int, left: int, per_file: int,
                 name: str) -> bytes:
    """One data file's voxel bytes (or ascii text): lines and bytes skipped, inflated to at
    most the ``left`` bytes still needed (plus the bytes to skip)."""
    start = 0
    for i in range(line_skip):  # positions only: no copy of the body per line
        nl = body.find(b"\n", start)
        if nl < 0:
            raise ValueError(f"NRRD data {name!r}: 'line skip' is {line_skip}, but the data hold only {i} lines")
        start = nl + 1
    body = body[start:] if start else body
    if encoding in _NRRD_TEXT:
        return body
    if encoding in _NRRD_CODECS:
        out = _inflate(body, _NRRD_CODECS[encoding], left + byte_skip, f"NRRD data {name!r}")
    else:
        out = body
    if byte_skip == -1:
        return out[max(len(out) - per_file, 0):]
    if byte_skip > len(out):
        raise ValueError(f"NRRD data {name!r}: 'byte skip' is {byte_skip}, but the data hold {len(out)} bytes")
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
    Header errors name the field and the file.
    """
    p = _check_file(Path(path), "MetaImage file")
    raw = p.read_bytes()
    fname = p.name
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
            raise ValueError(f"MetaImage file {fname!r}: header line {line[:80]!r} is not 'Key = Value'")
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
            raise ValueError(f"MetaImage file {fname!r} has no '{key}' field")
        return fields[key.lower()]

    ndims = _header_int(fields, "ndims", "MetaImage", fname, shown="NDims", minimum=1)
    sizes = _header_numbers(need("DimSize"), "DimSize", "MetaImage", fname, int)
    if len(sizes) != ndims:
        raise ValueError(f"MetaImage file {fname!r}: field 'DimSize' {sizes} does not have NDims = {ndims} values")
    if ndims == 2:
        sizes.append(1)
    elif ndims != 3:
        raise ValueError(f"MetaImage file {fname!r} has NDims = {ndims}: only 2D/3D scalar images are read")
    dims = _dims(sizes, f"MetaImage file {fname!r}: field 'DimSize'")
    channels = _header_int(fields, "elementnumberofchannels", "MetaImage", fname,
                           shown="ElementNumberOfChannels", default=1)
    if channels != 1:
        raise ValueError(f"MetaImage file {fname!r} has {channels} channels per voxel: only scalar images are read")
    etype = need("ElementType").upper()
    if etype not in _MET_TYPES:
        raise ValueError(f"MetaImage file {fname!r}: field 'ElementType' {etype!r} is not supported; "
                         f"expected one of {sorted(_MET_TYPES)}")
    msb = fields.get("elementbyteordermsb", fields.get("binarydatabyteordermsb", "False")).lower() == "true"
    dtype = np.dtype(_MET_TYPES[etype]).newbyteorder(">" if msb else "<")
    n_bytes = _check_declared(dims, dtype, f"MetaImage file {fname!r}")

    def floats(keys: tuple[str, ...], shown: str, count: int, default: ArrayLike) -> NDArray[np.float64]:
        for k in keys:
            if k in fields:
                vals = _header_numbers(fields[k], shown, "MetaImage", fname)
                if len(vals) != count or not all(math.isfinite(v) for v in vals):
                    raise ValueError(f"MetaImage file {fname!r}: field '{shown}' must be {count} finite numbers, "
                                     f"got {fields[k]!r}")
                return np.asarray(vals)
        return np.asarray(default, dtype=np.float64)

    spacing = floats(("elementspacing", "elementsize"), "ElementSpacing", ndims, [1.0] * ndims)
    origin = floats(("offset", "origin", "position"), "Offset", ndims, [0.0] * ndims)
    matrix = floats(("transformmatrix", "rotation", "orientation"), "TransformMatrix", ndims * ndims,
                    np.eye(ndims).ravel())
    if ndims == 2:
        spacing, origin = np.r_[spacing, 1.0], np.r_[origin, 0.0]
        m2 = matrix.reshape(2, 2)
        matrix = np.eye(3)
        matrix[:2, :2] = m2
        matrix = matrix.ravel()
    if np.any(spacing <= 0):
        raise ValueError(f"MetaImage file {fname!r}: field 'ElementSpacing' must be positive, got {spacing.tolist()}")
    direction = matrix.reshape(3, 3).T  # triple a = direction of index axis a

    compressed = fields.get("compresseddata", "False").lower() == "true"
    header_size = _header_int(fields, "headersize", "MetaImage", fname, shown="HeaderSize", minimum=-1, default=0)
    if header_size == -1 and compressed:
        raise ValueError(f"MetaImage file {fname!r}: field 'HeaderSize' -1 (data at the end of the file) "
                         "cannot be used with CompressedData")
    datafile = need("ElementDataFile")
    if datafile.upper() == "LOCAL":
        chunks = [raw[header_end:]]
    else:
        files = _met_data_files(p, datafile, list_files, dims)
        chunks = [f.read_bytes() for f in files]
    if compressed:
        # deflate cannot hold more than 1032 times its size: refuse before inflating.
        _check_declared(dims, dtype, f"MetaImage file {fname!r}", how=" (CompressedData)",
                        holds=_DEFLATE_MAX_RATIO * sum(len(c) for c in chunks))
    out = []
    got = 0
    for chunk in chunks:
        if compressed:
            chunk = _inflate(chunk, "zlib", max(n_bytes - got, 0) + header_size, f"MetaImage file {fname!r}")
        if header_size == -1:
            chunk = chunk[max(len(chunk) - n_bytes // len(chunks), 0):]
        elif header_size:
            chunk = chunk[header_size:]
        got += len(chunk)
        out.append(chunk)
    data = _from_bytes(b"".join(out), dtype, dims, f"MetaImage data of {fname!r}")
    vol = Volume(data=data, spacing=spacing, origin=origin, direction=direction, scalar_name=p.stem, space="LPS")
    return _to_space(vol, space)


def _met_data_files(header: Path, spec: str, listed: list[str] | None, dims: tuple[int, int, int]) -> list[Path]:
    """The ElementDataFile files; a pattern's count (one file per slice, as MetaIO reads
    them) is checked against DimSize before any name is built."""
    fname = header.name
    if listed is not None:
        names = listed  # one line of the header each: no more than the header holds
    else:
        parts = spec.split()
        if len(parts) >= 3 and "%" in parts[0]:
            lo, hi, *rest = _header_numbers(" ".join(parts[1:4]), "ElementDataFile", "MetaImage", fname, int)
            names = _pattern_names(parts[0], lo, hi, rest[0] if rest else 1, dims[2], "MetaImage", "ElementDataFile",
                                   fname, f"DimSize {list(dims)} (one file per slice)")
        else:
            names = [spec]
    if not names:
        raise ValueError(f"MetaImage file {fname!r}: field 'ElementDataFile' names no data files")
    return _existing_data_files(header, names, "MetaImage")


# ---------------------------------------------------------------------------------
# VTK XML image data (.vti)
# ---------------------------------------------------------------------------------

_VTK_TYPES = {
    "Int8": "i1", "UInt8": "u1", "Int16": "i2", "UInt16": "u2", "Int32": "i4", "UInt32": "u4",
    "Int64": "i8", "UInt64": "u8", "Float32": "f4", "Float64": "f8",
    "Char": "i1", "UnsignedChar": "u1", "Short": "i2", "UnsignedShort": "u2", "Int": "i4",
    "UnsignedInt": "u4", "Float": "f4", "Double": "f8",
}
_VTK_CODECS = {"vtkZLibDataCompressor": "zlib", "vtkLZMADataCompressor": "lzma"}


def read_vti(path: str | os.PathLike[str], *, scalars: str | None = None) -> Volume:
    """Read a VTK XML ImageData file (``.vti``): ascii, binary or appended (raw or base64),
    uncompressed, zlib or lzma; several pieces are assembled into the whole extent.

    ``scalars`` names the point-data array (default: the active scalars, else the first).
    Multi-component arrays give their magnitude. The pieces must cover the whole extent:
    a part left uncovered is an error naming it, never filled with zeros.
    """
    p = _check_file(Path(path), "VTI file")
    raw = p.read_bytes()
    fname = p.name
    appended = b""
    app_encoding = "raw"
    start = raw.find(b"<AppendedData")
    xml_bytes = raw
    if start >= 0:
        tag_end = raw.find(b">", start)
        under = raw.find(b"_", tag_end) if tag_end >= 0 else -1
        if under < 0:
            raise ValueError(f"VTI file {fname!r}: <AppendedData> has no '_' before its data")
        m = re.search(rb'encoding\s*=\s*"([^"]+)"', raw[start:tag_end])
        app_encoding = m.group(1).decode("latin-1") if m else "raw"
        stop = raw.rfind(b"</AppendedData>")
        appended = raw[under + 1:stop if stop > under else len(raw)]
        xml_bytes = raw[:start] + b"</VTKFile>"
    try:
        root = ET.fromstring(xml_bytes)
    except ET.ParseError as exc:
        raise ValueError(f"{fname!r} is not a readable VTK XML file: {exc}") from None
    if root.tag != "VTKFile" or root.get("type") != "ImageData":
        raise ValueError(f"{fname!r} is not a VTK ImageData file (VTKFile type={root.get('type')!r})")
    big = root.get("byte_order", "LittleEndian") == "BigEndian"
    header_dt = np.dtype({"UInt32": "u4", "UInt64": "u8"}.get(root.get("header_type", "UInt32"), "u4"))
    header_dt = header_dt.newbyteorder(">" if big else "<")
    compressor = root.get("compressor", "")
    if compressor and compressor not in _VTK_CODECS:
        raise ValueError(f"VTI file {fname!r}: compressor {compressor!r} is not supported (zlib and lzma are)")
    image = root.find("ImageData")
    if image is None:
        raise ValueError(f"{fname!r} has no <ImageData> element")
    whole = _vti_extent(image.get("WholeExtent", ""), "ImageData WholeExtent", fname)
    origin = _vec(_vti_numbers(image.get("Origin", "0 0 0"), "ImageData Origin", fname), f"VTI {fname!r} Origin")
    spacing = _vec(_vti_numbers(image.get("Spacing", "1 1 1"), "ImageData Spacing", fname), f"VTI {fname!r} Spacing")
    if np.any(spacing <= 0):
        raise ValueError(f"VTI Spacing must be positive, got {spacing.tolist()} in {fname!r}")
    dvals = _vti_numbers(image.get("Direction", "1 0 0 0 1 0 0 0 1"), "ImageData Direction", fname)
    if len(dvals) != 9:
        raise ValueError(f"VTI file {fname!r}: ImageData Direction must have 9 values, got {len(dvals)}")
    direction = np.asarray(dvals).reshape(3, 3)  # vtkImageData's row-major direction matrix
    dims = _dims([whole[1] - whole[0] + 1, whole[3] - whole[2] + 1, whole[5] - whole[4] + 1], "VTI extent")
    name = scalars
    blocks: list[tuple[list[int], NDArray[Any]]] = []
    for index, piece in enumerate(image.findall("Piece")):
        what = f"VTI file {fname!r}: Piece {index}"
        ext = _vti_extent(piece.get("Extent", ""), f"Piece {index} Extent", fname)
        if any(ext[2 * a] < whole[2 * a] or ext[2 * a + 1] > whole[2 * a + 1] for a in range(3)):
            raise ValueError(f"{what} Extent {ext} reaches outside the WholeExtent {whole}")
        pd = piece.find("PointData")
        arrays = [] if pd is None else pd.findall("DataArray")
        if not arrays:
            continue
        if name is None:
            name = pd.get("Scalars") if pd is not None and pd.get("Scalars") else arrays[0].get("Name")
        chosen = [a for a in arrays if a.get("Name") == name]
        if not chosen:
            names = [a.get("Name") for a in arrays]
            raise ValueError(f"{fname!r} has no point-data array {name!r}; it has {names}")
        el = chosen[0]
        what = f"{what}, array {name!r}"
        ncomp = _header_int(dict(el.attrib), "NumberOfComponents", "VTI", fname, minimum=1, default=1)
        if ncomp > 64:  # VTK's scalars have 1 to 4 components, tensors 9; more is not an image
            raise ValueError(f"{what}: NumberOfComponents {ncomp} is not a volume's scalar or vector")
        tname = el.get("type", "")
        if tname not in _VTK_TYPES:
            raise ValueError(f"{what}: DataArray type {tname!r} is not supported")
        dtype = np.dtype(_VTK_TYPES[tname])
        if not blocks:  # the whole extent is allocated below: refuse what memory cannot hold, up front
            _check_declared(dims, dtype if ncomp == 1 else np.dtype("f4"), f"VTI file {fname!r} (WholeExtent {whole})")
        pdims = (ext[1] - ext[0] + 1, ext[3] - ext[2] + 1, ext[5] - ext[4] + 1)
        npts = math.prod(pdims)
        arr = _vti_array(el, dtype.newbyteorder(">" if big else "<"), npts * ncomp, appended, app_encoding,
                         header_dt, compressor, what)
        if ncomp > 1:
            arr = np.linalg.norm(arr.reshape(npts, ncomp).astype(np.float64), axis=1).astype(np.float32)
        blocks.append((ext, arr.reshape(pdims[::-1])))
    if not blocks:
        raise ValueError(f"{fname!r} has no point data to render")
    out = _vti_assemble(blocks, whole, dims, fname)
    # Index 0 of the array is extent start, which VTK places at origin + D (e0 * spacing).
    origin = origin + direction @ (spacing * np.asarray(whole[0::2], dtype=np.float64))
    return Volume(data=out, spacing=spacing, origin=origin, direction=direction, scalar_name=name or "scalars")


def _vti_numbers(text: str, what: str, fname: str) -> list[float]:
    return _header_numbers(text, what, "VTI", fname)


def _vti_extent(text: str, what: str, fname: str) -> list[int]:
    ext = _header_numbers(text, what, "VTI", fname, int)
    if len(ext) != 6 or any(ext[2 * a] > ext[2 * a + 1] for a in range(3)):
        raise ValueError(f"VTI file {fname!r}: {what} {text!r} is not 6 integers x0 x1 y0 y1 z0 z1 with each "
                         "start <= its end")
    return ext


def _vti_assemble(blocks: list[tuple[list[int], NDArray[Any]]], whole: list[int], dims: tuple[int, int, int],
                  fname: str) -> NDArray[Any]:
    """The pieces placed into the whole extent, which they must cover (pieces may share points).

    Both arrays are of the whole extent's size, which :func:`_check_declared` has bounded."""
    shape = dims[::-1]
    slices = [tuple(slice(ext[2 * a] - whole[2 * a], ext[2 * a + 1] - whole[2 * a] + 1) for a in (2, 1, 0))
              for ext, _ in blocks]
    filled = np.zeros(shape, dtype=bool)
    for sl in slices:
        filled[sl] = True
    if not filled.all():
        missing = ~filled
        box = []
        for axis in (2, 1, 0):  # x, y, z of the (z, y, x) array
            idx = np.nonzero(missing.any(axis=tuple(a for a in range(3) if a != axis)))[0]
            box += [int(idx.min()) + whole[2 * (2 - axis)], int(idx.max()) + whole[2 * (2 - axis)]]
        raise ValueError(f"VTI file {fname!r}: the pieces leave part of WholeExtent {' '.join(map(str, whole))} "
                         f"uncovered: {int(missing.sum())} points within extent {' '.join(map(str, box))} have no "
                         "data (they are not filled with invented values)")
    out = np.empty(shape, dtype=np.result_type(*[b.dtype for _, b in blocks]))
    for sl, (_, block) in zip(slices, blocks):
        out[sl] = block
    return out


def _vti_array(el: ET.Element, dtype: np.dtype[Any], n_values: int, appended: bytes, app_encoding: str,
               header_dt: np.dtype[Any], compressor: str, what: str) -> NDArray[Any]:
    """The ``n_values`` values of one DataArray; every size its headers declare is checked first."""
    nbytes = n_values * dtype.itemsize
    fmt = el.get("format", "ascii")
    if fmt == "ascii":
        tokens = (el.text or "").split()
        if len(tokens) != n_values:
            raise ValueError(f"{what} holds {len(tokens)} ascii values, its extent needs {n_values}")
        try:
            return np.array(tokens, dtype=np.float64).astype(dtype.newbyteorder("="))
        except ValueError:
            raise ValueError(f"{what}: the ascii data hold a value that is not a number") from None
    if fmt == "binary":
        payload = _vti_blocks_base64((el.text or "").strip().encode(), header_dt, compressor, nbytes, what)
    elif fmt == "appended":
        try:
            offset = int(el.get("offset", "0"))
        except ValueError:
            offset = -1
        if offset < 0:
            raise ValueError(f"{what}: offset must be an integer >= 0, got {el.get('offset')!r}")
        if offset > len(appended):
            raise ValueError(f"{what}: offset {offset} is past the {len(appended)} bytes of appended data")
        if app_encoding == "base64":
            payload = _vti_blocks_base64(appended[offset:].split(b"<")[0].strip(), header_dt, compressor, nbytes, what)
        else:
            payload = _vti_blocks_raw(appended, offset, header_dt, compressor, nbytes, what)
    else:
        raise ValueError(f"{what}: DataArray format {fmt!r} is not supported")
    return np.frombuffer(payload, dtype=dtype).astype(dtype.newbyteorder("="))


def _b64(text: bytes, what: str) -> bytes:
    try:
        return base64.b64decode(text + b"=" * (-len(text) % 4))
    except ValueError as exc:
        raise ValueError(f"{what}: the base64 data cannot be decoded ({exc})") from None


def _vti_block_sizes(head: list[int], nbytes: int, what: str) -> list[int]:
    """Uncompressed size of each block of a compressed array's header ``[n, size, last, ...]``."""
    nblocks, block, last = head[:3]
    sizes = [block] * (nblocks - 1) + [last or block] if nblocks else []
    if sum(sizes) != nbytes or any(s <= 0 for s in sizes):
        raise ValueError(f"{what}: its compression header declares {sum(sizes)} bytes in {nblocks} blocks "
                         f"of {block} (last {last}), but its extent needs {nbytes}")
    return sizes


def _vti_inflate_blocks(data: bytes, head: list[int], sizes: list[int], compressor: str, what: str) -> bytes:
    comp = head[3:]
    if any(c < 0 for c in comp) or sum(comp) > len(data):
        raise ValueError(f"{what}: its compressed blocks of {sum(comp)} bytes do not fit in the {len(data)} "
                         "bytes that follow their header (truncated)")
    out, pos = [], 0
    for i, (c, size) in enumerate(zip(comp, sizes)):
        block = _inflate(data[pos:pos + c], _VTK_CODECS[compressor], size, f"{what}, block {i}")
        if len(block) != size:
            raise ValueError(f"{what}: block {i} inflates to {len(block)} bytes, its header declares {size}")
        out.append(block)
        pos += c
    return b"".join(out)


def _vti_blocks_raw(app: bytes, offset: int, hdt: np.dtype[Any], compressor: str, nbytes: int, what: str) -> bytes:
    hs = hdt.itemsize

    def header(count: int) -> list[int]:
        if offset + count * hs > len(app):
            raise ValueError(f"{what}: the appended data end inside its header ({count} entries at offset {offset})")
        return [int(v) for v in np.frombuffer(app, hdt, count, offset).tolist()]

    if not compressor:
        n = header(1)[0]
        if n != nbytes:
            raise ValueError(f"{what}: its header declares {n} bytes, its extent needs {nbytes}")
        if offset + hs + n > len(app):
            raise ValueError(f"{what}: the appended data end {offset + hs + n - len(app)} bytes early (truncated)")
        return app[offset + hs:offset + hs + n]
    nblocks = header(1)[0]
    head = header(3 + nblocks)  # checked against the data left before it is read
    sizes = _vti_block_sizes(head, nbytes, what)
    return _vti_inflate_blocks(app[offset + (3 + nblocks) * hs:], head, sizes, compressor, what)


def _vti_blocks_base64(text: bytes, hdt: np.dtype[Any], compressor: str, nbytes: int, what: str) -> bytes:
    hs = hdt.itemsize
    text = re.sub(rb"\s+", b"", text)
    nchar1 = 4 * math.ceil(hs / 3)
    first = _b64(text[:nchar1], what)
    if len(first) < hs:
        raise ValueError(f"{what}: the base64 data end inside their header")
    n = int(np.frombuffer(first[:hs], hdt)[0])
    if not compressor:
        if n != nbytes:
            raise ValueError(f"{what}: its header declares {n} bytes, its extent needs {nbytes}")
        # Header and data encoded as one base64 stream ...
        try:
            buf = _b64(text[:4 * math.ceil((hs + n) / 3)], what)
        except ValueError:
            buf = b""
        if len(buf) >= hs + n:
            return buf[hs:hs + n]
        # ... or, by some writers, the header as a base64 stream of its own.
        out = _b64(text[nchar1:nchar1 + 4 * math.ceil(n / 3)], what)
        if len(out) < n:
            raise ValueError(f"{what}: base64 data holds {len(out)} bytes, its header announces {n}")
        return out[:n]
    # Compressed: the header is base64-encoded on its own, then the blocks.
    nchar = 4 * math.ceil((3 + n) * hs / 3)
    if nchar > len(text):
        raise ValueError(f"{what}: its header declares {n} blocks, more than the base64 data can hold")
    head = [int(v) for v in np.frombuffer(_b64(text[:nchar], what)[:(3 + n) * hs], hdt).tolist()]
    if len(head) != 3 + n:
        raise ValueError(f"{what}: the base64 data end inside their header")
    sizes = _vti_block_sizes(head, nbytes, what)
    body = _b64(text[nchar:nchar + 4 * math.ceil(max(sum(head[3:]), 0) / 3)], what)
    return _vti_inflate_blocks(body, head, sizes, compressor, what)


# ---------------------------------------------------------------------------------
# Legacy VTK structured points
# ---------------------------------------------------------------------------------

_LEGACY_TYPES = {
    "unsigned_char": "u1", "char": "i1", "signed_char": "i1", "unsigned_short": "u2", "short": "i2",
    "unsigned_int": "u4", "int": "i4", "unsigned_long": "u8", "long": "i8", "float": "f4", "double": "f8",
    "vtktypeint64": "i8", "vtktypeuint64": "u8", "vtkidtype": "i8",
}
_LEGACY_TOKEN = re.compile(rb"\s*(\S+)")


class _Tokens:
    """A cursor over a legacy VTK file: whitespace tokens, lines, and raw binary blocks.

    Counts are bounded by what is left of the file before anything is allocated."""

    def __init__(self, raw: bytes, name: str) -> None:
        self.raw, self.pos, self.name = raw, 0, name

    def line(self) -> str:
        text, self.pos = _next_line(self.raw, self.pos)
        return text

    def token(self) -> str | None:
        m = _LEGACY_TOKEN.match(self.raw, self.pos)
        if not m:
            self.pos = len(self.raw)
            return None
        self.pos = m.end()
        return m.group(1).decode("latin-1")

    def count(self, what: str, *, minimum: int = 0) -> int:
        t = self.token()
        try:
            n = int(t) if t is not None else None
        except ValueError:
            n = None
        if n is None or n < minimum:
            raise ValueError(f"VTK file {self.name!r}: {what} must be an integer >= {minimum}, got {t!r}")
        return n

    def binary(self, n: int, what: str) -> bytes:
        # Binary data starts after the newline that ends the keyword line.
        nl = self.raw.find(b"\n", self.pos)
        self.pos = (nl + 1) if nl >= 0 else self.pos
        if self.pos + n > len(self.raw):
            raise ValueError(f"VTK file {self.name!r}: {what}: {n} bytes of binary data are declared at byte "
                             f"{self.pos}, but the file ends {len(self.raw) - self.pos} bytes later")
        out = self.raw[self.pos:self.pos + n]
        self.pos += n
        return out

    def values(self, n: int, dtype: np.dtype[Any], binary: bool, what: str) -> NDArray[Any]:
        if binary:
            big = dtype.newbyteorder(">")
            return np.frombuffer(self.binary(n * dtype.itemsize, what), big).astype(dtype.newbyteorder("="))
        if n == 0:
            return np.zeros(0, dtype)
        left = len(self.raw) - self.pos
        if n > left:  # each ascii value takes at least one byte
            raise ValueError(f"VTK file {self.name!r}: {what}: {n} values are declared, but only {left} bytes are left")
        parts = self.raw[self.pos:].split(maxsplit=n)
        if len(parts) < n:
            raise ValueError(f"VTK file {self.name!r}: {what}: the file ends after {len(parts)} of {n} ascii values")
        self.pos = len(self.raw) - (len(parts[n]) if len(parts) > n else 0)
        try:
            return np.array(parts[:n], dtype=np.float64).astype(dtype)
        except ValueError:
            raise ValueError(f"VTK file {self.name!r}: {what}: a value is not a number") from None


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

    def floats(key: str, n: int) -> NDArray[np.float64]:
        vals = [tok.token() for _ in range(n)]
        try:
            return np.asarray([float(v) for v in vals])  # type: ignore[arg-type]
        except (TypeError, ValueError):
            raise ValueError(f"VTK file {p.name!r}: {key} must be {n} numbers, got {vals}") from None

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
            dims = _dims([tok.token(), tok.token(), tok.token()], f"VTK file {p.name!r}: DIMENSIONS")
        elif key in ("SPACING", "ASPECT_RATIO"):
            spacing = floats(key, 3)
        elif key == "ORIGIN":
            origin = floats(key, 3)
        elif key == "DIRECTION":
            direction = floats(key, 9).reshape(3, 3)
        elif key == "METADATA":
            while tok.pos < len(tok.raw) and tok.line().strip() != "":
                pass
        elif key == "POINT_DATA":
            section, n_points = "point", tok.count("POINT_DATA count")
            if dims is not None and n_points != math.prod(dims):
                raise ValueError(f"VTK file {p.name!r}: POINT_DATA {n_points} does not match DIMENSIONS {dims} "
                                 f"({math.prod(dims)} points)")
            # Every point value takes a byte at least (ascii: a digit and a separator).
            left, least = len(tok.raw) - tok.pos, n_points * (1 if binary else 2) - (0 if binary else 1)
            if least > left:
                raise ValueError(f"VTK file {p.name!r}: DIMENSIONS {dims} and POINT_DATA declare {n_points} points, "
                                 f"but only {left} bytes of the file are left for their values")
        elif key == "CELL_DATA":
            section, n_cells = "cell", tok.count("CELL_DATA count")
        elif key in ("SCALARS", "VECTORS", "NORMALS", "TENSORS", "TEXTURE_COORDINATES", "COLOR_SCALARS"):
            aname = tok.token() or ""
            what = f"{key} {aname!r}"
            n = n_points if section == "point" else n_cells
            if key == "COLOR_SCALARS":
                ncomp = tok.count(f"{what} components", minimum=1)
                dt = np.dtype("u1") if binary else np.dtype("f4")
            else:
                tname = (tok.token() or "").lower()
                if tname not in _LEGACY_TYPES:
                    raise ValueError(f"{p.name!r}: data type {tname!r} of {aname!r} is not supported")
                dt = np.dtype(_LEGACY_TYPES[tname])
                ncomp = {"VECTORS": 3, "NORMALS": 3, "TENSORS": 9}.get(key, 1)
                if key == "SCALARS":
                    rest = tok.line().split()
                    ncomp = int(rest[0]) if rest and rest[0].isdigit() else 0 if rest else 1
                    if not 1 <= ncomp <= 4:
                        raise ValueError(f"VTK file {p.name!r}: {what} must have 1 to 4 components, got {rest[0]!r}")
                    mark = tok.pos
                    if (tok.token() or "").upper() == "LOOKUP_TABLE":
                        tok.token()
                    else:
                        tok.pos = mark
                elif key == "TEXTURE_COORDINATES":
                    ncomp = tok.count(f"{what} components", minimum=1)
            vals = tok.values(n * ncomp, dt, binary, what)
            want = (scalars is None and key == "SCALARS" and found is None) or scalars == aname
            if section == "point" and want and found is None:
                found = vals if ncomp == 1 else np.linalg.norm(vals.reshape(n, ncomp).astype(np.float64), axis=1)
                found_name = aname
        elif key == "LOOKUP_TABLE":
            tok.token()
            n = tok.count("LOOKUP_TABLE size")
            tok.values(4 * n, np.dtype("u1") if binary else np.dtype("f4"), binary, "LOOKUP_TABLE")
        elif key == "FIELD":
            tok.token()
            for _ in range(tok.count("FIELD array count")):  # each array consumes tokens: bounded by the file
                aname = tok.token() or ""
                what = f"FIELD array {aname!r}"
                ncomp = tok.count(f"{what} components", minimum=1)
                ntup = tok.count(f"{what} tuples")
                tname = (tok.token() or "").lower()
                if tname not in _LEGACY_TYPES:
                    raise ValueError(f"{p.name!r}: field array type {tname!r} is not supported")
                vals = tok.values(ncomp * ntup, np.dtype(_LEGACY_TYPES[tname]), binary, what)
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
    if found.size != math.prod(dims):
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
    then become float). 4D files with one volume are squeezed. The declared dimensions
    are checked against the file's size and this machine's memory before any voxel is read.
    """
    p = _check_file(Path(path), "NIfTI file")
    nib = _optional("nibabel", "nibabel", "NIfTI files")
    try:
        img = nib.load(str(p))
        shape = tuple(int(v) for v in img.shape)
        dtype = np.dtype(img.get_data_dtype())
        offset = int(getattr(img.dataobj, "offset", 0) or 0)
    except Exception as exc:  # nibabel's ImageFileError, gzip's BadGzipFile, struct errors, ...
        raise ValueError(f"cannot read NIfTI file {p.name!r}: {type(exc).__name__}: {exc}") from exc
    size = p.stat().st_size
    gz = p.name.lower().endswith(".gz")
    _check_declared(shape, dtype, f"NIfTI file {p.name!r}", how=" (gzip)" if gz else "",
                    holds=size * _DEFLATE_MAX_RATIO if gz else max(size - offset, 0))
    try:
        data = np.asanyarray(img.dataobj)
    except Exception as exc:  # truncated or corrupt data
        raise ValueError(f"cannot read the voxels of NIfTI file {p.name!r}: {type(exc).__name__}: {exc}") from exc
    while data.ndim > 3 and data.shape[-1] == 1:
        data = data[..., 0]
    if data.ndim == 2:
        data = data[:, :, None]
    if data.ndim != 3:
        raise ValueError(f"NIfTI {p.name!r} has shape {data.shape}: only one 3D scalar volume is read")
    aff = np.asarray(img.affine, dtype=np.float64)
    lin = aff[:3, :3]
    spacing = np.linalg.norm(lin, axis=0)
    if np.any(spacing == 0) or not np.all(np.isfinite(aff)):
        raise ValueError(f"NIfTI {p.name!r} has a zero or non-finite voxel size in its affine: {aff.tolist()}")
    if data.dtype.kind == "f" and not np.all(np.isfinite(data)):
        raise ValueError(f"NIfTI {p.name!r}: {int(np.count_nonzero(~np.isfinite(data)))} voxels are NaN or Inf "
                         "(after its scl_slope/scl_inter scaling)")
    vol = Volume(data=np.ascontiguousarray(data.transpose(2, 1, 0)), spacing=spacing, origin=aff[:3, 3],
                 direction=lin / spacing, scalar_name=p.name.split(".")[0], space="RAS")
    return _to_space(vol, space)


def read_dicom(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a DICOM series (a directory of slices) or a single slice, with pydicom.

    Slices are grouped by SeriesInstanceUID (the largest series is read; a warning
    names the others), sorted along the slice normal by ImagePositionPatient, and
    spaced by the median distance between positions. RescaleSlope/Intercept are
    applied (CT values become Hounsfield units; integers stay integers when they can);
    they must be finite, and the rescaled values are computed in a type that holds them.
    """
    p = Path(path)
    is_dir = _is_dir(p)
    if not is_dir:
        check_input_file(p, "DICOM file or directory")
    pydicom = _optional("pydicom", "pydicom", "DICOM series")
    from pydicom.errors import InvalidDicomError

    files = sorted(f for f in p.iterdir() if f.is_file()) if is_dir else [p]
    slices = []
    for f in files:
        try:
            ds = pydicom.dcmread(str(f), force=not is_dir)
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
    data = _dicom_rescaled(frames, [_dicom_rescale(ds, p) for ds in group])
    direction = np.stack([row_dir, col_dir, slice_dir], axis=1)
    vol = Volume(data=data, spacing=np.array([ps[1], ps[0], dz]), origin=ipp[0], direction=direction,
                 scalar_name=str(group[0].get("Modality", "dicom")), space="LPS")
    return _to_space(vol, space)


def _dicom_rescale(ds: Any, where: Path) -> tuple[float, float]:
    """A slice's (RescaleSlope, RescaleIntercept): finite, the slope non-zero; absent -> (1, 0)."""
    out = []
    for key, default in (("RescaleSlope", 1.0), ("RescaleIntercept", 0.0)):
        value = ds.get(key)
        try:
            number = default if value is None or str(value).strip() == "" else float(value)
        except (TypeError, ValueError):
            number = math.nan
        slope = key == "RescaleSlope"
        if not math.isfinite(number) or (slope and number == 0):
            raise ValueError(f"DICOM {str(where)!r}: {key} must be a finite{' non-zero' if slope else ''} number, "
                             f"got {str(value)!r} (slice {str(ds.get('SOPInstanceUID', '?'))!r})")
        out.append(number)
    return out[0], out[1]


def _dicom_rescaled(frames: list[NDArray[Any]], rescale: list[tuple[float, float]]) -> NDArray[Any]:
    """``frame * slope + intercept`` per slice, in a type that holds every value: the
    stored integer type or a wider one when slope and intercept are integers and the
    range fits (checked in float64 before any integer arithmetic, so nothing wraps),
    else float32, or float64 beyond float32's range."""
    raw = np.stack(frames)
    lo_hi = []
    for f, (k, b) in zip(frames, rescale):
        ends = (float(f.min()) * k + b, float(f.max()) * k + b)
        lo_hi += [min(ends), max(ends)]
    lo, hi = min(lo_hi), max(lo_hi)
    integral = all(k == int(k) and b == int(b) for k, b in rescale)
    if integral and raw.dtype.kind in "iu" and -2.0**62 < lo and hi < 2.0**62 and len(set(rescale)) == 1:
        (k, b), = set(rescale)
        wide = raw.astype(np.int64) * int(k) + int(b)
        ilo, ihi = int(wide.min()), int(wide.max())
        # The stored type if it still holds the values, else the narrowest signed one.
        for cand in (raw.dtype, np.dtype("i2"), np.dtype("i4"), np.dtype("i8")):
            info = np.iinfo(cand)
            if info.min <= ilo and ihi <= info.max and cand.itemsize >= raw.dtype.itemsize:
                return wide.astype(cand)
    f32 = np.finfo(np.float32).max
    out_dtype = np.float32 if -f32 <= lo and hi <= f32 else np.float64
    return np.stack([f.astype(np.float64) * k + b for f, (k, b) in zip(frames, rescale)]).astype(out_dtype)

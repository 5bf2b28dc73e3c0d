"""Reading image volumes from files: NRRD, MetaImage, NIfTI and DICOM through SimpleITK;
VTK image files (:mod:`tetvr.io.volume_vtk`); headerless raw voxels.

About this stage
----------------
Each reader turns a file into a :class:`~tetvr.volume.volume.Volume` (the grid, its dtype and
its index -> world placement; see :mod:`tetvr.volume.volume` for the conventions). NRRD
(``.nrrd``, ``.nhdr``), MetaImage (``.mha``, ``.mhd``), NIfTI (``.nii``, ``.nii.gz``)
and DICOM (a series in a directory, or one ``.dcm`` slice) are read by ITK through
SimpleITK, the reader clinical and research tools share: its geometry (spacing,
origin, direction matrix, LPS world frame), DICOM series grouping, slice ordering and
rescaling are ITK's (the bridge, and the NIfTI and DICOM readers: :mod:`tetvr.io.volume_itk`).
It needs the optional extra ``pip install tetvr[volumes]``.
VTK's XML image data and legacy structured points, which ITK does not read (or reads
without choosing an array), are read by :mod:`tetvr.io.volume_vtk`.

Hostile files. ITK allocates what a header declares and trusts the data to match, so
each file is checked before ITK sees it (:mod:`tetvr.io.voxels`): the header's fields
must parse (errors name the field, the file and the value), the declared size must fit
in what the data can hold and in this machine's memory, data files must be regular
files (a FIFO would block), a pattern of data file names is counted before any name is
built, and compressed data must inflate to exactly the declared size (checked a few
MiB at a time: a decompression bomb stops at the declared size, and a corrupt stream
is refused rather than read as whatever ITK's inflater left in the buffer).
"""

from __future__ import annotations

import math
import os
import re
import tempfile
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.checks import check_input_file
from tetvr.io.voxels import (
    _DEFLATE_MAX_RATIO,
    _check_declared,
    _check_file,
    _check_inflates_to,
    _dims,
    _existing_data_files,
    _from_bytes,
    _header_int,
    _header_numbers,
    _inflate_pieces,
    _is_dir,
    _next_line,
    _pattern_names,
    _to_space,
)
from tetvr.volume.volume import SPACES, Volume, _vec
from tetvr.io.volume_itk import _itk_execute, _itk_header, _sitk, _volume_from_itk, read_dicom, read_nifti
from tetvr.io.volume_vtk import read_vti, read_vtk_structured_points

__all__ = ["read_volume", "read_raw", "read_nrrd", "read_metaimage", "read_vti", "read_vtk_structured_points",
           "read_nifti", "read_dicom", "VOLUME_SUFFIXES"]

#: File name endings :func:`read_volume` recognises (a directory is a DICOM series).
VOLUME_SUFFIXES = (".nrrd", ".nhdr", ".mha", ".mhd", ".vti", ".vtk", ".nii", ".nii.gz", ".dcm")

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


# ---------------------------------------------------------------------------------
# Raw voxels (no library reads a file without a header)
# ---------------------------------------------------------------------------------


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


def _need(fields: dict[str, str], fmt: str, fname: str, key: str) -> str:
    """Field ``key`` of a NRRD/MetaImage header (looked up in lower case), else an error naming it and the file."""
    if key.lower() not in fields:
        raise ValueError(f"{fmt} file {fname!r} has no '{key}' field")
    return fields[key.lower()]


# ---------------------------------------------------------------------------------
# NRRD: the header checked here, the voxels and geometry read by ITK (teem)
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


def _nrrd_header(raw: bytes, fname: str) -> tuple[dict[str, str], list[str] | None, int]:
    """The fields of the header (its lines up to the first empty one, or the end), the LIST names, where it ends."""
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
            raise ValueError(f"NRRD file {fname!r}: header line {line[:80]!r} is not 'field: value'")
        key, value = line.split(":", 1)
        key = key.strip().lower()
        value = value.strip()
        if key == "data file" or key == "datafile":
            if value.startswith("LIST"):
                list_files = []
        fields[key] = value
    return fields, list_files, pos


def _nrrd_fields(fields: dict[str, str], fname: str) -> tuple[np.dtype[Any], str, tuple[int, ...], list[int], int]:
    """Dtype, encoding, dims, per-file sizes and bytes the fields declare, every field checked (geometry too)."""
    ndim = _header_int(fields, "dimension", "NRRD", fname, minimum=1)
    sizes = _header_numbers(_need(fields, "NRRD", fname, "sizes"), "sizes", "NRRD", fname, int)
    if len(sizes) != ndim:
        raise ValueError(f"NRRD file {fname!r}: field 'sizes' lists {len(sizes)} values ({fields['sizes']!r}) "
                         f"for dimension {ndim}")
    if any(s < 1 for s in sizes):
        raise ValueError(f"NRRD file {fname!r}: field 'sizes' must be positive, got {fields['sizes']!r}")
    file_sizes = list(sizes)
    type_name = _need(fields, "NRRD", fname, "type").lower()
    if type_name not in _NRRD_TYPE:
        raise ValueError(f"NRRD file {fname!r}: field 'type' {type_name!r} is not supported (block types are not)")
    dtype = _NRRD_TYPE[type_name]
    encoding = fields.get("encoding", "raw").lower()
    if encoding not in ("raw",) + _NRRD_TEXT + tuple(_NRRD_CODECS):
        raise ValueError(f"NRRD file {fname!r}: field 'encoding' {encoding!r} is not supported "
                         "(raw, gzip, bzip2, ascii)")
    if _NRRD_CODECS.get(encoding) == "bz2":
        raise ValueError(f"NRRD file {fname!r}: encoding {encoding!r} is not supported (ITK's NRRD reader is built "
                         "without bzip2): save it with gzip or raw encoding")
    if dtype.itemsize > 1 and encoding not in _NRRD_TEXT:
        endian = _need(fields, "NRRD", fname, "endian").lower()
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

    for key in ("spacings", "axis mins", "thicknesses"):
        if key in fields:
            _header_numbers(fields[key].lower().replace("nan", ""), key, "NRRD", fname)
    for key in ("space origin", "space directions"):
        if key in fields:
            for t in re.findall(r"\([^)]*\)|none", fields[key]):
                _nrrd_vector(t, key, fname)
    if "space dimension" in fields and "space" not in fields \
            and _header_int(fields, "space dimension", "NRRD", fname) != 3:
        raise ValueError(f"NRRD file {fname!r}: field 'space dimension' is {fields['space dimension']}, not 3")
    return dtype, encoding, dims, file_sizes, n_bytes


def read_nrrd(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a NRRD volume (``.nrrd`` attached or ``.nhdr`` detached, incl. slice lists) with ITK.

    Encodings raw, gzip and ascii (ITK's teem; bzip2 is refused: ITK is built without it); ``space directions``/``space origin`` or
    ``spacings``; ``data file`` as one name, a printf pattern with ``min max step
    [subdim]`` (its count must be the one the sizes imply) or ``LIST``. Files of an
    anatomical space come in LPS (as ITK gives them), then in ``space``. Header errors
    name the field and the file.

    Examples
    --------
    >>> vol = read_nrrd("../shared/data/volumes/headsq/quarter.nhdr")  # doctest: +SKIP
    >>> vol.dims                                                       # doctest: +SKIP
    (64, 64, 93)
    """
    p = _check_file(Path(path), "NRRD file")
    raw = p.read_bytes()
    if not raw.startswith(b"NRRD000"):
        raise ValueError(f"{p.name!r} is not a NRRD file (it does not start with 'NRRD000x')")
    fields, list_files, header_end = _nrrd_header(raw, p.name)
    fname = p.name
    dtype, encoding, dims, file_sizes, n_bytes = _nrrd_fields(fields, fname)
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
        bodies = [(f.read_bytes() if encoding in _NRRD_CODECS else b"", f.stat().st_size, f.name) for f in files]
    else:
        bodies = [(raw[header_end:], len(raw) - header_end, fname)]
    held = sum(size for _, size, _ in bodies)
    if encoding == "raw" and byte_skip >= 0 and held - byte_skip * len(bodies) < n_bytes:
        raise ValueError(f"NRRD file {fname!r} holds {held} bytes of voxel data, but sizes {list(dims)} of "
                         f"{dtype.name} need {n_bytes}: the header is wrong or the data are truncated")
    elif encoding in _NRRD_CODECS:
        # deflate cannot hold more than 1032 times its size: refuse before inflating.
        if _NRRD_CODECS[encoding] == "gzip":
            _check_declared(dims, dtype, f"NRRD file {fname!r}", how=f" ({encoding})", holds=_DEFLATE_MAX_RATIO * held)
        got = 0
        for body, _, name in bodies:
            body = _skip_lines(body, line_skip, name)
            left = max(n_bytes - got, 0) + max(byte_skip, 0)
            got += sum(len(x) for x in _inflate_pieces(body, _NRRD_CODECS[encoding], left, f"NRRD data {name!r}"))
            got -= max(byte_skip, 0)
        if got != n_bytes:
            raise ValueError(f"NRRD file {fname!r}: the {encoding} data inflate to {got} bytes, "
                             f"but sizes {dims} of {dtype.name} need {n_bytes}")
    del raw, bodies
    file_space = "LPS" if fields.get("space", "").strip().lower() in _NRRD_SPACES else ""
    sitk = _sitk("NRRD files")
    with tempfile.TemporaryDirectory(prefix="tetvr-nrrd-") as tmp:
        itk_path = _nrrd_for_itk(p, fields, header_end, Path(tmp))
        reader = _itk_header(sitk, itk_path, f"NRRD file {fname!r}", io="NrrdImageIO")
        img = _itk_execute(reader, f"NRRD file {fname!r}")
    vol = _volume_from_itk(sitk, img, f"NRRD file {fname!r}", scalar_name=p.stem, space=file_space)
    return _to_space(vol, space)


def _skip_lines(body: bytes, line_skip: int, name: str) -> bytes:
    start = 0
    for i in range(line_skip):  # positions only: no copy of the body per line
        nl = body.find(b"\n", start)
        if nl < 0:
            raise ValueError(f"NRRD data {name!r}: 'line skip' is {line_skip}, but the data hold only {i} lines")
        start = nl + 1
    return body[start:] if start else body


def _nrrd_for_itk(p: Path, fields: dict[str, str], header_end: int, tmp: Path) -> Path:
    """The file to give ITK: ``p`` itself, or, for a header that sets both ``space`` and
    per-axis ``spacings`` (VTK writes these; the NRRD format forbids the pair and teem
    refuses it), a detached copy of the header in ``tmp`` with the spacings as
    ``space directions`` (after ``space``, as teem needs) and the data named by absolute path."""
    if not ("space" in fields and "spacings" in fields and "space directions" not in fields):
        return p
    spacings = _header_numbers(fields["spacings"].lower().replace("nan", ""), "spacings", "NRRD", p.name)
    n = len(spacings)
    dirs = " ".join("(" + ",".join(str(s if i == j else 0.0) for j in range(n)) + ")" for i, s in enumerate(spacings))
    raw = p.read_bytes()[:header_end]
    out = []
    pos = raw.index(b"\n") + 1
    out.append(raw[:pos].decode("latin-1").rstrip("\r\n"))
    data_named = False
    while pos < len(raw):
        line, pos = _next_line(raw, pos)
        if not line.strip():
            break
        key = line.split(":", 1)[0].strip().lower()
        if key == "spacings":
            continue
        if key == "space":
            out += [line, f"space directions: {dirs}"]
            continue
        if key in ("data file", "datafile"):
            data_named = True
            value = line.split(":", 1)[1].strip()
            if value.startswith("LIST"):
                out.append("data file: LIST")
                out += [str(p.parent / n_) for n_ in raw[pos:].decode("latin-1").split()]
                break
            first, *rest = value.split()
            line = "data file: " + " ".join([str(p.parent / first)] + rest)
        out.append(line)
    if not data_named:  # attached data: the original file, past its header's lines
        out.insert(1, f"data file: {p}")
        out.insert(2, "line skip: %d" % raw.count(b"\n"))
    header = tmp / (p.stem + ".nhdr")
    header.write_text("\n".join(out) + "\n", encoding="latin-1")
    return header


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


# ---------------------------------------------------------------------------------
# MetaImage: the header checked here, the voxels and geometry read by ITK (MetaIO)
# ---------------------------------------------------------------------------------

_MET_TYPES = {
    "MET_CHAR": "i1", "MET_UCHAR": "u1", "MET_SHORT": "i2", "MET_USHORT": "u2", "MET_INT": "i4",
    "MET_UINT": "u4", "MET_LONG": "i4", "MET_ULONG": "u4", "MET_LONG_LONG": "i8", "MET_ULONG_LONG": "u8",
    "MET_FLOAT": "f4", "MET_DOUBLE": "f8",
}


def _met_header(raw: bytes, fname: str) -> tuple[dict[str, str], list[str] | None, int]:
    """The header's fields, the names after ``ElementDataFile = LIST``, and where it ends (LOCAL data follow)."""
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
    return fields, list_files, pos


def _met_fields(fields: dict[str, str], fname: str) -> tuple[tuple[int, int, int], np.dtype[Any], int]:
    """Dims, dtype (with byte order) and bytes the fields declare, every field checked (the geometry too)."""
    ndims = _header_int(fields, "ndims", "MetaImage", fname, shown="NDims", minimum=1)
    sizes = _header_numbers(_need(fields, "MetaImage", fname, "DimSize"), "DimSize", "MetaImage", fname, int)
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
    etype = _need(fields, "MetaImage", fname, "ElementType").upper()
    if etype not in _MET_TYPES:
        raise ValueError(f"MetaImage file {fname!r}: field 'ElementType' {etype!r} is not supported; "
                         f"expected one of {sorted(_MET_TYPES)}")
    msb = fields.get("elementbyteordermsb", fields.get("binarydatabyteordermsb", "False")).lower() == "true"
    dtype = np.dtype(_MET_TYPES[etype]).newbyteorder(">" if msb else "<")
    n_bytes = _check_declared(dims, dtype, f"MetaImage file {fname!r}")

    for keys, shown, count in ((("elementspacing", "elementsize"), "ElementSpacing", ndims),
                               (("offset", "origin", "position"), "Offset", ndims),
                               (("transformmatrix", "rotation", "orientation"), "TransformMatrix", ndims * ndims)):
        for k in keys:
            if k in fields:
                vals = _header_numbers(fields[k], shown, "MetaImage", fname)
                if len(vals) != count or not all(math.isfinite(v) for v in vals):
                    raise ValueError(f"MetaImage file {fname!r}: field '{shown}' must be {count} finite numbers, "
                                     f"got {fields[k]!r}")
                if shown == "ElementSpacing" and any(v <= 0 for v in vals):
                    raise ValueError(f"MetaImage file {fname!r}: field 'ElementSpacing' must be positive, got {vals}")
                break
    return dims, dtype, n_bytes


def read_metaimage(path: str | os.PathLike[str], *, space: str = "LPS") -> Volume:
    """Read a MetaImage volume (``.mha`` with local data, ``.mhd`` + data file) with ITK.

    ``TransformMatrix`` lists the direction of index axis ``a`` as its ``a``-th triple,
    ``Offset`` is the first voxel's position, and the frame is LPS whatever
    ``AnatomicalOrientation`` says (ITK's MetaImageIO). Header errors name the field and
    the file.

    Examples
    --------
    >>> vol = read_metaimage("../shared/data/volumes/LIDC2.mha")  # doctest: +SKIP
    >>> vol.direction.diagonal().tolist()                          # doctest: +SKIP
    [1.0, -1.0, -1.0]
    """
    p = _check_file(Path(path), "MetaImage file")
    raw = p.read_bytes()
    fname = p.name
    fields, list_files, header_end = _met_header(raw, fname)
    dims, dtype, n_bytes = _met_fields(fields, fname)
    compressed = fields.get("compresseddata", "False").lower() == "true"
    header_size = _header_int(fields, "headersize", "MetaImage", fname, shown="HeaderSize", minimum=-1, default=0)
    if header_size == -1 and compressed:
        raise ValueError(f"MetaImage file {fname!r}: field 'HeaderSize' -1 (data at the end of the file) "
                         "cannot be used with CompressedData")
    datafile = _need(fields, "MetaImage", fname, "ElementDataFile")
    if datafile.upper() == "LOCAL":
        chunks = [raw[header_end:]]
    else:
        chunks = [f.read_bytes() for f in _met_data_files(p, datafile, list_files, dims)]
    held = sum(len(c) for c in chunks)
    if compressed:
        # deflate cannot hold more than 1032 times its size: refuse before inflating.
        _check_declared(dims, dtype, f"MetaImage file {fname!r}", how=" (CompressedData)",
                        holds=_DEFLATE_MAX_RATIO * held)
        if len(chunks) == 1:
            _check_inflates_to(chunks[0], "zlib", n_bytes + max(header_size, 0), f"MetaImage file {fname!r}")
        else:
            for chunk in chunks:
                list(_inflate_pieces(chunk, "zlib", n_bytes + max(header_size, 0), f"MetaImage file {fname!r}"))
    elif header_size >= 0 and held - header_size * len(chunks) < n_bytes:
        raise ValueError(f"MetaImage file {fname!r} holds {held - header_size * len(chunks)} bytes of voxel data, "
                         f"but DimSize {list(dims)} of {dtype.name} need {n_bytes}: the header is wrong or the data "
                         "are truncated")
    sitk = _sitk("MetaImage files")
    with tempfile.TemporaryDirectory(prefix="tetvr-mha-") as tmp:
        itk_path = p
        if compressed and "compresseddatasize" not in fields and len(chunks) == 1:
            itk_path = _met_with_compressed_size(p, raw, header_end, len(chunks[0]), datafile, Path(tmp))
        del raw, chunks
        reader = _itk_header(sitk, itk_path, f"MetaImage file {fname!r}", io="MetaImageIO")
        img = _itk_execute(reader, f"MetaImage file {fname!r}")
    vol = _volume_from_itk(sitk, img, f"MetaImage file {fname!r}", scalar_name=p.stem, space="LPS")
    return _to_space(vol, space)


def _met_with_compressed_size(p: Path, raw: bytes, header_end: int, n_compressed: int, datafile: str,
                              tmp: Path) -> Path:
    """A copy of ``p``'s header in ``tmp`` that states ``CompressedDataSize``: MetaIO reads
    compressed data without it as garbage (it says "Uncompress failed" and goes on)."""
    lines = [ln for ln in raw[:header_end].decode("latin-1").splitlines()
             if ln.strip() and ln.split("=", 1)[0].strip().lower() != "elementdatafile"]
    lines.append(f"CompressedDataSize = {n_compressed}")
    if datafile.upper() == "LOCAL":
        out = tmp / (p.stem + ".mha")
        out.write_bytes(("\n".join(lines) + "\nElementDataFile = LOCAL\n").encode("latin-1") + raw[header_end:])
    else:
        out = tmp / (p.stem + ".mhd")
        out.write_text("\n".join(lines) + f"\nElementDataFile = {p.parent / datafile}\n", encoding="latin-1")
    return out


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

"""Reading VTK image files: XML image data (``.vti``) and legacy structured points (``.vtk``).

About this stage
----------------
ITK, which reads every other volume format (:mod:`tetvr.io.volume_file`), does not read VTK's
XML image data, and reads legacy structured points without choosing among several
arrays; these two readers are ours, written with numpy from VTK's file-format
specification: ``.vti`` in ascii, base64, appended raw, zlib or lzma compressed, in
pieces that must cover the whole extent (nothing is filled with invented zeros), and
legacy ``STRUCTURED_POINTS`` in ascii or binary, any point-data array by name (vectors
give their magnitude). Every size a header declares is checked against the file and
this machine's memory before it is allocated (:mod:`tetvr.io.voxels`).
"""

from __future__ import annotations

import base64
import math
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.io.voxels import _check_declared, _check_file, _dims, _header_int, _header_numbers, _inflate, _next_line
from tetvr.volume.volume import Volume, _vec

__all__ = ["read_vti", "read_vtk_structured_points"]


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
    fname = p.name
    root, appended, app_encoding = _vti_xml(p.read_bytes(), fname)
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


def _vti_xml(raw: bytes, fname: str) -> tuple[ET.Element, bytes, str]:
    """The file's ``VTKFile`` element, parsed with its ``<AppendedData>`` block cut out (raw
    bytes are not XML), and that block's data and encoding (empty and "raw" when absent)."""
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
    return root, appended, app_encoding


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


def _legacy_header(tok: _Tokens) -> bool:
    """Check the three header lines and ``DATASET STRUCTURED_POINTS``; whether the data are BINARY."""
    first = tok.line()
    if not first.startswith("# vtk DataFile"):
        raise ValueError(f"{tok.name!r} is not a legacy VTK file (first line {first[:40]!r})")
    tok.line()  # title
    mode = tok.line().strip().upper()
    if mode not in ("ASCII", "BINARY"):
        raise ValueError(f"{tok.name!r}: third line must be ASCII or BINARY, got {mode!r}")
    binary = mode == "BINARY"
    kw = tok.token()
    if (kw or "").upper() != "DATASET":
        raise ValueError(f"{tok.name!r}: expected DATASET, got {kw!r}")
    kind = (tok.token() or "").upper()
    if kind != "STRUCTURED_POINTS":
        raise ValueError(f"{tok.name!r} holds a {kind} dataset; only STRUCTURED_POINTS is a volume")
    return binary


def _legacy_floats(tok: _Tokens, key: str, n: int) -> NDArray[np.float64]:
    """The ``n`` numbers after keyword ``key`` (SPACING, ORIGIN, DIRECTION)."""
    vals = [tok.token() for _ in range(n)]
    try:
        return np.asarray([float(v) for v in vals])  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"VTK file {tok.name!r}: {key} must be {n} numbers, got {vals}") from None


def _legacy_point_count(tok: _Tokens, dims: tuple[int, int, int] | None, binary: bool) -> int:
    """The POINT_DATA count, checked against DIMENSIONS (if read yet) and what is left of the file."""
    n_points = tok.count("POINT_DATA count")
    if dims is not None and n_points != math.prod(dims):
        raise ValueError(f"VTK file {tok.name!r}: POINT_DATA {n_points} does not match DIMENSIONS {dims} "
                         f"({math.prod(dims)} points)")
    # Every point value takes a byte at least (ascii: a digit and a separator).
    left, least = len(tok.raw) - tok.pos, n_points * (1 if binary else 2) - (0 if binary else 1)
    if least > left:
        raise ValueError(f"VTK file {tok.name!r}: DIMENSIONS {dims} and POINT_DATA declare {n_points} points, "
                         f"but only {left} bytes of the file are left for their values")
    return n_points


def _legacy_attribute(tok: _Tokens, key: str, n: int, binary: bool) -> tuple[str, int, NDArray[Any]]:
    """One attribute array of ``n`` tuples (``key`` is SCALARS, VECTORS, NORMALS, TENSORS,
    TEXTURE_COORDINATES or COLOR_SCALARS): its name, its components and its values."""
    aname = tok.token() or ""
    what = f"{key} {aname!r}"
    if key == "COLOR_SCALARS":
        ncomp = tok.count(f"{what} components", minimum=1)
        dt = np.dtype("u1") if binary else np.dtype("f4")
    else:
        tname = (tok.token() or "").lower()
        if tname not in _LEGACY_TYPES:
            raise ValueError(f"{tok.name!r}: data type {tname!r} of {aname!r} is not supported")
        dt = np.dtype(_LEGACY_TYPES[tname])
        ncomp = {"VECTORS": 3, "NORMALS": 3, "TENSORS": 9}.get(key, 1)
        if key == "SCALARS":
            rest = tok.line().split()
            ncomp = int(rest[0]) if rest and rest[0].isdigit() else 0 if rest else 1
            if not 1 <= ncomp <= 4:
                raise ValueError(f"VTK file {tok.name!r}: {what} must have 1 to 4 components, got {rest[0]!r}")
            mark = tok.pos
            if (tok.token() or "").upper() == "LOOKUP_TABLE":
                tok.token()
            else:
                tok.pos = mark
        elif key == "TEXTURE_COORDINATES":
            ncomp = tok.count(f"{what} components", minimum=1)
    return aname, ncomp, tok.values(n * ncomp, dt, binary, what)


def _legacy_field(tok: _Tokens, binary: bool, scalars: str | None, want: bool) -> NDArray[Any] | None:
    """Read a FIELD's arrays; if ``want``, the values of the first named ``scalars`` (vectors: their magnitude)."""
    tok.token()
    match = None
    for _ in range(tok.count("FIELD array count")):  # each array consumes tokens: bounded by the file
        aname = tok.token() or ""
        what = f"FIELD array {aname!r}"
        ncomp = tok.count(f"{what} components", minimum=1)
        ntup = tok.count(f"{what} tuples")
        tname = (tok.token() or "").lower()
        if tname not in _LEGACY_TYPES:
            raise ValueError(f"{tok.name!r}: field array type {tname!r} is not supported")
        vals = tok.values(ncomp * ntup, np.dtype(_LEGACY_TYPES[tname]), binary, what)
        if want and scalars == aname and match is None:
            match = vals if ncomp == 1 else np.linalg.norm(vals.reshape(ntup, ncomp).astype(np.float64), axis=1)
    return match


def read_vtk_structured_points(path: str | os.PathLike[str], *, scalars: str | None = None) -> Volume:
    """Read a legacy VTK file with ``DATASET STRUCTURED_POINTS`` (ASCII or BINARY).

    ``scalars`` names the point-data array (SCALARS, VECTORS or a FIELD array); the
    default is the first SCALARS array. Vectors give their magnitude.
    """
    p = _check_file(Path(path), "VTK file")
    tok = _Tokens(p.read_bytes(), p.name)
    binary = _legacy_header(tok)
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
            spacing = _legacy_floats(tok, key, 3)
        elif key == "ORIGIN":
            origin = _legacy_floats(tok, key, 3)
        elif key == "DIRECTION":
            direction = _legacy_floats(tok, key, 9).reshape(3, 3)
        elif key == "METADATA":
            while tok.pos < len(tok.raw) and tok.line().strip() != "":
                pass
        elif key == "POINT_DATA":
            section, n_points = "point", _legacy_point_count(tok, dims, binary)
        elif key == "CELL_DATA":
            section, n_cells = "cell", tok.count("CELL_DATA count")
        elif key in ("SCALARS", "VECTORS", "NORMALS", "TENSORS", "TEXTURE_COORDINATES", "COLOR_SCALARS"):
            n = n_points if section == "point" else n_cells
            aname, ncomp, vals = _legacy_attribute(tok, key, n, binary)
            want = (scalars is None and key == "SCALARS" and found is None) or scalars == aname
            if section == "point" and want and found is None:
                found = vals if ncomp == 1 else np.linalg.norm(vals.reshape(n, ncomp).astype(np.float64), axis=1)
                found_name = aname
        elif key == "LOOKUP_TABLE":
            tok.token()
            n = tok.count("LOOKUP_TABLE size")
            tok.values(4 * n, np.dtype("u1") if binary else np.dtype("f4"), binary, "LOOKUP_TABLE")
        elif key == "FIELD":
            match = _legacy_field(tok, binary, scalars, section == "point" and found is None)
            if match is not None:
                found, found_name = match, scalars or ""
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

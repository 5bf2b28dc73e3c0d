"""Legacy VTK files (``# vtk DataFile``) that meshio refuses: an unstructured grid's points,
cells and fields, ASCII or binary, every declared count checked against what is left of the
file before anything is allocated.
"""

from __future__ import annotations

import itertools
import os
import re
from typing import Any

import numpy as np
from numpy.typing import NDArray

Int = NDArray[np.int64]

__all__ = ["VTK_CELL_TYPES", "is_legacy_vtk", "read_legacy_vtk"]


def is_legacy_vtk(path: str) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(14) == b"# vtk DataFile"
    except OSError:
        return False


#: VTK cell type ids -> meshio names (VTK's vtkCellType.h).
VTK_CELL_TYPES = {
    1: "vertex", 2: "polyvertex", 3: "line", 4: "polyline", 5: "triangle", 6: "triangle_strip",
    7: "polygon", 8: "pixel", 9: "quad", 10: "tetra", 11: "voxel", 12: "hexahedron", 13: "wedge",
    14: "pyramid", 15: "penta_prism", 16: "hexa_prism", 21: "line3", 22: "triangle6", 23: "quad8",
    24: "tetra10", 25: "hexahedron20", 26: "wedge15", 27: "pyramid13", 28: "quad9", 29: "hexahedron27",
    30: "quad6", 31: "wedge12", 32: "wedge18", 33: "hexahedron24", 34: "triangle7", 35: "line4",
    37: "pyramid14", 42: "polyhedron", 71: "VTK_LAGRANGE_TETRAHEDRON", 72: "VTK_LAGRANGE_HEXAHEDRON",
    73: "VTK_LAGRANGE_WEDGE", 74: "VTK_LAGRANGE_PYRAMID",
}

_VTK_DTYPES = {
    "bit": "u1", "unsigned_char": "u1", "char": "i1", "signed_char": "i1", "unsigned_short": "u2", "short": "i2",
    "unsigned_int": "u4", "int": "i4", "unsigned_long": "u8", "long": "i8", "float": "f4", "double": "f8",
    "vtktypeint64": "i8", "vtktypeuint64": "u8", "vtkidtype": "i8", "vtktypeint32": "i4",
}

_TOKEN = re.compile(rb"\s*(\S+)")


class _Cursor:
    """Tokens, lines and binary blocks of a legacy VTK file.

    Every count a file declares is checked against what is left of the file before
    anything is allocated or looped over (a 223-byte file declaring 500 million cells
    once allocated 3.7 GiB and spun in a loop that never advanced).
    """

    def __init__(self, raw: bytes, binary: bool, name: str) -> None:
        self.raw, self.pos, self.binary, self.name = raw, 0, binary, name

    def line(self) -> str:
        end = self.raw.find(b"\n", self.pos)
        end = len(self.raw) if end < 0 else end
        out = self.raw[self.pos:end].decode("latin-1").strip()
        self.pos = end + 1
        return out

    def token(self) -> str | None:
        m = _TOKEN.match(self.raw, self.pos)
        if not m:
            self.pos = len(self.raw)
            return None
        self.pos = m.end()
        return m.group(1).decode("latin-1")

    def peek(self) -> str | None:
        pos = self.pos
        t = self.token()
        self.pos = pos
        return t

    def fail(self, what: str, problem: str) -> ValueError:
        return ValueError(f"{self.name!r}: {what}: {problem}")

    def count(self, what: str, *, minimum: int = 0, default: int | None = None) -> int:
        """The next token as a count: an integer >= ``minimum``, else an error naming ``what``."""
        t = self.token()
        if t is None and default is not None:
            return default
        try:
            n = int(t) if t is not None else None
        except ValueError:
            n = None
        if n is None or n < minimum:
            raise self.fail(what, f"expected an integer >= {minimum}, got {t!r}" if t else "the file ends here")
        return n

    def dtype(self, what: str) -> str:
        t = (self.token() or "").lower()
        if t not in _VTK_DTYPES:
            raise self.fail(what, f"data type {t!r} is not one of {sorted(_VTK_DTYPES)}")
        return _VTK_DTYPES[t]

    def values(self, n: int, dtype: str, what: str) -> NDArray[Any]:
        dt = np.dtype(dtype)
        if self.binary:
            nl = self.raw.find(b"\n", self.pos)  # binary data start after the keyword's line
            self.pos = nl + 1 if nl >= 0 else self.pos
            nbytes = n * dt.itemsize
            if self.pos + nbytes > len(self.raw):
                raise self.fail(what, f"{n} values of {nbytes} bytes are declared, but the file ends "
                                      f"{len(self.raw) - self.pos} bytes later")
            out = np.frombuffer(self.raw, dt.newbyteorder(">"), count=n, offset=self.pos).astype(dt)
            self.pos += nbytes
            return out
        if n == 0:
            return np.zeros(0, dt)
        # Each ascii value takes at least one byte: refuse a count the rest cannot hold
        # before splitting anything.
        if n > len(self.raw) - self.pos:
            raise self.fail(what, f"{n} values are declared, but only {len(self.raw) - self.pos} bytes are left")
        parts = self.raw[self.pos:].split(maxsplit=n)
        if len(parts) < n:
            raise self.fail(what, f"the file ends after {len(parts)} of {n} values")
        self.pos = len(self.raw) - (len(parts[n]) if len(parts) > n else 0)
        if dt.kind == "f":
            try:
                return np.array(parts[:n], dtype=np.float64).astype(dt)
            except ValueError:
                bad = next(p for p in parts[:n] if not _is_number(p, float))
                raise self.fail(what, f"{bad.decode('latin-1')!r} is not a number") from None
        try:
            ints = np.array(parts[:n], dtype=np.int64)
        except (ValueError, OverflowError):
            bad = next(p for p in parts[:n] if not _is_number(p, int))
            raise self.fail(what, f"{bad.decode('latin-1')!r} is not an integer of {dt.name}") from None
        info = np.iinfo(dt)
        if ints.min() < info.min or ints.max() > info.max:  # the cast would wrap silently
            bad_i = ints.min() if ints.min() < info.min else ints.max()
            raise self.fail(what, f"value {bad_i} does not fit its declared type {dt.name}")
        return ints.astype(dt)


def _is_number(token: bytes, kind: type) -> bool:
    try:
        v = kind(token)
        return kind is float or -2**63 <= v < 2**63
    except ValueError:
        return False


def read_legacy_vtk(path: str | os.PathLike[str]) -> tuple[
        NDArray[np.float64], list[tuple[str, Any]], dict[str, NDArray[Any]], dict[str, list[NDArray[Any]]]]:
    """Read a legacy VTK ``UNSTRUCTURED_GRID`` (ASCII or BINARY, the classic and the 5.1
    OFFSETS/CONNECTIVITY cell layouts).

    Returns ``(points, blocks, point_data, cell_data)`` in meshio's layout: blocks are runs
    of consecutive cells of one type, ``(type name, (k, nodes) array)``, or a list of
    arrays for cells of varying size (polygons, strips); cell fields are lists with one
    array per block. SCALARS, VECTORS, NORMALS, TENSORS and FIELD arrays are read.
    Counts are checked against what the file holds before anything is allocated, and a
    field whose length is not the POINT_DATA/CELL_DATA count, or a count that is not the
    number of points/cells, is an error naming it.
    """
    name = os.fspath(path)
    cur = _open_cursor(name)
    points: NDArray[np.float64] | None = None
    offsets: Int | None = None
    conn: Int | None = None
    types: Int | None = None
    point_data: dict[str, NDArray[Any]] = {}
    cell_flat: dict[str, NDArray[Any]] = {}
    counts: dict[str, int] = {}
    section, count = "", 0
    while (t := cur.token()) is not None:
        key = t.upper()
        if key == "DATASET":
            kind = (cur.token() or "").upper()
            if kind != "UNSTRUCTURED_GRID":
                raise ValueError(f"{name!r} holds a {kind} dataset, not an UNSTRUCTURED_GRID")
        elif key == "POINTS":
            n = cur.count("POINTS count")
            dt = cur.dtype("POINTS")
            points = cur.values(3 * n, dt, f"POINTS {n}").astype(np.float64).reshape(n, 3)
        elif key == "CELLS":
            a, b = cur.count("CELLS count"), cur.count("CELLS size")
            if (cur.peek() or "").upper() == "OFFSETS":  # VTK 5.1: offsets and connectivity arrays
                offsets, conn = _offset_cells(cur, a, b)
            else:  # classic: per cell, its node count then its nodes
                offsets, conn = _classic_cells(cur, a, b)
        elif key == "CELL_TYPES":
            n = cur.count("CELL_TYPES count")
            types = cur.values(n, "i4", f"CELL_TYPES {n}").astype(np.int64)
        elif key in ("POINT_DATA", "CELL_DATA"):
            section, count = key, cur.count(f"{key} count")
            counts[key] = count
        elif key in ("SCALARS", "VECTORS", "NORMALS", "TENSORS", "TEXTURE_COORDINATES", "COLOR_SCALARS"):
            aname, ncomp, vals = _attribute(cur, key, count, section)
            _store(point_data if section == "POINT_DATA" else cell_flat, aname, vals, count, ncomp)
        elif key == "LOOKUP_TABLE":
            cur.token()
            n = cur.count("LOOKUP_TABLE size")
            cur.values(4 * n, "u1" if cur.binary else "f4", f"LOOKUP_TABLE {n}")
        elif key == "FIELD":
            _field(cur, section, count,
                   point_data if section == "POINT_DATA" else cell_flat if section == "CELL_DATA" else None)
        elif key == "METADATA":
            cur.pos -= len(t)
            _skip_metadata(cur)
        else:
            raise ValueError(f"{name!r}: unexpected keyword {t!r} at byte {cur.pos}")
    if points is None or offsets is None or conn is None or types is None:
        raise ValueError(f"{name!r} lacks POINTS, CELLS or CELL_TYPES")
    if types.shape[0] != offsets.shape[0] - 1:
        raise ValueError(f"{name!r}: {types.shape[0]} CELL_TYPES for {offsets.shape[0] - 1} CELLS")
    for key, want in (("POINT_DATA", points.shape[0]), ("CELL_DATA", types.shape[0])):
        if key in counts and counts[key] != want:
            what = "points" if key == "POINT_DATA" else "cells"
            raise ValueError(f"{name!r}: {key} {counts[key]} does not match the {want} {what} of the grid")
    blocks, cell_data = _blocks(offsets, conn, types, cell_flat)
    return points, blocks, point_data, cell_data


def _open_cursor(name: str) -> _Cursor:
    """A cursor past the three header lines (version, title, ASCII or BINARY) of file ``name``."""
    with open(name, "rb") as f:
        raw = f.read()
    if not raw.startswith(b"# vtk DataFile"):
        raise ValueError(f"{name!r} is not a legacy VTK file")
    head = _Cursor(raw, False, name)
    head.line()  # version
    head.line()  # title
    mode = head.line().upper()
    if mode not in ("ASCII", "BINARY"):
        raise ValueError(f"{name!r}: third line must be ASCII or BINARY, got {mode!r}")
    cur = _Cursor(raw, mode == "BINARY", name)
    cur.pos = head.pos
    return cur


def _attribute(cur: _Cursor, key: str, count: int, section: str) -> tuple[str, int, NDArray[Any]]:
    """One SCALARS, VECTORS, NORMALS, TENSORS, TEXTURE_COORDINATES or COLOR_SCALARS array of
    ``count`` tuples: its name, its components and its values."""
    aname = cur.token() or ""
    what = f"{key} {aname!r}"
    if key == "COLOR_SCALARS":
        ncomp, dt = cur.count(f"{what} components", minimum=1, default=1), ("u1" if cur.binary else "f4")
    else:
        dt = cur.dtype(what)
        ncomp = {"VECTORS": 3, "NORMALS": 3, "TENSORS": 9}.get(key, 1)
        if key == "SCALARS":
            rest = cur.line().split()
            ncomp = int(rest[0]) if rest and rest[0].isdigit() else 0 if rest else 1
            if not 1 <= ncomp <= 4:
                raise cur.fail(what, f"a SCALARS array has 1 to 4 components, got {rest[0]!r}")
            if (cur.peek() or "").upper() == "LOOKUP_TABLE":
                cur.token()
                cur.token()
        elif key == "TEXTURE_COORDINATES":
            ncomp = cur.count(f"{what} components", minimum=1)
    return aname, ncomp, cur.values(count * ncomp, dt, f"{what} in {section or 'no data section'} {count}")


def _field(cur: _Cursor, section: str, count: int, target: dict[str, NDArray[Any]] | None) -> None:
    """Read a FIELD's arrays into ``target`` (the data section's fields; None outside one), where
    each must hold the section's ``count`` tuples."""
    cur.token()
    for _ in range(cur.count("FIELD array count")):  # each array consumes tokens: bounded by the file
        aname = cur.token() or ""
        what = f"FIELD array {aname!r}"
        ncomp, ntup = cur.count(f"{what} components", minimum=1), cur.count(f"{what} tuples")
        vals = cur.values(ncomp * ntup, cur.dtype(what), what)
        if (cur.peek() or "").upper() == "METADATA":
            _skip_metadata(cur)
        if target is not None:
            if ntup != count:
                raise cur.fail(what, f"{ntup} tuples in {section} {count}")
            _store(target, aname, vals, ntup, ncomp)


def _blocks(offsets: Int, conn: Int, types: Int,
            cell_flat: dict[str, NDArray[Any]]) -> tuple[list[tuple[str, Any]], dict[str, list[NDArray[Any]]]]:
    """meshio's layout: runs of consecutive cells of one type, and each cell field cut into the same runs."""
    blocks: list[tuple[str, Any]] = []
    run_starts = np.r_[0, np.nonzero(np.diff(types))[0] + 1, types.shape[0]]
    for s, e in itertools.pairwise(run_starts):
        ctype = VTK_CELL_TYPES.get(int(types[s]), f"vtk_type_{int(types[s])}")
        sizes = np.diff(offsets[s:e + 1])
        if np.all(sizes == sizes[0]):
            blocks.append((ctype, conn[offsets[s]:offsets[e]].reshape(e - s, int(sizes[0]))))
        else:
            blocks.append((ctype, [conn[offsets[i]:offsets[i + 1]] for i in range(s, e)]))
    cell_data = {k: [v[s:e] for s, e in itertools.pairwise(run_starts)] for k, v in cell_flat.items()}
    return blocks, cell_data


def _offset_cells(cur: _Cursor, a: int, b: int) -> tuple[Int, Int]:
    """Offsets and connectivity of VTK 5.1 ``CELLS a b``: an OFFSETS array, then a CONNECTIVITY array."""
    cur.token()
    offsets = cur.values(a, cur.dtype("OFFSETS"), f"OFFSETS of CELLS {a} {b}").astype(np.int64)
    if (cur.token() or "").upper() != "CONNECTIVITY":
        raise ValueError(f"{cur.name!r}: OFFSETS must be followed by CONNECTIVITY")
    conn = cur.values(b, cur.dtype("CONNECTIVITY"), f"CONNECTIVITY of CELLS {a} {b}").astype(np.int64)
    if a == 0 or offsets[0] != 0 or offsets[-1] != b or np.any(np.diff(offsets) < 0):
        raise ValueError(f"{cur.name!r}: CELLS {a} {b}: OFFSETS must rise from 0 to {b} (the CONNECTIVITY "
                         f"size), got {offsets[:3].tolist()} ... {offsets[-3:].tolist()}")
    return offsets, conn


def _classic_cells(cur: _Cursor, a: int, b: int) -> tuple[Int, Int]:
    """Offsets and connectivity of classic ``CELLS a b``: per cell, its node count, then its nodes."""
    if a > b:
        raise cur.fail(f"CELLS {a} {b}", f"{a} cells cannot fit in {b} values (each takes at least its node count)")
    flat = cur.values(b, "i4", f"CELLS {a} {b}").astype(np.int64)
    k = int(flat[0]) if b else 0
    if a and k >= 0 and b == a * (k + 1) and np.all(flat[:: k + 1] == k):  # one cell size: no walk
        heads = np.arange(0, b, k + 1)
    else:  # each count says where the next cell starts; every step advances by at least one
        heads = np.empty(a, np.int64)
        pos = 0
        for i in range(a):
            size = int(flat[pos]) if pos < b else -1
            if size < 0 or pos + 1 + size > b:
                problem = (f"the {b} values end after {i} of {a} cells" if pos >= b else
                           f"cell {i} declares {size} nodes" + ("" if size < 0 else f", past the {b} values"))
                raise cur.fail(f"CELLS {a} {b}", problem)
            heads[i] = pos
            pos += size + 1
        if pos != b:
            raise cur.fail(f"CELLS {a} {b}", f"the {a} cells take {pos} of the {b} values declared")
    offsets = np.r_[0, np.cumsum(flat[heads])]
    keep = np.ones(flat.shape[0], dtype=bool)
    keep[heads] = False
    return offsets, flat[keep]


def _store(target: dict[str, NDArray[Any]], name: str, vals: NDArray[Any], n: int, ncomp: int) -> None:
    target[name] = vals if ncomp == 1 else vals.reshape(n, ncomp)


def _skip_metadata(cur: _Cursor) -> None:
    """METADATA blocks (information keys) end at the first blank line."""
    cur.line()
    while cur.pos < len(cur.raw) and cur.line() != "":
        pass

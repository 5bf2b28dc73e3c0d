"""Reading a tetrahedral mesh from a file: meshio for every format it knows, ParaView's
collections merged by :mod:`tetvr.io.collections`, legacy VTK files meshio refuses by
:mod:`tetvr.io.legacy_vtk`, each guarded against the ways a hostile file hangs or blows up
a reader (readers that loop at an unexpected end of file, NetCDF headers that declare more
than the file holds).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import os
import re
import tempfile
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.core.checks import check_input_file, warn
from tetvr.io.legacy_vtk import is_legacy_vtk, read_legacy_vtk
from tetvr.mesh.cells import CellSplit, split_cells
from tetvr.mesh.fields import _check_named_field, _field_to_scalar, _scalar_of, choose_field
from tetvr.mesh.tetmesh import TetMesh, _cell_to_point, _check_cell_data

__all__ = ["TetCells", "read", "read_cells"]

Int = NDArray[np.int64]


def read(path: str | os.PathLike[str], scalars: str | None = None, *, component: int | None = None,
         cell_data: str = "exact") -> TetMesh:
    """Read a tetrahedral mesh from any file meshio can read.

    Parameters
    ----------
    path : mesh file (VTU, VTK, Gmsh, Exodus, ...), or a ParaView collection: a ``.vtm``
        multiblock or ``.pvtu`` partitioned grid (merged), a ``.pvd`` (its first time step;
        :mod:`tetvr.io.collections` reads the others).
    scalars : name of the point or cell field to render; by default the first point
        field that varies, else the first cell field that varies (a constant field is
        passed over with a warning naming it; :func:`tetvr.mesh.fields.choose_field`).
        Vector fields render by magnitude, or by ``component`` when given
        (``mesh.report.scalar_of`` says which).
    cell_data : ``"exact"`` (default): a cell field is rendered constant in each cell, as
        the solver wrote it (a cell split into tets gives each its value);
        ``"average"``: it becomes point data by volume-weighted averaging (each point takes
        the mean of the tets around it, weighted by their volumes), linear in each tet.

    Notes
    -----
    Hexahedra, wedges,
    pyramids and quadratic cells are split into tetrahedra that conform across shared
    faces (:mod:`tetvr.mesh.cells`), with a warning listing them; surface, line and vertex
    cells are reported by type and count and left out. Zero-volume tets are dropped with
    a warning.

    Examples
    --------
    >>> mesh = read(demo_mesh_path(), "Pressure")  # doctest: +SKIP
    """
    # Not found, a directory, a FIFO (never opened: it would block), a symbolic link
    # loop, a name too long: each reported as what it is.
    path = check_input_file(path, "mesh file")
    if os.path.getsize(path) == 0:
        raise ValueError(f"cannot read mesh file {path!r}: the file is empty")
    if scalars is not None and not isinstance(scalars, str):
        raise TypeError(f"scalars must be a field name (str) or None, got {scalars!r}")
    if component is not None and (isinstance(component, bool) or not isinstance(component, (int, np.integer))):
        raise TypeError(f"component must be an integer or None, got {component!r}")

    exact_cells = _check_cell_data(cell_data)
    m = read_cells(path, meshio_read=_read_any)
    tets = m.tets
    if m.split.split or m.split.ignored:
        warn(f"{os.path.basename(path)}: {m.split.summary()}")

    point_names = list(m.point_data)
    cell_names = list(m.cell_data)
    named = scalars is not None
    if scalars is None:
        # The first field that varies: a constant one draws a shape in one colour.
        fields = [(n, m.point_data[n]) for n in point_names] + [(n, m.cell_data[n]) for n in cell_names
                                                                if n not in m.point_data]
        if not fields:
            raise ValueError(f"{path!r} has no point or cell data to render")
        scalars = choose_field(fields, component, os.path.basename(path))
    if scalars in m.point_data:
        values = _field_to_scalar(m.point_data[scalars], scalars, component)
        scalar_of, source = _scalar_of(m.point_data[scalars], component), "point"
    elif scalars in m.cell_data:
        cell_values = _field_to_scalar(m.cell_data[scalars], scalars, component).astype(np.float64)
        values = _cell_to_point(m.points, tets, cell_values)
        scalar_of, source = _scalar_of(m.cell_data[scalars], component), "cell"
    else:
        raise KeyError(
            f"no field named {scalars!r} in {path!r}; point fields: {point_names}, cell fields: {cell_names}"
        )
    if named:
        _check_named_field(cell_values if source == "cell" else values, scalars, os.path.basename(path))
    mesh = TetMesh.from_arrays(m.points, tets, values, scalar_name=scalars,
                               cell_scalars=cell_values if source == "cell" and exact_cells else None)
    report = dataclasses.replace(mesh.report, ignored_cells=m.split.ignored, scalar_source=source,
                                 split_cells=m.split.split, steiner_points=m.split.steiner_points,
                                 fields=tuple(point_names) + tuple(n for n in cell_names if n not in m.point_data),
                                 scalar_of=scalar_of)
    return dataclasses.replace(mesh, report=report)


# meshio readers that loop forever at an unexpected end of file, and the mode they open
# the file in: they are handed a file object that raises there instead.
_LOOPS_AT_EOF = {"tecplot": "r", "mdpa": "rb", "ply": "rb", "ansys": "rb"}
# Consecutive empty reads at the end of a file before it counts as such a loop.
_EOF_READS = 1000


class _EOFGuard:
    """Mixin for file objects: reads raise after returning nothing too many times."""

    _eof_reads = 0

    def _count(self, data: Any) -> Any:
        self._eof_reads = 0 if data else self._eof_reads + 1
        if self._eof_reads > _EOF_READS:
            raise EOFError("unexpected end of file (the file is truncated)")
        return data

    def readline(self, *args: Any) -> Any:
        return self._count(super().readline(*args))  # type: ignore[misc]

    def read(self, *args: Any) -> Any:
        return self._count(super().read(*args))  # type: ignore[misc]


class _GuardedBytes(_EOFGuard, io.BufferedReader):
    pass


class _GuardedText(_EOFGuard, io.TextIOWrapper):
    pass


def _meshio_formats(path: str) -> list[str]:
    """The meshio formats a file name can be, as meshio itself deduces them."""
    import meshio

    ext, formats = "", []
    for suffix in reversed(os.path.basename(path).split(".")[1:]):
        ext = ("." + suffix + ext).lower()
        formats += meshio.extension_to_filetypes.get(ext, [])
    if not formats:
        known = ", ".join(sorted(meshio.extension_to_filetypes))
        what = f"extension {os.path.splitext(path)[1]!r}" if os.path.splitext(path)[1] else "no file extension"
        raise ValueError(f"cannot read mesh file {path!r}: unknown format ({what}); known extensions: {known}")
    return formats


def _tetgen_has_header(path: str) -> None:
    # meshio's TetGen reader skips blank and comment lines without checking for the end.
    stem = os.path.splitext(path)[0]
    for name in (stem + ".node", stem + ".ele"):
        with open(name, "rb") as f:
            if not any(line.strip() and not line.lstrip().startswith(b"#") for line in f):
                raise EOFError(f"{name!r} has no header line")


# Exodus II files are netCDF. The netCDF library returns fill values for data that lie
# past the end of a short file, so a 4 KB header declaring 3e8 nodes made meshio fill
# gigabytes (minutes, then MemoryError): the data a header declares must fit in the file.
_NC_TYPE_BYTES = {1: 1, 2: 1, 3: 2, 4: 4, 5: 4, 6: 8, 7: 1, 8: 2, 9: 4, 10: 8, 11: 8}
# deflate never compresses more than ~1032:1; HDF5 variables compressed by it cannot hold more.
_DEFLATE_MAX_RATIO = 1032


def _netcdf_fits_file(path: str) -> None:
    """Refuse a netCDF (classic or HDF5-based) file whose variables need more bytes than it can hold."""
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        magic = f.read(8)
    if magic[:3] == b"CDF":
        declared, largest, dims = _netcdf_classic_sizes(path, size)
        limit, how = size, ""
    elif magic == b"\x89HDF\r\n\x1a\n":
        try:
            import netCDF4
        except ImportError:
            return  # meshio cannot read it either, and says so
        declared, largest, compressed = 0, (0, ""), False
        with netCDF4.Dataset(path) as nc:
            dims = {name: len(d) for name, d in nc.dimensions.items()}
            for name, var in nc.variables.items():
                itemsize = getattr(var.dtype, "itemsize", 8)  # variable-length strings: a pointer each
                n = math.prod(int(d) for d in var.shape) * itemsize
                declared += n
                if n > largest[0]:
                    largest = (n, f"variable {name!r} of shape {tuple(var.shape)}")
                compressed |= bool((var.filters() or {}).get("zlib"))
        limit, how = (size * _DEFLATE_MAX_RATIO, " (deflate-compressed)") if compressed else (size, "")
    else:
        return
    # meshio allocates (num_nodes, 3) float64 points from the dimension alone; a file's
    # coordinates take at least num_nodes * num_dim float32s.
    nodes = dims.get("num_nodes", 0) * max(dims.get("num_dim", 1), 1) * 4
    if nodes > declared:
        declared, largest = nodes, (nodes, f"dimension num_nodes = {dims['num_nodes']}")
    if declared > limit:
        raise ValueError(f"the netCDF header declares {declared} bytes of data ({largest[1]}), but the file"
                         f"{how} holds {size} bytes; it is truncated or its dimensions are corrupt")


def _netcdf_classic_sizes(path: str, size: int) -> tuple[int, tuple[int, str], dict[str, int]]:
    """Bytes of data a netCDF classic header (CDF-1, -2 or -5) declares, its largest
    variable, and its dimensions by name.

    Parsed here (the format is a few lines of spec) so that no netCDF library is needed
    to refuse a file; every count is bounded by the bytes left before it is looped over.
    """
    with open(path, "rb") as f:
        def take(n: int) -> bytes:
            if n < 0 or f.tell() + n > size:
                raise ValueError(f"the netCDF header is truncated at byte {f.tell()} ({n} more bytes declared)")
            return f.read(n)

        version = take(4)[3]
        if version not in (1, 2, 5):
            raise ValueError(f"unknown netCDF classic version {version}")
        width = 8 if version == 5 else 4

        def num(w: int = width) -> int:
            return int.from_bytes(take(w), "big")

        def skip_name() -> str:
            n = num()
            return take(n + (-n % 4))[:n].decode("utf-8", "replace")

        def count(tag: int, what: str) -> int:
            got, n = num(4), num()
            if got == 0 and n == 0:
                return 0
            if got != tag or 4 * n > size - f.tell():
                raise ValueError(f"the netCDF header's {what} list is corrupt (tag {got}, {n} entries)")
            return n

        def skip_attributes() -> None:
            for _ in range(count(0x0C, "attribute")):
                skip_name()
                nc_type, n = num(4), num()
                nbytes = n * _NC_TYPE_BYTES.get(nc_type, 0)
                if nc_type not in _NC_TYPE_BYTES:
                    raise ValueError(f"the netCDF header has an attribute of unknown type {nc_type}")
                take(nbytes + (-nbytes % 4))

        numrecs = num()
        numrecs = 0 if numrecs == (1 << 8 * width) - 1 else numrecs  # STREAMING: length unknown
        dims, names = [], []
        for _ in range(count(0x0A, "dimension")):
            names.append(skip_name())
            dims.append(num())
        skip_attributes()
        total, largest = 0, (0, "")
        for _ in range(count(0x0B, "variable")):
            name = skip_name()
            ndim = num()
            if 4 * ndim > size - f.tell():
                raise ValueError(f"the netCDF variable {name!r} declares {ndim} dimensions")
            ids = [num() for _ in range(ndim)]
            skip_attributes()
            nc_type = num(4)
            num()  # vsize: clipped to 2**32 - 1 in CDF-1/2, so recomputed from the dimensions
            num(4 if version == 1 else 8)  # begin
            if nc_type not in _NC_TYPE_BYTES or any(i >= len(dims) for i in ids):
                raise ValueError(f"the netCDF variable {name!r} has unknown type {nc_type} or dimension ids {ids}")
            shape = tuple(dims[i] or numrecs for i in ids)
            n = math.prod(shape) * _NC_TYPE_BYTES[nc_type]
            total += n
            if n > largest[0]:
                largest = (n, f"variable {name!r} of shape {shape}")
    return total, largest, dict(zip(names, dims))


def _meshio_read(path: str) -> Any:
    """``meshio.read`` made safe for corrupt files: any failure is a ValueError naming the file.

    meshio prints its reason and calls ``sys.exit(1)`` when a reader rejects a file, and a
    few of its text readers never return on a truncated one; its console output is
    captured into the error (or, after a successful read, re-issued as a warning).
    """
    import meshio  # deferred: importing meshio costs ~0.3 s

    failures = []
    for fmt in _meshio_formats(path):
        chatter = io.StringIO()
        try:
            with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
                if fmt == "tetgen":
                    _tetgen_has_header(path)
                if fmt == "exodus":
                    _netcdf_fits_file(path)
                if fmt in _LOOPS_AT_EOF:
                    raw = io.FileIO(path, "r")
                    f: Any = _GuardedBytes(raw) if _LOOPS_AT_EOF[fmt] == "rb" else _GuardedText(io.BufferedReader(raw))
                    with f:
                        m = meshio.read(f, file_format=fmt)
                elif fmt == "vtu":
                    with _vtu_meshio_reads(path) as readable:
                        m = meshio.read(readable, file_format=fmt)
                else:
                    m = meshio.read(path, file_format=fmt)
        except (Exception, SystemExit) as exc:  # SystemExit: meshio exits when a reader rejects a file
            said = [ln.strip() for ln in chatter.getvalue().splitlines()
                    if ln.strip() and "Couldn't read file" not in ln]
            why = f"not a valid {fmt} file" if isinstance(exc, SystemExit) else f"{type(exc).__name__}: {exc}"
            failures.append(f"as {fmt}: " + "; ".join(said + [why]))
            continue
        if np.asarray(m.points).size == 0:  # some text readers accept any text as an empty mesh
            failures.append(f"as {fmt}: no points found")
            continue
        said_ok = " ".join(chatter.getvalue().split())
        if said_ok:
            warn(f"meshio reading {path!r}: {said_ok}")
        return m
    raise ValueError(f"cannot read mesh file {path!r}: " + " | ".join(failures))


def _read_any(path: str) -> Any:
    """The dispatch: ParaView's collections (.pvd, .vtm, .pvtu) to :mod:`tetvr.io.collections`,
    which merges their files read by :func:`_meshio_read`; any other file to meshio (a
    parallel writer's piece without its ghost cells)."""
    from tetvr.io.collections import is_collection, merged_meshio, without_ghosts

    if is_collection(path):
        return merged_meshio(path, meshio_read=_meshio_read)
    return without_ghosts(_meshio_read(path))


# The root element's version attribute of a VTK XML file.
_VTK_XML_VERSION = re.compile(rb"<VTKFile\b[^>]*?\sversion\s*=\s*[\"']([^\"']*)[\"']")


@contextlib.contextmanager
def _vtu_meshio_reads(path: str) -> Iterator[str]:
    """``path``, or a copy of it with the version meshio's VTU reader knows.

    VTK 9 writes version "2.0" .. "2.3" where 8 wrote "1.0" once a file holds a ghost array
    (``vtkGhostType``, which a parallel solver's pieces hold), and meshio refuses any version
    but 0.1 and 1.0. Their layout is 1.0's for every cell but polyhedra (2.3 stores their
    faces in new arrays, refused here by name) and the high-order nodes of Lagrange
    hexahedra (tetvr uses only their corners); read with the version set to "1.0", each
    array is the one VTK's own reader returns.
    """
    with open(path, "rb") as f:
        head = f.read(4096)
    found = _VTK_XML_VERSION.search(head)
    if found is None or not found.group(1).startswith(b"2."):
        yield path
        return
    with open(path, "rb") as f:
        data = f.read()
    if b'"face_connectivity"' in data:
        raise ValueError(f"VTK XML version {found.group(1).decode()} polyhedron cells (face_connectivity) "
                         "are not read by tetvr; split them into tetrahedra first")
    with tempfile.TemporaryDirectory(prefix="tetvr-vtu-") as folder:
        copy = os.path.join(folder, os.path.basename(path))
        with open(copy, "wb") as f:
            f.write(data[:found.start(1)] + b"1.0" + data[found.end(1):])
        del data
        yield copy


@dataclasses.dataclass(frozen=True, eq=False)
class TetCells:
    """A mesh file's volume cells as tetrahedra, with its fields carried over.

    Attributes
    ----------
    split : the tets, points and what was done (:class:`CellSplit`).
    point_data : every point field, with values for the added centroids appended.
    cell_data : every cell field, one value (row) per tet, taken from its cell.
    reader : ``"meshio"`` or ``"legacy-vtk"`` (the fallback here).
    """

    split: CellSplit
    point_data: dict[str, NDArray[Any]]
    cell_data: dict[str, NDArray[Any]]
    reader: str = "meshio"

    @property
    def points(self) -> NDArray[np.float64]:
        return self.split.points

    @property
    def tets(self) -> Int:
        return self.split.tets


def read_cells(path: str | os.PathLike[str], *, meshio_read: Callable[[str], Any] | None = None) -> TetCells:
    """Read a mesh file and split its volume cells into conforming tetrahedra.

    Parameters
    ----------
    path : the mesh file.
    meshio_read : the function that reads with meshio (:func:`tetvr.io.meshfile.read` passes its
        guarded one); default ``meshio.read``. Legacy VTK files it cannot read go to
        :func:`read_legacy_vtk`.

    Points that no tet uses (mid-side nodes, points of surface and line cells) are left
    out, so the mesh's bounds and scalar range are those of what is rendered. Raises
    ``ValueError`` for unreadable files and for files without volume cells.

    Examples
    --------
    >>> cells = read_cells("uGridEx.vtk")  # doctest: +SKIP
    >>> cells.split.split, cells.reader  # doctest: +SKIP
    ((('hexahedron', 2),), 'legacy-vtk')
    """
    path = check_input_file(path, "mesh file")  # never hands meshio a FIFO, a loop of links, ...
    if meshio_read is None:
        import meshio  # deferred: importing meshio costs ~0.3 s

        meshio_read = meshio.read
    reader = "meshio"
    try:
        m = meshio_read(path)
        points = np.asarray(m.points, dtype=np.float64)
        blocks: list[tuple[str, Any]] = [(c.type, c.data) for c in m.cells]
        point_data = {k: np.asarray(v) for k, v in m.point_data.items()}
        cell_blocks = {k: [np.asarray(b) for b in v] for k, v in m.cell_data.items()}
    except (Exception, SystemExit) as exc:  # meshio raises many kinds, and exits when a reader rejects a file
        if not is_legacy_vtk(path):
            if isinstance(exc, ValueError):
                raise
            raise ValueError(f"cannot read mesh file {path!r}: {type(exc).__name__}: {exc}") from exc
        try:
            points, blocks, point_data, cell_blocks = read_legacy_vtk(path)
        except Exception as exc2:
            raise ValueError(f"cannot read mesh file {path!r}: meshio: {exc}; "
                             f"legacy VTK reader: {type(exc2).__name__}: {exc2}") from exc2
        reader = "legacy-vtk"
    if points.ndim == 2 and points.shape[1] == 2:
        points = np.c_[points, np.zeros(points.shape[0])]
    split = split_cells(points, blocks)
    if split.tets.shape[0] == 0:
        found = ", ".join(f"{k}: {v}" for k, v in split.ignored) or "no cells"
        raise ValueError(f"{path!r} contains no tetrahedra or other volume cells ({found})")
    # A field of the wrong length is a corrupt file: said here, naming it, rather than
    # left out to surface later as "no field named ...".
    for name, v in point_data.items():
        if v.shape[:1] != (points.shape[0],):
            raise ValueError(f"{path!r}: point field {name!r} has {v.shape[0] if v.ndim else 0} values "
                             f"(shape {v.shape}), but the mesh has {points.shape[0]} points")
    used = np.zeros(split.points.shape[0], dtype=bool)
    used[split.tets.ravel()] = True
    pdata = {k: split.extend(v)[used] for k, v in point_data.items()}
    if not np.all(used):
        split = split.compacted(used)
    cdata: dict[str, NDArray[Any]] = {}
    for name, per_block in cell_blocks.items():
        got = [len(b) for b in per_block]
        want = [len(d) for _, d in blocks]
        if got != want:
            raise ValueError(f"{path!r}: cell field {name!r} has {sum(got)} values in {len(got)} blocks {got}, "
                             f"but the mesh has {sum(want)} cells in {len(want)} blocks {want}")
        try:
            flat = np.concatenate([np.asarray(b).reshape(len(b), -1) for b in per_block])
        except ValueError:  # blocks with different component counts: not one field
            shapes = sorted({np.asarray(b).shape[1:] for b in per_block})
            warn(f"{os.path.basename(path)}: cell field {name!r} is left out: its blocks have different "
                 f"component shapes {shapes}")
            continue
        col = flat[split.parent]
        cdata[name] = col[:, 0] if col.shape[1] == 1 else col
    return TetCells(split=split, point_data=pdata, cell_data=cdata, reader=reader)

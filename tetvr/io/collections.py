"""ParaView's collection files: ``.pvd`` time series, ``.vtm`` multiblocks, ``.pvtu`` pieces.

These are small XML files that name other files (VTK's XML formats, which meshio reads):

* ``.pvd`` — a collection of ``<DataSet timestep=".." part=".." file=".."/>``: the time
  steps of a run, each made of one or more parts. :func:`read_pvd` lists them with their
  time values; :func:`read_step` reads one step's parts as one mesh.
* ``.vtm`` — a ``vtkMultiBlockDataSet``: ``<Block>`` s (nested) of ``<DataSet file=".."/>``
  and ``<Piece>`` s. Its leaf files are merged into one scene.
* ``.pvtu`` — a partitioned unstructured grid: ``<Piece Source=".."/>`` s, each a ``.vtu``
  readable alone (:func:`pieces`, for distributing them) or merged.

:func:`tetvr.read` reads all three (a ``.pvd`` with several steps: its first, with a
warning). Merging happens before the field is chosen and cell data become point data, so a
merged mesh is the mesh the solver split: points the pieces share (equal coordinates and
equal values) are joined, coincident nodes that differ stay apart as in one file, and ghost
cells (``vtkGhostType``'s duplicate bit, :func:`without_ghosts`) are left out, merged or read
alone.

Examples
--------
>>> coll = read_pvd("run.pvd")                 # doctest: +SKIP
>>> coll.times                                 # doctest: +SKIP
(0.0, 0.5, 1.0)
>>> mesh = read_step(coll, 2, "Pressure")      # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import os
import warnings
import xml.etree.ElementTree as ET
from typing import Any, Callable, Iterator

import numpy as np

from tetvr.core.checks import check_input_file, short_path, warn

__all__ = ["COLLECTION_SUFFIXES", "Collection", "TimeStep", "is_collection", "leaf_files", "pieces", "read_pvd",
           "merged_meshio", "without_ghosts"]

#: File suffixes read here (lower case).
COLLECTION_SUFFIXES = (".pvd", ".vtm", ".pvtu")
# Collections that name collections: deeper than this is a loop or a mistake.
_MAX_DEPTH = 16
# vtkGhostType bit of a cell another piece owns (vtkDataSetAttributes::DUPLICATECELL).
_DUPLICATE_CELL = 1
# Ghost arrays: bits (VTK XML files from version 2.0 on) and, before, levels.
_GHOST_ARRAYS = ("vtkGhostType", "vtkGhostLevels")

# The time step that read() of a .pvd takes (read_step sets it; the default is the first).
_STEP: contextvars.ContextVar[int | None] = contextvars.ContextVar("tetvr_pvd_step", default=None)


@dataclasses.dataclass(frozen=True)
class TimeStep:
    """One step of a ``.pvd``: its time value and the files of its parts (absolute paths)."""

    time: float
    files: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class Collection:
    """The time steps of a ``.pvd`` file, in ascending time."""

    path: str
    steps: tuple[TimeStep, ...]

    @property
    def times(self) -> tuple[float, ...]:
        return tuple(s.time for s in self.steps)

    def __len__(self) -> int:
        return len(self.steps)

    def input_paths(self) -> tuple[str, ...]:
        """The collection file and every file it names, down to the leaves."""
        out = [self.path]
        for step in self.steps:
            for f in step.files:
                out += [f] + (leaf_files(f) if is_collection(f) else [])
        return tuple(dict.fromkeys(out))


def is_collection(path: str | os.PathLike[str]) -> bool:
    """Whether ``path``'s suffix is one of :data:`COLLECTION_SUFFIXES`."""
    return os.path.splitext(os.fspath(path))[1].lower() in COLLECTION_SUFFIXES


def _parse(path: str, root_tag: str, named_by: str = "") -> ET.Element:
    path = check_input_file(path, "collection file", named_by=named_by)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"cannot read collection file {short_path(path)!r}: not valid XML ({exc})") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"cannot read collection file {short_path(path)!r}: not valid XML ({exc})") from None
    if root.tag != "VTKFile":
        raise ValueError(f"cannot read collection file {short_path(path)!r}: not a VTK XML file "
                         f"(root element <{root.tag}>, expected <VTKFile>)")
    body = root.find(root_tag)
    if body is None:
        raise ValueError(f"cannot read collection file {short_path(path)!r}: no <{root_tag}> element "
                         f"(type {root.get('type')!r})")
    return body


def _named(path: str, name: str | None, what: str) -> str:
    """A file a collection names, relative to the collection's folder; checked to exist."""
    if not name or not name.strip():
        raise ValueError(f"{short_path(path)!r}: a {what} has no file name")
    full = os.path.join(os.path.dirname(os.path.abspath(path)), name.strip())
    return check_input_file(full, "mesh file", named_by=os.path.basename(path))


def read_pvd(path: str | os.PathLike[str]) -> Collection:
    """The time steps of a ``.pvd`` collection with their time values and part files.

    Data sets with equal ``timestep`` values are the parts of one step; a data set without
    one is at time 0. Steps are returned in ascending time, parts in file order.

    Examples
    --------
    >>> read_pvd("run.pvd").times  # doctest: +SKIP
    (0.0, 0.5, 1.0)
    """
    path = os.fspath(path)
    body = _parse(path, "Collection")
    by_time: dict[float, list[str]] = {}
    for ds in body.iter("DataSet"):
        raw = ds.get("timestep", "0")
        try:
            t = float(raw)
        except ValueError:
            raise ValueError(f"{short_path(path)!r}: DataSet timestep {raw!r} is not a number") from None
        if not np.isfinite(t):
            raise ValueError(f"{short_path(path)!r}: DataSet timestep {raw!r} is not finite")
        by_time.setdefault(t, []).append(_named(path, ds.get("file"), "DataSet"))
    if not by_time:
        raise ValueError(f"{short_path(path)!r}: the collection has no DataSet with a file")
    steps = tuple(TimeStep(t, tuple(by_time[t])) for t in sorted(by_time))
    return Collection(path=os.path.abspath(path), steps=steps)


def leaf_files(path: str | os.PathLike[str], _depth: int = 0) -> list[str]:
    """The mesh files a ``.vtm``, ``.pvtu`` or ``.pvd`` names, expanded down to files that
    are not collections (for a ``.pvd``: every step's). Any other path is its own leaf."""
    name = os.fspath(path)
    if _depth > _MAX_DEPTH:
        raise ValueError(f"collection files nested deeper than {_MAX_DEPTH} levels at {short_path(name)!r} "
                         "(a file that names itself?)")
    suffix = os.path.splitext(name)[1].lower()
    if suffix == ".pvd":
        named = [f for step in read_pvd(name).steps for f in step.files]
    elif suffix == ".vtm":
        body = _parse(name, "vtkMultiBlockDataSet")
        # Every DataSet at any depth of Blocks and Pieces; one without a file is an empty block.
        named = [_named(name, ds.get("file"), "DataSet") for ds in body.iter("DataSet") if ds.get("file")]
    elif suffix == ".pvtu":
        body = _parse(name, "PUnstructuredGrid")
        named = [_named(name, p.get("Source"), "Piece") for p in body.iter("Piece")]
    else:
        return [check_input_file(name, "mesh file")]
    out: list[str] = []
    for f in named:
        out += leaf_files(f, _depth + 1) if is_collection(f) else [f]
    if not out:
        raise ValueError(f"{short_path(name)!r}: the collection names no data files")
    return out


def pieces(path: str | os.PathLike[str]) -> list[str]:
    """The files of a ``.pvtu`` (or the leaves of a ``.vtm``), each readable alone with
    :func:`tetvr.read`: the units to hand to workers."""
    return leaf_files(path)


def merged_meshio(path: str, *, meshio_read: Callable[[str], Any]) -> Any:
    """A collection's leaf files read with ``meshio_read`` and merged into one
    ``meshio.Mesh`` (what :func:`tetvr.read` builds its mesh from).

    For a ``.pvd`` the step is the one :func:`read_step` asks for, else the first (with a
    warning when there are more).
    """
    if os.path.splitext(path)[1].lower() == ".pvd":
        coll = read_pvd(path)
        index = _STEP.get()
        if index is None:
            index = 0
            if len(coll) > 1:
                warn(f"{os.path.basename(path)} holds {len(coll)} time steps "
                     f"(t = {_times_text(coll.times)}); read the first. tetvr.io.series.read_step "
                     "reads another; `tetvr render` renders them all")
        files: list[str] = []
        for f in coll.steps[index].files:
            files += leaf_files(f) if is_collection(f) else [f]
    else:
        files = leaf_files(path)
    return _merge([(f, meshio_read(f)) for f in files], path)


def _times_text(times: tuple[float, ...]) -> str:
    shown = ", ".join(f"{t:g}" for t in times[:4])
    return shown + (f", ... {times[-1]:g}" if len(times) > 4 else "")


def _merge(parts: list[tuple[str, Any]], path: str) -> Any:
    """One meshio mesh from several: ghost cells dropped, points with equal coordinates and
    equal values joined, the fields every part has kept (the others with a warning)."""
    import meshio

    parts = [(f, without_ghosts(m)) for f, m in parts]
    if len(parts) == 1:
        return parts[0][1]
    point_fields = _common(path, "point", [(f, {k: np.asarray(v) for k, v in m.point_data.items()})
                                           for f, m in parts])
    cell_names = _common(path, "cell", [(f, {k: np.asarray(v[0]) if v else np.zeros(0)
                                             for k, v in m.cell_data.items()})
                                        for f, m in parts])
    points, cells, pdata = [], [], {k: [] for k in point_fields}  # type: ignore[var-annotated]
    cdata: dict[str, list[Any]] = {k: [] for k in cell_names}
    offset = 0
    for f, m in parts:
        pts = np.asarray(m.points, dtype=np.float64)
        if pts.ndim == 2 and pts.shape[1] == 2:
            pts = np.c_[pts, np.zeros(pts.shape[0])]
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"{short_path(f)!r}: points of shape {pts.shape}, expected (n, 3)")
        for b, block in enumerate(m.cells):
            if len(block.data):
                cells.append((block.type, np.asarray(block.data).astype(np.int64) + offset))
                for k in cell_names:
                    cdata[k].append(np.asarray(m.cell_data[k][b]))
        points.append(pts)
        for k in point_fields:
            pdata[k].append(np.asarray(m.point_data[k]))
        offset += pts.shape[0]
    if not cells:
        raise ValueError(f"{short_path(path)!r}: its pieces hold no cells (all ghost cells?)")
    allpts = np.concatenate(points)
    fields = {k: np.concatenate(v) for k, v in pdata.items()}
    # Pieces repeat the points on the faces they share: joined, so the merged mesh is
    # connected there (the ray caster walks across) and cell fields average across the
    # seam as in one file. A point is joined only to one with the same values too: a
    # solver's coincident nodes (an interface with a jump) stay apart, as in one file.
    ids = _unwelded_where_collapsed(_welded(allpts, list(fields.values())), cells)
    # The points kept in the order of their coordinates (a mesh numbered so comes back as it was).
    keep = np.unique(ids)
    keep = keep[np.lexsort((keep, allpts[keep, 2], allpts[keep, 1], allpts[keep, 0]))]
    number = np.empty(allpts.shape[0], dtype=np.int64)
    number[keep] = np.arange(keep.shape[0])
    cells = [(t, number[ids[d]]) for t, d in cells]
    return meshio.Mesh(allpts[keep], cells, point_data={k: v[keep] for k, v in fields.items()}, cell_data=cdata)


def without_ghosts(mesh: Any) -> Any:
    """A meshio mesh without its ghost cells and ghost arrays.

    A parallel writer repeats, in each piece, cells that another piece owns
    (``vtkGhostType`` with the ``DUPLICATECELL`` bit; ``vtkGhostLevels`` above 0 in files
    VTK wrote before version 2.0): dropped, so that no cell is counted twice. The mesh is
    returned as it is when it has no ghost arrays.

    Examples
    --------
    >>> import meshio
    >>> m = meshio.Mesh(np.eye(4, 3), [("tetra", [[0, 1, 2, 3], [3, 2, 1, 0]])],
    ...                 cell_data={"vtkGhostType": [np.array([0, 1], np.uint8)]})
    >>> without_ghosts(m).cells[0].data.tolist(), list(without_ghosts(m).cell_data)
    ([[0, 1, 2, 3]], [])
    """
    import meshio

    if not any(n in mesh.cell_data or n in mesh.point_data for n in _GHOST_ARRAYS):
        return mesh
    # meshio.Mesh has checked that every cell array holds one value per cell.
    keeps = [np.ones(len(block.data), dtype=bool) for block in mesh.cells]
    if "vtkGhostType" in mesh.cell_data:  # bits, from version 2.0 on
        keeps = [(np.asarray(g).reshape(-1).astype(np.int64) & _DUPLICATE_CELL) == 0
                 for g in mesh.cell_data["vtkGhostType"]]
    elif "vtkGhostLevels" in mesh.cell_data:  # levels, before
        keeps = [np.asarray(g).reshape(-1) == 0 for g in mesh.cell_data["vtkGhostLevels"]]
    cells = [(block.type, np.asarray(block.data)[k]) for block, k in zip(mesh.cells, keeps)]
    cell_data = {n: [np.asarray(v)[k] for v, k in zip(blocks, keeps)]
                 for n, blocks in mesh.cell_data.items() if n not in _GHOST_ARRAYS}
    point_data = {n: v for n, v in mesh.point_data.items() if n not in _GHOST_ARRAYS}
    return meshio.Mesh(mesh.points, cells, point_data=point_data, cell_data=cell_data)


def _welded(points: np.ndarray, fields: list[np.ndarray]) -> np.ndarray:
    """Each point's id after joining: the lowest id of the points with exactly its
    coordinates (``-0.0`` is ``0.0``) and its values in every numeric field (a NaN equals
    nothing)."""
    n = points.shape[0]
    pts = points + 0.0
    ids = np.arange(n)
    order = np.lexsort((pts[:, 2], pts[:, 1], pts[:, 0]))
    same = np.all(pts[order][1:] == pts[order][:-1], axis=1)
    if not same.any():
        return ids
    # Only the points that share their coordinates with another are compared by value.
    shared = np.zeros(n, dtype=bool)
    shared[order[1:][same]] = True
    shared[order[:-1][same]] = True
    sub = np.nonzero(shared)[0]
    key = np.concatenate([pts[sub]] + [np.asarray(f)[sub].reshape(len(sub), -1).astype(np.float64) + 0.0
                                       for f in fields if np.asarray(f).dtype.kind in "biuf"], axis=1)
    o = np.lexsort(key.T[::-1])  # stable: equal rows stay in id order, the lowest first
    equal = np.all(key[o][1:] == key[o][:-1], axis=1)
    first = np.maximum.accumulate(np.where(np.r_[True, ~equal], np.arange(len(o)), 0))
    ids[sub[o]] = sub[o[first]]
    return ids


def _unwelded_where_collapsed(ids: np.ndarray, cells: list[tuple[str, np.ndarray]]) -> np.ndarray:
    """``ids`` with the points of every cell that joining would give a repeated vertex
    kept apart: such a cell has two corners at one place (zero volume), and stays what
    it is in one file, a flat cell :meth:`tetvr.TetMesh.from_arrays` drops with its
    warning, instead of a cell that repeats a vertex."""
    apart = []
    for _, data in cells:
        if data.ndim != 2 or data.shape[1] < 2:
            continue
        joined = np.sort(ids[data], axis=1)
        before = np.sort(data, axis=1)
        collapsed = np.any(joined[:, 1:] == joined[:, :-1], axis=1) & ~np.any(before[:, 1:] == before[:, :-1], axis=1)
        if collapsed.any():
            apart.append(data[collapsed].ravel())
    if not apart:
        return ids
    out = ids.copy()
    corners = np.concatenate(apart)
    out[corners] = corners
    return out


def _common(path: str, kind: str, fields: list[tuple[str, dict[str, np.ndarray]]]) -> list[str]:
    """The field names every part has with one component shape; the rest are warned about."""
    names = list(fields[0][1])
    keep = [k for k in names if all(k in d and d[k].shape[1:] == fields[0][1][k].shape[1:] for _, d in fields)]
    dropped = sorted({k for _, d in fields for k in d} - set(keep))
    if dropped:
        warn(f"{os.path.basename(path)}: {kind} field(s) {dropped} are left out: not in every piece "
             "with the same components")
    return keep


@contextlib.contextmanager
def quiet_first_step() -> Iterator[None]:
    """Silence :func:`merged_meshio`'s "read the first step" warning (for callers that
    render every step themselves)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".* holds \d+ time steps")
        yield

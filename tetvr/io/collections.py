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
merged mesh is the mesh the solver split: points the pieces share (equal coordinates) are
joined, and ghost cells (``vtkGhostType``'s duplicate bit) are left out.

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
           "merged_meshio"]

#: File suffixes read here (lower case).
COLLECTION_SUFFIXES = (".pvd", ".vtm", ".pvtu")
# Collections that name collections: deeper than this is a loop or a mistake.
_MAX_DEPTH = 16
# vtkGhostType bit of a cell another piece owns (vtkDataSetAttributes::DUPLICATECELL).
_DUPLICATE_CELL = 1

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
    """One meshio mesh from several: points with equal coordinates joined, ghost cells
    dropped, the fields every part has kept (the others with a warning)."""
    import meshio

    if len(parts) == 1 and "vtkGhostType" not in parts[0][1].cell_data:
        return parts[0][1]
    point_fields = _common(path, "point", [(f, {k: np.asarray(v) for k, v in m.point_data.items()})
                                           for f, m in parts])
    cell_names = _common(path, "cell", [(f, {k: np.asarray(v[0]) if v else np.zeros(0)
                                             for k, v in m.cell_data.items() if k != "vtkGhostType"})
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
        ghosts = m.cell_data.get("vtkGhostType")
        for b, block in enumerate(m.cells):
            data = np.asarray(block.data)
            keep = np.ones(len(data), dtype=bool)
            if ghosts is not None and b < len(ghosts):
                keep = (np.asarray(ghosts[b]).reshape(-1).astype(np.int64) & _DUPLICATE_CELL) == 0
            if not keep.any():
                continue
            cells.append((block.type, data[keep].astype(np.int64) + offset))
            for k in cell_names:
                cdata[k].append(np.asarray(m.cell_data[k][b])[keep])
        points.append(pts)
        for k in point_fields:
            pdata[k].append(np.asarray(m.point_data[k]))
        offset += pts.shape[0]
    if not cells:
        raise ValueError(f"{short_path(path)!r}: its pieces hold no cells (all ghost cells?)")
    allpts = np.concatenate(points)
    # Pieces repeat the points on the faces they share, with equal coordinates: joined, so the
    # merged mesh is connected there (the ray caster walks across) and cell fields average
    # across the seam as in one file.
    uniq, first, inverse = np.unique(allpts, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    cells = [(t, inverse[d]) for t, d in cells]
    pd = {k: np.concatenate(v)[first] for k, v in pdata.items()}
    return meshio.Mesh(uniq, cells, point_data=pd, cell_data=cdata)


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

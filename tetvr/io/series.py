"""Time series of meshes: a list of files, a ParaView ``.pvd`` collection, or an XDMF time
series (``meshio.xdmf.TimeSeriesWriter``), read one step at a time."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from tetvr.core.checks import short_path
from tetvr.io.collections import _STEP, Collection, read_pvd
from tetvr.io.meshfile import read
from tetvr.mesh.tetmesh import TetMesh, _cell_to_point, _field_to_scalar

__all__ = ["read_step", "read_time_series", "series_input_paths", "xdmf_data_files"]


def read_time_series(source: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], scalars: str | None = None,
                     *, component: int | None = None) -> Iterator[tuple[float, TetMesh]]:
    """Yield ``(time, mesh)`` for each step of a time series.

    ``source`` is either a list of mesh files (one per step; time = the index), a ``.pvd``
    collection (its steps and times), or one
    XDMF time series written by ``meshio.xdmf.TimeSeriesWriter`` (read with its
    ``TimeSeriesReader``; HDF5-backed files need h5py). ``scalars``/``component`` pick
    the field as in :func:`tetvr.read`.
    """
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if path.suffix.lower() in (".xdmf", ".xmf"):
            yield from _read_xdmf_series(path, scalars, component)
            return
        if path.suffix.lower() == ".pvd":
            coll = read_pvd(path)
            for i, t in enumerate(coll.times):
                yield t, read_step(coll, i, scalars, component=component)
            return
        paths: list[Any] = [path]
    else:
        paths = list(source)
    if not paths:
        raise ValueError("the time series is empty: give at least one mesh file")
    for i, p in enumerate(paths):
        yield float(i), read(p, scalars, component=component)


def _read_xdmf_series(path: Path, scalars: str | None, component: int | None) -> Iterator[tuple[float, TetMesh]]:
    import meshio

    if not path.is_file():
        raise FileNotFoundError(f"time series not found: {path}")
    reader = meshio.xdmf.TimeSeriesReader(str(path))
    points, cells = reader.read_points_cells()
    blocks = [i for i, c in enumerate(cells) if c.type == "tetra"]
    if not blocks:
        raise ValueError(f"{path} contains no tetrahedra ({', '.join(c.type for c in cells) or 'no cells'})")
    tets = np.concatenate([cells[i].data for i in blocks]).astype(np.int64)
    pts = np.asarray(points, dtype=np.float64)
    base: TetMesh | None = None
    for k in range(reader.num_steps):
        t, point_data, cell_data = reader.read_data(k)
        name = scalars or next(iter(point_data), None) or next(iter(cell_data), None)
        if name is None:
            raise ValueError(f"{path}: step {k} has no point or cell data")
        if name in point_data:
            values = _field_to_scalar(np.asarray(point_data[name]), name, component)
        elif name in cell_data:
            cv = np.concatenate([_field_to_scalar(np.asarray(cell_data[name][i]), name, component) for i in blocks])
            values = _cell_to_point(pts, tets, cv.astype(np.float64))
        else:
            raise KeyError(f"no field {name!r} in step {k} of {path}; point fields {list(point_data)}, "
                           f"cell fields {list(cell_data)}")
        # The geometry is the same in every step: canonicalise it once, then swap the field
        # (canonicalisation reorders cells, never points).
        base = TetMesh.from_arrays(pts, tets, values, scalar_name=name) if base is None else base.with_scalars(values, name)
        yield float(t), base


def read_step(collection: Collection | str | os.PathLike[str], index: int, scalars: str | None = None, *,
              component: int | None = None) -> Any:
    """Read step ``index`` of a ``.pvd`` (its parts merged) as a :class:`~tetvr.TetMesh`.

    ``scalars`` and ``component`` pick the field as in :func:`tetvr.read`.
    """
    coll = collection if isinstance(collection, Collection) else read_pvd(collection)
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
        raise TypeError(f"index must be an integer, got {index!r}")
    if not -len(coll) <= index < len(coll):
        raise IndexError(f"{short_path(coll.path)!r} has {len(coll)} time steps; step {index} is out of range")
    token = _STEP.set(int(index) % len(coll))
    try:
        return read(coll.path, scalars, component=component)
    finally:
        _STEP.reset(token)


def series_input_paths(source: Any) -> list[tuple[str, str]]:
    """``(what, path)`` for every file a time series reads (as :func:`read_time_series`
    takes it: mesh files, a ``.pvd`` and the files it names, an XDMF file and its HDF5
    data): what no output of the same call may be written over. Names that are not files
    are left out; the reader reports them."""
    from tetvr.io.collections import is_collection, leaf_files

    names = [source] if isinstance(source, (str, os.PathLike)) else list(source or ())
    out: list[tuple[str, str]] = []
    for item in names:
        if not isinstance(item, (str, os.PathLike)):
            continue  # a mesh in memory
        name = os.fspath(item)
        out.append(("time-series file", name))
        suffix = Path(name).suffix.lower()
        if suffix in (".xdmf", ".xmf"):
            out += [("time-series data file", p) for p in xdmf_data_files(name)]
        elif is_collection(name) and os.path.isfile(name):
            out += [("collection file", p) for p in leaf_files(name)]
    return out


def xdmf_data_files(path: str | os.PathLike[str]) -> list[str]:
    """The HDF5 files an XDMF file's data items name (``file.h5:/dataset``), best effort:
    an unreadable XDMF file is the reader's to report."""
    import xml.etree.ElementTree as ET

    if not os.path.isfile(path):  # never open a FIFO: it would block
        return []
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError, ValueError):
        return []
    folder = os.path.dirname(os.path.abspath(path))
    files = set()
    for item in root.iter():
        if item.tag.rsplit("}", 1)[-1] == "DataItem" and item.get("Format", "").upper() == "HDF" and item.text:
            files.add(os.path.join(folder, item.text.strip().split(":", 1)[0]))
    return sorted(files)

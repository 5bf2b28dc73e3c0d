"""Cells that appear more than once: each kept once, with the number of copies it stands for.

A ``.vtm`` that names one piece twice, or a solver that writes a partition's cells into two
pieces, gives a mesh in which some cells repeat: the same points (by coordinates: the copies
may number their own nodes, :func:`tetvr.mesh.adjacency.coincident_points`) and the same
field on them. The exact reference integrates every copy, one after the other along the ray,
and so must any renderer measured against it. A walk from cell to cell cannot step into two
cells at once, so tet marching walks the mesh of distinct cells and composites each segment
as many times as its cell has copies (``shaders/march.frag``, ``MULTIPLICITY``): the same
sum, in the same order, as the reference's.

Copies whose fields differ are not copies but overlapping cells (two values at one point):
:func:`distinct_cells` keeps them all and counts them (:mod:`tetvr.order.walkable` sends
such meshes to projected tetrahedra).
"""

from __future__ import annotations

import dataclasses
import threading
import weakref

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh.adjacency import coincident_points
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["DistinctCells", "distinct_cells"]


@dataclasses.dataclass(frozen=True, eq=False)
class DistinctCells:
    """A mesh with every repeated cell kept once (see :func:`distinct_cells`).

    Attributes
    ----------
    mesh : the cells, each once (the input mesh itself where no cell repeats).
    copies : (mesh.n_tets,) int32, how many cells of the input each one stands for; None
        where no cell repeats.
    n_repeats : cells of the input dropped as copies of another (``copies.sum() - n_tets``).
    n_conflicting : cells at the points of another cell with other values there (kept).
    """

    mesh: TetMesh
    copies: NDArray[np.int32] | None
    n_repeats: int
    n_conflicting: int


# id(mesh) -> its DistinctCells, or for a mesh with no repeated cell only its count of
# conflicting cells: an entry holding the mesh itself would keep it alive for ever (and the
# finalizer that drops the entry would never run).
_CACHE: dict[int, DistinctCells | int] = {}
_LOCK = threading.Lock()


def distinct_cells(mesh: TetMesh) -> DistinctCells:
    """``mesh`` with each repeated cell once and its number of copies; cached with the mesh.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> tet = synthetic.single_tet()
    >>> d = distinct_cells(synthetic.merge(tet, tet, tet))
    >>> d.mesh.n_tets, d.copies.tolist(), d.n_repeats
    (1, [3], 2)
    >>> distinct_cells(tet).mesh is tet
    True
    """
    cached = _CACHE.get(id(mesh))
    if isinstance(cached, int):
        return DistinctCells(mesh, None, 0, cached)
    if cached is not None:
        return cached
    found = _find(mesh)
    with _LOCK:
        _CACHE[id(mesh)] = found.n_conflicting if found.mesh is mesh else found
        weakref.finalize(mesh, _CACHE.pop, id(mesh), None)
    return found


def _find(mesh: TetMesh) -> DistinctCells:
    tets = mesh.tets  # int32, as are the welded ids below: half the bytes of int64 temporaries
    canonical = coincident_points(mesh.points)
    welded = tets if canonical is None else canonical.astype(tets.dtype)[tets]
    rows = np.sort(welded, axis=1)
    order = np.lexsort(rows.T[::-1])
    s = rows[order]
    same = np.all(s[1:] == s[:-1], axis=1)
    if not same.any():
        return DistinctCells(mesh, None, 0, 0)
    order_in = np.argsort(welded, axis=1, kind="stable")
    # The field each cell holds at its points, in the same (welded) order: copies must agree.
    if mesh.cell_scalars is not None:
        values = np.asarray(mesh.cell_scalars)[:, None]
    else:
        values = np.take_along_axis(np.asarray(mesh.scalars)[tets], order_in, axis=1)
    v = values[order]
    agree = same & np.all(v[1:] == v[:-1], axis=1)
    # A run of equal rows whose values agree with the run's first: copies of it. (A copy
    # with other values starts a group of its own, and is counted as conflicting.)
    group_start = np.r_[True, ~agree]
    group = np.cumsum(group_start) - 1
    counts = np.bincount(group).astype(np.int32)
    keep = order[group_start]
    n_conflicting = int(np.count_nonzero(same & ~agree))
    if keep.size == tets.shape[0]:
        return DistinctCells(mesh, None, 0, n_conflicting)
    # The kept cells in their input order: the mesh's rows are canonical and sorted, so a
    # subset of them in order is too, and from_arrays keeps it row for row.
    by_cell = np.argsort(keep, kind="stable")
    kept = keep[by_cell]
    cell = None if mesh.cell_scalars is None else np.asarray(mesh.cell_scalars)[kept]
    unique = TetMesh.from_arrays(mesh.points, tets[kept], mesh.scalars, scalar_name=mesh.scalar_name, cell_scalars=cell)
    return DistinctCells(unique, counts[by_cell], int(tets.shape[0] - kept.size), n_conflicting)

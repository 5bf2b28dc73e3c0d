"""A mesh's points numbered along a space-filling curve, for the walk's memory reads.

Tet marching reads, at every step of a ray, the link across a face and the point beyond it
(``shaders/march.frag``). Where the points are numbered in no spatial order (meshes from
TetGen, Gmsh or SimVascular often are), consecutive steps read points far apart in memory,
and so do neighbouring rays: on Mesa's llvmpipe the SimVascular pipe (171k tets, 30k points)
marched 10x slower than the same mesh numbered along a Morton (Z-order) curve, with the
same image. :func:`spatially_ordered` gives the walk that numbering: the points sorted by
the Morton code of their position in the bounding box, and the cells by their points
(:meth:`TetMesh.from_arrays` sorts them by their smallest point id), so that cells near in
space are near in memory too. Its result is cached with the mesh.
"""

from __future__ import annotations

import threading
import weakref

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh.tetmesh import TetMesh

__all__ = ["morton_order", "numbered_locally", "spatially_ordered"]

#: Meshes with fewer points than this are walked as given: their points fit in any cache.
MIN_POINTS = 4096

#: Points numbered within this many typical edges of the last, on average, are walked as
#: given (:func:`numbered_locally`): the reordering costs more than it saves there (a 384k-tet
#: grid: 20 % more to the first frame, the same frames after).
LOCAL_STEP = 3.0

#: Bits per axis of the Morton code: a 1024^3 lattice over the bounding box.
BITS = 10

# id(mesh) -> the mesh renumbered, or AS_IS for one numbered locally already (kept as it is);
# each entry goes with its mesh.
_CACHE: dict[int, "TetMesh | str"] = {}
_LOCK = threading.Lock()
AS_IS = "as is"


def morton_order(points: NDArray[np.float64], bits: int = BITS) -> NDArray[np.intp]:
    """The order of ``points`` (n, 3) along a Morton curve through their bounding box
    (stable: points in one lattice cell keep their order).

    Examples
    --------
    >>> morton_order(np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])).tolist()
    [1, 2, 0]
    """
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.intp)
    lo, hi = p.min(axis=0), p.max(axis=0)
    span = float((hi - lo).max())
    scale = (2**bits - 1) / span if span > 0 else 0.0
    f = p - lo  # >= 0: lo is the least
    f *= scale
    np.minimum(f, 2**bits - 1, out=f)
    if bits > 21:  # more than a 64-bit word's third: bit by bit
        q = f.astype(np.uint64)
        code = np.zeros(n, dtype=np.uint64)
        for b in range(bits):
            for axis in range(3):
                code |= ((q[:, axis] >> np.uint64(b)) & np.uint64(1)) << np.uint64(3 * b + axis)
    else:
        # Bit b of axis a goes to bit 3b + a: each axis's bits spread two apart by shifts and
        # masks (in 32-bit words where the code fits one).
        word, spread = (np.uint32, _SPREAD_32) if 3 * bits <= 32 else (np.uint64, _SPREAD_64)
        q = f.astype(word)
        code = np.zeros(n, dtype=word)
        for axis in range(3):
            x = np.ascontiguousarray(q[:, axis])
            for shift, mask in spread:
                x = (x | (x << word(shift))) & word(mask)
            code |= x << word(axis)
        code = code.astype(np.uint64)
    index_bits = max(1, (n - 1).bit_length())
    if 3 * bits + index_bits > 64:
        return np.argsort(code, kind="stable")
    # The index below the code makes every key distinct, so that any sort keeps points in
    # one lattice cell in their order, and the sorted keys hold the order itself.
    key = np.sort((code << np.uint64(index_bits)) | np.arange(n, dtype=np.uint64))
    return (key & np.uint64((1 << index_bits) - 1)).astype(np.intp)


#: The shifts and masks that spread the low 21 (10) bits of a 64-bit (32-bit) word to every third bit.
_SPREAD_64 = ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F), (4, 0x10C30C30C30C30C3),
              (2, 0x1249249249249249))
_SPREAD_32 = ((16, 0x030000FF), (8, 0x0300F00F), (4, 0x030C30C3), (2, 0x09249249))


def numbered_locally(mesh: TetMesh) -> bool:
    """Whether consecutive points lie near each other already: on average within
    :data:`LOCAL_STEP` typical edges (the median of the cells' first edges). A structured
    grid split into tets, numbered row by row, is (about 2); the SimVascular pipe's points
    are 18 edges apart on average."""
    p = mesh.points
    steps = float(np.mean(np.linalg.norm(np.diff(p, axis=0), axis=1)))
    edge = float(np.median(np.linalg.norm(p[mesh.tets[:, 1]] - p[mesh.tets[:, 0]], axis=1)))
    return steps <= LOCAL_STEP * edge


def spatially_ordered(mesh: TetMesh) -> TetMesh:
    """``mesh`` with its points numbered along a Morton curve and its cells in the order
    :meth:`TetMesh.from_arrays` gives them (by their points); the same cells, points and
    field. The mesh itself below :data:`MIN_POINTS` points or where its points are numbered
    locally already (:func:`numbered_locally`). Cached with the mesh.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> grid = synthetic.cube(20)  # numbered row by row: kept as it is
    >>> spatially_ordered(grid) is grid
    True
    >>> rng = np.random.default_rng(0)
    >>> shuffled = rng.permutation(grid.n_points)  # the same cells, their points in no order
    >>> rank = np.argsort(shuffled)
    >>> mesh = TetMesh.from_arrays(grid.points[shuffled], rank[grid.tets], grid.scalars[shuffled])
    >>> ordered = spatially_ordered(mesh)
    >>> ordered is not mesh and ordered.n_tets == mesh.n_tets and numbered_locally(ordered)
    True
    """
    cached = _CACHE.get(id(mesh))
    if cached is not None:
        return mesh if cached is AS_IS else cached  # type: ignore[return-value]
    if mesh.n_points < MIN_POINTS:
        return mesh
    if numbered_locally(mesh):  # 90 ms on 1M tets: once, not on every view change
        _remember(mesh, AS_IS)
        return mesh
    order = morton_order(mesh.points)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    tets, rows = _canonical(rank[mesh.tets], order.size)
    points, scalars = mesh.points[order], mesh.scalars[order]
    cells = None if mesh.cell_scalars is None else mesh.cell_scalars[rows]
    for arr in (points, tets, scalars, cells):
        if arr is not None:
            arr.setflags(write=False)
    ordered = TetMesh(points=points, tets=tets, scalars=scalars, scalar_name=mesh.scalar_name, report=mesh.report,
                      cell_scalars=cells)
    ordered.__dict__["float32_origin"] = mesh.float32_origin  # the same float32 frame as the mesh's
    _remember(mesh, ordered)
    return ordered


def _remember(mesh: TetMesh, found: "TetMesh | str") -> None:
    """Cache what :func:`spatially_ordered` found for ``mesh`` as long as the mesh lives."""
    with _LOCK:
        _CACHE[id(mesh)] = found
        weakref.finalize(mesh, _CACHE.pop, id(mesh), None)


def _canonical(tets: NDArray[np.int64], n_points: int) -> tuple[NDArray[np.int32], NDArray[np.intp]]:
    """Cells renumbered from a mesh's (each positively oriented) in the form
    :meth:`TetMesh.from_arrays` gives: each row's ids increasing but for the last two,
    swapped where the sort turned the cell inside out, and the rows in lexicographic order.
    Returns the rows and, for each, its row in ``tets``. (The cells are the mesh's own, so
    none is checked or dropped again: from_arrays takes 5x longer.)"""
    by_id = np.argsort(tets, axis=1, kind="stable")
    rows = np.take_along_axis(tets, by_id, axis=1)
    # The sort's parity: the number of pairs it puts the other way round.
    odd = np.zeros(tets.shape[0], dtype=bool)
    for i in range(4):
        for j in range(i + 1, 4):
            odd ^= by_id[:, i] > by_id[:, j]
    rows[odd] = rows[odd][:, [0, 1, 3, 2]]
    if float(n_points) ** 3 < 2.0**62:  # two stable sorts, by the last id and by the first three
        order = np.argsort(rows[:, 3], kind="stable")
        key = (rows[order, 0] * n_points + rows[order, 1]) * n_points + rows[order, 2]
        order = order[np.argsort(key, kind="stable")]
    else:
        order = np.lexsort(rows.T[::-1])
    return rows[order].astype(np.int32), order

"""Meshes as FEM and CFD tools write them: the imperfections the default method must draw
right or route (:mod:`tetvr.order.walkable`), built from a clean mesh.

``tests/test_imperfect_meshes.py`` holds each class to the reference, and
``bench/imperfect.py`` measures every method on them for docs/limits.md.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh import synthetic
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["field", "regions", "copies", "conflicting_copies", "embedded_block", "cell_laid_over", "gaps", "scaled"]


def field(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """A smooth field with structure in every direction, for the synthetic cases."""
    return 0.5 + 0.4 * np.sin(3.0 * p[:, 0]) * np.cos(2.0 * p[:, 1]) + 0.3 * p[:, 2]


def regions(mesh: TetMesh, axis: int, *, jump: bool = False) -> TetMesh:
    """``mesh`` as two material regions split at the median cell along ``axis``: the second
    numbers its own copy of every node, so the regions share coordinates on the interface,
    not point ids. With ``jump`` the second region's copies carry another field, which then
    jumps at the interface (a stress recovered per material).

    Examples
    --------
    >>> m = regions(synthetic.cube(2), axis=0)
    >>> m.n_points, m.n_tets
    (54, 48)
    """
    centroid = mesh.points[mesh.tets].mean(axis=1)[:, axis]
    second = centroid > np.median(centroid)
    n = mesh.n_points
    tets = mesh.tets.astype(np.int64).copy()
    tets[second] += n
    values = np.concatenate([mesh.scalars, mesh.scalars])
    if jump:
        lo, hi = mesh.scalar_range
        values[n:] = hi - 0.7 * (values[n:] - lo)
    return TetMesh.from_arrays(np.concatenate([mesh.points, mesh.points]), tets, values,
                               scalar_name=mesh.scalar_name, cell_scalars=mesh.cell_scalars)


def copies(mesh: TetMesh, k: int) -> TetMesh:
    """Every cell ``k`` times, each copy on its own nodes (a ``.vtm`` naming a piece ``k`` times)."""
    n = mesh.n_points
    return TetMesh.from_arrays(np.concatenate([mesh.points] * k),
                               np.concatenate([mesh.tets.astype(np.int64) + i * n for i in range(k)]),
                               np.concatenate([mesh.scalars] * k), scalar_name=mesh.scalar_name)


def conflicting_copies(mesh: TetMesh) -> TetMesh:
    """Every cell twice, the second copy with another field: two values at every point."""
    return synthetic.merge(mesh, mesh.with_scalars(mesh.scalars + 0.5 * float(np.ptp(mesh.scalars) or 1.0)))


def embedded_block() -> TetMesh:
    """A refined block exported beside the coarse cells it replaces: a cube of 6^3 hexahedra
    inside one of 3^3, overlapping its cells."""
    coarse = synthetic.cube(3, field, rotate=False)
    fine = synthetic.cube(6, size=0.4, rotate=False)
    pts = fine.points + (0.05, 0.02, 0.01)
    return synthetic.merge(coarse, TetMesh.from_arrays(pts, fine.tets, field(pts)))


def cell_laid_over() -> TetMesh:
    """One cell laid over the cells of a cube, sharing no face with them."""
    corners = np.array([[0.0, 0.0, 0.0], [0.3, 0.02, 0.05], [0.04, 0.31, 0.02], [0.03, 0.05, 0.29]]) - 0.1
    extra = TetMesh.from_arrays(corners, np.array([[0, 1, 2, 3]]), field(corners))
    return synthetic.merge(synthetic.cube(3, field, rotate=False), extra)


def gaps(n: int = 4, layers: int = 12) -> TetMesh:
    """Layers of hexahedra split into six tets each, every other layer split the mirror way,
    so the two layers' triangles on the plane between them do not match: a ray crossing it
    leaves the mesh and enters it again at one depth, as where a mesher's zero-volume cells
    were dropped (``layers - 1`` such planes; :attr:`tetvr.order.walkable.WalkCheck.most_entries`).

    Examples
    --------
    >>> gaps(2, 3).n_tets
    72
    """
    ids = np.arange((n + 1) ** 2 * (layers + 1)).reshape(layers + 1, n + 1, n + 1)  # [z, y, x]
    k, j, i = (a.reshape(-1) for a in np.meshgrid(np.arange(layers), np.arange(n), np.arange(n), indexing="ij"))
    cells = []
    for perm in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):  # Kuhn's six paths 0 -> 1
        corner = np.zeros(3, dtype=np.int64)
        path = [corner.copy()]
        for axis in perm:
            corner[axis] = 1
            path.append(corner.copy())
        cells.append(np.stack([ids[k + c[2], j + c[1], np.where(k % 2 == 1, i + 1 - c[0], i + c[0])]
                               for c in path], axis=1))
    z, y, x = np.meshgrid(np.arange(layers + 1), np.arange(n + 1), np.arange(n + 1), indexing="ij")
    points = np.stack([x.reshape(-1) / n, y.reshape(-1) / n, z.reshape(-1) / layers], axis=1) - 0.5
    return TetMesh.from_arrays(points, np.concatenate(cells), field(points))


def scaled(mesh: TetMesh, factor: float) -> TetMesh:
    """``mesh`` with its coordinates multiplied by ``factor``."""
    return TetMesh.from_arrays(mesh.points * factor, mesh.tets, mesh.scalars, scalar_name=mesh.scalar_name,
                               cell_scalars=mesh.cell_scalars)

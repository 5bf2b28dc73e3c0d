"""Meshes as FEM and CFD tools write them: the imperfections the default method must draw
right or route (:mod:`tetvr.order.walkable`), built from a clean mesh.

``tests/test_imperfect_meshes.py`` holds each class to the reference, and
``bench/imperfect.py`` measures every method on them for docs/limits.md.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh import synthetic
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["field", "regions", "copies", "conflicting_copies", "embedded_block", "cell_laid_over", "gaps", "delaunay_pipe", "scaled"]


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


#: The pipe of :func:`delaunay_pipe`: radius, length, and its wall layers (first thickness,
#: growth, count).
PIPE_RADIUS, PIPE_LENGTH = 1.0, 6.0
WALL_FIRST, WALL_GROWTH, WALL_LAYERS = 0.002, 1.25, 18


def delaunay_pipe(around: int = 64, along: int = 80, *, jitter: bool = True, seed: int = 7) -> TetMesh:
    """A pipe whose points crowd towards the wall in a geometric boundary layer (first layer
    0.2 % of the radius, growth 1.25; ``around`` points round each ring, ``along`` rings),
    joined by a Delaunay tetrahedralisation (scipy), with a developing pipe flow and a wake:
    the graded, stretched cells and the slivers of a CFD mesh. Points on exact circles and
    planes make a tenth of the cells flat (dropped: gaps, :func:`gaps`); ``jitter`` moves them
    by 5 % of the thinnest layer, which leaves a few.

    Examples
    --------
    >>> delaunay_pipe(8, 6).n_tets > 1000  # doctest: +SKIP
    True
    """
    from scipy.spatial import Delaunay  # tetvr[mesh]

    rng = np.random.default_rng(seed)
    pts = _pipe_points(around, along, rng)
    if jitter:
        pts += rng.normal(scale=0.05 * WALL_FIRST, size=pts.shape)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "dropped N zero-volume tetrahedra"
        return TetMesh.from_arrays(pts, Delaunay(pts).simplices, _pipe_flow(pts), scalar_name="velocity")


def _pipe_points(around: int, along: int, rng: np.random.Generator) -> NDArray[np.float64]:
    """Points of the pipe: rings graded towards the wall, staggered, and a random core."""
    layers = PIPE_RADIUS - WALL_FIRST * np.cumsum(WALL_GROWTH ** np.arange(WALL_LAYERS))
    layers = np.concatenate([[PIPE_RADIUS], layers[layers > 0.35 * PIPE_RADIUS]])
    z = np.linspace(0.0, PIPE_LENGTH, along)
    angle = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    rings = []
    for i, r in enumerate(layers):
        a = angle + (0.5 * i % 1.0) * (angle[1] - angle[0])
        rr, zz = np.meshgrid(np.full(a.shape, r), z, indexing="ij")
        aa = np.broadcast_to(a[:, None], rr.shape)
        rings.append(np.stack([rr * np.cos(aa), rr * np.sin(aa), zz], axis=-1).reshape(-1, 3))
    inner = layers[-1]  # the core: random points up to the innermost layer, about as far apart
    h = 2.0 * np.pi * inner / around
    u = rng.random((int(np.pi * inner**2 * PIPE_LENGTH / h**3 * 1.2), 3))
    r, a = 0.97 * inner * np.sqrt(u[:, 0]), 2.0 * np.pi * u[:, 1]
    return np.concatenate(rings + [np.stack([r * np.cos(a), r * np.sin(a), PIPE_LENGTH * u[:, 2]], axis=-1)])


def _pipe_flow(p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Axial velocity: a wall layer thickening downstream, less the wake of an obstacle."""
    r = np.hypot(p[:, 0], p[:, 1]) / PIPE_RADIUS
    delta = 0.02 + 0.08 * p[:, 2] / PIPE_LENGTH
    wake = 0.6 * np.exp(-((p[:, 0] - 0.2) ** 2 + p[:, 1] ** 2) / 0.05 - (p[:, 2] - 2.0) / 2.5) * (p[:, 2] > 2.0)
    return np.tanh((1.0 - r) / delta) * (1.0 + 0.3 * (1.0 - r**2)) - wake


def scaled(mesh: TetMesh, factor: float) -> TetMesh:
    """``mesh`` with its coordinates multiplied by ``factor``."""
    return TetMesh.from_arrays(mesh.points * factor, mesh.tets, mesh.scalars, scalar_name=mesh.scalar_name,
                               cell_scalars=mesh.cell_scalars)

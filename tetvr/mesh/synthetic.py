"""Small analytic scenes for tests, benchmarks and documentation.

Each returns a :class:`~tetvr.mesh.tetmesh.TetMesh` whose exact image is easy to reason about.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh.tetmesh import TetMesh

__all__ = ["single_tet", "two_tets", "cube", "slab", "linear_field", "torus", "interlocking_rings", "merge"]

# The six tets of the Freudenthal (Kuhn) split of a unit cube, all around the main
# diagonal 0-7; corners are numbered by bits (x, y, z) = (c & 1, c >> 1 & 1, c >> 2 & 1).
_KUHN = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])


def linear_field(gradient: tuple[float, float, float] = (1.0, 0.0, 0.0), offset: float = 0.0) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """A scalar field ``g . x + offset`` (piecewise-linear interpolation is exact for it)."""
    g = np.asarray(gradient, dtype=np.float64)
    return lambda p: p @ g + offset


def single_tet(scalars: tuple[float, float, float, float] = (0.5, 0.5, 0.5, 0.5)) -> TetMesh:
    """A well-shaped tet around the origin with the given vertex scalars."""
    pts = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]]) * 0.5
    pts = pts @ _rotation(0.3, 0.2)
    return TetMesh.from_arrays(pts, [[0, 1, 2, 3]], scalars)


def two_tets(scalars: tuple[float, ...] = (0.0, 0.3, 0.6, 1.0, 0.8)) -> TetMesh:
    """Two tets sharing the face (0, 1, 2), with a different scalar at each apex."""
    pts = np.array([[-0.6, -0.5, 0.0], [0.6, -0.5, 0.0], [0.0, 0.6, 0.0], [0.1, 0.0, 0.7], [-0.1, 0.05, -0.6]])
    pts = pts @ _rotation(0.4, -0.25)
    return TetMesh.from_arrays(pts, [[0, 1, 2, 3], [0, 1, 2, 4]], scalars)


def cube(n: int = 1, field: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
         *, size: float = 1.0, rotate: bool = True) -> TetMesh:
    """A cube of ``n^3`` hexahedra, each split into 6 conforming tets, centred at 0."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    g = np.linspace(-0.5, 0.5, n + 1) * size
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    pts = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij"))
    corners = np.stack([idx[i + (c & 1), j + (c >> 1 & 1), k + (c >> 2 & 1)] for c in range(8)], axis=1)
    tets = corners[:, _KUHN].reshape(-1, 4)
    if rotate:
        pts = pts @ _rotation(0.5, 0.35)
    field = field or linear_field((0.6, 0.3, -0.4), 0.5)
    return TetMesh.from_arrays(pts, tets, field(pts))


def slab(thickness: float = 0.1, width: float = 1.0, value: float = 0.5, n: int = 4) -> TetMesh:
    """An axis-aligned box ``width x width x thickness`` (z) of constant scalar, n x n x 1 hexes."""
    g = np.linspace(-0.5, 0.5, n + 1) * width
    gz = np.array([-0.5, 0.5]) * thickness
    x, y, z = np.meshgrid(g, g, gz, indexing="ij")
    pts = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    idx = np.arange(pts.shape[0]).reshape(n + 1, n + 1, 2)
    i, j = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n), indexing="ij"))
    corners = np.stack([idx[i + (c & 1), j + (c >> 1 & 1), (c >> 2 & 1)] for c in range(8)], axis=1)
    return TetMesh.from_arrays(pts, corners[:, _KUHN].reshape(-1, 4), np.full(pts.shape[0], value))


def torus(major: float = 1.0, minor: float = 0.3, n_around: int = 24, n_cross: int = 2,
          field: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None) -> TetMesh:
    """A ring of square cross-section (side 2*minor) around the z axis: a closed loop of
    ``n_around x n_cross x n_cross`` hexahedra, each split into 6 conforming tets.

    Non-convex: rays cross it twice, and coarse rings fool centroid sorting.
    """
    if n_around < 3 or n_cross < 1:
        raise ValueError(f"need n_around >= 3 and n_cross >= 1, got {n_around}, {n_cross}")
    ang = np.linspace(0.0, 2 * np.pi, n_around, endpoint=False)
    off = np.linspace(-minor, minor, n_cross + 1)
    a, r, z = np.meshgrid(ang, major + off, off, indexing="ij")
    pts = np.stack([r * np.cos(a), r * np.sin(a), z], axis=-1).reshape(-1, 3)
    idx = np.arange(pts.shape[0]).reshape(n_around, n_cross + 1, n_cross + 1)
    i, j, k = (v.ravel() for v in np.meshgrid(np.arange(n_around), np.arange(n_cross), np.arange(n_cross), indexing="ij"))
    corners = np.stack([idx[(i + (c & 1)) % n_around, j + (c >> 1 & 1), k + (c >> 2 & 1)] for c in range(8)], axis=1)
    field = field or (lambda p: np.arctan2(p[:, 1], p[:, 0]) / (2 * np.pi) + 0.5)
    return TetMesh.from_arrays(pts, corners[:, _KUHN].reshape(-1, 4), field(pts))


def merge(*meshes: TetMesh) -> TetMesh:
    """One mesh of several (disconnected) meshes."""
    pts, tets, vals, base = [], [], [], 0
    for m in meshes:
        pts.append(m.points)
        tets.append(m.tets.astype(np.int64) + base)
        vals.append(m.scalars)
        base += m.n_points
    return TetMesh.from_arrays(np.concatenate(pts), np.concatenate(tets), np.concatenate(vals))


def interlocking_rings(n_around: int = 12, n_cross: int = 1) -> TetMesh:
    """Two linked rings (like chain links): non-convex, disconnected, and each ring passes
    through the other, so no single back-to-front order of coarse cells by centroid exists."""
    a = torus(1.0, 0.25, n_around, n_cross)
    b = torus(1.0, 0.25, n_around, n_cross, field=lambda p: (0.25 + 0.5 * (p[:, 2] > 0)).astype(np.float64))
    rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # ring b stands upright
    b_pts = b.points @ rot.T + np.array([1.0, 0.0, 0.0])
    b = TetMesh.from_arrays(b_pts, b.tets, b.scalars)
    return merge(a, b)


def _rotation(a: float, b: float) -> NDArray[np.float64]:
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cb, -sb], [0.0, sb, cb]])
    return rz @ rx

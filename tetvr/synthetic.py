"""Small analytic scenes for tests, benchmarks and documentation.

Each returns a :class:`~tetvr.mesh.TetMesh` whose exact image is easy to reason about.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .mesh import TetMesh

__all__ = ["single_tet", "two_tets", "cube", "slab", "linear_field"]

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


def _rotation(a: float, b: float) -> NDArray[np.float64]:
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cb, -sb], [0.0, sb, cb]])
    return rz @ rx

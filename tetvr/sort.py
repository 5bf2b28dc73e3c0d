"""Visibility ordering of the cells, back to front.

About this technique
--------------------
Projected tetrahedra composite each cell's contribution with the "over" operator, so the
cells must be drawn back to front. ``centroid`` sorts by the distance of each centroid
from the eye (perspective) or by its depth along the view axis (parallel): exact for
many meshes and views, wrong where a large cell's centroid is nearer than a small cell
it hides (Williams 1992 gives MPVONC for an exact order on convex meshes).

Ties are broken by the cell's position in the mesh, which is canonical (see
:class:`~tetvr.mesh.TetMesh`), so the order does not depend on how the input was listed.
The sort is a stable LSD radix sort over two 16-bit halves of a monotone 32-bit key,
which numpy runs in linear time.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .camera import Camera
from .mesh import TetMesh

__all__ = ["visibility_order", "centroid_order", "SORTERS"]


def _radix_argsort_desc(key: NDArray[np.float32]) -> NDArray[np.uint32]:
    """Stable argsort of float32 keys, descending, in two 16-bit counting passes."""
    bits = key.view(np.uint32)
    # Map IEEE floats to unsigned ints with the same order, then invert for descending.
    neg = (bits >> 31).astype(bool)
    ordered = np.where(neg, ~bits, bits | np.uint32(0x80000000))
    desc = ~ordered
    lo = (desc & np.uint32(0xFFFF)).astype(np.uint16)
    hi = (desc >> np.uint32(16)).astype(np.uint16)
    first = np.argsort(lo, kind="stable")
    second = np.argsort(hi[first], kind="stable")
    return first[second].astype(np.uint32)


def centroid_order(mesh: TetMesh, camera: Camera) -> NDArray[np.uint32]:
    """Cell ids back to front by centroid (distance to the eye, or depth if parallel)."""
    c = mesh.centroids
    eye = np.asarray(camera.position)
    if camera.parallel_projection:
        key = (c - eye) @ np.asarray(camera.direction)
    else:
        diff = c - eye
        key = np.einsum("ij,ij->i", diff, diff)  # squared distance orders the same
    return _radix_argsort_desc(key.astype(np.float32))


def _input_order(mesh: TetMesh, camera: Camera) -> NDArray[np.uint32]:
    return np.arange(mesh.n_tets, dtype=np.uint32)


SORTERS: dict[str, Callable[[TetMesh, Camera], NDArray[np.uint32]]] = {
    "centroid": centroid_order,
    "none": _input_order,
}


def visibility_order(mesh: TetMesh, camera: Camera, method: str = "centroid") -> NDArray[np.uint32]:
    """Cell ids in drawing order (back to front) for ``method`` (see :data:`SORTERS`)."""
    try:
        sorter = SORTERS[method]
    except KeyError:
        raise ValueError(f"unknown sort method {method!r}; choose one of {sorted(SORTERS)}") from None
    return sorter(mesh, camera)

"""Boxes of runs of nearby tets, so that the rays of a few pixels skip most of a mesh.

A frame of tet marching that checks itself traces a few of its pixels again on the CPU
(:mod:`tetvr.gl.selfcheck`), and :func:`tetvr.reference.tets.render_reference_pixels`
first finds the tets whose screen boxes may hold those pixels. Projecting every tet costs
a pass over the mesh per frame (0.2 s for a 924k-tet mesh on two cores, for a handful of
pixels). Here the tets are put in Morton order of their centroids once per mesh, and each
run of :data:`RUN` of them gets its bounding box in mesh coordinates; per view, only the
eight corners of each box are projected, and only the tets of the runs whose boxes may
hold a pixel are projected one by one.

Building the boxes costs more than one pass projecting every tet (1.2 s against 0.8 s
on a 2.9M-tet mesh), so a mesh's first few pixels are found by that pass, while its boxes
are built in the background for the frames after (``wait=False``, as the reference's
pixels ask).

The boxes never lose a tet: where all eight corners lie in front of the near plane, the
perspective (or parallel) projection of a box is the convex hull of its corners'
projections, which holds the projection of every vertex in it; a box with a corner behind
the near plane is kept whole, as the tets that reach the near plane are.
"""

from __future__ import annotations

import threading
import weakref
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from tetvr.core.rays import EyeRays
from tetvr.mesh.locality import morton_order
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["RUN", "MIN_TETS", "TetBoxes", "tet_boxes", "candidates"]

#: Tets a box bounds.
RUN = 64
#: Meshes with fewer tets than this are projected tet by tet (as cheap as their boxes).
MIN_TETS = 1 << 15
#: Pixels a box's projection is widened by against rounding (the exact tests come after).
MARGIN_PX = 1.0

_CACHE: dict[int, "TetBoxes"] = {}
_BUILDING: set[int] = set()  # meshes whose boxes a background thread builds
_LOCK = threading.Lock()


class TetBoxes:
    """A mesh's tets in Morton order of their centroids (``order``) and the bounding box
    (``lo``, ``hi``: (runs, 3) in mesh coordinates) of each run of :data:`RUN` of them."""

    def __init__(self, mesh: TetMesh) -> None:
        pts, tets = mesh.points, mesh.tets
        centre = pts[tets[:, 0]] + pts[tets[:, 1]] + pts[tets[:, 2]] + pts[tets[:, 3]]  # 4x the centroid
        self.order = morton_order(centre).astype(np.int32 if tets.shape[0] < 2**31 else np.int64)
        starts = np.arange(0, tets.shape[0], RUN)  # (RUN is read here: tests change it)
        lo = hi = None
        for k in range(4):  # one corner column at a time: n x 3 temporaries
            v = pts[tets[self.order, k]]
            run_lo, run_hi = np.minimum.reduceat(v, starts, axis=0), np.maximum.reduceat(v, starts, axis=0)
            lo = run_lo if lo is None else np.minimum(lo, run_lo)
            hi = run_hi if hi is None else np.maximum(hi, run_hi)
        assert lo is not None and hi is not None
        self.lo, self.hi = lo, hi
        self.n_tets, self.run = tets.shape[0], RUN


def tet_boxes(mesh: TetMesh) -> TetBoxes:
    """The :class:`TetBoxes` of ``mesh``, cached with it."""
    cached = _cached(mesh)
    if cached is not None:
        return cached
    boxes = TetBoxes(mesh)
    with _LOCK:
        _CACHE[id(mesh)] = boxes
        weakref.finalize(mesh, _CACHE.pop, id(mesh), None)
    return boxes


def _cached(mesh: TetMesh) -> TetBoxes | None:
    cached = _CACHE.get(id(mesh))
    return cached if cached is not None and cached.run == RUN else None


def _build_later(mesh: TetMesh) -> None:
    """Build ``mesh``'s boxes in a daemon thread, unless one does already."""
    with _LOCK:
        if id(mesh) in _BUILDING:
            return
        _BUILDING.add(id(mesh))

    def build() -> None:
        try:
            tet_boxes(mesh)
        finally:
            with _LOCK:
                _BUILDING.discard(id(mesh))

    threading.Thread(target=build, name="tetvr-boxes", daemon=True).start()


def candidates(mesh: TetMesh, position: NDArray[np.float64], rotation: NDArray[np.float64], rays: EyeRays,
               project: Callable[..., tuple[NDArray[np.float64], NDArray[np.float64]]],
               held: Callable[..., NDArray[np.bool_]], *, wait: bool = True) -> NDArray[np.int64] | None:
    """The tets (increasing ids) of the runs whose boxes may hold one of the pixels that
    ``held`` counts: ``held(col_min, col_max, row_min, row_max)`` says, per box, whether
    its range of pixel coordinates holds one. Eye space is ``(x - position) @ rotation.T``,
    ``project(x, y, depth or None, rays)`` its pixel coordinates (the tets' own, for the
    same arithmetic). None below :data:`MIN_TETS` tets (every tet is a candidate), and,
    with ``wait=False``, where the mesh's boxes are not built yet (they are then built in
    the background)."""
    if mesh.n_tets < MIN_TETS:
        return None
    boxes = _cached(mesh)
    if boxes is None:
        if not wait:
            _build_later(mesh)
            return None
        boxes = tet_boxes(mesh)

    corners = np.stack([np.where([(c >> a) & 1 for a in range(3)], boxes.hi, boxes.lo) for c in range(8)], axis=1)
    eye = (corners - position) @ rotation.T  # (runs, 8, 3)
    depth = -eye[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        col, row = project(eye[..., 0], eye[..., 1], None if rays.parallel else depth, rays)
    loose = ~(np.isfinite(col) & np.isfinite(row)).all(axis=1)
    if not rays.parallel:
        loose |= (depth < rays.near).any(axis=1)
    col, row = np.where(np.isfinite(col), col, 0.0), np.where(np.isfinite(row), row, 0.0)
    keep = loose | held(col.min(axis=1) - MARGIN_PX, col.max(axis=1) + MARGIN_PX,
                        row.min(axis=1) - MARGIN_PX, row.max(axis=1) + MARGIN_PX)
    runs = np.flatnonzero(keep)
    ids = (runs[:, None] * boxes.run + np.arange(boxes.run)).reshape(-1)
    return np.sort(boxes.order[ids[ids < boxes.n_tets]].astype(np.int64))

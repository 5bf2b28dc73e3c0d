"""Visibility ordering of the cells, back to front.

About this technique
--------------------
Projected tetrahedra composite each cell's contribution with the "over" operator, so the
cells must be drawn back to front. ``centroid`` sorts by the distance of each centroid
from the eye (perspective) or by its depth along the view axis (parallel): fast, but wrong
where a large cell's centroid is nearer than a small cell it hides.

``mpvo`` and ``mpvonc`` are Williams' Meshed Polyhedra Visibility Ordering (P. L.
Williams, "Visibility-ordering meshed polyhedra", ACM TOG 11(2), 1992). Two tets that
share a face are ordered by that face's plane: the one on the eye's side of it is in
front, so it is drawn later. Every interior face thus becomes an edge "draw A before B"
of a directed graph over the cells, and any topological order of that graph is a
visibility order when the mesh is convex and the graph acyclic (it always is for a
Delaunay mesh). The face test is made against the *eye point*, ``n . eye - d``, not the
view direction, so the order is right in perspective, including for cells beside or
around the eye; VTK's and HAPT's sorters order for a single view direction, which is
exact only for a parallel projection. With ``parallel_projection`` the view direction is
used, as it should be. A face seen exactly edge-on (the eye in its plane, within
rounding) gives no edge: the two cells cannot overlap on screen then, and leaving the
edge out cannot create a cycle.

The topological sort is Kahn's algorithm run level by level, each level one vectorised
numpy step: all ready cells (every cell behind them already drawn) are emitted at once
and the cells in front of them are tested for readiness. The number of levels grows like
the mesh's diameter in cells, O(m^(1/3)), so a million tets take a few hundred steps.

``mpvo`` emits each whole level, ordered inside by decreasing centroid distance: exact
for convex meshes. On a mesh with cavities or several components, cells with no face path
between them are not ordered at all, so a cell far behind can be drawn after a near one.
``mpvonc`` is the non-convex variant. Williams' MPVONC takes the cells that start the
sort (those whose back faces are all on the boundary) in order of distance from the
viewpoint instead of all at once; here that is generalised to every ready cell: a step
emits only the ready cells within ``depth_window`` (default: two typical cell sizes) of
the farthest ready one. Every face constraint still holds (a ready cell is never
blocked), and cells that the graph does not relate come out back to front, as in the
centroid sort. Like Williams' heuristic this is not exact for every non-convex mesh.

A cycle (possible in non-Delaunay meshes and in degenerate views) leaves cells that
never become ready. It is broken by drawing one cell regardless: among the blocked cells
reached so far, the one with the fewest undrawn cells behind it, then the farthest, then
the lowest id. The number of breaks is reported in :class:`SortStats`
(:func:`sort_with_stats`); it is zero whenever the order satisfies every face constraint.

Ties are broken by the cell's position in the mesh, which is canonical (see
:class:`~tetvr.mesh.TetMesh`), so the order does not depend on how the input was listed.
The centroid sort is a stable LSD radix sort over two 16-bit halves of a monotone 32-bit
key, which numpy runs in linear time.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .adjacency import FaceAdjacency, face_adjacency
from .camera import Camera
from .mesh import TetMesh

__all__ = [
    "visibility_order",
    "sort_with_stats",
    "centroid_order",
    "mpvo_order",
    "mpvonc_order",
    "SortStats",
    "SORTERS",
]


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


@dataclasses.dataclass(frozen=True)
class SortStats:
    """What one visibility sort did (for render statistics and logs).

    Attributes
    ----------
    method : the sort method.
    n_cells : cells ordered.
    n_steps : vectorised steps taken (graph levels for ``mpvo``; 1 for the others).
    n_sources : cells with no cell behind them across a face (0 for non-graph methods).
    n_constraints : interior faces that gave an ordering edge.
    n_edge_on : interior faces seen edge-on (no edge needed).
    n_cycle_breaks : cells drawn before a cell behind them to break a cycle; nonzero
        means the order is not a visibility order somewhere.

    Examples
    --------
    >>> from tetvr import synthetic
    >>> mesh = synthetic.cube(2)
    >>> ids, stats = mpvonc_order(mesh, Camera.fit(mesh))
    >>> stats.n_cells, stats.n_cycle_breaks
    (48, 0)
    """

    method: str
    n_cells: int
    n_steps: int = 1
    n_sources: int = 0
    n_constraints: int = 0
    n_edge_on: int = 0
    n_cycle_breaks: int = 0


def _eye_side(adj: FaceAdjacency, camera: Camera) -> NDArray[np.float64]:
    """Signed side of every face plane, (m, 4): > 0 when the eye is outside the face.

    Values within rounding of zero are set to exactly 0 (the face is seen edge-on).
    """
    flat_n = adj.normals.reshape(-1, 3)
    if camera.parallel_projection:
        # The eye at infinity behind the view direction: only the direction matters.
        toward_eye = -np.asarray(camera.direction)
        side = flat_n @ toward_eye
        tol = 64.0 * np.finfo(np.float64).eps
    else:
        eye = np.asarray(camera.position) - adj.origin
        side = flat_n @ eye
        side -= adj.offsets.reshape(-1)
        # |normal| = 1 and |offset| <= radius, so this bounds the rounding error of the test.
        tol = 64.0 * np.finfo(np.float64).eps * (float(np.linalg.norm(eye)) + adj.radius)
    side[np.abs(side) <= tol] = 0.0
    return side.reshape(-1, 4)


def _depth(mesh: TetMesh, camera: Camera) -> NDArray[np.float64]:
    """Distance of each centroid from the eye (perspective) or depth along the view axis."""
    diff = mesh.centroids - np.asarray(camera.position)
    if camera.parallel_projection:
        return diff @ np.asarray(camera.direction)
    return np.sqrt(np.einsum("ij,ij->i", diff, diff))


def _graph_order(mesh: TetMesh, camera: Camera, method: str, window: float) -> tuple[NDArray[np.uint32], SortStats]:
    """Kahn's topological sort of the face graph, one vectorised step per batch.

    A step emits the ready cells within ``window`` of the farthest ready cell (all of
    them when ``window`` is infinite), farthest first.
    """
    adj = face_adjacency(mesh)
    m = mesh.n_tets
    side = _eye_side(adj, camera)
    interior = adj.neighbors >= 0
    # behind[t, k]: the neighbour across face k is behind t (the eye is on t's side of
    # the face), so it must be drawn first. front[t, k]: t must be drawn first.
    behind = (side < 0) & interior
    front = (side > 0) & interior
    n_constraints = int(np.count_nonzero(front))
    n_edge_on = int(np.count_nonzero(interior)) // 2 - n_constraints
    key = _depth(mesh, camera)
    nbr = adj.neighbors

    # One extra slot so that the boundary marker -1 indexes a cell that counts as drawn.
    drawn = np.zeros(m + 1, dtype=bool)
    drawn[m] = True
    stamp = np.zeros(m, dtype=np.intp)
    order = np.empty(m, dtype=np.uint32)
    ready = np.flatnonzero(~behind.any(axis=1))
    n_sources = int(ready.size)
    ready_key = key[ready]
    blocked_seen: list[NDArray[np.intp]] = []
    pos = steps = breaks = 0
    while pos < m:
        if ready.size == 0:
            cell, blocked_seen = _break_cycle(blocked_seen, drawn, behind, nbr, key)
            batch = np.array([cell], dtype=np.intp)
            breaks += 1
        else:
            if math.isfinite(window):
                take = ready_key >= ready_key.max() - window
                batch, batch_key = ready[take], ready_key[take]
                ready, ready_key = ready[~take], ready_key[~take]
            else:
                batch, batch_key = ready, ready_key
                ready = ready[:0]
                ready_key = ready_key[:0]
            batch = batch[np.lexsort((batch, -batch_key))]
        steps += 1
        order[pos:pos + batch.size] = batch
        pos += batch.size
        drawn[batch] = True
        # Cells in front of the batch; each is ready once nothing behind it is undrawn.
        succ = nbr[batch][front[batch]].astype(np.intp)
        if succ.size == 0:
            continue
        succ = succ[~drawn[succ]]  # a cell drawn to break a cycle is done already
        waiting = (behind[succ] & ~drawn[nbr[succ]]).any(axis=1)
        new = succ[~waiting]
        if new.size:
            # A cell can follow several cells of the batch: keep one copy.
            idx = np.arange(new.size)
            stamp[new] = idx
            new = new[stamp[new] == idx]
            ready = np.concatenate((ready, new))
            ready_key = np.concatenate((ready_key, key[new]))
        if waiting.any():
            blocked_seen.append(succ[waiting])
    stats = SortStats(method=method, n_cells=m, n_steps=steps, n_sources=n_sources,
                      n_constraints=n_constraints, n_edge_on=n_edge_on, n_cycle_breaks=breaks)
    return order, stats


def _break_cycle(
    blocked_seen: list[NDArray[np.intp]],
    drawn: NDArray[np.bool_],
    behind: NDArray[np.bool_],
    nbr: NDArray[np.int32],
    key: NDArray[np.float64],
) -> tuple[int, list[NDArray[np.intp]]]:
    """The cell to draw next when no cell is ready: every undrawn cell waits on another.

    Candidates are the blocked cells reached so far (the rim of the cycle region), or all
    undrawn cells when none was reached (a component with no source at all).
    """
    cand = np.unique(np.concatenate(blocked_seen)) if blocked_seen else np.empty(0, dtype=np.intp)
    cand = cand[~drawn[cand]]
    if cand.size == 0:
        cand = np.flatnonzero(~drawn[:-1])
    undrawn_behind = (behind[cand] & ~drawn[nbr[cand]]).sum(axis=1)
    pick = np.lexsort((cand, -key[cand], undrawn_behind))[0]
    return int(cand[pick]), [cand]


def mpvo_order(mesh: TetMesh, camera: Camera) -> tuple[NDArray[np.uint32], SortStats]:
    """Williams' MPVO: cell ids back to front, exact for a convex mesh, and the sort's stats.

    Examples
    --------
    >>> from tetvr import synthetic
    >>> mesh = synthetic.two_tets()
    >>> ids, stats = mpvo_order(mesh, Camera(position=(0.0, 0.0, 5.0)))
    >>> sorted(ids.tolist()), stats.n_constraints
    ([0, 1], 1)
    """
    return _graph_order(mesh, camera, "mpvo", math.inf)


def mpvonc_order(
    mesh: TetMesh, camera: Camera, *, depth_window: float | None = None
) -> tuple[NDArray[np.uint32], SortStats]:
    """MPVONC: MPVO that also orders unrelated cells by depth; for non-convex meshes too.

    Parameters
    ----------
    depth_window : a step emits the ready cells whose centroid is at most this much
        nearer than the farthest ready cell. Smaller is closer to a strict
        farthest-first order and takes more steps; ``math.inf`` gives MPVO. The default
        is twice the median longest edge of the tets.

    Examples
    --------
    >>> from tetvr import synthetic
    >>> mesh = synthetic.cube(3)
    >>> ids, stats = mpvonc_order(mesh, Camera.fit(mesh))
    >>> ids.shape, stats.n_cycle_breaks
    ((162,), 0)
    """
    if depth_window is None:
        window = 2.0 * face_adjacency(mesh).cell_size
    else:
        window = float(depth_window)
        if not window >= 0:
            raise ValueError(f"depth_window must be >= 0, got {depth_window!r}")
    return _graph_order(mesh, camera, "mpvonc", window)


def _input_order(mesh: TetMesh, camera: Camera) -> NDArray[np.uint32]:
    return np.arange(mesh.n_tets, dtype=np.uint32)


SORTERS: dict[str, Callable[[TetMesh, Camera], NDArray[np.uint32]]] = {
    "centroid": centroid_order,
    "mpvo": lambda mesh, camera: mpvo_order(mesh, camera)[0],
    "mpvonc": lambda mesh, camera: mpvonc_order(mesh, camera)[0],
    "none": _input_order,
}

#: Sorters that also report :class:`SortStats` (the others report one step, no graph).
_SORTERS_WITH_STATS: dict[str, Callable[[TetMesh, Camera], tuple[NDArray[np.uint32], SortStats]]] = {
    "mpvo": mpvo_order,
    "mpvonc": mpvonc_order,
}


def visibility_order(mesh: TetMesh, camera: Camera, method: str = "centroid") -> NDArray[np.uint32]:
    """Cell ids in drawing order (back to front) for ``method`` (see :data:`SORTERS`)."""
    try:
        sorter = SORTERS[method]
    except KeyError:
        raise ValueError(f"unknown sort method {method!r}; choose one of {sorted(SORTERS)}") from None
    return sorter(mesh, camera)


def sort_with_stats(mesh: TetMesh, camera: Camera, method: str = "centroid") -> tuple[NDArray[np.uint32], SortStats]:
    """Like :func:`visibility_order`, also returning what the sort did.

    Examples
    --------
    >>> from tetvr import synthetic
    >>> mesh = synthetic.cube(2)
    >>> ids, stats = sort_with_stats(mesh, Camera.fit(mesh), "mpvonc")
    >>> stats.method, stats.n_cycle_breaks
    ('mpvonc', 0)
    """
    if method in _SORTERS_WITH_STATS:
        return _SORTERS_WITH_STATS[method](mesh, camera)
    ids = visibility_order(mesh, camera, method)
    return ids, SortStats(method=method, n_cells=mesh.n_tets)

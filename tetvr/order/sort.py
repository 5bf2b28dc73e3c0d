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
visibility order when the mesh is convex and the graph acyclic (it is acyclic from every
viewpoint for a Delaunay mesh, Edelsbrunner 1990). The face test is made against the *eye
point*, ``n . eye - d``, not the view direction, so the order is right in perspective,
including for cells beside or around the eye; the sorters of VTK and HAPT order for a
single view direction, which is exact only for a parallel projection. With
``parallel_projection`` the view direction is used, as it should be. A face seen exactly edge-on (the eye in its plane, within
rounding) gives no edge: the two cells cannot overlap on screen then, and leaving the
edge out cannot create a cycle.

The topological sort is Kahn's algorithm run level by level, each level one vectorised
numpy step: all ready cells (every cell behind them already drawn) are emitted at once
and the cells in front of them are tested for readiness. The number of levels grows like
the mesh's diameter in cells, O(m^(1/3)), so a million tets take a few hundred steps.

``mpvo`` emits each whole level, ordered inside by decreasing centroid distance: exact
for convex meshes. On a mesh with cavities or several components, cells with no face path
between them are not ordered at all, so a cell far behind can be drawn after a near one.
``mpvonc`` is the non-convex variant. Williams' MPVONC heuristic takes the cells that
start the sort (boundary cells with nothing behind them) in order of their distance from
the viewpoint instead of all at once. Here that is applied to every ready cell, so that
it also orders cells reached later: a step emits only the ready cells within
``depth_window`` (default: two typical cell sizes) of the farthest ready one. Every face constraint still holds (a ready cell is never
blocked), and cells that the graph does not relate come out back to front, as in the
centroid sort. Like Williams' heuristic this is not exact for every non-convex mesh.

A cycle (possible in non-Delaunay meshes and in degenerate views) leaves cells that
never become ready. It is broken by drawing one cell of the cycle regardless: the one with
the fewest undrawn cells behind it, then the farthest, then the lowest id (see
:func:`_break_cycle`). The number of breaks is reported in :class:`SortStats`
(:func:`sort_with_stats`); it is zero exactly when the order satisfies every face
constraint.

Ties are broken by the cell's position in the mesh, which is canonical (see
:class:`~tetvr.mesh.tetmesh.TetMesh`), so the order does not depend on how the input was listed.
The centroid sort is a stable LSD radix sort over two 16-bit halves of a monotone 32-bit
key, which numpy runs in linear time.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh.adjacency import FaceAdjacency, face_adjacency
from tetvr.order.boundary import BoundaryConstraints, boundary_constraints
from tetvr.core.camera import Camera
from tetvr.mesh.tetmesh import TetMesh

__all__ = [
    "visibility_order",
    "sort_with_stats",
    "centroid_order",
    "mpvo_order",
    "mpvonc_order",
    "xmpvo_order",
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
    # The squared distance orders the same and saves the square root.
    return _radix_argsort_desc(_depth(mesh, camera, squared=True).astype(np.float32))


@dataclasses.dataclass(frozen=True)
class SortStats:
    """What one visibility sort did (for render statistics and logs).

    Attributes
    ----------
    method : the sort method.
    n_cells : cells ordered.
    n_steps : vectorised steps taken: graph levels for ``mpvo``, depth-window batches
        for ``mpvonc``, plus one per cycle break; 1 for the non-graph methods.
    n_sources : cells with no cell behind them across a face (0 for non-graph methods).
    n_constraints : interior faces that gave an ordering edge.
    n_edge_on : interior faces seen edge-on (no edge needed).
    n_cycle_breaks : cells drawn before a cell behind them to break a cycle; nonzero
        means the order is not a visibility order somewhere.
    n_boundary_constraints : edges between cells that share no face, from rays through
        the boundary (``xmpvo`` only; see :mod:`tetvr.order.boundary`).

    Examples
    --------
    >>> from tetvr.mesh import synthetic
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
    n_boundary_constraints: int = 0


def _face_graph(adj: FaceAdjacency, camera: Camera) -> tuple[NDArray[np.int32], NDArray[np.bool_]]:
    """The per-view face graph, as the successors of each cell and its ready slots.

    Returns ``front`` and ``clear``, both (m, 4). ``front[t, k]`` is the neighbour across
    face k, as the flat slot ``4 * neighbour + j`` of the same face (see
    :attr:`FaceAdjacency.mates`), when that neighbour is in front of t (the eye is on its
    side of the face), else -1. ``clear[t, k]`` is False while a cell behind t across
    face k, which must be drawn first, is not drawn yet: True at the start for boundary
    faces, faces toward the eye, and faces within rounding of the eye's plane (seen
    edge-on, the two cells cannot overlap on screen, and a missing edge cannot close a
    cycle).
    """
    flat_n = adj.normals.reshape(-1, 3)
    if camera.parallel_projection:
        # The eye is at infinity against the view direction: only the direction matters.
        side = flat_n @ -np.asarray(camera.direction)
        tol = 64.0 * np.finfo(np.float64).eps
    else:
        eye = np.asarray(camera.position) - adj.origin
        side = flat_n @ eye
        side -= adj.offsets.reshape(-1)
        # |normal| = 1 and |offset| <= radius, so this bounds the rounding error of the test.
        tol = 64.0 * np.finfo(np.float64).eps * (float(np.linalg.norm(eye)) + adj.radius)
    side = side.reshape(-1, 4)
    front = np.where(side > tol, adj.mates, -1)
    clear = (side >= -tol) | (adj.mates < 0)
    return front, clear


def _depth(mesh: TetMesh, camera: Camera, *, squared: bool = False) -> NDArray[np.float64]:
    """Distance of each centroid from the eye (perspective; its square if ``squared``) or
    depth along the view axis (parallel)."""
    diff = mesh.centroids - np.asarray(camera.position)
    if camera.parallel_projection:
        return diff @ np.asarray(camera.direction)
    d2 = np.einsum("ij,ij->i", diff, diff)
    return d2 if squared else np.sqrt(d2)


# The four bytes of a row of `clear` read as one uint32: all True.
_ALL_CLEAR = np.frombuffer(b"\x01\x01\x01\x01", dtype=np.uint32)[0]
_SHIFT = np.uint64(32)
_LOW = np.uint64(0xFFFFFFFF)


def _graph_order(mesh: TetMesh, camera: Camera, method: str, window: float,
                 extra: BoundaryConstraints | None = None) -> tuple[NDArray[np.uint32], SortStats]:
    """Kahn's topological sort of the face graph, one vectorised step per batch.

    A step emits the ready cells within ``window`` of the farthest ready cell (all of
    them when ``window`` is infinite), farthest first. ``extra`` adds edges between cells
    that share no face (see :mod:`tetvr.order.boundary`): a cell is ready when every face slot
    is clear and every extra cell behind it is drawn.
    """
    adj = face_adjacency(mesh)
    m = mesh.n_tets
    front, clear = _face_graph(adj, camera)
    n_constraints = int(np.count_nonzero(front >= 0))
    waits, succ_ptr, succ_list, pred_ptr, pred_list = _extra_edges(extra, m)
    n_extra = 0 if extra is None else int(extra.behind.size)
    near, key = _sort_keys(mesh, camera)

    # Readiness is per face slot, not a counter per cell: a drawn cell clears the slot of
    # each successor that faces it. Every slot is hit once, so plain fancy assignment is
    # exact where a counter would need the slow np.subtract.at for repeated cells.
    clear_slots = clear.reshape(-1)
    clear_rows = clear.view(np.uint32).reshape(-1)
    drawn = np.zeros(m, dtype=bool)
    stamp = np.zeros(m, dtype=np.intp)
    order = np.empty(m, dtype=np.uint32)
    sources = np.flatnonzero((clear_rows == _ALL_CLEAR) & (waits == 0))
    ready = key[sources]
    blocked_seen: list[NDArray[np.intp]] = []
    pos = steps = breaks = 0
    while pos < m:
        if ready.size == 0:
            cell, blocked_seen = _break_cycle(blocked_seen, drawn, clear, adj.neighbors, near,
                                              waits, pred_ptr, pred_list)
            batch = np.array([cell], dtype=np.intp)
            breaks += 1
        else:
            if math.isfinite(window):
                reach = np.float32(near[int(ready.min() & _LOW)] + window)
                take = ready <= (np.uint64(reach.view(np.uint32)) << _SHIFT) | _LOW
                batch_key, ready = ready[take], ready[~take]
            else:
                batch_key, ready = ready, ready[:0]
            batch = (np.sort(batch_key, kind="stable") & _LOW).astype(np.intp)
        steps += 1
        order[pos:pos + batch.size] = batch
        pos += batch.size
        drawn[batch] = True
        slots = front[batch].reshape(-1)
        slots = slots[slots >= 0]
        clear_slots[slots] = True
        succ = slots >> 2
        if succ_ptr is not None:
            succ = _extra_successors(batch, succ_ptr, succ_list, waits, succ)
        if succ.size == 0:
            continue
        # A cell can be in front of several cells of the batch: keep one copy.
        idx = np.arange(succ.size)
        stamp[succ] = idx
        succ = succ[stamp[succ] == idx]
        done = (clear_rows[succ] == _ALL_CLEAR) & (waits[succ] == 0)
        new = succ[done & ~drawn[succ]]  # a cell drawn to break a cycle is done already
        if new.size:
            ready = np.concatenate((ready, key[new]))
        if new.size < succ.size:
            blocked_seen.append(succ[~done])
    stats = SortStats(method=method, n_cells=m, n_steps=steps, n_sources=int(sources.size),
                      n_constraints=n_constraints, n_edge_on=adj.n_interior_faces - n_constraints,
                      n_cycle_breaks=breaks, n_boundary_constraints=n_extra)
    return order, stats


def _extra_edges(extra: BoundaryConstraints | None, m: int) -> tuple[
        NDArray[np.int64], NDArray[np.intp] | None, NDArray[np.int64], NDArray[np.intp] | None,
        NDArray[np.int64] | None]:
    """The extra edges as CSR lists: how many extra cells each cell waits for, then the
    successors (cells in front: pointers, list) and the predecessors (pointers, list)."""
    # Without extra edges the pointers stay None, which keeps MPVO/MPVONC's loop as it was.
    waits = np.zeros(m, dtype=np.int64)
    succ_ptr: NDArray[np.intp] | None = None
    succ_list = np.empty(0, dtype=np.int64)
    pred_ptr: NDArray[np.intp] | None = None
    pred_list: NDArray[np.int64] | None = None
    if extra is not None and extra.behind.size:
        by_behind = np.argsort(extra.behind, kind="stable")
        succ_ptr = np.searchsorted(extra.behind[by_behind], np.arange(m + 1))
        succ_list = extra.front[by_behind]
        by_front = np.argsort(extra.front, kind="stable")
        pred_ptr = np.searchsorted(extra.front[by_front], np.arange(m + 1))
        pred_list = extra.behind[by_front]
        waits = np.bincount(extra.front, minlength=m).astype(np.int64)
    return waits, succ_ptr, succ_list, pred_ptr, pred_list


def _sort_keys(mesh: TetMesh, camera: Camera) -> tuple[NDArray[np.float32], NDArray[np.uint64]]:
    """Each cell's nearness (distance from the farthest cell) and its uint64 sort key."""
    m = mesh.n_tets
    # Each cell's sort key packs its nearness (distance from the farthest cell, float32,
    # whose bits order like the values since they are >= 0) above its id: one uint64
    # sort then orders a batch farthest first, ties by id, with no argsort and no
    # separate key array to carry along.
    depth = _depth(mesh, camera)
    near = (depth.max() - depth).astype(np.float32)
    key = (near.view(np.uint32).astype(np.uint64) << _SHIFT) | np.arange(m, dtype=np.uint64)
    return near, key


def _extra_successors(batch: NDArray[np.intp], succ_ptr: NDArray[np.intp], succ_list: NDArray[np.int64],
                      waits: NDArray[np.int64], succ: NDArray[np.int64]) -> NDArray[np.int64]:
    """``succ`` with the extra successors of the batch appended; each of their ``waits`` drops
    by one per edge from the batch (cells repeat)."""
    lo_, hi_ = succ_ptr[batch], succ_ptr[batch + 1]
    k = hi_ - lo_
    if k.any():
        idx = np.repeat(lo_ - np.cumsum(k) + k, k) + np.arange(int(k.sum()))
        more = succ_list[idx]
        cells_hit, times = np.unique(more, return_counts=True)
        waits[cells_hit] -= times
        succ = np.concatenate((succ, more))
    return succ


def _break_cycle(
    blocked_seen: list[NDArray[np.intp]],
    drawn: NDArray[np.bool_],
    clear: NDArray[np.bool_],
    neighbors: NDArray[np.int32],
    near: NDArray[np.float32],
    waits: NDArray[np.int64],
    pred_ptr: NDArray[np.intp] | None,
    pred_list: NDArray[np.int64] | None,
) -> tuple[int, list[NDArray[np.intp]]]:
    """The cell to draw next when no cell is ready, i.e. every undrawn cell waits.

    Every undrawn cell then has an undrawn cell behind it, so walking from cell to cell
    behind must come back to a cell already visited: that closes a cycle. The cell drawn
    is one on that cycle (not one merely waiting for it), the one with the fewest undrawn
    cells behind it, then the farthest, then the lowest id. The walk starts from the
    blocked cells reached so far (the rim of the drawn region), else from the first
    undrawn cell (a component with no source at all). It is a Python loop, but cycles
    are rare and short, and each step is one array lookup.
    """
    cand = np.unique(np.concatenate(blocked_seen)) if blocked_seen else np.empty(0, dtype=np.intp)
    cand = cand[~drawn[cand]]

    def best(cells: NDArray[np.intp]) -> int:
        waiting_on = 4 - np.count_nonzero(clear[cells], axis=1) + waits[cells]
        return int(cells[np.lexsort((cells, near[cells], waiting_on))[0]])

    def behind(cell: int) -> int:
        """An undrawn cell that ``cell`` waits on: across a face, else by an extra edge."""
        if not clear[cell].all():
            return int(neighbors[cell, np.argmin(clear[cell])])
        assert pred_ptr is not None and pred_list is not None  # waits[cell] > 0
        preds = pred_list[pred_ptr[cell]:pred_ptr[cell + 1]]
        return int(preds[np.argmax(~drawn[preds])])

    cur = best(cand) if cand.size else int(np.argmax(~drawn))
    seen: dict[int, int] = {}
    path: list[int] = []
    while cur not in seen:
        seen[cur] = len(path)
        path.append(cur)
        cur = behind(cur)
    cycle = np.array(path[seen[cur]:], dtype=np.intp)
    return best(cycle), [cand]


def mpvo_order(mesh: TetMesh, camera: Camera) -> tuple[NDArray[np.uint32], SortStats]:
    """Williams' MPVO: cell ids back to front, exact for a convex mesh, and the sort's stats.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
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
    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.cube(3)
    >>> ids, stats = mpvonc_order(mesh, Camera.fit(mesh))
    >>> ids.shape, stats.n_cycle_breaks
    ((162,), 0)
    """
    return _graph_order(mesh, camera, "mpvonc", _window(mesh, depth_window))


def xmpvo_order(
    mesh: TetMesh, camera: Camera, *, grid: int | None = None, depth_window: float | None = None
) -> tuple[NDArray[np.uint32], SortStats]:
    """MPVONC with edges between cells that share no face, from rays through the boundary.

    The XMPVO idea (Silva, Mitchell & Williams 1998): where a ray leaves the mesh through
    one cell and enters it again through another, the second is behind the first. With
    those edges the order is right between separate or interlocking parts and across
    cavities, wherever the ``grid x grid`` rays see the overlap (by default 64 to 256 per
    side, growing with the boundary; see :mod:`tetvr.order.boundary`); elsewhere it is MPVONC's.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.interlocking_rings(12, 1)
    >>> ids, stats = xmpvo_order(mesh, Camera.fit(mesh, direction=(-0.5, -1.0, -0.6), view_up=(0, 0, 1)))
    >>> stats.n_boundary_constraints > 0
    True
    """
    return _graph_order(mesh, camera, "xmpvo", _window(mesh, depth_window),
                        boundary_constraints(mesh, camera, grid=grid))


def _window(mesh: TetMesh, depth_window: float | None) -> float:
    """The depth window of a step: ``depth_window``, or twice the median longest edge."""
    if depth_window is None:
        return 2.0 * face_adjacency(mesh).cell_size
    window = float(depth_window)
    if not window >= 0:
        raise ValueError(f"depth_window must be >= 0, got {depth_window!r}")
    return window


def _input_order(mesh: TetMesh, camera: Camera) -> NDArray[np.uint32]:
    return np.arange(mesh.n_tets, dtype=np.uint32)


#: Below this many cells ``"auto"`` uses a graph sort: there its per-view cost (~0.3 us
#: per cell on 2 CPU cores, plus ~10 ms of boundary rays for ``xmpvo``) is small next to
#: drawing, and it is exact where centroid order fails; above, centroid order (~30 ns per
#: cell) keeps view changes fast.
AUTO_MPVONC_MAX_CELLS = 100_000


def auto_method(mesh: TetMesh) -> str:
    """The sort ``"auto"`` picks for a mesh.

    Up to :data:`AUTO_MPVONC_MAX_CELLS` cells: ``"mpvonc"`` for a convex mesh (its face
    graph alone gives the exact order) and ``"xmpvo"`` otherwise (gaps, cavities and
    separate parts need the boundary rays). Beyond: ``"centroid"``.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> auto_method(synthetic.cube(3)), auto_method(synthetic.interlocking_rings(8))
    ('mpvonc', 'xmpvo')
    """
    if mesh.n_tets > AUTO_MPVONC_MAX_CELLS:
        return "centroid"
    return "mpvonc" if face_adjacency(mesh).convex else "xmpvo"


SORTERS: dict[str, Callable[[TetMesh, Camera], NDArray[np.uint32]]] = {
    "auto": lambda mesh, camera: SORTERS[auto_method(mesh)](mesh, camera),
    "centroid": centroid_order,
    "mpvo": lambda mesh, camera: mpvo_order(mesh, camera)[0],
    "mpvonc": lambda mesh, camera: mpvonc_order(mesh, camera)[0],
    "xmpvo": lambda mesh, camera: xmpvo_order(mesh, camera)[0],
    "none": _input_order,
}

#: Sorters that also report :class:`SortStats` (the others report one step, no graph).
_SORTERS_WITH_STATS: dict[str, Callable[[TetMesh, Camera], tuple[NDArray[np.uint32], SortStats]]] = {
    "mpvo": mpvo_order,
    "mpvonc": mpvonc_order,
    "xmpvo": xmpvo_order,
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
    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.cube(2)
    >>> ids, stats = sort_with_stats(mesh, Camera.fit(mesh), "mpvonc")
    >>> stats.method, stats.n_cycle_breaks
    ('mpvonc', 0)
    """
    if method == "auto":
        method = auto_method(mesh)
    if method in _SORTERS_WITH_STATS:
        return _SORTERS_WITH_STATS[method](mesh, camera)
    ids = visibility_order(mesh, camera, method)
    return ids, SortStats(method=method, n_cells=mesh.n_tets)

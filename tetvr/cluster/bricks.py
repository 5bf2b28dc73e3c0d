"""Sort-last bricks: a mesh split by a k-d tree of axis-aligned planes, composited "over".

About this technique
--------------------
Sort-last parallel rendering (Molnar et al. 1994, "A sorting classification of parallel
rendering"): each process renders a part of the data to a full-size image, and the images
are composited in visibility order. Here the parts are the leaves of a k-d tree of
axis-aligned planes (:func:`kd_bricks`), so the order is exact: two bricks on either side
of a plane are crossed in the same order by every ray -- the side of the plane the eye is
on first (in parallel projection: the side the view direction comes from) -- for any
camera, inside the mesh included, as long as no cell reaches across a plane
(:func:`visibility_order`, :func:`composite_over`). This is IceT's k-d ordering
(Moreland et al. 2011) and what ParaView does after ``vtkRedistributeDataSet``.

A cell that crosses a plane is cut there into tets on either side (the field is linear on
a tet, so the pieces carry it exactly), so every brick is a box of the mesh. Where a plane
runs along cell faces (a grid's faces, block boundaries), nothing is cut and the bricks
hold the mesh's own cells.

Every brick renders with what it shares with the whole (:class:`Whole`): the float32
origin its coordinates are taken relative to (:meth:`TetMesh.with_float32_origin`), the
scalar range, longest edge and segment sample that set the pre-integration table. A brick
made by :func:`part_mesh` holds only its own points.

Solver pieces (a ``.pvtu``) are not convex and cannot be ordered as wholes; they are
redistributed into k-d bricks (:func:`plan_bricks` on a sample of their cells, then
:func:`select_cells` per piece and :func:`clip_to_box` per brick), which
:mod:`tetvr.cluster.distributed` runs on a Dask cluster.

This module is numpy only; it imports no OpenGL and no Dask.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any, Callable, NamedTuple, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.camera import Camera
from tetvr.mesh.cells import split_cells
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["Brick", "BrickTree", "Split", "Whole", "kd_bricks", "visibility_order", "composite_over", "part_mesh",
           "Part", "plan_bricks", "select_cells", "clip_to_box", "merge_parts", "leaf_boxes", "leaves"]

#: A split plane whose straddle-free position is this far (as a fraction of the node's cells)
#: from the balanced rank is not taken; the centroid median is, with its cells cut.
SEPARABLE_IMBALANCE = 0.25
# A cutting plane goes in the widest gap between vertex coordinates within this fraction of
# their extent from the median centroid.
_GAP_REACH = 0.05


# ---- what every brick shares with the whole ----

@dataclasses.dataclass(frozen=True, eq=False)
class Whole:
    """What the bricks of one mesh share so that each renders as a part of the whole.

    Attributes
    ----------
    bounds : (2, 3) the whole mesh's bounding box.
    float32_origin : (3,) the point GPU coordinates are relative to (the box's centre).
    scalar_range : the whole field's range (the table's scalar axis).
    max_edge : the whole mesh's longest edge (the table's thickness axis).
    segment_sample : the :class:`tetvr.optics.tablesize.SegmentSample` that sizes an "auto" table.
    n_tets : cells in the whole mesh (before any cut).
    """

    bounds: NDArray[np.float64]
    float32_origin: NDArray[np.float64]
    scalar_range: tuple[float, float]
    max_edge: float
    segment_sample: Any
    n_tets: int

    @classmethod
    def of(cls, mesh: TetMesh) -> "Whole":
        """The whole's values of ``mesh``.

        Examples
        --------
        >>> from tetvr.mesh import synthetic
        >>> Whole.of(synthetic.cube(2)).float32_origin.tolist()
        [0.0, 0.0, 0.0]
        """
        from tetvr.optics.tablesize import segment_sample

        return cls(np.asarray(mesh.bounds), np.asarray(mesh.float32_origin), mesh.scalar_range, mesh.max_edge,
                   segment_sample(mesh), mesh.n_tets)


def part_mesh(points: ArrayLike, tets: ArrayLike, scalars: ArrayLike, whole: Whole, *,
              scalar_name: str = "scalars", cell_scalars: ArrayLike | None = None) -> TetMesh:
    """The cells ``tets`` of ``points`` as a mesh of their own points that renders as a part
    of ``whole``: its float32 origin, scalar range, longest edge and segment sample are the
    whole's (so the GPU builds the whole's table and rounds coordinates as the whole does).

    Cells flat to rounding (slivers of a cut) are dropped. ``cell_scalars`` (one per row
    of ``tets``) make it cell data, as the whole is.
    """
    from tetvr.optics.tablesize import SegmentSample

    pts = np.asarray(points, dtype=np.float64)
    t = np.asarray(tets, dtype=np.int64).reshape(-1, 4)
    if t.shape[0] == 0:
        raise ValueError("a brick with no cells")
    used, local = np.unique(t, return_inverse=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # slivers of a cut below the flatness bound: dropped
        sub = TetMesh.from_arrays(pts[used], local.reshape(-1, 4), np.asarray(scalars, dtype=np.float64)[used],
                                  scalar_name=scalar_name, cell_scalars=cell_scalars)
    sub = sub.with_float32_origin(whole.float32_origin)
    # Cached properties seeded with the whole's values (a frozen dataclass: in the instance).
    sub.__dict__["max_edge"] = float(whole.max_edge)
    sub.__dict__["scalar_range"] = (float(whole.scalar_range[0]), float(whole.scalar_range[1]))
    if isinstance(whole.segment_sample, SegmentSample):
        sub.__dict__["_segment_sample"] = whole.segment_sample
    return sub


# ---- the k-d tree ----

@dataclasses.dataclass(frozen=True, eq=False)
class Brick:
    """A leaf of the k-d tree: its tets, as ids of the tree's points (empty in a plan), and
    for cell data their values (a cut cell's pieces carry its value)."""

    index: int
    tets: NDArray[np.int64]
    cells: NDArray[np.float64] | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Split:
    """A node: what lies below ``plane`` on ``axis`` goes to ``low``, the rest to ``high``.
    ``n_cut``: cells cut in two at the plane; ``separable``: no cell reaches across the
    plane (true when every straddling cell was cut), so the two sides composite exactly in
    plane order."""

    axis: int
    plane: float
    low: "Brick | Split"
    high: "Brick | Split"
    n_cut: int
    separable: bool

    def bricks(self) -> list[Brick]:
        return [b for side in (self.low, self.high) for b in (side.bricks() if isinstance(side, Split) else [side])]


@dataclasses.dataclass(frozen=True, eq=False)
class BrickTree:
    """A mesh split into bricks (:func:`kd_bricks`): the tree, and the points and scalars
    its bricks index (the mesh's own, then the points made where planes cut cells)."""

    root: "Split | Brick"
    points: NDArray[np.float64]
    scalars: NDArray[np.float64]
    mesh: TetMesh

    def bricks(self) -> list[Brick]:
        return leaves(self.root)

    @property
    def separable(self) -> bool:
        return _all_separable(self.root)

    @property
    def n_cut(self) -> int:
        return _count_cut(self.root)

    @property
    def whole(self) -> Whole:
        w = self.__dict__.get("_whole")
        if w is None:
            w = Whole.of(self.mesh)
            self.__dict__["_whole"] = w
        return w

    def brick_mesh(self, brick: Brick) -> TetMesh:
        """One brick as a mesh of its own points that renders as a part of the whole
        (:func:`part_mesh`)."""
        return part_mesh(self.points, brick.tets, self.scalars, self.whole, scalar_name=self.mesh.scalar_name,
                         cell_scalars=brick.cells)

    def visibility_order(self, camera: Camera) -> list[int]:
        return visibility_order(self.root, camera)


def leaves(tree: "Split | Brick") -> list[Brick]:
    """The bricks of a tree, low side first."""
    return tree.bricks() if isinstance(tree, Split) else [tree]


def kd_bricks(mesh: TetMesh, n_bricks: int, *, cut: bool = True) -> BrickTree:
    """Split ``mesh`` into ``n_bricks`` bricks by a k-d tree of axis-aligned planes.

    Each plane balances the bricks' cell counts. It moves to the nearest plane no cell
    straddles when one lies within :data:`SEPARABLE_IMBALANCE` of the node's cells (on the
    longest axis of the node's centroids, else another): a grid's face, a block boundary.
    Where there is none it crosses the longest axis at the median centroid (nudged off
    the vertices) and, with ``cut``, the cells it crosses are cut there into tets on
    either side (the field is linear on a tet, so the pieces carry it exactly; the pieces
    conform, :func:`tetvr.mesh.cells.split_cells`), so every brick is a box of the mesh. Without
    ``cut`` they are assigned by centroid and the split is not separable.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> tree = kd_bricks(synthetic.cube(4, rotate=False), 4)
    >>> [len(b.tets) for b in tree.bricks()], tree.separable, tree.n_cut
    ([96, 96, 96, 96], True, 0)
    """
    _check_n_bricks(n_bricks, mesh.n_tets)
    state = {"points": mesh.points, "scalars": mesh.scalars}
    counter = iter(range(n_bricks))
    cell_data = mesh.cell_scalars is not None

    def build(tets: NDArray[np.int64], n: int, vals: NDArray[np.float64]) -> "Split | Brick":
        if n == 1:
            return Brick(next(counter), tets, vals if cell_data else None)
        pts = state["points"]
        corners = pts[tets]
        lo, hi, c = corners.min(axis=1), corners.max(axis=1), corners.mean(axis=1)
        n_low = n // 2
        want = len(tets) * n_low // n  # cells below the plane for balanced bricks
        for axis in np.argsort(-(c.max(axis=0) - c.min(axis=0)), kind="stable").tolist():
            plane, low = _separating_plane(lo[:, axis], hi[:, axis], want)
            if plane is not None:
                return Split(axis, plane, build(tets[low], n_low, vals[low]),
                             build(tets[~low], n - n_low, vals[~low]), 0, True)
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = np.argsort(c[:, axis], kind="stable")
        plane = 0.5 * (c[order[want - 1], axis] + c[order[want], axis])
        if not cut:
            low = np.zeros(len(tets), dtype=bool)
            low[order[:want]] = True
            separable = not np.any((lo[:, axis] < plane) & (hi[:, axis] > plane))
            return Split(axis, float(plane), build(tets[low], n_low, vals[low]),
                         build(tets[~low], n - n_low, vals[~low]), 0, separable)
        plane = _plane_off_vertices(pts[np.unique(tets), axis], plane)
        state["points"], state["scalars"], below, above, v_below, v_above, n_cut = cut_at_plane(
            state["points"], state["scalars"], tets, axis, float(plane), vals)
        if len(below) == 0 or len(above) == 0:
            raise ValueError(f"cannot split {len(tets)} cells into {n} bricks: a plane leaves one side empty")
        return Split(axis, float(plane), build(below, n_low, v_below), build(above, n - n_low, v_above), n_cut, True)

    cells = mesh.cell_scalars if cell_data else np.zeros(mesh.n_tets)
    root = build(mesh.tets.astype(np.int64), int(n_bricks), np.asarray(cells, dtype=np.float64))
    return BrickTree(root, state["points"], state["scalars"], mesh)


def _check_n_bricks(n_bricks: Any, n_tets: int) -> None:
    if isinstance(n_bricks, bool) or not isinstance(n_bricks, (int, np.integer)) or n_bricks < 1:
        raise ValueError(f"n_bricks must be a positive integer, got {n_bricks!r}")
    if n_bricks > n_tets:
        raise ValueError(f"n_bricks ({n_bricks}) is more than the mesh's {n_tets} cells")


def _plane_off_vertices(coords: NDArray[np.float64], plane: float, reach: float = _GAP_REACH) -> float:
    """The middle of the widest gap between vertex coordinates within ``reach`` (a fraction
    of their extent) of ``plane``: every cut is then a clean 1|3 or 2|2 one, far (for this
    mesh) from its vertices, so no piece is a sliver flat to rounding, and the balance the
    plane was chosen for is kept. In a gap wider than that, the plane stays, a quarter of
    the gap away from its ends at least."""
    c = np.unique(coords)
    if len(c) < 2:
        return plane
    r = reach * float(c[-1] - c[0])
    mid, width = 0.5 * (c[1:] + c[:-1]), c[1:] - c[:-1]
    near = (c[:-1] >= plane - r) & (c[1:] <= plane + r)
    if near.any():
        k = int(np.flatnonzero(near)[np.argmax(width[near])])
        return float(mid[k])
    k = int(np.clip(np.searchsorted(c, plane) - 1, 0, len(width) - 1))  # the gap that holds the plane
    return float(np.clip(plane, c[k] + 0.25 * width[k], c[k + 1] - 0.25 * width[k]))


def _separating_plane(lo: NDArray[np.float64], hi: NDArray[np.float64], want: int
                      ) -> tuple[float | None, NDArray[np.bool_]]:
    """The plane no cell straddles (``lo < plane < hi``) whose count of cells below is
    nearest ``want``, if within the imbalance allowed; else ``(None, ...)``."""
    n = len(lo)
    cand = np.unique(hi)
    below = np.searchsorted(np.sort(hi), cand, side="right")  # cells wholly at or below the plane
    started = np.searchsorted(np.sort(lo), cand, side="left")  # cells starting below it
    ok = (started == below) & (below > 0) & (below < n)
    if not ok.any():
        return None, np.zeros(n, dtype=bool)
    k = np.flatnonzero(ok)[np.argmin(np.abs(below[ok] - want))]
    if abs(int(below[k]) - want) > SEPARABLE_IMBALANCE * n:
        return None, np.zeros(n, dtype=bool)
    plane = float(cand[k])
    return plane, hi <= plane


def cut_at_plane(points: NDArray[np.float64], scalars: NDArray[np.float64], tets: NDArray[np.int64], axis: int,
                 plane: float, cells: NDArray[np.float64] | None = None
                 ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.int64],
                            NDArray[np.float64], NDArray[np.float64], int]:
    """Cut ``tets`` at the plane ``x[axis] = plane``. Returns the points and scalars with
    the edge crossings appended, the tets below and above, the cell values of those (each
    piece the value of the cell it was cut from; ``cells`` gives one per row of ``tets``
    for cell data, zeros without), and how many cells were cut.

    A cell with no vertex above the plane is below (one touching it from below included),
    and the reverse. A cut tet with one vertex on one side leaves a tet there and a wedge
    on the other; one with two on each side, two wedges. Each crossing point is made once
    per edge, so the pieces of neighbouring cells share it, and wedges are split into tets
    by the smallest global id on each quad (:func:`tetvr.mesh.cells.split_cells`), so the pieces
    conform. A vertex that lies on the plane (a plane chosen on a sample of the cells) is
    its own crossing; the flat pieces that leaves are dropped.
    """
    vals = np.zeros(len(tets)) if cells is None else np.asarray(cells, dtype=np.float64)
    d = points[tets, axis] - plane
    n_below = (d < 0).sum(axis=1)
    n_above = (d > 0).sum(axis=1)
    low_rows, high_rows = n_above == 0, (n_below == 0) & (n_above > 0)
    keep_low, keep_high = tets[low_rows], tets[high_rows]
    keep_low_v, keep_high_v = vals[low_rows], vals[high_rows]
    straddle = (n_below > 0) & (n_above > 0)
    if not straddle.any():
        return points, scalars, keep_low, keep_high, keep_low_v, keep_high_v, 0
    below = d < 0  # a vertex on the plane goes with those above
    # Each cut tet's vertices, those below first.
    order = np.argsort(~below[straddle], axis=1, kind="stable")
    t = np.take_along_axis(tets[straddle], order, axis=1)
    new_pts, new_s, x = _edge_crossings(points, scalars, t, axis, plane)
    tet_in, wedge_in, side, piece_v = _cut_pieces(t, n_below[straddle], vals[straddle], x)
    all_pts = np.concatenate([points, new_pts])
    all_s = np.concatenate([scalars, new_s])
    split = split_cells(all_pts, [("tetra", tet_in), ("wedge", wedge_in)])
    is_low = side[split.parent]
    cut_v = piece_v[split.parent]
    all_pts = split.points
    all_s = split.extend(all_s)
    cut_tets = split.tets.astype(np.int64)
    s = np.sort(cut_tets, axis=1)
    ok = np.all(s[:, 1:] != s[:, :-1], axis=1)  # pieces of a vertex on the plane repeat it: flat
    cut_tets, is_low, cut_v = cut_tets[ok], is_low[ok], cut_v[ok]
    low = np.concatenate([keep_low, cut_tets[is_low]])
    high = np.concatenate([keep_high, cut_tets[~is_low]])
    low_v = np.concatenate([keep_low_v, cut_v[is_low]])
    high_v = np.concatenate([keep_high_v, cut_v[~is_low]])
    return all_pts, all_s, low, high, low_v, high_v, int(straddle.sum())


def _edge_crossings(points: NDArray[np.float64], scalars: NDArray[np.float64], t: NDArray[np.int64], axis: int,
                    plane: float) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                           Callable[[NDArray[np.int64], NDArray[np.int64]], NDArray[np.int64]]]:
    """Where the edges of the cut tets ``t`` cross the plane: the new points and their
    scalars (to be appended after ``points``), and ``x(a, b)``, the id of the point where
    edge (a, b) crosses, made once per edge so that neighbouring cells share it."""
    # One new point per crossed edge.
    pairs = np.concatenate([t[:, [i, j]] for i in range(4) for j in range(i + 1, 4)])
    pairs = pairs[(points[pairs[:, 0], axis] < plane) != (points[pairs[:, 1], axis] < plane)]
    n_pts = points.shape[0]
    keys = np.unique(np.minimum(pairs[:, 0], pairs[:, 1]) * n_pts + np.maximum(pairs[:, 0], pairs[:, 1]))
    u, v = keys // n_pts, keys % n_pts
    du, dv = points[u, axis] - plane, points[v, axis] - plane
    w = (du / (du - dv))[:, None]
    new_pts = points[u] + w * (points[v] - points[u])
    new_pts[:, axis] = plane
    new_s = scalars[u] + w[:, 0] * (scalars[v] - scalars[u])
    # An edge ending on the plane crosses it at that vertex: no new point.
    crossing = n_pts + np.arange(len(keys))
    crossing = np.where(du == 0, u, np.where(dv == 0, v, crossing))

    def x(a: NDArray[np.int64], b: NDArray[np.int64]) -> NDArray[np.int64]:
        k = np.minimum(a, b) * n_pts + np.maximum(a, b)
        return crossing[np.searchsorted(keys, k)]

    return new_pts, new_s, x


def _cut_pieces(t: NDArray[np.int64], nb: NDArray[np.int64], vs: NDArray[np.float64],
                x: Callable[[NDArray[np.int64], NDArray[np.int64]], NDArray[np.int64]]
                ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.bool_], NDArray[np.float64]]:
    """The pieces of the cut tets ``t`` (``nb[i]`` vertices below the plane, listed first;
    cell values ``vs``; crossings ``x``): their tets and wedges, then for each piece, tets
    first, whether it lies below and the value of the cell it is cut from."""
    pieces_tet: list[NDArray[np.int64]] = []
    pieces_wedge: list[NDArray[np.int64]] = []
    side_tet: list[NDArray[np.bool_]] = []
    side_wedge: list[NDArray[np.bool_]] = []
    val_tet: list[NDArray[np.float64]] = []  # the value of the cell each piece is cut from
    val_wedge: list[NDArray[np.float64]] = []
    # One vertex alone on its side (rows list the vertices below first): a tet on that side,
    # a wedge on the other. x() is symmetric, so both cases cut the same edges.
    for count, lone_below in ((1, True), (3, False)):
        sel = nb == count
        if not sel.any():
            continue
        rows = t[sel]
        lone, (a, b, c) = (rows[:, 0], rows[:, 1:].T) if lone_below else (rows[:, 3], rows[:, :3].T)
        xa, xb, xc = x(lone, a), x(lone, b), x(lone, c)
        pieces_tet.append(np.stack([lone, xa, xb, xc], 1))
        side_tet.append(np.full(len(rows), lone_below))
        pieces_wedge.append(np.stack([a, b, c, xa, xb, xc], 1))
        side_wedge.append(np.full(len(rows), not lone_below))
        val_tet.append(vs[sel])
        val_wedge.append(vs[sel])
    two = t[nb == 2]  # two on each side: a wedge each
    if len(two):
        a, b, c, dd = two.T
        xac, xad, xbc, xbd = x(a, c), x(a, dd), x(b, c), x(b, dd)
        pieces_wedge += [np.stack([a, xac, xad, b, xbc, xbd], 1), np.stack([c, xac, xbc, dd, xad, xbd], 1)]
        side_wedge += [np.ones(len(two), dtype=bool), np.zeros(len(two), dtype=bool)]
        val_wedge += [vs[nb == 2], vs[nb == 2]]
    tet_in = np.concatenate(pieces_tet) if pieces_tet else np.zeros((0, 4), dtype=np.int64)
    wedge_in = np.concatenate(pieces_wedge) if pieces_wedge else np.zeros((0, 6), dtype=np.int64)
    return tet_in, wedge_in, np.concatenate(side_tet + side_wedge), np.concatenate(val_tet + val_wedge)


def visibility_order(tree: "BrickTree | Split | Brick", camera: Camera) -> list[int]:
    """Brick indices front to back for ``camera``: at each split, the side the eye is on
    first (parallel projection: the side the view direction comes from)."""
    if isinstance(tree, BrickTree):
        tree = tree.root
    if isinstance(tree, Brick):
        return [tree.index]
    if camera.parallel_projection:
        d = np.asarray(camera.focal_point) - np.asarray(camera.position)
        low_first = d[tree.axis] >= 0  # looking towards +axis: the low side is nearer
    else:
        low_first = camera.position[tree.axis] <= tree.plane
    first, second = (tree.low, tree.high) if low_first else (tree.high, tree.low)
    return visibility_order(first, camera) + visibility_order(second, camera)


def composite_over(images_front_to_back: Sequence[NDArray[Any]]) -> NDArray[np.float32]:
    """Premultiplied RGBA images composited "over", the first in front (in float64).

    Examples
    --------
    >>> front = np.full((1, 1, 4), 0.5, dtype=np.float32)
    >>> composite_over([front, np.ones((1, 1, 4), dtype=np.float32)])[0, 0].tolist()
    [1.0, 1.0, 1.0, 1.0]
    """
    if not images_front_to_back:
        raise ValueError("nothing to composite")
    out = np.asarray(images_front_to_back[0], dtype=np.float64).copy()
    for img in images_front_to_back[1:]:
        out += (1.0 - out[..., 3:4]) * np.asarray(img, dtype=np.float64)
    return out.astype(np.float32)


def _all_separable(tree: "Split | Brick") -> bool:
    if isinstance(tree, Brick):
        return True
    return tree.separable and _all_separable(tree.low) and _all_separable(tree.high)


def _count_cut(tree: "Split | Brick") -> int:
    if isinstance(tree, Brick):
        return 0
    return tree.n_cut + _count_cut(tree.low) + _count_cut(tree.high)


# ---- solver pieces redistributed into bricks ----

def plan_bricks(corners: NDArray[np.float64], n_bricks: int) -> "Split | Brick":
    """The k-d planes for ``n_bricks`` bricks, chosen on a sample of the cells (``(k, 4,
    3)`` corner coordinates, drawn evenly from every piece), as :func:`kd_bricks` chooses
    them on all cells: a plane along cell faces where the sample has one near the balanced
    rank (nothing is cut where the sample's plane is the mesh's: grids, block boundaries),
    else the median centroid nudged into the widest gap between the sample's vertex
    coordinates. Cells the plane crosses go to both sides. The leaves hold no cells.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> m = synthetic.cube(4, rotate=False)
    >>> plan = plan_bricks(m.points[m.tets], 4)
    >>> len(leaves(plan)), leaf_boxes(plan, m.bounds)[0].tolist()
    (4, [[-0.5, -0.5, -0.5], [0.0, 0.0, 0.5]])
    """
    corners = np.asarray(corners, dtype=np.float64)
    _check_n_bricks(n_bricks, len(corners))
    counter = iter(range(n_bricks))
    empty = np.zeros((0, 4), dtype=np.int64)

    def build(ids: NDArray[np.int64], n: int) -> "Split | Brick":
        if n == 1:
            return Brick(next(counter), empty)
        cs = corners[ids]
        lo, hi, c = cs.min(axis=1), cs.max(axis=1), cs.mean(axis=1)
        n_low = n // 2
        want = max(1, len(ids) * n_low // n)
        for axis in np.argsort(-(c.max(axis=0) - c.min(axis=0)), kind="stable").tolist():
            plane, low = _separating_plane(lo[:, axis], hi[:, axis], want)
            if plane is not None:
                return Split(axis, plane, build(ids[low], n_low), build(ids[~low], n - n_low), 0, True)
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = np.argsort(c[:, axis], kind="stable")
        plane = 0.5 * (c[order[want - 1], axis] + c[order[min(want, len(ids) - 1)], axis])
        plane = _plane_off_vertices(cs[..., axis].reshape(-1), plane)
        low, high = lo[:, axis] < plane, hi[:, axis] > plane
        if not low.any() or not high.any():
            raise ValueError(f"cannot plan {n} bricks from a sample of {len(ids)} cells: a plane leaves one side empty")
        return Split(axis, float(plane), build(ids[low], n_low), build(ids[high], n - n_low), 0, True)

    return build(np.arange(len(corners)), int(n_bricks))


def leaf_boxes(tree: "Split | Brick", bounds: ArrayLike) -> dict[int, NDArray[np.float64]]:
    """Each brick's box, ``(2, 3)``, within ``bounds`` (the whole mesh's)."""
    out: dict[int, NDArray[np.float64]] = {}

    def walk(node: "Split | Brick", box: NDArray[np.float64]) -> None:
        if isinstance(node, Brick):
            out[node.index] = box
            return
        lo_box, hi_box = box.copy(), box.copy()
        lo_box[1, node.axis] = node.plane
        hi_box[0, node.axis] = node.plane
        walk(node.low, lo_box)
        walk(node.high, hi_box)

    walk(tree, np.array(bounds, dtype=np.float64).reshape(2, 3))
    return out


class Part(NamedTuple):
    """Cells with their own points: what a piece sends a brick, and what a brick joins.

    ``cells`` holds one value per row of ``tets`` for cell data, None for point data."""

    points: NDArray[np.float64]
    tets: NDArray[np.int64]
    scalars: NDArray[np.float64]
    cells: NDArray[np.float64] | None = None


def select_cells(mesh: TetMesh, box: ArrayLike) -> Part:
    """The cells of ``mesh`` whose bounding box overlaps the inside of ``box``, with their
    own points (and their values, for cell data): what a piece sends to one brick."""
    b = np.asarray(box, dtype=np.float64).reshape(2, 3)
    corners = mesh.points[mesh.tets]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    inside = np.all((lo < b[1]) & (hi > b[0]), axis=1)
    t = mesh.tets[inside].astype(np.int64)
    used, local = np.unique(t, return_inverse=True)
    cells = None if mesh.cell_scalars is None else np.asarray(mesh.cell_scalars, dtype=np.float64)[inside]
    return Part(mesh.points[used], local.reshape(-1, 4), mesh.scalars[used], cells)


def merge_parts(parts: Sequence[Part]) -> Part:
    """Parts from several pieces as one: points with equal coordinates joined (pieces
    repeat the points on the faces they share), so the cells conform across the pieces'
    seams as in one file. Cell values follow their cells; the parts are all point data or
    all cell data."""
    parts = [Part(*p) for p in parts if len(p[1])]
    if not parts:
        return Part(np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64), np.zeros(0))
    kinds = {p.cells is None for p in parts}
    if len(kinds) > 1:
        raise ValueError("parts mix point data and cell data")
    offsets = np.cumsum([0] + [len(p.points) for p in parts])
    pts = np.concatenate([p.points for p in parts])
    tets = np.concatenate([p.tets + off for p, off in zip(parts, offsets)])
    s = np.concatenate([p.scalars for p in parts])
    cells = None if parts[0].cells is None else np.concatenate([np.asarray(p.cells, dtype=np.float64) for p in parts])
    uniq, first, inverse = np.unique(pts, axis=0, return_index=True, return_inverse=True)
    return Part(uniq, inverse.reshape(-1)[tets], s[first], cells)


def clip_to_box(part: Part, path: Sequence[tuple[int, float, bool]]) -> tuple[Part, int]:
    """The part of the cells inside a brick's box: cut at each plane of the brick's path
    from the root (``(axis, plane, low side?)``) and the other side left; each piece of a
    cut cell keeps its cell's value. Returns the part and how many cells were cut."""
    points, tets, scalars, cells = part
    vals = np.zeros(len(tets)) if cells is None else np.asarray(cells, dtype=np.float64)
    n_cut = 0
    for axis, plane, low in path:
        points, scalars, below, above, v_below, v_above, k = cut_at_plane(points, scalars, tets, axis, plane, vals)
        tets, vals = (below, v_below) if low else (above, v_above)
        n_cut += k
    return Part(points, tets, scalars, None if cells is None else vals), n_cut


def leaf_paths(tree: "Split | Brick") -> dict[int, list[tuple[int, float, bool]]]:
    """Each brick's planes from the root: ``(axis, plane, on the low side)``."""
    out: dict[int, list[tuple[int, float, bool]]] = {}

    def walk(node: "Split | Brick", path: list[tuple[int, float, bool]]) -> None:
        if isinstance(node, Brick):
            out[node.index] = path
            return
        walk(node.low, path + [(node.axis, node.plane, True)])
        walk(node.high, path + [(node.axis, node.plane, False)])

    walk(tree, [])
    return out

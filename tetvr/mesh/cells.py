"""Mixed-cell meshes: hexahedra, wedges, pyramids and quadratic cells split into tetrahedra.

About this technique
--------------------
Dompierre, Labbé, Vallet & Camarero 1999, "How to subdivide pyramids, prisms and
hexahedra into tetrahedra" (8th International Meshing Roundtable). A cell with
quadrilateral faces splits into tetrahedra once each quad has a diagonal; two cells that
share a quad conform (no crack, every triangle shared by exactly two tets) only if they
pick the *same* diagonal. The rule that needs no communication between cells: **each quad
takes the diagonal through its smallest global vertex id**. Both sides see the same four
ids, so both choose alike.

Two refinements here:

* A quad that a neighbouring tetrahedron (or a wedge's or pyramid's triangular face)
  already covers with one of its halves takes that triangle's diagonal instead, so a hex
  sitting under a tet conforms to it too (``uGridEx.vtk`` has two). Where both halves are
  claimed with different diagonals the input itself does not conform; the min-id rule
  decides and :attr:`CellSplit.conflicts` counts it.
* With the diagonals fixed, a cell is split by a table built once, at first use, by
  exhaustive search: every set of corner tetrahedra that tiles the reference cell exactly
  (an exact cover of a cloud of generic sample points, with the volumes summing to the
  cell's) is a triangulation without new points — the cube has 74 — and each induces one
  diagonal per quad. Each configuration of diagonals takes its triangulation with the
  fewest tets (5 or 6 for a hex, 3 for a wedge, 2 for a pyramid). 18 of the 64 hex
  configurations and the two "twisted" wedges are induced by no triangulation. The min-id
  rule never produces them (the smallest corner's faces all take diagonals through it;
  the tests try all 8! orders of a hex's ids), but diagonals claimed by neighbouring
  triangles can. Such a cell gets a **Steiner point at its centroid**, joined to every
  boundary triangle: 12 tets for a hex, 8 for a wedge. Its scalar (and every point field)
  is the mean of the cell's corners — the value of trilinear interpolation at a hex's
  centre.

Quadratic and higher-order cells (``tetra10``, ``hexahedron20/27``, ``wedge15/18``,
``pyramid13/14``, VTK Lagrange cells) keep their corner nodes, which VTK, Gmsh and meshio
all list first; the mid-side nodes stay in the point list unused. Surface, line and
vertex cells, polyhedra and n-gonal prisms are not volume cells that this module splits:
they are counted and left out.

Split cells with repeated nodes (a hex collapsed into a wedge by repeating a node) give
some tets with a repeated vertex; those have no volume and are dropped, with a count.

Reading: :func:`read_cells` reads with meshio and falls back to a reader of legacy VTK
unstructured grids here (ASCII or binary), for the files meshio refuses (meshio 5.3 has no
triangle strips, VTK type 6, and raises ``KeyError: 6``).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "VOLUME_CELLS",
    "CellSplit",
    "cell_triangulation",
    "split_cells",
]

Int = NDArray[np.int64]

# ---------------------------------------------------------------------------------
# Reference cells (VTK node order). Quads are listed cyclically; the diagonal bit of a
# quad (a, b, c, d) is 0 for a-c and 1 for b-d.
# ---------------------------------------------------------------------------------

_REFERENCE: dict[str, tuple[NDArray[np.float64], tuple[tuple[int, ...], ...], tuple[tuple[int, ...], ...]]] = {
    "tetra": (
        np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float),
        (),
        ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)),
    ),
    "pyramid": (
        np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]], float),
        ((0, 1, 2, 3),),
        ((0, 1, 4), (1, 2, 4), (2, 3, 4), (3, 0, 4)),
    ),
    "wedge": (
        np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [0, 1, 1]], float),
        ((0, 1, 4, 3), (1, 2, 5, 4), (2, 0, 3, 5)),
        ((0, 1, 2), (3, 4, 5)),
    ),
    "hexahedron": (
        np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float),
        ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)),
        (),
    ),
}

#: Cell types split into tets: meshio name -> (linear shape, corner-node selection).
VOLUME_CELLS: dict[str, tuple[str, tuple[int, ...]]] = {
    **{name: ("tetra", (0, 1, 2, 3)) for name in ("tetra", "tetra10", "tetra14", "VTK_LAGRANGE_TETRAHEDRON")},
    **{name: ("pyramid", (0, 1, 2, 3, 4)) for name in ("pyramid", "pyramid13", "pyramid14",
                                                         "VTK_LAGRANGE_PYRAMID")},
    **{name: ("wedge", (0, 1, 2, 3, 4, 5)) for name in ("wedge", "wedge12", "wedge15", "wedge18",
                                                          "VTK_LAGRANGE_WEDGE")},
    **{name: ("hexahedron", tuple(range(8))) for name in ("hexahedron", "hexahedron20", "hexahedron24",
                                                          "hexahedron27", "VTK_LAGRANGE_HEXAHEDRON")},
    # VTK's voxel numbers its corners by bits (x, y, z); reorder to the hexahedron's cycle.
    "voxel": ("hexahedron", (0, 1, 3, 2, 4, 5, 7, 6)),
}

# Sample points for the triangulation search; fixed seed, so the tables never change.
_SEARCH_SEED = 19990901
_SEARCH_SAMPLES = 4000


@functools.cache
def cell_triangulation(shape: str) -> tuple[tuple[NDArray[np.int64], ...], NDArray[np.bool_]]:
    """The split of a reference cell for every configuration of its quad diagonals.

    Returns ``(tables, centroid)``: ``tables[config]`` is a ``(k, 4)`` array of local
    corner indices, where index ``n_corners`` stands for the cell's centroid, and
    ``centroid[config]`` tells whether that configuration needed it. ``config`` has bit
    ``f`` set when quad ``f`` takes its b-d diagonal.

    Examples
    --------
    >>> tables, centroid = cell_triangulation("hexahedron")
    >>> len(tables), int(centroid.sum()), sorted({len(t) for t in tables})
    (64, 18, [5, 6, 12])
    """
    if shape not in _REFERENCE:
        raise ValueError(f"shape must be one of {sorted(_REFERENCE)}, got {shape!r}")
    corners, quads, tris = _REFERENCE[shape]
    n = corners.shape[0]
    found = [sol for sol in _search_triangulations(corners, _volume6(corners, quads, tris))
             if _face_to_face(sol, quads, tris)]
    best: dict[int, tuple[tuple[int, ...], ...]] = {}
    for sol in found:
        edges = {frozenset(e) for tet in sol for e in itertools.combinations(tet, 2)}
        config = 0
        for f, (a, b, c, d) in enumerate(quads):
            ac, bd = frozenset((a, c)) in edges, frozenset((b, d)) in edges
            if ac == bd:  # pragma: no cover - a triangulation cuts each quad exactly once
                raise AssertionError(f"{shape}: triangulation {sol} cuts quad {quads[f]} ambiguously")
            config |= int(bd) << f
        key = (len(sol), sorted(sol))
        if config not in best or key < (len(best[config]), sorted(best[config])):
            best[config] = sol
    tables: list[NDArray[np.int64]] = []
    centroid = np.zeros(1 << len(quads), dtype=bool)
    for config in range(1 << len(quads)):
        if config in best:
            tables.append(np.array(sorted(best[config]), dtype=np.int64).reshape(-1, 4))
            continue
        # No triangulation induces these diagonals: join the centroid to every boundary triangle.
        centroid[config] = True
        faces = [tuple(t) for t in tris]
        for f, (a, b, c, d) in enumerate(quads):
            faces += [(a, b, d), (b, c, d)] if config >> f & 1 else [(a, b, c), (a, c, d)]
        tables.append(np.array([(*t, n) for t in faces], dtype=np.int64))
    for t in tables:
        t.setflags(write=False)
    centroid.setflags(write=False)
    return tuple(tables), centroid


def _search_triangulations(corners: NDArray[np.float64], cell_volume6: float) -> list[tuple[tuple[int, ...], ...]]:
    """Every set of corner tets that tiles the (convex) reference cell: exact covers of a
    cloud of generic interior points whose volumes add up to the cell's."""
    n = corners.shape[0]
    cand = [c for c in itertools.combinations(range(n), 4)
            if abs(np.linalg.det(corners[list(c[1:])] - corners[c[0]])) > 1e-9]
    rng = np.random.default_rng(_SEARCH_SEED)
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    q = lo + rng.random((_SEARCH_SAMPLES, 3)) * (hi - lo)
    bary = []
    for c in cand:
        p = corners[list(c)]
        m = np.linalg.inv(np.vstack([p.T, np.ones(4)]))
        bary.append(np.c_[q, np.ones(len(q))] @ m.T)
    b = np.stack(bary)  # (n_cand, n_q, 4)
    # Keep points well inside the cell and off every candidate's face planes: then each
    # lies strictly inside or strictly outside every tet, and a tiling covers it once.
    generic = np.all(np.abs(b) > 1e-6, axis=(0, 2)) & np.any(np.all(b > 0, axis=2), axis=0)
    inside = np.all(b[:, generic] > 0, axis=2)  # (n_cand, n_q')
    n_q = int(inside.shape[1])
    masks = [int.from_bytes(np.packbits(row, bitorder="little").tobytes(), "little") for row in inside]
    volume = [abs(np.linalg.det(corners[list(c[1:])] - corners[c[0]])) for c in cand]
    by_point = [[i for i in range(len(cand)) if inside[i, j]] for j in range(n_q)]
    full = (1 << n_q) - 1
    out: list[tuple[tuple[int, ...], ...]] = []

    def extend(covered: int, chosen: list[int]) -> None:
        if covered == full:
            if abs(sum(volume[i] for i in chosen) - cell_volume6) < 1e-9:
                out.append(tuple(cand[i] for i in chosen))
            return
        free = ~covered & full
        j = (free & -free).bit_length() - 1  # the first point not yet covered
        for i in by_point[j]:
            if masks[i] & covered == 0:
                extend(covered | masks[i], chosen + [i])

    extend(0, [])
    return out


def _face_to_face(sol: tuple[tuple[int, ...], ...], quads: tuple[tuple[int, ...], ...],
                  tris: tuple[tuple[int, ...], ...]) -> bool:
    """Whether a dissection is a triangulation: each tet face is either on the cell's
    boundary or shared whole by exactly one other tet (so no face is cut by another's edge)."""
    boundary = [set(f) for f in quads] + [set(f) for f in tris]
    count: dict[tuple[int, ...], int] = {}
    for tet in sol:
        for face in itertools.combinations(sorted(tet), 3):
            count[face] = count.get(face, 0) + 1
    return all(n == 2 or (n == 1 and any(set(f) <= b for b in boundary)) for f, n in count.items())


def _volume6(corners: NDArray[np.float64], quads: tuple[tuple[int, ...], ...],
             tris: tuple[tuple[int, ...], ...]) -> float:
    """Six times the volume of a convex reference cell, by cones from its centroid."""
    c = corners.mean(axis=0)
    faces = [list(t) for t in tris] + [t for a, b, cc, d in quads for t in ([a, b, cc], [a, cc, d])]
    return float(sum(abs(np.linalg.det(corners[f] - c)) for f in faces))


# ---------------------------------------------------------------------------------
# Splitting
# ---------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class CellSplit:
    """The volume cells of a mesh as tetrahedra.

    Attributes
    ----------
    points : (n + k, 3) the input points, then ``k`` added cell centroids.
    tets : (m, 4) int64 vertex ids (orientation not fixed; :class:`~tetvr.mesh.tetmesh.TetMesh` does that).
    parent : (m,) int64 index of the input cell each tet comes from, counting every input
        cell (of any type) in block order.
    centroid_corners : (k, 8) int64 corner ids of the cell of each added point, ``-1`` padded.
    split : ``(cell type, count)`` of the input cells that were not linear tets.
    ignored : ``(cell type, count)`` of the cells left out (not volume cells).
    dropped_repeated : tets dropped because a collapsed cell repeats a node in them.
    conflicts : quads whose two halves neighbouring triangles claim with different diagonals.
    """

    points: NDArray[np.float64]
    tets: Int
    parent: Int
    centroid_corners: Int
    split: tuple[tuple[str, int], ...] = ()
    ignored: tuple[tuple[str, int], ...] = ()
    dropped_repeated: int = 0
    conflicts: int = 0

    @property
    def n_input_points(self) -> int:
        return int(self.points.shape[0] - self.centroid_corners.shape[0])

    @property
    def steiner_points(self) -> int:
        """Centroids added to cells that cannot be split otherwise."""
        return int(self.centroid_corners.shape[0])

    def extend(self, point_values: ArrayLike) -> NDArray[Any]:
        """A point field of the input points, with the added centroids appended (mean of
        the cell's corners, per component).

        Examples
        --------
        >>> s = split_cells(np.eye(4, 3), [("tetra", [[0, 1, 2, 3]])])
        >>> s.extend([1.0, 2.0, 3.0, 4.0]).tolist()
        [1.0, 2.0, 3.0, 4.0]
        """
        v = np.asarray(point_values)
        if v.shape[:1] != (self.n_input_points,):
            raise ValueError(f"point_values must have one row per input point ({self.n_input_points}), "
                             f"got shape {v.shape}")
        if self.steiner_points == 0:
            return v.copy()
        cc = self.centroid_corners
        valid = cc >= 0
        rows = v[np.where(valid, cc, 0)].astype(np.float64)
        w = valid.reshape(valid.shape + (1,) * (v.ndim - 1))
        mean = (rows * w).sum(axis=1) / w.sum(axis=1)
        return np.concatenate([v.astype(np.result_type(v.dtype, np.float64)), mean])

    def compacted(self, keep: NDArray[np.bool_]) -> CellSplit:
        """The same split over the points where ``keep`` is true (every tet vertex must be
        kept); :meth:`extend` then expects values for the input points that are kept."""
        if not np.all(keep[self.tets]):
            raise ValueError("compacted() must keep every point a tet uses")
        new_id = np.cumsum(keep) - 1
        old = self.centroid_corners
        if np.any((old >= 0) & ~keep[np.maximum(old, 0)]):
            raise ValueError("compacted() must keep the corners of every cell given a centroid")
        cc = np.where(old >= 0, new_id[np.maximum(old, 0)], -1)
        return dataclasses.replace(self, points=self.points[keep], tets=new_id[self.tets], centroid_corners=cc)

    def summary(self) -> str:
        """One line for logs and warnings."""
        parts = []
        if self.split:
            parts.append("split into tetrahedra: " + ", ".join(f"{v} {k}" for k, v in self.split))
        if self.steiner_points:
            parts.append(f"{self.steiner_points} cell centroids added")
        if self.dropped_repeated:
            parts.append(f"{self.dropped_repeated} tets of collapsed cells dropped")
        if self.conflicts:
            parts.append(f"{self.conflicts} quad faces claimed by non-conforming neighbours")
        if self.ignored:
            parts.append("ignored non-volume cells: " + ", ".join(f"{v} {k}" for k, v in self.ignored))
        return "; ".join(parts)


def split_cells(points: ArrayLike, blocks: Sequence[tuple[str, Any]]) -> CellSplit:
    """Split every volume cell into tetrahedra that conform across shared faces.

    Parameters
    ----------
    points : (n, 3) point coordinates.
    blocks : ``(cell type, connectivity)`` pairs with meshio's type names (``"tetra"``,
        ``"hexahedron"``, ``"wedge"``, ``"pyramid"``, ``"hexahedron20"``, ...); the
        connectivity of a volume type is ``(k, nodes)`` in VTK node order. Other types
        (``"triangle"``, ``"polygon"``, ...) need only a ``len()`` and are counted as ignored.

    Returns
    -------
    CellSplit
        The tets, the points (with any added centroids) and what was done.

    Examples
    --------
    >>> cube = [[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    >>> s = split_cells(cube, [("hexahedron", [[0, 1, 3, 2, 4, 5, 7, 6]])])
    >>> s.tets.shape, s.split, s.steiner_points
    ((6, 4), (('hexahedron', 1),), 0)
    """
    pts = np.array(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
    n_pts = pts.shape[0]

    cells, split, ignored = _gather_cells(blocks, n_pts)
    bits, conflicts = _quad_diagonals(cells)
    tets, parent_all, from_split, cc, n_new = _split_by_table(cells, bits, n_pts)
    # Keep the input order of the cells (a stable sort by parent).
    order = np.argsort(parent_all, kind="stable")
    tets, parent_all, from_split = tets[order], parent_all[order], from_split[order]
    s = np.sort(tets, axis=1)
    # Only split cells lose such tets here; a tet listed with a repeated node stays, for
    # TetMesh.from_arrays to refuse as before.
    repeated = np.any(s[:, 1:] == s[:, :-1], axis=1) & from_split
    if np.any(repeated):
        tets, parent_all = tets[~repeated], parent_all[~repeated]
    if n_new:
        valid = cc >= 0
        centre = (pts[np.where(valid, cc, 0)] * valid[..., None]).sum(axis=1) / valid.sum(axis=1)[:, None]
        pts = np.concatenate([pts, centre])
    return CellSplit(points=pts, tets=tets, parent=parent_all, centroid_corners=cc,
                     split=tuple(split.items()), ignored=tuple(ignored.items()),
                     dropped_repeated=int(repeated.sum()), conflicts=conflicts)


def _gather_cells(blocks: Sequence[tuple[str, Any]],
                  n_pts: int) -> tuple[dict[str, tuple[Int, Int]], dict[str, int], dict[str, int]]:
    """The volume cells by linear shape, as (corner ids, input index) arrays, each block checked;
    and the counts of cells to be split and of non-volume cells ignored, by type."""
    by_shape: dict[str, list[tuple[Int, Int]]] = {s: [] for s in _REFERENCE}
    split: dict[str, int] = {}
    ignored: dict[str, int] = {}
    offset = 0
    for i, (ctype, data) in enumerate(blocks):
        ctype = str(ctype)
        count = len(data)
        if ctype not in VOLUME_CELLS:
            if count:
                ignored[ctype] = ignored.get(ctype, 0) + count
            offset += count
            continue
        shape, pick = VOLUME_CELLS[ctype]
        conn = np.asarray(data)
        if conn.size == 0:
            offset += count
            continue
        if conn.ndim != 2 or conn.shape[1] < max(pick) + 1 or conn.dtype.kind not in "iuf":
            raise ValueError(f"block {i} ({ctype}) must be an integer array of shape (k, >= {max(pick) + 1}), "
                             f"got {conn.dtype} {conn.shape}")
        corners = conn[:, list(pick)]
        if corners.dtype.kind == "f":  # ids stored as floats: checked before the cast (inf -> -2**63)
            wrong = ~np.isfinite(corners) | (corners != np.round(corners))
            if np.any(wrong):
                row, col = np.argwhere(wrong)[0]
                raise ValueError(f"block {i} ({ctype}) has node id {corners[row, col]} in cell {row}: "
                                 "node ids must be integers")
        if corners.min() < 0 or corners.max() >= n_pts:
            bad = corners.min() if corners.min() < 0 else corners.max()
            shown = f"{bad:g}" if corners.dtype.kind == "f" else int(bad)
            raise ValueError(f"block {i} ({ctype}) indexes point {shown}, outside 0..{n_pts - 1}")
        corners = corners.astype(np.int64)
        by_shape[shape].append((corners, np.arange(offset, offset + count, dtype=np.int64)))
        if ctype != "tetra":
            split[ctype] = split.get(ctype, 0) + count
        offset += count
    cells = {s: (np.concatenate([c for c, _ in v]), np.concatenate([p for _, p in v]))
             for s, v in by_shape.items() if v}
    return cells, split, ignored


def _split_by_table(cells: dict[str, tuple[Int, Int]], bits: dict[str, Int],
                    n_pts: int) -> tuple[Int, Int, NDArray[np.bool_], Int, int]:
    """Each cell's tets by the table of its configuration of diagonals, grouped by shape and configuration:
    the tets, their parent cells, whether each comes from a split cell, the corners of the cells given a
    centroid (its point id ``n_pts`` + its row), and the number of centroids."""
    tets_out: list[Int] = []
    parent_out: list[Int] = []
    split_out: list[NDArray[np.bool_]] = []
    centroid_rows: list[Int] = []
    n_new = 0
    for shape, (corners, parent) in cells.items():
        nq = len(_REFERENCE[shape][1])
        tables, needs_centroid = cell_triangulation(shape)
        config = (bits[shape] << np.arange(nq)).sum(axis=1) if nq else np.zeros(corners.shape[0], np.int64)
        for cfg in np.unique(config):
            sel = np.nonzero(config == cfg)[0]
            local = tables[int(cfg)]
            ext = corners[sel]
            if needs_centroid[cfg]:
                ids = n_pts + n_new + np.arange(sel.shape[0], dtype=np.int64)
                n_new += sel.shape[0]
                ext = np.concatenate([ext, ids[:, None]], axis=1)
                centroid_rows.append(np.pad(corners[sel], ((0, 0), (0, 8 - corners.shape[1])), constant_values=-1))
            tets_out.append(ext[:, local].reshape(-1, 4))
            parent_out.append(np.repeat(parent[sel], local.shape[0]))
            split_out.append(np.full(sel.shape[0] * local.shape[0], shape != "tetra"))

    if tets_out:
        tets = np.concatenate(tets_out)
        parent_all = np.concatenate(parent_out)
        from_split = np.concatenate(split_out)
    else:
        tets = np.zeros((0, 4), np.int64)
        parent_all = np.zeros(0, np.int64)
        from_split = np.zeros(0, dtype=bool)
    cc = np.concatenate(centroid_rows) if centroid_rows else np.zeros((0, 8), np.int64)
    return tets, parent_all, from_split, cc, n_new


def _quad_diagonals(cells: dict[str, tuple[Int, Int]]) -> tuple[dict[str, Int], int]:
    """The diagonal bit of every quad of every cell, the same wherever a quad is shared."""
    quads: dict[str, Int] = {}
    tris: list[Int] = []
    for shape, (corners, _) in cells.items():
        _, q, t = _REFERENCE[shape]
        if q:
            quads[shape] = corners[:, np.array(q)]  # (k, nq, 4)
        if t:
            tris.append(corners[:, np.array(t)].reshape(-1, 3))
    out: dict[str, Int] = {}
    if not quads:
        return out, 0
    allq = np.concatenate([v.reshape(-1, 4) for v in quads.values()])
    a, b, c, d = allq.T
    # Smallest global id wins (Dompierre et al. 1999): bit 1 takes b-d.
    bit = (np.minimum(b, d) < np.minimum(a, c)).astype(np.int64)
    conflicts = 0
    if tris:
        # A quad half that is already another cell's triangle fixes the diagonal.
        tri = np.sort(np.concatenate(tris), axis=1)
        halves = np.sort(np.stack([allq[:, [1, 2, 3]], allq[:, [0, 2, 3]], allq[:, [0, 1, 3]], allq[:, [0, 1, 2]]],
                                  axis=1).reshape(-1, 3), axis=1)
        _, inv = np.unique(np.concatenate([tri, halves]), axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        is_tri = np.zeros(int(inv.max()) + 1, dtype=bool)
        is_tri[inv[: tri.shape[0]]] = True
        claimed = is_tri[inv[tri.shape[0]:]].reshape(-1, 4)  # claimed[:, j]: the half without corner j
        wants_bd = claimed[:, 0] | claimed[:, 2]  # a half without a (or c) holds b-d
        wants_ac = claimed[:, 1] | claimed[:, 3]
        bit = np.where(wants_bd & ~wants_ac, 1, np.where(wants_ac & ~wants_bd, 0, bit))
        conflicts = int(np.sum(wants_bd & wants_ac))
    start = 0
    for shape, per_cell in quads.items():
        k, nq = per_cell.shape[:2]
        out[shape] = bit[start:start + k * nq].reshape(k, nq)
        start += k * nq
    return out, conflicts


# ---------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------

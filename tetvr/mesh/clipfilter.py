"""ParaView's Clip filter on a tetrahedral mesh: cells cut by planes into new tetrahedra.

About this technique
--------------------
In ParaView a clip of a volume is a filter: ``Clip`` with a plane ("Invert" unchecked, so
the side the normal points into is kept) runs VTK's ``vtkTableBasedClipDataSet``, the
marching-cells clip (``vtkMarchingCellsClipCases``). The clip function at each point is the
plane's signed distance, and a point is kept where it is ``>= 0``. A tet whose four points
are kept passes whole, one with none is dropped, and any other becomes one tet or one wedge
(prism) from the case table. Its new points lie on the cut edges at
``t = -s_low / (s_high - s_low)`` from the lower-valued end (then flipped to run from the
lower point id), with the scalar interpolated at the same ``t``. Kept points keep their
order; the new ones follow, one per cut edge, in the order of the edges' (lower id, higher id).

The volume representation then makes tets of what is not a tet: ``vtkDataSetTriangleFilter``
passes a grid of tets alone as it is, and otherwise sends every cell, tets included, through
``vtkOrderedTriangulator``: Bowyer-Watson in the cell's parametric space, the points
inserted in the order of their ids into a bounding octahedron. A wedge's six corners lie on
one sphere, so the insertion order alone decides its three tets (the *placing*
triangulation), and the order in which VTK builds and lists them decides each tet's vertex
order, which VTK's projected tetrahedra read (the first vertex picks the edges that decide
the thick vertex and its depth). :func:`_ordered_triangulation` takes the triangulator's
steps, once per cell type and order of ids (``tests/test_parity_clip_surface.py`` checks
all 24 orders of a tet and 720 of a wedge against VTK 9.7's output).

:func:`clip_cells` takes these steps for a :class:`~tetvr.core.clip.Clip`, one plane after
another; VTK parity (:mod:`tetvr.gl.vtkpt`) draws the result, as ParaView's "Projected
tetra" draws the Clip's output. With several planes (a box is six) it matches a chain of
Clip filters each followed by a Tetrahedralize filter; a chain without them would cut the
wedges by the wedge table instead: the kept region is the same, the tets inside differ.
Pieces the cut leaves without volume (a vertex on the plane) are dropped: VTK draws nothing
for them.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import NDArray

from tetvr.core.clip import Clip
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["clip_cells"]

Int = NDArray[np.int64]
Float = NDArray[np.float64]
Point = tuple[float, float, float]

#: A tet's edges as the clip table numbers them (EA..EF).
_EDGES = ((0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3))
_A, _B, _C, _D, _E, _F = range(4, 10)
#: vtkMarchingCellsClipCases for VTK_TETRA: case (bit k set where point k is kept) ->
#: the output cell, points 0-3 the tet's, 4-9 the new points on edges EA-EF.
_TET_CASES: dict[int, tuple[int, ...]] = {
    1: (0, _A, _C, _D), 2: (1, _B, _A, _E), 4: (2, _C, _B, _F), 8: (3, _E, _D, _F),
    3: (0, _C, _D, 1, _B, _E), 5: (2, _B, _F, 0, _A, _D), 6: (1, _A, _E, 2, _C, _F),
    7: (_D, _F, _E, 0, 2, 1), 9: (0, _A, _C, 3, _E, _F), 10: (3, _D, _F, 1, _A, _B),
    11: (0, 3, 1, _C, _F, _B), 12: (2, _C, _B, 3, _D, _E), 13: (_A, _E, _B, 0, 3, 2),
    14: (1, 3, 2, _A, _D, _C),
}
#: VTK's parametric tet and wedge (GetParametricCoords; the wedge's triangles (0, 1, 2) and
#: (3, 4, 5)), and vtkDataSetTriangleFilter's wedge map: the point of corner ``_WEDGE_MAP[j]``
#: goes to the triangulator with corner j's parametric coordinates.
_TETRA = ((0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1))
_PRISM = ((0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (0, 1, 1))
_WEDGE_MAP = (3, 4, 5, 0, 1, 2)


def clip_cells(mesh: TetMesh, clip: Clip) -> TetMesh | None:
    """``mesh`` cut to the part ``clip`` keeps, as ParaView's Clip filter and its volume
    representation cut and tetrahedralize it (module notes); None where nothing is left.

    The tets keep VTK's vertex order and cell order, not :meth:`TetMesh.from_arrays`'s
    canonical ones: VTK's projected tetrahedra read both (the first vertex picks the edges
    that decide the thick vertex; cells of equal depth keep their order), so this mesh is
    for VTK parity. Pieces without volume are dropped.

    Examples
    --------
    >>> from tetvr.mesh.synthetic import single_tet
    >>> half = clip_cells(single_tet(), Clip.plane((0.25, 0, 0), (-1, 0, 0)))  # keeps x <= 0.25
    >>> half.n_tets, float(half.points[:, 0].max())
    (3, 0.25)
    """
    points, tets, scalars = mesh.points, mesh.tets.astype(np.int64), mesh.scalars
    cells = mesh.cell_scalars
    for plane in np.asarray(clip.planes, dtype=np.float64):
        points, tets, scalars, cells = _cut(points, tets, scalars, cells, plane)
        if tets.shape[0] == 0:
            return None
    q = points[tets]
    volume6 = np.einsum("ij,ij->i", np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), q[:, 3] - q[:, 0])
    edge = np.max([np.linalg.norm(q[:, i] - q[:, j], axis=1) for i in range(4) for j in range(i)], axis=0)
    solid = np.abs(volume6) > 1e-10 * edge ** 3  # TetMesh's bound for a flat tet
    if not solid.any():
        return None
    used, inverse = np.unique(tets[solid], return_inverse=True)  # the points the tets use, in order
    arrays = [points[used], inverse.reshape(-1, 4).astype(np.int32), scalars[used]]
    if cells is not None:
        arrays.append(cells[solid])
    for arr in arrays:
        arr.setflags(write=False)
    return TetMesh(points=arrays[0], tets=arrays[1], scalars=arrays[2], scalar_name=mesh.scalar_name,
                   cell_scalars=arrays[3] if cells is not None else None)


def _cut(points: Float, tets: Int, scalars: Float, cells: Float | None, plane: Float
         ) -> tuple[Float, Int, Float, Float | None]:
    """One plane's Clip filter, then vtkDataSetTriangleFilter: new point ids as VTK numbers
    them, the tets in VTK's order, each with VTK's vertex order."""
    s = points @ plane[:3] + plane[3]
    kept = s >= 0.0
    case = (kept[tets] * np.array([1, 2, 4, 8])).sum(axis=1)
    whole, cut = case == 15, (case != 0) & (case != 15)
    new_id = np.cumsum(kept) - 1
    # The cut edges, by their (lower id, higher id), numbered after the kept points.
    ends = np.stack([tets[cut][:, list(e)] for e in _EDGES], axis=1)  # (m, 6, 2)
    lo, hi = ends.min(axis=2), ends.max(axis=2)
    crossed = kept[lo] != kept[hi]
    n = points.shape[0]
    keys = np.unique(lo[crossed] * n + hi[crossed])
    a, b = keys // n, keys % n
    edge_id = np.full(ends.shape[:2], -1, dtype=np.int64)
    edge_id[crossed] = int(kept.sum()) + np.searchsorted(keys, lo[crossed] * n + hi[crossed])
    t = _edge_parameter(s, a, b)
    new_points = np.concatenate([points[kept], points[a] + t[:, None] * (points[b] - points[a])])
    new_scalars = np.concatenate([scalars[kept], scalars[a] + t * (scalars[b] - scalars[a])])
    # The Clip filter's cells, in the input's order: whole tets, one tet or wedge per cut one.
    corner = np.concatenate([new_id[tets[cut]], edge_id], axis=1)  # (m, 10): points 0-3, edges EA-EF
    shapes: dict[int, list[Int]] = {4: [new_id[tets[whole]]], 6: [np.zeros((0, 6), dtype=np.int64)]}
    parents: dict[int, list[Int]] = {4: [np.nonzero(whole)[0]], 6: [np.zeros(0, dtype=np.int64)]}
    for c, shape in _TET_CASES.items():
        rows = np.nonzero(case[cut] == c)[0]
        shapes[len(shape)].append(corner[rows][:, list(shape)])
        parents[len(shape)].append(np.nonzero(cut)[0][rows])
    tet4, parent4 = np.concatenate(shapes[4]), np.concatenate(parents[4])
    wedges, parent6 = np.concatenate(shapes[6]), np.concatenate(parents[6])
    if wedges.shape[0]:  # else a grid of tets alone, which the triangle filter passes as it is
        tet4 = np.concatenate([_triangulated(tet4, _TETRA, (0, 1, 2, 3))[:, 0],
                               _triangulated(wedges, _PRISM, _WEDGE_MAP).reshape(-1, 4)])
        parent4 = np.concatenate([parent4, np.repeat(parent6, 3)])
    order = np.argsort(parent4, kind="stable")  # each input cell's pieces in the order appended
    return new_points, tet4[order], new_scalars, None if cells is None else cells[parent4[order]]


def _edge_parameter(s: Float, lo: Int, hi: Int) -> Float:
    """Where the plane cuts each edge, from its lower id, in VTK's arithmetic: ``t`` from
    the end with the lower clip value, flipped when that end has the higher id."""
    low_first = s[lo] <= s[hi]
    a = np.where(low_first, s[lo], s[hi])
    b = np.where(low_first, s[hi], s[lo])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(b != a, (0.0 - a) / (b - a), 0.0)
    return np.where(low_first, t, 1.0 - t)


def _triangulated(cells: Int, pcoords: tuple[tuple[int, int, int], ...], corner_of: tuple[int, ...]) -> Int:
    """(r, k) cells -> (r, j, 4) tets as vtkDataSetTriangleFilter makes them, by the order of
    each cell's point ids (:func:`_cell_tets`, once per order met)."""
    k = cells.shape[1]
    order = np.argsort(cells, axis=1, kind="stable")
    keys, inverse = np.unique((order * (k ** np.arange(k))).sum(axis=1), return_inverse=True)
    if keys.size == 0:
        return np.zeros((0, 3 if k == 6 else 1, 4), dtype=np.int64)
    local = np.array([_cell_tets(pcoords, corner_of, int(key)) for key in keys], dtype=np.int64)
    local = local[inverse.reshape(-1)]  # (r, j, 4) corner numbers
    return np.take_along_axis(cells[:, None, :].repeat(local.shape[1], axis=1), local, axis=2)


@functools.lru_cache(maxsize=None)
def _cell_tets(pcoords: tuple[tuple[int, int, int], ...], corner_of: tuple[int, ...], key: int
               ) -> tuple[tuple[int, ...], ...]:
    """The tets of one cell whose corners by increasing point id are ``order`` (``key`` is
    ``sum(order[k] n^k)``), as corner numbers: :func:`_ordered_triangulation` of its points,
    the one at position ``j`` being corner ``corner_of[j]``."""
    n = len(pcoords)
    rank = [0] * n
    for r in range(n):
        rank[key // n ** r % n] = r
    tets = _ordered_triangulation(pcoords, tuple(rank[corner_of[j]] for j in range(n)))
    return tuple(tuple(corner_of[j] for j in t) for t in tets)


class _Tetra:
    """vtkOrderedTriangulator's OTTetra: internal point numbers, face neighbours, circumsphere."""

    def __init__(self, points: tuple[int, ...], pc: list[Point]) -> None:
        self.points = points
        self.neighbors: list[_Tetra | None] = [None] * 4
        self.center, self.radius2 = _circumsphere(*(pc[i] for i in (points[3], points[0], points[1], points[2])))
        self.visit, self.in_cavity, self.deleted = -1, False, False

    def face(self, i: int) -> tuple[int, int, int]:
        """OTTetra::GetFacePoints: ordered so that the face and a point beyond it make a
        positively oriented tet."""
        a, b, c, d = self.points
        return ((a, d, b), (b, d, c), (a, c, d), (a, b, c))[i]


def _circumsphere(x1: Point, x2: Point, x3: Point, x4: Point) -> tuple[Point, float]:
    """vtkTetra::Circumsphere (Cramer's rule): centre and squared radius."""
    a, b, c = ([q[i] - x1[i] for i in range(3)] for q in (x2, x3, x4))
    ra, rb, rc = (sum(v * v for v in q) for q in (a, b, c))
    bxc, cxa, axb = _cross(b, c), _cross(c, a), _cross(a, b)
    det = 2.0 * sum(a[i] * bxc[i] for i in range(3))
    if det == 0.0:
        return (0.0, 0.0, 0.0), float("inf")
    off = [(ra * bxc[i] + rb * cxa[i] + rc * axb[i]) / det for i in range(3)]
    return (off[0] + x1[0], off[1] + x1[1], off[2] + x1[2]), sum(v * v for v in off)


def _cross(u: list[float], v: list[float]) -> list[float]:
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def _barycentric(x: Point, x1: Point, x2: Point, x3: Point, x4: Point) -> list[float]:
    """vtkTetra::BarycentricCoords (Cramer's rule)."""
    a, b, c, d = ([q[i] - x1[i] for i in range(3)] for q in (x2, x3, x4, x))
    bxc = _cross(b, c)
    det = sum(a[i] * bxc[i] for i in range(3))
    u = sum(d[i] * bxc[i] for i in range(3)) / det
    v = sum(a[i] * w for i, w in enumerate(_cross(d, c))) / det
    w = sum(a[i] * z for i, z in enumerate(_cross(b, d))) / det
    return [1.0 - u - v - w, u, v, w]


def _ordered_triangulation(pcoords: tuple[tuple[int, int, int], ...], ids: tuple[int, ...]
                           ) -> list[tuple[int, ...]]:
    """vtkOrderedTriangulator::Triangulate, then AddTetras: a cell's points (``pcoords``, its
    parametric coordinates, with point ids ``ids``) inserted in the order of their ids into a
    bounding octahedron of [0, 1]^3 by Bowyer-Watson, each new point's cavity walked from
    the front of the tetra list, each cavity face making a tetra (face, point) pushed to its
    front. Returns the cell's tetras in the order VTK lists them, as input positions.
    """
    n = len(ids)
    order = sorted(range(n), key=lambda k: ids[k])
    length = 2.0 * math.sqrt(3.0)
    pc: list[Point] = [(float(pcoords[k][0]), float(pcoords[k][1]), float(pcoords[k][2])) for k in order]
    pc += [(0.5 - length, 0.5, 0.5), (0.5 + length, 0.5, 0.5), (0.5, 0.5 - length, 0.5),
           (0.5, 0.5 + length, 0.5), (0.5, 0.5, 0.5 - length), (0.5, 0.5, 0.5 + length)]
    tol2 = length * length * 1.0e-10
    b = n  # the bounding points follow the cell's
    start = [_Tetra(pts, pc) for pts in ((b, b + 2, b + 4, b + 5), (b + 2, b + 1, b + 4, b + 5),
                                        (b + 1, b + 3, b + 4, b + 5), (b + 3, b, b + 4, b + 5))]
    for t in start:
        t.center, t.radius2 = (0.5, 0.5, 0.5), 1.5
    for i, (n1, n2) in enumerate(((1, 3), (2, 0), (3, 1), (0, 2))):
        start[i].neighbors[1], start[i].neighbors[2] = start[n1], start[n2]
    tetras = start[::-1]  # each pushed to the front
    for p in range(n):
        x = pc[p]
        tetra: _Tetra | None = tetras[0]
        for _ in range(201):  # WalkToTetra: towards the most negative barycentric coordinate
            assert tetra is not None
            bc = _barycentric(x, *(pc[i] for i in tetra.points))
            neg = min((j for j in range(4) if bc[j] < -0.000001), key=lambda j: bc[j], default=-1)
            if neg < 0:
                break
            tetra = tetra.neighbors[(1, 2, 0, 3)[neg]]
        assert tetra is not None
        faces = _cavity(p, x, tetra, pc, tol2)
        tetras = [t for t in tetras if not t.deleted]
        edges: dict[frozenset[int], _Tetra] = {}
        for face, outside in faces:
            new = _Tetra((*face, p), pc)
            tetras.insert(0, new)
            if outside is not None:
                _assign_neighbors(new, outside)
            for i in range(3):
                edge = frozenset((face[i], face[(i + 1) % 3]))
                if edge in edges:
                    _assign_neighbors(new, edges[edge])
                else:
                    edges[edge] = new
    return [tuple(order[i] for i in t.points) for t in tetras if max(t.points) < n]


def _cavity(p: int, x: Point, seed: _Tetra, pc: list[Point],
            tol2: float) -> list[tuple[tuple[int, int, int], _Tetra | None]]:
    """vtkOTMesh::CreateInsertionCavity: the tetras whose circumsphere holds point ``p``
    (marked deleted) and the cavity's boundary faces with the tetra beyond each, in VTK's
    order; a face ``p`` does not see restarts the search with its tetra kept out."""
    degenerate: list[_Tetra] = []
    while True:
        stack, visited, faces = [seed], [seed], []
        seed.visit, seed.in_cavity = p, True
        valid = True
        while stack and valid:
            tetra = stack.pop()
            for i in range(4):
                nei = tetra.neighbors[i]
                if nei is not None and nei.visit != p:
                    visited.append(nei)
                    nei.visit = p
                    d2 = sum((x[k] - nei.center[k]) ** 2 for k in range(3))
                    nei.in_cavity = d2 < 0.999999 * nei.radius2
                    if nei.in_cavity:
                        stack.append(nei)
                        continue
                elif nei is not None and nei.in_cavity:
                    continue
                face = tetra.face(i)
                faces.append((face, nei))
                if not _sees(x, face, pc, tol2):
                    valid = False
                    degenerate.append(tetra)
                    break
        if valid:
            for t in visited:
                t.deleted = t.visit == p and t.in_cavity
            return faces
        for t in visited:
            t.visit = -1
        for t in degenerate:
            t.visit, t.in_cavity = p, False


def _sees(x: Point, face: tuple[int, int, int], pc: list[Point],
          tol2: float) -> bool:
    """OTFace::IsValidCavityFace: ``x`` strictly in front of the face, beyond the tolerance."""
    p0, p1, p2 = (pc[i] for i in face)
    normal = _cross([p1[k] - p0[k] for k in range(3)], [p2[k] - p0[k] for k in range(3)])
    d = sum((x[k] - p0[k]) * normal[k] for k in range(3))
    return d > 0.0 and d * d > tol2 * sum(v * v for v in normal)


def _assign_neighbors(t1: _Tetra, t2: _Tetra) -> None:
    """Make two tetras that share a face each other's neighbour across it."""
    for a, other in ((t1, t2), (t2, t1)):
        mask = sum(1 << i for i in range(4) if a.points[i] in other.points)
        slot = {11: 0, 14: 1, 13: 2, 7: 3}.get(mask)
        if slot is not None:
            a.neighbors[slot] = other

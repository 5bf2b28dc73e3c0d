"""Face adjacency of a tetrahedral mesh: neighbours across faces and the face planes.

About this technique
--------------------
Cell-connectivity visibility orderings (Williams 1992, MPVO/MPVONC) need, for every
tetrahedron, the cell on the other side of each of its four faces and the plane of that
face. Both depend only on the mesh, so they are built once and reused for every view.

A face is keyed by its three vertex ids in ascending order, packed into one int64
(``(a*N + b)*N + c`` for ``N`` points; a lexicographic sort when ``N**3`` overflows). One
argsort of the ``4m`` keys puts the two copies of every interior face next to each other,
so pairing is a comparison of neighbours in the sorted array: O(m log m) in numpy, with
no Python loop. A face held by more than two cells (a non-manifold mesh) is left
unpaired, i.e. treated as boundary on every side, and counted.

Faces are keyed by *welded* point ids: points at exactly the same coordinates count as one
(:func:`coincident_points`). FEM tools write a mesh of several material regions with each
region's own copy of the nodes on the interface; welded, the two copies of an interface face
pair up like any interior face, so the regions join into one mesh (the walk of
:mod:`tetvr.mesh.records` goes straight through, and MPVO orders across). The fields are
not welded: each copy keeps its own value, so a field that jumps at the interface still does.

Each face plane is stored as an outward unit normal ``n`` and an offset ``d`` with
``n . (x - origin) = d`` on the face, where ``origin`` is the centre of the mesh's
bounding box: measuring from there keeps ``|d|`` below the mesh radius, so the rounding
error of a plane test has a bound that does not depend on where the mesh sits in space.
The two sides of an interior face carry exactly negated planes, so the test ``n . e - d``
of an eye point ``e`` gives exactly opposite signs for the two cells: the two cells can
never both claim to be in front.

The planes of all ``4m`` faces take 96 bytes a tet in float64, more than the rest of the
adjacency together, and tet marching reads each only once, into its float32 records: they
are computed from the mesh's points when asked for, either for a set of faces
(:meth:`FaceAdjacency.planes`, in blocks) or all at once (``normals`` and ``offsets``, kept
once computed, as the visibility sort of projected tetrahedra reads them every view).
"""

from __future__ import annotations

import dataclasses
import threading
import weakref
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh.tetmesh import TetMesh

__all__ = ["FaceAdjacency", "face_adjacency", "FACE_VERTICES", "BLOCK_TETS", "blocks"]

#: Local vertex ids of the face opposite local vertex k (slot k of a tet).
FACE_VERTICES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]], dtype=np.intp)

#: Tets a block of per-tet work is done in (face planes, cell sizes, the walk's records):
#: its float64 temporaries then take a few MB, whatever the mesh's size. A multiple of
#: every records texture's row (:class:`tetvr.gl.march_layout.Layout`: at most 8192 items).
BLOCK_TETS = 1 << 16


def blocks(n: int, size: int | None = None) -> list[slice]:
    """``range(n)`` as consecutive slices of ``size`` (:data:`BLOCK_TETS` unless given; the last shorter).

    >>> blocks(5, 2)
    [slice(0, 2, None), slice(2, 4, None), slice(4, 5, None)]
    """
    size = size or BLOCK_TETS
    return [slice(start, min(start + size, n)) for start in range(0, n, size)]


@dataclasses.dataclass(frozen=True, eq=False)
class FaceAdjacency:
    """Per-tet face neighbours and face planes of one mesh (see :func:`face_adjacency`).

    Slot ``k`` of tet ``t`` is the face opposite vertex ``mesh.tets[t, k]``.

    Attributes
    ----------
    neighbors : (m, 4) int32, the tet across each face, -1 on the boundary (computed from
        ``mates`` when first read).
    mates : (m, 4) int32, the same face as a slot of that neighbour, as the flat index
        ``4 * neighbor + k`` (so ``mates // 4`` is ``neighbors``), -1 on the boundary.
    mirrored : (m, 4) bool, the second copy of each interior face: its plane is the exact
        negation of its mate's.
    normals : (m, 4, 3) float64, outward unit normal of each face (computed when first read).
    offsets : (m, 4) float64, ``normals . (x - origin)`` for any point ``x`` of the face
        (computed with ``normals``).
    origin : (3,) float64, centre of the mesh's bounding box.
    radius : largest distance of a mesh point from ``origin``.
    n_interior_faces : faces shared by two tets.
    n_boundary_faces : faces on one tet only (including non-manifold ones).
    n_nonmanifold_faces : distinct faces held by more than two tets (left unpaired).
    cell_size : median longest edge of the tets, a length scale for heuristics.
    boundary_slots : (F,) int64 flat slots ``4 * t + k`` of the boundary faces.
    boundary_faces : (F, 3) vertex ids of those faces (``FACE_VERTICES`` of each slot),
        welded (see ``canonical``).
    convex : whether the mesh fills a convex region: its boundary is one closed,
        connected, manifold surface, convex at every edge (then it is convex
        everywhere, Tietze 1928), so MPVO's order is exact from every viewpoint and
        rays through the boundary (:mod:`tetvr.order.boundary`) add nothing.
    canonical : (n_points,) int64, each point's welded id (the lowest id of the points at
        exactly its coordinates), or None where no two points coincide.
    n_welded_points : points that coincide with a lower-numbered one (duplicated nodes).
    rel_points : (3, n_points) float64, the points relative to ``origin``, one row an axis,
        and ``tets``, the mesh's tets (the array itself): what the planes are computed from.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> adj = face_adjacency(synthetic.two_tets())
    >>> adj.neighbors.tolist()
    [[-1, -1, -1, 1], [-1, -1, 0, -1]]
    >>> int(adj.mates[0, 3]), adj.n_interior_faces, adj.n_boundary_faces
    (6, 1, 6)
    """

    mates: NDArray[np.int32]
    mirrored: NDArray[np.bool_]
    origin: NDArray[np.float64]
    radius: float
    n_interior_faces: int
    n_boundary_faces: int
    n_nonmanifold_faces: int
    cell_size: float
    boundary_slots: NDArray[np.int64]
    boundary_faces: NDArray[np.int64]
    convex: bool = False
    canonical: NDArray[np.int64] | None = None
    n_welded_points: int = 0
    rel_points: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros((3, 0)), repr=False)
    tets: NDArray[np.int32] = dataclasses.field(default_factory=lambda: np.zeros((0, 4), np.int32), repr=False)

    def planes(self, slots: NDArray[np.integer[Any]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Outward unit normals (k, 3) and offsets (k,) of the faces at flat ``slots``
        (``4 * t + k``): the rows of ``normals`` and ``offsets`` there, bit for bit.

        Examples
        --------
        >>> from tetvr.mesh import synthetic
        >>> adj = face_adjacency(synthetic.cube(2))
        >>> n, d = adj.planes(np.arange(8))
        >>> bool(np.array_equal(n, adj.normals.reshape(-1, 3)[:8]) and np.array_equal(d, adj.offsets.reshape(-1)[:8]))
        True
        """
        slots = np.asarray(slots, dtype=np.int64).reshape(-1)
        mirrored = self.mirrored.reshape(-1)[slots]
        # The second copy of an interior face takes its mate's plane, negated.
        normals, offsets = _face_planes(self.rel_points, self.tets,
                                        np.where(mirrored, self.mates.reshape(-1)[slots], slots))
        np.negative(normals, out=normals, where=mirrored[:, None])
        np.negative(offsets, out=offsets, where=mirrored)
        return normals, offsets

    @cached_property
    def neighbors(self) -> NDArray[np.int32]:
        """(m, 4) int32, the tet across each face, -1 on the boundary."""
        out = np.where(self.mates >= 0, self.mates // 4, -1).astype(np.int32)
        out.setflags(write=False)
        return out

    @cached_property
    def normals(self) -> NDArray[np.float64]:
        """(m, 4, 3) float64, outward unit normal of each face (computed once, in blocks)."""
        m = self.mates.shape[0]
        normals = np.empty((m, 4, 3))
        offsets = np.empty((m, 4))
        for rows in blocks(m):
            n, d = self.planes(np.arange(4 * rows.start, 4 * rows.stop))
            normals[rows], offsets[rows] = n.reshape(-1, 4, 3), d.reshape(-1, 4)
        for arr in (normals, offsets):
            arr.setflags(write=False)
        self.__dict__["offsets"] = offsets  # a cached_property: seeded in the instance
        return normals

    @cached_property
    def offsets(self) -> NDArray[np.float64]:
        """(m, 4) float64, ``normals . (x - origin)`` for any point ``x`` of each face."""
        _ = self.normals  # computes both
        return self.__dict__["offsets"]


# Keyed on the identity of the (points, tets) arrays rather than on the mesh, so that
# meshes that share geometry (``TetMesh.with_scalars``) share one adjacency. An entry is
# dropped when either array is freed, before its id can be reused: the points, since the
# adjacency holds the tets (the planes are computed from them).
_CACHE: dict[tuple[int, int, bytes], FaceAdjacency] = {}
_LOCK = threading.Lock()


def face_adjacency(mesh: TetMesh) -> FaceAdjacency:
    """The face adjacency of ``mesh``, built on first use and cached while it lives.

    The cache follows the mesh's ``points`` and ``tets`` arrays (immutable in a
    :class:`~tetvr.mesh.tetmesh.TetMesh`), so a mesh with only new scalars reuses it, and it
    does not keep the points alive (the adjacency holds the tets: its entry goes with the points).

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.cube(2)
    >>> face_adjacency(mesh) is face_adjacency(mesh.with_scalars(mesh.scalars * 2))
    True
    """
    # The origin too: a mesh given another float32 origin shares its arrays with the first.
    key = (id(mesh.points), id(mesh.tets), mesh.float32_origin.tobytes())
    adj = _CACHE.get(key)
    if adj is None:
        built = _build(mesh)
        with _LOCK:
            adj = _CACHE.get(key)
            if adj is None:
                adj = _CACHE[key] = built
                for arr in (mesh.points, mesh.tets):
                    weakref.finalize(arr, _CACHE.pop, key, None)
    return adj


def _build(mesh: TetMesh) -> FaceAdjacency:
    tets = mesh.tets
    pts = np.asarray(mesh.points, dtype=np.float64)
    m = tets.shape[0]
    n_pts = pts.shape[0]
    if 4 * m > np.iinfo(np.int32).max:  # pragma: no cover - flat slot ids are int32
        raise ValueError(f"face adjacency supports up to {np.iinfo(np.int32).max // 4} tets, got {m}")

    canonical = coincident_points(pts)
    welded = tets if canonical is None else canonical[tets]
    p, q, n_nonmanifold = _pair_faces(welded, n_pts)
    mates = np.full(4 * m, -1, dtype=np.int32)
    mates[p] = q
    mates[q] = p
    mirrored = np.zeros(4 * m, dtype=bool)
    mirrored[q] = True

    origin = np.array(mesh.float32_origin)  # the bounding box's centre unless a whole mesh's was given
    rel = pts - origin
    radius = float(np.sqrt(np.max(np.einsum("ij,ij->i", rel, rel))))
    rel_points = np.ascontiguousarray(rel.T)
    cell_size = _cell_size(rel_points, tets)

    mates = mates.reshape(m, 4)
    mirrored = mirrored.reshape(m, 4)
    for arr in (mates, mirrored, origin):
        arr.setflags(write=False)
    n_interior = int(p.size)
    boundary_slots = np.flatnonzero(mates.reshape(-1) < 0)
    boundary_faces = welded[boundary_slots[:, None] >> 2, FACE_VERTICES[boundary_slots & 3]].astype(np.int64)
    for out in (boundary_slots, boundary_faces) + (() if canonical is None else (canonical,)):
        out.setflags(write=False)
    adj = FaceAdjacency(
        mates=mates,
        mirrored=mirrored,
        origin=origin,
        radius=radius,
        n_interior_faces=n_interior,
        n_boundary_faces=4 * m - 2 * n_interior,
        n_nonmanifold_faces=n_nonmanifold,
        cell_size=cell_size,
        boundary_slots=boundary_slots,
        boundary_faces=boundary_faces,
        canonical=canonical,
        n_welded_points=0 if canonical is None else int(np.count_nonzero(canonical != np.arange(n_pts))),
        rel_points=rel_points,
        tets=mesh.tets,
    )
    convex = n_nonmanifold == 0 and _convex_boundary(boundary_slots, boundary_faces, rel,
                                                     *adj.planes(boundary_slots), cell_size)
    return dataclasses.replace(adj, convex=convex)


def coincident_points(points: NDArray[np.float64]) -> NDArray[np.int64] | None:
    """Each point's welded id: the lowest id of the points at exactly its coordinates
    (``-0.0`` and ``0.0`` are one coordinate); None when no two points coincide.

    Examples
    --------
    >>> coincident_points(np.array([[0.0, 0, 0], [1, 0, 0], [0, 0, 0]])).tolist()
    [0, 1, 0]
    >>> coincident_points(np.eye(3)) is None
    True
    """
    pts = np.asarray(points, dtype=np.float64) + 0.0  # -0.0 + 0.0 is 0.0
    n = pts.shape[0]
    if n < 2:
        return None
    order = np.lexsort((np.arange(n), pts[:, 2], pts[:, 1], pts[:, 0]))
    s = pts[order]
    same = np.all(s[1:] == s[:-1], axis=1)
    if not same.any():
        return None
    # The first of each run of equal rows (its lowest id: ties are ordered by id).
    run_start = np.maximum.accumulate(np.where(np.r_[True, ~same], np.arange(n), 0))
    canonical = np.empty(n, dtype=np.int64)
    canonical[order] = order[run_start]
    return canonical




def _pair_faces(tets: NDArray[np.integer[Any]], n_pts: int) -> tuple[NDArray[np.intp], NDArray[np.intp], int]:
    """The two flat slots of every interior face (``p[i]`` and ``q[i]`` hold the same
    face) and the number of non-manifold faces (held by more than two cells: unpaired)."""
    m = tets.shape[0]
    # One int64 key per face (slot-major: entry 4*t + k is the face opposite vertex k),
    # its vertex ids sorted, built column by column to avoid (4m, 3) temporaries.
    cols = [tets[:, i] for i in range(4)]
    wide = n_pts <= 2_097_151  # 3 * 21 bits fit an int64
    key = np.empty((m, 4), dtype=np.int64)
    sorted_faces = []
    for k, (i, j, h) in enumerate(FACE_VERTICES):
        x, y, z = cols[i], cols[j], cols[h]
        lo = np.minimum(np.minimum(x, y), z).astype(np.int64)
        hi = np.maximum(np.maximum(x, y), z).astype(np.int64)
        mid = np.maximum(np.minimum(x, y), np.minimum(np.maximum(x, y), z)).astype(np.int64)
        if wide:
            key[:, k] = (lo * n_pts + mid) * n_pts + hi
        else:  # pragma: no cover - meshes with more than two million points
            sorted_faces.append((lo, mid, hi))
    if wide:
        flat_key = key.reshape(-1)
        order = np.argsort(flat_key)
        ks = flat_key[order]
        del key, flat_key
        same = ks[1:] == ks[:-1]
        del ks
    else:  # pragma: no cover
        lo, mid, hi = (np.stack([f[c] for f in sorted_faces], axis=1).reshape(-1) for c in range(3))
        order = np.lexsort((hi, mid, lo))
        lo, mid, hi = lo[order], mid[order], hi[order]
        same = (lo[1:] == lo[:-1]) & (mid[1:] == mid[:-1]) & (hi[1:] == hi[:-1])

    # A pair of equal neighbours is an interior face, unless the run of equal keys is
    # longer than two (a non-manifold face), which is left as boundary on every side.
    run_before = np.concatenate(([False], same[:-1]))
    run_after = np.concatenate((same[1:], [False]))
    pair = same & ~run_before & ~run_after
    n_nonmanifold = int(np.count_nonzero(same & ~run_before)) - int(np.count_nonzero(pair))
    first = np.flatnonzero(pair)
    return order[first], order[first + 1], n_nonmanifold


def _face_planes(rel_points: NDArray[np.float64], tets: NDArray[np.integer[Any]],
                 slots: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Outward unit normals (k, 3) and offsets (k,) of the faces at flat ``slots``, each
    from its own tet's corners (``rel_points``: (3, n), the points relative to the
    origin, one row an axis), component by component."""
    flat = tets.reshape(-1)
    base, k = slots & ~3, slots & 3
    corner = [flat[base + FACE_VERTICES[k, c]] for c in range(3)] + [flat[slots]]
    # (x, y, z) of the face's three corners a, b, c and of the opposite vertex o.
    (ax, ay, az), (bx, by, bz), (cx, cy, cz), (ox, oy, oz) = ([axis[v] for axis in rel_points] for v in corner)
    ux, uy, uz = bx - ax, by - ay, bz - az
    vx, vy, vz = cx - ax, cy - ay, cz - az
    nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    # Outward: the opposite vertex lies on the negative side of the plane.
    side = nx * (ox - ax) + ny * (oy - ay) + nz * (oz - az)
    scale = np.where(side > 0, -1.0, 1.0) / np.sqrt(nx * nx + ny * ny + nz * nz)
    nx *= scale
    ny *= scale
    nz *= scale
    return np.stack([nx, ny, nz], axis=1), nx * ax + ny * ay + nz * az


def _cell_size(rel_points: NDArray[np.float64], tets: NDArray[np.integer[Any]]) -> float:
    """The median over the cells of the longest edge (``rel_points``: (3, n), the points), in blocks of cells."""
    longest = np.zeros(tets.shape[0])
    for rows in blocks(tets.shape[0]):
        cx, cy, cz = (axis[tets[rows]] for axis in rel_points)
        for i, j in ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)):
            ex, ey, ez = cx[:, i] - cx[:, j], cy[:, i] - cy[:, j], cz[:, i] - cz[:, j]
            np.maximum(longest[rows], ex * ex + ey * ey + ez * ez, out=longest[rows])
    return float(np.sqrt(np.median(longest)))


def _convex_boundary(slots: NDArray[np.int64], verts: NDArray[np.int64], rel: NDArray[np.float64],
                     n: NDArray[np.float64], d: NDArray[np.float64], cell_size: float) -> bool:
    """Whether the boundary faces form one closed connected surface, convex at every edge
    (``n``, ``d``: the planes of the faces at ``slots``).

    Each boundary edge must be held by exactly two boundary faces, and the far vertex of
    each must lie on or behind the other's plane (within a rounding tolerance relative to
    the cell size). Connectivity is checked by propagating the smallest face label across
    shared edges, with pointer jumping, to a fixed point.
    """
    if slots.size < 4:
        return False
    n_f = slots.size
    # The three edges of every boundary face, as (face, sorted vertex pair, far vertex).
    ea = np.concatenate([verts[:, 0], verts[:, 1], verts[:, 2]])
    eb = np.concatenate([verts[:, 1], verts[:, 2], verts[:, 0]])
    far = np.concatenate([verts[:, 2], verts[:, 0], verts[:, 1]])
    face = np.tile(np.arange(n_f), 3)
    lo, hi = np.minimum(ea, eb), np.maximum(ea, eb)
    order = np.lexsort((hi, lo))
    lo, hi, far, face = lo[order], hi[order], far[order], face[order]
    same = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1])
    # Closed manifold surface: the edges come in exactly two copies.
    if lo.size % 2 or not np.all(same[0::2]) or np.any(same[1::2]):
        return False
    f, g = face[0::2], face[1::2]
    far_f, far_g = far[0::2], far[1::2]
    tol = 1e-9 * max(cell_size, 1e-300)
    if np.any(np.einsum("ij,ij->i", n[f], rel[far_g]) - d[f] > tol):
        return False
    if np.any(np.einsum("ij,ij->i", n[g], rel[far_f]) - d[g] > tol):
        return False
    label = np.arange(n_f)
    while True:
        low = np.minimum(label[f], label[g])
        new = label.copy()
        np.minimum.at(new, f, low)
        np.minimum.at(new, g, low)
        new = new[new]  # pointer jumping
        if np.array_equal(new, label):
            return bool(np.all(label == 0))
        label = new

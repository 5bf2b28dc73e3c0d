"""Per-tet records and ray entry points for the tet-marching ray caster (CPU stage).

About this technique
--------------------
Tet marching (Garrity 1990; on the GPU, Weiler et al. 2003, "Hardware-based ray casting
for tetrahedral meshes") follows each pixel's ray from cell to cell through shared faces:
in the tet it is in, the ray leaves by the nearest of the faces it points out of, and the
neighbour across that face is the next cell. Each tet contributes one exact segment,
integrated by a lookup in the same pre-integration table as projected tetrahedra
(Kraus et al. 2004), composited front to back in traversal order: there is no sort and
no visibility error, and the cost follows the ray--tet segments, not the tets.

The walk by points (Marmitt & Slusallek 2006, "Fast ray traversal of tetrahedral and
hexahedral meshes for direct volume rendering"): seen in the plane across the ray, the face
a ray came in by is a triangle about the ray; the tet's fourth point and the three edges
to it say, by the signs of three 2D cross products, which face the ray leaves by, and the
same products are the exit's barycentric weights (its depth and its scalar, exact for a
linear field). The walk carries the triangle from tet to tet, so each step reads one link
and one point -- against three face planes, a scalar record and the mates in a walk by
planes -- and whatever the rounding, the triangle it holds is about the ray.

Built here once per mesh:

* each tet's points in increasing id (slot ``k`` of every record is the ``k``-th, face
  ``k`` is opposite it): the three points of a face then come in the same order in both
  its tets, so the walk finds their slots in the next tet from the two faces' slots alone;
* each face's mate: ``4 * neighbour + k`` for the neighbour's face ``k`` that is the same
  face, or -1 on the boundary (the ray leaves the mesh there), and the *link*: the mate,
  the neighbour's point opposite that face and, for cell data, the neighbour's scalar;
* the four face planes, outward unit normal ``n`` and ``w`` with ``n . x + w = 0`` on the
  face (``x`` relative to the mesh's bounding-box centre), and the scalar as an affine
  function ``s(x) = g . x + c``: the entry passes use them, and so does the walk in each
  ray's first tet (a ray that starts inside a tet, at the near plane, has no triangle yet)
  and in the next ones until the face it leaves by holds the ray as seen across it (an
  entry beside faces seen edge-on may be a cell a grazing ray misses by a rounding).

The per-tet records (the planes and links, 144 bytes a tet) are built in blocks of
:data:`~tetvr.mesh.adjacency.BLOCK_TETS` tets (:func:`cell_records`), so that the GL can take
each block as it is built and the host never holds them whole; :func:`march_records` builds
them whole, for the CPU.

The points themselves go to the GPU per view, relative to the eye in float64 first, so
that float32 keeps their precision near the eye wherever the mesh's centre is
(:mod:`tetvr.gl.raymarch`).

Rays enter the mesh at front-facing boundary faces; where the mesh is not convex a ray may
leave and enter again, and each further entry is the nearest boundary face behind the
last exit, picked from a list of the pixel's faces or found by peeling the boundary there
(:mod:`tetvr.gl.raymarch`). Rays that start inside the mesh -- the eye inside,
the near plane cutting cells -- start in the tet that holds the ray's point on the near
plane: :func:`near_plane_cells` lists the tets the near plane cuts and where they project.
"""

from __future__ import annotations

import dataclasses
import weakref

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh.adjacency import FACE_VERTICES, blocks, face_adjacency
from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["MarchRecords", "march_records", "cell_records", "near_plane_cells", "rim_faces", "folded_faces",
           "RECORD_TEXELS"]

#: Texels of one tet's record in the float texture: four face planes, then the scalar.
RECORD_TEXELS = 5
#: A boundary face counts as seen edge-on (:func:`rim_faces`) where the rays meet its plane
#: at a sine below this: a ray the rasteriser drops within 1/256 pixel of its edge would
#: cross less than a quarter of a pixel's footprint before leaving through that plane
#: at any larger sine.
EDGE_ON_SINE = 1.0 / 64.0
#: A boundary face counts as seen edge-on (:func:`rim_faces`) too where its projection is
#: thinner than this, in pixels: a needle (a face of almost no area, whatever its plane
#: says) or a face whose corners nearly line up seen from the eye. The rasteriser snaps
#: corners to 1/256 pixel, which can turn such a triangle over or move a pixel centre
#: across its long edge, and a pixel next to it then falls between the faces drawn.
THIN_PIXELS = 1.0 / 64.0


@dataclasses.dataclass(frozen=True, eq=False)
class MarchRecords:
    """What the walk reads per tet (see the module docstring).

    Attributes
    ----------
    ids : (m, 4) int32, each tet's point ids in increasing welded id: slot ``k`` of every
        record is this point (face ``k`` is opposite it), so the three points of a face are
        in the same order in both its tets, also where each holds its own copy of them.
        None in the records the ray caster keeps once they are on the GL (no view reads them).
    planes : (m, 4, 4) float32, face ``k`` of tet ``t``: ``(n, w)`` with ``n . x + w``
        negative inside (``x`` relative to ``origin``). None where the per-tet records were
        left to :func:`cell_records` (``march_records(mesh, cells=False)``), as are
        ``scalar`` and ``links``.
    scalar : (m, 4) float32, ``(g, c)`` with ``s(x) = g . x + c``.
    links : (m, 4, 4) int32, across face ``k``: (the mate, the neighbour's point opposite
        that face (on the boundary: the face's row of ``boundary_neighbors``), the neighbour's cell scalar as float32 bits (cell data; else 0), 1 where
        the point field jumps at the face, else 0); the walk reads one link a step
        (``march.frag``). A face jumps where its points are duplicated nodes (two regions
        meeting there, :func:`tetvr.mesh.adjacency.coincident_points`) whose copies carry
        different values: the walk then takes the scalars of the tet it enters.
    boundary_slots : (F,) int64, ``4 * t + k`` of each boundary face.
    boundary_triangles : (F, 3, 3) float32, the boundary faces' corners (relative to
        ``origin``), counter-clockwise seen from outside the mesh.
    boundary_corners : (F, 3) int64, the boundary faces' corners as point indices, wound
        as ``boundary_triangles``.
    boundary_edges : (F, 3) int64, each boundary face's edges as ``i * n_points + j``
        (point indices ``i < j``): faces sharing a key share that edge.
    boundary_pairs : (P, 2) int64, the pairs of boundary faces that share an edge.
    boundary_neighbors : (F, 4) int32, each boundary face's neighbours on the boundary (the
        faces sharing an edge with it) as slots ``4 * t + k``, -1 after the last: where a ray
        leaves the mesh beside a fold of its surface, it may enter again at once through
        one of them (``march.frag`` tests them as it tests the face it left by).
    boundary_planes : (F, 4) float64, ``planes`` of the boundary faces.
    boundary_spheres : (F, 4) float64, a sphere round each boundary face (centre, radius).
    boundary_heights : (F,) float64, each boundary face's smallest height (twice its area
        over its longest edge; 0 for a needle).
    origin : (3,) float64, the mesh's bounding-box centre.
    convex : the mesh fills a convex region (no ray enters twice).
    may_jump : some welded point's copies carry other float32 values (else no face jumps,
        and :func:`cell_records` does not look for jumps).
    """

    ids: NDArray[np.int32] | None
    boundary_slots: NDArray[np.int64]
    boundary_triangles: NDArray[np.float32]
    boundary_corners: NDArray[np.int64]
    boundary_edges: NDArray[np.int64]
    boundary_pairs: NDArray[np.int64]
    boundary_neighbors: NDArray[np.int32]
    boundary_planes: NDArray[np.float64]
    boundary_spheres: NDArray[np.float64]
    boundary_heights: NDArray[np.float64]
    origin: NDArray[np.float64]
    convex: bool
    may_jump: bool = False
    planes: NDArray[np.float32] | None = None
    scalar: NDArray[np.float32] | None = None
    links: NDArray[np.int32] | None = None

    @property
    def mates(self) -> NDArray[np.int32]:
        """(m, 4) int32, ``4 * neighbour + k`` across each face, -1 on the boundary (the
        links' first column)."""
        assert self.links is not None, "built with cells=False: see cell_records"
        return self.links[..., 0]

    @property
    def nbytes(self) -> int:
        return int(sum(f.nbytes for f in (getattr(self, d.name) for d in dataclasses.fields(self))
                       if isinstance(f, np.ndarray)))


def march_records(mesh: TetMesh, *, cells: bool = True) -> MarchRecords:
    """The records and boundary faces of ``mesh`` (the face adjacency is cached with the
    mesh's geometry, :func:`tetvr.mesh.adjacency.face_adjacency`); without the per-tet
    planes, scalars and links unless ``cells`` (:func:`cell_records` builds them in blocks).

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> rec = march_records(synthetic.two_tets())
    >>> rec.planes.shape, rec.ids.tolist(), rec.mates.tolist()
    ((2, 4, 4), [[0, 1, 2, 3], [0, 1, 2, 4]], [[-1, -1, -1, 7], [-1, -1, -1, 3]])
    """
    adj = face_adjacency(mesh)
    origin = np.asarray(adj.origin, dtype=np.float64)
    # The records list each tet's points in increasing welded id (slot k still opposite
    # face k), so the three points of a face come in the same order in both its tets.
    ids = np.empty((mesh.n_tets, 4), dtype=np.int32)
    for rows in blocks(mesh.n_tets):
        ids[rows] = np.take_along_axis(mesh.tets[rows], _slot_order(mesh.tets[rows], adj.canonical), axis=1)
    old_slots = np.asarray(adj.boundary_slots, dtype=np.int64)
    tets = mesh.tets[old_slots // 4]
    corners = tets[np.arange(old_slots.shape[0])[:, None], FACE_VERTICES[old_slots % 4]].astype(np.int64)
    # Wound counter-clockwise seen from outside (the GL's front face): entry passes cull the rest.
    tri = mesh.points[corners] - origin
    normals, offsets = adj.planes(old_slots)
    inward = np.einsum("ij,ij->i", np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), normals) < 0
    corners[inward] = corners[inward][:, [0, 2, 1]]
    tri[inward] = tri[inward][:, [0, 2, 1]]
    slots = 4 * (old_slots // 4) + _new_slot(tets, old_slots % 4, adj.canonical)
    a = corners if adj.canonical is None else adj.canonical[corners]
    b = np.roll(a, -1, axis=1)
    edge_keys = np.minimum(a, b).astype(np.int64) * mesh.n_points + np.maximum(a, b)
    pairs = _edge_pairs(edge_keys)
    planes = np.concatenate([normals, -offsets[:, None]], axis=1).astype(np.float32)  # as the records hold them
    centres = tri.mean(axis=1)
    radii = np.sqrt(((tri - centres[:, None]) ** 2).sum(axis=-1)).max(axis=1)
    spheres = np.concatenate([centres, radii[:, None] * (1 + 1e-6)], axis=1)
    edges = np.roll(tri, -1, axis=1) - tri
    longest = np.sqrt((edges ** 2).sum(axis=-1)).max(axis=1)
    area2 = np.sqrt((np.cross(edges[:, 0], edges[:, 1]) ** 2).sum(axis=-1))
    heights = np.divide(area2, longest, out=np.zeros_like(area2), where=longest > 0)
    rec = MarchRecords(ids=ids, boundary_slots=slots, boundary_triangles=tri.astype(np.float32),
                       boundary_corners=corners, boundary_edges=edge_keys, boundary_pairs=pairs,
                       boundary_neighbors=_neighbors(slots, pairs), boundary_planes=planes.astype(np.float64),
                       boundary_spheres=spheres, boundary_heights=heights, origin=origin, convex=bool(adj.convex),
                       may_jump=_may_jump(mesh, adj.canonical))
    if not cells:
        return rec
    texels = np.empty((mesh.n_tets, RECORD_TEXELS, 4), dtype=np.float32)
    links = np.empty((mesh.n_tets, 4, 4), dtype=np.int32)
    for rows in blocks(mesh.n_tets):
        texels[rows], links[rows] = cell_records(mesh, rec, rows)
    return dataclasses.replace(rec, planes=texels[:, :4], scalar=texels[:, 4], links=links)


def cell_records(mesh: TetMesh, rec: MarchRecords, rows: slice) -> tuple[NDArray[np.float32], NDArray[np.int32]]:
    """The per-tet records of tets ``rows`` of ``mesh`` (``rec``: its :func:`march_records`):
    (n, :data:`RECORD_TEXELS`, 4) float32, the four face planes and the scalar (``planes``
    and ``scalar``), and (n, 4, 4) int32 ``links``, in the slot order of ``rec.ids``."""
    assert rec.ids is not None, "the records' ids were dropped: build them again with march_records"
    adj = face_adjacency(mesh)
    tets = mesh.tets[rows]
    n = tets.shape[0]
    # Each record slot's slot in the adjacency (4 * t + k); then, across it, the adjacency's
    # slot of the face beyond and the record slot of that face in the tet beyond.
    old = (np.arange(rows.start, rows.stop)[:, None] * 4 + _slot_order(tets, adj.canonical)).reshape(-1)
    texels = np.empty((n, RECORD_TEXELS, 4), dtype=np.float32)
    normals, offsets = adj.planes(old)
    texels[:, :4, :3] = normals.reshape(n, 4, 3)
    texels[:, :4, 3] = -offsets.reshape(n, 4)
    texels[:, 4] = _scalar_records(mesh, rec.origin, rows)
    old_mates = adj.mates.reshape(-1)[old].astype(np.int64)
    inner = old_mates >= 0
    beyond = np.maximum(old_mates, 0)
    nbr = beyond >> 2
    mates = np.where(inner, 4 * nbr + _new_slot(mesh.tets[nbr], beyond & 3, adj.canonical), -1)
    links = np.zeros((n * 4, 4), dtype=np.int32)
    links[:, 0] = mates
    links[:, 1] = np.where(inner, mesh.tets.reshape(-1)[beyond], -1)  # the neighbour's point off the face
    # On the boundary the link's second column names the face's row of boundary_neighbors.
    tet_of = rec.boundary_slots >> 2
    first, last = np.searchsorted(tet_of, [rows.start, rows.stop])
    links[rec.boundary_slots[first:last] - 4 * rows.start, 1] = np.arange(first, last, dtype=np.int32)
    if mesh.cell_scalars is not None:
        links[:, 2] = np.where(inner, mesh.cell_scalars[nbr].astype(np.float32).view(np.int32), 0)
    elif rec.may_jump:
        links[:, 3] = _jumps(rec.ids, rows, mates, np.asarray(mesh.scalars, dtype=np.float32))
    return texels, links.reshape(n, 4, 4)


def _slot_order(tets: NDArray[np.int32], canonical: NDArray[np.int64] | None) -> NDArray[np.intp]:
    """(n, 4): each record slot's column in ``tets``, by increasing welded id."""
    return np.argsort(tets if canonical is None else canonical[tets], axis=1, kind="stable")


def _new_slot(tets: NDArray[np.int32], k: NDArray[np.int64], canonical: NDArray[np.int64] | None) -> NDArray[np.int64]:
    """The record slot of column ``k`` of each row of ``tets`` (:func:`_slot_order`'s inverse):
    the points before it by welded id, ties by column (a stable sort's order)."""
    welded = tets if canonical is None else canonical[tets]
    own = welded[np.arange(k.size), k][:, None]
    return np.count_nonzero((welded < own) | ((welded == own) & (np.arange(4) < k[:, None])), axis=1)


def _scalar_records(mesh: TetMesh, origin: NDArray[np.float64], rows: slice) -> NDArray[np.float32]:
    """(n, 4) float32, the field in each of tets ``rows`` as ``(g, c)`` with ``s(x) = g . x + c``."""
    tets = mesh.tets[rows]
    scalar = np.empty((tets.shape[0], 4), dtype=np.float32)
    if mesh.cell_scalars is not None:  # cell data: constant in each tet
        scalar[:, :3] = 0.0
        scalar[:, 3] = mesh.cell_scalars[rows]
        return scalar
    p0 = mesh.points[tets[:, 0]] - origin
    e1, e2, e3 = ((mesh.points[tets[:, k]] - origin) - p0 for k in (1, 2, 3))  # rows p_k - p_0
    ds = mesh.scalars[tets[:, 1:]] - mesh.scalars[tets[:, :1]]  # (n, 3)
    # grad . e_k = ds_k, by the inverse of the edge matrix (its columns the rows' crosses over
    # the determinant): 3x faster than a batched LAPACK solve. Zero-volume tets are dropped
    # on reading, so every determinant is non-zero.
    c1, c2, c3 = np.cross(e2, e3), np.cross(e3, e1), np.cross(e1, e2)
    grad = (ds[:, :1] * c1 + ds[:, 1:2] * c2 + ds[:, 2:] * c3) / np.einsum("ij,ij->i", e1, c1)[:, None]
    scalar[:, :3] = grad
    scalar[:, 3] = mesh.scalars[tets[:, 0]] - np.einsum("ij,ij->i", grad, p0)
    return scalar


def _may_jump(mesh: TetMesh, canonical: NDArray[np.int64] | None) -> bool:
    """Whether the point field may jump at a face: some welded point's copies carry other
    values (float32, as the GPU reads them); never with cell data."""
    if canonical is None or mesh.cell_scalars is not None:
        return False
    values = np.asarray(mesh.scalars, dtype=np.float32)
    return bool(np.any(values[canonical] != values))


def _jumps(ids: NDArray[np.int32], rows: slice, mates: NDArray[np.int64], scalars: NDArray[np.float32]) -> NDArray[np.int32]:
    """(4n,) int32: 1 across the faces of tets ``rows`` whose points carry other values in
    the tet beyond (duplicated nodes of two regions), as the GPU reads them (float32)."""
    faces = scalars[ids[rows][:, FACE_VERTICES]].reshape(-1, 3)  # (4n, 3), in the records' slot order
    beyond = np.maximum(mates, 0)
    other = scalars[ids[(beyond >> 2)[:, None], FACE_VERTICES[beyond & 3]]]  # the same faces, seen from beyond
    return ((mates >= 0) & np.any(faces != other, axis=1)).astype(np.int32)


def _neighbors(slots: NDArray[np.int64], pairs: NDArray[np.int64]) -> NDArray[np.int32]:
    """(F, 4) int32: the slots of up to four boundary faces sharing an edge with each, -1 after."""
    out = np.full((slots.size, 4), -1, dtype=np.int32)
    if pairs.size == 0:
        return out
    face = np.concatenate([pairs[:, 0], pairs[:, 1]])
    other = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.argsort(face, kind="stable")
    face, other = face[order], other[order]
    start = np.searchsorted(face, face, side="left")
    rank = np.arange(face.size) - start
    keep = rank < 4  # a non-manifold edge can give a face more: the first four
    out[face[keep], rank[keep]] = slots[other[keep]].astype(np.int32)
    return out


def _edge_pairs(edge_keys: NDArray[np.int64]) -> NDArray[np.int64]:
    """The pairs of faces (rows of ``edge_keys``) that share an edge key: each pair once."""
    flat = edge_keys.reshape(-1)
    order = np.argsort(flat, kind="stable")
    keys, faces = flat[order], order // 3
    starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    lengths = np.diff(np.r_[starts, keys.size])
    pairs = [np.stack([faces[starts[lengths >= 2]], faces[starts[lengths >= 2] + 1]], axis=1)]
    for start, n in zip(starts[lengths > 2], lengths[lengths > 2]):  # non-manifold edges: every pair
        i, j = np.triu_indices(int(n), 1)  # (0, 1) first, which is in already
        pairs.append(np.stack([faces[start + i[1:]], faces[start + j[1:]]], axis=1))
    return np.concatenate(pairs).astype(np.int64)


def _grow(mask: NDArray[np.bool_], pairs: NDArray[np.int64]) -> NDArray[np.bool_]:
    """``mask`` and every face sharing an edge with a face in it."""
    out = mask.copy()
    out[pairs[mask[pairs[:, 1]], 0]] = True
    out[pairs[mask[pairs[:, 0]], 1]] = True
    return out


def folded_faces(mesh: TetMesh) -> int:
    """How many interior faces are folded: the two tets sharing the face lie on the same
    side of it (a tangled mesh, e.g. inverted elements, whose cells overlap in space).

    A ray walking through a folded face goes into a cell that does not continue the ray's
    path, so tet marching cannot render such a mesh; projected tetrahedra draw every cell
    and integrate the overlaps as the reference does. Cached with the face adjacency.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> folded_faces(synthetic.cube(3))
    0
    """
    adj = face_adjacency(mesh)
    cached = _FOLDS.get(id(adj))
    if cached is not None and cached[0]() is adj:
        return cached[1]
    mates = adj.mates.reshape(-1)
    mirrored = adj.mirrored.reshape(-1)
    n = 0
    for rows in blocks(mesh.n_tets):
        # Each interior face once, where its plane is its own tet's (the copy across it
        # takes that plane negated, which the far vertex of its mate always lies ahead of).
        slots = np.arange(4 * rows.start, 4 * rows.stop)
        slots = slots[(mates[slots] >= 0) & ~mirrored[slots]]
        mate = mates[slots]
        other = mesh.points[mesh.tets[mate // 4, mate % 4]] - adj.origin  # the mate's vertex off the face
        normals, offsets = adj.planes(slots)
        side = np.einsum("ij,ij->i", normals, other) - offsets
        # Outward from the slot's tet, so the mate's far vertex must be ahead of the plane; allow rounding.
        n += int(np.count_nonzero(side <= -1e-12 * adj.radius))
    _FOLDS.clear()
    _FOLDS[id(adj)] = (weakref.ref(adj), n)
    return n


_FOLDS: dict[int, tuple[weakref.ref[object], int]] = {}  # the last adjacency, held weakly, and its count


def near_plane_cells(mesh: TetMesh, camera: Camera, aspect: float) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """The tets the near plane cuts, and the NDC rectangle their cut projects to.

    Returns ``(ids, rects)``: ``rects[i] = (x_lo, y_lo, x_hi, y_hi)`` bounds the polygon
    where tet ``ids[i]`` meets the near plane (clamped to the viewport). A ray's point on
    the near plane lies in one of these tets exactly when the ray starts inside the mesh.
    """
    camera = resolve_clipping_range(camera, mesh.bounds)
    near = camera.near_far()[0]
    view = camera.view_matrix()
    depth = -(mesh.points @ view[2, :3] + view[2, 3])
    if not depth.min() < near <= depth.max():
        return np.empty(0, dtype=np.int64), np.empty((0, 4))
    d = depth[mesh.tets]
    ids = np.flatnonzero((d.min(axis=1) < near) & (d.max(axis=1) >= near))
    if ids.size == 0:
        return ids.astype(np.int64), np.empty((0, 4))
    eye = mesh.points[mesh.tets[ids]] @ view[:3, :3].T + view[:3, 3]  # (n, 4, 3)
    dd = d[ids] - near
    proj = camera.projection_matrix(aspect)
    lo = np.full((ids.size, 2), np.inf)
    hi = np.full((ids.size, 2), -np.inf)
    for a in range(4):
        for b in range(a + 1, 4):
            cross = (dd[:, a] < 0) != (dd[:, b] < 0)
            f = np.where(cross, dd[:, a] / np.where(cross, dd[:, a] - dd[:, b], 1.0), 0.0)
            q = eye[:, a] + f[:, None] * (eye[:, b] - eye[:, a])  # on the near plane
            clip = q @ proj[:, :3].T + proj[:, 3]
            with np.errstate(divide="ignore", invalid="ignore"):  # rows without a crossing
                ndc = clip[:, :2] / np.where(cross, clip[:, 3], 1.0)[:, None]
            lo = np.where(cross[:, None], np.minimum(lo, ndc), lo)
            hi = np.where(cross[:, None], np.maximum(hi, ndc), hi)
    rects = np.clip(np.concatenate([lo, hi], axis=1), -1.0, 1.0)
    return ids.astype(np.int64), rects


def _projected(tri: NDArray[np.float32], origin: NDArray[np.float64], camera: Camera, view: NDArray[np.float64],
               proj: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Triangles' corners (object coordinates less ``origin``) in NDC, and which
    triangles lie wholly ahead of the near plane (the others' NDC mean nothing)."""
    eye = (tri.astype(np.float64) + origin) @ view[:3, :3].T + view[:3, 3]  # (n, 3, 3)
    if camera.parallel_projection:
        ahead = np.ones(len(tri), dtype=bool)
    else:
        ahead = (-eye[..., 2]).min(axis=1) > camera.near_far()[0]
    with np.errstate(divide="ignore", invalid="ignore"):
        ndc = (eye @ proj[:2, :3].T + proj[:2, 3]) / (eye @ proj[3, :3] + proj[3, 3])[..., None]
    return ndc, ahead


def _thin(ndc: NDArray[np.float64], ahead: NDArray[np.bool_], size: tuple[int, int]) -> NDArray[np.bool_]:
    """Which triangles (corners in NDC) project thinner than :data:`THIN_PIXELS`: twice
    their area over their longest edge, in pixels. Triangles reaching behind the near
    plane are not (the rasteriser keeps them, :func:`rim_faces`)."""
    pix = ndc * (0.5 * np.array(size, dtype=np.float64))
    e0, e1, e2 = pix[:, 1] - pix[:, 0], pix[:, 2] - pix[:, 0], pix[:, 2] - pix[:, 1]
    area2 = np.abs(e0[:, 0] * e1[:, 1] - e0[:, 1] * e1[:, 0])
    longest = np.sqrt(np.maximum(np.maximum((e0 ** 2).sum(axis=1), (e1 ** 2).sum(axis=1)), (e2 ** 2).sum(axis=1)))
    with np.errstate(invalid="ignore"):
        return ahead & (area2 < THIN_PIXELS * longest)


def rim_faces(rec: MarchRecords, camera: Camera, size: tuple[int, int]
              ) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.bool_]]:
    """The boundary faces whose entries are decided exactly in this view, the NDC
    rectangle each is drawn as (one pixel wider than its projection on every side), and
    which of them the rasteriser leaves out.

    A face seen edge-on (its plane through the eye, or along the view direction in
    parallel projection) lets rays run along it, so a ray a thousandth of a pixel inside
    the mesh next to it crosses a long chord while one just outside crosses nothing. The
    rasteriser decides which pixel centres a face covers after snapping its corners to
    1/256 pixel, so there it can drop a ray that enters or take one that does not. The
    faces the rays meet at a sine below :data:`EDGE_ON_SINE`, those projecting thinner
    than :data:`THIN_PIXELS` (needles, whose plane says little), and every boundary face
    sharing an edge with one (the *core*) are therefore entered only where the pixel's
    ray, in float64, meets the triangle itself (march_entry.frag, RIM 1), as the
    reference decides. The faces around the core are tested exactly as well as
    rasterised, so that the exact and the rasterised coverage meet without a crack: a
    ray near an edge between the core and the rest is decided exactly on both sides.
    Faces reaching behind the near plane cannot be drawn as rectangles; they stay with
    the rasteriser, and so do their neighbours.

    Returns ``(indices, rects, exclusive)``: indices into ``rec.boundary_slots``,
    ``rects[i] = (x_lo, y_lo, x_hi, y_hi)`` in NDC clamped to the viewport, and whether
    the rasteriser leaves face ``indices[i]`` out.
    """
    width, height = size
    planes = rec.boundary_planes
    tri = rec.boundary_triangles
    if camera.clipping_range is None:  # from the data: the boundary's corners bound the mesh
        corners = tri.reshape(-1, 3).astype(np.float64) + rec.origin
        camera = resolve_clipping_range(camera, corners if len(corners) else rec.origin[None])
    view = camera.view_matrix()
    proj = camera.projection_matrix(width / height)
    if camera.parallel_projection:
        edge_on = np.abs(planes[:, :3] @ view[2, :3]) < EDGE_ON_SINE
    else:
        eye = np.asarray(camera.position, dtype=np.float64) - rec.origin
        distance = np.abs(planes[:, :3] @ eye + planes[:, 3])  # the eye's distance to each plane
        # The sine at the face's nearest corner: only where a sphere round the face could
        # allow it below EDGE_ON_SINE is that corner found.
        sphere = rec.boundary_spheres
        far = np.sqrt(((sphere[:, :3] - eye) ** 2).sum(axis=1)) + sphere[:, 3]
        edge_on = np.zeros(planes.shape[0], dtype=bool)
        maybe = np.flatnonzero(distance < EDGE_ON_SINE * far)
        nearest = np.sqrt(((tri[maybe] - eye.astype(np.float32)) ** 2).sum(axis=-1).min(axis=1)).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            edge_on[maybe] = distance[maybe] / nearest < EDGE_ON_SINE
    # Thin in projection: where the face's smallest height, times a lower bound on how the
    # view scales lengths across the face (its sine over its depth, perspective), is not
    # far above THIN_PIXELS, the projection itself is measured.
    px_per_unit = 0.5 * min(proj[0, 0] * width, proj[1, 1] * height)
    if camera.parallel_projection:
        shrink = np.abs(planes[:, :3] @ view[2, :3])
    else:
        shrink = distance / far ** 2
    maybe = np.flatnonzero(rec.boundary_heights * shrink * px_per_unit < 4.0 * THIN_PIXELS)
    edge_on[maybe[_thin(*_projected(tri[maybe], rec.origin, camera, view, proj), size)]] = True
    if not edge_on.any():
        return np.empty(0, dtype=np.int64), np.empty((0, 4)), np.empty(0, dtype=bool)
    pairs = rec.boundary_pairs
    core = _grow(edge_on, pairs)
    idx = np.flatnonzero(_grow(core, pairs))
    ndc, ahead = _projected(tri[idx], rec.origin, camera, view, proj)
    exclusive = core[idx] & ahead
    if not ahead.all():  # a face left to the rasteriser keeps its neighbours with it
        behind = np.zeros(planes.shape[0], dtype=bool)
        behind[idx[~ahead]] = True
        exclusive &= ~_grow(behind, pairs)[idx]
    idx, ndc, exclusive = idx[ahead], ndc[ahead], exclusive[ahead]
    pad = np.array([2.0 / width, 2.0 / height])
    rects = np.concatenate([ndc.min(axis=1) - pad, ndc.max(axis=1) + pad], axis=1)
    keep = (rects[:, 0] < 1) & (rects[:, 1] < 1) & (rects[:, 2] > -1) & (rects[:, 3] > -1)
    return idx[keep].astype(np.int64), np.clip(rects[keep], -1.0, 1.0), exclusive[keep]

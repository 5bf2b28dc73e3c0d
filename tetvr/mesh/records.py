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

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh.adjacency import FACE_VERTICES, face_adjacency
from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["MarchRecords", "march_records", "near_plane_cells", "rim_faces", "folded_faces", "RECORD_TEXELS"]

#: Texels of one tet's record in the float texture: four face planes, then the scalar.
RECORD_TEXELS = 5
#: A boundary face counts as seen edge-on (:func:`rim_faces`) where the rays meet its plane
#: at a sine below this: a ray the rasteriser drops within 1/256 pixel of its edge would
#: cross less than a quarter of a pixel's footprint before leaving through that plane
#: at any larger sine.
EDGE_ON_SINE = 1.0 / 64.0


@dataclasses.dataclass(frozen=True, eq=False)
class MarchRecords:
    """What the walk reads per tet (see the module docstring).

    Attributes
    ----------
    planes : (m, 4, 4) float32, face ``k`` of tet ``t``: ``(n, w)`` with ``n . x + w``
        negative inside (``x`` relative to ``origin``).
    scalar : (m, 4) float32, ``(g, c)`` with ``s(x) = g . x + c``.
    ids : (m, 4) int32, each tet's point ids in increasing welded id: slot ``k`` of every
        record is this point (face ``k`` is opposite it), so the three points of a face are
        in the same order in both its tets, also where each holds its own copy of them.
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
    origin : (3,) float64, the mesh's bounding-box centre.
    convex : the mesh fills a convex region (no ray enters twice).
    """

    planes: NDArray[np.float32]
    scalar: NDArray[np.float32]
    ids: NDArray[np.int32]
    links: NDArray[np.int32]
    boundary_slots: NDArray[np.int64]
    boundary_triangles: NDArray[np.float32]
    boundary_corners: NDArray[np.int64]
    boundary_edges: NDArray[np.int64]
    boundary_pairs: NDArray[np.int64]
    boundary_neighbors: NDArray[np.int32]
    boundary_planes: NDArray[np.float64]
    boundary_spheres: NDArray[np.float64]
    origin: NDArray[np.float64]
    convex: bool

    @property
    def mates(self) -> NDArray[np.int32]:
        """(m, 4) int32, ``4 * neighbour + k`` across each face, -1 on the boundary (the
        links' first column)."""
        return self.links[..., 0]

    @property
    def nbytes(self) -> int:
        return int(sum(f.nbytes for f in (getattr(self, d.name) for d in dataclasses.fields(self))
                       if isinstance(f, np.ndarray)))


def march_records(mesh: TetMesh) -> MarchRecords:
    """The per-tet records and boundary faces of ``mesh`` (the face adjacency is cached
    with the mesh's geometry, :func:`tetvr.mesh.adjacency.face_adjacency`).

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> rec = march_records(synthetic.two_tets())
    >>> rec.planes.shape, rec.ids.tolist(), rec.mates.tolist()
    ((2, 4, 4), [[0, 1, 2, 3], [0, 1, 2, 4]], [[-1, -1, -1, 7], [-1, -1, -1, 3]])
    """
    adj = face_adjacency(mesh)
    origin = np.asarray(adj.origin, dtype=np.float64)
    planes = np.empty((mesh.n_tets, 4, 4), dtype=np.float32)
    planes[..., :3] = adj.normals
    planes[..., 3] = -adj.offsets
    rel = mesh.points - origin
    tets = np.asarray(mesh.tets, dtype=np.intp)
    p0 = rel[tets[:, 0]]
    edges = rel[tets[:, 1:]] - p0[:, None, :]  # (m, 3, 3), rows p_k - p_0
    scalar = np.empty((mesh.n_tets, 4), dtype=np.float32)
    if mesh.cell_scalars is None:
        ds = mesh.scalars[tets[:, 1:]] - mesh.scalars[tets[:, :1]]  # (m, 3)
        # Zero-volume tets are dropped on reading, so every edge matrix is invertible.
        grad = np.linalg.solve(edges, ds[..., None])[..., 0]
        scalar[:, :3] = grad
        scalar[:, 3] = mesh.scalars[tets[:, 0]] - np.einsum("ij,ij->i", grad, p0)
    else:  # cell data: constant in each tet
        scalar[:, :3] = 0.0
        scalar[:, 3] = mesh.cell_scalars
    slots = np.asarray(adj.boundary_slots, dtype=np.int64)
    corners = tets[slots // 4][np.arange(slots.shape[0])[:, None], FACE_VERTICES[slots % 4]]
    # The records list each tet's points in increasing welded id (slot k still opposite
    # face k), so the three points of a face come in the same order in both its tets.
    welded = tets if adj.canonical is None else adj.canonical[tets]
    order = np.argsort(welded, axis=1, kind="stable")
    new_slot = np.argsort(order, axis=1).reshape(-1)  # the inverse permutation, by flat slot
    flat = (np.arange(mesh.n_tets)[:, None] * 4 + order).reshape(-1)  # new flat slot -> old
    ids = tets.reshape(-1)[flat].reshape(-1, 4)
    planes = planes.reshape(-1, 4)[flat].reshape(-1, 4, 4)
    old_mates = np.asarray(adj.mates, dtype=np.int64).reshape(-1)[flat]
    inner = old_mates >= 0
    mates = np.where(inner, (old_mates & ~3) + new_slot[np.maximum(old_mates, 0)], -1)
    links = np.zeros((mesh.n_tets, 4, 4), dtype=np.int32)
    links[..., 0] = mates.reshape(-1, 4)
    links[..., 1] = np.where(inner, ids.reshape(-1)[np.maximum(mates, 0)], -1).reshape(-1, 4)
    nbr = (np.maximum(mates, 0) >> 2).reshape(-1, 4)
    inner = inner.reshape(-1, 4)
    if mesh.cell_scalars is not None:
        cell = np.asarray(mesh.cell_scalars, dtype=np.float32).view(np.int32)
        links[..., 2] = np.where(inner, cell[nbr], 0)
    elif adj.canonical is not None:
        links[..., 3] = _jumps(ids, mates, np.asarray(mesh.scalars, dtype=np.float32))
    # Wound counter-clockwise seen from outside (the GL's front face): entry passes cull the rest.
    tri = rel[corners]
    inward = np.einsum("ij,ij->i", np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                       adj.normals[slots // 4, slots % 4]) < 0
    corners[inward] = corners[inward][:, [0, 2, 1]]
    tri[inward] = tri[inward][:, [0, 2, 1]]
    slots = 4 * (slots // 4) + new_slot[slots]
    a = corners if adj.canonical is None else adj.canonical[corners]
    b = np.roll(a, -1, axis=1)
    edge_keys = np.minimum(a, b).astype(np.int64) * mesh.n_points + np.maximum(a, b)
    pairs = _edge_pairs(edge_keys)
    # On the boundary the link's second column names the face's row of boundary_neighbors.
    links.reshape(-1, 4)[slots, 1] = np.arange(slots.size, dtype=np.int32)
    centres = tri.astype(np.float64).mean(axis=1)
    radii = np.sqrt(((tri - centres[:, None]) ** 2).sum(axis=-1)).max(axis=1)
    spheres = np.concatenate([centres, radii[:, None] * (1 + 1e-6)], axis=1)
    return MarchRecords(planes=planes, scalar=scalar, ids=ids.astype(np.int32), links=links, boundary_slots=slots,
                        boundary_triangles=tri.astype(np.float32), boundary_corners=corners.astype(np.int64),
                        boundary_edges=edge_keys, boundary_pairs=pairs,
                        boundary_neighbors=_neighbors(slots, pairs),
                        boundary_planes=planes[slots // 4, slots % 4].astype(np.float64), boundary_spheres=spheres,
                        origin=origin,
                        convex=bool(adj.convex))


def _jumps(ids: NDArray[np.intp], mates: NDArray[np.int64], scalars: NDArray[np.float32]) -> NDArray[np.int32]:
    """(m, 4) int32: 1 across the faces whose points carry other values in the tet beyond
    (duplicated nodes of two regions), as the GPU reads them (float32)."""
    faces = scalars[ids[:, FACE_VERTICES]].reshape(-1, 3)  # (4m, 3), in the records' slot order
    inner = mates >= 0
    other = faces[np.maximum(mates, 0)]
    return (inner & np.any(faces != other, axis=1)).astype(np.int32).reshape(-1, 4)


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
    if cached is not None and cached[0] is adj:
        return cached[1]
    t, k = np.nonzero(adj.mates >= 0)
    mate = adj.mates[t, k]
    other = mesh.points[mesh.tets[mate // 4, mate % 4]] - adj.origin  # the mate's vertex off the face
    side = np.einsum("ij,ij->i", adj.normals[t, k], other) - adj.offsets[t, k]
    # Outward from t, so the mate's far vertex must be ahead of the plane; allow rounding.
    n = int(np.count_nonzero(side <= -1e-12 * adj.radius)) // 2
    _FOLDS.clear()
    _FOLDS[id(adj)] = (adj, n)
    return n


_FOLDS: dict[int, tuple[object, int]] = {}


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
    faces the rays meet at a sine below :data:`EDGE_ON_SINE` and every boundary face
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
    if not edge_on.any():
        return np.empty(0, dtype=np.int64), np.empty((0, 4)), np.empty(0, dtype=bool)
    pairs = rec.boundary_pairs
    core = _grow(edge_on, pairs)
    idx = np.flatnonzero(_grow(core, pairs))
    eye_pts = (tri[idx].astype(np.float64) + rec.origin) @ view[:3, :3].T + view[:3, 3]
    if camera.parallel_projection:
        ahead = np.ones(idx.size, dtype=bool)
    else:
        ahead = (-eye_pts[..., 2]).min(axis=1) > camera.near_far()[0]
    exclusive = core[idx] & ahead
    if not ahead.all():  # a face left to the rasteriser keeps its neighbours with it
        behind = np.zeros(planes.shape[0], dtype=bool)
        behind[idx[~ahead]] = True
        exclusive &= ~_grow(behind, pairs)[idx]
    idx, eye_pts, exclusive = idx[ahead], eye_pts[ahead], exclusive[ahead]
    proj = camera.projection_matrix(width / height)
    ndc = (eye_pts @ proj[:2, :3].T + proj[:2, 3]) / (eye_pts @ proj[3, :3] + proj[3, 3])[..., None]
    pad = np.array([2.0 / width, 2.0 / height])
    rects = np.concatenate([ndc.min(axis=1) - pad, ndc.max(axis=1) + pad], axis=1)
    keep = (rects[:, 0] < 1) & (rects[:, 1] < 1) & (rects[:, 2] > -1) & (rects[:, 3] > -1)
    return idx[keep].astype(np.int64), np.clip(rects[keep], -1.0, 1.0), exclusive[keep]

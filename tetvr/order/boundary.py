"""Ordering constraints between cells that share no face, from rays through the boundary.

About this technique
--------------------
MPVO orders two cells only when they share a face. Across a gap, a cavity or between two
separate parts of a mesh, nothing in the face graph says which cell is in front, and
Williams' MPVONC heuristic falls back on depth, which fails for interlocking parts: a
ring's far side can be nearer than the centroid of the ring it passes behind.

XMPVO (Silva, Mitchell & Williams, "An exact interactive time visibility ordering
algorithm for polyhedral cell complexes", IEEE VolVis 1998) closes that gap by casting
rays against the boundary faces only. Along one ray the boundary hits alternate between
entering the mesh (a front-facing boundary face) and leaving it (a back-facing one). Where
the ray leaves through the back face of cell ``a`` and next enters through the front face
of cell ``b``, ``b`` lies behind ``a`` on that ray, so ``b`` must be drawn first: one more
edge of the visibility graph, added to the face edges of :mod:`tetvr.order.sort`. With an edge
for every such pair on every pixel's ray, MPVO's topological sort becomes exact for any
acyclic mesh, convex or not.

Here the rays are a ``grid x grid`` lattice of sample points over the projected boundary
(not the image's pixels: the sort does not know the image size; by default the lattice
grows with the number of boundary faces, see :func:`default_grid`), and the boundary faces
are scan-converted onto it in numpy: each face, row by lattice row, gives the span of
lattice columns inside its three edges, and records the depth of its plane at each of
them. Rays that cannot leave and re-enter (fewer than two entries or exits) are dropped,
and one sort by (ray, depth) lines up the remaining rays' hits. A pair of parts
that overlap on screen only between lattice points gets no edge and keeps the depth
heuristic, so the lattice should be finer than the smallest gap that matters.

Faces that reach behind the eye plane (the camera inside or beside the mesh) cannot be
projected and are skipped, as are faces seen edge-on; both are counted. The rays are
in front of the eye only, so the order behind the eye is the heuristic's.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh.adjacency import FaceAdjacency, face_adjacency
from tetvr.core.camera import Camera
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["BoundaryConstraints", "boundary_constraints", "default_grid"]


def default_grid(n_boundary_faces: int) -> int:
    """Lattice points per side for a mesh with this many boundary faces: about 16 rays
    per boundary face over the whole lattice, at least 64 and at most 256 per side.

    A coarse mesh needs few rays (its parts overlap in large regions); 256 x 256 rays
    resolve gaps down to about 1/256 of the mesh's screen extent and cost ~7 ms.

    >>> default_grid(100), default_grid(1_728), default_grid(50_000)
    (64, 166, 256)
    """
    return int(min(max(round(math.sqrt(16.0 * n_boundary_faces)), 64), 256))


@dataclasses.dataclass(frozen=True)
class BoundaryConstraints:
    """Edges "draw ``behind[i]`` before ``front[i]``" found by rays through the boundary.

    Attributes
    ----------
    behind, front : (e,) int64 cell ids, unique pairs, ``behind != front``.
    n_faces : boundary faces rasterised (front- or back-facing, in front of the eye).
    n_skipped : boundary faces skipped: edge-on, or reaching behind the eye plane.
    n_hits : ray-face hits found.
    grid : lattice points per side.
    """

    behind: NDArray[np.int64]
    front: NDArray[np.int64]
    n_faces: int
    n_skipped: int
    n_hits: int
    grid: int


def boundary_constraints(mesh: TetMesh, camera: Camera, *, grid: int | None = None) -> BoundaryConstraints:
    """Ordering edges between cells that a ray leaves and next enters through the boundary.

    Parameters
    ----------
    mesh : the mesh; its face adjacency is built once and cached.
    camera : eye point (perspective) or view direction (parallel) of the view.
    grid : lattice points per side of the ray grid (>= 2); by default
        :func:`default_grid` of the mesh's boundary faces.

    Examples
    --------
    Two separate tets, one behind the other along the view axis:

    >>> from tetvr import TetMesh
    >>> from tetvr.mesh import synthetic
    >>> a = synthetic.single_tet()
    >>> b = synthetic.merge(a, TetMesh.from_arrays(a.points - (0.0, 0.0, 2.0), a.tets, a.scalars))
    >>> cam = Camera(position=(0.3, 0.3, 5.0), focal_point=(0.3, 0.3, 0.0))
    >>> c = boundary_constraints(b, cam, grid=32)
    >>> [(int(x), int(y)) for x, y in zip(c.behind, c.front)]  # cell 1 (farther) first
    [(1, 0)]
    """
    adj = face_adjacency(mesh)
    if grid is None:
        grid = default_grid(adj.n_boundary_faces)
    if not (isinstance(grid, (int, np.integer)) and not isinstance(grid, bool) and grid >= 2):
        raise ValueError(f"grid must be an integer >= 2, got {grid!r}")
    grid = int(grid)
    p, n, c, cells, entering, n_skipped = _eye_faces(mesh, camera, adj)
    empty = np.empty(0, dtype=np.int64)
    if cells.size == 0:
        return BoundaryConstraints(empty, empty, 0, n_skipped, 0, grid)
    face, ray, depth = _lattice_hits(p, n, c, camera, grid)
    n_hits = int(ray.size)
    if n_hits == 0:
        return BoundaryConstraints(empty, empty, int(cells.size), n_skipped, 0, grid)
    behind, front = _ray_pairs(ray, depth, face, entering, cells, grid, mesh.n_tets)
    return BoundaryConstraints(behind, front, int(cells.size), n_skipped, n_hits, grid)


def _eye_faces(mesh: TetMesh, camera: Camera, adj: FaceAdjacency) -> tuple[
        NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_], int]:
    """The boundary faces that can be projected, in eye space: corners (F, 3, 3), outward
    normals, plane offsets, cells, and whether each faces the eye; and how many were skipped."""
    slots = adj.boundary_slots
    cells = slots >> 2
    verts = adj.boundary_faces

    # Eye space: camera at the origin looking down -z. The outward unit normals are the
    # face adjacency's, turned into eye space.
    view = camera.view_matrix()
    eye_pts = mesh.points @ view[:3, :3].T + view[:3, 3]
    p = eye_pts[verts]  # (F, 3, 3)
    n = adj.planes(slots)[0] @ view[:3, :3].T  # the boundary's planes only (not all of normals)
    c = np.einsum("ij,ij->i", n, p[:, 0])  # plane: n . x = c
    if camera.parallel_projection:
        facing = n[:, 2]  # > 0: the outward normal points at the eye (toward +z)
        ok = np.abs(facing) > 1e-9
    else:
        facing = -c  # n . (eye - x) with the eye at the origin
        near = -p[:, :, 2].max(axis=1)  # smallest depth of the face's vertices
        ok = (np.abs(facing) > 1e-9 * (np.abs(p).max(axis=(1, 2)) + 1e-300)) & (near > 1e-9 * np.abs(p).max(initial=0.0))
    n_skipped = int(np.count_nonzero(~ok))
    p, n, c, cells, entering = p[ok], n[ok], c[ok], cells[ok], facing[ok] > 0
    return p, n, c, cells, entering, n_skipped


def _lattice_hits(p: NDArray[np.float64], n: NDArray[np.float64], c: NDArray[np.float64], camera: Camera,
                  grid: int) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """The faces scan-converted onto the ``grid x grid`` ray lattice: for each hit, the face,
    the ray (``row * grid + column``) and the depth of the face's plane along it."""
    # Screen coordinates: x/depth, y/depth in perspective; x, y in parallel.
    if camera.parallel_projection:
        xy = p[:, :, :2]
        half = camera.parallel_scale
    else:
        xy = p[:, :, :2] / -p[:, :, 2:3]
        half = math.tan(math.radians(camera.view_angle) / 2)
    # The lattice spans the projected boundary, cut to a window wide enough for any
    # aspect ratio up to 4:1 around the view.
    lo = np.maximum(xy.reshape(-1, 2).min(axis=0), -4.0 * half)
    hi = np.minimum(xy.reshape(-1, 2).max(axis=0), 4.0 * half)
    if not np.all(hi > lo):
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64), np.empty(0)
    step = (hi - lo) / grid
    # Lattice units: lattice point (i, j) sits at lo + (i + 0.5, j + 0.5) * step.
    g = (xy - lo) / step - 0.5
    j0 = np.clip(np.ceil(g[:, :, 1].min(axis=1)), 0, grid).astype(np.int64)
    j1 = np.clip(np.floor(g[:, :, 1].max(axis=1)), -1, grid - 1).astype(np.int64)
    # Each face's edges as half-planes a * i + b * j + e >= 0 (inside, either winding).
    ga, gb = g, np.roll(g, -1, axis=1)
    a = -(gb[:, :, 1] - ga[:, :, 1])
    b = gb[:, :, 0] - ga[:, :, 0]
    e = -(a * ga[:, :, 0] + b * ga[:, :, 1])
    # Orient them so that the third vertex of edge 0 (hence the inside) is on the + side.
    orient = np.where(a[:, 0] * g[:, 2, 0] + b[:, 0] * g[:, 2, 1] + e[:, 0] >= 0, 1.0, -1.0)[:, None]
    a, b, e = a * orient, b * orient, e * orient

    # Scanlines: one (face, row) pair per lattice row a face spans; its span of lattice
    # columns is where all three half-planes hold.
    rows = np.maximum(j1 - j0 + 1, 0)
    fr_face = np.repeat(np.arange(p.shape[0]), rows)
    fr_j = (j0[fr_face] + np.arange(fr_face.size) - np.repeat(np.cumsum(rows) - rows, rows)).astype(np.float64)
    i_lo = np.zeros(fr_face.size)
    i_hi = np.full(fr_face.size, grid - 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        for u in range(3):
            au, rest = a[fr_face, u], b[fr_face, u] * fr_j + e[fr_face, u]
            bound = -rest / au
            i_lo = np.where(au > 0, np.maximum(i_lo, bound), i_lo)
            i_hi = np.where(au < 0, np.minimum(i_hi, bound), i_hi)
            # An edge parallel to the rows: the whole row is in or out.
            i_hi = np.where((au == 0) & (rest < 0), -1.0, i_hi)
    i_lo = np.ceil(i_lo).astype(np.int64)
    i_hi = np.floor(i_hi).astype(np.int64)
    span = np.maximum(i_hi - i_lo + 1, 0)

    face = np.repeat(fr_face, span)
    gj = np.repeat(fr_j.astype(np.int64), span)
    gi = np.repeat(i_lo, span) + np.arange(face.size) - np.repeat(np.cumsum(span) - span, span)
    sx = lo[0] + (gi + 0.5) * step[0]
    sy = lo[1] + (gj + 0.5) * step[1]
    nf = n[face]
    if camera.parallel_projection:
        # Ray (sx, sy, 0) + t (0, 0, -1): depth t.
        depth = (nf[:, 0] * sx + nf[:, 1] * sy - c[face]) / nf[:, 2]
    else:
        # Ray t (sx, sy, -1): depth t.
        depth = c[face] / (nf[:, 0] * sx + nf[:, 1] * sy - nf[:, 2])
    ray = gj * grid + gi
    return face, ray, depth


def _ray_pairs(ray: NDArray[np.int64], depth: NDArray[np.float64], face: NDArray[np.int64],
               entering: NDArray[np.bool_], cells: NDArray[np.int64], grid: int,
               n_tets: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The unique (behind, front) cell pairs where a ray leaves the mesh through ``front``'s
    face and next enters it through ``behind``'s, further along."""
    # Only rays that can leave and enter again need sorting: two or more entries or
    # exits, or one exit nearer than the one entry (the eye inside a cavity).
    into = entering[face]
    n_in = np.bincount(ray, weights=into, minlength=grid * grid)
    n_out = np.bincount(ray, weights=~into, minlength=grid * grid)
    d_in = np.bincount(ray, weights=np.where(into, depth, 0.0), minlength=grid * grid)
    d_out = np.bincount(ray, weights=np.where(into, 0.0, depth), minlength=grid * grid)
    busy = (n_in >= 2) | (n_out >= 2) | ((n_in == 1) & (n_out == 1) & (d_out < d_in))
    sel = busy[ray]
    ray, depth, face = ray[sel], depth[sel], face[sel]
    if ray.size < 2:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    # One sort by (ray, depth): the depth's float32 bits, made >= 0, order like its values.
    d32 = (depth - depth.min()).astype(np.float32)
    order = np.argsort((ray.astype(np.uint64) << np.uint64(32)) | d32.view(np.uint32).astype(np.uint64))
    ray, depth, face = ray[order], depth[order], face[order]
    # Leave through cell a, next enter through cell b further along the same ray.
    pair = (ray[1:] == ray[:-1]) & ~entering[face[:-1]] & entering[face[1:]] & (depth[1:] > depth[:-1])
    front = cells[face[:-1][pair]]
    behind = cells[face[1:][pair]]
    keep = front != behind
    key = np.unique(behind[keep].astype(np.int64) * n_tets + front[keep])
    return key // n_tets, key % n_tets

"""Whether tet marching can walk a mesh: what the mesh is, found once and cached with it.

About this technique
--------------------
The ray caster (:mod:`tetvr.mesh.records`, ``shaders/march.frag``) follows each ray from a
cell to the one across the face it leaves by, and composites one segment per cell. That is
exact where the cells tile space: every point inside lies in exactly one cell, and cells
that touch share whole faces. Meshes as FEM and CFD tools write them are not always so:

* **duplicated interface nodes** (each material region numbers its own nodes): the
  regions' faces on the interface coincide but share no point ids. The face adjacency welds
  points at exactly the same coordinates (:func:`tetvr.mesh.adjacency.coincident_points`),
  so such faces pair up and the walk goes straight through; a field that differs between
  the two copies jumps there (``link.w`` in the records). Nothing to route.
* **the same cell twice** (a ``.vtm`` naming one piece twice): the reference integrates
  each copy. The walk goes through the mesh of distinct cells and composites each segment
  once per copy (:mod:`tetvr.mesh.copies`). Nothing to route; copies with *other* values
  at the same points are overlapping cells (below).
* **faces held by more than two cells**, **folded faces** (the two cells on one side of
  their face: inverted or tangled elements) and **overlapping parts** (a refined block
  exported beside the coarse cells it replaces, cells laid over others without sharing a
  face): somewhere two cells hold the same point, and a walk from cell to cell follows only
  one of them.

* **gaps between cells**: where zero-volume cells were dropped (:meth:`TetMesh.from_arrays`),
  or two parts' faces do not match, a ray leaves the mesh and enters it again at one depth.
  The march takes each entry as one more layer (a pass over the screen and the boundary) and
  is exact there; projected tetrahedra, whose cell order does not cross a gap, are not
  (``tests/test_imperfect_meshes.py``). Nothing to route; the lattice below counts the most
  entries along one ray (:attr:`WalkCheck.most_entries`), what a frame's passes follow.

And **sizes float32 cannot walk**: the walk's products of coordinates (areas of triangles
about the ray, times depths) overflow float32 beyond an extent of about 1e13 and lose the
triangles about the ray where the cells are about 1e-12 across (measured on a cube and a
beam scaled from 1e-13 to 1e15; :data:`WALK_EXTENT_RANGE` keeps a margin). A few tiny cells
in a mesh of ordinary ones do not (the cells a cut at a plane leaves, 1e-16 across, walk
right): the typical cell, the median of the cells' longest edges, is what counts. Projected tetrahedra draw
those sizes right (their products are per cell, relative to its centre).

The overlap test casts a lattice of parallel rays in three oblique directions against the
boundary faces only (the scan conversion of XMPVO, :mod:`tetvr.order.boundary`) and counts,
along each ray in depth order, the boundary entered minus the boundary left: a mesh whose
cells tile space never has that count above one. (The sum of the cell volumes against the
volume the boundary encloses says nothing here: by the divergence theorem the boundary of
overlapping closed parts encloses exactly the sum of their volumes.) A lattice misses an
overlap smaller than its spacing (1/64 to 1/256 of the mesh across); the frame statistics of
the ray caster count what the walk finds inconsistent.

``RenderSettings(method="auto")`` sends a mesh with any of the overlaps to projected
tetrahedra, with one warning naming what was found (:func:`tetvr.order.method.choose`);
``method="raymarch"`` refuses it with the same words. All of it is found on the mesh of
distinct cells.
"""

from __future__ import annotations

import dataclasses
import threading
import weakref

import numpy as np

from tetvr.core.camera import Camera
from tetvr.mesh.adjacency import FaceAdjacency, face_adjacency
from tetvr.mesh.locality import spatially_ordered
from tetvr.mesh.copies import distinct_cells
from tetvr.mesh.records import folded_faces
from tetvr.mesh.tetmesh import TetMesh
from tetvr.order.boundary import _eye_faces, _lattice_hits, default_grid

__all__ = ["WalkCheck", "walk_check", "OVERLAP_DIRECTIONS", "WALK_EXTENT_RANGE"]

#: (typical cell, largest extent) the walk renders exactly in float32: the median of the
#: cells' longest edges, and the bounding-box diagonal. Measured: a 162-tet cube failed with
#: its cells at 1.1e-12 and, seen in parallel projection, at an extent of 1.7e13; a
#: 21,756-tet beam with its typical cell at 1.1e-12 (and rendered right at 3.4e-12).
WALK_EXTENT_RANGE = (1e-11, 1e12)

#: The lattice directions of the overlap test: oblique, so that no lattice ray of a mesh
#: built on axis-aligned grids runs along its faces or through its edges.
OVERLAP_DIRECTIONS = ((0.5773, 0.3112, -0.7548), (-0.2113, 0.8817, 0.4219), (0.7071, -0.4472, 0.5477))


@dataclasses.dataclass(frozen=True)
class WalkCheck:
    """What :func:`walk_check` found in a mesh.

    Attributes
    ----------
    welded_points : points at the coordinates of a lower-numbered point (duplicated
        nodes); their faces are joined, not a problem.
    repeated_cells : cells that repeat another cell, points and values (walked once,
        composited once per copy: not a problem).
    conflicting_cells : cells on the points of another cell with other values there.
    nonmanifold_faces : faces held by more than two cells.
    folded_faces : interior faces whose two cells lie on the same side.
    overlap_rays : lattice rays along which the mesh is entered twice before it is left.
    lattice_rays : rays cast for the overlap test.
    typical_cell : the median over the cells of the longest edge.
    extent : the bounding-box diagonal.
    most_entries : the most times one test ray enters the mesh's boundary, a gap between
        cells (where zero-volume cells were dropped, or faces that do not match) counted as
        leaving and entering again.
    """

    welded_points: int
    repeated_cells: int
    conflicting_cells: int
    nonmanifold_faces: int
    folded_faces: int
    overlap_rays: int
    lattice_rays: int
    typical_cell: float = 1.0
    extent: float = 1.0
    most_entries: int = 1

    @property
    def reasons(self) -> tuple[str, ...]:
        """Why tet marching cannot render the mesh exactly, one phrase each (empty if it can)."""
        out = []
        if self.conflicting_cells:
            out.append(f"{self.conflicting_cells} cells lie on the points of another cell with other values there")
        if self.nonmanifold_faces:
            out.append(f"{self.nonmanifold_faces} faces are held by more than two cells")
        if self.folded_faces:
            out.append(f"{self.folded_faces} interior faces are folded (their two cells overlap: inverted or "
                       "tangled elements)")
        if self.overlap_rays:
            out.append(f"parts of the mesh overlap (along {self.overlap_rays} of {self.lattice_rays} test rays a "
                       "second part is entered before the first is left, e.g. a refined block exported beside "
                       "the cells it replaces)")
        lo, hi = WALK_EXTENT_RANGE
        if self.typical_cell < lo:
            out.append(f"its cells (median longest edge {self.typical_cell:.3g}) are below {lo:g}, where the "
                       "walk's float32 arithmetic underflows (or scale the mesh, camera and unit distance up)")
        if self.extent > hi:
            out.append(f"the mesh's extent ({self.extent:.3g}) is above {hi:g}, where the walk's float32 arithmetic "
                       "overflows (or scale the mesh, camera and unit distance down)")
        return tuple(out)

    @property
    def walkable(self) -> bool:
        return not self.reasons

    @property
    def overlapping(self) -> bool:
        """Cells hold the same points: no cell order composites them exactly either."""
        return bool(self.conflicting_cells or self.nonmanifold_faces or self.folded_faces or self.overlap_rays)


# id(adjacency) -> (a weak reference to it, its check): the check lives as long as the
# adjacency, and the cache keeps neither it nor the mesh's arrays alive.
_CACHE: dict[int, tuple[weakref.ref[FaceAdjacency], WalkCheck]] = {}
_LOCK = threading.Lock()


def walk_check(mesh: TetMesh) -> WalkCheck:
    """What in ``mesh`` a walk from cell to cell cannot follow (see the module docstring);
    computed once per mesh geometry and cached with its face adjacency.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> walk_check(synthetic.cube(3)).reasons
    ()
    >>> tet = synthetic.single_tet()
    >>> walk_check(synthetic.merge(tet, tet)).reasons  # a repeated cell is composited twice
    ()
    >>> walk_check(synthetic.merge(tet, tet.with_scalars(tet.scalars + 1))).reasons[0]
    '1 cells lie on the points of another cell with other values there'
    """
    distinct = distinct_cells(spatially_ordered(mesh))  # the mesh tet marching walks
    mesh = distinct.mesh
    adj = face_adjacency(mesh)
    cached = _CACHE.get(id(adj))
    if cached is not None and cached[0]() is adj:
        return cached[1]
    overlap, rays, entries = ((0, 0, 0) if distinct.n_conflicting or adj.n_nonmanifold_faces
                              else _overlap_rays(mesh, adj))
    check = WalkCheck(welded_points=adj.n_welded_points, repeated_cells=distinct.n_repeats,
                      conflicting_cells=distinct.n_conflicting, nonmanifold_faces=adj.n_nonmanifold_faces,
                      folded_faces=folded_faces(mesh), overlap_rays=overlap, lattice_rays=rays, most_entries=entries,
                      typical_cell=adj.cell_size,
                      extent=float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0])))
    with _LOCK:
        if len(_CACHE) > 64:
            _CACHE.clear()
        _CACHE[id(adj)] = (weakref.ref(adj), check)
    return check


def _overlap_rays(mesh: TetMesh, adj: FaceAdjacency) -> tuple[int, int, int]:
    """(rays along which the boundary is entered twice before it is left, rays cast, the
    most times one ray enters the boundary)."""
    if adj.convex:
        return 0, 0, 1  # one closed convex boundary: every ray enters once and leaves once
    grid = default_grid(adj.n_boundary_faces)
    centre = 0.5 * (mesh.bounds[0] + mesh.bounds[1])
    radius = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0])) / 2 or 1.0
    # Touching parts, and neighbouring faces that share the edge a ray passes through, give
    # an entry and an exit, or two entries, at one depth: within this tolerance hits are one.
    tol = 1e-9 * radius
    found = most = 0
    for direction in OVERLAP_DIRECTIONS:
        d = np.asarray(direction, dtype=np.float64)
        up = np.cross(d, (0.0, 0.0, 1.0) if abs(d[2]) < 0.9 else (1.0, 0.0, 0.0))
        camera = Camera(position=tuple(centre - 3.0 * radius * d), focal_point=tuple(centre), view_up=tuple(up),
                        parallel_projection=True, parallel_scale=radius,
                        clipping_range=(-10.0 * radius, 10.0 * radius))
        p, n, c, cells, entering, _ = _eye_faces(mesh, camera, adj)
        if cells.size == 0:
            continue
        face, ray, depth = _lattice_hits(p, n, c, camera, grid)
        if ray.size == 0:
            continue
        sign = np.where(entering[face], 1, -1)
        order = np.lexsort((depth, ray))
        ray, depth, sign = ray[order], depth[order], sign[order]
        # Hits within the tolerance of the one before on the same ray are one crossing:
        # their net sign, clipped to one (two entries there are a ray through an edge).
        new_ray = np.r_[True, ray[1:] != ray[:-1]]
        start = new_ray | np.r_[True, np.diff(depth) > tol]
        group = np.cumsum(start) - 1
        net = np.clip(np.bincount(group, weights=sign), -1, 1)
        group_ray = ray[start]
        first_of_ray = new_ray[start]
        inside = np.cumsum(net)
        ray_starts = np.flatnonzero(first_of_ray)
        inside -= np.repeat(np.r_[0.0, inside[ray_starts[1:] - 1]], np.diff(np.r_[ray_starts, net.size]))
        found += int(np.unique(group_ray[inside > 1.5]).size)
        # Entries, each a layer of tet marching: a gap between cells is left and entered
        # again at one depth (its net sign is zero), so count the crossings that enter.
        entering = np.bincount(group, weights=(sign > 0).astype(np.float64)) > 0
        if entering.any():
            most = max(most, int(np.bincount(group_ray[entering]).max()))
    return found, grid * grid * len(OVERLAP_DIRECTIONS), most

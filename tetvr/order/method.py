"""Which GPU method renders a scene: projected tetrahedra or tet marching.

Both methods take the same (mesh, camera, transfer function, settings), read the same
pre-integration table and return the same premultiplied image; they differ in what their
cost follows. Projected tetrahedra pay per cell (classify, sort, 3-4 triangles each) plus
per fragment; tet marching pays per ray--tet segment (~20 ns each on llvmpipe) plus a
small per-frame cost for the boundary passes, and needs no sort, so it is exact in
visibility where a cell order is not. ``RenderSettings(method="auto")`` asks
:func:`choose`; bench/README.md has the measurements behind the rule.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from tetvr.core.camera import resolve_clipping_range
from tetvr.core.checks import warn
from tetvr.core.image import available_memory
from tetvr.order.walkable import walk_check
from tetvr.settings import RenderSettings

if TYPE_CHECKING:
    from tetvr.core.camera import Camera
    from tetvr.mesh.tetmesh import TetMesh

__all__ = ["choose", "segments_per_tet", "RAYMARCH_ONLY", "PROJECTED_ONLY", "CROSSOVER_SEGMENTS_PER_TET",
           "AUTO_MAX_TETS", "MARCH_BYTES_PER_TET", "MARCH_MEMORY_SHARE", "march_fits", "PROJECTED_NS_PER_TET", "PROJECTED_NS_PER_FRAGMENT", "MARCH_NS_PER_SEGMENT", "AUTO_MARGIN"]

#: The measured cost model on llvmpipe at 512x512 (bench/results/stages.json, six meshes of
#: 10k to 1M tets, wall time per frame; least squares): projected tetrahedra pay
#: ~1.1 us per tet plus ~20.5 ns per fragment, tet marching ~16.1 ns per ray--tet segment
#: (its march time; a fragment of projected tetrahedra is one segment) plus its boundary
#: pass (7-18 ms).
PROJECTED_NS_PER_TET = 1125.0
PROJECTED_NS_PER_FRAGMENT = 20.5
MARCH_NS_PER_SEGMENT = 16.1
#: "auto" takes projected tetrahedra for speed only where they are predicted this much
#: faster: large cells seen close up are where a cell order and degenerate projections
#: cost projected tetrahedra accuracy (the stability suite, tests/test_near_plane_fuzz.py),
#: which tet marching does not lose.
AUTO_MARGIN = 1.5
#: Segments per tet above which projected tetrahedra are predicted AUTO_MARGIN times faster:
#: s with MARCH * s = AUTO_MARGIN * (PER_TET + PER_FRAGMENT * s). A segment of tet
#: marching costs less than a fragment of projected tetrahedra on llvmpipe, so there is
#: none (infinity): "auto" takes tet marching however large the cells are on screen. A
#: device with cheaper rasterisation would have one.
CROSSOVER_SEGMENTS_PER_TET = (
    AUTO_MARGIN * PROJECTED_NS_PER_TET / (MARCH_NS_PER_SEGMENT - AUTO_MARGIN * PROJECTED_NS_PER_FRAGMENT)
    if MARCH_NS_PER_SEGMENT > AUTO_MARGIN * PROJECTED_NS_PER_FRAGMENT else float("inf"))
#: Host memory tet marching takes per tet for a mesh's first frame on llvmpipe, which keeps
#: GL textures in host memory: the records, the face adjacency and its temporaries
#: (bench/results/frame_memory.json: 330 B a tet measured on 105k and 413k tets, beside the
#: mesh's own 22, rounded up; projected tetrahedra add 510 and draw in chunks).
MARCH_BYTES_PER_TET = 400
#: "auto" takes tet marching for a mesh whose records take at most this share of the memory
#: the system says is available (:func:`tetvr.core.image.available_memory`), else projected
#: tetrahedra, which draw in chunks with bounded memory (bench/memory.py: 10M tets in 3.5 GB).
MARCH_MEMORY_SHARE = 0.5
#: Where the available memory is not known: "auto" takes tet marching up to this many tets.
AUTO_MAX_TETS = 2_000_000
_SAMPLE = 4096

#: Settings only projected tetrahedra implement: VTK parity (VTK's projected tetrahedra,
#: tetvr.gl.vtkpt), screen-linear interpolation and an 8-bit compositing target.
PROJECTED_ONLY = ("optics='vtk'", "framebuffer='uint8'", "perspective_correct=False")
#: Settings only the ray caster implements.
RAYMARCH_ONLY: tuple[str, ...] = ("integration='exact'",)


def choose(settings: RenderSettings, mesh: "TetMesh | None" = None, camera: "Camera | None" = None,
           size: tuple[int, int] | None = None) -> str:
    """The method a frame with these settings (and this mesh) uses: ``"projected"`` or
    ``"raymarch"``.

    ``"auto"`` picks tet marching -- exact in visibility order, and on llvmpipe never
    slower than projected tetrahedra by more than ~5 % (bench/README.md) -- except:

    * settings only projected tetrahedra implement (:data:`PROJECTED_ONLY`: VTK parity,
      8-bit compositing, screen-linear interpolation);
    * meshes a walk from cell to cell cannot follow (:func:`tetvr.order.walkable.walk_check`:
      the same cell twice, faces held by more than two cells, folded faces, overlapping
      parts), with one warning naming what was found; ``method="raymarch"`` refuses them
      with the same words (ValueError);
    * meshes whose records would not fit in memory (:func:`march_fits`: projected
      tetrahedra draw in chunks);
    * given the camera and size, views from outside the mesh whose tets are so large on
      screen (:func:`segments_per_tet` above :data:`CROSSOVER_SEGMENTS_PER_TET`) that
      rasterising their few triangles is predicted 1.5x faster than walking their many
      segments (by the measured cost model, never on llvmpipe).

    Examples
    --------
    >>> choose(RenderSettings())
    'raymarch'
    >>> choose(RenderSettings(optics="vtk"))
    'projected'
    """
    if settings.method == "raymarch" and mesh is not None:
        reasons = walk_check(mesh).reasons
        if reasons:
            raise ValueError(f"tet marching cannot render this mesh exactly: {'; '.join(reasons)}. Use "
                             "method=\"projected\" (or \"auto\", which does)")
    if settings.method != "auto":
        return settings.method
    if settings.integration == "exact":
        return "raymarch"  # only tet marching integrates without the table
    if settings.optics == "vtk" or settings.framebuffer != "float32" or not settings.perspective_correct:
        return "projected"
    if mesh is not None:
        if not march_fits(mesh.n_tets):
            return "projected"
        check = walk_check(mesh)
        if check.reasons:
            caveat = (" (where cells overlap, projected tetrahedra composite them in an approximate order: "
                      "method=\"reference\" is exact)" if check.overlapping else "")
            warn(f"tet marching cannot render this mesh exactly: {'; '.join(check.reasons)}. Rendering by "
                 f"projected tetrahedra instead{caveat}")
            return "projected"
        # (The estimate costs a pass over a sample of cells on every view change: skipped
        # where no cell size can cross over.)
        if (camera is not None and size is not None and CROSSOVER_SEGMENTS_PER_TET < float("inf")
                and not _eye_near_mesh(mesh, camera)
                and segments_per_tet(mesh, camera, size) > CROSSOVER_SEGMENTS_PER_TET):
            return "projected"
    return "raymarch"


def march_fits(n_tets: int, available: int | None = -1) -> bool:
    """Whether tet marching's records for ``n_tets`` tets (:data:`MARCH_BYTES_PER_TET` each)
    take at most :data:`MARCH_MEMORY_SHARE` of the available memory (``available`` bytes;
    by default what the system says, :func:`tetvr.core.image.available_memory`); where that
    is not known, whether ``n_tets`` is at most :data:`AUTO_MAX_TETS`. What "auto" chooses
    by, in place of a fixed count of tets.

    Examples
    --------
    >>> march_fits(3_000_000, available=16 * 2**30), march_fits(3_000_000, available=2 * 2**30)
    (True, False)
    >>> march_fits(3_000_000, available=None)
    False
    """
    if available == -1:
        available = available_memory()
    if available is None:
        return n_tets <= AUTO_MAX_TETS
    return n_tets * MARCH_BYTES_PER_TET <= MARCH_MEMORY_SHARE * available


def _eye_near_mesh(mesh: "TetMesh", camera: "Camera") -> bool:
    """The eye inside the mesh's bounding box grown by a tenth of its diagonal (views from
    inside or beside the mesh: no cell order is exact there)."""
    lo, hi = mesh.bounds
    pad = 0.1 * float(np.linalg.norm(hi - lo))
    eye = np.asarray(camera.position)
    return bool(np.all(eye >= lo - pad) and np.all(eye <= hi + pad))


def segments_per_tet(mesh: "TetMesh", camera: "Camera", size: tuple[int, int]) -> float:
    """Estimated ray--tet segments per tet in a view: the mean projected area, in pixels,
    of the tets in front of the eye (a sample of at most 4096), whose sum over the mesh is
    the number of segments either method integrates (a fragment of projected tetrahedra is
    one segment). A tet's parallel projection covers half the sum of its faces' areas
    times their |cosine| to the view direction; in perspective the scale at its centroid's
    depth is used.

    Examples
    --------
    >>> from tetvr import Camera
    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.cube(4)
    >>> round(segments_per_tet(mesh, Camera.fit(mesh, parallel=True), (64, 64)), 1) > 0
    True
    """
    n = mesh.n_tets
    # An evenly strided sample: no per-frame O(n) shuffle (this runs on every view change).
    ids = np.arange(0, n, max(1, n // _SAMPLE))
    p = mesh.points[mesh.tets[ids]]  # (s, 4, 3)
    view = camera.view_matrix()
    eye = p @ view[:3, :3].T + view[:3, 3]
    depth = -eye[..., 2].mean(axis=1)
    faces = ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))
    area = np.zeros(ids.shape[0])
    for a, b, c in faces:
        area += 0.5 * np.abs(np.cross(eye[:, b] - eye[:, a], eye[:, c] - eye[:, a])[:, 2])
    area *= 0.5  # front and back faces both cover the projection
    near = resolve_clipping_range(camera, mesh.bounds).near_far()[0]
    if camera.parallel_projection:
        px_per_unit = size[1] / (2.0 * camera.parallel_scale)
        scale = np.full(ids.shape[0], px_per_unit**2)
    else:
        focal = size[1] / (2.0 * np.tan(np.radians(camera.view_angle) / 2.0))
        scale = (focal / np.maximum(depth, near)) ** 2
    visible = depth > near
    return float(np.sum(area * scale * visible) / ids.shape[0])

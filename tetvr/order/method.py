"""Which GPU method renders a scene: projected tetrahedra or tet marching.

Both methods take the same (mesh, camera, transfer function, settings), read the same
pre-integration table and return the same premultiplied image; they differ in what their
cost follows. Projected tetrahedra pay per cell (classify, sort, 3-4 triangles each) plus
per fragment; tet marching pays per ray--tet segment (~13 ns each on llvmpipe) plus a
cost per entering ray (its setup and the boundary passes), and needs no sort, so it is
exact in visibility where a cell order is not. ``RenderSettings(method="auto")`` asks
:func:`choose`; bench/README.md has the measurements behind the rule.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from tetvr.core.camera import resolve_clipping_range
from tetvr.core.checks import warn
from tetvr.core.image import available_memory
from tetvr.mesh.adjacency import face_adjacency
from tetvr.order.sort import AUTO_MPVONC_MAX_CELLS
from tetvr.order.walkable import walk_check
from tetvr.settings import RenderSettings

if TYPE_CHECKING:
    from tetvr.core.camera import Camera
    from tetvr.mesh.tetmesh import TetMesh

__all__ = ["choose", "segments_per_tet", "entering_rays", "predicted_seconds", "order_exact", "CostModel",
           "LLVMPIPE", "AUTO_MARGIN", "RAYMARCH_ONLY", "PROJECTED_ONLY", "AUTO_MAX_TETS", "MARCH_BYTES_PER_TET",
           "MARCH_MEMORY_SHARE", "march_fits"]


@dataclasses.dataclass(frozen=True)
class CostModel:
    """Seconds a view change costs each method, linear in what each pays for.

    Tet marching pays per ray--tet segment, per ray entering the mesh (its setup and the
    boundary passes) and per tet (the records' working set: a larger mesh's walk misses
    the caches more often); projected tetrahedra pay per tet (classify, sort, 3-4
    triangles), per fragment (one a segment) and per frame. All in nanoseconds.
    """

    march_ns_per_segment: float
    march_ns_per_ray: float
    march_ns_per_tet: float
    projected_ns_per_tet: float
    projected_ns_per_fragment: float
    projected_ns_per_frame: float

    def seconds(self, n_tets: float, segments: float, rays: float) -> dict[str, float]:
        """Predicted seconds of a view change by each method, ``{"raymarch": ...,
        "projected": ...}``, for a view with these estimated segments and entering rays.

        Examples
        --------
        >>> model = CostModel(20.0, 100.0, 0.0, 1000.0, 20.0, 0.0)
        >>> {k: round(v, 6) for k, v in model.seconds(1000, 10**6, 10**4).items()}
        {'raymarch': 0.021, 'projected': 0.021}
        """
        march = (self.march_ns_per_segment * segments + self.march_ns_per_ray * rays
                 + self.march_ns_per_tet * n_tets)
        projected = (self.projected_ns_per_tet * n_tets + self.projected_ns_per_fragment * segments
                     + self.projected_ns_per_frame)
        return {"raymarch": march * 1e-9, "projected": projected * 1e-9}


#: The cost model on llvmpipe (2 cores), fitted by ``bench/cost_model.py`` on the view
#: changes of ``bench/vs_vtk.py`` (the corpus's eleven meshes, grids and unstructured, at
#: 512x512 and 1024x1024; relative least squares, coefficients non-negative) with the
#: estimates below (:func:`segments_per_tet`, :func:`entering_rays`) as its inputs;
#: bench/results/cost_model.json holds the fit and its error per scene.
LLVMPIPE = CostModel(march_ns_per_segment=11.6, march_ns_per_ray=189.0, march_ns_per_tet=119.0,
                     projected_ns_per_tet=1280.0, projected_ns_per_fragment=14.6,
                     projected_ns_per_frame=18.7e6)
#: "auto" takes projected tetrahedra for speed only where the model predicts them this
#: much faster: a near tie goes to tet marching, the more accurate method on real meshes
#: at large sizes (bench/results/speed_accuracy.json, the beam at 1024x1024: projected
#: tetrahedra's largest error ten times tet marching's). Chosen on the fit's and the
#: held-out scenes of bench/results/cost_model.json: within the model's scatter there,
#: and no scene loses more than a few per cent against the faster method.
AUTO_MARGIN = 1.2
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

    ``"auto"`` picks tet marching -- exact in visibility order, from inside the mesh too --
    except:

    * settings only projected tetrahedra implement (:data:`PROJECTED_ONLY`: VTK parity,
      8-bit compositing, screen-linear interpolation);
    * meshes a walk from cell to cell cannot follow (:func:`tetvr.order.walkable.walk_check`:
      the same cell twice, faces held by more than two cells, folded faces, overlapping
      parts), with one warning naming what was found; ``method="raymarch"`` refuses them
      with the same words (ValueError);
    * meshes whose records would not fit in memory (:func:`march_fits`: projected
      tetrahedra draw in chunks);
    * given the camera and size, views from outside a mesh whose cell order is exact
      (:func:`order_exact`: convex, sorted by MPVO) where the cost model
      (:func:`predicted_seconds`, :data:`LLVMPIPE`) predicts projected tetrahedra
      :data:`AUTO_MARGIN` times faster: few large cells at a large size. Where the order
      is not exact, tet marching even where it is the slower (a fast wrong picture is
      worse than a slow right one).

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
        # (The estimates cost a pass over a sample of cells and boundary faces on every view
        # change: only where projected tetrahedra would be exact.)
        if (camera is not None and size is not None and order_exact(settings, mesh)
                and not _eye_near_mesh(mesh, camera)):
            cost = predicted_seconds(mesh, camera, size)
            if AUTO_MARGIN * cost["projected"] < cost["raymarch"]:
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


def order_exact(settings: RenderSettings, mesh: "TetMesh") -> bool:
    """Whether projected tetrahedra's cell order is exact for ``mesh`` from every view
    outside it under ``settings``: a convex mesh (``face_adjacency(mesh).convex``) sorted
    by MPVO (``sort`` ``"mpvo"``, ``"mpvonc"`` or ``"xmpvo"``, or ``"auto"`` up to
    :data:`tetvr.order.sort.AUTO_MPVONC_MAX_CELLS` cells).

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> order_exact(RenderSettings(), synthetic.cube(3)), order_exact(RenderSettings(sort="centroid"), synthetic.cube(3))
    (True, False)
    """
    by_graph = settings.sort in ("mpvo", "mpvonc", "xmpvo") or (
        settings.sort == "auto" and mesh.n_tets <= AUTO_MPVONC_MAX_CELLS)
    return by_graph and face_adjacency(mesh).convex


def predicted_seconds(mesh: "TetMesh", camera: "Camera", size: tuple[int, int],
                      model: CostModel = LLVMPIPE) -> dict[str, float]:
    """Seconds ``model`` predicts a view change of ``mesh`` takes by each method,
    ``{"raymarch": ..., "projected": ...}``, from the estimated segments
    (:func:`segments_per_tet`) and entering rays (:func:`entering_rays`).

    Examples
    --------
    >>> from tetvr import Camera
    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.cube(12)
    >>> small, large = (predicted_seconds(mesh, Camera.fit(mesh), (s, s)) for s in (256, 2048))
    >>> small["raymarch"] < small["projected"], large["projected"] < large["raymarch"]
    (True, True)
    """
    segments = segments_per_tet(mesh, camera, size) * mesh.n_tets
    return model.seconds(mesh.n_tets, segments, entering_rays(mesh, camera, size))


def entering_rays(mesh: "TetMesh", camera: "Camera", size: tuple[int, int]) -> float:
    """Estimated rays entering the mesh in a view, counting each entry of a ray that
    leaves and enters again: half the projected area, in pixels, of the boundary faces in
    front of the eye and on the image (a strided sample of at most 4096). In perspective
    each face is scaled at its centroid's depth.

    Examples
    --------
    >>> from tetvr import Camera
    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.cube(4)
    >>> rays = entering_rays(mesh, Camera.fit(mesh, parallel=True, direction=(0, 0, -1)), (64, 64))
    >>> bool(0.3 * 64 * 64 < rays <= 64 * 64)
    True
    """
    adj = face_adjacency(mesh)
    faces = adj.boundary_faces
    n = faces.shape[0]
    if n == 0:
        return 0.0
    ids = np.arange(0, n, max(1, n // _SAMPLE))
    eye = _in_eye_space(mesh.points[faces[ids]], camera)  # (s, 3, 3)
    area = 0.5 * np.abs(np.cross(eye[:, 1] - eye[:, 0], eye[:, 2] - eye[:, 0])[:, 2])
    scale, visible = _pixel_scale(mesh, camera, size, eye)
    return float(0.5 * np.sum(area * scale * visible) * n / ids.shape[0])


def _in_eye_space(points: np.ndarray, camera: "Camera") -> np.ndarray:
    view = camera.view_matrix()
    return points @ view[:3, :3].T + view[:3, 3]


def _pixel_scale(mesh: "TetMesh", camera: "Camera", size: tuple[int, int],
                 eye: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For shapes given by their corners in eye space ``(s, k, 3)``: square pixels per
    square world unit at each one's centroid, and which centroids are in front of the
    near plane and within the image (a shape partly off the image counts whole or not at
    all: views from close by are neither over- nor under-counted by much)."""
    centre = eye.mean(axis=1)
    depth = -centre[:, 2]
    near = resolve_clipping_range(camera, mesh.bounds).near_far()[0]
    if camera.parallel_projection:
        per_unit = np.full(depth.shape[0], size[1] / (2.0 * camera.parallel_scale))
    else:
        per_unit = size[1] / (2.0 * np.tan(np.radians(camera.view_angle) / 2.0)) / np.maximum(depth, near)
    on_image = ((np.abs(centre[:, 0] * per_unit) <= size[0] / 2.0)
                & (np.abs(centre[:, 1] * per_unit) <= size[1] / 2.0))
    return per_unit**2, (depth > near) & on_image


def _eye_near_mesh(mesh: "TetMesh", camera: "Camera") -> bool:
    """The eye inside the mesh's bounding box grown by a tenth of its diagonal (views from
    inside or beside the mesh: no cell order is exact there)."""
    lo, hi = mesh.bounds
    pad = 0.1 * float(np.linalg.norm(hi - lo))
    eye = np.asarray(camera.position)
    return bool(np.all(eye >= lo - pad) and np.all(eye <= hi + pad))


def segments_per_tet(mesh: "TetMesh", camera: "Camera", size: tuple[int, int]) -> float:
    """Estimated ray--tet segments per tet in a view: the mean projected area, in pixels,
    of the tets in front of the eye and on the image (a sample of at most 4096), whose sum over the mesh is
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
    eye = _in_eye_space(mesh.points[mesh.tets[ids]], camera)  # (s, 4, 3)
    faces = ((1, 2, 3), (0, 3, 2), (0, 1, 3), (0, 2, 1))
    area = np.zeros(ids.shape[0])
    for a, b, c in faces:
        area += 0.5 * np.abs(np.cross(eye[:, b] - eye[:, a], eye[:, c] - eye[:, a])[:, 2])
    area *= 0.5  # front and back faces both cover the projection
    scale, visible = _pixel_scale(mesh, camera, size, eye)
    return float(np.sum(area * scale * visible) / ids.shape[0])

"""VTK parity on the GPU (``RenderSettings(optics="vtk")``): ParaView's "Projected tetra".

About this technique
--------------------
VTK's ``vtkOpenGLProjectedTetrahedraMapper`` is Shirley & Tuchman's (1990) projected
tetrahedra with Wylie et al.'s (2002) thick vertex found where two opposite edges cross in
projection. Parity mode exists to show ParaView's picture, defects included, so it takes
VTK's steps rather than tetvr's own (docs/paraview.md, "What VTK's Projected tetra
computes"): colour and opacity classified at the vertices and kept in 8 bits by
truncation (:func:`tetvr.optics.model.vtk_vertex_rgba8`), the thick vertex's values averaged
(and truncated again), the class-2 opacity taken with the wrong edge parameter, the
thickness in perspective views read from a 2,048-entry square-root table, everything
interpolated linearly in screen space, and ``alpha = 1 - exp(-a d / u)`` per fragment
(``shaders/classify_vtk.comp``, ``vtk_pt.vert``, ``vtk_pt.frag``). The drawing order is
VTK's too: cell centroids by their depth along the direction of projection
(``vtkCellCenterDepthSort``, :func:`vtk_depth_order`). Nothing here is used by the other
optics; the pre-integration table is not built.

What ParaView draws with the volume is taken VTK's way too:

* **Opaque surfaces** (:class:`tetvr.Surface`). ParaView draws opaque geometry first;
  ``vtkOpenGLProjectedTetrahedraMapper::ProjectTetrahedra`` copies its depth buffer and draws
  the tets' triangles with the depth test on (``GL_LEQUAL``) and depth writes off, each fan
  vertex at its projected depth (the class-2 crossing at the first edge's), so every
  triangle lies in a face of its tet. A fragment is kept, with the tet's whole thickness, if
  that face is not behind the surface, and dropped otherwise: a tet straddling a surface is
  drawn whole or not at all, pixel by pixel. Parity tests each fragment so against the
  surfaces' depth (:class:`~tetvr.gl.surfaces.SurfacePass`, ``shaders/vtk_pt.frag``); the
  renderer then composites the tets over the surfaces' colour, as VTK's blend over the
  framebuffer does. The same depth puts the far plane where VTK's GL puts it.
* **Clips** (:class:`tetvr.Clip`). In ParaView a clip of a volume is the Clip filter: it cuts
  the cells into new ones before the volume mapper (which has no clipping planes of its own;
  ``vtkOpenGLProjectedTetrahedraMapper`` ignores the mapper's), and the representation
  tetrahedralizes them. Parity does the same on the CPU (:func:`tetvr.mesh.clipfilter.clip_cells`,
  cached per mesh and clip) and draws the cut mesh: new vertices, classified like any others,
  not tetvr's per-pixel cut of each ray.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera
from tetvr.core.clip import Clip
from tetvr.mesh.clipfilter import clip_cells
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.model import vtk_vertex_rgba8
from tetvr.optics.transfer import TransferFunction
from tetvr.gl.host import DrawHost
from tetvr.gl.surfaces import LIMIT_UNIT
from tetvr.gl.util import set_uniforms

__all__ = ["VTKParity", "vtk_depth_order", "SQRT_TABLE_SIZE"]

#: Entries of VTK's square-root table for the thickness in perspective views.
SQRT_TABLE_SIZE = 2048


def vtk_depth_order(mesh: TetMesh, camera: Camera) -> NDArray[np.uint32]:
    """Cell ids back to front as ``vtkCellCenterDepthSort`` orders them.

    VTK sorts cell centres by their dot product with ``position - focal_point`` (in
    float), for perspective views too, where tetvr's centroid sort takes the distance to
    the eye. Ties, which VTK leaves to a random-pivot quicksort, keep the cell order here.
    """
    vector = (np.asarray(camera.position) - np.asarray(camera.focal_point)).astype(np.float32)
    depth = mesh.centroids.astype(np.float32) @ vector
    return np.argsort(depth, kind="stable").astype(np.uint32)


class VTKParity:
    """The parity renderer's GL state for one :class:`~tetvr.gl.renderer.Renderer`: the
    vertices' 8-bit colours, uploaded once per mesh and transfer function."""

    def __init__(self, owner: DrawHost) -> None:
        self.owner = owner
        self._colors: tuple[TetMesh, TransferFunction, Any] | None = None
        self._cut: tuple[TetMesh, Clip, TetMesh | None] | None = None

    def forget(self) -> None:
        self._colors = None

    def cut(self, mesh: TetMesh, clip: Clip, order: NDArray[Any] | None
            ) -> tuple[TetMesh, NDArray[np.uint32] | None]:
        """The mesh ParaView's Clip filter makes of ``mesh`` (:func:`~tetvr.mesh.clipfilter.clip_cells`;
        the last one kept), and the drawing order: None (the sort's), or empty where the clip
        leaves nothing (``mesh`` is then returned, none of it drawn). An explicit ``order``
        names cells of the uncut mesh and is refused."""
        if order is not None:
            raise ValueError("an explicit drawing order cannot go with a clip in VTK parity (optics='vtk'): the "
                             "clip cuts the cells into new ones first, as ParaView's Clip filter does")
        if self._cut is None or self._cut[0] is not mesh or self._cut[1] != clip:
            self._cut = (mesh, clip, clip_cells(mesh, clip))
        kept = self._cut[2]
        return (mesh, np.empty(0, dtype=np.uint32)) if kept is None else (kept, None)

    def gl_objects(self) -> list[Any]:
        return [] if self._colors is None else [self._colors[2]]

    def gpu_bytes(self) -> int:
        return 0 if self._colors is None else int(self._colors[2].size)

    def _use_colors(self, mesh: TetMesh, tf: TransferFunction) -> Any:
        """The packed RGBA8 of every point of the renderer's points buffer (cell data: each
        tet's four points carry its cell's colour, as VTK colours the cell)."""
        if self._colors is not None and self._colors[0] is mesh and self._colors[1] == tf:
            return self._colors[2]
        if self._colors is not None:
            self._colors[2].release()
            self._colors = None
        values = mesh.scalars if mesh.cell_scalars is None else np.repeat(mesh.cell_scalars, 4)
        rgba = vtk_vertex_rgba8(tf, values).astype(np.uint32)
        packed = rgba[:, 0] | (rgba[:, 1] << 8) | (rgba[:, 2] << 16) | (rgba[:, 3] << 24)
        buffer = self.owner.ctx.buffer(np.ascontiguousarray(packed, dtype=np.uint32).tobytes())
        self._colors = (mesh, tf, buffer)
        return buffer

    def render(self, mesh: TetMesh, tf: TransferFunction, size: tuple[int, int], uniforms: dict[str, Any],
               order_ids: NDArray[Any], limit: Any = None) -> NDArray[np.float32]:
        """One frame: premultiplied RGBA, (height, width, 4), row 0 at the top. ``uniforms``
        are the renderer's view uniforms (the mesh uploaded), ``order_ids`` the drawing order,
        ``limit`` the opaque surfaces' eye depths (:class:`~tetvr.gl.surfaces.SurfacePass`) or None."""
        import moderngl

        owner = self.owner
        colors = self._use_colors(mesh, tf)
        proj32 = np.asarray(uniforms["u_proj"], dtype=np.float32)
        inv_proj = np.linalg.inv(proj32.astype(np.float64))  # VTK inverts its float matrix in double
        # VTK's test for a parallel projection: then NDC depth is linear in eye depth and the
        # thickness exact, (far - near) / 2 per unit; in perspective it reads the table.
        parallel = bool(np.all(proj32[3, :3] == 0.0) and proj32[3, 3] == 1.0)
        max_edge2 = float(np.float32(mesh.max_edge ** 2))
        vtk_uniforms = dict(uniforms, u_inv_proj=inv_proj,
                            u_linear_depth=float(np.linalg.norm(inv_proj[:3, 2])) if parallel else 0.0,
                            u_sqrt_bias=(SQRT_TABLE_SIZE - 1) / max(max_edge2, 1e-30),
                            u_unit_distance=float(tf.unit_distance))
        classify = owner._program("classify_vtk")
        prog = owner._program("vtk_pt", SURFACE_DEPTH=int(limit is not None))
        fb_dtype = "f4" if owner.settings.framebuffer == "float32" else "f1"
        fbo = owner._use_target(size, 4, fb_dtype)
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        if limit is not None:  # bound after the target, which may be made (and bound) just above
            limit.use(LIMIT_UNIT)
            set_uniforms(prog, u_limit=LIMIT_UNIT, u_proj=proj32)
        owner._clock.lap("setup")
        for n in owner._chunks(mesh, order_ids):
            colors.bind_to_storage_buffer(5)
            owner._classify(n, vtk_uniforms, perspective_correct=0, program=classify)
            owner._draw(prog, fbo, n, ((moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA), moderngl.FUNC_ADD))
        return owner._read(fbo, size, 4, fb_dtype)

"""The tet-marching ray caster's GL side: records as textures, entry passes, march passes.

Owned by a :class:`~tetvr.gl.renderer.Renderer` (its context, its table texture, its
programs), chosen by ``RenderSettings(method="raymarch")``. Per mesh (once): the records of
:func:`tetvr.mesh.records.march_records` go to textures read as images with ``imageLoad`` (on
llvmpipe several times faster in the walk's loop than the same reads from a storage
buffer, and faster than ``texelFetch``) and the boundary faces to a vertex buffer. Per
view, the points relative to the eye (float64, then float32), and then layer by layer:

1. *entry* (``march_entry.*``): the boundary faces that face each ray -- and, in the first
   layer, the cells the near plane cuts -- are rasterised; the depth test keeps each ray's
   nearest entry at its exact ray parameter;
2. *march* (``march.frag``): one full-screen pass walks every ray from its entry until it
   leaves the mesh, reaches the far plane or turns opaque, compositing front to back. It
   is drawn at the far end of the depth range against the entry depths, so that the depth
   test (before the shader) leaves out the pixels no ray enters: llvmpipe runs a shader
   eight pixels at a time, and a group whose rays all miss the mesh would still pay for
   the shader's set-up and one pass through each of its loops.

Where a ray left the mesh (a non-convex mesh, or separate parts) it may enter again at a
boundary face behind. The first entry pass also lists each pixel's front faces (up to
:data:`LIST_LENGTH`), and the march pass picks the next entry from the list where its
ray left and counts the rays that go on: another march pass runs while any does, and no
pass rasterises the boundary again. Before it, a mark pass (``march_mark.frag``) copies
the targets and leaves depth 0 only where a ray goes on, so that the pass runs there
alone (on bluntfin at 512x512, 0.2 % of the segments are in the second layer: as a full
pass it took 20 ms, as a marked one 8). Where a pixel overflowed the list (or a frame is too
tall for one), the next layer's entry pass instead peels the boundary behind where each
ray left, and an occlusion query says when no ray enters again. A convex mesh needs one
layer and neither.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera
from tetvr.core.image import release_free_memory
from tetvr.gl.march_layout import (COPIES_IMAGE, COUNT_IMAGE, LIST_IMAGE, LIST_LENGTH, LIST_MAX_BYTES, MORE_BUFFER, NEAREST,
                                   SUSPECT_BUFFER, SUSPECT_LENGTH, OVERFLOW_BUFFER, POINTS_IMAGE, Layout, Rim,
                                   raymarch_capacity, records_textures, rect_triangles, texture)
from tetvr.mesh.records import MarchRecords, near_plane_cells, rim_faces
from tetvr.gl.prefetch import Prefetch, records
from tetvr.mesh.tetmesh import TetMesh
from tetvr.mesh.adjacency import face_adjacency
from tetvr.gl.host import ProgramHost

__all__ = ["Marcher", "MarchStats", "raymarch_capacity"]

#: Most entry layers per frame: a ray leaving and entering the mesh more often than this
#: (a mesh of many separate shells seen edge-on, gaps where zero-volume cells were dropped)
#: is traced again exactly on the CPU (:mod:`tetvr.gl.selfcheck`); the count is in the stats.
MAX_LAYERS = 64
#: A walk stops once the transparency left is below this (early ray termination: what the
#: rest of the ray could add is at most this much). Terminating at 2**-12 or 1e-3 instead
#: measured no faster on bluntfin and combustor at 512x512 (their rays rarely get opaque
#: under the benchmark's transfer function).
OPAQUE_REMAINDER = 2.0**-20


#: OpenGL's GL_DEPTH_CLAMP (moderngl names no flag for it).
GL_DEPTH_CLAMP = 0x864F


def _slack(mesh: TetMesh, camera: Camera) -> float:
    """Length an exit may lie behind its entry by float32 rounding alone (march.frag's
    check): 1e-4 of the mesh's diagonal, and 1e-5 of the eye's distance from its centre."""
    lo, hi = mesh.bounds
    far = float(np.linalg.norm(np.asarray(camera.position, dtype=np.float64) - (lo + hi) / 2))
    return 1e-4 * float(np.linalg.norm(hi - lo)) + 1e-5 * far


@dataclasses.dataclass(frozen=True)
class MarchStats:
    """Layers the last ray-cast frame needed (1 for a convex mesh), whether rays were
    cut off at :data:`MAX_LAYERS`, whether the first entry pass kept a list for the layers
    after the first (not for a convex mesh; else they peel: a pixel overflowed the list,
    or the frame is too tall or too large for one), the cells the near plane cut and the boundary faces
    whose entries were decided by a float64 ray-triangle test beside faces seen edge-on
    (:func:`~tetvr.mesh.records.rim_faces`)."""

    layers: int = 0
    layers_exhausted: bool = False
    entry_list: bool = False
    n_near_cells: int = 0
    n_rim_faces: int = 0
    #: Rays whose walk went wrong (march.frag's check: a step bound reached, no face ahead,
    #: an exit behind its entry), each counted once in each pass; 0 on a clean mesh.
    n_suspect: int = 0
    #: Their pixels (row * width + column, unique; at most SUSPECT_LENGTH listed).
    suspect_pixels: NDArray[np.int64] = dataclasses.field(default_factory=lambda: np.zeros(0, np.int64),
                                                          compare=False, repr=False)


class Marcher:
    """GL state of the tet-marching ray caster for one :class:`Renderer`."""

    def __init__(self, owner: ProgramHost) -> None:
        self.owner = owner
        self.ctx = owner.ctx
        self._mesh: TetMesh | None = None  # the mesh given, and the one walked (each repeated cell once)
        self._walked: TetMesh | None = None
        self._jumps = False
        self._records: MarchRecords | None = None
        self._textures: dict[int, Any] = {}  # image unit -> records texture
        self._faces: list[Any] = []  # boundary positions, slots
        self._vaos: dict[Any, Any] = {}
        self._targets: dict[tuple[int, int], dict[str, Any]] = {}
        self._query: Any = None
        self._counters: list[Any] = []  # the overflow and more counters (LIST)
        self._suspects: Any = None  # the frame's check of itself (march.frag, SUSPECT_BUFFER)
        self.frames = 0  # frames drawn: a caller tells whether last_stats is its frame's
        self._prefetch: Prefetch | None = None
        self._unused: TetMesh | None = None  # a mesh whose records settle() put on the GL before a frame used them
        self._shifts: dict[str, int] = {}
        self._points: NDArray[np.float32] = np.zeros((0, 4), dtype=np.float32)
        self._points_eye: NDArray[np.float64] | None = None
        self.last_stats = MarchStats()

    # ---- ownership ----
    def gl_objects(self) -> list[Any]:
        objs = [*self._vaos.values(), *self._textures.values(), *self._faces, *self._counters,
                *([self._suspects] if self._suspects is not None else [])]
        for t in self._targets.values():
            objs += list(t.values())
        return objs  # the occlusion query has no release in moderngl: it goes with the context

    def forget(self) -> None:
        self._vaos.clear()
        self._textures, self._faces, self._counters = {}, [], []
        self._suspects = None
        self._targets.clear()
        self._query = None
        self._mesh = self._walked = self._records = self._unused = None
        self._prefetch = None

    def gpu_bytes(self) -> int:
        """Bytes held in the records, boundary buffers and targets."""
        total = sum(b.size for b in [*self._faces, *self._counters])
        textures = [*self._textures.values(), *(tex for t in self._targets.values() for name, tex in t.items()
                                       if "fbo" not in name)]
        for tex in textures:
            texel = 4 if tex.depth else tex.components * int(tex.dtype[1])
            total += tex.width * tex.height * texel
        return int(total)

    # ---- per mesh ----
    def prefetch(self, mesh: TetMesh) -> None:
        """Start building ``mesh``'s records and walk check in the background (unless held or under way)."""
        if (mesh is self._mesh and self._records is not None) or (self._prefetch and self._prefetch.mesh is mesh):
            return
        self._prefetch = Prefetch(mesh)

    def settle(self, mesh: TetMesh, keep: bool, upload: bool = False) -> None:
        """Wait for a prefetch of ``mesh`` (its walk check is then cached), and drop it
        unless ``keep`` (the mesh goes to projected tetrahedra), with the records it put on
        the GL. ``upload``: put the records on the GL as soon as they are built, while the
        walk check finishes, where its first findings leave the walk possible."""
        pending = self._prefetch
        if pending is None or pending.mesh is not mesh:
            return
        if upload and pending.records.exception() is None:  # waits for the records
            distinct = pending.records.result()[0]
            if (self._holds(distinct.mesh) and not distinct.n_conflicting
                    and not face_adjacency(distinct.mesh).n_nonmanifold_faces):
                self._use_mesh(mesh)
                self._unused = mesh
        pending.check.exception()  # waits; an error is raised where the check is taken
        if self._unused is mesh:
            release_free_memory()  # the check's temporaries, freed while the records went to the GL
        if self._mesh is mesh:
            self._prefetch = None  # taken
        if not keep:
            self._prefetch = None
            self.drop_unused(mesh)

    def drop_unused(self, mesh: TetMesh) -> None:
        """Release ``mesh``'s records if :meth:`settle` put them on the GL and no frame used them."""
        if self._unused is mesh and self._mesh is mesh:
            self._drop_mesh()
        self._unused = None

    def _holds(self, mesh: TetMesh) -> bool:
        """Whether one texture of this GL holds the records of ``mesh``'s tets and points."""
        return max(mesh.n_tets, mesh.n_points) <= raymarch_capacity(int(self.ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384)))

    def _drop_mesh(self) -> None:
        """Release the records on the GL."""
        for obj in [*self._vaos.values(), *self._textures.values(), *self._faces]:
            obj.release()
        self._vaos.clear()
        self._textures, self._faces = {}, []
        self._mesh = self._walked = self._records = None

    def _use_mesh(self, mesh: TetMesh) -> tuple[TetMesh, MarchRecords]:
        """The mesh the walk goes through (``mesh`` with each repeated cell once) and its
        records, on the GL."""
        if mesh is self._mesh and self._records is not None:
            assert self._walked is not None
            return self._walked, self._records
        self._drop_mesh()
        pending = self._prefetch
        if pending is not None and pending.mesh is mesh:
            distinct, rec = pending.records.result()
            if pending.check.done():
                self._prefetch = None
        else:
            self._prefetch = None
            distinct, rec = records(mesh)
        release_free_memory()  # the walk check's temporaries, before the textures take their place
        given, mesh = mesh, distinct.mesh
        max_tex = int(self.ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384))
        if not self._holds(mesh):
            raise MemoryError(f"the ray caster holds at most {raymarch_capacity(max_tex)} tets and points in one texture "
                              f"on this GL (GL_MAX_TEXTURE_SIZE {max_tex}); the mesh has {mesh.n_tets} tets, "
                              f"{mesh.n_points} points: use "
                              f"method=\"projected\" or split it into bricks (tetvr.order.cull.submesh)")
        layout = Layout.of(max_tex)
        # The points' positions are written per view (_write_points): padded to whole rows here.
        self._points = np.zeros((-(-mesh.n_points // layout.items) * layout.items, 4), dtype=np.float32)
        self._points[:mesh.n_points, 3] = mesh.scalars
        self._points_eye = None
        self._textures, self._jumps = records_textures(self.ctx, layout, mesh, rec, distinct.copies)
        self._textures[POINTS_IMAGE] = texture(self.ctx, self._points, layout.items, 1, 0.0)
        pos = self.ctx.buffer(np.ascontiguousarray(rec.boundary_triangles, dtype=np.float32).tobytes())
        slots = self.ctx.buffer(np.repeat(rec.boundary_slots.astype(np.int32), 3).tobytes())
        self._faces = [pos, slots]
        self._shifts = layout.defines
        # Kept for the views: the boundary faces; each tet's point ids are on the GL alone.
        rec = dataclasses.replace(rec, ids=None)
        self._mesh, self._walked, self._records = given, mesh, rec
        return mesh, rec

    def _write_points(self, mesh: TetMesh, rec: MarchRecords, inv_view: NDArray[np.float64]) -> None:
        """The points relative to the eye, for the walk (march.frag): in float64 first,
        so that float32 keeps their precision near the eye wherever the mesh's centre is."""
        eye = rec.origin + inv_view[:3, 3]
        if self._points_eye is not None and np.array_equal(eye, self._points_eye):
            return
        self._points[:mesh.n_points, :3] = mesh.points - eye
        self._textures[POINTS_IMAGE].write(self._points)
        self._points_eye = eye

    # ---- per size ----
    def _target(self, size: tuple[int, int]) -> dict[str, Any]:
        from tetvr.gl.util import cached_targets

        return cached_targets(self.ctx, self._targets, size, self._make_target)

    def _make_target(self, size: tuple[int, int], t: dict[str, Any]) -> None:
        ctx = self.ctx
        t.update(entry=ctx.texture(size, 1, dtype="i4"), depth=ctx.depth_texture(size))
        t["depth"].compare_func = ""
        t["entry_fbo"] = ctx.framebuffer(color_attachments=[t["entry"]], depth_attachment=t["depth"])
        for side in "ab":
            t[f"color_{side}"] = ctx.texture(size, 4, dtype="f4")
            t[f"state_{side}"] = ctx.texture(size, 2, dtype="f4")
            t[f"last_{side}"] = ctx.texture(size, 1, dtype="i4")
            # With the entry depths: march passes run where the depth test passes (march.frag).
            t[f"fbo_{side}"] = ctx.framebuffer(color_attachments=[t[f"color_{side}"], t[f"state_{side}"],
                                                                  t[f"last_{side}"]], depth_attachment=t["depth"])
        for name, tex in t.items():
            if "fbo" not in name:
                tex.filter = (NEAREST, NEAREST)

    # ---- the frame ----
    def render(self, mesh: TetMesh, camera: Camera, size: tuple[int, int], uniforms: dict[str, Any],
               table_uniforms: dict[str, Any], defines: dict[str, int], clock: Any, window: Any = None
               ) -> NDArray[np.float32]:
        """Premultiplied RGBA, (height, width, 4), row 0 at the top; ``window`` a
        :class:`~tetvr.gl.surfaces.RayWindow` (clip planes, ray limit) or None."""
        self._unused = None
        return self._frame(mesh, camera, size, uniforms, table_uniforms, dict(defines, EXTENT=0), clock, window)

    def extent(self, mesh: TetMesh, camera: Camera, size: tuple[int, int], uniforms: dict[str, Any],
               clock: Any) -> NDArray[np.float32]:
        """Per pixel (first entry depth, last exit depth, segments walked, 0); (3e38, -3e38)
        where no ray enters the mesh."""
        self._unused = None
        defines = dict(TABLE_NORMALIZED=1, TABLE_CUBIC=0, EXTENT=1)
        return self._frame(mesh, camera, size, uniforms, {}, defines, clock)

    def _frame(self, mesh: TetMesh, camera: Camera, size: tuple[int, int], uniforms: dict[str, Any],
               table_uniforms: dict[str, Any], defines: dict[str, int], clock: Any, window: Any = None
               ) -> NDArray[np.float32]:
        """One frame: the first layer's entries, then march passes, each followed by a peel
        pass where rays go on without an entry list; the last march pass's colour read back."""
        import moderngl

        ctx = self.ctx
        mesh, rec = self._use_mesh(mesh)
        clock.lap("upload")
        perspective = int(not camera.parallel_projection)
        view = np.asarray(uniforms["u_view"], dtype=np.float64)
        common = dict(u_view=view, u_proj=uniforms["u_proj"], u_inv_view=np.linalg.inv(view),
                      u_ray_scale=uniforms["u_ray_scale"], u_viewport=(float(size[0]), float(size[1])),
                      u_near=uniforms["u_near"], u_far=uniforms["u_far"],
                      u_tolerance=1e-6 * float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0])))
        t = self._target(size)
        if self._suspects is None:
            self._suspects = ctx.buffer(reserve=4 * (1 + SUSPECT_LENGTH))
        self._suspects.write(b"\0" * 4)
        self._suspects.bind_to_storage_buffer(SUSPECT_BUFFER)
        self._write_points(mesh, rec, common["u_inv_view"])
        for unit, tex in self._textures.items():
            tex.bind_to_image(unit, read=True, write=False)
        ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        listed, rim, n_near_cells = self._first_entries(t, mesh, rec, camera, size, common, perspective,
                                                        bool(defines.get("EXTENT")))
        clock.lap("entry")

        march_defines = dict(defines, **self._shifts, PERSPECTIVE=perspective, CELL_DATA=int(mesh.cell_data),
                             MULTIPLICITY=int(COPIES_IMAGE in self._textures), JUMPS=int(self._jumps),
                             **(window.defines if window is not None else {}))
        samplers = dict(u_entry=4, u_color_in=5, u_state_in=6, u_last_in=7, u_state=5, u_last=7)
        steps = dict(u_max_steps=int(min(mesh.n_tets + 1, 1 << 30)), u_opaque=1.0 - OPAQUE_REMAINDER,
                     u_slack=_slack(mesh, camera))
        march_uniforms = {**common, **table_uniforms, **samplers, **steps}
        src, dst = "b", "a"
        layers, exhausted = 0, False
        for layer in range(MAX_LAYERS):
            self._march_pass(t, src, dst, layer, listed, march_defines, march_uniforms, window, perspective)
            layers += 1
            src, dst = dst, src
            clock.lap("march")
            if rec.convex:
                break  # a ray that leaves a convex mesh does not enter it again: no peel
            if listed:  # the march picked the next entries: another pass if any ray has one
                ctx.memory_barrier()
                if self._counters[1].read() == b"\0" * 4:
                    break
                continue
            self._peel(t, src, rim, perspective, common, samplers)
            clock.lap("entry")
            if self._query.samples == 0:
                break
        else:
            exhausted = True
        if rim is not None:
            rim.release()
        n_suspect, suspects = self._read_suspects()
        if exhausted:  # rays that would enter again: traced again exactly, never cut off
            suspects = np.union1d(suspects, _pending_entries(t))
            n_suspect = max(n_suspect, int(suspects.size))  # beyond the list's length if the march's overflowed
        self.frames += 1
        self.last_stats = MarchStats(layers=layers, layers_exhausted=exhausted, entry_list=listed,
                                     n_near_cells=n_near_cells, n_rim_faces=rim.n_faces if rim is not None else 0,
                                     n_suspect=n_suspect, suspect_pixels=suspects)
        raw = t[f"color_{src}"].read()
        clock.lap("readback")
        return np.frombuffer(raw, dtype=np.float32).reshape(size[1], size[0], 4)[::-1].copy()

    def _read_suspects(self) -> tuple[int, NDArray[np.int64]]:
        """The frame's count of rays whose walk went wrong, and their pixels (unique)."""
        self.ctx.memory_barrier()
        n = int(np.frombuffer(self._suspects.read(4), dtype=np.uint32)[0])
        if n == 0:
            return 0, np.zeros(0, np.int64)
        listed = np.frombuffer(self._suspects.read(4 * min(n, SUSPECT_LENGTH), offset=4), dtype=np.uint32)
        return n, np.unique(listed.astype(np.int64))

    def _first_entries(self, t: dict[str, Any], mesh: TetMesh, rec: MarchRecords, camera: Camera,
                       size: tuple[int, int], common: dict[str, Any], perspective: int, extent: bool
                       ) -> tuple[bool, Rim | None, int]:
        """Layer 1's entry pass: boundary faces and the cells the near plane cuts. Returns
        whether the march passes read an entry list, this view's rim faces and the number
        of cells the near plane cut."""
        import moderngl

        ctx = self.ctx
        # The first march pass's targets keep what a pixel no ray enters shows (its state:
        # done), since the pass runs only where the entry pass leaves a depth below 1.
        near_ids, rects = near_plane_cells(mesh, camera, size[0] / size[1])
        # A pixel wider on every side: the rasteriser may leave out a pixel whose centre lies
        # within its snapping of a rectangle's edge; the fragments test the tet exactly.
        rects = np.clip(rects + np.array([-2.0 / size[0], -2.0 / size[1], 2.0 / size[0], 2.0 / size[1]]), -1.0, 1.0)
        t["fbo_a"].clear(*((3.0e38, -3.0e38, 0.0, 0.0) if extent else (0.0, 0.0, 0.0, 0.0)), depth=1.0)
        self._clear_entries(t)  # not read where no entry is drawn, but left stale llvmpipe marched 3-4x slower
        t["entry_fbo"].use()
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.depth_func = "<"
        listed = self._start_list(t, rec)
        face_prog = self._entry_program(perspective, listed=listed)
        self._set(face_prog, common)
        rim = self._rim_buffers(mesh, rec, camera, size)
        self._draw_faces(face_prog, rim)
        near_buffers: list[Any] = []
        if near_ids.size:
            near_prog = self._entry_program(perspective, near_cells=1)
            self._set(near_prog, common)
            near_buffers = [ctx.buffer(rect_triangles(rects).tobytes()),
                            ctx.buffer(np.repeat(near_ids.astype(np.int32), 6).tobytes())]
            vao = ctx.vertex_array(near_prog, [(near_buffers[0], "2f", "in_pos"), (near_buffers[1], "1i", "in_id")])
            vao.render(moderngl.TRIANGLES)
            vao.release()
        for b in near_buffers:
            b.release()
        self._draw_rim(rim, perspective, 0, common, {}, listed=listed)
        ctx.disable(moderngl.DEPTH_TEST)
        if listed:
            ctx.memory_barrier()
            listed = self._counters[0].read() == b"\0" * 4  # no pixel overflowed the list: use it
        if listed:  # for the march passes to read
            self._counters[1].bind_to_storage_buffer(MORE_BUFFER)
            t["count"].bind_to_image(COUNT_IMAGE, read=True, write=False)
            t["list"].bind_to_image(LIST_IMAGE, read=True, write=False)
        return listed, rim, int(near_ids.size)

    def _march_pass(self, t: dict[str, Any], src: str, dst: str, layer: int, listed: bool,
                    march_defines: dict[str, int], march_uniforms: dict[str, Any], window: Any,
                    perspective: int) -> None:
        """One full-screen march pass (march.frag) from set ``src``'s targets into ``dst``'s,
        run only where a ray enters (the depth test before the shader)."""
        import moderngl

        march = self.owner._program("march", **march_defines, FIRST=int(layer == 0), LIST=int(listed),
                                    LIST_LENGTH=LIST_LENGTH, AT_FAR=1)
        self._set(march, march_uniforms)
        if listed:
            self._counters[1].write(b"\0" * 4)
        if window is not None:
            window.bind(march)
        t["entry"].use(4)
        t[f"color_{src}"].use(5)
        t[f"state_{src}"].use(6)
        t[f"last_{src}"].use(7)
        t[f"fbo_{dst}"].use()
        # Only where a ray enters: the first layer's entry depths (below 1), or the rays
        # the mark pass found going on; the depth test runs before the shader.
        chosen = layer == 0 or listed
        if chosen and layer > 0:
            self._mark(t, dst, perspective)
        if chosen:
            self.ctx.enable(moderngl.DEPTH_TEST)
            self.ctx.depth_func = ">"
            t[f"fbo_{dst}"].depth_mask = False
        self._fullscreen(march)
        if chosen:
            self.ctx.disable(moderngl.DEPTH_TEST)
            t[f"fbo_{dst}"].depth_mask = True

    def _peel(self, t: dict[str, Any], src: str, rim: Rim | None, perspective: int, common: dict[str, Any],
              samplers: dict[str, Any]) -> None:
        """Peel: the next entry behind where each ray of set ``src`` left the mesh, if any
        ray did; the occlusion query counts the samples (none: no ray enters again)."""
        import moderngl

        ctx = self.ctx
        peel = self._entry_program(perspective, peel=1)
        self._set(peel, {**common, **samplers})
        t[f"state_{src}"].use(5)
        t[f"last_{src}"].use(7)
        t["entry_fbo"].use()
        t["entry_fbo"].clear(depth=1.0)
        self._clear_entries(t)  # this march runs on every pixel (march.frag reads NO_ENTRY)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.depth_func = "<"
        if self._query is None:
            self._query = ctx.query(samples=True)
        with self._query:
            self._draw_faces(peel, rim)
            self._draw_rim(rim, perspective, 1, common, samplers)
        ctx.disable(moderngl.DEPTH_TEST)

    def _rim_buffers(self, mesh: TetMesh, rec: MarchRecords, camera: Camera,
                     size: tuple[int, int]) -> Rim | None:
        """This view's :func:`~tetvr.mesh.records.rim_faces` on the GL, or None without any."""
        idx, rects, exclusive = rim_faces(rec, camera, size)
        if idx.size == 0:
            return None
        tri = mesh.points[rec.boundary_corners[idx]] - rec.origin  # (n, 3, 3) float64
        per_face = np.repeat(tri.reshape(-1, 1, 9), 6, axis=1)
        slots = np.repeat(rec.boundary_slots[idx].astype(np.int32), 6)
        drawn = np.ones(rec.boundary_slots.shape[0], dtype=bool)
        drawn[idx[exclusive]] = False
        indices = (3 * np.flatnonzero(drawn)[:, None] + np.arange(3)).astype(np.uint32).reshape(-1)
        return Rim(rects=self.ctx.buffer(rect_triangles(rects).tobytes()),
                    corners=self.ctx.buffer(per_face.tobytes()),
                    slots=self.ctx.buffer(slots.tobytes()), drawn=self.ctx.buffer(indices.tobytes() or b"\0" * 4),
                    n_faces=int(idx.size), n_drawn=int(indices.size))

    def _draw_rim(self, rim: Rim | None, perspective: int, peel: int, common: dict[str, Any],
                  samplers: dict[str, Any], listed: bool = False) -> None:
        import moderngl

        if rim is None:
            return
        prog = self._entry_program(perspective, peel=peel, rim=1, listed=listed)
        self._set(prog, {**common, **samplers, "u_inv_view_d": common["u_inv_view"],
                         "u_ray_scale_d": common["u_ray_scale"]})
        vao = self.ctx.vertex_array(prog, [(rim.rects, "2f", "in_pos"),
                                           (rim.corners, "3f8 3f8 3f8", "in_c0", "in_c1", "in_c2"),
                                           (rim.slots, "1i", "in_id")])
        vao.render(moderngl.TRIANGLES)
        vao.release()

    def _entry_program(self, perspective: int, near_cells: int = 0, peel: int = 0, rim: int = 0,
                       listed: bool = False) -> Any:
        """march_entry's program for this mesh's record layout (see the shader's defines)."""
        return self.owner._program("march_entry", **self._shifts, PERSPECTIVE=perspective, NEAR_CELLS=near_cells,
                                   PEEL=peel, RIM=rim, LIST=int(listed), LIST_LENGTH=LIST_LENGTH)

    def _clear_entries(self, t: dict[str, Any]) -> None:
        """The entry target to NO_ENTRY (march_common.glsl), -1, before a peel pass (a clear
        of an integer target with a float colour is undefined)."""
        entry = t["entry"]
        entry.write(np.full(entry.width * entry.height, -1, dtype=np.int32).tobytes())

    def _mark(self, t: dict[str, Any], dst: str, perspective: int) -> None:
        """march_mark.frag: the last march pass's targets (bound to units 5-7) copied to
        set ``dst``'s, depth 0 where a ray goes on and 1 elsewhere, for the next march pass."""
        import moderngl

        mark = self.owner._program("march_mark", **self._shifts, PERSPECTIVE=perspective)
        self._set(mark, dict(u_color_in=5, u_state_in=6, u_last_in=7))
        t[f"fbo_{dst}"].use()
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.depth_func = "1"
        self._fullscreen(mark)
        self.ctx.disable(moderngl.DEPTH_TEST)

    def _start_list(self, t: dict[str, Any], rec: MarchRecords) -> bool:
        """Clear and bind the first entry pass's list (march_entry.frag, LIST); False where
        no list is kept: a convex mesh (no ray enters twice), or a frame too tall for one or
        larger than :data:`LIST_MAX_BYTES` allows."""
        width, height = t["entry"].size
        if (rec.convex or height * LIST_LENGTH > int(self.ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384))
                or width * height * (4 + 8 * LIST_LENGTH) > LIST_MAX_BYTES):
            return False
        if "count" not in t:  # LIST_LENGTH rows of pixels
            t["count"] = self.ctx.texture((width, height), 1, dtype="u4")
            t["list"] = self.ctx.texture((width, height * LIST_LENGTH), 2, dtype="i4")
        if not self._counters:
            self._counters = [self.ctx.buffer(reserve=4), self.ctx.buffer(reserve=4)]
        count = t["count"]
        self.ctx.memory_barrier()
        count.write(bytes(count.width * count.height * 4))
        count.bind_to_image(COUNT_IMAGE, read=True, write=True)
        t["list"].bind_to_image(LIST_IMAGE, read=False, write=True)
        self._counters[0].write(b"\0" * 4)
        self._counters[0].bind_to_storage_buffer(OVERFLOW_BUFFER)
        return True

    def _set(self, prog: Any, uniforms: dict[str, Any]) -> None:
        from tetvr.gl.util import set_uniforms

        set_uniforms(prog, **uniforms)

    def _draw_faces(self, prog: Any, rim: Rim | None) -> None:
        """The boundary faces that face the eye, but for this view's rim faces (``rim``,
        :meth:`_rim_buffers`): the GL culls the others before they are rasterised (they are
        wound counter-clockwise seen from outside), and the shader drops the few whose
        winding the rounding of their projection turned (faces seen nearly edge-on,
        which are rim faces or covered by their neighbours)."""
        import moderngl

        self.ctx.front_face = "ccw"
        self.ctx.enable(moderngl.CULL_FACE)
        # No clipping at the near plane: a face it cuts is drawn whole, and the shader keeps
        # what lies past it. Clipped by the GL, a ray entering within a rounding past the
        # near plane lay on the clipped edge, which the rasteriser may leave out, and started
        # in none of the near plane's cells either (it is a rounding outside them).
        self.ctx.enable_direct(GL_DEPTH_CLAMP)
        if rim is not None:
            vao = self.ctx.vertex_array(prog, [(self._faces[0], "3f", "in_pos"), (self._faces[1], "1i", "in_id")],
                                        index_buffer=rim.drawn, index_element_size=4)
            if rim.n_drawn:
                vao.render(moderngl.TRIANGLES, vertices=rim.n_drawn)
            vao.release()
        else:
            self._faces_vao(prog).render(moderngl.TRIANGLES)
        self.ctx.disable_direct(GL_DEPTH_CLAMP)
        self.ctx.disable(moderngl.CULL_FACE)

    def _faces_vao(self, prog: Any) -> Any:
        vao = self._vaos.get(id(prog))
        if vao is None:
            vao = self._vaos[id(prog)] = self.ctx.vertex_array(
                prog, [(self._faces[0], "3f", "in_pos"), (self._faces[1], "1i", "in_id")])
        return vao

    def _fullscreen(self, prog: Any) -> None:
        import moderngl

        key = ("fullscreen", id(prog))
        vao = self._vaos.get(key)
        if vao is None:
            vao = self._vaos[key] = self.ctx.vertex_array(prog, [])
        vao.render(moderngl.TRIANGLES, vertices=3)


def _pending_entries(t: dict[str, Any]) -> NDArray[np.int64]:
    """The pixels (GL rows, row 0 at the bottom) whose ray the last peel pass found another
    entry for: after :data:`MAX_LAYERS` layers, the rays the march would cut off."""
    depth = np.frombuffer(t["depth"].read(), dtype=np.float32)
    return np.flatnonzero(depth < 1.0).astype(np.int64)

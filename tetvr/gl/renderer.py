"""The GPU renderer: one object owns the context and all GL objects, for both methods.

Projected tetrahedra (``method="projected"``). Per mesh (once): points and tets go to
shader storage buffers. Per transfer function (once): the pre-integration table goes to a
3D texture. Per view: the CPU sorts the cells and uploads the order; ``classify.comp``
classifies the cells in drawing order and writes each one's finished fan vertices into a
vertex buffer; one draw call per batch passes them through (``tet.vert``) to fragments that
look up the table (``tet.frag``) and blend back to front into an RGBA32F target, which is
read back. Tet marching (``method="raymarch"``, the default through ``"auto"``) is
:mod:`tetvr.gl.raymarch` on the same context and table; :func:`tetvr.order.method.choose` picks.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Iterator

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera, resolve_clipping_range, union_bounds
from tetvr.core.clip import Clip, check_clip
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.preintegrate import table_for
from tetvr.optics.table import PreintegrationTable
from tetvr.optics.tablesize import resolve as resolve_table_size, segment_sample
from tetvr.order.precision import check_float32_range, check_view_precision, float32_clipping_range
from tetvr.settings import RenderSettings
from tetvr.order.cull import gpu_scalar_margin, visible_cells
from tetvr.order.sort import sort_with_stats
from tetvr.optics.transfer import TransferFunction
from tetvr.gl.context import create_context, describe
from tetvr.gl.interpolation import exactness_defines
from tetvr.gl.shaders import ShaderCompileError, assemble, explain
from tetvr.order.method import choose, march_fits
from tetvr.gl.projected import ProjectedCells, depth_pass, exact_runs
from tetvr.gl.framesize import frame_method
from tetvr.gl.raymarch import Marcher, raymarch_capacity
from tetvr.gl.selfcheck import retrace, retrace_extent
from tetvr.gl.vtkpt import VTKParity, vtk_depth_order
from tetvr.gl.surfaces import RayWindow, SurfacePass
from tetvr.gl.tablebuild import TableRuns
from tetvr.core.surface import Surface, check_surfaces
from tetvr.gl.util import (Clock, GLOwner, check_size, clear_gl_errors, gl_locked, locked, make_target, set_uniforms,
                   table_texture, tf_points_texture)

__all__ = ["Renderer", "FrameStats"]

#: Texture unit of the transfer function's points (integration="exact"); 0-9 are taken
#: (the table, the ray caster's records and targets, the warp, the ray limit).
TF_POINTS_UNIT = 10


@dataclasses.dataclass(frozen=True)
class FrameStats:
    """Counts and stage times (seconds) of the last frame; times need ``profile=True``."""

    n_tets: int = 0
    size: tuple[int, int] = (0, 0)
    cycle_breaks: int = 0  # visibility cycles the sort had to break (MPVONC)
    n_culled: int = 0  # cells dropped before drawing (RenderSettings.cull)
    upload: float = 0.0
    classify: float = 0.0
    sort: float = 0.0
    order_upload: float = 0.0
    table: float = 0.0
    setup: float = 0.0  # program choice, uniforms, target clear
    draw: float = 0.0
    entry: float = 0.0  # tet marching: the entry (boundary) passes
    march: float = 0.0  # tet marching: the march passes
    readback: float = 0.0

    @property
    def total(self) -> float:
        return sum(getattr(self, f.name) for f in dataclasses.fields(self) if f.type in (float, "float"))


class Renderer(GLOwner):
    """Renders tetrahedral meshes on the GPU; reuse one for many frames.

    Parameters
    ----------
    settings : method settings (table size, sort, interpolation).
    profile : wait for the GPU after each stage so :attr:`last_stats` holds stage times.
    chunk_tets : the most tets drawn at once (default 600,000, capped by the GL's storage
        buffer size); larger meshes are classified and drawn in sorted chunks.
    device : the EGL device (GPU) its context is made on (:func:`tetvr.gl.context.create_context`);
        None: the driver's first.

    One renderer holds one GL context. It may be shared by threads: each call takes the
    context's lock and makes the context current for its duration, so a second thread waits
    for the first and both get the frames they would get alone (moderngl holds Python's
    interpreter lock while the GL draws; the Jupyter viewer renders in a child process).

    Examples
    --------
    >>> with Renderer() as r:                                  # doctest: +SKIP
    ...     image = r.render(mesh, camera, tf, size=(256, 256))
    """

    def __init__(self, settings: RenderSettings | None = None, *, profile: bool = False,
                 chunk_tets: int | None = None, device: int | None = None) -> None:
        # Arguments are checked before the context is made: a refused one leaks nothing.
        settings = RenderSettings() if settings is None else settings
        if not isinstance(settings, RenderSettings):
            hint = " (for a dict of fields, pass RenderSettings.from_dict(it))" if isinstance(settings, dict) else ""
            raise TypeError(f"settings must be a RenderSettings or None, got {type(settings).__name__}{hint}")
        if chunk_tets is not None and not (isinstance(chunk_tets, int) and not isinstance(chunk_tets, bool) and chunk_tets >= 1):
            raise ValueError(f"chunk_tets must be a positive integer, got {chunk_tets!r}")
        self.settings = settings
        self.profile = bool(profile)
        self.ctx: Any = create_context(device)
        self.gl_info = describe(self.ctx)
        self._programs: dict[tuple[str, ...], Any] = {}
        self._cells = ProjectedCells(self, chunk_tets)  # projected tetrahedra's buffers (no GL object yet)
        self._marcher: Marcher | None = None  # the tet-marching ray caster's GL state, made on first use
        self._parity = VTKParity(self)  # VTK parity's GL state (optics="vtk"; no GL object yet)
        self._surfaces: SurfacePass | None = None  # the opaque surfaces' GL state, made on first use
        self._table: PreintegrationTable | None = None  # the table in the texture
        self._table_cache: tuple[tuple[Any, ...], PreintegrationTable] | None = None  # table()'s last (key, table)
        self._table_tex: Any = None
        self._tf_points: tuple[TransferFunction, Any] | None = None  # integration="exact": (tf, its points)
        self._targets: dict[tuple[tuple[int, int], int, str], Any] = {}
        self._clock = Clock(self.ctx, False)
        self.last_stats = FrameStats()
        self._released = False

    # ---- lifetime (GLOwner: release(), the context manager) ----
    def _forget(self) -> None:
        self._programs.clear()
        self._cells.forget()
        self._targets.clear()
        self._table_tex = self._tf_points = None
        self._table = self._table_cache = None
        if self._marcher is not None:
            self._marcher.forget()
        self._parity.forget()
        if self._surfaces is not None:
            self._surfaces.forget()

    def _gl_objects(self) -> list[Any]:
        objs = [*self._cells.gl_objects(), *self._programs.values(), *self._parity.gl_objects()]
        if self._marcher is not None:
            objs += self._marcher.gl_objects()
        if self._surfaces is not None:
            objs += self._surfaces.gl_objects()
        if self._tf_points is not None:
            objs.append(self._tf_points[1])
        if self._table_tex is not None:
            objs.append(self._table_tex)
        for fbo in self._targets.values():
            objs += [fbo, *fbo.color_attachments]
        return objs

    @locked
    def gpu_bytes(self) -> int:
        """Bytes of GPU memory held in this renderer's buffers, table and targets."""
        total = self._cells.gpu_bytes()
        if self._table is not None:
            total += self._table.data.nbytes
        for (size, components, dtype) in self._targets:
            total += size[0] * size[1] * components * (4 if dtype == "f4" else 1)
        total += sum(part.gpu_bytes() for part in (self._marcher, self._parity, self._surfaces) if part is not None)
        return int(total)

    # ---- programs ----
    @gl_locked  # tests and tools call it directly
    def _program(self, kind: str, **defines: int) -> Any:
        defines.update(exactness_defines(self.ctx))  # shaders/filter.glsl, shaders/fan_varyings.glsl
        key = (kind, *(f"{k}={v}" for k, v in sorted(defines.items())))
        prog = self._programs.get(key)
        if prog is not None:
            return prog
        programs = {"classify": {"compute_shader": "classify.comp"},
                    "tet": {"vertex_shader": "tet.vert", "fragment_shader": "tet.frag"},
                    # VTK parity (optics="vtk", tetvr.gl.vtkpt): VTK's projected tetrahedra.
                    "classify_vtk": {"compute_shader": "classify_vtk.comp"},
                    "vtk_pt": {"vertex_shader": "vtk_pt.vert", "fragment_shader": "vtk_pt.frag"},
                    "floor": {"vertex_shader": "tet.vert", "fragment_shader": "floor.frag"},
                    "depth": {"vertex_shader": "tet.vert", "fragment_shader": "depth.frag"},
                    "march_entry": {"vertex_shader": "march_entry.vert", "fragment_shader": "march_entry.frag"},
                    "march": {"vertex_shader": "raycast.vert", "fragment_shader": "march.frag"},
                    "march_mark": {"vertex_shader": "raycast.vert", "fragment_shader": "march_mark.frag"},
                    "surface": {"vertex_shader": "surface.vert", "fragment_shader": "surface.frag"},
                    "table_runs": {"compute_shader": "table_runs.comp"}}
        if kind not in programs:
            raise ValueError(f"unknown shader {kind!r}; choose one of {sorted(programs)}")
        stages = programs[kind]
        sources: dict[str, str] = {}
        all_files: list[str] = []
        try:
            for stage, name in stages.items():
                src, files = assemble(name, defines)
                sources[stage] = src
                all_files = files
                if stage == "compute_shader":
                    prog = self.ctx.compute_shader(src)
            if prog is None:
                prog = self.ctx.program(**sources)
        except Exception as exc:
            if isinstance(exc, ShaderCompileError):
                raise
            raise ShaderCompileError(f"{kind} ({', '.join(stages.values())}): {explain(exc, all_files)}") from exc
        self._programs[key] = prog
        return prog

    # ---- per-mesh, per-table, per-size state ----
    @property
    def chunk_tets(self) -> int:
        """The most tets classified and drawn at once; larger meshes are drawn in sorted chunks."""
        return self._cells.chunk_tets

    def _chunks(self, mesh: TetMesh, order: NDArray[np.uint32]) -> Iterator[int]:
        """Make each chunk of ``mesh``'s drawing order current in turn (:meth:`ProjectedCells.chunks`)."""
        return self._cells.chunks(order, self._clock)

    def _use_table(self, table: PreintegrationTable) -> None:
        if table is self._table:
            return
        if self._table_tex is not None:
            self._table_tex.release()
        self._table_tex = table_texture(self.ctx, table)
        self._table = table

    def _use_target(self, size: tuple[int, int], components: int, dtype: str = "f4") -> Any:
        """The framebuffer of this size, channel count and type (made once, then reused)."""
        key = (size, components, dtype)
        fbo = self._targets.get(key)
        if fbo is not None:
            return fbo
        if len(self._targets) >= 4:
            # Bind the default framebuffer first: deleting the bound one leaves GL pointing
            # at a dead name, and the next framebuffer's creation reports INVALID_OPERATION.
            self.ctx.detect_framebuffer(0).use()
            for old in self._targets.values():
                tex = old.color_attachments[0]
                old.release()
                tex.release()
            self._targets.clear()
        _, fbo = make_target(self.ctx, size, components, dtype)  # nothing left behind if it fails
        self._targets[key] = fbo
        return fbo

    # ---- the frame ----
    @locked
    def table(self, mesh: TetMesh, tf: TransferFunction) -> PreintegrationTable:
        """The pre-integration table this renderer uses for a mesh and transfer function.

        The renderer keeps the last table it returned, so a frame with the same inputs
        reuses it whatever other renderers did to the shared cache of :func:`table_for`.
        """
        s = self.settings
        auto = "auto" in (s.table_scalar_bins, s.table_thickness_slices)
        # The settings may be replaced between frames; an "auto" size also depends on the
        # mesh's cells (its segment sample), not only on the scalar range and longest edge.
        key = (s, tf, mesh.scalar_range, mesh.max_edge, segment_sample(mesh) if auto else None)
        if self._table_cache is not None and self._table_cache[0] == key:
            return self._table_cache[1]
        size = resolve_table_size(s, tf, mesh)
        table = table_for(tf, mesh.scalar_range, mesh.max_edge, n_bins=size.n_bins, n_slices=size.n_slices,
                          log_base=size.log_base, encoding=s.table_encoding, dtype=s.table_dtype, optics=s.optics,
                          align_nodes=s.table_align_nodes, warp=size.warp,
                          runs=TableRuns(self.ctx, lambda ring: self._program("table_runs", RING=ring)))
        self._table_cache = (key, table)
        return table

    def _view_uniforms(self, mesh: TetMesh, camera: Camera, size: tuple[int, int]) -> dict[str, Any]:
        """Upload the mesh if new; the uniforms of this view."""
        self._cells.use_mesh(mesh)
        self._clock.lap("upload")
        view = camera.view_matrix()
        view[:3, 3] += view[:3, :3] @ self._cells.centre  # the buffers hold points minus the centre
        near, far = camera.near_far()
        proj = camera.projection_matrix(size[0] / size[1])
        return dict(u_view=view, u_proj=proj, u_perspective=0 if camera.parallel_projection else 1,
                    u_half_px=(size[0] / 2.0, size[1] / 2.0),
                    u_near=near, u_far=far, u_ray_scale=(1.0 / float(proj[0, 0]), 1.0 / float(proj[1, 1])))

    def _classify(self, n_tets: int, uniforms: dict[str, Any], *, perspective_correct: int,
                  count_exact: bool = False, program: Any = None) -> range:
        """Classify the first ``n_tets`` cells of the current chunk (:meth:`ProjectedCells.classify`)."""
        return self._cells.classify(n_tets, uniforms, self._clock, perspective_correct=perspective_correct,
                                    count_exact=count_exact, program=program)

    def _draw(self, prog: Any, fbo: Any, n_tets: int, blend: tuple[Any, ...], first: int = 0) -> None:
        """Draw the classified fans ``first`` to ``n_tets`` into ``fbo`` (:meth:`ProjectedCells.draw`)."""
        self._cells.draw(prog, fbo, n_tets, blend, self._clock, first)

    def _read(self, fbo: Any, size: tuple[int, int], components: int, dtype: str = "f4") -> NDArray[np.float32]:
        raw = fbo.read(components=components, dtype=dtype)
        if dtype == "f1":
            flat = np.frombuffer(raw, dtype=np.uint8).astype(np.float32) / np.float32(255.0)
        else:
            flat = np.frombuffer(raw, dtype=np.float32)
        image = flat.reshape(size[1], size[0], components)[::-1].copy()
        self._clock.lap("readback")
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error after rendering: {err}")
        return image

    def _check(self, size: tuple[int, int], method: str = "projected", surfaces: bool = False) -> tuple[int, int]:
        """Start a frame: the size checked against the GL's limits and a ``method`` frame's memory
        (:mod:`tetvr.gl.framesize`) before any GL call, and the error flags a failed earlier
        frame may have left (``GL_OUT_OF_MEMORY``) cleared, so this frame's own check after
        the readback reports only this frame's errors."""
        self._check_alive()
        self._clock = Clock(self.ctx, self.profile)
        size = check_size(size, self.ctx, method=method, surfaces=surfaces)
        clear_gl_errors(self.ctx)
        return size

    @gl_locked
    def render(self, mesh: TetMesh, camera: Camera, tf: TransferFunction, *, size: tuple[int, int] = (512, 512),
               order: NDArray[np.integer[Any]] | None = None, shader: str = "tet", clip: Clip | None = None,
               surfaces: Surface | tuple[Surface, ...] | list[Surface] = ()) -> NDArray[np.float32]:
        """Render one frame.

        Parameters
        ----------
        mesh, camera, tf : the scene.
        size : (width, height) in pixels.
        order : an explicit drawing order (cell ids, back to front) instead of the sort;
            it may leave cells out (they are not drawn).
        shader : "tet" (the real thing) or "floor" (constant colour; fill-rate floor).
        clip : keep only this part of the mesh (:class:`tetvr.Clip`), cut exactly per pixel
            (VTK parity: the cells cut first, as ParaView's Clip filter cuts them; :mod:`tetvr.gl.vtkpt`).
        surfaces : opaque surfaces (:class:`tetvr.Surface`) that end the rays they meet,
            composited behind the tets in front of them (VTK parity: VTK's depth test per fragment).

        Returns
        -------
        (height, width, 4) float32 premultiplied RGBA, row 0 at the top.
        """
        self._check_alive()
        clip, surfaces = check_clip(clip), check_surfaces(surfaces)
        windowed = clip is not None or bool(surfaces)
        if windowed and shader != "tet":
            raise ValueError(f"clip and surfaces need shader='tet', got {shader!r}")
        if clip is not None and self.settings.optics == "vtk":  # ParaView's Clip filter: the cells cut first
            (mesh, order), clip = self._parity.cut(mesh, clip, order), None
        size = self._check(size, frame_method(self.settings, mesh.n_tets, order=order, shader=shader), bool(surfaces))
        camera = resolve_clipping_range(camera, union_bounds(mesh.bounds, *(s.points for s in surfaces)))  # None: VTK's
        window = RayWindow.make(clip, camera)
        if surfaces:
            if self._surfaces is None:
                self._surfaces = SurfacePass(self)
            _, limit = self._surfaces.draw(surfaces, camera, size, mesh.float32_origin)
            window = dataclasses.replace(window, limit=limit)
        frames = self._marcher.frames if self._marcher is not None else 0
        image = self._render(mesh, camera, tf, size, order, shader, window)
        if surfaces:
            assert self._surfaces is not None
            image += (1.0 - image[..., 3:4]) * self._surfaces.read_color(size)  # the tets over the surfaces
        if self._marcher is not None and self._marcher.frames != frames:  # tet marching drew it: its check
            st = self._marcher.last_stats  # (tetvr.gl.selfcheck)
            retrace(image, st.n_suspect, st.suspect_pixels, mesh, camera, tf, optics=self.settings.optics, clip=clip,
                    surfaces=surfaces)
        return image

    def _render(self, mesh: TetMesh, camera: Camera, tf: TransferFunction, size: tuple[int, int],
                order: NDArray[np.integer[Any]] | None, shader: str, window: RayWindow = RayWindow()
                ) -> NDArray[np.float32]:
        import moderngl

        check_float32_range(mesh, tf)
        check_view_precision(mesh, camera, size)
        if shader == "tet" and self.settings.optics == "vtk":
            return self._render_vtk(mesh, camera, tf, size, order, window.limit)
        if shader == "tet" and self.settings.integration == "exact":
            return self._raymarch_exact(mesh, camera, tf, size, order, window)
        if (shader == "tet" and order is None and self.settings.method != "projected"
                and not (self.settings.method == "auto" and not march_fits(mesh.n_tets))):
            # A new mesh's walk check and records, while the table is built (not for a mesh
            # "auto" sends to projected tetrahedra for its size: memory it cannot spare).
            self._march.prefetch(mesh)
        table = self.table(mesh, tf)
        self._use_table(table)
        self._clock.lap("table")
        if shader == "tet" and order is None and self._uses_raymarch(mesh, camera, size):
            return self._raymarch(mesh, camera, table, size, window)
        uniforms = self._view_uniforms(mesh, camera, size)
        order_ids, cycle_breaks, n_culled = self._drawing_order(mesh, camera, tf, size, order, table)
        self._clock.lap("sort")

        defines = dict(PERSPECTIVE_CORRECT=int(self.settings.perspective_correct),
                       TABLE_NORMALIZED=int(table.encoding == "normalized"), TABLE_WARP=int(table.nodes is not None),
                       TABLE_CUBIC=int(self.settings.table_filter == "cubic"),
                       **({"TABLE_STEPS": 1} if table.steps is not None else {}))  # lookup_steps.glsl
        if shader == "tet":
            before_near, beyond_far = _outside_clipping_range(mesh, camera)
            defines.update(CLIP_RANGE=int(before_near or beyond_far or window.active),
                           PERSPECTIVE=int(not camera.parallel_projection), **window.defines)
        # tet.frag with its exact per-fragment branch (NEAR_CROSSING) and without (exact_runs).
        progs = [self._program(shader, **defines, **({"NEAR_CROSSING": on} if shader == "tet" else {}))
                 for on in (0, 1)]
        for prog in progs:
            set_uniforms(prog, **table.gl_uniforms(), **uniforms)
            window.bind(prog)
        fb_dtype = "f4" if self.settings.framebuffer == "float32" else "f1"
        fbo = self._use_target(size, 4, fb_dtype)
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        self._table_tex.use(0)  # nothing in the loop binds another texture
        self._clock.lap("setup")
        blend = (moderngl.ONE, moderngl.ONE_MINUS_SRC_ALPHA)
        for n in self._chunks(mesh, order_ids):
            exact = self._classify(n, {**uniforms, **table.gl_uniforms()},
                                   perspective_correct=defines["PERSPECTIVE_CORRECT"], count_exact=True)
            for variant, run in exact_runs(exact, n):
                self._draw(progs[variant], fbo, run.stop, (blend, moderngl.FUNC_ADD), run.start)
        image = self._read(fbo, size, 4, fb_dtype)
        self.last_stats = FrameStats(n_tets=mesh.n_tets, size=size, cycle_breaks=cycle_breaks, n_culled=n_culled,
                                     **self._clock.laps)
        return image

    def _drawing_order(self, mesh: TetMesh, camera: Camera, tf: TransferFunction, size: tuple[int, int],
                       order: NDArray[np.integer[Any]] | None, table: PreintegrationTable | None,
                       sort: Callable[[TetMesh, Camera], NDArray[Any]] | None = None
                       ) -> tuple[NDArray[Any], int, int]:
        """The cells to draw, back to front: the sort (``settings.sort``, or ``sort``; less
        the culled cells with ``settings.cull``, which sizes its margin from ``table``) or
        the caller's order, checked. Also returns the sort's cycle breaks and the number of
        culled cells."""
        cycle_breaks = n_culled = 0
        if order is None:
            if sort is None:
                order_ids, sort_stats = sort_with_stats(mesh, camera, self.settings.sort)
                cycle_breaks = sort_stats.n_cycle_breaks
            else:
                order_ids = sort(mesh, camera)
            if self.settings.cull:
                # Sort everything, then filter: MPVONC constraints through culled cells hold.
                spacing = (table or self.table(mesh, tf)).node_spacing
                keep, _ = visible_cells(mesh, camera, tf, size=size,
                                        scalar_margin=gpu_scalar_margin(mesh, tf, node_spacing=spacing))
                mask = np.zeros(mesh.n_tets, dtype=bool)
                mask[keep] = True
                order_ids = order_ids[mask[order_ids]]
                n_culled = mesh.n_tets - int(order_ids.shape[0])
        else:
            order_ids = np.asarray(order)
            if order_ids.ndim != 1 or order_ids.shape[0] > mesh.n_tets or order_ids.dtype.kind not in "iu":
                raise ValueError(f"order must be at most {mesh.n_tets} integer cell ids, got {order_ids.dtype} "
                                 f"of shape {order_ids.shape}")
            if order_ids.size and (order_ids.min() < 0 or order_ids.max() >= mesh.n_tets
                                   or np.bincount(order_ids, minlength=mesh.n_tets).max() != 1):
                raise ValueError(f"order must list cell ids in 0..{mesh.n_tets - 1}, each at most once")
        return order_ids, cycle_breaks, n_culled

    def _render_vtk(self, mesh: TetMesh, camera: Camera, tf: TransferFunction, size: tuple[int, int],
                    order: NDArray[np.integer[Any]] | None, limit: Any) -> NDArray[np.float32]:
        """One frame in VTK parity (``optics="vtk"``): VTK's projected tetrahedra step for
        step (:mod:`tetvr.gl.vtkpt`), without the table, depth-tested against the surfaces'
        ``limit``. ``sort="auto"`` is VTK's order (:func:`~tetvr.gl.vtkpt.vtk_depth_order`); another is honoured."""
        uniforms = self._view_uniforms(mesh, camera, size)
        sort = vtk_depth_order if self.settings.sort == "auto" else None
        order_ids, cycle_breaks, n_culled = self._drawing_order(mesh, camera, tf, size, order, None, sort)
        self._clock.lap("sort")
        image = self._parity.render(mesh, tf, size, uniforms, order_ids, limit)
        self.last_stats = FrameStats(n_tets=mesh.n_tets, size=size, cycle_breaks=cycle_breaks, n_culled=n_culled,
                                     **self._clock.laps)
        return image

    @property
    def _march(self) -> Marcher:
        """The tet-marching ray caster's GL state, made on first use."""
        if self._marcher is None:
            self._marcher = Marcher(self)
        return self._marcher

    def _uses_raymarch(self, mesh: TetMesh, camera: Camera | None = None, size: tuple[int, int] | None = None) -> bool:
        """Whether frames of this mesh go to the tet-marching ray caster: what :func:`tetvr.order.method.choose`
        says, unless the records would not fit one texture of this GL (then projected tetrahedra)."""
        if self._marcher is not None:
            # The walk check choose() reads (and, meanwhile, the records on the GL: tetvr.gl.raymarch).
            upload = choose(self.settings) == "raymarch"
            self._marcher.settle(mesh, keep=upload, upload=upload)
        if choose(self.settings, mesh) != "raymarch":  # the mesh itself goes to projected tetrahedra
            if self._marcher is not None:
                self._marcher.settle(mesh, keep=False)
                self._marcher.drop_unused(mesh)
            return False
        if camera is not None and choose(self.settings, mesh, camera, size) != "raymarch":
            return False  # this view alone (the cost model): the records stay for the next that marches
        fits = mesh.n_tets <= raymarch_capacity(int(self.ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384)))
        if not fits and self.settings.method == "raymarch":
            raise MemoryError(f"the mesh has {mesh.n_tets} tets, more than the ray caster holds in one texture on "
                              f"this GL; use method=\"projected\" (or \"auto\") or split it into bricks")
        return fits

    def _march_view(self, mesh: TetMesh, camera: Camera, size: tuple[int, int]) -> tuple[Camera, dict[str, Any]]:
        """The camera the ray caster draws with (its clipping range cut to float32,
        :func:`~tetvr.order.precision.float32_clipping_range`) and its view uniforms."""
        camera = float32_clipping_range(mesh, camera)
        return camera, self._march_uniforms(mesh, camera, size)

    def _march_uniforms(self, mesh: TetMesh, camera: Camera, size: tuple[int, int]) -> dict[str, Any]:
        view = camera.view_matrix()
        view[:3, 3] += view[:3, :3] @ mesh.float32_origin  # the records are relative to it
        near, far = camera.near_far()
        proj = camera.projection_matrix(size[0] / size[1])
        return dict(u_view=view, u_proj=proj, u_near=near, u_far=far,
                    u_ray_scale=(1.0 / float(proj[0, 0]), 1.0 / float(proj[1, 1])))

    def _raymarch(self, mesh: TetMesh, camera: Camera, table: PreintegrationTable, size: tuple[int, int],
                  window: RayWindow = RayWindow()) -> NDArray[np.float32]:
        """One frame by tet marching (:mod:`tetvr.gl.raymarch`), with this renderer's table."""
        defines = dict(TABLE_NORMALIZED=int(table.encoding == "normalized"), TABLE_WARP=int(table.nodes is not None),
                       TABLE_CUBIC=int(self.settings.table_filter == "cubic"),
                       **({"TABLE_STEPS": 1} if table.steps is not None else {}))  # lookup_steps.glsl
        self._table_tex.use(0)
        return self._march_frame(mesh, camera, size, table.gl_uniforms(), defines, window)

    def _raymarch_exact(self, mesh: TetMesh, camera: Camera, tf: TransferFunction, size: tuple[int, int],
                        order: NDArray[np.integer[Any]] | None, window: RayWindow) -> NDArray[np.float32]:
        """One frame by tet marching with ``integration="exact"``: no table, the transfer
        function's control points in a texture (shaders/tf_points.glsl)."""
        if order is not None:
            raise ValueError("an explicit drawing order is for projected tetrahedra; integration='exact' marches rays")
        if not self._uses_raymarch(mesh, camera, size):  # records beyond one texture of this GL
            raise MemoryError(f"integration='exact' needs tet marching, whose records of {mesh.n_tets} tets do not "
                              f"fit one texture of this GL; use integration='table' (projected tetrahedra draw in "
                              f"chunks) or split the mesh into bricks")
        if self._tf_points is None or self._tf_points[0] != tf:
            if self._tf_points is not None:
                self._tf_points[1].release()
            self._tf_points = (tf, tf_points_texture(self.ctx, tf))
        self._tf_points[1].use(TF_POINTS_UNIT)
        self._clock.lap("table")
        uniforms = dict(u_tf_points=TF_POINTS_UNIT, u_tf_count=int(tf.breakpoints.shape[0]),
                        u_inv_unit_distance=1.0 / tf.unit_distance)
        return self._march_frame(mesh, camera, size, uniforms, dict(INTEGRATION_EXACT=1), window)

    def _march_frame(self, mesh: TetMesh, camera: Camera, size: tuple[int, int], table_uniforms: dict[str, Any],
                     defines: dict[str, int], window: RayWindow) -> NDArray[np.float32]:
        camera, uniforms = self._march_view(mesh, camera, size)
        image = self._march.render(mesh, camera, size, uniforms, table_uniforms, defines, self._clock, window)
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error after rendering: {err}")
        self.last_stats = FrameStats(n_tets=mesh.n_tets, size=size, **self._clock.laps)  # type: ignore[arg-type]
        return image

    @gl_locked
    def depth_extent(self, mesh: TetMesh, camera: Camera, *, size: tuple[int, int] = (512, 512)
                     ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        """Per pixel, the eye depth of the mesh's nearest entry and farthest exit.

        Returns ``(front, back)``, each (height, width) float32, clipped to the camera's
        clipping range; ``+inf`` / ``-inf`` where no tet covers the pixel. These are the ray
        limits for fusing the mesh with a ray-cast volume (:mod:`tetvr.fuse`).
        """
        camera = resolve_clipping_range(camera, mesh.bounds)
        if self._uses_raymarch(mesh):
            size = self._check(size, "raymarch")
            camera, uniforms = self._march_view(mesh, camera, size)
            ext = self._march.extent(mesh, camera, size, uniforms, self._clock)
            st = self._marcher.last_stats  # its pixels gone wrong, traced again (tetvr.gl.selfcheck)
            return retrace_extent(ext, st.n_suspect, st.suspect_pixels, mesh, camera)
        return self._depth_extent(mesh, camera, size)

    @gl_locked
    def segment_counts(self, mesh: TetMesh, camera: Camera, *, size: tuple[int, int] = (512, 512)
                       ) -> NDArray[np.int64]:
        """Per pixel, how many ray--tet segments tet marching walks (no early termination):
        the measure of the ray caster's work (``bench/stages.py``)."""
        size = self._check(size, "raymarch")
        camera = resolve_clipping_range(camera, mesh.bounds)
        camera, uniforms = self._march_view(mesh, camera, size)
        ext = self._march.extent(mesh, camera, size, uniforms, self._clock)
        return ext[..., 2].astype(np.int64)

    def _depth_extent(self, mesh: TetMesh, camera: Camera, size: tuple[int, int]
                      ) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
        size = self._check(size)
        uniforms = self._view_uniforms(mesh, camera, size)
        return depth_pass(self, mesh, size, uniforms, perspective=int(not camera.parallel_projection))


def _outside_clipping_range(mesh: TetMesh, camera: Camera) -> tuple[bool, bool]:
    """Whether any point lies nearer than the near plane (then some tet may cross it), and
    whether any lies beyond the far plane."""
    depth = (mesh.points - np.asarray(camera.position)) @ np.asarray(camera.direction)
    near, far = camera.near_far()
    return bool(depth.min() < near), bool(depth.max() > far)

"""The GPU volume ray caster: one object owns every GL object it makes.

Per volume (once): the voxels go to a 3D texture at the precision the accuracy needs
(16-bit normalized for 8- and 16-bit data: an 8-bit texture is filtered at 8-bit
precision; 32-bit float otherwise), checked against the GL's and the host's memory before
it is made, and downsampled with a warning when an axis exceeds the GPU's largest 3D
texture. Per transfer function and step (once), for emission-absorption: either the
control points (``integration="exact"``: ``raycast_exact.glsl`` cuts each piece at them
and integrates in closed form) or the pre-integration table
(:func:`tetvr.optics.preintegrate.table_for` with aligned nodes, whose top thickness slice is the
step; refused before it is built when the GL or the memory cannot hold it); "auto" picks
(:mod:`tetvr.optics.raycast_size`); every mode reads the transfer function's control points, so
a maximum or mean is classified exactly. Per
frame: the optional per-pixel ray limits go to a texture, one full-screen triangle runs
``raycast.frag``, and the RGBA32F target is read back.

Modes are a table (:data:`MODES`): each maps to the ``RAYCAST_MODE`` define; every mode
writes its final pixel from the shader, so none needs blending.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.checks import check_instances
from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.core.image import _gib, check_memory
from tetvr.optics.preintegrate import table_for
from tetvr.optics.table import PreintegrationTable, check_unit_distance, table_build_bytes, table_scalar_range
from tetvr.reference.volume import INTEGRATIONS, INTERPOLATIONS, RAYCAST_MODES, RaycastSettings, normalize_ray_limits
from tetvr.optics.transfer import TransferFunction
from tetvr.volume.volume import Volume
from tetvr.gl.context import context_alive, create_context, describe
from tetvr.gl.filtering import filter_in_shader
from tetvr.gl.shaders import ShaderCompileError, assemble, explain
from tetvr.gl.tablebuild import TableRuns, compile_runs
from tetvr.gl.util import (_LLVMPIPE_TEXTURE_BYTES, _SOFTWARE_GL, Clock, GLOwner, check_size, clear_gl_errors,
                   free_video_memory, gl_locked, locked, make_target, set_uniforms, table_texture, tf_points_texture)

__all__ = ["Raycaster", "RaycastStats", "MODES"]


@dataclasses.dataclass(frozen=True)
class _Mode:
    """How a mode is drawn: its shader defines and what it reads."""

    defines: tuple[tuple[str, int], ...]
    integrates: bool  # emission-absorption along the ray (else one classification per pixel)


#: Rendering mode -> shader variant (see :class:`~tetvr.reference.volume.RaycastSettings`).
MODES: dict[str, _Mode] = {
    "emission_absorption": _Mode(defines=(("RAYCAST_MODE", 0),), integrates=True),
    "mip": _Mode(defines=(("RAYCAST_MODE", 1),), integrates=False),
    "xray": _Mode(defines=(("RAYCAST_MODE", 2),), integrates=False),
    "isosurface": _Mode(defines=(("RAYCAST_MODE", 3),), integrates=False),
}
assert tuple(MODES) == RAYCAST_MODES

#: Integration of emission-absorption -> INTEGRATION_EXACT define.
_INTEGRATIONS = {"exact": 1, "table": 0}
assert set(_INTEGRATIONS) | {"auto"} == set(INTEGRATIONS)

#: Reconstruction -> INTERPOLATION_CUBIC define.
_INTERPOLATIONS = {"linear": 0, "cubic": 1}
assert tuple(_INTERPOLATIONS) == INTERPOLATIONS

# Volume dtype -> (moderngl texture dtype, how the stored texels are made from the voxels,
# factor that turns the texel back into the value). 16-bit data go up as 16-bit normalized,
# exact at half the memory of float32 (signed normalized maps the most negative value to
# -1 like the next one: -32768 reads as -32767). 8-bit data are widened to 16 bits: an
# 8-bit texture is filtered at 8-bit precision (llvmpipe), which held uint8 volumes at
# ~79 dB from the reference; uint8 v is stored as v * 257 (exact in unorm16: 257 / 65535 =
# 1 / 255), int8 as float16 (exact). Other dtypes go up as float32.
_TEXTURE_FORMATS: dict[str, tuple[str, Callable[[NDArray[Any]], NDArray[Any]], float]] = {
    "uint8": ("nu2", lambda a: a.astype(np.uint16) * np.uint16(257), 255.0),
    "int8": ("f2", lambda a: a.astype(np.float16), 1.0),
    "uint16": ("nu2", lambda a: a, 65535.0),
    "int16": ("ni2", lambda a: a, 32767.0),
}
_FLOAT32 = ("f4", lambda a: np.ascontiguousarray(a, dtype=np.float32), 1.0)
#: Bytes per texel of the moderngl dtypes above.
_TEXEL_BYTES = {"f1": 1, "ni1": 1, "nu2": 2, "ni2": 2, "f2": 2, "f4": 4}

_BIG = 3.0e38  # "unlimited" ray limits: finite, so no inf reaches the shader


def _check_texture(ctx: Any, dims: tuple[int, int, int], texel_bytes: int, what: str) -> None:
    """``MemoryError`` naming ``what`` if a 3D texture of ``dims`` texels is more than the
    GL holds: llvmpipe's per-texture limit (its storage has room for the mipmap chain,
    about 8/7 of the base level), or the free video memory where the driver reports it."""
    need = texel_bytes * math.prod(dims)
    renderer = str(ctx.info.get("GL_RENDERER", "")).lower()
    if any(name in renderer for name in _SOFTWARE_GL):
        if need * 8 // 7 > _LLVMPIPE_TEXTURE_BYTES:
            raise MemoryError(f"{what} is a {_gib(need)} texture; {ctx.info.get('GL_RENDERER')} makes textures of "
                              f"at most {_gib(_LLVMPIPE_TEXTURE_BYTES * 7 // 8)}")
        return
    free = free_video_memory(ctx)
    if free is not None and need > free:
        raise MemoryError(f"{what} is a {_gib(need)} texture; the GPU reports {_gib(free)} free")


@dataclasses.dataclass(frozen=True)
class RaycastStats:
    """Size and stage times (seconds) of the last frame; times need ``profile=True``."""

    size: tuple[int, int] = (0, 0)
    volume_dims: tuple[int, int, int] = (0, 0, 0)
    max_steps: int = 0
    upload: float = 0.0
    table: float = 0.0
    draw: float = 0.0
    readback: float = 0.0

    @property
    def total(self) -> float:
        return self.upload + self.table + self.draw + self.readback


class Raycaster(GLOwner):
    """Renders image volumes on the GPU by ray casting; reuse one for many frames.

    Parameters
    ----------
    settings : mode, step, termination tolerance, jitter, iso value, clip box, table sizes.
    ctx : a moderngl context to draw in (e.g. the tets :class:`~tetvr.gl.Renderer`'s
        ``ctx``); it is borrowed, not released. ``None`` creates and owns one.
    max_texture_size : largest 3D texture side to use (default: the GPU's limit).
    profile : wait for the GPU after each stage so :attr:`last_stats` holds stage times.

    Examples
    --------
    >>> with Raycaster(RaycastSettings(mode="mip")) as rc:          # doctest: +SKIP
    ...     image = rc.render(volume, camera, tf, size=(256, 256))
    """

    def __init__(self, settings: RaycastSettings | None = None, *, ctx: Any = None,
                 max_texture_size: int | None = None, profile: bool = False) -> None:
        # Arguments are checked before a context is made: a refused one leaks nothing.
        if settings is None:
            settings = RaycastSettings()
        elif not isinstance(settings, RaycastSettings):
            hint = " (for a dict of fields, pass RaycastSettings.from_dict(it))" if isinstance(settings, dict) else ""
            raise TypeError(f"settings must be a RaycastSettings or None, got {type(settings).__name__}{hint}")
        if max_texture_size is not None and (isinstance(max_texture_size, bool)
                                             or not isinstance(max_texture_size, (int, np.integer))
                                             or max_texture_size < 2):
            raise ValueError(f"max_texture_size must be an integer of at least 2, got {max_texture_size!r}")
        if ctx is not None and not context_alive(ctx):
            raise RuntimeError("ctx has been released: a Raycaster needs a live OpenGL context (pass ctx=None to "
                               "make one, or the ctx of a Renderer that is not released)")
        self.settings = settings
        self._owns_ctx = ctx is None
        self.ctx: Any = create_context() if ctx is None else ctx
        self.gl_info = describe(self.ctx)  # under the context's lock; caches ctx.info
        gl_max = int(self.ctx.info.get("GL_MAX_3D_TEXTURE_SIZE", 2048))
        self.max_texture_size = min(gl_max, int(max_texture_size)) if max_texture_size is not None else gl_max
        self.profile = profile
        self._programs: dict[tuple[str, ...], Any] = {}
        self._vaos: dict[int, Any] = {}
        self._volume: Volume | None = None  # the caller's volume ...
        self._gpu_volume: Volume | None = None  # ... and the one in the texture (maybe downsampled)
        self._volume_tex: Any = None
        self._value_scale = 1.0
        self._table: PreintegrationTable | None = None
        self._table_tex: Any = None
        self._table_checked: tuple[Any, ...] | None = None
        self._tf_points_tex: Any = None
        self._tf_points_key: TransferFunction | None = None
        self._limits_tex: Any = None
        self._limits_size: tuple[int, int] = (0, 0)
        self._no_limits_tex: Any = None
        self._fbo: Any = None
        self._fbo_tex: Any = None
        self._fbo_size: tuple[int, int] = (0, 0)
        self.last_stats = RaycastStats()
        self._released = False

    # ---- lifetime (GLOwner: release(), the context manager) ----
    def _forget(self) -> None:
        self._programs.clear()
        self._vaos.clear()
        self._volume_tex = self._table_tex = self._limits_tex = self._tf_points_tex = None
        self._tf_points_key = None
        self._no_limits_tex = self._fbo = self._fbo_tex = None
        self._volume = self._gpu_volume = None
        self._table = None

    def _gl_objects(self) -> list[Any]:
        objs = [*self._vaos.values(), *self._programs.values()]
        objs += [o for o in (self._volume_tex, self._table_tex, self._tf_points_tex, self._limits_tex,
                             self._no_limits_tex, self._fbo, self._fbo_tex) if o is not None]
        return objs

    # ---- programs ----
    @gl_locked  # tests and tools call it directly
    def _program(self, mode: str, interpolation: str = "linear", integration: str = "exact") -> Any:
        spec = MODES[mode]
        defines = dict(spec.defines)
        defines["TABLE_NORMALIZED"] = 1
        defines["INTERPOLATION_CUBIC"] = _INTERPOLATIONS[interpolation]
        defines["INTEGRATION_EXACT"] = _INTEGRATIONS[integration] if spec.integrates else 0
        defines["FILTER_IN_SHADER"] = int(filter_in_shader(self.ctx))  # shaders/filter.glsl
        key = tuple(f"{k}={v}" for k, v in sorted(defines.items()))
        prog = self._programs.get(key)
        if prog is not None:
            return prog
        files: list[str] = []
        try:
            vert, _ = assemble("raycast.vert", defines)
            frag, files = assemble("raycast.frag", defines)
            prog = self.ctx.program(vertex_shader=vert, fragment_shader=frag)
        except ShaderCompileError:
            raise
        except Exception as exc:
            raise ShaderCompileError(f"raycast ({mode}, {interpolation}, {integration}): {explain(exc, files)}") from exc
        self._programs[key] = prog
        return prog

    # ---- cached GPU state ----
    @locked
    def gpu_volume(self, volume: Volume) -> Volume:
        """The volume as it is (or will be) on the GPU: ``volume``, or a downsampled copy
        if an axis exceeds :attr:`max_texture_size` (warns once per volume)."""
        if volume is self._volume and self._gpu_volume is not None:
            return self._gpu_volume
        return volume.fit_size(self.max_texture_size)

    def _use_volume(self, volume: Volume) -> Volume:
        if volume is self._volume and self._gpu_volume is not None:
            return self._gpu_volume
        import moderngl

        gpu = volume.fit_size(self.max_texture_size)
        dtype, widen, scale = _TEXTURE_FORMATS.get(gpu.data.dtype.name, _FLOAT32)
        _check_texture(self.ctx, gpu.dims, _TEXEL_BYTES[dtype], f"a volume of {gpu.dims} voxels ({dtype})")
        check_memory(2 * _TEXEL_BYTES[dtype] * math.prod(gpu.dims), f"uploading a volume of {gpu.dims} voxels")
        payload = widen(gpu.data)
        if self._volume_tex is not None:
            self._volume_tex.release()
            self._volume_tex = None
            self._volume = self._gpu_volume = None
        tex = self.ctx.texture3d(gpu.dims, 1, payload.tobytes(), dtype=dtype)
        tex.repeat_x = tex.repeat_y = tex.repeat_z = False
        tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self._volume_tex = tex
        self._value_scale = scale
        self._volume, self._gpu_volume = volume, gpu
        return gpu

    @locked
    def table(self, volume: Volume, tf: TransferFunction, settings: RaycastSettings | None = None) -> PreintegrationTable:
        """The pre-integration table for a volume, transfer function and step.

        Its last thickness slice is the step (to 1e-6), so a full step reads one table
        entry; the partial steps where a ray enters and leaves read thinner slices.
        """
        s = settings or self.settings
        n_bins = s.bins_for(volume, tf)
        step = s.step_for(volume, tf)
        key = (tf, volume.scalar_range, step, n_bins, s.table_thickness_slices)
        if key != self._table_checked:  # checked once: a built (cached) table needs no memory again
            self._check_table(n_bins, s.table_thickness_slices)
        table = table_for(tf, volume.scalar_range, step, n_bins=n_bins, n_slices=s.table_thickness_slices,
                          log_base=2.0, encoding="normalized", dtype="float32", align_nodes=True,
                          runs=TableRuns(self.ctx, self._runs_program))
        self._table_checked = key
        return table

    def _runs_program(self, ring: int) -> Any:
        """The compiled ``table_runs.comp`` (the table's runs on the GPU: :mod:`tetvr.gl.tablebuild`)."""
        key = ("table_runs", ring)
        if key not in self._programs:
            self._programs[key] = compile_runs(self.ctx, ring)
        return self._programs[key]

    def _check_table(self, n_bins: int, n_slices: int) -> None:
        """Refuse a table this GL cannot hold, or this machine cannot build, before any
        of it is allocated (``ValueError`` / ``MemoryError`` naming the settings)."""
        names = f"table_scalar_bins={n_bins} with table_thickness_slices={n_slices}"
        gl_max = int(self.ctx.info.get("GL_MAX_3D_TEXTURE_SIZE", 2048))
        if n_bins > gl_max:
            raise ValueError(f"table_scalar_bins={n_bins} is more than this GL's largest 3D texture side "
                             f"(GL_MAX_3D_TEXTURE_SIZE {gl_max}), which the table's scalar axes must fit; "
                             f"use at most {gl_max} bins")
        dims = (n_slices + 1, n_bins, n_bins)
        _check_texture(self.ctx, dims, 16, f"the pre-integration table of {names}")
        check_memory(table_build_bytes(n_bins, n_slices) + 16 * math.prod(dims),
                     f"building the pre-integration table of {names} ({n_bins} x {n_bins} x {n_slices + 1})")

    def _use_table(self, table: PreintegrationTable) -> None:
        if table is self._table:
            return
        if self._table_tex is not None:
            self._table_tex.release()
        self._table_tex = table_texture(self.ctx, table)
        self._table = table

    def _use_tf_points(self, tf: TransferFunction) -> None:
        """The transfer function's control points (raycast_sample.glsl): row 0 (scalar,
        opacity), row 1 the colour, one texel per point of the union of both maps."""
        if tf == self._tf_points_key:
            return
        if self._tf_points_tex is not None:
            self._tf_points_tex.release()
            self._tf_points_tex = None
        self._tf_points_tex = tf_points_texture(self.ctx, tf)
        self._tf_points_key = tf

    def _use_limits(self, t_start: ArrayLike | None, t_end: ArrayLike | None, size: tuple[int, int]) -> bool:
        import moderngl

        if self._no_limits_tex is None:
            self._no_limits_tex = self.ctx.texture((1, 1), 2, np.array([-_BIG, _BIG], np.float32).tobytes(), dtype="f4")
            self._no_limits_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        if t_start is None and t_end is None:
            return False
        start, end = normalize_ray_limits(t_start, t_end, size)
        lim = np.stack([np.clip(start, -_BIG, _BIG), np.clip(end, -_BIG, _BIG)], axis=-1)[::-1]  # GL rows go up
        lim = np.ascontiguousarray(lim, dtype=np.float32)
        if self._limits_tex is None or self._limits_size != size:
            if self._limits_tex is not None:
                self._limits_tex.release()
            self._limits_tex = self.ctx.texture(size, 2, lim.tobytes(), dtype="f4")
            self._limits_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._limits_size = size
        else:
            self._limits_tex.write(lim.tobytes())
        return True

    def _use_target(self, size: tuple[int, int]) -> None:
        if self._fbo is not None and self._fbo_size == size:
            return
        if self._fbo is not None:
            # Unbind before deleting (see Renderer._use_target).
            self.ctx.detect_framebuffer(0).use()
        for o in (self._fbo, self._fbo_tex):
            if o is not None:
                o.release()
        self._fbo_tex = self._fbo = None
        self._fbo_tex, self._fbo = make_target(self.ctx, size, 4, "f4")  # nothing left behind if it fails
        self._fbo_size = size

    # ---- the frame ----
    @gl_locked
    def render(
        self,
        volume: Volume,
        camera: Camera,
        tf: TransferFunction,
        *,
        size: tuple[int, int] = (512, 512),
        t_start: ArrayLike | None = None,
        t_end: ArrayLike | None = None,
        settings: RaycastSettings | None = None,
    ) -> NDArray[np.float32]:
        """Render one frame.

        Parameters
        ----------
        volume, camera, tf : the scene.
        size : (width, height) in pixels.
        t_start, t_end : optional (H, W) float arrays of eye depth (row 0 at the top):
            each ray is integrated only over ``[max(entry, t_start), min(exit, t_end)]``.
            NaN or +-inf means unlimited.
        settings : overrides :attr:`settings` for this frame.

        Returns
        -------
        (height, width, 4) float32 premultiplied RGBA, row 0 at the top.
        """
        # gl_locked: the context is current in this thread (whatever other contexts were
        # made or released since), and no other thread uses it until we return.
        return self._render(volume, camera, tf, size, t_start, t_end, settings)

    def _render(self, volume: Volume, camera: Camera, tf: TransferFunction, size: tuple[int, int],
                t_start: ArrayLike | None, t_end: ArrayLike | None, settings: RaycastSettings | None) -> NDArray[np.float32]:
        check_instances(volume=(volume, Volume), camera=(camera, Camera), tf=(tf, TransferFunction))
        camera = resolve_clipping_range(camera, volume.bounds)  # None: from the data, as VTK
        s = settings or self.settings
        width, height = check_size(size, self.ctx, method="raycast")
        clear_gl_errors(self.ctx)  # what a failed earlier frame left is not this frame's error
        clock = Clock(self.ctx, self.profile)

        gpu = self._use_volume(volume)
        use_limits = self._use_limits(t_start, t_end, (width, height))
        clock.lap("upload")
        integration, uses_table, scalar_range, table_uniforms = self._use_optics(volume, tf, s)
        clock.lap("table")

        uniforms, max_steps = self._view_uniforms(volume, gpu, camera, tf, s, (width, height), use_limits,
                                                  scalar_range)
        prog = self._program(s.mode, s.interpolation, integration)
        uniforms.update(table_uniforms)  # its u_scalar_range is scalar_range
        self._draw(prog, uniforms, (width, height), uses_table, use_limits)
        clock.lap("draw")
        raw = self._fbo.read(components=4, dtype="f4")
        image = np.frombuffer(raw, dtype=np.float32).reshape(height, width, 4)[::-1].copy()
        clock.lap("readback")
        err = self.ctx.error
        if err != "GL_NO_ERROR":
            raise RuntimeError(f"OpenGL error after ray casting: {err}")
        self.last_stats = RaycastStats(size=(width, height), volume_dims=gpu.dims, max_steps=max_steps, **clock.laps)
        return image

    def _use_optics(self, volume: Volume, tf: TransferFunction, s: RaycastSettings
                    ) -> tuple[str, bool, tuple[float, float], dict[str, Any]]:
        """The frame's integration (``"table"`` for the modes that integrate nothing), whether
        it reads the pre-integration table (then built and uploaded), the scalar range the
        shaders map onto the transfer function, and the table's or the exact integral's
        uniforms. Also uploads the transfer function's points."""
        mode = MODES[s.mode]
        # Ranges come from the original volume: downsampling only narrows them. A table
        # may span more (its nodes aligned on the transfer function's control points):
        # its own range is what lookup.glsl reads then.
        scalar_range = table_scalar_range(volume.scalar_range, tf)
        table_uniforms: dict[str, Any] = {}
        integration = s.integration_for(volume, tf) if mode.integrates else "table"
        uses_table = mode.integrates and integration == "table"
        if mode.integrates and integration == "exact":
            table_uniforms = dict(u_inv_unit_distance=min(1.0 / check_unit_distance(tf.unit_distance), 1e30))
        if uses_table:
            table = self.table(volume, tf, s)
            self._use_table(table)
            table_uniforms = table.gl_uniforms()
            scalar_range = table.scalar_range
        self._use_tf_points(tf)
        return integration, uses_table, scalar_range, table_uniforms

    def _view_uniforms(self, volume: Volume, gpu: Volume, camera: Camera, tf: TransferFunction, s: RaycastSettings,
                       size: tuple[int, int], use_limits: bool, scalar_range: tuple[float, float]
                       ) -> tuple[dict[str, Any], int]:
        """raycast.frag's uniforms for this view of the uploaded volume ``gpu`` (but the
        table's), and the most steps a ray takes."""
        width, height = size
        step = s.step_for(volume, tf)
        # Regular steps, plus one sample per voxel-index plane the ray crosses (raycast.frag).
        max_steps = int(math.ceil(gpu.diagonal / step)) + sum(gpu.dims) + 3
        if max_steps > 1 << 20:
            raise ValueError(f"step {step} is too small for a volume of diagonal {gpu.diagonal:.4g}: "
                             f"{max_steps} steps per ray")
        centre = gpu.center
        eye_to_world = np.linalg.inv(camera.view_matrix())
        to_local = np.eye(4)
        to_local[:3, 3] = -centre
        eye_to_local = to_local @ eye_to_world
        eye_to_index = gpu.world_to_index @ eye_to_world
        aspect = width / height
        k = camera.parallel_scale if camera.parallel_projection else math.tan(math.radians(camera.view_angle) / 2)
        a_inv = gpu.world_to_index[:3, :3]
        clip_lo, clip_hi = (np.asarray(s.clip_box[0]) - centre, np.asarray(s.clip_box[1]) - centre) \
            if s.clip_box is not None else (np.zeros(3), np.zeros(3))
        uniforms = dict(
            u_inv_viewport=(1.0 / width, 1.0 / height), u_perspective=0 if camera.parallel_projection else 1,
            u_k=(k * aspect, k), u_eye_to_index=eye_to_index, u_eye_to_local=eye_to_local,
            u_box_hi=tuple(float(n - 1) for n in gpu.dims), u_clip_range=camera.near_far(),
            u_use_clip_box=int(s.clip_box is not None), u_clip_lo=tuple(clip_lo), u_clip_hi=tuple(clip_hi),
            u_use_limits=int(use_limits), u_step=step, u_max_steps=max_steps,
            u_termination_tolerance=s.termination_tolerance, u_jitter=int(s.jitter), u_seed=s.seed,
            u_iso=s.iso_for(volume), u_iso_opacity=s.iso_opacity, u_shading=s.shading,
            u_gradient_to_local=a_inv.T,
            u_inv_dims=tuple(1.0 / n for n in gpu.dims), u_value_scale=self._value_scale,
            u_scalar_range=scalar_range, u_volume=1, u_tf_points=2, u_tf_count=self._tf_points_tex.width,
            u_limits=3)
        return uniforms, max_steps

    def _draw(self, prog: Any, uniforms: dict[str, Any], size: tuple[int, int], uses_table: bool,
              use_limits: bool) -> None:
        """One full-screen triangle of ``prog`` into the cleared target, the table (if used),
        volume, transfer function points and ray limits bound to units 0-3."""
        import moderngl

        set_uniforms(prog, **uniforms)
        self._use_target(size)
        self._fbo.use()
        self._fbo.clear(0.0, 0.0, 0.0, 0.0)
        if uses_table:
            self._table_tex.use(0)
        self._volume_tex.use(1)
        self._tf_points_tex.use(2)
        (self._limits_tex if use_limits else self._no_limits_tex).use(3)
        self.ctx.disable(moderngl.BLEND | moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        vao = self._vaos.get(id(prog))
        if vao is None:
            vao = self._vaos[id(prog)] = self.ctx.vertex_array(prog, [])
        vao.render(moderngl.TRIANGLES, vertices=3)

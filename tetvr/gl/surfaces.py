"""The opaque surfaces' GL pass and the ray window both tet methods cut their rays to.

Owned by a :class:`~tetvr.gl.renderer.Renderer`. Per frame with surfaces, one draw
(``shaders/surface.*``, :mod:`tetvr.core.surface` for the technique) leaves, per pixel, the
nearest hit's shaded colour and eye depth; the depth becomes the far end of each ray's
window (``shaders/window.glsl``, bound at :data:`LIMIT_UNIT`), and the colour is
composited behind the tets' image. Clip planes (:class:`tetvr.core.clip.Clip`) go to the
same window as eye-space uniforms.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera
from tetvr.core.clip import Clip
from tetvr.core.surface import Surface
from tetvr.gl.host import ProgramHost

__all__ = ["LIMIT_UNIT", "RayWindow", "SurfacePass"]

#: Texture unit of the per-pixel ray limit (window.glsl's u_limit); 0-8 are the table,
#: the ray caster's records and targets, and a warped table's warp.
LIMIT_UNIT = 9
#: The SSBO binding of the surfaces' triangles (surface.vert); 0-4 are the mesh's.
SURFACE_BINDING = 6
_NEAREST = 0x2600


@dataclasses.dataclass(frozen=True)
class RayWindow:
    """What cuts this frame's rays: clip planes in eye space and/or a per-pixel limit."""

    planes_eye: NDArray[np.float32] | None = None
    limit: Any = None  # R32F texture of eye depths, or None

    @classmethod
    def make(cls, clip: Clip | None, camera: Camera, limit: Any = None) -> "RayWindow":
        planes = None if clip is None else clip.eye_planes(camera).astype(np.float32)
        return cls(planes, limit)

    @property
    def defines(self) -> dict[str, int]:
        return dict(CLIP_PLANES=0 if self.planes_eye is None else int(self.planes_eye.shape[0]),
                    RAY_LIMIT=int(self.limit is not None))

    @property
    def active(self) -> bool:
        return self.planes_eye is not None or self.limit is not None

    def bind(self, prog: Any) -> None:
        """Set a program's window uniforms and bind the limit texture."""
        if self.planes_eye is not None and "u_clip" in prog:
            prog["u_clip"].write(np.ascontiguousarray(self.planes_eye).tobytes())
        if self.limit is not None:
            self.limit.use(LIMIT_UNIT)
            if "u_limit" in prog:
                prog["u_limit"].value = LIMIT_UNIT


class SurfacePass:
    """GL state of the opaque surfaces for one :class:`Renderer`."""

    def __init__(self, owner: ProgramHost) -> None:
        self.owner = owner
        self.ctx = owner.ctx
        self._key: tuple[Any, ...] | None = None
        self._buffer: Any = None
        self._n_triangles = 0
        self._vaos: dict[int, Any] = {}
        self._targets: dict[tuple[int, int], dict[str, Any]] = {}

    # ---- ownership ----
    def gl_objects(self) -> list[Any]:
        objs = [*self._vaos.values()]
        if self._buffer is not None:
            objs.append(self._buffer)
        for t in self._targets.values():
            objs += [t["fbo"], t["depth_fbo"], t["color"], t["depth"], t["zbuffer"]]
        return objs

    def forget(self) -> None:
        self._vaos.clear()
        self._targets.clear()
        self._buffer = self._key = None

    def gpu_bytes(self) -> int:
        total = 0 if self._buffer is None else int(self._buffer.size)
        for size in self._targets:
            total += size[0] * size[1] * (16 + 4 + 4)
        return total

    # ---- per surface set ----
    def _upload(self, surfaces: Sequence[Surface], origin: NDArray[np.float64]) -> None:
        # The surfaces themselves, held (Surface compares by identity): ids of dropped
        # objects are reused, and a new surface must not pass for the old one.
        key = (tuple(surfaces), tuple(origin.tolist()))
        if key == self._key:
            return
        rows = []
        for s in surfaces:
            pos = s.corners - origin  # (m, 3, 3), relative to the mesh's float32 origin
            nrm = s.shading_normals()
            data = np.zeros((s.n_triangles, 6, 4), dtype=np.float64)
            data[:, :3, :3] = pos
            data[:, 1, 3] = s.ambient
            data[:, 3:, :3] = nrm
            data[:, 3:, 3] = s.color
            rows.append(data)
        data32 = np.concatenate(rows).astype(np.float32)
        if self._buffer is not None:
            self._buffer.release()
        self._buffer = self.ctx.buffer(data32.tobytes())
        self._n_triangles = int(data32.shape[0])
        self._key = key

    def _target(self, size: tuple[int, int]) -> dict[str, Any]:
        from tetvr.gl.util import cached_targets

        return cached_targets(self.ctx, self._targets, size, self._make_target)

    def _make_target(self, size: tuple[int, int], t: dict[str, Any]) -> None:
        ctx = self.ctx
        t.update(color=ctx.texture(size, 4, dtype="f4"), depth=ctx.texture(size, 1, dtype="f4"),
                 zbuffer=ctx.depth_texture(size))
        t["depth"].filter = (_NEAREST, _NEAREST)
        t["fbo"] = ctx.framebuffer(color_attachments=[t["color"], t["depth"]], depth_attachment=t["zbuffer"])
        t["depth_fbo"] = ctx.framebuffer(color_attachments=[t["depth"]])

    # ---- the frame ----
    def draw(self, surfaces: Sequence[Surface], camera: Camera, size: tuple[int, int],
             origin: NDArray[np.float64]) -> tuple[Any, Any]:
        """Draw the surfaces; returns the (colour, depth) textures (valid until the next draw)."""
        import moderngl

        self._upload(surfaces, origin)
        view = camera.view_matrix()
        view[:3, 3] += view[:3, :3] @ origin
        near, far = camera.near_far()
        proj = camera.projection_matrix(size[0] / size[1])
        prog = self.owner._program("surface", PERSPECTIVE=int(not camera.parallel_projection))
        from tetvr.gl.util import set_uniforms

        set_uniforms(prog, u_view=view, u_proj=proj, u_viewport=(float(size[0]), float(size[1])), u_near=near,
                     u_far=far, u_ray_scale=(1.0 / float(proj[0, 0]), 1.0 / float(proj[1, 1])))
        t = self._target(size)
        fbo = t["fbo"]
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)  # every attachment
        # The depth target's "no hit" is +3e38, not the colour's 0: cleared again on its own.
        t["depth_fbo"].use()
        t["depth_fbo"].clear(3.0e38, 0.0, 0.0, 0.0)
        fbo.use()
        self.ctx.disable(moderngl.BLEND | moderngl.CULL_FACE)
        self.ctx.enable(moderngl.DEPTH_TEST)
        self.ctx.depth_func = "<="
        self._buffer.bind_to_storage_buffer(SURFACE_BINDING)
        vao = self._vaos.get(id(prog))
        if vao is None:
            vao = self._vaos[id(prog)] = self.ctx.vertex_array(prog, [])
        vao.render(moderngl.TRIANGLES, vertices=6 * self._n_triangles)
        self.ctx.disable(moderngl.DEPTH_TEST)
        return t["color"], t["depth"]

    def read_color(self, size: tuple[int, int]) -> NDArray[np.float32]:
        """The last draw's colour, premultiplied RGBA (height, width, 4), row 0 at the top."""
        raw = self._targets[size]["color"].read()
        return np.frombuffer(raw, dtype=np.float32).reshape(size[1], size[0], 4)[::-1].copy()

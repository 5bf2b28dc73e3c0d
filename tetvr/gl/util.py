"""Small GL helpers shared by the renderers: GL ownership, size checks, uniforms, the table texture, stage clocks."""

from __future__ import annotations

import abc
import time
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from ..image import image_size

if TYPE_CHECKING:
    from ..preintegrate import PreintegrationTable

__all__ = ["GLOwner", "check_size", "set_uniforms", "table_texture", "Clock"]


_Owner = TypeVar("_Owner", bound="GLOwner")


class GLOwner(abc.ABC):
    """The lifetime of a renderer: a moderngl context, made (and released) or borrowed,
    and every GL object made in it, released together by :meth:`release` or on leaving a
    ``with`` block. Subclasses list their objects in :meth:`_gl_objects` and drop their
    references in :meth:`_forget`; nothing relies on ``__del__``.
    """

    ctx: Any
    _owns_ctx: bool = True
    _released: bool = False

    def __enter__(self: _Owner) -> _Owner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def release(self) -> None:
        """Release every GL object (and the context, if this object made it). Safe twice."""
        if self._released:
            return
        # Creating another context (a Raycaster, a second Renderer) makes it current:
        # enter ours so that the releases below reach it, and unbind any framebuffer of
        # ours first (a released framebuffer left bound is a dead name the next
        # framebuffer's creation trips over).
        with self.ctx:
            self.ctx.detect_framebuffer(0).use()
            for obj in self._gl_objects():
                obj.release()
        self._forget()
        if self._owns_ctx:
            self.ctx.release()
        self._released = True

    def _check_alive(self) -> None:
        if self._released:
            raise RuntimeError(f"this {type(self).__name__} has been released")

    @abc.abstractmethod
    def _gl_objects(self) -> list[Any]:
        """Every GL object this owner made and still holds."""

    @abc.abstractmethod
    def _forget(self) -> None:
        """Drop the references to released GL objects and cached GPU state."""


def check_size(size: tuple[int, int], ctx: Any) -> tuple[int, int]:
    """(width, height) as ints, within 1 .. the GL's texture and viewport limit."""
    width, height = image_size(size)
    limit = int(min(ctx.info.get("GL_MAX_TEXTURE_SIZE", 16384), ctx.info.get("GL_MAX_VIEWPORT_DIMS", (16384,))[0]))
    if not (1 <= width <= limit and 1 <= height <= limit):
        raise ValueError(f"image size {size!r} is outside 1..{limit} pixels per side (the GL limit here)")
    return width, height


def table_texture(ctx: Any, table: "PreintegrationTable") -> Any:
    """A 3D texture of a :class:`~tetvr.preintegrate.PreintegrationTable` for
    ``shaders/lookup.glsl``: linear filtering, clamped to the edge texels.

    Texel (slice, front, back): the thickness slice varies fastest, so the 8 texels of one
    trilinear fetch lie within a few hundred bytes instead of a slice (1 MiB at 256 bins)
    apart -- the same image, and on llvmpipe a tenth less draw time at 10k tets.
    """
    import moderngl

    k1, n, _, _ = table.data.shape  # (slice, back, front, RGBA)
    texels = np.moveaxis(table.data, 0, 2)  # (back, front, slice, RGBA); tobytes() lays it out in C order
    dtype = "f4" if texels.dtype == np.float32 else "f1"
    tex = ctx.texture3d((k1, n, n), 4, texels.tobytes(), dtype=dtype)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    return tex


def set_uniforms(prog: Any, **uniforms: Any) -> None:
    """Set the uniforms a program uses; 2D arrays are written as column-major matrices."""
    for name, value in uniforms.items():
        if name not in prog:
            continue  # optimised away by the compiler
        arr = np.asarray(value) if isinstance(value, np.ndarray) else None
        if arr is not None and arr.ndim == 2:
            prog[name].write(arr.T.astype(np.float32).tobytes())  # GLSL is column-major
        else:
            prog[name].value = value


class Clock:
    """Stage timer: ``lap(name)`` adds the time since the last lap (after glFinish if
    ``sync``) to ``laps[name]``."""

    def __init__(self, ctx: Any, sync: bool) -> None:
        self.ctx, self.sync = ctx, sync
        self.laps: dict[str, float] = {}
        self.t = time.perf_counter()

    def lap(self, name: str) -> None:
        if self.sync:
            self.ctx.finish()
        now = time.perf_counter()
        self.laps[name] = self.laps.get(name, 0.0) + now - self.t
        self.t = now

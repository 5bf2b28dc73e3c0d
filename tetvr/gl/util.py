"""Small GL helpers shared by the renderers: size checks, uniforms, the table texture, stage clocks."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np

from ..image import image_size

if TYPE_CHECKING:
    from ..preintegrate import PreintegrationTable

__all__ = ["check_size", "set_uniforms", "table_texture", "Clock"]


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

"""Small GL helpers shared by the renderers: GL ownership, size checks, uniforms, the table texture, stage clocks."""

from __future__ import annotations

import abc
import contextlib
import ctypes
import functools
import time
from typing import TYPE_CHECKING, Any, Callable, Concatenate, Iterator, ParamSpec, TypeVar

import numpy as np

from tetvr.core.image import _gib, image_size
from tetvr.gl.framesize import FrameMemoryError, check_frame
from tetvr.gl.context import ForkedProcessError, check_not_forked, context_alive, context_lock, current_in_thread
from tetvr.optics.tablesteps import STEPS_UNIT

if TYPE_CHECKING:
    from tetvr.optics.table import PreintegrationTable

__all__ = ["GLOwner", "gl_locked", "locked", "check_size", "is_software", "clear_gl_errors", "free_video_memory", "make_target", "set_uniforms",
           "table_texture", "Clock"]


_Owner = TypeVar("_Owner", bound="GLOwner")
_P = ParamSpec("_P")
_R = TypeVar("_R")


def gl_locked(method: Callable[Concatenate[_Owner, _P], _R]) -> Callable[Concatenate[_Owner, _P], _R]:
    """Decorate a :class:`GLOwner` method that touches GL: it runs holding the context's
    lock, with the context current in the calling thread, after :meth:`GLOwner._check_alive`.
    So one renderer (or several sharing a context) can be called from many threads."""

    @functools.wraps(method)
    def locked_method(self: _Owner, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        with self._gl_scope():
            return method(self, *args, **kwargs)

    return locked_method


def locked(method: Callable[Concatenate[_Owner, _P], _R]) -> Callable[Concatenate[_Owner, _P], _R]:
    """Decorate a :class:`GLOwner` method that reads or changes its state but makes no GL
    call: it runs holding the context's lock only (and works after release)."""

    @functools.wraps(method)
    def locked_method(self: _Owner, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        with context_lock(self.ctx):
            return method(self, *args, **kwargs)

    return locked_method


class GLOwner(abc.ABC):
    """The lifetime of a renderer: a moderngl context, made (and released) or borrowed,
    and every GL object made in it, released together by :meth:`release` or on leaving a
    ``with`` block. Subclasses list their objects in :meth:`_gl_objects` and drop their
    references in :meth:`_forget`; nothing relies on ``__del__``.

    Threads: every method that touches GL is decorated with :func:`gl_locked`: it holds
    the context's re-entrant lock (one per context, shared by all its owners) and makes
    the context current in the calling thread for the call only. So one renderer may be
    called from several threads, one call at a time. Between calls the context is current
    in no thread; to use ``ctx`` directly, enter ``with owner.ctx:`` in one thread.
    """

    ctx: Any
    _owns_ctx: bool = True
    _released: bool = False

    def __enter__(self: _Owner) -> _Owner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def release(self) -> None:
        """Release every GL object (and the context, if this object made it). Safe twice,
        from any thread, after a borrowed context was released by its owner (its GL objects
        went with it), and in a forked child (which drops its references without GL)."""
        if self._released:
            return
        try:
            check_not_forked()
        except ForkedProcessError:
            # The child's copy of the GL state cannot be touched (GL would hang); it goes
            # with the process.
            self._forget()
            self._released = True
            return
        with context_lock(self.ctx):
            if self._released:  # another thread was first
                return
            if context_alive(self.ctx):
                with current_in_thread(self.ctx):
                    # Unbind any framebuffer of ours first: a released framebuffer left bound
                    # is a dead name the next framebuffer's creation trips over.
                    self.ctx.detect_framebuffer(0).use()
                    for obj in self._gl_objects():
                        obj.release()
                    if self._owns_ctx:
                        self.ctx.release()
            self._forget()
            self._released = True

    def _check_alive(self) -> None:
        name = type(self).__name__
        if self._released:
            raise RuntimeError(f"this {name} has been released")
        if not context_alive(self.ctx):
            raise RuntimeError(f"the OpenGL context of this {name} has been released: it was borrowed, and its "
                               f"owner (e.g. the Renderer whose ctx it shares) was released first. Make a new {name}, "
                               f"and release it before the context's owner")

    @contextlib.contextmanager
    def _gl_scope(self) -> Iterator[None]:
        """Hold the context's lock with the context current in this thread (:func:`gl_locked`)."""
        check_not_forked()  # before the lock: one that a thread of the parent held stays held
        with context_lock(self.ctx):
            self._check_alive()  # inside the lock: another thread may have released us meanwhile
            with current_in_thread(self.ctx):
                yield

    @abc.abstractmethod
    def _gl_objects(self) -> list[Any]:
        """Every GL object this owner made and still holds."""

    @abc.abstractmethod
    def _forget(self) -> None:
        """Drop the references to released GL objects and cached GPU state."""


#: Mesa's software rasterisers (their textures live in host memory).
_SOFTWARE_GL = ("llvmpipe", "softpipe", "swrast")
#: llvmpipe refuses a texture whose storage, with room for the whole mipmap chain and
#: levels padded to 4 x 4 pixels, passes 2 GiB (``LP_MAX_TEXTURE_SIZE``: its 32-bit
#: signed offsets); a plain ``GL_OUT_OF_MEMORY`` at ``ctx.texture`` was all it said.
_LLVMPIPE_TEXTURE_BYTES = 1 << 31


def check_size(size: tuple[int, int], ctx: Any, *, bytes_per_pixel: int = 16, method: str = "projected",
               surfaces: bool = False) -> tuple[int, int]:
    """(width, height) as ints, checked against the GL's real limits before any GL call.

    Each side must be within ``GL_MAX_TEXTURE_SIZE``, ``GL_MAX_RENDERBUFFER_SIZE`` and
    ``GL_MAX_VIEWPORT_DIMS`` (``ValueError``); the largest render target, of
    ``bytes_per_pixel`` (16: RGBA float32), must fit the GL's memory (llvmpipe's
    per-texture limit), and the frame of ``method`` (:mod:`tetvr.gl.framesize`: every
    target, the readback) the free video memory where the driver reports it and the
    host's memory (:class:`~tetvr.gl.framesize.FrameMemoryError`, naming the sizes). A
    frame that would fail half-way through making its targets fails here instead, with
    the renderer untouched.
    """
    width, height = image_size(size)
    info = ctx.info
    viewport = info.get("GL_MAX_VIEWPORT_DIMS", (16384, 16384))
    limits = {"GL_MAX_TEXTURE_SIZE": int(info.get("GL_MAX_TEXTURE_SIZE", 16384)),
              "GL_MAX_RENDERBUFFER_SIZE": int(info.get("GL_MAX_RENDERBUFFER_SIZE", 16384)),
              "GL_MAX_VIEWPORT_DIMS": int(min(viewport))}
    limit = min(limits.values())
    if not (1 <= width <= limit and 1 <= height <= limit):
        raise ValueError(f"image size {size!r} is outside 1..{limit} pixels per side (the GL limit here): "
                         + ", ".join(f"{k} {v}" for k, v in limits.items()))
    need = width * height * bytes_per_pixel
    what = f"a {width}x{height} image ({bytes_per_pixel} bytes a pixel)"
    software = is_software(ctx)
    if software and _mipmapped_bytes(width, height, bytes_per_pixel) > _LLVMPIPE_TEXTURE_BYTES:
        raise MemoryError(f"{what} needs a {_gib(need)} render target; {info.get('GL_RENDERER', 'this GL')} "
                          f"makes textures of at most {_gib(_LLVMPIPE_TEXTURE_BYTES * 3 // 4)}: render it smaller")
    estimate = check_frame((width, height), method, software=software, surfaces=surfaces)
    free = None if software else free_video_memory(ctx)
    if free is not None and estimate.gpu > free:
        raise FrameMemoryError(f"a {width}x{height} frame needs {_gib(estimate.gpu)} of render targets; the GPU "
                               f"reports {_gib(free)} free: render it smaller", size=(width, height), method=method,
                               need=estimate.gpu, available=free)
    return width, height


def is_software(ctx: Any) -> bool:
    """Whether ``ctx`` is a Mesa software rasteriser's (its textures live in host memory)."""
    renderer = str(ctx.info.get("GL_RENDERER", "")).lower()
    return any(name in renderer for name in _SOFTWARE_GL)


def _mipmapped_bytes(width: int, height: int, bytes_per_pixel: int) -> int:
    """Storage llvmpipe reserves for a 2D texture: every mip level, padded to 4 x 4."""
    total = 0
    while True:
        total += -(-width // 4) * 4 * -(-height // 4) * 4 * bytes_per_pixel
        if width == height == 1:
            return total
        width, height = max(1, width // 2), max(1, height // 2)


def free_video_memory(ctx: Any) -> int | None:
    """Bytes of free video memory, where the driver reports it (``GL_NVX_gpu_memory_info``,
    ``GL_ATI_meminfo``), else None. Read with ``glGetIntegerv``, which moderngl does not
    expose, from the GL library: ``ctx`` must be current (as it is during a frame); with
    no context current the call does nothing and the answer is None."""
    extensions: set[str] = getattr(ctx, "extensions", set())
    if "GL_NVX_gpu_memory_info" in extensions:
        pname = 0x9049  # GL_GPU_MEMORY_INFO_CURRENT_AVAILABLE_VIDMEM_NVX, KiB
    elif "GL_ATI_meminfo" in extensions:
        pname = 0x87FC  # GL_TEXTURE_FREE_MEMORY_ATI: (total free KiB, largest block, ...)
    else:
        return None
    get = _gl_get_integerv()
    if get is None:
        return None
    out = (ctypes.c_int * 4)()
    get(pname, out)
    if clear_gl_errors(ctx):
        return None
    return int(out[0]) * 1024 if out[0] > 0 else None


@functools.lru_cache(maxsize=1)
def _gl_get_integerv() -> Any:
    for name in ("libGL.so.1", "libOpenGL.so.0", "libGL.so"):
        try:
            fn = ctypes.CDLL(name).glGetIntegerv
        except (OSError, AttributeError):
            continue
        fn.restype = None
        fn.argtypes = [ctypes.c_uint, ctypes.POINTER(ctypes.c_int)]
        return fn
    return None


def clear_gl_errors(ctx: Any) -> list[str]:
    """Read and clear every pending GL error flag (a failed frame can leave one, e.g.
    ``GL_OUT_OF_MEMORY`` from a texture that could not be made, which the next frame's
    own check would otherwise report as its error); returns what was pending."""
    pending = []
    for _ in range(16):  # one flag per kind of error at most; a lost context keeps answering
        err = ctx.error
        if err == "GL_NO_ERROR":
            break
        pending.append(err)
    return pending


def make_target(ctx: Any, size: tuple[int, int], components: int, dtype: str) -> tuple[Any, Any]:
    """A colour texture and a framebuffer over it, or an error with nothing left behind:
    a texture the GL could not make, or a framebuffer it calls incomplete, is released, the
    default framebuffer bound and the GL's error flags cleared, so the owner's next frame
    starts clean. Raises ``MemoryError`` for ``GL_OUT_OF_MEMORY``, else ``RuntimeError``."""
    tex = fbo = None
    try:
        tex = ctx.texture(size, components, dtype=dtype)
        err = ctx.error
        if err != "GL_NO_ERROR":
            raise RuntimeError(err)
        fbo = ctx.framebuffer(color_attachments=[tex])
        return tex, fbo
    except Exception as exc:
        ctx.detect_framebuffer(0).use()
        for obj in (fbo, tex):
            if obj is not None:
                obj.release()
        pending = [str(exc)] + clear_gl_errors(ctx)
        what = f"could not make a {size[0]}x{size[1]} render target of {components} x {dtype} ({', '.join(pending)})"
        if any("OUT_OF_MEMORY" in p for p in pending):
            raise MemoryError(what) from exc
        raise RuntimeError(what) from exc


def table_texture(ctx: Any, table: "PreintegrationTable") -> Any:
    """A 3D texture of a :class:`~tetvr.optics.table.PreintegrationTable` for
    ``shaders/lookup.glsl``: linear filtering, clamped to the edge texels.

    Texel (slice, front, back): the thickness slice varies fastest, so the 8 texels of one
    trilinear fetch lie within a few hundred bytes instead of a slice (1 MiB at 256 bins)
    apart -- the same image, and on llvmpipe a tenth less draw time at 10k tets.
    """
    import moderngl

    k1, n, _, _ = table.data.shape  # (slice, back, front, RGBA)
    texels = np.moveaxis(table.data, 0, 2)  # (back, front, slice, RGBA), in C order below
    dtype = "f4" if texels.dtype == np.float32 else "f1"
    # A table built in this layout (tetvr.gl.tablebuild) is uploaded as it is, without a copy.
    tex = ctx.texture3d((k1, n, n), 4, texels if texels.flags.c_contiguous else texels.tobytes(), dtype=dtype)
    tex.repeat_x = tex.repeat_y = tex.repeat_z = False
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    extras = {}
    warp = table.warp_texels()
    if warp is not None:
        # A warped table's node index and optical depth per scalar cell (lookup.glsl's u_warp:
        # rows 0 and 1), read unfiltered.
        warp_tex = ctx.texture((warp.shape[1], warp.shape[0]), 4, warp.tobytes(), dtype="f4")
        warp_tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        extras[WARP_UNIT] = warp_tex
    if table.steps is not None:
        # A stepped table's corner blocks (lookup_steps.glsl's u_steps), filtered as the table.
        k1, _, width, _ = table.steps.shape  # (slice, back node, bin and front node, RGBA)
        steps_tex = ctx.texture3d((width, 2, k1), 4, np.ascontiguousarray(table.steps).tobytes(), dtype=dtype)
        steps_tex.repeat_x = steps_tex.repeat_y = steps_tex.repeat_z = False
        steps_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        extras[STEPS_UNIT] = steps_tex
    return TableTextures(tex, extras) if extras else tex


class TableTextures:
    """The textures of a warped table (:mod:`tetvr.optics.tablewarp`) or of one whose transfer
    function steps at its nodes (:mod:`tetvr.optics.tablesteps`), used and released as one:
    ``use(unit)`` binds the table there and the others at their units (:data:`WARP_UNIT`,
    ``u_warp``; :data:`~tetvr.optics.tablesteps.STEPS_UNIT`, ``u_steps``)."""

    def __init__(self, table: Any, extras: dict[int, Any]) -> None:
        self.table, self.extras = table, extras

    def use(self, location: int = 0) -> None:
        self.table.use(location)
        for unit, tex in self.extras.items():
            tex.use(unit)

    def release(self) -> None:
        self.table.release()
        for tex in self.extras.values():
            tex.release()


#: The texture unit of a warped table's warp (``PreintegrationTable.gl_uniforms``' u_warp;
#: the ray caster's own textures take units 1-7).
WARP_UNIT = 8


def set_uniforms(prog: Any, **uniforms: Any) -> None:
    """Set the uniforms a program uses; 2D arrays are written as column-major matrices, in
    float64 for a ``dmat`` uniform."""
    for name, value in uniforms.items():
        if name not in prog:
            continue  # optimised away by the compiler
        arr = np.asarray(value) if isinstance(value, np.ndarray) else None
        if arr is not None and arr.ndim == 2:
            dtype = np.float64 if prog[name].fmt.endswith("d") else np.float32
            prog[name].write(arr.T.astype(dtype).tobytes())  # GLSL is column-major
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


def tf_points_texture(ctx: Any, tf: Any) -> Any:
    """The transfer function's control points for integration without a table
    (shaders/tf_points.glsl): row 0 (scalar, opacity), row 1 the colour, one texel per
    point of the union of both maps."""
    bp = tf.breakpoints
    rgb, a = tf.evaluate(bp)
    data = np.zeros((2, bp.shape[0], 4), np.float32)
    data[0, :, 0], data[0, :, 1], data[1, :, :3] = bp, a, rgb
    tex = ctx.texture((bp.shape[0], 2), 4, data.tobytes(), dtype="f4")
    tex.repeat_x = tex.repeat_y = False
    return tex


def cached_targets(ctx: Any, targets: dict[Any, dict[str, Any]], size: tuple[int, int],
                   make: Any, keep: int = 2) -> dict[str, Any]:
    """The render-target set of this size from ``targets``, made by ``make(size, t)`` (which
    fills the dict ``t``) on first use; beyond ``keep`` sizes the old sets are released
    first (a window being resized would otherwise keep one set per size it passed through).

    A set the GL could not make (a texture out of memory, a framebuffer it calls
    incomplete) is released, whatever of it was made, and named in a ``MemoryError``
    (``GL_OUT_OF_MEMORY``, or an incomplete framebuffer, which is how a software GL
    reports a texture it could not allocate) or a ``RuntimeError``, with the size.
    """
    t = targets.get(size)
    if t is None:
        if len(targets) >= keep:
            drop_targets(ctx, targets)
        t = {}
        try:
            make(size, t)
            err = ctx.error
            if err != "GL_NO_ERROR":
                raise RuntimeError(err)
        except Exception as exc:
            drop_targets(ctx, {size: t})
            pending = [str(exc)] + clear_gl_errors(ctx)
            what = (f"could not make the {size[0]}x{size[1]} render targets ({', '.join(pending)}); "
                    f"the GL probably ran out of memory for a frame of this size: render it smaller")
            if any("OUT_OF_MEMORY" in p or "not complete" in p for p in pending):
                raise MemoryError(what) from exc
            raise RuntimeError(what) from exc
        targets[size] = t
    return t


def drop_targets(ctx: Any, targets: dict[Any, dict[str, Any]]) -> None:
    """Release cached render-target sets (each a dict of name -> GL object) and forget them.
    The default framebuffer is bound first (deleting the bound one leaves GL pointing at a
    dead name: INVALID_OPERATION at the next framebuffer), and each set's framebuffers
    (names holding "fbo") go before their attachments."""
    ctx.detect_framebuffer(0).use()
    for old in targets.values():
        for name in sorted(old, key=lambda n: "fbo" not in n):
            old[name].release()
    targets.clear()

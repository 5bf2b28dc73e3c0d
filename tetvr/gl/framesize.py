"""The memory one frame takes, estimated from its size before anything is drawn.

Everything a frame allocates in proportion to its pixels is counted here, per method: the
GL render targets (tet marching's entry, depth, two sets of colour, state and last-cell
images and, on a non-convex mesh, its per-pixel entry lists; projected tetrahedra's and
the volume ray caster's RGBA32F target; the opaque surfaces' targets), the readback (the
bytes read and the flipped float32 image) and, for ``tetvr render``, the picture (the
legend's matplotlib canvas and the PNG). A software GL (Mesa's llvmpipe) keeps its render
targets in host memory, so there they count against the host as well.

A frame that does not fit is refused with :class:`FrameMemoryError` (a ``MemoryError``)
naming the size, the estimate, what is available and what would fit, before any GL work.
Without the check, a frame too large for the host failed half-way: llvmpipe called the
framebuffer "not complete (UNSUPPORTED)", and under an address-space limit (``ulimit -v``)
moderngl's readback crashed the process with SIGSEGV.

The bytes per pixel follow from the targets' formats. ``bench/frame_memory.py`` measures
them on llvmpipe (``bench/results/frame_memory.json``, the table in ``docs/limits.md``), and
``tests/badinput/test_frame_memory.py`` holds the constants here to those measurements.

Examples
--------
>>> est = frame_estimate((2048, 2048), "raymarch", software=True)
>>> est.bytes_per_pixel, est.host // 2**20  # and 32 MiB whatever the size
(96, 416)
>>> frame_estimate((2048, 2048), "projected", software=False).bytes_per_pixel  # targets on the GPU
32
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from typing import Any

from tetvr.core import image as _image
from tetvr.core.image import _gib, image_size
from tetvr.gl.march_layout import LIST_LENGTH, LIST_MAX_BYTES
from tetvr.order.method import march_fits
from tetvr.settings import RenderSettings

__all__ = ["FrameMemoryError", "FrameEstimate", "TARGET_BYTES_PER_PIXEL", "LIST_BYTES_PER_PIXEL",
           "READBACK_BYTES_PER_PIXEL", "SURFACE_BYTES_PER_PIXEL", "PICTURE_BYTES_PER_PIXEL", "PNG_BLOCK_BYTES",
           "CONTEXT_BYTES", "CONTEXT_ADDRESS_SPACE", "FRAME_FIXED_BYTES", "FRAME_MARGIN_BYTES",
           "ANNOTATE_FIXED_BYTES", "frame_method", "frame_estimate", "picture_estimate", "host_available",
           "check_frame", "check_picture"]

#: Bytes per pixel of each method's GL render targets.
TARGET_BYTES_PER_PIXEL: dict[str, int] = {
    # entry cell (i4) + depth (4) + two sets of colour (4 x f4), state (2 x f4) and last cell (i4)
    "raymarch": 4 + 4 + 2 * (16 + 8 + 4),
    "projected": 16,  # RGBA32F
    "raycast": 16,  # RGBA32F
}
#: Tet marching's entry lists on a non-convex mesh: a count (u4) and LIST_LENGTH (i4, i4)
#: per pixel, kept only up to :data:`~tetvr.gl.march_layout.LIST_MAX_BYTES`.
LIST_BYTES_PER_PIXEL = 4 + 8 * LIST_LENGTH
#: The readback: the bytes the GL returns and the flipped float32 image made from them.
READBACK_BYTES_PER_PIXEL = 32
#: Opaque surfaces: their targets (colour RGBA32F, eye depth f4, z-buffer) and their
#: colour's readback.
SURFACE_BYTES_PER_PIXEL = 24 + 32
#: The picture of a finished frame, beyond the frame itself (16 bytes a pixel): the legend,
#: triad and outline drawn by matplotlib and its PNG ("annotate", ``tetvr render``), or the
#: plain PNG (``--no-annotations``), whose float conversion works on blocks of rows.
PICTURE_BYTES_PER_PIXEL: dict[str, int] = {"annotate": 160, "png": 8}
#: The plain PNG's block of rows (:func:`tetvr.core.image.png_bytes`) and its temporaries.
PNG_BLOCK_BYTES = 64 << 20
#: What a renderer takes before its first pixel, whatever the size: its GL context and
#: its first frame's shaders, table and driver threads. Resident memory, and address space
#: (mostly the driver's compiled code and thread stacks), which ``ulimit -v`` counts.
CONTEXT_BYTES = 256 << 20
CONTEXT_ADDRESS_SPACE = 1 << 30
#: Address space a frame may take besides its pixels once the context is made (a
#: renderer's first frame: its shaders' compiled code, the table). Under an address-space
#: limit an allocation that fails in the GL driver or in moderngl's readback ends the
#: process, so there the margin is kept; it also keeps the advised largest size safe.
FRAME_MARGIN_BYTES = 256 << 20
#: What a frame takes besides its pixels, whatever its size: the view's buffers, the
#: driver's working memory.
FRAME_FIXED_BYTES = 32 << 20
#: The picture's fixed part: matplotlib's figure and fonts.
ANNOTATE_FIXED_BYTES = 64 << 20

_NAMES = {"raymarch": "tet marching", "projected": "projected tetrahedra", "raycast": "the volume ray caster"}


class FrameMemoryError(MemoryError):
    """A frame larger than the memory it may take; raised before any GL work.

    ``size`` (width, height), ``method``, ``need`` and ``available`` (bytes) say why.
    """

    def __init__(self, message: str, *, size: tuple[int, int], method: str, need: int, available: int) -> None:
        super().__init__(message)
        self.size, self.method, self.need, self.available = size, method, need, available


@dataclasses.dataclass(frozen=True)
class FrameEstimate:
    """The bytes one frame of ``size`` takes: ``host`` (host memory at the frame's peak:
    ``fixed`` bytes and the ``parts`` that grow with the pixels, as (name, bytes)) and
    ``gpu`` (render targets in video memory; 0 on a software GL, whose targets are counted
    in ``host``)."""

    size: tuple[int, int]
    method: str
    host: int
    gpu: int
    parts: tuple[tuple[str, int], ...]
    fixed: int = 0

    @property
    def bytes_per_pixel(self) -> int:
        """Host bytes per pixel, rounded, besides the fixed part."""
        return round((self.host - self.fixed) / (self.size[0] * self.size[1]))


def frame_method(settings: RenderSettings | None, n_tets: int, *, order: Any = None, shader: str = "tet") -> str:
    """The method a mesh's frame will take, as far as its memory goes: ``"raymarch"`` or
    ``"projected"``. ``method="auto"`` counts as tet marching (the larger of the two)
    unless the mesh is large enough that "auto" takes projected tetrahedra by its size."""
    s = settings or RenderSettings()
    if shader != "tet" or order is not None or s.optics == "vtk":
        return "projected"
    if s.integration == "exact" or s.method == "raymarch":
        return "raymarch"
    if s.method == "projected" or not march_fits(n_tets):
        return "projected"
    return "raymarch"


def frame_estimate(size: tuple[int, int], method: str, *, software: bool | None, surfaces: bool = False
                   ) -> FrameEstimate:
    """The memory one frame of ``method`` at ``size`` (width, height) takes.

    ``software``: whether the GL keeps its render targets in host memory (llvmpipe); None
    where the GL is not known yet (no context made): then the host part is what every GL
    needs of the host. ``surfaces``: opaque surfaces drawn with it.
    """
    if method not in TARGET_BYTES_PER_PIXEL:
        raise ValueError(f"method must be one of {sorted(TARGET_BYTES_PER_PIXEL)}, got {method!r}")
    width, height = image_size(size)
    px = width * height
    targets = [("render targets", TARGET_BYTES_PER_PIXEL[method] * px)]
    if method == "raymarch" and px * LIST_BYTES_PER_PIXEL <= LIST_MAX_BYTES:
        targets.append(("entry lists", px * LIST_BYTES_PER_PIXEL))
    if surfaces:
        targets.append(("surface targets", 24 * px))
    host = [("readback", READBACK_BYTES_PER_PIXEL * px)]
    if surfaces:
        host.append(("surface readback", (SURFACE_BYTES_PER_PIXEL - 24) * px))
    gpu = sum(b for _, b in targets)
    if software:
        host, gpu = targets + host, 0
    return FrameEstimate((width, height), method, sum(b for _, b in host) + FRAME_FIXED_BYTES, gpu, tuple(host),
                         FRAME_FIXED_BYTES)


def picture_estimate(size: tuple[int, int], picture: str) -> FrameEstimate:
    """The memory the picture of a finished frame takes: the frame's image (16 bytes a
    pixel) and ``picture``, ``"annotate"`` (legend, triad, outline and PNG, as
    ``tetvr render`` writes it) or ``"png"`` (the plain PNG)."""
    if picture not in PICTURE_BYTES_PER_PIXEL:
        raise ValueError(f"picture must be one of {sorted(PICTURE_BYTES_PER_PIXEL)}, got {picture!r}")
    width, height = image_size(size)
    px = width * height
    parts = (("image", 16 * px), (picture, PICTURE_BYTES_PER_PIXEL[picture] * px))
    fixed = PNG_BLOCK_BYTES if picture == "png" else ANNOTATE_FIXED_BYTES
    return FrameEstimate((width, height), picture, sum(b for _, b in parts) + fixed, 0, parts, fixed)


def host_available() -> tuple[int | None, str]:
    """Bytes of host memory this process may still take, and where that comes from:
    the memory the system says is available (:func:`tetvr.core.image.available_memory`)
    and, where an address-space limit is set (``ulimit -v``, ``RLIMIT_AS``), what it
    leaves beyond the address space in use. (None, "") where the system says nothing."""
    budgets = _budgets()
    if not budgets:
        return None, ""
    return min(b[0] for b in budgets), "; ".join(b[1] for b in budgets)


def _budgets(context_made: bool = True) -> list[tuple[int, str, int, str]]:
    """Each limit on host memory that is known: (bytes left, what they are, what a frame
    takes of them besides its pixels, how to get more)."""
    found: list[tuple[int, str, int, str]] = []
    mem = _image.available_memory()
    if mem is not None:
        found.append((mem, f"{_gib(mem)} of memory available", 0 if context_made else CONTEXT_BYTES, "free memory"))
    limit = _address_space_limit()
    if limit is not None:
        used = _address_space_used()
        left = max(limit - used, 0)
        found.append((left, f"{_gib(left)} left under the address-space limit of {_gib(limit)} (ulimit -v, "
                            f"RLIMIT_AS; {_gib(used)} in use)",
                      FRAME_MARGIN_BYTES if context_made else CONTEXT_ADDRESS_SPACE,
                      "raise the address-space limit (ulimit -v)"))
    return found


def _address_space_limit() -> int | None:
    try:
        import resource
    except ImportError:  # pragma: no cover - not on Unix
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    return None if soft == resource.RLIM_INFINITY else int(soft)


def _address_space_used() -> int:
    """This process's virtual size (Linux: ``VmSize``); 0 where the system does not say."""
    with contextlib.suppress(OSError, ValueError, StopIteration):
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmSize:"))
    return 0


def check_frame(size: tuple[int, int], method: str, *, software: bool | None, surfaces: bool = False,
                context_made: bool = True) -> FrameEstimate:
    """The estimate of :func:`frame_estimate`, or :class:`FrameMemoryError` where its host
    part is more than the host can give (:func:`host_available`; with
    ``context_made=False``, counting the GL context yet to be made). The message names the
    size, the estimate, what is available and what to do: the largest size of this aspect
    that fits, projected tetrahedra where they fit and tet marching does not, or more memory.

    Examples
    --------
    >>> check_frame((64, 64), "projected", software=True).bytes_per_pixel
    48
    """
    est = frame_estimate(size, method, software=software, surfaces=surfaces)
    # Before the context is made, the GL is not known: the advice also gives a software GL's size.
    worst = frame_estimate(size, method, software=True, surfaces=surfaces) if software is None else None
    alt = frame_estimate(size, "projected", software=software, surfaces=surfaces) if method == "raymarch" else None
    _refuse_beyond(est, context_made, worst, alt)
    return est


def check_picture(size: tuple[int, int], picture: str) -> FrameEstimate:
    """The estimate of :func:`picture_estimate`, or :class:`FrameMemoryError` as
    :func:`check_frame` says, for the picture written after the frame."""
    est = picture_estimate(size, picture)
    _refuse_beyond(est, True, None, None)
    return est


def _refuse_beyond(est: FrameEstimate, context_made: bool, worst: FrameEstimate | None,
                   alt: FrameEstimate | None) -> None:
    """Raise :class:`FrameMemoryError` if ``est`` (and a context yet to be made) exceeds a
    limit; ``worst`` (a software GL's estimate) and ``alt`` (projected tetrahedra's) go
    into the advice."""
    budgets = _budgets(context_made)
    short = [(est.host + fixed - have, have, fixed, remedy) for have, _, fixed, remedy in budgets
             if est.host + fixed > have]
    if not short:
        return
    _, have, fixed, remedy = max(short)  # the limit that binds most
    need = est.host + fixed
    width, height = est.size
    px = width * height
    parts = ", ".join(f"{name} {round(b / px)}" for name, b in est.parts)
    working = {"annotate": "for the figure", "png": "for the PNG's block of rows"}.get(est.method, "for the frame")
    margin = "kept for its shaders and table" if context_made else "for the renderer's context, shaders and table"
    besides = [f"{_gib(b)} {name}" for b, name in ((est.fixed, working), (fixed, margin)) if b]
    what = _NAMES.get(est.method, "its picture: " + ("legend and PNG" if est.method == "annotate" else "PNG"))
    text = (f"a frame of {width}x{height} pixels ({what}) needs about {_gib(need)} of host memory "
            f"({est.bytes_per_pixel} bytes a pixel: {parts}{'; and ' + ', '.join(besides) if besides else ''}), "
            f"more than the {_gib(have)} this process may take ({'; '.join(b[1] for b in budgets)}). ")

    def largest(e: FrameEstimate) -> str:
        scale = min(math.sqrt(max(h - max(f, FRAME_MARGIN_BYTES) - e.fixed, 0) / (e.host - e.fixed))
                    for h, _, f, _ in budgets)
        return f"{int(width * scale)}x{int(height * scale)}"

    todo = [f"render at most {largest(est)} (the same aspect"
            + (f"; {largest(worst)} where the GL keeps its render targets in host memory, as Mesa's llvmpipe does)"
               if worst is not None else ")")]
    if alt is not None and all(alt.host + f <= h for h, _, f, _ in budgets):
        todo.append(f"use method=\"projected\" ({alt.bytes_per_pixel} bytes a pixel)")
    todo.append(remedy)
    raise FrameMemoryError(text + "To render it: " + ", or ".join(todo) + ".",
                           size=est.size, method=est.method, need=need, available=have)

"""The viewer's render loop: one thread owns the renderer; input only changes what is wanted.

Input (a mouse move, a transfer-function edit, a resize) arrives on whatever thread the
front end delivers it on. It changes the *wanted* state of a :class:`~tetvr.apps.viewer.model.ViewerModel`
under the loop's lock and wakes the loop; it never renders. The loop thread renders the
latest wanted state whenever it is free, so states that arrive while a frame renders are
merged into the next frame, never queued. While input keeps coming (less than
``settle_s`` since the last change) the loop draws *previews*; once it stops, one *full*
frame. A preview's size comes from the measured cost of the frames before it
(:class:`PreviewSizer`), so a preview arrives within about ``budget_s`` of the input
whatever the mesh.

Nothing here imports a front end: the loop hands each :class:`Frame` (or the error that
stopped one) to a ``deliver`` callback, which the Jupyter viewer turns into a message to
the browser. Tests drive the loop with a fake renderer and :meth:`RenderLoop.wait_idle`.

Examples
--------
>>> loop = RenderLoop(model, deliver=print)      # doctest: +SKIP
>>> loop.update(lambda m: m.control.azimuth(10))  # doctest: +SKIP
>>> loop.wait_idle(5.0)                          # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
import traceback
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["Frame", "PreviewSizer", "RenderLoop"]


@dataclasses.dataclass(frozen=True)
class Frame:
    """One finished frame (or the error instead of it).

    ``image`` is float premultiplied RGBA (row 0 at the top), ``None`` when ``error`` is
    set; ``final`` — the full-size frame after input stopped (else a preview);
    ``revision`` — the wanted state it shows; ``seconds`` — its render time;
    ``wanted_at`` — the clock time of the oldest input it answers (for latency)."""

    image: NDArray[np.float32] | None
    size: tuple[int, int]
    final: bool
    revision: int
    seconds: float
    wanted_at: float
    error: str | None = None


class PreviewSizer:
    """The preview size from the measured cost of this mesh's frames.

    A frame's time is modelled as ``overhead + per_pixel * pixels``, fitted (least
    squares) to the last ``window`` *warm* frames: the projected tetrahedra's per-tet work and a
    frame's fixed costs (transfer, setup) do not shrink with the image, the ray caster's
    marching does. The preview gets the pixels whose predicted time meets ``budget_s``.
    Where the overhead alone takes more than half the budget, the budget cannot be met and
    shrinking further buys little: the pixels then get half the budget, so a preview takes
    the overhead and ``budget_s / 2`` more. (A fit on a loaded machine can find a large
    overhead and a tiny cost a pixel; the pixels' share is bounded whatever the fit says.)
    It is never narrower than ``min_scale`` of the full frame: below a quarter of the width
    a preview is a smear.

    A *cold* frame (``observe(..., cold=True)``) also paid for what is done once: the
    mesh sent to the render process, its per-mesh records, a new table; a mesh's first
    frame takes many times a warm one. It is no sample of the view's cost, only an upper
    bound of it: until a warm frame is measured, the preview gets the pixels the budget
    buys at the cold frame's time per pixel. Growth from warm samples is limited to
    ``max_growth`` (in side length) a frame, so one lucky frame cannot make the next slow.
    :meth:`reset` forgets the samples (another mesh).

    Examples
    --------
    >>> s = PreviewSizer(budget_s=0.1, min_scale=0.1)
    >>> s.observe(1.0, size=(400, 300), full=(400, 300))  # a full frame took 1 s
    >>> s.size((400, 300))                                  # -> ~1/10 the pixels
    (126, 95)
    >>> s.reset(); s.observe(10.0, size=(400, 300), full=(400, 300), cold=True)
    >>> s.size((400, 300))                                  # a first frame: at least min_scale
    (40, 30)
    """

    def __init__(self, *, budget_s: float = 0.1, min_scale: float = 0.25, max_scale: float = 1.0,
                 max_growth: float = 1.5, window: int = 8) -> None:
        if not (math.isfinite(budget_s) and budget_s > 0):
            raise ValueError(f"budget_s must be positive, got {budget_s!r}")
        if not (0 < min_scale <= max_scale <= 1):
            raise ValueError(f"need 0 < min_scale <= max_scale <= 1, got {min_scale!r}, {max_scale!r}")
        if not (math.isfinite(max_growth) and max_growth >= 1):
            raise ValueError(f"max_growth must be >= 1, got {max_growth!r}")
        self.budget_s = float(budget_s)
        self.min_scale = float(min_scale)
        self.max_scale = float(max_scale)
        self.max_growth = float(max_growth)
        self.window = int(window)
        self.reset()

    def reset(self) -> None:
        """Forget the measured frames (the next mesh costs something else)."""
        self.samples: list[tuple[float, float]] = []  # (pixels, seconds) of warm frames
        self.scale = float(np.clip(0.5, self.min_scale, self.max_scale))
        self.overhead_s = 0.0
        self.per_pixel_s = 0.0

    def _fit(self) -> tuple[float, float]:
        px = np.array([p for p, _ in self.samples])
        t = np.array([s for _, s in self.samples])
        if np.ptp(px) > 0.1 * px.max():
            k, c = np.polyfit(px, t, 1)
            if k > 0 and c >= 0:
                return float(c), float(k)
        # One size only, or a fit the noise bent: all of the time is per pixel.
        return 0.0, float(np.median(t / px))

    def _scale_for(self, c: float, k: float, full: tuple[int, int]) -> float:
        target_px = max(self.budget_s - c, self.budget_s / 2) / k
        return math.sqrt(max(target_px, 1.0) / float(full[0] * full[1]))

    def observe(self, seconds: float, *, size: tuple[int, int], full: tuple[int, int], cold: bool = False) -> None:
        """A frame of ``size`` pixels took ``seconds``; ``full`` is the full frame's size;
        ``cold``: the frame included work done once (see above)."""
        if not (seconds > 0 and math.isfinite(seconds)):
            return
        pixels = float(size[0] * size[1])
        if cold:
            if not self.samples:  # the best bound there is until a warm frame
                self.scale = float(np.clip(self._scale_for(0.0, seconds / pixels, full), self.min_scale,
                                           self.max_scale))
            return
        self.samples = (self.samples + [(pixels, float(seconds))])[-self.window:]
        c, k = self._fit()
        self.overhead_s, self.per_pixel_s = c, k
        want = self._scale_for(c, k, full)
        self.scale = float(np.clip(min(want, self.scale * self.max_growth), self.min_scale, self.max_scale))

    def size(self, full: tuple[int, int]) -> tuple[int, int]:
        """The preview size for a full frame of ``full`` pixels (aspect kept)."""
        w, h = full
        return max(1, round(w * self.scale)), max(1, round(h * self.scale))


class RenderLoop:
    """A thread that renders the latest wanted state of ``model``.

    Parameters
    ----------
    model : a :class:`~tetvr.apps.viewer.model.ViewerModel`; its renderer is used by this thread only
        (and released by :meth:`close` with the model).
    deliver : called on the loop thread with each :class:`Frame`; keep it short (hand the
        frame to the front end).
    settle_s : quiet time after the last change before the full frame.
    budget_s : the render time a preview aims for (see :class:`PreviewSizer`).
    on_busy : called with ``True`` when a frame starts and ``False`` when the loop has
        nothing left to draw ("rendering…" feedback).
    clock : time source, of the settle times and of each frame's render time.
    """

    def __init__(self, model: Any, deliver: Callable[[Frame], None], *, settle_s: float = 0.25,
                 budget_s: float = 0.1, on_busy: Callable[[bool], None] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not float(settle_s) >= 0.0:
            raise ValueError(f"settle_s must be >= 0, got {settle_s!r}")
        self.model = model
        self.deliver = deliver
        self.settle_s = float(settle_s)
        self.sizer = PreviewSizer(budget_s=budget_s)
        self._last_state: tuple[Any, ...] | None = None  # what the last frame drew, but the view
        self.on_busy = on_busy
        self.clock = clock
        self._cond = threading.Condition(threading.RLock())
        self._revision = 0  # bumped by every change; 0: nothing wanted yet (update() asks for the first frame)
        self._drawn = 0  # revision of the last frame drawn (any kind)
        self._final = 0  # revision of the last full frame drawn
        self._camera_moved = True
        self._tf_changed = False  # since the last full frame: previews use a small table
        self._last_change = -math.inf
        self._first_unanswered: float | None = None  # clock time of the oldest input not yet drawn
        self._closed = False
        self._holding = False  # a button is held (a drag): its end, not a pause, brings the full frame
        self.hold_settle_s = max(1.0, self.settle_s)
        self._suspend = False
        self._busy = False
        self.last_frame: Frame | None = None
        self.last_error: str | None = None
        self.frames = 0
        self._thread = threading.Thread(target=self._run, name="tetvr-render-loop", daemon=True)
        self._thread.start()

    # ---- input side (any thread) ----
    @property
    def lock(self) -> Any:
        """Held while the wanted state changes and while the loop reads it."""
        return self._cond

    def update(self, change: Callable[[Any], Any] | None = None, *, camera: bool = True,
               final: bool = False) -> Any:
        """Apply ``change(model)`` to the wanted state and wake the loop; returns what
        ``change`` returned. ``camera`` — the view moved (a projected-tetrahedra frame
        sorts afresh); ``final`` — skip previews (a resize, a scene load)."""
        with self._cond:
            if self._closed:
                raise RuntimeError("the viewer is closed")
            out = change(self.model) if change is not None else None
            self._revision += 1
            self._camera_moved = self._camera_moved or camera
            self._tf_changed = self._tf_changed or not camera
            now = self.clock()
            self._last_change = -math.inf if final else now
            if self._first_unanswered is None:
                self._first_unanswered = now
            self._cond.notify_all()
            return out

    def hold(self) -> None:
        """A drag has begun (a mouse button went down): pauses in its input are not its
        end, so the full frame waits ``hold_settle_s`` (1 s) of quiet, or :meth:`settle`.
        (Under load, browser events arrive with gaps longer than ``settle_s``; a full frame
        started in such a gap would hold up the previews for its whole length.)"""
        with self._cond:
            self._holding = True

    def settle(self) -> None:
        """The input has ended (a mouse button came up): draw the full frame now rather
        than ``settle_s`` later. Nothing is drawn if the full frame is already current."""
        with self._cond:
            self._holding = False
            self._last_change = -math.inf
            self._cond.notify_all()

    def suspend(self) -> None:
        """Free the renderer (its GL memory, its process) on the loop thread, between
        frames; the next frame makes a new one. For a viewer nobody sees."""
        with self._cond:
            self._suspend = True
            self._cond.notify_all()

    def redraw(self) -> None:
        """Draw the full frame again (e.g. the front end reconnected)."""
        self.update(camera=False, final=True)

    @property
    def revision(self) -> int:
        return self._revision

    def wait_idle(self, timeout: float = 30.0) -> bool:
        """Block until the latest state is drawn as a full frame (or ``timeout``)."""
        end = time.monotonic() + timeout
        with self._cond:
            while not self._closed and (self._final != self._revision or self._busy):
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.05))
        return True

    def wait_frame(self, after: int, timeout: float = 30.0) -> Frame | None:
        """The first frame drawn after frame count ``after`` (None on timeout)."""
        end = time.monotonic() + timeout
        with self._cond:
            while not self._closed and self.frames <= after:
                left = end - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(min(left, 0.05))
            return self.last_frame

    def close(self, timeout: float = 30.0) -> None:
        """Stop the thread (after the frame it is drawing) and release the model's GL."""
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)
        self.model.close()

    @property
    def closed(self) -> bool:
        return self._closed

    # ---- the loop thread ----
    def _next(self) -> tuple[Any, ...] | None:
        """Wait for something to draw; the request and a snapshot of the wanted state."""
        from tetvr.apps.viewer.model import RenderRequest

        with self._cond:
            while True:
                if self._closed:
                    return None
                if self._suspend:
                    self._suspend = False
                    return ()
                now = self.clock()
                quiet = now - self._last_change
                settle = self.hold_settle_s if self._holding else self.settle_s
                if self._revision != self._drawn and quiet < settle:
                    final = False
                    break
                if self._final != self._revision and quiet >= settle:
                    final = True
                    break
                if self._busy:
                    self._busy = False
                    self._notify_busy(False)
                    self._cond.notify_all()
                timeout = None if self._final == self._revision else max(settle - quiet, 0.001)
                self._cond.wait(timeout)
            m = self.model
            full = tuple(m.size)
            size = full if final else self.sizer.size(full)  # type: ignore[arg-type]
            sort = self._camera_moved and final
            request = RenderRequest(size, sort=sort, final=final)  # type: ignore[arg-type]
            state = (m.mesh, m.camera, m.editor.transfer_function(), self._tf_changed and not final, m.fusion_state())
            revision, wanted_at = self._revision, self._first_unanswered
            self._first_unanswered = None
            if final:
                self._camera_moved = self._tf_changed = False
            if not self._busy:
                self._busy = True
                self._notify_busy(True)
            return request, state, revision, (now if wanted_at is None else wanted_at)

    def _notify_busy(self, busy: bool) -> None:
        if self.on_busy is not None:
            try:
                self.on_busy(busy)
            except Exception:  # noqa: BLE001 - feedback must not stop the loop; the error is kept
                self.last_error = traceback.format_exc()

    def _cold(self, mesh: Any, tf: Any, small_table: bool, fusion: Any) -> bool:
        """Whether the next frame does work once, besides drawing the view (a new mesh, its
        renderer made, a new table): its time is no measure of the view's cost. Another
        mesh also makes the sizer forget the last one's costs."""
        state = (mesh, tf, small_table, None if fusion is None else (id(fusion[0]), *fusion[1:]))
        last, self._last_state = self._last_state, state
        if last is None or last[0] is not mesh:
            self.sizer.reset()
            return True
        return not self.model.renderer_ready or last[1:] != state[1:]

    def _run(self) -> None:
        while True:
            job = self._next()
            if job is None:
                return
            if job == ():
                try:
                    self.model.close()  # made again by the next frame
                except Exception:  # noqa: BLE001 - kept, and shown with the next frame's status
                    self.last_error = traceback.format_exc()
                continue
            request, (mesh, camera, tf, small_table, fusion), revision, wanted_at = job
            cold = self._cold(mesh, tf, small_table, fusion)
            t0 = self.clock()
            try:
                image = self.model.draw(mesh, camera, tf, request, preview_table=small_table, fusion=fusion)
                error = None
            except Exception as exc:  # noqa: BLE001 - shown in the viewer, not swallowed
                image, error = None, f"{type(exc).__name__}: {exc}"
                self.last_error = traceback.format_exc()
            seconds = self.clock() - t0
            if error is None:
                self.sizer.observe(seconds, size=request.size, full=tuple(self.model.size), cold=cold)
            frame = Frame(image, request.size, request.final, revision, seconds, wanted_at, error)
            with self._cond:
                self._drawn = revision
                if request.final or error is not None:
                    # an error is not retried until the state changes again
                    self._final = revision
                self.last_frame = frame
                self.frames += 1
                self._cond.notify_all()
            try:
                self.deliver(frame)
            except Exception:  # noqa: BLE001 - the front end's failure is kept and shown next frame
                self.last_error = traceback.format_exc()

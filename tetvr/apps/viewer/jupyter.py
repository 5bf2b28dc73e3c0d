"""The Jupyter viewer: frames from :class:`~tetvr.apps.viewer.loop.RenderLoop`, shown by ``jupyter_rfb``.

``jupyter_rfb`` (the remote frame buffer pygfx, vispy and fastplotlib use) carries the
picture and the input: it throttles pointer and wheel events in the browser, keeps at
most two frames in flight (the browser acknowledges each), sends JPEG while frames keep
coming and a lossless PNG when they stop (here: PNG throughout, see ``_build``), and
reports the size the picture really has on the page. This module only connects it to the render loop:

* browser events -> :meth:`RenderLoop.update` (the wanted camera, transfer function,
  size); nothing renders on the kernel's threads;
* each finished frame -> 8-bit RGB in a one-frame slot -> sent by the render thread
  itself while fewer than two frames are in flight, else by the thread that receives the
  browser's acknowledgement; a frame the browser had no time for is replaced, never
  queued. A cell that keeps the kernel busy does not hold the frames back (the kernel's
  event loop is not involved), though the input that arrives meanwhile waits for it.

The transfer-function editor is a second frame buffer showing the histogram, the opacity
curve, the colour legend and its ticks: click to add a point, drag to move it,
double-click to remove it (:class:`~tetvr.apps.viewer.editor.HistogramPicker`).

Examples
--------
>>> from tetvr.apps.viewer import Viewer                  # doctest: +SKIP
>>> Viewer("post.vtk")                               # doctest: +SKIP
"""

from __future__ import annotations

import asyncio
import base64
import html
import math
import os
import threading
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from tetvr.core.image import png_bytes, to_rgba8
from tetvr.mesh.tetmesh import TetMesh
from tetvr.scene.scene import Scene
from tetvr.optics.transfer import PRESETS
from tetvr.apps.viewer.model import FUSION_PICKER, PICKER_COLORMAPS, ViewerModel, _colormap_choice, _has_matplotlib
from tetvr.apps.viewer.editor import HistogramPicker, legend_image, nice_ticks
from tetvr.apps.viewer.loop import Frame, RenderLoop

try:
    import ipywidgets as w
    from jupyter_rfb import RemoteFrameBuffer
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError(f"the Jupyter viewer needs jupyter_rfb and ipywidgets: pip install 'tetvr[widget]' ({exc})"
                      ) from None

__all__ = ["Viewer"]

HIST_SIZE = (360, 120)
LEGEND_HEIGHT = 14


def _same(value: float, current: float, scale: float) -> bool:
    """Whether a control's value is ``current`` up to rounding (relative to ``scale``): a
    control echoes the value it was given as the browser rounds it, and an echo must not
    draw a frame."""
    return abs(float(value) - float(current)) <= 1e-9 * max(abs(float(scale)), abs(float(current)))


class _Canvas(RemoteFrameBuffer):  # type: ignore[misc]
    """A frame buffer whose frames and events belong to someone else (the viewer)."""

    def __init__(self, frames: Callable[[], NDArray[np.uint8] | None], events: Callable[[dict[str, Any]], None],
                 **kw: Any) -> None:
        super().__init__(**kw)
        self._frames = frames
        self._events = events

    def get_frame(self) -> NDArray[np.uint8] | None:
        return self._frames()

    def handle_event(self, event: dict[str, Any]) -> None:
        self._events(event)


class _EditorPanel:
    """A transfer-function editor on a histogram, as a frame buffer with value ticks under it.

    ``editor`` and ``log_counts`` are called for the current editor and its histogram
    (they change with the field or a loaded scene); edits go through ``viewer._edit``."""

    def __init__(self, viewer: "Viewer", editor: Callable[[], Any], log_counts: Callable[[], NDArray[np.float64]],
                 css_class: str) -> None:
        self.viewer = viewer
        self._editor = editor
        self._log_counts = log_counts
        self.picker = HistogramPicker(editor(), size=HIST_SIZE)
        self.canvas = _Canvas(self.frame, self.event, css_width=f"{HIST_SIZE[0] + 2}px",
                              css_height=f"{HIST_SIZE[1] + LEGEND_HEIGHT + 2}px", resizable=False, cursor="crosshair")
        self.canvas.add_class(css_class)
        self.ticks = w.HTML(layout=w.Layout(width=f"{HIST_SIZE[0] + 2}px", height="20px"))

    def frame(self) -> NDArray[np.uint8]:
        with self.viewer.loop.lock:
            ed = self._editor()
            tf = ed.transfer_function()
            picture = ed.image(None, size=HIST_SIZE, selected=self.picker.selected, log_counts=self._log_counts())
            lo, hi = ed.scalar_range
        legend = legend_image(tf, (lo, hi), size=(HIST_SIZE[0], LEGEND_HEIGHT), ticks=nice_ticks(lo, hi))
        return np.ascontiguousarray(to_rgba8(np.concatenate([picture, legend]))[..., :3])

    def event(self, event: dict[str, Any]) -> None:
        kind = event.get("type") or event.get("event_type")
        x, y = float(event.get("x", 0.0)), float(event.get("y", 0.0))
        picker = self.picker
        if kind == "pointer_down" and y < HIST_SIZE[1]:
            self.viewer.loop.hold()
            self.viewer._edit(self, lambda: picker.press(x, y))
        elif kind == "pointer_move" and picker.dragging:
            self.viewer._edit(self, lambda: picker.move(x, y))
        elif kind == "pointer_up":
            if picker.dragging:
                self.viewer.loop.settle()  # the edit is over: the full frame now
            picker.release()
        elif kind == "double_click" and y < HIST_SIZE[1]:
            self.viewer._edit(self, lambda: picker.double_click(x, y))

    def sync(self) -> None:
        """Follow the current editor (after a load or a field change): ticks and picture."""
        ed = self._editor()
        if self.picker.editor is not ed:
            self.picker.editor = ed
            self.picker.selected = 0
        lo, hi = ed.scalar_range
        spans = []
        for t in nice_ticks(lo, hi):
            left = (t - lo) / (hi - lo) * (HIST_SIZE[0] - 1)
            spans.append(f'<span style="position:absolute;left:{left:.0f}px;transform:translateX(-50%);'
                         f'font-size:11px">{t:.4g}</span>')
        self.ticks.value = f'<div style="position:relative;height:18px;margin-left:1px">{"".join(spans)}</div>'
        self.canvas.request_draw()


class Viewer:
    """A scene in Jupyter: drag to orbit, shift- or right-drag to pan, wheel to zoom; edit
    the transfer function on the histogram; pick the field and colour map; save and load
    the scene JSON.

    Parameters
    ----------
    scene : a :class:`~tetvr.Scene`, a scene file, a mesh file or a :class:`~tetvr.TetMesh`.
    size : the full frame's size (default: the scene's; 560x420 for a mesh). The picture
        narrows with the page, keeping this aspect.
    settle_s : quiet time after the last input before the full frame is drawn.
    preview_budget_s : the render time previews aim for; their size follows the measured
        cost of this mesh's frames (:class:`~tetvr.apps.viewer.loop.PreviewSizer`), never
        less than a quarter of the picture's width.
    volume, volume_tf, fusion : an image volume (:class:`tetvr.Volume`, e.g. the CT the
        mesh was made from) shown around the mesh, its transfer function (default: grey
        levels with an opacity ramp) and the fusion mode (:data:`tetvr.apps.viewer.model.FUSION_PICKER`,
        see :mod:`tetvr.fuse`); the viewer then has a second histogram editor and a
        fusion picker.
    renderer : anything with ``render(mesh, camera, tf, size=, order=)`` (and
        ``fuse(...)`` for a volume); by default
        (``"process"``) a :class:`tetvr.gl.Renderer` in a child process
        (:mod:`tetvr.apps.viewer.process`: moderngl holds the interpreter lock while it draws,
        which would stop the kernel's input and output for the length of each frame);
        ``None``: one in the kernel's process. Either is driven by the render loop only.
    idle_release_s : after this long with no view of the picture on any page (its output
        cleared by re-running the cell, or scrolled away), the renderer and its GL memory
        are freed; the next frame makes them again.

    :meth:`close` stops the loop and frees the GL memory; closing the widget calls it.

    Examples
    --------
    >>> v = Viewer("post.vtk")                          # doctest: +SKIP
    >>> v                                               # doctest: +SKIP
    """

    def __init__(self, scene: Scene | TetMesh | str | os.PathLike[str], *, size: tuple[int, int] | None = None,
                 settle_s: float = 0.25, preview_budget_s: float = 0.1, step_degrees: float = 15.0,
                 volume: Any = None, volume_tf: Any = None, fusion: str = "interleave",
                 renderer: Any = "process", idle_release_s: float = 60.0) -> None:
        from tetvr.apps.viewer.model import scene_of

        self.model = ViewerModel(scene_of(scene, size=size), renderer=renderer, settle_s=settle_s)
        self.model.set_volume(volume, volume_tf, mode=fusion)
        self.step_degrees = float(step_degrees)
        self._closed = False
        self._aspect = self.model.size[0] / self.model.size[1]
        self._css_size = tuple(self.model.size)
        self._slot_lock = threading.RLock()  # the slot, and the sending (the ack re-enters _send)
        self._status_lock = threading.Lock()
        self._sent = 0  # frames sent: jupyter_rfb numbers them the same way, and the browser acknowledges them
        self._pending: tuple[NDArray[np.uint8], bool] | None = None
        self._shown: tuple[NDArray[np.uint8], bool] | None = None
        self._resend = False
        self._last_full: Frame | None = None
        self._drag: tuple[float, float, bool] | None = None
        try:
            self._kernel_loop: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:  # plain Python, tests: deliver on the calling thread
            self._kernel_loop = None
        self.idle_release_s = float(idle_release_s)
        self._hidden_timer: threading.Timer | None = None
        self._build()
        self.canvas.observe(self._on_visibility, names="_has_visible_views")
        # The browser acknowledges each frame it took (jupyter_rfb's flow control): the
        # frame kept for lack of room goes out then, on the thread the message comes in on.
        self.canvas.observe(self._send, names="_frame_feedback")
        self.loop = RenderLoop(self.model, self._deliver, settle_s=settle_s, budget_s=preview_budget_s,
                               on_busy=self._busy)
        self.loop.update(final=True)

    # ---- layout ----
    def _build(self) -> None:
        m = self.model
        width, height = m.size
        # jupyter_rfb's own draws (on the kernel's event loop) send nothing: the render
        # thread sends each frame itself (_send), so a cell that keeps the kernel busy does not
        # hold back the frames of input that came before it.
        self.canvas = _Canvas(lambda: None, self._image_event, css_width="100%",
                              css_height=f"{height + 2}px", resizable=False, cursor="grab")
        self.canvas.max_buffered_frames = 2
        # Every frame as PNG: previews are small, and a JPEG preview would be followed
        # 0.3 s later by jupyter_rfb's lossless copy of it, in the way of the full frame.
        self.canvas.quality = 100
        self.canvas.add_class("tetvr-image")  # names for styling and the browser tests
        self.status = w.HTML(value="rendering…")
        self.status.add_class("tetvr-status")
        image_box = w.VBox([self.canvas, self.status],
                           layout=w.Layout(width=f"{width + 2}px", max_width="100%", min_width="120px"))
        self.tf_panel = _EditorPanel(self, lambda: self.model.editor, lambda: self.model.log_counts(), "tetvr-hist")
        self.hist, self.picker = self.tf_panel.canvas, self.tf_panel.picker
        self.volume_panel: _EditorPanel | None = None
        volume_box: list[Any] = []
        if m.volume is not None:
            self.volume_panel = _EditorPanel(self, lambda: self.model.volume_editor,
                                             lambda: self.model.volume_log_counts(), "tetvr-volume-hist")
            self.fusion = w.Dropdown(options=FUSION_PICKER, value=m.fusion, description="fusion")
            self.fusion.observe(lambda c: self._guard(lambda: self._on_fusion(c["new"])), names="value")
            volume_box = [self.fusion, w.HTML("<b>volume</b>"), self.volume_panel.canvas, self.volume_panel.ticks]
        self.field = w.Dropdown(options=m.fields, value=m.field, description="field")
        cmaps = tuple(c for c in PICKER_COLORMAPS if c in PRESETS or _has_matplotlib())
        options, initial = _colormap_choice(cmaps, m.editor.colormap)
        self.colormap = w.Dropdown(options=options, value=initial, description="colours")
        u = m.editor.unit_distance
        self.unit = w.FloatLogSlider(value=u, base=10, min=math.log10(u) - 3, max=math.log10(u) + 3, step=0.05,
                                     description="unit dist.", readout_format=".3g")
        lo, hi = m.editor.scalar_range
        self.lo = w.FloatText(value=lo, description="range", layout=w.Layout(width="190px"))
        self.hi = w.FloatText(value=hi, layout=w.Layout(width="110px"))
        self.path = w.Text(value="scene.json", description="scene file", layout=w.Layout(width="220px"))
        self._syncing = False

        def button(label: str, tip: str, fn: Callable[[], Any], width: str = "44px") -> Any:
            b = w.Button(description=label, tooltip=tip, layout=w.Layout(width=width))
            b.on_click(lambda _b: self._guard(fn))
            return b

        s = self.step_degrees
        nav = w.HBox([
            button("◀", "orbit left", lambda: self._camera(lambda c: c.azimuth(-s))),
            button("▶", "orbit right", lambda: self._camera(lambda c: c.azimuth(s))),
            button("▲", "orbit up", lambda: self._camera(lambda c: c.elevation(s))),
            button("▼", "orbit down", lambda: self._camera(lambda c: c.elevation(-s))),
            button("⟲", "reset the camera", lambda: self._camera(lambda c: c.reset())),
        ], layout=w.Layout(flex_flow="row wrap"))
        files = w.HBox([self.path, button("save", "save the scene JSON", self._save, "60px"),
                        button("load", "load a scene JSON", self._load, "60px")],
                       layout=w.Layout(flex_flow="row wrap"))
        self.field.observe(lambda c: self._guard(lambda: self._on_field(c["new"])), names="value")
        self.colormap.observe(lambda c: self._guard(lambda: self._on_colormap(c["new"])), names="value")
        self.unit.observe(lambda c: self._guard(lambda: self._on_unit(c["new"])), names="value")
        for box in (self.lo, self.hi):
            box.observe(lambda _c: self._guard(self._on_range), names="value")
        side = w.VBox([nav, self.field, self.colormap, self.unit, w.HTML("<b>mesh</b>"), self.hist, self.tf_panel.ticks,
                       w.HBox([self.lo, self.hi], layout=w.Layout(flex_flow="row wrap")), *volume_box, files],
                      layout=w.Layout(min_width="0", max_width="100%"))
        self.widget = w.HBox([image_box, side], layout=w.Layout(flex_flow="row wrap", width="100%"))
        self.widget.add_class("tetvr-viewer")
        self._sync_ticks()
        if self.volume_panel is not None:
            self.volume_panel.sync()

    # ---- display ----
    def _repr_mimebundle_(self, **kw: Any) -> Any:  # pragma: no cover - needs a front-end
        self.loop.wait_idle(60.0)  # the first frame, so that the saved notebook has a picture
        data = self.widget._repr_mimebundle_(**kw)
        frame = self._last_full
        if isinstance(data, dict) and frame is not None and frame.image is not None:
            data["image/png"] = base64.b64encode(png_bytes(frame.image, self.model.background)).decode()
        return data

    def snapshot(self) -> Any:
        """The last full frame as an IPython image (for a static picture in the notebook)."""
        from IPython.display import Image

        frame = self._last_full
        if frame is None or frame.image is None:
            raise RuntimeError("no full frame drawn yet")
        return Image(data=png_bytes(frame.image, self.model.background), format="png")

    # ---- frames: loop thread -> kernel ----
    def _post(self, fn: Callable[[], Any]) -> None:
        """Run ``fn`` on the kernel's event loop (widgets are updated there)."""
        loop = self._kernel_loop
        if loop is None or loop.is_closed():
            fn()
        else:
            loop.call_soon_threadsafe(fn)

    def _busy(self, busy: bool) -> None:
        if busy:
            self._set_status("rendering…", final=False)

    def _deliver(self, frame: Frame) -> None:
        """A finished frame, on the render thread: into the slot, and out if the browser has room."""
        if frame.error is not None:
            self._show_error(frame.error)
            return
        assert frame.image is not None
        rgb = np.ascontiguousarray(to_rgba8(frame.image, self.model.background)[..., :3])
        with self._slot_lock:
            self._pending = (rgb, frame.final)  # a frame not yet sent is replaced
        if frame.final:
            self._last_full = frame
        self._send()
        if frame.final:
            # Previews leave the status at "rendering…": one message fewer per frame for the
            # browser to lay out while the pictures stream.
            self._set_status(f"full {frame.size[0]}×{frame.size[1]} · {frame.seconds * 1e3:.0f} ms", final=True)

    def _send(self, *_change: Any) -> None:
        """Send the newest frame if fewer than ``max_buffered_frames`` are in flight (any thread).

        jupyter_rfb's own scheduling would send from the kernel's event loop, which a running
        cell blocks. Its comm messages may be sent from any thread (ipykernel hands them to its
        IO thread), so the render thread sends, and keeps jupyter_rfb's rules: nothing before
        the page reports a view (a frame sent before the page has made the widget is lost),
        and a frame waits in the slot while the browser still decodes two earlier ones, to go
        out with the acknowledgement that makes room."""
        with self._slot_lock:
            if self._closed or not self.canvas._has_visible_views:
                return
            acknowledged = int(self.canvas._frame_feedback.get("index", 0))
            if self._sent - acknowledged >= self.canvas.max_buffered_frames:
                return
            item = self._image_frame()
            if item is None:
                return
            self._sent += 1
            self.canvas.send_frame(item)

    def _image_frame(self) -> NDArray[np.uint8] | None:
        """The frame to send next: the newest not yet sent, or after a new view the last one again."""
        with self._slot_lock:
            item, self._pending = self._pending, None
            if item is None and self._resend:
                item = self._shown  # a new view or a resize: the last frame again
            self._resend = False
            if item is None:
                return None
            self._shown = item
        return item[0]

    def _set_status(self, text: str, *, final: bool) -> None:
        colour = "#444" if final else "#a60"
        with self._status_lock:  # set from the render thread and the kernel's
            self.status.value = f'<span style="color:{colour}">{html.escape(text)}</span>'

    def _show_error(self, text: str) -> None:
        with self._status_lock:
            self.status.value = f'<span style="color:#c00">error: {html.escape(text)}</span>'
        if self.loop.last_error:
            self.canvas.print(self.loop.last_error)

    def _guard(self, fn: Callable[[], Any]) -> None:
        """Run a control's action; a refused input is shown, not raised into the void."""
        try:
            fn()
        except (ValueError, KeyError, OSError, IndexError, RuntimeError) as exc:
            self._show_error(str(exc))

    # ---- image events (any kernel thread) ----
    def _camera(self, change: Callable[[Any], Any], *, final: bool = False) -> None:
        self.loop.update(lambda m: change(m.control), camera=True, final=final)

    def _image_event(self, event: dict[str, Any]) -> None:
        kind = event.get("type") or event.get("event_type")
        if kind == "resize":
            self._resize(event)
        elif kind == "pointer_down":
            pan = event.get("button") == 2 or "Shift" in event.get("modifiers", ())
            self._drag = (float(event["x"]), float(event["y"]), pan)
            self.loop.hold()
        elif kind == "pointer_move" and self._drag is not None:
            x0, y0, pan = self._drag
            x, y = float(event["x"]), float(event["y"])
            self._drag = (x, y, pan)
            dx, dy = x - x0, y - y0
            if pan:
                shown = self._css_size
                self._camera(lambda c: c.pan(dx, dy, shown))
            else:
                self._camera(lambda c: c.drag(dx, dy))
        elif kind == "pointer_up":
            if self._drag is not None:
                self.loop.settle()  # the drag is over: no need to wait settle_s for more
            self._drag = None
        elif kind == "wheel":
            dy = float(event.get("dy", 0.0))
            if dy:
                self._camera(lambda c: c.zoom(1.1 ** (-float(np.clip(dy, -500, 500)) / 100.0)))
        elif kind == "close":
            self.close()

    def _resize(self, event: dict[str, Any]) -> None:
        """The picture's real size on the page: render at it, and keep the scene's aspect
        by setting the height from the width."""
        ratio = float(event.get("ratio", 1.0)) or 1.0
        width = float(event["width"])
        if width < 16:
            return  # hidden (zero size): nothing to draw for
        want_h = width / self._aspect
        if abs(float(event["height"]) - want_h) > 1.0:
            self._post(lambda: setattr(self.canvas, "css_height", f"{want_h + 2:.0f}px"))
        size = (max(1, round(width * ratio)), max(1, round(want_h * ratio)))
        self._css_size = (max(1, round(width)), max(1, round(want_h)))
        if size != tuple(self.model.size):
            self.loop.update(lambda m: setattr(m, "size", size), camera=False, final=True)
        else:
            with self._slot_lock:
                self._resend = True
            self._send()  # a new view: send it the last frame

    # ---- transfer-function editor ----
    def _hist_frame(self) -> NDArray[np.uint8]:
        return self.tf_panel.frame()

    def _hist_event(self, event: dict[str, Any]) -> None:
        self.tf_panel.event(event)

    def _edit(self, panel: _EditorPanel, change: Callable[[], bool]) -> None:
        """A histogram edit: transfer-function points only, so no re-sort and no histogram pass."""
        with self.loop.lock:
            changed = change()
            if changed:
                self.loop.update(camera=False)
        panel.canvas.request_draw()  # the selection may have moved even when the points did not

    def _on_fusion(self, mode: str) -> None:
        self.loop.update(lambda m: m.set_fusion(mode), camera=False)

    def _tf(self, change: Callable[[Any], Any]) -> None:
        if self._syncing:
            return
        self.loop.update(lambda m: change(m.editor), camera=False)
        self._sync_ticks()
        self.hist.request_draw()

    def _sync_ticks(self) -> None:
        self.tf_panel.sync()

    def _on_field(self, name: str) -> None:
        if self._syncing:
            return
        self.loop.update(lambda m: m.set_field(name), camera=False)
        self._sync_range()
        self._sync_ticks()
        self.hist.request_draw()

    def _on_colormap(self, name: str) -> None:
        if name != "(scene)":
            self._tf(lambda ed: ed.set_colormap(name))

    def _on_unit(self, value: float) -> None:
        if _same(value, self.model.editor.unit_distance, value):
            return  # the slider's echo of the value it was given (through log10 and 10**x)
        self._tf(lambda ed: ed.set_unit_distance(value))

    def _on_range(self) -> None:
        lo, hi = self.lo.value, self.hi.value
        old_lo, old_hi = self.model.editor.scalar_range
        span = abs(old_hi - old_lo)
        if _same(lo, old_lo, span) and _same(hi, old_hi, span):
            return  # a box's echo of the value it was given
        self._tf(lambda ed: ed.set_range(lo, hi))

    def _sync_range(self) -> None:
        self._syncing = True
        try:
            self.lo.value, self.hi.value = self.model.editor.scalar_range
        finally:
            self._syncing = False

    # ---- files ----
    def _save(self) -> None:
        with self.loop.lock:
            path = self.model.save(self.path.value)
        self._set_status(f"saved {path}", final=True)

    def _load(self) -> None:
        path = self.path.value
        size = tuple(self.model.size)

        def load(m: ViewerModel) -> None:
            m.load(path)
            m.size = size  # the picture keeps its place on the page
        self.loop.update(load, camera=True, final=True)
        m = self.model
        self._syncing = True
        try:
            self.field.options = m.fields
            self.field.value = m.field
            options, value = _colormap_choice(tuple(self.colormap.options), m.editor.colormap)
            if options != tuple(self.colormap.options):
                self.colormap.options = options
            self.colormap.value = value
            self.unit.value = m.editor.unit_distance
        finally:
            self._syncing = False
        self._sync_range()
        self._sync_ticks()
        self.hist.request_draw()

    # ---- lifetime ----
    def _on_visibility(self, change: dict[str, Any]) -> None:
        if self._hidden_timer is not None:
            self._hidden_timer.cancel()
            self._hidden_timer = None
        if change["new"]:
            self._send()  # what was drawn while no view was there
        elif not self._closed:
            self._hidden_timer = threading.Timer(self.idle_release_s, self._release_if_hidden)
            self._hidden_timer.daemon = True
            self._hidden_timer.start()

    def _release_if_hidden(self) -> None:
        if not self._closed and not self.canvas._has_visible_views:
            self.loop.suspend()

    def close(self) -> None:
        """Stop the render loop, free the renderer's GL memory and close the widgets."""
        if self._closed:
            return
        self._closed = True
        if self._hidden_timer is not None:
            self._hidden_timer.cancel()
        self.loop.close()

        def close_all(widget: Any) -> None:
            for child in getattr(widget, "children", ()):
                close_all(child)
            widget.close()
        close_all(self.widget)

    @property
    def closed(self) -> bool:
        return self._closed

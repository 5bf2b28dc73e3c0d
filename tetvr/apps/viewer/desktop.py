"""The desktop front end (``tetvr view``): a moderngl-window window that shows the frames of a
:class:`~tetvr.apps.viewer.model.ViewerModel` as a texture, the mouse and keys driving its
camera. Needs ``moderngl-window`` (``pip install moderngl-window``) and a display."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.apps.viewer.model import ViewerModel
from tetvr.core.image import to_rgba8
from tetvr.scene.load import load_scene
from tetvr.scene.scene import Scene

__all__ = ["run_desktop"]


def _display_available() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) or os.name == "nt" or \
        (os.uname().sysname == "Darwin" if hasattr(os, "uname") else False)


def run_desktop(scene: Scene | str | os.PathLike[str], *, settle_s: float = 0.25, preview_scale: float = 0.5) -> None:
    """Open a window showing ``scene`` (``tetvr view``): drag to orbit, shift-drag to
    pan, wheel to zoom, ``r`` to reset, ``s`` to save ``<scene>.view.json``, Esc to quit.

    Frames are rendered off-screen by :class:`tetvr.gl.Renderer` and shown as a texture,
    with the same progressive scheme as the Jupyter viewer. Needs ``moderngl-window``
    (``pip install moderngl-window``) and a display.
    """
    if not _display_available():
        raise RuntimeError("no display: set DISPLAY (X11) or WAYLAND_DISPLAY, or use the Jupyter viewer "
                           "(tetvr.apps.viewer.Viewer) or `tetvr render`")
    try:
        import moderngl_window as mglw
    except ImportError:
        raise RuntimeError("`tetvr view` needs moderngl-window: pip install moderngl-window") from None
    if isinstance(scene, Scene):
        source = Path(scene.mesh_path).with_suffix(".json")
    else:
        source = Path(scene)
        scene = load_scene(scene)
    model = ViewerModel(scene, settle_s=settle_s, preview_scale=preview_scale)
    window = _window_config(mglw.WindowConfig, model, scene, source)
    try:
        mglw.run_window_config(window, args=["--window", "pyglet"])
    finally:
        model.close()


def _blit_quad(ctx: Any) -> tuple[Any, Any, Any]:
    """The program, vertex buffer and vertex array that draw a texture over the window."""
    from tetvr.gl.shaders import assemble

    prog = ctx.program(vertex_shader=assemble("blit.vert")[0], fragment_shader=assemble("blit.frag")[0])
    quad = np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4")
    vbo = ctx.buffer(quad.tobytes())
    return prog, vbo, ctx.vertex_array(prog, [(vbo, "2f", "in_pos")])


def _texture(ctx: Any, tex: Any, rgba: NDArray[np.uint8]) -> Any:
    """``tex`` with the RGBA8 image ``rgba`` written into it, or a new texture in its place
    where there is none or its size differs."""
    size = (rgba.shape[1], rgba.shape[0])
    if tex is None or tex.size != size:
        if tex is not None:
            tex.release()
        tex = ctx.texture(size, 4, rgba.tobytes())
        tex.filter = (ctx.LINEAR, ctx.LINEAR)
    else:
        tex.write(rgba.tobytes())
    return tex


def _window_config(base: type, model: ViewerModel, scene: Scene, source: Path) -> type:
    """The window of :func:`run_desktop`: a moderngl-window ``WindowConfig`` (``base``) that
    draws ``model``'s frames and saves its view next to ``source``."""
    width, height = scene.size
    mesh_name, field = Path(scene.mesh_path).name, scene.mesh.scalar_name

    class ViewWindow(base):  # type: ignore[misc, valid-type]
        gl_version = (3, 3)
        title = f"tetvr — {mesh_name} ({field})"
        window_size = (width, height)
        aspect_ratio = width / height
        resizable = False
        vsync = True

        def __init__(self, **kw: Any) -> None:
            super().__init__(**kw)
            self.prog, self.vbo, self.vao = _blit_quad(self.ctx)
            self.tex: Any = None
            self.shift = False
            self._upload(model.final())

        def _upload(self, image: NDArray[np.float32]) -> None:
            rgba = np.ascontiguousarray(to_rgba8(image, model.background))
            self.tex = _texture(self.ctx, self.tex, rgba)

        def on_render(self, time_s: float, frame_time: float) -> None:  # moderngl-window >= 3
            image = model.poll()
            if image is not None:
                self._upload(image)
            self.ctx.screen.use()
            r, g, b = model.background
            self.ctx.clear(r, g, b, 1.0)
            self.tex.use(0)
            self.vao.render(self.ctx.TRIANGLE_STRIP)

        render = on_render  # moderngl-window 2.x names it render()

        def _changed(self) -> None:
            self._upload(model.changed(camera=True))

        def on_mouse_drag_event(self, x: int, y: int, dx: int, dy: int) -> None:
            if self.shift:
                model.control.pan(dx, dy, model.size)  # type: ignore[arg-type]
            else:
                model.control.drag(dx, dy)
            self._changed()

        mouse_drag_event = on_mouse_drag_event

        def on_mouse_scroll_event(self, x_offset: float, y_offset: float) -> None:
            if y_offset:
                model.control.zoom(1.1 if y_offset > 0 else 1 / 1.1)
                self._changed()

        mouse_scroll_event = on_mouse_scroll_event

        def on_key_event(self, key: Any, action: Any, modifiers: Any) -> None:
            keys = self.wnd.keys
            self.shift = bool(getattr(modifiers, "shift", False))
            if action != keys.ACTION_PRESS:
                return
            if key == keys.R:
                model.control.reset()
                self._upload(model.final())
            elif key == keys.S:
                out = source.with_suffix(".view.json")
                model.save(out)
                print(f"saved {out}")

        key_event = on_key_event

    return ViewWindow

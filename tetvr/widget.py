"""Interactive viewing: a Jupyter widget (ipywidgets) and a desktop window (``tetvr view``).

The logic is plain Python and testable without a browser or a display:

* :class:`OrbitControl` — camera navigation (orbit about the focal point, zoom, pan), with
  the clipping range kept around the mesh's bounding sphere;
* :class:`ProgressiveRefiner` — the progressive scheme: while the user drags, draw a
  smaller image with the previous visibility order (no sort); once nothing has changed
  for ``settle_s`` seconds, draw the full-size frame with a fresh sort;
* :class:`TransferFunctionEditor` — opacity control points over a colour map, drawn over
  a log-scaled histogram of the scalar values (:func:`histogram_image`);
* :class:`ViewerModel` — a scene plus the three above, which renders frames and saves and
  loads the scene JSON.

The front-ends are thin: :class:`Viewer` (needs ``ipywidgets``; ``ipyevents``, if
installed, adds mouse drag and wheel on the image) and :func:`run_desktop` (needs
``moderngl-window`` and a display).

Examples
--------
>>> import tetvr                                                     # doctest: +SKIP
>>> from tetvr.widget import Viewer                                 # doctest: +SKIP
>>> Viewer(tetvr.load_scene("scene.json"))    # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .camera import Camera, bounding_sphere
from .image import png_bytes as _png_bytes
from .image import to_rgba8
from .mesh import TetMesh
from .render import default_transfer_function
from .scene import Scene, load_scene
from .settings import RenderSettings
from .transfer import PRESETS, TransferFunction

__all__ = [
    "OrbitControl",
    "ProgressiveRefiner",
    "RenderRequest",
    "TransferFunctionEditor",
    "ViewerModel",
    "Viewer",
    "histogram_image",
    "log_histogram",
    "png_bytes",
    "list_fields",
    "run_desktop",
    "PICKER_COLORMAPS",
]

#: Colour maps offered by the pickers (matplotlib's only when it is installed).
PICKER_COLORMAPS = tuple(sorted(PRESETS)) + ("magma", "inferno", "plasma", "cividis", "coolwarm", "RdBu_r",
                                             "turbo", "jet", "gray")


# ---------------------------------------------------------------- images
def png_bytes(image: ArrayLike, background: Sequence[float] | None = (1.0, 1.0, 1.0)) -> bytes:
    """A premultiplied float RGBA image as PNG bytes, fast compression for live frames."""
    return _png_bytes(image, background, level=1)


# ---------------------------------------------------------------- camera
class OrbitControl:
    """Orbit, zoom and pan a :class:`~tetvr.Camera` about its focal point.

    Parameters
    ----------
    camera : the starting camera (kept for :meth:`reset`).
    bounds : (2, 3) box the clipping range must enclose (the mesh's bounds); ``None``
        keeps the camera's clipping range as it is.
    degrees_per_pixel : orbit speed of :meth:`drag`.

    Orbiting turns the camera and its view up together (a trackball), so it never
    reaches a pole where the view up would be parallel to the view direction.

    Examples
    --------
    >>> c = OrbitControl(Camera(position=(0, 0, 5), view_up=(0, 1, 0)))
    >>> c.azimuth(90).position[0] > 4.99 and c.zoom(2.0).position[0] > 2.49
    True
    """

    def __init__(self, camera: Camera, *, bounds: ArrayLike | None = None, degrees_per_pixel: float = 0.4) -> None:
        self.home = camera
        self.camera = camera
        self.bounds = None if bounds is None else np.asarray(bounds, dtype=np.float64).reshape(2, 3)
        self._sphere = None if self.bounds is None else bounding_sphere(self.bounds)
        self.degrees_per_pixel = float(degrees_per_pixel)

    def reset(self) -> Camera:
        self.camera = self.home
        return self.camera

    def set(self, camera: Camera, *, home: bool = False) -> Camera:
        self.camera = camera
        if home:
            self.home = camera
        return camera

    def _rotate(self, axis: NDArray[np.float64], degrees: float) -> Camera:
        from .animate import azimuth

        return self._clipped(azimuth(self.camera, degrees, axis=axis))

    def azimuth(self, degrees: float) -> Camera:
        """Turn about the view up; positive moves the camera to its right."""
        _, up, _ = self.camera.basis()
        self.camera = self._rotate(up, degrees)
        return self.camera

    def elevation(self, degrees: float) -> Camera:
        """Turn about the camera's right axis; positive moves the camera up."""
        right, _, _ = self.camera.basis()
        self.camera = self._rotate(right, -degrees)
        return self.camera

    def drag(self, dx_px: float, dy_px: float) -> Camera:
        """A mouse drag of ``(dx, dy)`` pixels (y down): the object follows the pointer."""
        if dx_px:
            self.azimuth(-dx_px * self.degrees_per_pixel)
        if dy_px:
            self.elevation(dy_px * self.degrees_per_pixel)
        return self.camera

    def zoom(self, factor: float) -> Camera:
        """Magnify by ``factor`` (> 1: closer): dolly a perspective camera, shrink a
        parallel camera's scale."""
        f = float(factor)
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f"zoom factor must be positive, got {factor!r}")
        cam = self.camera
        if cam.parallel_projection:
            cam = dataclasses.replace(cam, parallel_scale=cam.parallel_scale / f)
        else:
            focal = np.asarray(cam.focal_point)
            pos = focal + (np.asarray(cam.position) - focal) / f
            cam = dataclasses.replace(cam, position=tuple(pos))  # type: ignore[arg-type]
        self.camera = self._clipped(cam)
        return self.camera

    def pan(self, dx_px: float, dy_px: float, size: tuple[int, int]) -> Camera:
        """Shift the view so the scene follows a drag of ``(dx, dy)`` pixels (y down)."""
        cam = self.camera
        right, up, _ = cam.basis()
        if cam.parallel_projection:
            half_h = cam.parallel_scale
        else:
            dist = float(np.linalg.norm(np.subtract(cam.focal_point, cam.position)))
            half_h = dist * math.tan(math.radians(cam.view_angle) / 2)
        world_per_px = 2.0 * half_h / size[1]
        shift = (-dx_px * right + dy_px * up) * world_per_px
        self.camera = self._clipped(dataclasses.replace(
            cam, position=tuple(np.asarray(cam.position) + shift),  # type: ignore[arg-type]
            focal_point=tuple(np.asarray(cam.focal_point) + shift)))  # type: ignore[arg-type]
        return self.camera

    def _clipped(self, cam: Camera) -> Camera:
        """Clipping range around the bounding sphere of ``bounds`` (as Camera.fit makes it)."""
        if self._sphere is None:
            return cam
        centre, radius = self._sphere
        depth = float(np.dot(centre - np.asarray(cam.position), np.asarray(cam.direction)))
        far = depth + 1.05 * radius
        near = depth - 1.05 * radius
        if not cam.parallel_projection:
            near = max(near, 1e-3 * radius)
            far = max(far, 2e-3 * radius)
        elif far <= near:  # pragma: no cover - radius > 0
            far = near + 1e-3 * radius
        return dataclasses.replace(cam, clipping_range=(near, far))


# ---------------------------------------------------------------- progressive refinement
@dataclasses.dataclass(frozen=True)
class RenderRequest:
    """What to draw next: ``size``; ``sort`` — compute a fresh visibility order (else
    reuse the previous one); ``final`` — the refined frame (else a preview)."""

    size: tuple[int, int]
    sort: bool
    final: bool


class ProgressiveRefiner:
    """The progressive-rendering decision, as a small state machine over explicit times.

    Every change (camera, transfer function, field) calls :meth:`change`, which answers a
    *preview*: ``preview_scale`` of the full size, drawn with the previous visibility
    order (a sort costs as much as the rest of a small frame, and the old order is nearly
    right for a small camera step). When :meth:`poll` finds that ``settle_s`` seconds
    passed since the last change, it answers the *final* frame once: full size, sorted
    afresh if the camera moved since the last sort.

    States: ``"idle"`` (the shown frame is final) and ``"interacting"`` (a preview is shown).

    Examples
    --------
    >>> r = ProgressiveRefiner((400, 300), preview_scale=0.5, settle_s=0.2)
    >>> r.change(now=0.0)                      # the first frame has no order to reuse
    RenderRequest(size=(200, 150), sort=True, final=False)
    >>> r.change(now=0.1), r.poll(now=0.25), r.poll(now=0.31).final, r.poll(now=0.5)
    (RenderRequest(size=(200, 150), sort=False, final=False), None, True, None)
    """

    def __init__(self, full_size: tuple[int, int], *, preview_scale: float = 0.5, settle_s: float = 0.3) -> None:
        if not (0.0 < float(preview_scale) <= 1.0):
            raise ValueError(f"preview_scale must be in (0, 1], got {preview_scale!r}")
        if not float(settle_s) >= 0.0:
            raise ValueError(f"settle_s must be >= 0, got {settle_s!r}")
        self.full_size = (int(full_size[0]), int(full_size[1]))
        self.preview_scale = float(preview_scale)
        self.settle_s = float(settle_s)
        self.state = "idle"
        self.last_change = -math.inf
        self.has_order = False
        self.camera_moved = False

    @property
    def preview_size(self) -> tuple[int, int]:
        w, h = self.full_size
        return max(1, round(w * self.preview_scale)), max(1, round(h * self.preview_scale))

    def change(self, now: float, *, camera: bool = True) -> RenderRequest:
        """Something changed at time ``now``: the preview to draw at once."""
        self.state = "interacting"
        self.last_change = float(now)
        self.camera_moved = self.camera_moved or camera
        sort = not self.has_order
        self.has_order = True
        return RenderRequest(self.preview_size, sort=sort, final=False)

    def poll(self, now: float) -> RenderRequest | None:
        """The final frame if changes stopped ``settle_s`` ago and it is not drawn yet."""
        # (a nanosecond of slack: 1.3 - 1.1 is 0.19999999999999996 in binary)
        if self.state != "interacting" or float(now) - self.last_change < self.settle_s - 1e-9:
            return None
        return self.finish()

    def finish(self) -> RenderRequest:
        """The final frame now (e.g. for the first frame, or when the user asks)."""
        sort = self.camera_moved or not self.has_order
        self.state = "idle"
        self.camera_moved = False
        self.has_order = True
        return RenderRequest(self.full_size, sort=sort, final=True)

    def invalidate_order(self) -> None:
        """The geometry changed: the next frame must sort."""
        self.has_order = False

    @property
    def seconds_to_refine(self) -> float | None:
        """How long after the last change :meth:`poll` will answer (None when idle)."""
        return None if self.state == "idle" else self.settle_s


# ---------------------------------------------------------------- transfer-function editing
def log_histogram(values: ArrayLike, scalar_range: tuple[float, float], bins: int = 64
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(log10(1 + count), edges)`` of the values in ``scalar_range``."""
    counts, edges = np.histogram(np.asarray(values, dtype=np.float64), bins=bins, range=scalar_range)
    return np.log10(1.0 + counts), edges


def histogram_image(values: ArrayLike, tf: TransferFunction, scalar_range: tuple[float, float], *,
                    size: tuple[int, int] = (360, 120), bins: int = 72,
                    points: Sequence[tuple[float, float]] = (), selected: int | None = None) -> NDArray[np.float32]:
    """The transfer-function editor's picture: a log-scaled histogram of ``values`` with
    bars in the transfer function's colour, the opacity curve over it (white line, dark
    rim) and the control ``points`` (``(t, a)``, ``t`` in [0, 1] of the range) as squares,
    the ``selected`` one red. Premultiplied RGBA, opaque, row 0 at the top."""
    w, h = int(size[0]), int(size[1])
    lo, hi = (float(v) for v in scalar_range)
    img = np.zeros((h, w, 4), np.float32)
    img[...] = (0.12, 0.12, 0.14, 1.0)
    logc, _ = log_histogram(values, (lo, hi), bins)
    top = max(float(logc.max()), 1e-12)
    xs = lo + (hi - lo) * (np.arange(w) + 0.5) / w
    rgb, alpha = tf.evaluate(xs)
    bar_h = np.round(logc[np.minimum((np.arange(w) * bins) // w, bins - 1)] / top * (h - 4)).astype(int)
    rows = np.arange(h)[:, None]
    bars = rows >= (h - bar_h)[None, :]
    img[..., :3] = np.where(bars[..., None], (0.35 + 0.65 * rgb[None, :, :]).astype(np.float32), img[..., :3])
    # Opacity curve: y = a, 2 px thick with a dark rim so it reads over any bar colour.
    y = np.clip(np.round((1.0 - alpha) * (h - 3)).astype(int) + 1, 1, h - 2)
    for col in range(w):  # each column: from the previous column's height to its own
        y0 = y[col] if col == 0 else y[col - 1]
        a, b = sorted((int(y0), int(y[col])))
        img[max(a - 1, 0):b + 2, col, :3] = 0.0
        img[a:b + 1, col, :3] = 1.0
    for i, (pt, pa) in enumerate(points):
        cx = int(round(float(pt) * (w - 1)))
        cy = int(round((1.0 - float(pa)) * (h - 3))) + 1
        colour = (1.0, 0.2, 0.2) if i == selected else (1.0, 1.0, 1.0)
        img[max(cy - 3, 0):cy + 4, max(cx - 3, 0):cx + 4, :3] = 0.0
        img[max(cy - 2, 0):cy + 3, max(cx - 2, 0):cx + 3, :3] = colour
    return img


class TransferFunctionEditor:
    """Editable opacity control points over a colour map.

    Points are ``(t, a)``: ``t`` in [0, 1] across ``scalar_range``, ``a`` the opacity per
    ``unit_distance``. The two end points stay at ``t = 0`` and ``t = 1``; interior points
    keep their order (a move is clamped between the neighbours).

    Parameters
    ----------
    scalar_range : (lo, hi) the colour map and the points stretch over.
    colormap : a name for :func:`tetvr.colormaps.colormap` (tetvr preset or matplotlib),
        or ``None`` to keep ``color`` (explicit ``(t, r, g, b)`` rows).
    points : the opacity control points.
    unit_distance : world length over which opacity ``a`` is reached.

    Examples
    --------
    >>> ed = TransferFunctionEditor((0.0, 10.0), points=[(0, 0), (1, 1)], unit_distance=0.5)
    >>> ed.add_point(0.5, 0.2)
    1
    >>> ed.transfer_function().opacity
    ((0.0, 0.0), (5.0, 0.2), (10.0, 1.0))
    """

    MIN_GAP = 1e-4

    def __init__(self, scalar_range: tuple[float, float], *, colormap: str | None = "viridis",
                 points: Sequence[tuple[float, float]] = ((0.0, 0.0), (1.0, 0.5)), unit_distance: float = 1.0,
                 color: Sequence[tuple[float, float, float, float]] | None = None) -> None:
        self.scalar_range = _range(scalar_range)
        if colormap is None and color is None:
            raise ValueError("give a colormap name or explicit color rows")
        self.colormap = colormap
        self.color = None if color is None else tuple(tuple(float(v) for v in row) for row in color)
        pts = sorted((float(t), float(a)) for t, a in points)
        if len(pts) < 2:
            raise ValueError(f"need at least 2 opacity points, got {len(pts)}")
        pts[0] = (0.0, pts[0][1])
        pts[-1] = (1.0, pts[-1][1])
        self.points: list[tuple[float, float]] = [(t, float(np.clip(a, 0, 1))) for t, a in pts]
        self.unit_distance = float(unit_distance)
        self.transfer_function()  # validates everything

    @classmethod
    def from_transfer_function(cls, tf: TransferFunction, *, colormap: str | None = None) -> "TransferFunctionEditor":
        """An editor holding ``tf`` (its colour kept explicitly unless ``colormap`` is given)."""
        lo, hi = tf.domain
        if hi <= lo:
            hi = lo + 1.0
        span = hi - lo
        color = [((x - lo) / span, r, g, b) for x, r, g, b in tf.color]
        pts = [((x - lo) / span, a) for x, a in tf.opacity]
        if pts[0][0] > 0:
            pts.insert(0, (0.0, pts[0][1]))
        if pts[-1][0] < 1:
            pts.append((1.0, pts[-1][1]))
        return cls((lo, hi), colormap=colormap, color=None if colormap else color, points=pts,
                   unit_distance=tf.unit_distance)

    # ---- edits ----
    def add_point(self, t: float, a: float) -> int:
        """Insert a point (or set the opacity of the one at ``t``); returns its index."""
        t = float(np.clip(t, 0.0, 1.0))
        a = float(np.clip(a, 0.0, 1.0))
        for i, (ti, _) in enumerate(self.points):
            if abs(ti - t) < self.MIN_GAP:
                self.points[i] = (ti, a)
                return i
        i = int(np.searchsorted([p[0] for p in self.points], t))
        self.points.insert(i, (t, a))
        return i

    def move_point(self, index: int, t: float | None = None, a: float | None = None) -> tuple[float, float]:
        """Move point ``index``; end points move in opacity only. Returns where it went."""
        self._check_index(index)
        ti, ai = self.points[index]
        if t is not None and 0 < index < len(self.points) - 1:
            lo = self.points[index - 1][0] + self.MIN_GAP
            hi = self.points[index + 1][0] - self.MIN_GAP
            ti = float(np.clip(t, lo, hi))
        if a is not None:
            ai = float(np.clip(a, 0.0, 1.0))
        self.points[index] = (ti, ai)
        return self.points[index]

    def remove_point(self, index: int) -> None:
        """Remove an interior point (the two ends stay)."""
        self._check_index(index)
        if index in (0, len(self.points) - 1):
            raise ValueError("the end points at t = 0 and t = 1 cannot be removed")
        del self.points[index]

    def nearest_point(self, t: float, a: float, *, aspect: float = 3.0) -> int:
        """Index of the point closest to ``(t, a)`` (``t`` weighted by ``aspect``, the
        width/height ratio of the picture the user clicks in)."""
        d = [(aspect * (ti - t)) ** 2 + (ai - a) ** 2 for ti, ai in self.points]
        return int(np.argmin(d))

    def set_range(self, lo: float, hi: float) -> None:
        self.scalar_range = _range((lo, hi))

    def set_colormap(self, name: str) -> None:
        from .colormaps import colormap

        colormap(name, self.scalar_range)  # fails here, not at the next render
        self.colormap = name
        self.color = None

    def set_unit_distance(self, u: float) -> None:
        u = float(u)
        if not (math.isfinite(u) and u > 0):
            raise ValueError(f"unit_distance must be positive, got {u!r}")
        self.unit_distance = u

    def _check_index(self, index: int) -> None:
        if not (isinstance(index, (int, np.integer)) and 0 <= index < len(self.points)):
            raise IndexError(f"point index {index!r} outside 0..{len(self.points) - 1}")

    # ---- results ----
    def transfer_function(self) -> TransferFunction:
        from .colormaps import colormap

        lo, hi = self.scalar_range
        opacity = [(t, a) for t, a in self.points]
        if self.colormap is not None:
            return colormap(self.colormap, (lo, hi), opacity=opacity, unit_distance=self.unit_distance)
        assert self.color is not None
        color = tuple((lo + (hi - lo) * t, r, g, b) for t, r, g, b in self.color)
        op = tuple((lo + (hi - lo) * t, a) for t, a in opacity)
        return TransferFunction(color=color, opacity=op, unit_distance=self.unit_distance)

    def image(self, values: ArrayLike, *, size: tuple[int, int] = (360, 120), selected: int | None = None
              ) -> NDArray[np.float32]:
        """The editor's picture over ``values`` (see :func:`histogram_image`)."""
        return histogram_image(values, self.transfer_function(), self.scalar_range, size=size,
                               points=self.points, selected=selected)


def _range(r: Sequence[float]) -> tuple[float, float]:
    lo, hi = (float(v) for v in r)
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        raise ValueError(f"scalar range must be finite with lo < hi, got {tuple(r)!r}")
    return lo, hi


# ---------------------------------------------------------------- the model behind any front-end
def list_fields(path: str | os.PathLike[str]) -> list[str]:
    """Names of the point and cell fields of a mesh file (point fields first).

    (A mesh from :func:`tetvr.read` knows them already: ``mesh.report.fields``.)"""
    import meshio

    m = meshio.read(os.fspath(path))
    return list(m.point_data) + [n for n in m.cell_data if n not in m.point_data]


class ViewerModel:
    """A scene under interactive control: camera, field, transfer function, refinement.

    Parameters
    ----------
    scene : the scene to show, or a scene JSON path (its size is the refined frame's size).
    renderer : anything with ``render(mesh, camera, tf, size=, order=)`` (default: a
        :class:`tetvr.gl.Renderer` made on the first frame and released by :meth:`close`).
    preview_scale, settle_s : see :class:`ProgressiveRefiner`.
    clock : the time source (tests pass a fake one).
    """

    def __init__(self, scene: Scene | str | os.PathLike[str], *, renderer: Any = None, preview_scale: float = 0.5,
                 settle_s: float = 0.3, clock: Callable[[], float] = time.monotonic) -> None:
        self._renderer = renderer
        self._own_renderer = renderer is None
        self.clock = clock
        self.preview_scale = preview_scale
        self.settle_s = settle_s
        self.order: NDArray[np.uint32] | None = None
        self.last_request: RenderRequest | None = None
        self.last_seconds = 0.0
        self._meshes: dict[str, TetMesh] = {}
        self.load(scene)

    # ---- scene in, scene out ----
    def load(self, scene: Scene | str | os.PathLike[str]) -> None:
        """Show another scene (a :class:`Scene` or a scene JSON path)."""
        if not isinstance(scene, Scene):
            scene = load_scene(scene)
        if self._renderer is not None and self._own_renderer and scene.settings != self.settings:
            self.close()  # made with the old settings: the next frame makes one with the new
        self.mesh_path = scene.mesh_path
        self.mesh = scene.mesh
        self.field = scene.mesh.scalar_name
        self.component = scene.component
        self._meshes = {self.field: scene.mesh}
        self.size = tuple(scene.size)
        self.background = tuple(scene.background)
        self.settings: RenderSettings = scene.settings
        self.control = OrbitControl(scene.camera, bounds=scene.mesh.bounds)
        self.editor = TransferFunctionEditor.from_transfer_function(scene.tf)
        self.refiner = ProgressiveRefiner(self.size, preview_scale=self.preview_scale,  # type: ignore[arg-type]
                                          settle_s=self.settle_s)
        self.order = None
        # The fields tetvr.read found in the file; a mesh built in memory has only its own.
        self.fields = list(scene.mesh.report.fields) or [self.field]

    def scene(self) -> Scene:
        """The current state as a :class:`Scene` (for :meth:`Scene.save` and ``tetvr render``)."""
        return Scene(mesh_path=self.mesh_path, mesh=self.mesh, tf=self.editor.transfer_function(),
                     camera=self.control.camera, size=self.size, background=self.background,  # type: ignore[arg-type]
                     settings=self.settings, scalars=self.field, component=self.component)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the current scene JSON (paths relative to it)."""
        self.scene().save(path)
        return Path(path)

    # ---- changes ----
    @property
    def camera(self) -> Camera:
        return self.control.camera

    def set_field(self, name: str) -> None:
        """Render another field of the same mesh file; the transfer function's range and
        unit distance follow it (its opacity points and colour map are kept)."""
        if name not in self._meshes:
            from .mesh import read

            self._meshes[name] = read(self.mesh_path, name)
        new = self._meshes[name]
        # Same file, same cells: the visibility order stays valid (render() sorts afresh
        # should the number of tets differ).
        self.mesh = new
        self.field = name
        self.component = None
        self.editor.set_range(*default_transfer_function(new).domain)  # the default rule's range (tetvr.transfer)

    def set_colormap(self, name: str) -> None:
        self.editor.set_colormap(name)

    # ---- frames ----
    @property
    def renderer(self) -> Any:
        if self._renderer is None:
            from .gl.renderer import Renderer

            self._renderer = Renderer(self.settings)
        return self._renderer

    def render(self, request: RenderRequest) -> NDArray[np.float32]:
        """Draw what ``request`` asks for."""
        from .sort import visibility_order

        from .method import choose

        t0 = time.perf_counter()
        order = None  # tet marching needs no order
        if choose(self.settings, self.mesh) == "projected":
            # Projected tetrahedra: previews reuse the last order; refined frames sort anew.
            if request.sort or self.order is None or self.order.shape[0] != self.mesh.n_tets:
                self.order = visibility_order(self.mesh, self.camera, self.settings.sort)
            order = self.order
        image = self.renderer.render(self.mesh, self.camera, self.editor.transfer_function(), size=request.size,
                                     order=order)
        self.last_seconds = time.perf_counter() - t0
        self.last_request = request
        return image

    def changed(self, *, camera: bool = True) -> NDArray[np.float32]:
        """Something changed: the preview frame."""
        return self.render(self.refiner.change(self.clock(), camera=camera))

    def poll(self) -> NDArray[np.float32] | None:
        """The refined frame if the interaction has settled, else None."""
        req = self.refiner.poll(self.clock())
        return None if req is None else self.render(req)

    def final(self) -> NDArray[np.float32]:
        """The refined frame now."""
        return self.render(self.refiner.finish())

    def close(self) -> None:
        if self._own_renderer and self._renderer is not None:
            self._renderer.release()
        self._renderer = None


# ---------------------------------------------------------------- Jupyter front-end
class Viewer:
    """An ipywidgets viewer of a scene (``pip install ipywidgets``; ``ipyevents`` for
    mouse drag and wheel on the image).

    Shows the image with orbit/zoom buttons, field and colour-map pickers, the
    transfer-function editor over the histogram, and scene save/load. While the user
    interacts it draws previews; ``settle_s`` seconds after the last change it draws the
    refined frame (asyncio timer in the kernel; :meth:`refine` does it by hand).

    Examples
    --------
    >>> v = Viewer(tetvr.load_scene("scene.json"))        # doctest: +SKIP
    >>> v                                                  # doctest: +SKIP
    """

    def __init__(self, scene: Scene | str | os.PathLike[str], *, preview_scale: float = 0.5, settle_s: float = 0.3,
                 step_degrees: float = 15.0, renderer: Any = None, clock: Callable[[], float] = time.monotonic) -> None:
        try:
            import ipywidgets as w
        except ImportError:
            raise ImportError("the Jupyter viewer needs ipywidgets: pip install ipywidgets") from None
        self.model = ViewerModel(scene, renderer=renderer, preview_scale=preview_scale, settle_s=settle_s, clock=clock)
        self.step_degrees = float(step_degrees)
        self._timer: Any = None
        self._selected = 0
        self._syncing = False
        m = self.model
        width, height = m.size
        self.image = w.Image(format="png", layout=w.Layout(width=f"{width}px", height=f"{height}px"))
        self.status = w.Label()

        def button(label: str, tip: str, fn: Callable[[], Any]) -> Any:
            b = w.Button(description=label, tooltip=tip, layout=w.Layout(width="44px"))
            b.on_click(lambda _b: self._camera(fn))
            return b

        nav = w.HBox([
            button("◀", "orbit left", lambda: m.control.azimuth(-self.step_degrees)),
            button("▶", "orbit right", lambda: m.control.azimuth(self.step_degrees)),
            button("▲", "orbit up", lambda: m.control.elevation(self.step_degrees)),
            button("▼", "orbit down", lambda: m.control.elevation(-self.step_degrees)),
            button("+", "zoom in", lambda: m.control.zoom(1.25)),
            button("−", "zoom out", lambda: m.control.zoom(0.8)),
            button("⟲", "reset the camera", lambda: m.control.reset()),  # the control load() made
        ])
        self.field = w.Dropdown(options=m.fields, value=m.field, description="field")
        cmaps = tuple(c for c in PICKER_COLORMAPS if c in PRESETS or _has_matplotlib())
        options, initial = _colormap_choice(cmaps, m.editor.colormap)
        self.colormap = w.Dropdown(options=options, value=initial, description="colours")
        self.unit = w.FloatLogSlider(value=m.editor.unit_distance, base=10,
                                     min=math.log10(m.editor.unit_distance) - 3,
                                     max=math.log10(m.editor.unit_distance) + 3, step=0.05,
                                     description="unit dist.", readout_format=".3g")
        lo, hi = m.editor.scalar_range
        self.lo = w.FloatText(value=lo, description="range", layout=w.Layout(width="190px"))
        self.hi = w.FloatText(value=hi, layout=w.Layout(width="110px"))
        self.hist = w.Image(format="png", layout=w.Layout(width="360px", height="120px"))
        self.point = w.Dropdown(description="point", layout=w.Layout(width="160px"))
        self.point_t = w.FloatSlider(min=0, max=1, step=0.001, description="position", readout_format=".3f")
        self.point_a = w.FloatSlider(min=0, max=1, step=0.001, description="opacity", readout_format=".3f")
        add = w.Button(description="add point", layout=w.Layout(width="100px"))
        remove = w.Button(description="remove", layout=w.Layout(width="100px"))
        add.on_click(lambda _b: self._add_point())
        remove.on_click(lambda _b: self._remove_point())
        self.path = w.Text(value="scene.json", description="scene file")
        save = w.Button(description="save", layout=w.Layout(width="70px"))
        load = w.Button(description="load", layout=w.Layout(width="70px"))
        save.on_click(lambda _b: self._save())
        load.on_click(lambda _b: self._load())
        refine = w.Button(description="refine", tooltip="draw the full frame now", layout=w.Layout(width="70px"))
        refine.on_click(lambda _b: self.refine())

        self.field.observe(lambda c: self._on_field(c["new"]), names="value")
        self.colormap.observe(lambda c: self._on_colormap(c["new"]), names="value")
        self.unit.observe(lambda c: self._tf(lambda: m.editor.set_unit_distance(c["new"])), names="value")
        for box in (self.lo, self.hi):
            box.observe(lambda _c: self._on_range(), names="value")
        self.point.observe(lambda c: self._select(c["new"]), names="value")
        self.point_t.observe(lambda c: self._move(t=c["new"]), names="value")
        self.point_a.observe(lambda c: self._move(a=c["new"]), names="value")

        tf_box = w.VBox([self.hist, w.HBox([self.lo, self.hi]), w.HBox([self.point, add, remove]),
                         self.point_t, self.point_a])
        side = w.VBox([self.field, self.colormap, self.unit, tf_box, w.HBox([self.path, save, load]), refine])
        self.widget = w.VBox([w.HBox([w.VBox([self.image, nav, self.status]), side])])
        self._mouse = self._attach_mouse()
        self._sync_points()
        self._show(m.final())
        self._show_hist()

    # ---- display ----
    def _ipython_display_(self) -> None:  # pragma: no cover - needs a front-end
        from IPython.display import display

        display(self.widget)

    def _repr_mimebundle_(self, **kw: Any) -> Any:  # pragma: no cover - needs a front-end
        return self.widget._repr_mimebundle_(**kw)

    def _show(self, image: NDArray[np.float32]) -> None:
        m = self.model
        self.image.value = png_bytes(image, m.background)
        req = m.last_request
        kind = "refined" if req is None or req.final else "preview"
        w, h = (req.size if req else m.size)
        self.status.value = f"{kind} {w}x{h}: {m.last_seconds * 1000:.0f} ms"

    def _show_hist(self) -> None:
        """Redraw the transfer-function picture (after an edit, not after a camera move)."""
        m = self.model
        self.hist.value = png_bytes(m.editor.image(m.mesh.scalars, selected=self._selected), None)

    # ---- events ----
    def _changed(self, *, camera: bool) -> None:
        self._show(self.model.changed(camera=camera))
        self._schedule()

    def _camera(self, fn: Callable[[], Any]) -> None:
        fn()
        self._changed(camera=True)

    def _tf(self, fn: Callable[[], Any]) -> None:
        if self._syncing:
            return
        try:
            fn()
        except ValueError as exc:
            self.status.value = f"error: {exc}"
            return
        self._changed(camera=False)
        self._show_hist()

    def _on_field(self, name: str) -> None:
        if self._syncing:
            return
        try:
            self.model.set_field(name)
        except (KeyError, ValueError) as exc:
            self.status.value = f"error: {exc}"
            return
        self._sync_range()
        self._changed(camera=False)
        self._show_hist()

    def _on_colormap(self, name: str) -> None:
        if name != "(scene)":
            self._tf(lambda: self.model.set_colormap(name))

    def _on_range(self) -> None:
        self._tf(lambda: self.model.editor.set_range(self.lo.value, self.hi.value))

    def _select(self, index: Any) -> None:
        if index is None or self._syncing:
            return
        self._selected = int(index)
        self._sync_points()
        self._show_hist()

    def _move(self, t: float | None = None, a: float | None = None) -> None:
        self._tf(lambda: self.model.editor.move_point(self._selected, t=t, a=a))

    def _add_point(self) -> None:
        ed = self.model.editor
        # Halfway between the selected point and the next one (or the previous, at the end).
        j = min(self._selected, len(ed.points) - 2)
        (t0, a0), (t1, a1) = ed.points[j], ed.points[j + 1]
        self._selected = ed.add_point(0.5 * (t0 + t1), 0.5 * (a0 + a1))
        self._sync_points()
        self._changed(camera=False)
        self._show_hist()

    def _remove_point(self) -> None:
        try:
            self.model.editor.remove_point(self._selected)
        except ValueError as exc:
            self.status.value = f"error: {exc}"
            return
        self._selected = max(self._selected - 1, 0)
        self._sync_points()
        self._changed(camera=False)
        self._show_hist()

    def _sync_points(self) -> None:
        ed = self.model.editor
        self._syncing = True
        try:
            self._selected = min(self._selected, len(ed.points) - 1)
            self.point.options = [(f"{i}: t={t:.3f}", i) for i, (t, _) in enumerate(ed.points)]
            self.point.value = self._selected
            t, a = ed.points[self._selected]
            self.point_t.value, self.point_a.value = t, a
            self.point_t.disabled = self._selected in (0, len(ed.points) - 1)
        finally:
            self._syncing = False

    def _sync_range(self) -> None:
        self._syncing = True
        try:
            self.lo.value, self.hi.value = self.model.editor.scalar_range
        finally:
            self._syncing = False

    def _save(self) -> None:
        try:
            path = self.model.save(self.path.value)
            self.status.value = f"saved {path}"
        except (OSError, ValueError) as exc:
            self.status.value = f"error: {exc}"

    def _load(self) -> None:
        try:
            self.model.load(self.path.value)
        except (OSError, ValueError, KeyError) as exc:
            self.status.value = f"error: {exc}"
            return
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
        self._selected = 0
        self._sync_points()
        self._show(m.final())
        self._show_hist()

    # ---- refinement ----
    def refine(self) -> None:
        """Draw the refined frame now (also what the timer does)."""
        self._cancel()
        self._show(self.model.final())

    def _poll(self) -> None:
        self._timer = None
        image = self.model.poll()
        if image is not None:
            self._show(image)
        elif self.model.refiner.state == "interacting":
            self._schedule()

    def _schedule(self) -> None:
        import asyncio

        self._cancel()
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # no event loop (plain Python, tests): refine by hand
            return
        self._timer = loop.call_later(self.model.settle_s, self._poll)

    def _cancel(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

    # ---- mouse (ipyevents) ----
    def _attach_mouse(self) -> Any:
        try:
            from ipyevents import Event
        except ImportError:
            return None
        ev = Event(source=self.image, watched_events=["mousedown", "mouseup", "mousemove", "mouseleave", "wheel"],
                   prevent_default_action=True, wait=30)
        self._drag_from: tuple[float, float] | None = None
        ev.on_dom_event(self.handle_mouse)
        return ev

    def handle_mouse(self, event: dict[str, Any]) -> None:
        """An ipyevents DOM event: drag with the left button orbits, with shift pans;
        the wheel zooms."""
        kind = event.get("type")
        x, y = float(event.get("relativeX", 0)), float(event.get("relativeY", 0))
        if kind == "mousedown":
            self._drag_from = (x, y)
        elif kind in ("mouseup", "mouseleave"):
            self._drag_from = None
        elif kind == "mousemove" and self._drag_from is not None and event.get("buttons", 0):
            dx, dy = x - self._drag_from[0], y - self._drag_from[1]
            self._drag_from = (x, y)
            if event.get("shiftKey"):
                self._camera(lambda: self.model.control.pan(dx, dy, self.model.size))  # type: ignore[arg-type]
            else:
                self._camera(lambda: self.model.control.drag(dx, dy))
        elif kind == "wheel":
            dy = float(event.get("deltaY", 0))
            if dy:
                self._camera(lambda: self.model.control.zoom(1.1 if dy < 0 else 1 / 1.1))

    def close(self) -> None:
        self._cancel()
        self.model.close()
        self.widget.close()


def _colormap_choice(options: tuple[str, ...], colormap: str | None) -> tuple[tuple[str, ...], str]:
    """The colour picker's options and value for an editor's ``colormap``: explicit colour
    rows (``None``) show as ``"(scene)"``, an entry added in front when missing."""
    if colormap is None and "(scene)" not in options:
        options = ("(scene)", *options)
    return options, colormap or "(scene)"


def _has_matplotlib() -> bool:
    try:
        import matplotlib  # noqa: F401
    except ImportError:  # pragma: no cover - depends on the environment
        return False
    return True


# ---------------------------------------------------------------- desktop front-end
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
                           "(tetvr.widget.Viewer) or `tetvr render`")
    try:
        import moderngl
        import moderngl_window as mglw
    except ImportError:
        raise RuntimeError("`tetvr view` needs moderngl-window: pip install moderngl-window") from None
    if isinstance(scene, Scene):
        source = Path(scene.mesh_path).with_suffix(".json")
    else:
        source = Path(scene)
        scene = load_scene(scene)
    model = ViewerModel(scene, settle_s=settle_s, preview_scale=preview_scale)
    width, height = scene.size
    mesh_name, field = Path(scene.mesh_path).name, scene.mesh.scalar_name

    class ViewWindow(mglw.WindowConfig):  # type: ignore[misc, name-defined]
        gl_version = (3, 3)
        title = f"tetvr — {mesh_name} ({field})"
        window_size = (width, height)
        aspect_ratio = width / height
        resizable = False
        vsync = True

        def __init__(self, **kw: Any) -> None:
            super().__init__(**kw)
            from .gl.shaders import assemble

            self.prog = self.ctx.program(vertex_shader=assemble("blit.vert")[0],
                                         fragment_shader=assemble("blit.frag")[0])
            quad = np.array([-1, -1, 1, -1, -1, 1, 1, 1], dtype="f4")
            self.vbo = self.ctx.buffer(quad.tobytes())
            self.vao = self.ctx.vertex_array(self.prog, [(self.vbo, "2f", "in_pos")])
            self.tex: Any = None
            self.shift = False
            self._upload(model.final())

        def _upload(self, image: NDArray[np.float32]) -> None:
            rgba = np.ascontiguousarray(to_rgba8(image, model.background))
            size = (rgba.shape[1], rgba.shape[0])
            if self.tex is None or self.tex.size != size:
                if self.tex is not None:
                    self.tex.release()
                self.tex = self.ctx.texture(size, 4, rgba.tobytes())
                self.tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
            else:
                self.tex.write(rgba.tobytes())

        def on_render(self, time_s: float, frame_time: float) -> None:  # moderngl-window >= 3
            image = model.poll()
            if image is not None:
                self._upload(image)
            self.ctx.screen.use()
            r, g, b = model.background
            self.ctx.clear(r, g, b, 1.0)
            self.tex.use(0)
            self.vao.render(moderngl.TRIANGLE_STRIP)

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

    try:
        mglw.run_window_config(ViewWindow, args=["--window", "pyglet"])
    finally:
        model.close()

"""Interactive viewing: a Jupyter viewer (``jupyter_rfb``) and a desktop window (``tetvr view``).

The logic is plain Python and testable without a browser or a display:

* :class:`OrbitControl` — camera navigation (orbit about the focal point, zoom, pan), with
  the clipping range kept around the mesh's bounding sphere;
* :class:`ProgressiveRefiner` — the progressive scheme: while the user drags, draw a
  smaller image with the previous visibility order (no sort); once nothing has changed
  for ``settle_s`` seconds, draw the full-size frame with a fresh sort;
* :class:`TransferFunctionEditor` — opacity control points over a colour map, drawn over
  a log-scaled histogram of the scalar values (:mod:`tetvr.apps.viewer.editor`);
* :class:`ViewerModel` — a scene plus the three above, which renders frames and saves and
  loads the scene JSON;
* :class:`~tetvr.apps.viewer.loop.RenderLoop` — the thread that owns the renderer and draws the
  latest wanted state (previews while input continues, the full frame when it stops).

The front-ends are thin: :class:`Viewer` (:mod:`tetvr.apps.viewer.jupyter`, needs
``jupyter_rfb``) and :func:`~tetvr.apps.viewer.desktop.run_desktop`
(:mod:`tetvr.apps.viewer.desktop`, needs ``moderngl-window`` and a display).

Examples
--------
>>> import tetvr                                                     # doctest: +SKIP
>>> from tetvr.apps.viewer import Viewer                                 # doctest: +SKIP
>>> Viewer("post.vtk")                          # doctest: +SKIP
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

from tetvr.core.camera import Camera, bounding_sphere
from tetvr.core.image import png_bytes as _png_bytes
from tetvr.mesh.tetmesh import TetMesh
from tetvr.render import default_transfer_function
from tetvr.scene.scene import Scene
from tetvr.scene.load import load_scene
from tetvr.settings import RenderSettings
from tetvr.optics.transfer import PRESETS, TransferFunction

__all__ = [
    "OrbitControl",
    "ProgressiveRefiner",
    "RenderRequest",
    "TransferFunctionEditor",
    "ViewerModel",
    "HistogramPicker",
    "histogram_image",
    "legend_image",
    "log_histogram",
    "nice_ticks",
    "scene_of",
    "FUSION_PICKER",
    "png_bytes",
    "list_fields",
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
        from tetvr.apps.animate import azimuth

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


from tetvr.apps.viewer.editor import (HistogramPicker, TransferFunctionEditor, histogram_image,  # noqa: E402
                            legend_image, log_histogram, nice_ticks)

#: Fusion modes the viewer offers (``ray_textures`` needs per-pixel images from the user).
FUSION_PICKER = ("interleave", "overlay", "cutaway")

#: The full frame's size when the viewer is given a mesh rather than a scene.
DEFAULT_SIZE = (560, 420)
_SCENE_SUFFIXES = (".json", ".pvsm")


def scene_of(source: "Scene | TetMesh | str | os.PathLike[str]", *, size: tuple[int, int] | None = None) -> Scene:
    """A :class:`Scene` from a scene, a scene file (``.json``, ``.pvsm``), a mesh file
    (any :func:`tetvr.read` reads) or a :class:`TetMesh`: the mesh ones get the default
    transfer function and a fitted camera. ``size`` replaces the scene's size."""
    if isinstance(source, Scene):
        scene = source
    elif isinstance(source, TetMesh):
        scene = Scene(mesh_path="", mesh=source, tf=default_transfer_function(source), camera=Camera.fit(source),
                      size=DEFAULT_SIZE, scalars=source.scalar_name)
    elif isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if not path.exists():
            raise FileNotFoundError(f"{os.fspath(source)!r}: no such scene or mesh file")
        if path.suffix.lower() in _SCENE_SUFFIXES:
            scene = load_scene(path)
        else:
            from tetvr.io.meshfile import read

            scene = dataclasses.replace(scene_of(read(path)), mesh_path=str(path.resolve()))
    else:
        raise TypeError(f"show a Scene, a TetMesh or the path of a scene or mesh file, got {type(source).__name__}")
    if size is not None:
        w, h = (int(v) for v in size)
        if w < 1 or h < 1:
            raise ValueError(f"size must be two positive integers, got {size!r}")
        scene = dataclasses.replace(scene, size=(w, h))
    return scene


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
    scene : the scene to show: a :class:`Scene`, a scene or mesh file, or a :class:`TetMesh`
        (:func:`scene_of`); its size is the full frame's size.
    renderer : anything with ``render(mesh, camera, tf, size=, order=)`` (default: a
        :class:`tetvr.gl.Renderer` made on the first frame and released by :meth:`close`;
        ``"process"``: the same in a child process, :class:`tetvr.apps.viewer.process.ProcessRenderer`).
    preview_scale, settle_s : see :class:`ProgressiveRefiner`.
    clock : the time source (tests pass a fake one).
    """

    def __init__(self, scene: Scene | TetMesh | str | os.PathLike[str], *, renderer: Any = None, preview_scale: float = 0.5,
                 settle_s: float = 0.3, clock: Callable[[], float] = time.monotonic) -> None:
        if isinstance(renderer, str) and renderer != "process":
            raise ValueError(f"renderer must be None, 'process' or a renderer object, got {renderer!r}")
        self._in_process = renderer == "process"
        self._renderer = None if self._in_process else renderer
        self._own_renderer = self._renderer is None
        self.clock = clock
        self.preview_scale = preview_scale
        self.settle_s = settle_s
        self.order: NDArray[np.uint32] | None = None
        self.last_request: RenderRequest | None = None
        self.last_seconds = 0.0
        self._meshes: dict[str, TetMesh] = {}
        self._raycaster: Any = None  # the fused scene's volume ray caster (in-process renderer)
        self.volume: Any = None
        self.volume_editor: TransferFunctionEditor | None = None
        self.fusion = "interleave"
        self.load(scene)

    # ---- scene in, scene out ----
    def load(self, scene: Scene | TetMesh | str | os.PathLike[str]) -> None:
        """Show another scene (anything :func:`scene_of` takes)."""
        scene = scene_of(scene)
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
        self.clip, self.surfaces, self._surface_specs = scene.clip, scene.surfaces, scene.surface_specs
        self.control = OrbitControl(scene.camera, bounds=scene.mesh.bounds)
        self.editor = TransferFunctionEditor.from_transfer_function(scene.tf)
        self.refiner = ProgressiveRefiner(self.size, preview_scale=self.preview_scale,  # type: ignore[arg-type]
                                          settle_s=self.settle_s)
        self.order = None
        # The fields tetvr.read found in the file; a mesh built in memory has only its own.
        self.fields = list(scene.mesh.report.fields) or [self.field]
        self.hist_cache: dict[tuple[Any, ...], NDArray[np.float64]] = {}

    def log_counts(self, bins: int = 72) -> NDArray[np.float64]:
        """The field's log histogram over the editor's range, computed once per (field, range)."""
        key = (self.field, self.editor.scalar_range, bins)
        if key not in self.hist_cache:
            self.hist_cache[key] = log_histogram(self.mesh.scalars, self.editor.scalar_range, bins)[0]
        return self.hist_cache[key]

    def scene(self) -> Scene:
        """The current state as a :class:`Scene` (for :meth:`Scene.save` and ``tetvr render``)."""
        return Scene(mesh_path=self.mesh_path, mesh=self.mesh, tf=self.editor.transfer_function(),
                     camera=self.control.camera, size=self.size, background=self.background,  # type: ignore[arg-type]
                     settings=self.settings, scalars=self.field, component=self.component, clip=self.clip,
                     surfaces=self.surfaces, surface_specs=self._surface_specs)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the current scene JSON (paths relative to it)."""
        if not self.mesh_path:
            raise ValueError("this mesh was given in memory: write it to a file (meshio) and view that file "
                             "to save a scene that refers to it")
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
            from tetvr.io.meshfile import read

            self._meshes[name] = read(self.mesh_path, name)
        new = self._meshes[name]
        # Same file, same cells: the visibility order stays valid (render() sorts afresh
        # should the number of tets differ).
        self.mesh = new
        self.field = name
        self.component = None
        self.editor.set_range(*default_transfer_function(new).domain)  # the default rule's range (tetvr.optics.transfer)

    def set_colormap(self, name: str) -> None:
        self.editor.set_colormap(name)

    def set_volume(self, volume: Any, tf: TransferFunction | None = None, *, mode: str | None = None) -> None:
        """Show an image volume around the mesh (a :class:`tetvr.Volume`; ``None`` removes
        it), fused by ``mode`` (:data:`FUSION_PICKER`, see :mod:`tetvr.fuse`). ``tf``
        defaults to grey levels over the volume's range with a linear opacity ramp."""
        if volume is None:
            self.volume = self.volume_editor = None
            return
        from tetvr.optics.colormaps import colormap
        from tetvr.volume.volume import Volume

        if not isinstance(volume, Volume):
            raise TypeError(f"volume must be a tetvr.Volume or None, got {type(volume).__name__}")
        if mode is not None:
            self.set_fusion(mode)
        if tf is None:
            lo, hi = volume.scalar_range
            tf = colormap("grayscale", (lo, hi if hi > lo else lo + 1.0), opacity=[(0.0, 0.0), (1.0, 0.4)],
                          unit_distance=volume.diagonal / 10)
        elif not isinstance(tf, TransferFunction):
            raise TypeError(f"volume_tf must be a TransferFunction or None, got {type(tf).__name__}")
        self.volume = volume
        self.volume_editor = TransferFunctionEditor.from_transfer_function(tf)

    def set_fusion(self, mode: str) -> None:
        if mode not in FUSION_PICKER:
            raise ValueError(f"fusion mode must be one of {FUSION_PICKER}, got {mode!r}")
        self.fusion = mode

    def fusion_state(self) -> tuple[Any, TransferFunction, str] | None:
        """What :meth:`draw` needs of the volume: ``(volume, volume_tf, mode)``, or None."""
        if self.volume is None or self.volume_editor is None:
            return None
        return self.volume, self.volume_editor.transfer_function(), self.fusion

    def volume_log_counts(self, bins: int = 72) -> NDArray[np.float64]:
        """The volume's log histogram over its editor's range (computed once per range)."""
        assert self.volume is not None and self.volume_editor is not None
        key = ("<volume>", self.volume_editor.scalar_range, bins)
        if key not in self.hist_cache:
            values = np.asarray(self.volume.data).ravel()
            self.hist_cache[key] = log_histogram(values, self.volume_editor.scalar_range, bins)[0]
        return self.hist_cache[key]

    # ---- frames ----
    @property
    def renderer(self) -> Any:
        if self._renderer is None:
            if self._in_process:
                from tetvr.apps.viewer.process import ProcessRenderer

                self._renderer = ProcessRenderer(self.settings)
            else:
                from tetvr.gl.renderer import Renderer

                self._renderer = Renderer(self.settings)
        return self._renderer

    @property
    def renderer_ready(self) -> bool:
        """Whether the renderer is made (else the next frame makes it, or starts its process)."""
        r = self._renderer
        return r is not None and bool(getattr(r, "alive", True))

    def render(self, request: RenderRequest) -> NDArray[np.float32]:
        """Draw what ``request`` asks for, of the current state."""
        return self.draw(self.mesh, self.camera, self.editor.transfer_function(), request, fusion=self.fusion_state())

    @property
    def preview_settings(self) -> RenderSettings:
        """The settings of previews after a transfer-function edit: the same, with a small
        pre-integration table (64 scalar bins x 8 thickness slices builds in a fraction
        of the full table's time; the full frame uses the full table)."""
        return dataclasses.replace(self.settings, table_scalar_bins=64, table_thickness_slices=8)

    def draw(self, mesh: TetMesh, camera: Camera, tf: TransferFunction, request: RenderRequest, *,
             preview_table: bool = False, fusion: tuple[Any, TransferFunction, str] | None = None
             ) -> NDArray[np.float32]:
        """Draw ``request`` of an explicit state (the render loop's snapshot of it);
        ``preview_table``: with :attr:`preview_settings`; ``fusion``: with the volume
        (:meth:`fusion_state`)."""
        from tetvr.order.method import choose
        from tetvr.order.sort import visibility_order

        t0 = time.perf_counter()
        renderer = self.renderer
        if hasattr(renderer, "settings") and self._own_renderer:
            renderer.settings = self.preview_settings if preview_table and not request.final else self.settings
        if fusion is not None:
            image = self._fuse(renderer, mesh, camera, tf, fusion, request.size)
            self.last_seconds = time.perf_counter() - t0
            self.last_request = request
            return image
        order = None  # tet marching needs no order
        if choose(self.settings, mesh) == "projected":
            # Projected tetrahedra: previews reuse the last order; refined frames sort anew.
            if request.sort or self.order is None or self.order.shape[0] != mesh.n_tets:
                self.order = visibility_order(mesh, camera, self.settings.sort)
            order = self.order
        options = {**({"clip": self.clip} if self.clip is not None else {}),
                   **({"surfaces": self.surfaces} if self.surfaces else {})}
        image = renderer.render(mesh, camera, tf, size=request.size, order=order, **options)
        self.last_seconds = time.perf_counter() - t0
        self.last_request = request
        return image

    def _fuse(self, renderer: Any, mesh: TetMesh, camera: Camera, tf: TransferFunction,
              fusion: tuple[Any, TransferFunction, str], size: tuple[int, int]) -> NDArray[np.float32]:
        volume, volume_tf, mode = fusion
        if hasattr(renderer, "fuse"):  # the render process (or a test's stand-in)
            return renderer.fuse(mesh, volume, camera, tf, volume_tf, size=size, mode=mode)  # type: ignore[no-any-return]
        from tetvr.fuse import fuse
        from tetvr.gl.raycaster import Raycaster

        if self._raycaster is None:
            self._raycaster = Raycaster(ctx=renderer.ctx)
        return fuse(mesh, volume, camera, tf, volume_tf, size=size, mode=mode, renderer=renderer,
                    raycaster=self._raycaster)

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
        if self._raycaster is not None:
            self._raycaster.release()
            self._raycaster = None
        if self._own_renderer and self._renderer is not None:
            self._renderer.release()
        self._renderer = None



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

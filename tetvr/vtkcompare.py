"""Side by side with VTK's (ParaView's) unstructured-grid volume mappers.

About this comparison
---------------------
ParaView renders a tetrahedral mesh as a volume with one of three VTK mappers:

* ``"pt"`` -- ``vtkProjectedTetrahedraMapper``, ParaView's "Projected tetra": Shirley &
  Tuchman's (1990) projected tetrahedra with Wylie et al.'s (2002) thick-vertex
  construction, cells sorted by centroid depth, one fragment formula per tet;
* ``"bunyk"`` -- ``vtkUnstructuredGridVolumeRayCastMapper``, "Bunyk ray cast": Bunyk,
  Kaufman & Silva (1997) ray casting on the CPU, pre-integrated (Engel et al. 2001) by
  ``vtkUnstructuredGridPreIntegration``;
* ``"zsweep"`` -- ``vtkUnstructuredGridVolumeZSweepMapper``, "Z sweep": Farias,
  Mitchell & Silva's (2000) sweep, with the same pre-integration.

:class:`VTKRenderer` renders a tetvr mesh, camera and transfer function with one of them,
offscreen through EGL, and reads the image back. :func:`compare` measures all of them,
and tetvr's GPU renderer, against tetvr's exact CPU reference and writes the pictures and
a table (see docs/paraview.md for what was measured and why the images differ).

What VTK's images are. Every mapper blends ``rgb`` with ``SRC_ALPHA`` (the ray casters
draw a premultiplied image with ``ONE``) over the renderer's background, which we set to
black with alpha 0, into an RGBA8 window: so the window holds *premultiplied* colour and
the accumulated alpha, 8 bits per channel, and is read back as such.

VTK runs in a child process (:class:`VTKProcess`). In one process, VTK's EGL window and
tetvr's moderngl context do not coexist: once VTK has made its window current on the EGL
display they share, glcontext's ``eglMakeCurrent`` no longer takes effect, so tetvr's GL
calls land in VTK's context (``GL_INVALID_OPERATION``; VTK 9.7.2, glcontext 3.1.0, Mesa
llvmpipe). A separate process is also how ParaView runs next to an application.

VTK is optional (``pip install "tetvr[compare]"``): this module imports it only in the
VTK process, and :func:`vtk_status` says whether it can render here.
:data:`PARITY_SETTINGS` render what "Projected tetra" renders (VTK parity).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from .animate import azimuth
from .camera import Camera
from .image import atomic_output, psnr, rmse, write_png
from .mesh import TetMesh
from .settings import RenderSettings
from .transfer import TransferFunction

__all__ = [
    "MAPPERS",
    "PARITY_SETTINGS",
    "VTKProcess",
    "VTKRenderer",
    "VTKUnavailableError",
    "compare",
    "orbit",
    "quantize8",
    "tile_images",
    "vtk_status",
    "write_report",
]

#: The mappers, by key: (VTK class, ParaView's name for it).
MAPPERS: dict[str, tuple[str, str]] = {
    "pt": ("vtkProjectedTetrahedraMapper", "Projected tetra"),
    "bunyk": ("vtkUnstructuredGridVolumeRayCastMapper", "Bunyk ray cast"),
    "zsweep": ("vtkUnstructuredGridVolumeZSweepMapper", "Z sweep"),
}

#: tetvr's VTK parity: ``optics="vtk"`` on the GPU draws VTK's projected tetrahedra with
#: VTK's own steps (:mod:`tetvr.gl.vtkpt`: 8-bit vertex colours, its thick vertex and
#: class-2 opacity, its perspective thickness table, screen-linear interpolation, its
#: drawing order). VTK composites in a float target (``UseFloatingPointFrameBuffer``, on by
#: default) and rounds to 8 bits once, when it copies to the window: so the target stays
#: float here and :func:`compare` rounds the final image (:func:`quantize8`). What remains
#: different is listed in docs/paraview.md ("What parity does not reproduce").
PARITY_SETTINGS = RenderSettings(optics="vtk", perspective_correct=False)


class VTKUnavailableError(RuntimeError):
    """VTK is not installed or cannot open an offscreen OpenGL window here."""


# ---------------------------------------------------------------------------- VTK setup
def _import_vtk() -> Any:
    """The VTK modules this module uses, importing them on first use."""
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        # VTK >= 9.4 wheels try X first and log an error without a display; EGL is
        # the headless window (VTK reads this variable when it makes a window).
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (registers the OpenGL windows)
        import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: F401  (the OpenGL PT mapper)
        from vtkmodules import vtkCommonCore, vtkCommonDataModel, vtkRenderingCore, vtkRenderingVolume
        from vtkmodules.util import numpy_support
    except ImportError as exc:
        raise VTKUnavailableError(f"VTK is not installed ({exc}); pip install 'tetvr[compare]'") from None

    class _Modules:
        core = vtkCommonCore
        data = vtkCommonDataModel
        render = vtkRenderingCore
        volume = vtkRenderingVolume
        np_support = numpy_support
        version = vtkCommonCore.vtkVersion.GetVTKVersion()

    return _Modules


@functools.lru_cache(maxsize=1)
def vtk_status() -> tuple[bool, str]:
    """Whether VTK can render offscreen here, and what it is (or why not).

    Renders one tet with the projected-tetrahedra mapper and checks that pixels came
    out. The result is cached for the process.

    Returns
    -------
    (ok, description) : e.g. ``(True, "VTK 9.7.2, vtkEGLRenderWindow, llvmpipe (...)")``.
    """
    import importlib.util

    if importlib.util.find_spec("vtkmodules") is None:
        return False, "VTK is not installed; pip install 'tetvr[compare]'"
    from .synthetic import single_tet

    mesh = single_tet((0.0, 0.3, 0.6, 1.0))
    tf = TransferFunction.preset("grayscale", (0.0, 1.0), opacity=0.9, unit_distance=0.5)
    try:
        with VTKProcess(mesh, tf, mapper="pt", size=(16, 16), timeout=120.0) as r:
            image = r.render(Camera.fit(mesh, direction=(0.3, -0.2, -1.0)))
            info = r.info
    except (VTKUnavailableError, RuntimeError, OSError) as exc:
        return False, f"VTK cannot render offscreen here: {exc}"
    what = f"VTK {info['version']}, {info['window']}, {info['gl_renderer']}"
    if not image[..., 3].max() > 0:
        return False, f"{what}: rendered an empty image offscreen"
    return True, what


def _vtk_grid(mods: Any, mesh: TetMesh) -> Any:
    """The mesh as a vtkUnstructuredGrid of tetrahedra with its field: point scalars, or
    cell scalars for cell data (VTK's mappers then hold each cell's value constant)."""
    ns = mods.np_support
    points = mods.core.vtkPoints()
    points.SetData(ns.numpy_to_vtk(np.ascontiguousarray(mesh.points, dtype=np.float64), deep=True))
    n = mesh.n_tets
    offsets = ns.numpy_to_vtkIdTypeArray(np.arange(0, 4 * n + 1, 4, dtype=np.int64), deep=True)
    conn = ns.numpy_to_vtkIdTypeArray(np.ascontiguousarray(mesh.tets.reshape(-1), dtype=np.int64), deep=True)
    cells = mods.data.vtkCellArray()
    cells.SetData(offsets, conn)
    grid = mods.data.vtkUnstructuredGrid()
    grid.SetPoints(points)
    grid.SetCells(mods.data.VTK_TETRA, cells)
    cells_data = getattr(mesh, "cell_scalars", None)
    values = mesh.scalars if cells_data is None else cells_data
    scalars = ns.numpy_to_vtk(np.ascontiguousarray(values, dtype=np.float64), deep=True)
    scalars.SetName(mesh.scalar_name or "scalars")
    (grid.GetPointData() if cells_data is None else grid.GetCellData()).SetScalars(scalars)
    return grid


def _vtk_property(mods: Any, tf: TransferFunction) -> Any:
    """A vtkVolumeProperty with the same piecewise-linear colour and opacity."""
    color = mods.render.vtkColorTransferFunction()
    color.SetColorSpaceToRGB()
    for x, r, g, b in tf.color:
        color.AddRGBPoint(x, r, g, b)
    opacity = mods.data.vtkPiecewiseFunction()
    for x, a in tf.opacity:
        opacity.AddPoint(x, a)
    prop = mods.render.vtkVolumeProperty()
    prop.SetColor(color)
    prop.SetScalarOpacity(opacity)
    prop.SetScalarOpacityUnitDistance(tf.unit_distance)
    prop.SetInterpolationTypeToLinear()
    prop.ShadeOff()
    return prop


def _set_camera(vtk_camera: Any, camera: Camera) -> None:
    """Copy a tetvr camera; VTK's fields mean the same (vertical view angle, half-height
    parallel scale, clipping range along the view direction)."""
    vtk_camera.SetPosition(*camera.position)
    vtk_camera.SetFocalPoint(*camera.focal_point)
    vtk_camera.SetViewUp(*camera.view_up)
    vtk_camera.SetViewAngle(camera.view_angle)
    vtk_camera.SetParallelProjection(int(camera.parallel_projection))
    vtk_camera.SetParallelScale(camera.parallel_scale)
    vtk_camera.SetClippingRange(*camera.clipping_range)


class VTKRenderer:
    """One VTK mapper in its own offscreen window; many frames of one mesh.

    Use it in a process without tetvr's GL renderer (see the module notes); next to
    tetvr, use :class:`VTKProcess`, which runs one of these in a child process.

    Parameters
    ----------
    mesh, tf : the scene (the transfer function becomes a vtkColorTransferFunction and a
        vtkPiecewiseFunction with ``ScalarOpacityUnitDistance = tf.unit_distance``).
    mapper : a key of :data:`MAPPERS`.
    size : (width, height) of the window.

    Notes
    -----
    The ray casters' automatic image-sample-distance adjustment is switched off, so every
    frame casts one ray per pixel. VTK 9.7's projected-tetrahedra mapper draws nothing on
    the first ``Render()`` of a new window (seen with EGL on llvmpipe), so the first frame
    renders twice; :attr:`first_frame_renders` records it.

    Examples
    --------
    >>> with VTKRenderer(mesh, tf, mapper="pt", size=(256, 256)) as r:  # doctest: +SKIP
    ...     image = r.render(camera)      # (256, 256, 4) float32, premultiplied
    """

    def __init__(self, mesh: TetMesh, tf: TransferFunction, *, mapper: str = "pt",
                 size: tuple[int, int] = (512, 512)) -> None:
        if mapper not in MAPPERS:
            raise ValueError(f"mapper must be one of {sorted(MAPPERS)}, got {mapper!r}")
        width, height = (int(v) for v in size)
        if width < 1 or height < 1:
            raise ValueError(f"size must be two positive integers, got {size!r}")
        self._mods = mods = _import_vtk()
        self.mapper_key = mapper
        self.size = (width, height)
        self._window: Any = None
        self._window = window = mods.render.vtkRenderWindow()
        window.SetOffScreenRendering(1)
        window.SetMultiSamples(0)
        window.SetAlphaBitPlanes(1)
        window.SetSize(width, height)
        self.window_class = window.GetClassName()
        self._renderer = renderer = mods.render.vtkRenderer()
        renderer.SetBackground(0.0, 0.0, 0.0)
        renderer.SetBackgroundAlpha(0.0)
        window.AddRenderer(renderer)
        self._mapper = m = getattr(mods.volume, MAPPERS[mapper][0])()
        if mapper != "pt":
            m.SetAutoAdjustSampleDistances(0)
            m.SetImageSampleDistance(1.0)
        m.SetInputData(_vtk_grid(mods, mesh))
        self._volume = mods.render.vtkVolume()
        self._volume.SetMapper(m)
        self._volume.SetProperty(_vtk_property(mods, tf))
        renderer.AddVolume(self._volume)
        self.gl_renderer = ""
        self.first_frame_renders = 0
        self.mapper_class = m.GetClassName()  # the OpenGL override, for "pt"

    def __enter__(self) -> "VTKRenderer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def release(self) -> None:
        """Release the window's GL resources. Safe to call twice."""
        if self._window is not None:
            self._window.Finalize()
            self._window = None

    def render(self, camera: Camera) -> NDArray[np.float32]:
        """Render one frame; (height, width, 4) float32 premultiplied RGBA, row 0 at the top."""
        if self._window is None:
            raise RuntimeError("this VTKRenderer has been released")
        vtk_camera = self._renderer.GetActiveCamera()
        _set_camera(vtk_camera, camera)
        self._window.Render()
        if self.first_frame_renders == 0:
            self.first_frame_renders = 1
            if self.mapper_key == "pt":
                self._window.Render()
                self.first_frame_renders = 2
            self.gl_renderer = _gl_renderer(self._window)
        near, far = vtk_camera.GetClippingRange()
        if not np.allclose((near, far), camera.clipping_range, rtol=1e-9):
            raise RuntimeError(f"VTK changed the clipping range to {(near, far)}")
        return self._read()

    def _read(self) -> NDArray[np.float32]:
        w, h = self.size
        arr = self._mods.core.vtkUnsignedCharArray()
        self._window.GetRGBACharPixelData(0, 0, w - 1, h - 1, 0, arr)
        raw = self._mods.np_support.vtk_to_numpy(arr).reshape(h, w, 4)
        return (raw[::-1].astype(np.float32) / np.float32(255.0)).copy()


def _gl_renderer(window: Any) -> str:
    text = window.ReportCapabilities() or ""
    for line in text.splitlines():
        if line.startswith("OpenGL renderer string:"):
            return line.split(":", 1)[1].strip()
    return "unknown"


class VTKProcess:
    """A :class:`VTKRenderer` in a child process, so that it can run next to tetvr.

    Same parameters as :class:`VTKRenderer`, plus ``timeout`` (seconds to wait for any
    one reply). :attr:`last_seconds` is the time of the last frame *inside* the child,
    from the camera change to the image read back into numpy, without the transfer
    between processes; :attr:`first_seconds` is the same for the first frame, from the
    window's creation on (it does not count starting Python and importing VTK).
    :attr:`info` holds the VTK version, window class, mapper class and GL renderer.

    The child is a fresh interpreter (``python -c``, not ``multiprocessing``, so scripts
    need no ``if __name__ == "__main__"`` guard) that talks over two pipes (POSIX only;
    VTK renders headless through EGL on Linux anyway).

    Examples
    --------
    >>> with VTKProcess(mesh, tf, mapper="pt", size=(256, 256)) as r:  # doctest: +SKIP
    ...     image = r.render(camera)
    ...     r.last_seconds
    """

    def __init__(self, mesh: TetMesh, tf: TransferFunction, *, mapper: str = "pt",
                 size: tuple[int, int] = (512, 512), timeout: float = 600.0) -> None:
        import subprocess
        import sys
        from multiprocessing.connection import Connection

        if mapper not in MAPPERS:
            raise ValueError(f"mapper must be one of {sorted(MAPPERS)}, got {mapper!r}")
        self.timeout = float(timeout)
        self.last_seconds = float("nan")
        self.first_seconds = float("nan")
        self.info: dict[str, Any] = {}
        self._first = True
        self._proc: Any = None
        down_r, down_w = os.pipe()  # parent -> child
        up_r, up_w = os.pipe()  # child -> parent
        env = dict(os.environ)
        # The child imports this very tetvr, installed or not (benchmarks put the checkout on sys.path).
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(Path(__file__).resolve().parents[1]),
                                                         env.get("PYTHONPATH")) if p)
        code = "import sys; from tetvr.vtkcompare import _serve; _serve(int(sys.argv[1]), int(sys.argv[2]))"
        try:
            self._proc = subprocess.Popen([sys.executable, "-c", code, str(down_r), str(up_w)],
                                          pass_fds=(down_r, up_w), env=env)
        finally:
            os.close(down_r)
            os.close(up_w)
        self._out = Connection(down_w, readable=False)
        self._in = Connection(up_r, writable=False)
        grid = {"points": np.asarray(mesh.points), "tets": np.asarray(mesh.tets),
                "scalars": np.asarray(mesh.scalars), "scalar_name": mesh.scalar_name,
                "cell_scalars": None if mesh.cell_scalars is None else np.asarray(mesh.cell_scalars)}
        self._out.send((grid, tf.to_dict(), mapper, tuple(int(v) for v in size)))
        self.info = self._reply()

    def _reply(self) -> Any:
        try:
            if not self._in.poll(self.timeout):
                self.release()
                raise RuntimeError(f"the VTK process did not answer within {self.timeout:.0f} s")
            kind, payload = self._in.recv()
        except (EOFError, OSError):
            code = self._proc.poll() if self._proc is not None else None
            self.release()
            raise RuntimeError(f"the VTK process died (exit code {code})") from None
        if kind == "error":
            self.release()
            raise VTKUnavailableError(payload) if payload.startswith("VTK is not installed") else RuntimeError(payload)
        return payload

    def __enter__(self) -> "VTKProcess":
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def render(self, camera: Camera) -> NDArray[np.float32]:
        """Render one frame in the child: (height, width, 4) float32 premultiplied RGBA."""
        if self._proc is None:
            raise RuntimeError("this VTKProcess has been released")
        self._out.send(camera.to_dict())
        image, seconds, info = self._reply()
        self.info.update(info)
        self.last_seconds = seconds
        if self._first:
            self.first_seconds, self._first = seconds + self.info.get("setup_seconds", 0.0), False
        return image

    def release(self) -> None:
        """Stop the child process. Safe to call twice."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            self._out.send(None)
        except (OSError, ValueError):
            pass
        try:
            proc.wait(timeout=10)
        except Exception:
            proc.kill()
            proc.wait(timeout=5)
        self._out.close()
        self._in.close()


def _serve(in_fd: int, out_fd: int) -> None:
    """The child of :class:`VTKProcess`: renders the cameras it is sent until it gets None."""
    import types
    from multiprocessing.connection import Connection

    inbox, outbox = Connection(in_fd, writable=False), Connection(out_fd, readable=False)
    try:
        grid, tf_dict, mapper, size = inbox.recv()
        t0 = time.perf_counter()
        mesh = types.SimpleNamespace(**grid, n_tets=len(grid["tets"]))
        renderer = VTKRenderer(mesh, TransferFunction.from_dict(tf_dict), mapper=mapper, size=size)  # type: ignore[arg-type]
        setup = time.perf_counter() - t0
    except Exception as exc:
        outbox.send(("error", str(exc) if isinstance(exc, VTKUnavailableError) else f"{type(exc).__name__}: {exc}"))
        return
    try:
        outbox.send(("ok", {"version": renderer._mods.version, "window": renderer.window_class,
                            "mapper_class": renderer.mapper_class, "gl_renderer": "", "setup_seconds": setup}))
        while True:
            msg = inbox.recv()
            if msg is None:
                break
            t0 = time.perf_counter()
            try:
                image = renderer.render(Camera.from_dict(msg))
            except Exception as exc:
                outbox.send(("error", f"{type(exc).__name__}: {exc}"))
                continue
            seconds = time.perf_counter() - t0
            outbox.send(("ok", (image, seconds, {"gl_renderer": renderer.gl_renderer,
                                                 "first_frame_renders": renderer.first_frame_renders})))
    except (EOFError, BrokenPipeError):
        pass
    finally:
        renderer.release()


# ---------------------------------------------------------------------------- helpers
def orbit(camera: Camera, degrees: float) -> Camera:
    """The camera turned about its view-up axis through the focal point (vtkCamera.Azimuth);
    :func:`tetvr.animate.azimuth`."""
    return azimuth(camera, degrees)


def quantize8(image: NDArray[np.floating[Any]]) -> NDArray[np.float32]:
    """An image as an RGBA8 window stores it (rounded to 1/255), back as float."""
    return (np.round(np.clip(image, 0.0, 1.0) * 255.0) / 255.0).astype(np.float32)


# ---------------------------------------------------------------------------- compare
@dataclasses.dataclass
class _Method:
    key: str
    label: str
    kind: str  # "reference", "tetvr" or "vtk"
    image: NDArray[np.float32] | None = None
    first_frame_s: float | None = None
    view_change_s: list[float] = dataclasses.field(default_factory=list)
    info: dict[str, Any] = dataclasses.field(default_factory=dict)


def compare(
    scene: Any,
    *,
    mappers: Sequence[str] = ("pt", "bunyk", "zsweep"),
    size: tuple[int, int] | None = None,
    views: int = 5,
    azimuth_step: float = 5.0,
    references: Sequence[str] = ("exact", "linear", "vtk"),
    outdir: str | os.PathLike[str] | None = None,
    log: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Render a scene with tetvr and VTK's mappers; time them and measure their error.

    Parameters
    ----------
    scene : a :class:`tetvr.scene.Scene` (or the path of a scene JSON file).
    mappers : keys of :data:`MAPPERS` to run (VTK must be available; see :func:`vtk_status`).
    size : (width, height); default the scene's.
    views : view changes timed after the first frame; each turns the camera by
        ``azimuth_step`` degrees about its view-up axis (vtkCamera.Azimuth).
    references : conventions of the CPU reference to measure against (``"exact"``
        first; ``"linear"`` and ``"vtk"`` show which convention each renderer follows).
    outdir : if given, :func:`write_report` writes the pictures and tables there.

    A scene that leaves the transfer function's unit distance to the default
    (``"unit_distance": null``, :attr:`Scene.unit_distance_default`) is compared with
    ParaView's default unit distance (:func:`tetvr.paraview.paraview_unit_distance`), the
    one a ParaView user gets, for every renderer alike.
    log : called with a line of progress per method (e.g. ``print``).

    Returns
    -------
    dict
        ``scene`` (mesh, tets, size), ``machine``, ``vtk`` (version, window, GL renderer),
        and ``methods``: per renderer its first-frame time, the median view-change time
        (and every sample), and RMSE/PSNR of premultiplied RGB against each reference at
        the first view. Times include reading the image back.

    Examples
    --------
    >>> from tetvr.scene import load_scene                       # doctest: +SKIP
    >>> table = compare(load_scene("scene.json"), outdir="out")  # doctest: +SKIP
    >>> [(m["label"], m["psnr"]["exact"]) for m in table["methods"]]  # doctest: +SKIP
    """
    from .reference import render_reference
    from .scene import Scene, load_scene

    if isinstance(scene, (str, os.PathLike)):
        scene = load_scene(scene)
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a tetvr Scene or a path, got {type(scene).__name__}")
    for m in mappers:
        if m not in MAPPERS:
            raise ValueError(f"mappers must be keys of {sorted(MAPPERS)}, got {m!r}")
    if not references or references[0] != "exact":
        raise ValueError(f"references must start with 'exact', got {references!r}")
    if not (isinstance(views, int) and views >= 1):
        raise ValueError(f"views must be a positive integer, got {views!r}")
    say = log or (lambda line: None)
    vtk_info: dict[str, Any] = {}
    if mappers:
        # Before anything is rendered: the reference alone takes seconds to minutes.
        ok, why = vtk_status()
        if not ok:
            raise VTKUnavailableError(why)
        vtk_info["status"] = why
    width, height = (int(v) for v in (size or scene.size))
    size = (width, height)
    unit_from = "the scene"
    if getattr(scene, "unit_distance_default", False):
        # The scene left the unit distance to tetvr's default (diagonal / 20): compare what a
        # ParaView user sees, ParaView's default (diagonal / cube root of the cells), everywhere.
        from .paraview import paraview_unit_distance

        u = paraview_unit_distance(scene.mesh.bounds, scene.mesh.n_tets)
        scene = dataclasses.replace(scene, tf=dataclasses.replace(scene.tf, unit_distance=u),
                                    unit_distance_default=False)
        unit_from = "ParaView's default (bounding-box diagonal / cube root of the cell count)"
        say(f"unit distance: {u:.6g}, {unit_from}; the scene left it to the default")
    mesh, tf, camera = scene.mesh, scene.tf, scene.camera
    cams = [orbit(camera, azimuth_step * (i + 1)) for i in range(views)]

    refs: dict[str, NDArray[np.float32]] = {}
    ref_times: dict[str, float] = {}
    for optics in references:
        t0 = time.perf_counter()
        refs[optics] = render_reference(mesh, camera, tf, size, optics=optics)
        ref_times[optics] = time.perf_counter() - t0
        say(f"reference ({optics}): {ref_times[optics]:.2f} s")
    methods: list[_Method] = [_Method(f"reference_{o}", f"tetvr CPU reference ({o})", "reference", refs[o],
                                      first_frame_s=ref_times[o]) for o in references]

    # tetvr: the scene's settings, then VTK parity. First frame = context + upload + table.
    for key, label, settings, parity in (("tetvr", "tetvr GPU", scene.settings, False),
                                         ("tetvr_parity", "tetvr GPU, VTK parity", PARITY_SETTINGS, True)):
        from .gl.renderer import Renderer

        meth = _Method(key, label, "tetvr", info={"settings": settings.to_dict()})
        t0 = time.perf_counter()
        with Renderer(settings) as r:
            image = r.render(mesh, camera, tf, size=size)
            meth.first_frame_s = time.perf_counter() - t0
            for cam in cams:
                t0 = time.perf_counter()
                r.render(mesh, cam, tf, size=size)
                meth.view_change_s.append(time.perf_counter() - t0)
            meth.info["gl_renderer"] = r.gl_info.get("GL_RENDERER", "")
        meth.image = quantize8(image) if parity else image
        methods.append(meth)
        say(f"{label}: first {meth.first_frame_s:.3f} s, view change {statistics.median(meth.view_change_s):.3f} s")

    for key in mappers:
        cls, pv_name = MAPPERS[key]
        meth = _Method(f"vtk_{key}", f'VTK {cls} (ParaView "{pv_name}")', "vtk")
        # Timed inside the VTK process (VTKProcess): without starting it and moving images.
        with VTKProcess(mesh, tf, mapper=key, size=size) as r:
            image = r.render(camera)
            meth.first_frame_s = r.first_seconds
            for cam in cams:
                r.render(cam)
                meth.view_change_s.append(r.last_seconds)
            meth.info.update(r.info)
            vtk_info.update(version=r.info["version"], window=r.info["window"], gl_renderer=r.info["gl_renderer"])
        meth.image = image
        methods.append(meth)
        say(f"{meth.label}: first {meth.first_frame_s:.3f} s, view change {statistics.median(meth.view_change_s):.3f} s")

    result = _table(scene, size, views, azimuth_step, methods, refs, vtk_info)
    result["scene"]["unit_distance_from"] = unit_from
    if outdir is not None:
        write_report(result, outdir, images={m.key: m.image for m in methods if m.image is not None},
                     background=scene.background)
    return result


def _table(scene: Any, size: tuple[int, int], views: int, step: float, methods: list[_Method],
           refs: dict[str, NDArray[np.float32]], vtk_info: dict[str, Any]) -> dict[str, Any]:
    rows = []
    exact = refs["exact"]
    covered = exact[..., 3] > 1.0 / 255.0
    for m in methods:
        if m.image is None:
            raise AssertionError(f"{m.key} has no image")
        row: dict[str, Any] = {"key": m.key, "label": m.label, "kind": m.kind,
                               "first_frame_s": m.first_frame_s,
                               "view_change_s": statistics.median(m.view_change_s) if m.view_change_s else None,
                               "view_change_samples_s": m.view_change_s,
                               "rmse": {o: rmse(m.image, r) for o, r in refs.items()},
                               "psnr": {o: psnr(m.image, r) for o, r in refs.items()},
                               "max_abs_error": float(np.abs(m.image[..., :4].astype(np.float64) - exact).max()),
                               "mean_alpha": float(m.image[..., 3][covered].mean()) if covered.any() else 0.0}
        row.update(m.info)
        rows.append(row)
    pt = next((m.image for m in methods if m.key == "vtk_pt"), None)
    for row, m in zip(rows, methods):
        if pt is not None and m.image is not None:
            row["psnr_vs_vtk_pt"] = psnr(m.image, pt)
            row["max_abs_diff_vs_vtk_pt"] = float(np.abs(m.image.astype(np.float64) - pt).max())
    tetvr_row = next((r for r in rows if r["key"] == "tetvr"), None)
    for row in rows:
        if tetvr_row and row["view_change_s"] and tetvr_row["view_change_s"]:
            row["view_change_vs_tetvr"] = row["view_change_s"] / tetvr_row["view_change_s"]
    return {
        "scene": {"mesh": scene.mesh_path, "n_tets": scene.mesh.n_tets, "n_points": scene.mesh.n_points,
                  "scalars": scene.mesh.scalar_name, "size": list(size), "camera": scene.camera.to_dict(),
                  "transfer_function": scene.tf.to_dict()},
        "timing": {"views": views, "azimuth_step_deg": step,
                   "note": "first frame: from the mesh in memory to the image read back, window/context "
                           "creation included; view change: median over the views, camera turned each "
                           "frame, image read back"},
        "machine": {"platform": platform.platform(), "processor": platform.processor(), "cpus": os.cpu_count()},
        "vtk": vtk_info,
        "methods": rows,
    }


def write_report(result: dict[str, Any], outdir: str | os.PathLike[str], *,
                 images: dict[str, NDArray[np.float32]] | None = None, diff_gain: float = 10.0,
                 background: Any = None) -> Path:
    """Write ``comparison.json``, ``comparison.md`` and, with ``images``, the pictures.

    Pictures: ``side_by_side.png`` (every method in table order, four to a row, each
    titled with its number, name and PSNR against the exact reference), ``differences.png``
    (``|image - exact reference|`` of premultiplied RGB times ``diff_gain``, same order)
    and one ``<key>.png`` / ``<key>_diff.png`` per method. Without matplotlib the two
    grids are written untitled. The images are drawn over ``background`` (the scene's;
    default :data:`tetvr.image.DEFAULT_BACKGROUND`), the differences over black.
    """
    bg = {} if background is None else {"background": tuple(background)}
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "comparison.json", "w") as f:
        json.dump(result, f, indent=2, default=float)
    if images:
        exact = images.get("reference_exact")
        tiles, diffs, titles = [], [], []
        for i, m in enumerate(result["methods"]):
            if m["key"] not in images:
                continue
            img = images[m["key"]]
            write_png(img, out / f"{m['key']}.png", **bg)
            tiles.append(img)
            db = (m.get("psnr") or {}).get("exact")
            name = m["label"] if len(m["label"]) <= 26 else m["key"]  # the table has the full name
            score = "" if db is None else "\nthe reference" if math.isinf(db) else f"\n{_fmt(db, '.1f')} dB"
            titles.append(f"{i + 1}. {name}{score}")
            if exact is not None:
                d = np.zeros_like(img)
                d[..., :3] = np.clip(np.abs(img[..., :3].astype(np.float64) - exact[..., :3]) * diff_gain, 0, 1)
                d[..., 3] = 1.0
                write_png(d, out / f"{m['key']}_diff.png", background=None)
                diffs.append(d)
        _write_grid(tiles, titles, out / "side_by_side.png", suptitle=None, **bg)
        if diffs:
            _write_grid(diffs, titles, out / "differences.png", suptitle=f"|image - exact reference| x {diff_gain:g}")
    (out / "comparison.md").write_text(_markdown(result, diff_gain))
    return out


def _write_grid(images: list[NDArray[np.float32]], titles: list[str], path: Path, *, suptitle: str | None,
                **background: Any) -> None:
    try:
        from .annotate import panels

        data = panels(images, titles, cols=min(4, len(images)), suptitle=suptitle, **background)
    except ImportError:  # matplotlib absent: the grid without its titles
        write_png(tile_images(images), path, **background)
        return
    with atomic_output(path) as f:
        f.write(data)


def tile_images(images: list[NDArray[np.float32]], cols: int = 4, gap: int = 4) -> NDArray[np.float32]:
    """Images of one size tiled in reading order, ``cols`` per row, on a grey grid."""
    h, w = images[0].shape[:2]
    rows = -(-len(images) // cols)
    cols = min(cols, len(images))
    out = np.zeros((rows * h + (rows - 1) * gap, cols * w + (cols - 1) * gap, 4), dtype=np.float32)
    out[..., :3] = 0.5
    out[..., 3] = 1.0
    for i, img in enumerate(images):
        r, c = divmod(i, cols)
        out[r * (h + gap):r * (h + gap) + h, c * (w + gap):c * (w + gap) + w] = img
    for i in range(len(images), rows * cols):
        r, c = divmod(i, cols)
        out[r * (h + gap):r * (h + gap) + h, c * (w + gap):c * (w + gap) + w] = (0, 0, 0, 1)
    return out


def _fmt(v: Any, spec: str) -> str:
    if v is None:
        return "-"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return format(v, spec)


def _markdown(result: dict[str, Any], gain: float) -> str:
    s = result["scene"]
    refs = list(result["methods"][0]["psnr"])
    lines = [f"# tetvr against VTK: {Path(s['mesh']).name}", "",
             f"{s['n_tets']} tets, field {s['scalars']!r}, {s['size'][0]}x{s['size'][1]} px. "
             f"{result['timing']['note']}; {result['timing']['views']} views, "
             f"{result['timing']['azimuth_step_deg']} degrees apart.", "",
             f"VTK: {result['vtk'].get('status', 'not run')}", "",
             "Error: PSNR (dB) and RMSE of premultiplied RGB against tetvr's CPU reference in each "
             "convention (`exact`: tau = -ln(1-a)/u; `linear`: tau = a/u; `vtk`: VTK's projected-"
             "tetrahedra segment formula on exact geometry; see docs/paraview.md).", "",
             "| # | method | first frame (s) | view change (s) | / tetvr | "
             + " | ".join(f"PSNR {o}" for o in refs) + " | PSNR vs VTK PT | RMSE exact | max abs err |",
             "|---|---|---|---|---|" + "---|" * len(refs) + "---|---|---|"]
    for i, m in enumerate(result["methods"]):
        lines.append(
            f"| {i + 1} | {m['label']} | {_fmt(m['first_frame_s'], '.3f')} | {_fmt(m['view_change_s'], '.3f')} | "
            f"{_fmt(m.get('view_change_vs_tetvr'), '.2f')} | "
            + " | ".join(_fmt(m["psnr"][o], ".1f") for o in refs)
            + f" | {_fmt(m.get('psnr_vs_vtk_pt'), '.1f')} | {_fmt(m['rmse']['exact'], '.2e')}"
            f" | {_fmt(m['max_abs_error'], '.3f')} |")
    lines += ["", "Pictures, numbered and titled as the table, four to a row: `side_by_side.png` "
              f"and `differences.png` (|image - exact reference| x {gain:g}); one "
              "`<key>.png` and `<key>_diff.png` per method.", ""]
    return "\n".join(lines)

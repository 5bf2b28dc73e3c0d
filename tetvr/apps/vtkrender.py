"""VTK's (ParaView's) unstructured-grid volume mappers, offscreen, for :mod:`tetvr.apps.vtkcompare`.

About these mappers
-------------------
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
offscreen through EGL, and reads the image back.

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
"""

from __future__ import annotations

import functools
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.transfer import TransferFunction

__all__ = [
    "MAPPERS",
    "VTKProcess",
    "VTKRenderer",
    "VTKUnavailableError",
    "vtk_status",
]

#: The mappers, by key: (VTK class, ParaView's name for it).
MAPPERS: dict[str, tuple[str, str]] = {
    "pt": ("vtkProjectedTetrahedraMapper", "Projected tetra"),
    "bunyk": ("vtkUnstructuredGridVolumeRayCastMapper", "Bunyk ray cast"),
    "zsweep": ("vtkUnstructuredGridVolumeZSweepMapper", "Z sweep"),
}


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
    from tetvr.mesh.synthetic import single_tet

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
        pts = np.asarray(mesh.points, dtype=np.float64)
        self._bounds = np.stack([pts.min(axis=0), pts.max(axis=0)])  # for a camera without a clipping range
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
        camera = resolve_clipping_range(camera, self._bounds)
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
    :attr:`info` holds the VTK version, window class, mapper class and GL renderer, and
    ``cpu_seconds``, the child's CPU time over the last frame (all its threads).

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
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(Path(__file__).resolve().parents[2]),
                                                         env.get("PYTHONPATH")) if p)
        code = "import sys; from tetvr.apps.vtkrender import _serve; _serve(int(sys.argv[1]), int(sys.argv[2]))"
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
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                image = renderer.render(Camera.from_dict(msg))
            except Exception as exc:
                outbox.send(("error", f"{type(exc).__name__}: {exc}"))
                continue
            seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
            outbox.send(("ok", (image, seconds, {"gl_renderer": renderer.gl_renderer, "cpu_seconds": cpu,
                                                 "first_frame_renders": renderer.first_frame_renders})))
    except (EOFError, BrokenPipeError):
        pass
    finally:
        renderer.release()

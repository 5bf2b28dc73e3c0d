"""Animations: a camera orbit or a sequence of time steps, to PNG frames or a video.

One :class:`~tetvr.gl.Renderer` renders every frame, so the mesh, the shaders and the
pre-integration table are made once (the table once for the whole run: a time series
keeps the scene's transfer function, so colours mean the same value in every frame).

Examples
--------
>>> from tetvr import Camera
>>> cams = orbit(Camera(position=(0, -5, 0), view_up=(0, 0, 1)), 4)
>>> [tuple(round(v, 6) + 0.0 for v in c.position) for c in cams]
[(0.0, -5.0, 0.0), (5.0, 0.0, 0.0), (0.0, 5.0, 0.0), (-5.0, 0.0, 0.0)]
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.camera import Camera
from tetvr.io.series import read_time_series, series_input_paths
from tetvr.io.video import VIDEO_SUFFIXES, check_frames_output, write_frames
from tetvr.mesh.tetmesh import TetMesh
from tetvr.settings import RenderSettings
from tetvr.optics.transfer import TransferFunction

__all__ = ["orbit", "azimuth", "read_time_series", "render_frames", "write_frames", "animate", "VIDEO_SUFFIXES"]


Image = NDArray[np.float32]


def azimuth(camera: Camera, degrees: float, *, axis: ArrayLike | None = None) -> Camera:
    """The camera turned by ``degrees`` about ``axis`` (default its ``view_up``) through
    its focal point, as VTK's ``Azimuth``: the view up and the distance are kept.

    A whole number of turns returns ``camera`` itself, so a full orbit ends bit-exactly
    where it started.
    """
    a = math.fmod(float(degrees), 360.0)
    if not math.isfinite(a):
        raise ValueError(f"degrees must be finite, got {degrees!r}")
    if a == 0.0:
        return camera
    k = np.asarray(camera.view_up if axis is None else axis, dtype=np.float64)
    if k.shape != (3,) or not np.linalg.norm(k) > 0:
        raise ValueError(f"axis must be a non-zero 3-vector, got {axis!r}")
    k = k / np.linalg.norm(k)
    rad = math.radians(a)
    focal = np.asarray(camera.focal_point)
    v = np.asarray(camera.position) - focal
    # Rodrigues' rotation of the eye offset about k.
    v_rot = v * math.cos(rad) + np.cross(k, v) * math.sin(rad) + k * np.dot(k, v) * (1.0 - math.cos(rad))
    up = np.asarray(camera.view_up, dtype=np.float64)
    if axis is not None:
        up = up * math.cos(rad) + np.cross(k, up) * math.sin(rad) + k * np.dot(k, up) * (1.0 - math.cos(rad))
    return dataclasses.replace(camera, position=tuple(focal + v_rot), view_up=tuple(up))  # type: ignore[arg-type]


def orbit(camera: Camera, n_frames: int, *, degrees: float = 360.0, endpoint: bool = False,
          axis: ArrayLike | None = None) -> list[Camera]:
    """``n_frames`` cameras turning ``degrees`` about the view up through the focal point.

    ``endpoint=False`` (default) spaces the frames ``degrees / n_frames`` apart and leaves
    the end angle out, so a 360° orbit loops without a repeated frame; ``endpoint=True``
    includes it (for 360°, the last camera is then the first).
    """
    if not isinstance(n_frames, int) or isinstance(n_frames, bool) or n_frames < 1:
        raise ValueError(f"n_frames must be a positive integer, got {n_frames!r}")
    if endpoint and n_frames < 2:
        raise ValueError("endpoint=True needs at least 2 frames")
    den = n_frames - 1 if endpoint else n_frames
    # k/den of the sweep, with the end angle exactly ``degrees`` (no k * step rounding).
    angles = [float(degrees) if k == den else float(degrees) * k / den for k in range(n_frames)]
    return [azimuth(camera, a, axis=axis) for a in angles]


def render_frames(frames: Iterable[tuple[TetMesh, Camera]], tf: TransferFunction, *,
                  size: tuple[int, int] = (512, 512), settings: RenderSettings | None = None,
                  renderer: Any = None, progress: bool = True, total: int | None = None,
                  desc: str = "frames", **options: Any) -> Iterator[Image]:
    """Render ``(mesh, camera)`` pairs with one renderer; yields premultiplied float images.

    A tqdm progress bar counts the frames unless ``progress=False``; ``options`` (``clip``,
    ``surfaces``) go to every ``Renderer.render``.
    """
    from tqdm.auto import tqdm

    from tetvr.gl.renderer import Renderer

    own = renderer is None
    r = renderer or Renderer(settings)
    try:
        for mesh, cam in tqdm(frames, total=total, desc=desc, unit="frame", disable=not progress):
            yield r.render(mesh, cam, tf, size=size, **options)
    finally:
        if own:
            r.release()


def animate(scene: Any, out: str | os.PathLike[str], *, orbit_frames: int | None = None, degrees: float = 360.0,
            time_series: Any = None, fps: float = 12.0, size: tuple[int, int] | None = None,
            progress: bool = True, scheduler: Any = None) -> list[Path]:
    """Render a scene's orbit or time series to ``out`` (a folder of PNGs, or a video).

    Parameters
    ----------
    scene : a :class:`tetvr.Scene` (or the path of a scene JSON file).
    out : a folder, or a file ending in one of :data:`VIDEO_SUFFIXES`.
    orbit_frames : frames of an orbit of ``degrees`` about the camera's view up (the end
        angle left out, so 360° loops).
    time_series : mesh files or an XDMF time series (see :func:`read_time_series`), drawn
        with the scene's field name, camera and transfer function; with ``orbit_frames``
        too, the camera turns while time runs, one step per frame.
    fps : frames per second of a video.
    size : (width, height); default the scene's.
    scheduler : render the time series on a Dask cluster (:func:`tetvr.cluster.timeseries.animate_series`):
        a ``distributed.Client``, a scheduler address, or ``"local"`` for a ``LocalCluster``
        on this machine's cores; None renders here, one frame after another.
    """
    from tetvr.scene.scene import Scene
    from tetvr.scene.load import load_scene

    inputs = [] if isinstance(scene, Scene) else [("scene file", os.fspath(scene))]
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if orbit_frames is None and time_series is None:
        raise ValueError("nothing to animate: give orbit_frames, time_series or both")
    # Before a step is read or a frame rendered: no frame over an input, and a place to write.
    inputs += [("mesh file", p) for p in scene.input_paths()] + series_input_paths(time_series)
    check_frames_output(out, inputs, by="animate")
    if scheduler is not None:
        if time_series is None or orbit_frames is not None:
            raise ValueError("a scheduler renders a time series with the scene's camera: give time_series "
                             "and no orbit_frames")
        from tetvr.cluster.timeseries import animate_series

        return animate_series(scene, time_series, out, client=None if scheduler == "local" else scheduler, fps=fps,
                              size=size, progress=progress)
    size = tuple(size or scene.size)  # type: ignore[assignment]
    if time_series is not None:
        steps = [m for _, m in read_time_series(time_series, scene.scalars, component=scene.component)]
        n = len(steps) if orbit_frames is None else orbit_frames
        meshes = [steps[min(i, len(steps) - 1)] for i in range(n)]
    else:
        n = int(orbit_frames)  # type: ignore[arg-type]
        meshes = [scene.mesh] * n
    cams = orbit(scene.camera, n, degrees=degrees) if orbit_frames is not None else [scene.camera] * n
    images = render_frames(zip(meshes, cams), scene.tf, size=size, settings=scene.settings,  # type: ignore[arg-type]
                           progress=progress, total=n, **scene.render_options)
    return write_frames(images, out, background=scene.background, fps=fps, inputs=inputs)

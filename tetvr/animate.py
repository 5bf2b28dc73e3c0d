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
from typing import Any, Iterable, Iterator, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .camera import Camera
from .image import to_rgba8, write_png
from .mesh import TetMesh, _cell_to_point, _field_to_scalar
from .settings import RenderSettings
from .transfer import TransferFunction

__all__ = ["orbit", "azimuth", "read_time_series", "render_frames", "write_frames", "animate", "VIDEO_SUFFIXES"]

#: Output suffixes written as one video file (imageio; mp4/webm/mkv/mov/avi need imageio-ffmpeg).
VIDEO_SUFFIXES = (".mp4", ".webm", ".mkv", ".mov", ".avi", ".gif")

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


def read_time_series(source: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], scalars: str | None = None,
                     *, component: int | None = None) -> Iterator[tuple[float, TetMesh]]:
    """Yield ``(time, mesh)`` for each step of a time series.

    ``source`` is either a list of mesh files (one per step; time = the index), a ``.pvd``
    collection (its steps and times), or one
    XDMF time series written by ``meshio.xdmf.TimeSeriesWriter`` (read with its
    ``TimeSeriesReader``; HDF5-backed files need h5py). ``scalars``/``component`` pick
    the field as in :func:`tetvr.read`.
    """
    from .mesh import read

    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if path.suffix.lower() in (".xdmf", ".xmf"):
            yield from _read_xdmf_series(path, scalars, component)
            return
        if path.suffix.lower() == ".pvd":
            from .collections import read_pvd, read_step

            coll = read_pvd(path)
            for i, t in enumerate(coll.times):
                yield t, read_step(coll, i, scalars, component=component)
            return
        paths: list[Any] = [path]
    else:
        paths = list(source)
    if not paths:
        raise ValueError("the time series is empty: give at least one mesh file")
    for i, p in enumerate(paths):
        yield float(i), read(p, scalars, component=component)


def _read_xdmf_series(path: Path, scalars: str | None, component: int | None) -> Iterator[tuple[float, TetMesh]]:
    import meshio

    if not path.is_file():
        raise FileNotFoundError(f"time series not found: {path}")
    reader = meshio.xdmf.TimeSeriesReader(str(path))
    points, cells = reader.read_points_cells()
    blocks = [i for i, c in enumerate(cells) if c.type == "tetra"]
    if not blocks:
        raise ValueError(f"{path} contains no tetrahedra ({', '.join(c.type for c in cells) or 'no cells'})")
    tets = np.concatenate([cells[i].data for i in blocks]).astype(np.int64)
    pts = np.asarray(points, dtype=np.float64)
    base: TetMesh | None = None
    for k in range(reader.num_steps):
        t, point_data, cell_data = reader.read_data(k)
        name = scalars or next(iter(point_data), None) or next(iter(cell_data), None)
        if name is None:
            raise ValueError(f"{path}: step {k} has no point or cell data")
        if name in point_data:
            values = _field_to_scalar(np.asarray(point_data[name]), name, component)
        elif name in cell_data:
            cv = np.concatenate([_field_to_scalar(np.asarray(cell_data[name][i]), name, component) for i in blocks])
            values = _cell_to_point(pts, tets, cv.astype(np.float64))
        else:
            raise KeyError(f"no field {name!r} in step {k} of {path}; point fields {list(point_data)}, "
                           f"cell fields {list(cell_data)}")
        # The geometry is the same in every step: canonicalise it once, then swap the field
        # (canonicalisation reorders cells, never points).
        base = TetMesh.from_arrays(pts, tets, values, scalar_name=name) if base is None else base.with_scalars(values, name)
        yield float(t), base


def render_frames(frames: Iterable[tuple[TetMesh, Camera]], tf: TransferFunction, *,
                  size: tuple[int, int] = (512, 512), settings: RenderSettings | None = None,
                  renderer: Any = None, progress: bool = True, total: int | None = None,
                  desc: str = "frames", **options: Any) -> Iterator[Image]:
    """Render ``(mesh, camera)`` pairs with one renderer; yields premultiplied float images.

    A tqdm progress bar counts the frames unless ``progress=False``; ``options`` (``clip``,
    ``surfaces``) go to every ``Renderer.render``.
    """
    from tqdm.auto import tqdm

    from .gl.renderer import Renderer

    own = renderer is None
    r = renderer or Renderer(settings)
    try:
        for mesh, cam in tqdm(frames, total=total, desc=desc, unit="frame", disable=not progress):
            yield r.render(mesh, cam, tf, size=size, **options)
    finally:
        if own:
            r.release()


def write_frames(images: Iterable[ArrayLike], out: str | os.PathLike[str], *,
                 background: Sequence[float] | None = (1.0, 1.0, 1.0), fps: float = 12.0,
                 prefix: str = "frame_") -> list[Path]:
    """Write images as ``out/frame_0000.png``, ... (a folder), or as one video when
    ``out`` ends in a :data:`VIDEO_SUFFIXES` suffix. Returns the files written."""
    out = Path(out)
    if out.suffix.lower() in VIDEO_SUFFIXES:
        return [_write_video(images, out, background, fps)]
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} exists and is not a folder; give a folder for PNG frames or a video file "
                         f"({', '.join(VIDEO_SUFFIXES)})")
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for i, image in enumerate(images):
        path = out / f"{prefix}{i:04d}.png"
        write_png(image, path, background=background)
        written.append(path)
    return written


def _write_video(images: Iterable[ArrayLike], out: Path, background: Sequence[float] | None, fps: float) -> Path:
    try:
        import imageio.v2 as imageio
    except ImportError:
        raise ImportError(f"writing {out.suffix} needs imageio (and imageio-ffmpeg for video): "
                          "pip install imageio imageio-ffmpeg; or give a folder for PNG frames") from None
    if out.suffix.lower() != ".gif":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise ImportError(f"writing {out.suffix} needs imageio-ffmpeg: pip install imageio-ffmpeg; "
                              "or write a .gif, or a folder of PNG frames") from None
    out.parent.mkdir(parents=True, exist_ok=True)
    bg = (1.0, 1.0, 1.0) if background is None and out.suffix.lower() != ".gif" else background
    kw: dict[str, Any] = {"duration": 1.0 / fps, "loop": 0} if out.suffix.lower() == ".gif" else {"fps": fps, "macro_block_size": 1}
    with imageio.get_writer(out, **kw) as writer:
        for image in images:
            rgba = to_rgba8(image, bg)
            writer.append_data(rgba if out.suffix.lower() == ".gif" else rgba[..., :3])  # type: ignore[attr-defined]
    return out


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
    scheduler : render the time series on a Dask cluster (:func:`tetvr.distributed.animate_series`):
        a ``distributed.Client``, a scheduler address, or ``"local"`` for a ``LocalCluster``
        on this machine's cores; None renders here, one frame after another.
    """
    from .scene import Scene, load_scene

    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if orbit_frames is None and time_series is None:
        raise ValueError("nothing to animate: give orbit_frames, time_series or both")
    if scheduler is not None:
        if time_series is None or orbit_frames is not None:
            raise ValueError("a scheduler renders a time series with the scene's camera: give time_series "
                             "and no orbit_frames")
        from .distributed import animate_series

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
    return write_frames(images, out, background=scene.background, fps=fps)

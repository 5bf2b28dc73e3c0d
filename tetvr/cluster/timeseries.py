"""Rendering a time series on a Dask cluster, one task per step.

About this technique
--------------------
Each worker reads its own step (the client never loads the meshes) and renders it with
the one :class:`~tetvr.gl.Renderer` that worker keeps for the run
(:func:`tetvr.cluster.workers.worker_renderer`). The renderer is a pure function of (mesh,
camera, transfer function, settings), so a frame is the same bits wherever it was
rendered. A step is a mesh, a mesh file, a step of a ``.pvd`` collection or of an XDMF
time series (:func:`series_sources`); the cluster is ``dask.distributed``'s
(:func:`tetvr.cluster.workers.cluster_client`). Measured speed-ups: ``docs/distributed.md``.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Union

import numpy as np
from numpy.typing import NDArray

from tetvr.cluster.workers import as_completed, cluster_client, gather, worker_renderer
from tetvr.core.camera import Camera
from tetvr.core.image import image_size
from tetvr.core.outputs import check_outputs, check_writable
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.transfer import TransferFunction, default_unit_distance
from tetvr.settings import RenderSettings

__all__ = ["Source", "animate_series", "render_series", "series_sources"]

# A step: a mesh, a mesh file, (a .pvd, a step index) or ("xdmf", an XDMF file, a step index).
Source = Union[TetMesh, str, tuple[str, int], tuple[str, str, int]]
_XDMF = (".xdmf", ".xmf")
_GLOB = ("*", "?", "[")


@dataclasses.dataclass(frozen=True)
class _Step:
    source: Source
    time: float


def series_sources(steps: Any) -> list[_Step]:
    """The steps of a series: a ``.pvd`` path or :class:`~tetvr.io.collections.Collection`
    (its times), an XDMF time series (its times), a glob pattern (``"run/step_*.vtu"``,
    the files in natural order: ``s2`` before ``s10``), or a sequence of meshes or mesh
    files (time = index). Only the collection's own file is read here, never a mesh."""
    from tetvr.io.collections import Collection, read_pvd

    if isinstance(steps, (str, os.PathLike)):
        name = os.fspath(steps)
        if name.lower().endswith(".pvd"):
            steps = read_pvd(name)
        elif name.lower().endswith(_XDMF):
            return [_Step(("xdmf", os.path.abspath(name), k), t) for k, t in enumerate(_xdmf_times(name))]
        elif any(ch in name for ch in _GLOB) and not os.path.exists(name):
            import glob

            steps = sorted(glob.glob(name), key=_natural_key)
            if not steps:
                raise FileNotFoundError(f"no file matches {name!r}")
    if isinstance(steps, Collection):
        return [_Step((steps.path, i), t) for i, t in enumerate(steps.times)]
    if isinstance(steps, (str, os.PathLike, TetMesh)):
        steps = [steps]
    out = []
    for i, s in enumerate(steps):
        if not isinstance(s, (TetMesh, str, os.PathLike)):
            raise TypeError(f"step {i} must be a TetMesh or a mesh file, got {type(s).__name__}")
        out.append(_Step(s if isinstance(s, TetMesh) else os.path.abspath(os.fspath(s)), float(i)))
    if not out:
        raise ValueError("the series is empty: give at least one mesh or file")
    return out


def _step_inputs(items: list[_Step]) -> list[tuple[str, str]]:
    """``(what, path)`` for every file the steps read: what no frame may be written over."""
    from tetvr.io.collections import read_pvd
    from tetvr.io.series import series_input_paths, xdmf_data_files

    out: list[tuple[str, str]] = []
    seen: set[str] = set()
    for step in items:
        src = step.source
        if isinstance(src, TetMesh):
            continue
        if isinstance(src, tuple):  # a step of a .pvd or of an XDMF time series: its files, once
            path = str(src[1] if len(src) == 3 else src[0])
            if path not in seen:
                seen.add(path)
                out += ([("time-series file", path)] + [("time-series data file", p) for p in xdmf_data_files(path)]
                        if len(src) == 3 else [("collection file", p) for p in read_pvd(path).input_paths()])
            continue
        out += series_input_paths(src)
    return out


def _natural_key(name: str) -> list[Any]:
    import re

    return [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", name)]


def _xdmf_times(path: str) -> list[float]:
    """The time values of an XDMF time series (its XML only, no data)."""
    import meshio

    if not os.path.isfile(path):
        raise FileNotFoundError(f"time series not found: {path}")
    reader = meshio.xdmf.TimeSeriesReader(path)
    times = []
    for k, grid in enumerate(reader.collection):
        t = grid.find("Time")
        times.append(float(t.get("Value")) if t is not None and t.get("Value") is not None else float(k))
    return times


def _read_xdmf_step(path: str, k: int, scalars: str | None, component: int | None) -> TetMesh:
    """Step ``k`` of an XDMF time series, as :func:`tetvr.io.series.read_time_series` reads it."""
    import itertools
    from pathlib import Path

    from tetvr.io.series import _read_xdmf_series

    # Through the serial reader, so a frame is the same bits as the serial path's; the
    # steps before k cost one field array each (the geometry is read once).
    return next(itertools.islice(_read_xdmf_series(Path(path), scalars, component), k, None))[1]


def _load(source: Source, scalars: str | None, component: int | None) -> TetMesh:
    from tetvr.io.series import read_step
    from tetvr.io.meshfile import read

    if isinstance(source, TetMesh):
        return source
    if isinstance(source, tuple) and len(source) == 3:
        return _read_xdmf_step(str(source[1]), int(source[2]), scalars, component)
    if isinstance(source, tuple):
        return read_step(str(source[0]), int(source[1]), scalars, component=component)
    return read(source, scalars, component=component)


def _summary(source: Source, scalars: str | None, component: int | None) -> tuple[NDArray[np.float64], tuple[float, float]]:
    m = _load(source, scalars, component)
    return m.bounds, m.scalar_range


def _render_step(source: Source, camera: Camera, tf: TransferFunction, size: tuple[int, int],
                 settings: RenderSettings, scalars: str | None, component: int | None, output: str | None,
                 background: tuple[float, float, float] | None) -> Any:
    mesh = _load(source, scalars, component)
    image = worker_renderer(settings).render(mesh, camera, tf, size=size)
    if output is None:
        return image
    from tetvr.core.image import write_png

    write_png(image, output, background=background)  # atomic: no half-written PNG after a failure
    return output


def _frame_names(output: str | os.PathLike[str] | None, items: list[_Step]) -> list[str | None]:
    """Each step's PNG from the ``output`` pattern (None: no files), checked before the
    cluster starts: one name a step, no frame over a step's file, a folder to write in."""
    if output is None:
        return [None] * len(items)
    pattern = os.fspath(output)
    if len(items) > 1 and "{" not in pattern:
        raise ValueError(f"output must be a pattern with {{index}} or {{time}} for {len(items)} steps, "
                         f"got {pattern!r}")
    try:
        names = [pattern.format(index=i, time=s.time) for i, s in enumerate(items)]
    except (KeyError, IndexError, ValueError) as exc:
        raise ValueError(f"the output pattern {pattern!r} may use only {{index}} and {{time}} fields "
                         f"(e.g. 'frames/f_{{index:04d}}.png'): {exc!r}") from None
    if len(set(names)) != len(names):
        raise ValueError(f"the output pattern {pattern!r} gives two steps the same file name")
    outputs = [(f"frame of step {i}", name) for i, name in enumerate(names)]
    check_outputs(outputs, _step_inputs(items), by="render_series")
    for label, name in outputs:
        check_writable(name, label)
    return list(names)


class _Bounds:
    """What :meth:`Camera.fit` reads of a mesh: the union of the steps' bounds."""

    def __init__(self, bounds: NDArray[np.float64]) -> None:
        self.bounds = bounds


def render_series(
    steps: Any,
    *,
    camera: Camera | None = None,
    tf: TransferFunction | None = None,
    size: tuple[int, int] = (512, 512),
    settings: RenderSettings | None = None,
    scalars: str | None = None,
    component: int | None = None,
    output: str | os.PathLike[str] | None = None,
    background: tuple[float, float, float] | None = (1.0, 1.0, 1.0),
    client: Any = None,
    progress: bool = True,
) -> list[Any]:
    """Render every step of a series on a Dask cluster, one scene for all steps.

    Parameters
    ----------
    steps : a ``.pvd`` file or :class:`~tetvr.io.collections.Collection`, or a list of mesh
        files (each read on the worker that renders it) or of :class:`TetMesh` es.
    camera : default: fitted to the union of the steps' bounds.
    tf : default: :func:`tetvr.render.default_transfer_function` over the union of the
        steps' scalar ranges (a first pass on the cluster), so colours mean the same value
        in every frame.
    output : None to return the premultiplied float images; else a PNG name pattern with
        ``{index}`` and/or ``{time}`` (``"frames/f_{index:04d}.png"``), written on the
        workers, atomically; the names are returned. Before the cluster starts, a
        ``ValueError`` refuses a name that is one of the steps' files (or a link to one)
        and a ``PermissionError`` a folder that cannot be written (:mod:`tetvr.core.outputs`).
    client : see :func:`cluster_client`.
    progress : a tqdm bar over the finished frames.

    Returns
    -------
    The images (or file names), in step order.

    Examples
    --------
    >>> frames = render_series("run.pvd", size=(256, 256), output="f_{time}.png")  # doctest: +SKIP
    """
    from tqdm.auto import tqdm

    from tetvr.render import _tf_range

    items = series_sources(steps)
    settings = settings or RenderSettings()
    size = image_size(size)
    names = _frame_names(output, items)
    with cluster_client(client) as c:
        if camera is None or tf is None:
            got = gather(c, [c.submit(_summary, s.source, scalars, component, pure=False) for s in items],
                         "reading the steps' bounds and ranges")
            lo = np.min([b[0] for b, _ in got], axis=0)
            hi = np.max([b[1] for b, _ in got], axis=0)
            if camera is None:
                camera = Camera.fit(_Bounds(np.stack([lo, hi])))  # type: ignore[arg-type]
            if tf is None:
                s_lo, s_hi = _tf_range(min(r[0] for _, r in got), max(r[1] for _, r in got))
                tf = TransferFunction.preset("viridis", (s_lo, s_hi), opacity=0.5,
                                             unit_distance=default_unit_distance(np.stack([lo, hi])))
        futures = [c.submit(_render_step, s.source, camera, tf, size, settings, scalars, component, name, background,
                            pure=False)
                   for s, name in zip(items, names)]
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[Any] = [None] * len(futures)
        with tqdm(total=len(futures), disable=not progress, unit="frame", desc="tetvr") as bar:
            for fut in as_completed(c, futures, "rendering the steps"):
                results[index[fut.key]] = fut.result()  # a failed step raises here, naming its error
                bar.update(1)
    return results


def animate_series(scene: Any, steps: Any, out: str | os.PathLike[str], *, client: Any = None, fps: float = 12.0,
                   size: tuple[int, int] | None = None, progress: bool = True) -> list[Any]:
    """``tetvr animate``'s time series on a Dask cluster: every step of ``steps`` (see
    :func:`series_sources`) with the scene's camera, transfer function and settings, as
    PNG frames ``out/frame_0000.png``, ... written on the workers, atomically, or as one
    video (the frames gathered here, in order). Returns the files written."""
    from pathlib import Path

    from tetvr.io.video import VIDEO_SUFFIXES, check_frames_output, write_frames

    inputs = [("mesh file", p) for p in scene.input_paths()] + _step_inputs(series_sources(steps))
    out = check_frames_output(out, inputs, by="animate_series")
    kw = dict(camera=scene.camera, tf=scene.tf, size=tuple(size or scene.size), settings=scene.settings,
              scalars=scene.scalars, component=scene.component, client=client, progress=progress)
    if out.suffix.lower() in VIDEO_SUFFIXES:
        return write_frames(render_series(steps, **kw), out, background=scene.background, fps=fps)
    out.mkdir(parents=True, exist_ok=True)
    names = render_series(steps, output=str(out / "frame_{index:04d}.png"), background=scene.background, **kw)
    return [Path(n) for n in names]

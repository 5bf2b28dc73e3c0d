"""Rendering a time series on a Dask cluster, one task per step.

About this technique
--------------------
Each step is read on the worker that renders it (the client never parses the meshes) and
rendered with the one :class:`~tetvr.gl.Renderer` that worker keeps for the run
(:func:`tetvr.cluster.workers.worker_renderer`). The renderer is a pure function of (mesh,
camera, transfer function, settings), so a frame is the same bits wherever it was
rendered. A step is a mesh, a mesh file, a step of a ``.pvd`` collection or of an XDMF
time series (:func:`series_sources`); the cluster is ``dask.distributed``'s
(:func:`tetvr.cluster.workers.cluster_client`). No file system is shared
(:mod:`tetvr.cluster.inputs`): a step named by a path is read here as bytes and sent to its
worker, one named by a URL the worker fetches; PNG frames come back to be written here, or
go to the URL given. A video's frames stream (:func:`iter_series`): each is fetched from
its worker in step order as the encoder takes it, so the client holds one at a time.
Measured speed-ups: ``docs/distributed.md``.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Callable, Iterator, Literal, Sequence, Union

import numpy as np
from numpy.typing import NDArray

from tetvr.cluster.inputs import (Files, fetch_bytes, is_url, local_files, materialised, named_error, url_files,
                                  url_glob, url_leaf_files, url_pvd_steps, write_bytes)
from tetvr.cluster.workers import cluster_client, worker_renderer
from tetvr.core.camera import Camera
from tetvr.core.image import image_size
from tetvr.core.outputs import check_outputs, check_writable
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.transfer import TransferFunction, default_unit_distance
from tetvr.settings import RenderSettings

__all__ = ["Source", "animate_series", "iter_series", "render_series", "series_sources", "series_window"]

# A step: a mesh, a mesh file (a path or URL), (a .pvd, a step index) or ("xdmf", an XDMF file, a step index).
Source = Union[TetMesh, str, tuple[str, int], tuple[str, str, int]]
_XDMF = (".xdmf", ".xmf")
_GLOB = ("*", "?", "[")


@dataclasses.dataclass(frozen=True)
class _Step:
    source: Source
    time: float
    parts: tuple[str, ...] = ()  # a .pvd step's files


def series_sources(steps: Any) -> list[_Step]:
    """The steps of a series: a ``.pvd`` path or URL, or a
    :class:`~tetvr.io.collections.Collection` (its times), an XDMF time series (its times),
    a glob pattern (``"run/step_*.vtu"``, ``"s3://bucket/run/step_*.vtu"``: the files in
    natural order, ``s2`` before ``s10``), or a sequence of meshes, mesh files or URLs
    (time = index). Only the collection's own file is read here, never a mesh."""
    from tetvr.io.collections import Collection, read_pvd

    if isinstance(steps, (str, os.PathLike)):
        name = os.fspath(steps)
        url = is_url(name)
        if name.lower().endswith(".pvd"):
            if url:
                return [_Step((name, i), t, tuple(parts)) for i, (t, parts) in enumerate(url_pvd_steps(name))]
            steps = read_pvd(name)
        elif name.lower().endswith(_XDMF):
            where = name if url else os.path.abspath(name)
            return [_Step(("xdmf", where, k), t) for k, t in enumerate(_xdmf_times(name))]
        elif any(ch in name for ch in _GLOB) and (url or not os.path.exists(name)):
            import glob

            steps = sorted(url_glob(name) if url else glob.glob(name), key=_natural_key)
            if not steps:
                raise FileNotFoundError(f"no file matches {name!r}")
    if isinstance(steps, Collection):
        return [_Step((steps.path, i), s.time, s.files) for i, s in enumerate(steps.steps)]
    if isinstance(steps, (str, os.PathLike, TetMesh)):
        steps = [steps]
    out = []
    for i, s in enumerate(steps):
        if not isinstance(s, (TetMesh, str, os.PathLike)):
            raise TypeError(f"step {i} must be a TetMesh, a mesh file or a URL, got {type(s).__name__}")
        if isinstance(s, TetMesh):
            out.append(_Step(s, float(i)))
        else:
            out.append(_Step(os.fspath(s), float(i)))  # a path: read here, where it is relative to
    if not out:
        raise ValueError("the series is empty: give at least one mesh or file")
    return out


def _step_inputs(items: list[_Step]) -> list[tuple[str, str]]:
    """``(what, path)`` for every local file the steps read: what no frame may be written over."""
    from tetvr.io.collections import read_pvd
    from tetvr.io.series import series_input_paths, xdmf_data_files

    out: list[tuple[str, str]] = []
    seen: set[str] = set()
    for step in items:
        src = step.source
        if isinstance(src, TetMesh) or is_url(src if isinstance(src, str) else str(src[-2])):
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


def _xdmf_times(name: str) -> list[float]:
    """The time values of an XDMF time series (its XML only, no data; a URL's fetched here)."""
    import tempfile

    import meshio

    if is_url(name):
        with tempfile.TemporaryDirectory(prefix="tetvr-") as tmp:
            local = os.path.join(tmp, "series.xdmf")
            with open(local, "wb") as f:
                f.write(fetch_bytes(name))
            return _xdmf_times(local)
    if not os.path.isfile(name):
        raise FileNotFoundError(f"time series not found: {name}")
    reader = meshio.xdmf.TimeSeriesReader(name)
    times = []
    for k, grid in enumerate(reader.collection):
        t = grid.find("Time")
        times.append(float(t.get("Value")) if t is not None and t.get("Value") is not None else float(k))
    return times


def _xdmf_data_urls(url: str) -> list[str]:
    """The URLs of the HDF5 files an XDMF file at ``url`` names (beside it)."""
    import posixpath
    import tempfile

    from tetvr.io.series import xdmf_data_files

    with tempfile.TemporaryDirectory(prefix="tetvr-") as tmp:
        local = os.path.join(tmp, "series.xdmf")
        with open(local, "wb") as f:
            f.write(fetch_bytes(url))
        names = [os.path.relpath(p, tmp).replace(os.sep, "/") for p in xdmf_data_files(local)]
    head, _, path = url.rpartition("://")
    return [f"{head}://{posixpath.normpath(posixpath.join(posixpath.dirname(path), n))}" for n in names]


def _one_step_pvd(pvd: str, step: _Step, relpath: Callable[[str, str], str]) -> bytes:
    """A ``.pvd`` of ``step`` alone (its parts named relative to ``pvd``'s folder): what
    its worker reads, as the serial reader reads the step from the whole collection."""
    from xml.sax.saxutils import quoteattr

    folder = os.path.dirname(pvd) if not is_url(pvd) else pvd.rsplit("/", 1)[0]
    rows = "".join(f"<DataSet timestep={quoteattr(repr(step.time))} part=\"{k}\" "
                   f"file={quoteattr(relpath(p, folder))}/>" for k, p in enumerate(step.parts))
    return f'<?xml version="1.0"?><VTKFile type="Collection"><Collection>{rows}</Collection></VTKFile>'.encode()


def _step_files(step: _Step) -> tuple[Files | TetMesh, str, int]:
    """What the worker of ``step`` reads (a path's files read here as bytes; a URL's left
    to the worker), how (``"mesh"``, ``"pvd"``, ``"xdmf"``), and the step index in it."""
    import posixpath

    from tetvr.io.collections import is_collection, leaf_files
    from tetvr.io.series import xdmf_data_files

    src = step.source
    if isinstance(src, TetMesh):
        return src, "mesh", 0
    if isinstance(src, tuple) and len(src) == 3:
        path = str(src[1])
        if is_url(path):
            return url_files(path, _xdmf_data_urls(path)), "xdmf", int(src[2])
        return local_files(path, "time-series file", xdmf_data_files(path)), "xdmf", int(src[2])
    if isinstance(src, tuple):
        pvd = str(src[0])
        if is_url(pvd):
            rel = lambda p, folder: posixpath.relpath(p.rpartition("://")[2], folder.rpartition("://")[2])  # noqa: E731
            return url_files(pvd, step.parts, sent={pvd: _one_step_pvd(pvd, step, rel)}), "pvd", 0
        files = [g for p in step.parts for g in ([p] + (leaf_files(p) if is_collection(p) else []))]
        return (local_files(pvd, "collection file", files, replace={pvd: _one_step_pvd(pvd, step, os.path.relpath)}),
                "pvd", 0)
    if is_url(src):
        return url_files(src, url_leaf_files(src) if is_collection(src) else ()), "mesh", 0
    return local_files(src, "mesh file", leaf_files(src) if is_collection(src) else ()), "mesh", 0


def _load(source: Files | TetMesh, kind: str, index: int, scalars: str | None, component: int | None) -> TetMesh:
    """The step's mesh, read on this worker (:func:`tetvr.cluster.inputs.materialised`)."""
    from tetvr.io.meshfile import read
    from tetvr.io.series import read_step

    if isinstance(source, TetMesh):
        return source
    with materialised(source) as path:
        try:
            if kind == "xdmf":
                return _read_xdmf_step(path, index, scalars, component)
            if kind == "pvd":
                return read_step(path, index, scalars, component=component)
            return read(path, scalars, component=component)
        except Exception as exc:
            raise named_error(exc, source, path, "step") from exc


def _read_xdmf_step(path: str, k: int, scalars: str | None, component: int | None) -> TetMesh:
    """Step ``k`` of an XDMF time series, as :func:`tetvr.io.series.read_time_series` reads it."""
    import itertools
    from pathlib import Path

    from tetvr.io.series import _read_xdmf_series

    # Through the serial reader, so a frame is the same bits as the serial path's; the
    # steps before k cost one field array each (the geometry is read once).
    return next(itertools.islice(_read_xdmf_series(Path(path), scalars, component), k, None))[1]


def _summary(source: Files | TetMesh, kind: str, index: int, scalars: str | None, component: int | None
             ) -> tuple[NDArray[np.float64], tuple[float, float]]:
    m = _load(source, kind, index, scalars, component)
    return m.bounds, m.scalar_range


def _render_step(source: Files | TetMesh, kind: str, index: int, camera: Camera, tf: TransferFunction,
                 size: tuple[int, int], settings: RenderSettings, scalars: str | None, component: int | None,
                 encode: str, url: str | None, background: Sequence[float] | None) -> Any:
    """The step's image as ``encode`` says: ``"float"``, the premultiplied float image;
    ``"rgba8"``, 8-bit RGBA over ``background`` (:func:`~tetvr.core.image.to_rgba8`, a
    quarter of the bytes); ``"png"``, its PNG file, written by this worker to ``url``
    (which is returned), or its bytes (for the client to write)."""
    mesh = _load(source, kind, index, scalars, component)
    image = worker_renderer(settings).render(mesh, camera, tf, size=size)
    if encode == "float":
        return image
    from tetvr.core.image import png_bytes, to_rgba8

    if encode == "rgba8":
        return to_rgba8(image, background)
    data = png_bytes(image, background=background)
    return write_bytes(data, url) if url is not None else data


def _frame_names(output: str | os.PathLike[str] | None, items: list[_Step]) -> list[str | None]:
    """Each step's PNG from the ``output`` pattern (None: no files), checked before the
    cluster starts: one name a step; for paths (written here), no frame over a step's
    file and a folder to write in. A URL pattern names files the workers write."""
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
    if is_url(pattern):
        return list(names)
    outputs = [(f"frame of step {i}", name) for i, name in enumerate(names)]
    check_outputs(outputs, _step_inputs(items), by="render_series")
    for label, name in outputs:
        check_writable(name, label)
    return list(names)


class _Bounds:
    """What :meth:`Camera.fit` reads of a mesh: the union of the steps' bounds."""

    def __init__(self, bounds: NDArray[np.float64]) -> None:
        self.bounds = bounds


def _steps_done(c: Any, items: list[_Step], submit: Callable[[Any, str, int, int], Any], what: str, *,
                window: int | None = None, ordered: bool = False) -> Iterator[tuple[int, Any]]:
    """``(step, result)`` of each step as it is done (``ordered``: in step order),
    ``submit(files, kind, index, step)`` making its task (see :func:`_step_files`).

    At most ``window`` steps (default: two per worker) are in flight, and, ``ordered``,
    done and waiting on the workers for an earlier step: a result is fetched here only when
    it is yielded, so the client holds one at a time. A step named by a path is read here
    (and its bytes sent to a worker) only when its turn comes, so neither the client nor the
    workers hold the series. A step whose bytes or result were lost with a worker is sent
    again (twice at most); a step that fails raises, naming its error."""
    from concurrent.futures import CancelledError

    from tetvr.cluster.workers import as_completed, wait

    send = _StepSender(c, items, submit)
    window = window or max(2, 2 * len(c.nthreads()))
    todo = list(range(len(items)))[::-1]
    tries = [0] * len(items)
    pending: dict[Any, int] = {}
    done: dict[int, Any] = {}  # ordered: finished on a worker, waiting for an earlier step
    turn = 0  # ordered: the step to yield next

    def lost(i: int, exc: BaseException) -> None:
        tries[i] += 1
        if tries[i] > 2:
            raise exc
        send.shared.clear()
        todo.append(i)
        todo.sort(reverse=True)  # the earliest is sent first: the step ``turn`` never waits for a place

    while todo or pending or done:
        while todo and (len(pending) + len(done) < window or (ordered and todo[-1] == turn)):
            i = todo.pop()
            pending[send(i, tries[i])] = i
        if not pending and ordered and turn not in done:
            # (Were ``turn`` to send, the loop above would have sent it.) Nothing would move:
            # a bug, raised here rather than spinning for ever.
            raise RuntimeError(f"{what}: step {turn} is neither sent, nor done, nor to send")
        if pending:
            fut = next(as_completed(c, list(pending), what))
            i = pending.pop(fut)
            if ordered and fut.status == "finished":
                done[i] = fut  # its result stays on the worker until its turn
            else:  # a failed step raises now, not at its turn
                try:
                    value = fut.result()
                except CancelledError as exc:
                    lost(i, exc)
                else:
                    if ordered:  # finished again since (its worker was lost): its turn as the others'
                        done[i] = fut
                    else:
                        yield i, value
            fut = value = None  # no frame kept here while the next is awaited
        while ordered and turn in done:
            fut = done.pop(turn)
            wait(c, [fut], what)  # done, unless its worker died since and it runs again
            try:
                value = fut.result()
            except CancelledError as exc:
                lost(turn, exc)
                break
            fut = None
            yield turn, value
            value = None
            turn += 1


class _StepSender:
    """``send(i, tries)``: the task of step ``i``, its files read here (a path's) and
    scattered, or left to the worker (a URL's); an XDMF series' files are sent once for
    all its steps (``shared``, cleared when a worker that held them is lost)."""

    def __init__(self, c: Any, items: list[_Step], submit: Callable[[Any, str, int, int], Any]) -> None:
        self.c, self.items, self.submit = c, items, submit
        self.direct = True if c.direct_to_workers is None else bool(c.direct_to_workers)
        self.shared: dict[str, Any] = {}

    def __call__(self, i: int, tries: int) -> Any:
        src = self.items[i].source
        key = str(src[1]) if isinstance(src, tuple) and len(src) == 3 else None
        if key is not None and key in self.shared and tries == 0:
            files, kind, k = self.shared[key], "xdmf", int(src[2])  # type: ignore[index]
        else:
            files, kind, k = _step_files(self.items[i])
            if isinstance(files, Files) and files.sent:
                files = self.c.scatter(files, direct=self.direct, hash=False)
            if key is not None:
                self.shared[key] = files
        return self.submit(files, kind, k, i)


def _fitted(c: Any, items: list[_Step], camera: Camera | None, tf: TransferFunction | None, scalars: str | None,
            component: int | None) -> tuple[Camera, TransferFunction]:
    """``camera`` and ``tf``, each made where None from the steps' bounds and scalar
    ranges, reduced on the cluster (a first pass over the steps)."""
    from tetvr.render import _tf_range

    got = [r for _, r in sorted(_steps_done(
        c, items, lambda f, kind, k, _: c.submit(_summary, f, kind, k, scalars, component, pure=False),
        "reading the steps' bounds and ranges"), key=lambda x: x[0])]
    lo = np.min([b[0] for b, _ in got], axis=0)
    hi = np.max([b[1] for b, _ in got], axis=0)
    if camera is None:
        camera = Camera.fit(_Bounds(np.stack([lo, hi])))  # type: ignore[arg-type]
    if tf is None:
        s_lo, s_hi = _tf_range(min(r[0] for _, r in got), max(r[1] for _, r in got))
        tf = TransferFunction.preset("viridis", (s_lo, s_hi), opacity=0.5,
                                     unit_distance=default_unit_distance(np.stack([lo, hi])))
    return camera, tf


def series_window(window: int | None = None) -> int | None:
    """How many steps of a series may be in flight, or done and waiting for an earlier
    step, at once: ``window`` where given, else ``TETVR_SERIES_WINDOW`` where set, else
    None (two per worker, counted when the cluster is reached). It bounds the frames a
    streamed series (:func:`iter_series`, a video) holds on the workers; the client holds
    one at a time.

    Examples
    --------
    >>> series_window(3)
    3
    """
    if window is None:
        given = os.environ.get("TETVR_SERIES_WINDOW", "").strip()
        if not given:
            return None
        if not given.isdigit() or int(given) < 1:
            raise ValueError(f"TETVR_SERIES_WINDOW must be a positive integer (frames), got {given!r}")
        return int(given)
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)):
        raise TypeError(f"window must be a positive integer (frames) or None, got {window!r}")
    if window < 1:
        raise ValueError(f"window must be a positive integer (frames) or None, got {window!r}")
    return int(window)


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
    window: int | None = None,
) -> list[Any]:
    """Render every step of a series on a Dask cluster, one scene for all steps.

    Parameters
    ----------
    steps : a ``.pvd`` file or :class:`~tetvr.io.collections.Collection`, an XDMF time
        series, a glob pattern, or a list of mesh files or :class:`TetMesh` es. Files are
        paths on this machine (read here, their bytes sent to the workers) or URLs the
        workers read themselves (``s3://...``, ``file:///shared/...``;
        :mod:`tetvr.cluster.inputs`).
    camera : default: fitted to the union of the steps' bounds.
    tf : default: :func:`tetvr.render.default_transfer_function` over the union of the
        steps' scalar ranges (a first pass on the cluster), so colours mean the same value
        in every frame.
    output : None to return the premultiplied float images; else a PNG name pattern with
        ``{index}`` and/or ``{time}`` (``"frames/f_{index:04d}.png"``). The PNGs are encoded
        on the workers; a path pattern's files are written here, atomically, a URL
        pattern's (``"s3://bucket/frames/f_{index:04d}.png"``) by the workers; the names are
        returned. Before the cluster starts, a ``ValueError`` refuses a path that is one of
        the steps' files (or a link to one) and a ``PermissionError`` a folder that cannot
        be written (:mod:`tetvr.core.outputs`).
    client : see :func:`cluster_client`.
    progress : a tqdm bar over the finished frames.
    window : steps in flight at once (:func:`series_window`; default two per worker). A
        PNG is written as it arrives, so the client holds one at a time; the images
        (``output=None``) are all returned, so all held: :func:`iter_series` hands them
        over one by one instead.

    Returns
    -------
    The images (or file names), in step order.

    Examples
    --------
    >>> frames = render_series("run.pvd", size=(256, 256), output="f_{time}.png")  # doctest: +SKIP
    """
    from tqdm.auto import tqdm

    from tetvr.core.image import atomic_output

    items = series_sources(steps)
    settings = settings or RenderSettings()
    size = image_size(size)
    names = _frame_names(output, items)
    window = series_window(window)
    with cluster_client(client) as c:
        if camera is None or tf is None:
            camera, tf = _fitted(c, items, camera, tf, scalars, component)
        results: list[Any] = [None] * len(items)

        def submit(files: Any, kind: str, k: int, i: int) -> Any:
            url = names[i] if names[i] is not None and is_url(names[i]) else None
            return c.submit(_render_step, files, kind, k, camera, tf, size, settings, scalars, component,
                            "float" if names[i] is None else "png", url, background, pure=False)

        with tqdm(total=len(items), disable=not progress, unit="frame", desc="tetvr") as bar:
            for i, value in _steps_done(c, items, submit, "rendering the steps", window=window):
                name = names[i]
                if name is not None and not is_url(name):
                    with atomic_output(name) as f:  # the worker's PNG, written here
                        f.write(value)
                    value = name
                results[i] = value
                bar.update(1)
    return results


def iter_series(
    steps: Any,
    *,
    camera: Camera | None = None,
    tf: TransferFunction | None = None,
    size: tuple[int, int] = (512, 512),
    settings: RenderSettings | None = None,
    scalars: str | None = None,
    component: int | None = None,
    pixels: Literal["float", "rgba8"] = "float",
    background: Sequence[float] | None = (1.0, 1.0, 1.0),
    client: Any = None,
    progress: bool = True,
    window: int | None = None,
) -> Iterator[NDArray[Any]]:
    """The frames of :func:`render_series`, one at a time, in step order, as the cluster
    renders them: what a video's encoder takes, so that the client never holds the series.

    At most ``window`` steps (:func:`series_window`; default two per worker) are in flight
    or done and waiting on their workers for an earlier step; a frame is fetched from its
    worker when it is yielded, so the client holds the frame it hands over (and what the
    caller keeps). The cluster is reached, and the first pass that fits ``camera`` and
    ``tf`` where None is run, at the first frame asked for; the arguments are checked now.

    Parameters
    ----------
    pixels : ``"float"``, the premultiplied float RGBA images of :func:`render_series`;
        ``"rgba8"``, 8-bit straight RGBA composited over ``background`` on the workers
        (:func:`~tetvr.core.image.to_rgba8`: what a video stores, a quarter of the bytes).
    steps, camera, tf, size, settings, scalars, component, client, progress : as
        :func:`render_series`.

    Examples
    --------
    >>> from tetvr.io.video import write_frames
    >>> write_frames(iter_series("run.pvd", pixels="rgba8"), "run.mp4")  # doctest: +SKIP
    """
    if pixels not in ("float", "rgba8"):
        raise ValueError(f"pixels must be 'float' or 'rgba8', got {pixels!r}")
    items = series_sources(steps)
    return _stream(items, camera, tf, image_size(size), settings or RenderSettings(), scalars, component, pixels,
                   background, client, progress, series_window(window))


def _stream(items: list[_Step], camera: Camera | None, tf: TransferFunction | None, size: tuple[int, int],
            settings: RenderSettings, scalars: str | None, component: int | None, pixels: str,
            background: Sequence[float] | None, client: Any, progress: bool, window: int | None
            ) -> Iterator[NDArray[Any]]:
    from tqdm.auto import tqdm

    with cluster_client(client) as c:
        if camera is None or tf is None:
            camera, tf = _fitted(c, items, camera, tf, scalars, component)

        def submit(files: Any, kind: str, k: int, i: int) -> Any:
            return c.submit(_render_step, files, kind, k, camera, tf, size, settings, scalars, component, pixels,
                            None, background, pure=False)

        with tqdm(total=len(items), disable=not progress, unit="frame", desc="tetvr") as bar:
            for _, image in _steps_done(c, items, submit, "rendering the steps", window=window, ordered=True):
                bar.update(1)
                yield image
                image = None  # noqa: F841 - not held while the next frame is awaited


def animate_series(scene: Any, steps: Any, out: str | os.PathLike[str], *, client: Any = None, fps: float = 12.0,
                   size: tuple[int, int] | None = None, progress: bool = True, window: int | None = None) -> list[Any]:
    """``tetvr animate``'s time series on a Dask cluster: every step of ``steps`` (see
    :func:`series_sources`) with the scene's camera, transfer function and settings, as
    PNG frames ``out/frame_0000.png``, ... (encoded on the workers, written here,
    atomically, as each arrives), or as one video (8-bit frames made on the workers, handed
    to the encoder one by one in step order: :func:`iter_series`). ``window``: see
    :func:`series_window`. Returns the files written."""
    from pathlib import Path

    from tetvr.io.video import VIDEO_SUFFIXES, check_frames_output, video_background, write_frames

    inputs = [("mesh file", p) for p in scene.input_paths()] + _step_inputs(series_sources(steps))
    out = check_frames_output(out, inputs, by="animate_series")
    kw = dict(camera=scene.camera, tf=scene.tf, size=tuple(size or scene.size), settings=scene.settings,
              scalars=scene.scalars, component=scene.component, client=client, progress=progress, window=window)
    if out.suffix.lower() in VIDEO_SUFFIXES:
        frames = iter_series(steps, pixels="rgba8", background=video_background(out, scene.background), **kw)
        return write_frames(frames, out, background=scene.background, fps=fps)
    out.mkdir(parents=True, exist_ok=True)
    names = render_series(steps, output=str(out / "frame_{index:04d}.png"), background=scene.background, **kw)
    return [Path(n) for n in names]

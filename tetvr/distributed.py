"""Rendering on a Dask cluster: time steps in parallel, and one mesh as sort-last bricks.

About this technique
--------------------
Two ways to use more than one process, both on ``dask.distributed`` (pip install
"tetvr[dask]"), so one code path runs on a laptop (a :class:`~distributed.LocalCluster`),
a cluster or an HPC batch system (dask-jobqueue):

* **Time series** (:func:`render_series`): one task per step; each worker reads its own
  step (the client never loads the meshes) and renders it with the one
  :class:`~tetvr.gl.Renderer` that worker keeps for the run (:func:`worker_renderer`).
  The renderer is a pure function of (mesh, camera, transfer function, settings), so a
  frame is the same bits wherever it was rendered.
* **Sort-last bricks** (:func:`render_bricks`, :func:`render_pieces`; the bricks
  themselves are :mod:`tetvr.bricks`): a k-d tree of axis-aligned planes splits the mesh
  into bricks, each worker holds its bricks (:class:`ClusterBricks`) and renders them to
  premultiplied float images with the shared camera, transfer function, table and float32
  origin, and the client composites them "over" in the tree's visibility order.
  A mesh held here is split here and its bricks sent (:func:`distribute_mesh`); a mesh in
  solver pieces (a ``.pvtu``) is read and redistributed into bricks on the workers
  (:func:`distribute_pieces`), the client holding only a sample of its cells.

Where the composite is exact, and what it costs: ``docs/distributed.md``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import threading
import warnings
from typing import Any, Iterator, Union

import numpy as np
from numpy.typing import NDArray

from .camera import Camera
from .image import image_size
from .mesh import TetMesh
from .settings import RenderSettings
from .bricks import (Brick, BrickTree, Part, Split, Whole, _check_n_bricks, clip_to_box, composite_over, kd_bricks,
                     leaf_boxes, leaf_paths, merge_parts, part_mesh, plan_bricks, select_cells, visibility_order)
from .transfer import TransferFunction, default_unit_distance

__all__ = ["ClusterBricks", "distribute_mesh", "distribute_pieces", "render_bricks", "render_pieces", "render_series",
           "series_sources", "cluster_client", "worker_renderer",
           # the bricks themselves (tetvr.bricks), here too for one import
           "Brick", "BrickTree", "Split", "Whole", "kd_bricks", "visibility_order", "composite_over"]

_EXTRA = 'tetvr.distributed needs dask.distributed: pip install "tetvr[dask]"'


def _dask() -> Any:
    try:
        import distributed
    except ImportError as exc:
        raise ImportError(f"{_EXTRA} ({exc})") from exc
    return distributed


# ---- the cluster ----

@contextlib.contextmanager
def cluster_client(client: Any = None, *, n_workers: int | None = None) -> Iterator[Any]:
    """A ``distributed.Client`` for the duration of the block.

    ``client``: a ``Client`` (used as is, left open), a scheduler address
    (``"tcp://host:8786"``), or None: the ``TETVR_SCHEDULER`` environment variable's
    address, else an in-process ``LocalCluster`` of ``n_workers`` worker processes (default:
    the CPU count, at most 4), one thread each, started by *spawn*: a worker forked from a
    process holding a GL context could not make its own (tetvr raises ForkedProcessError).
    """
    distributed = _dask()
    if isinstance(client, distributed.Client):
        yield client
        return
    address = client if client is not None else os.environ.get("TETVR_SCHEDULER") or None
    if address is not None:
        if not isinstance(address, str):
            raise TypeError(f"client must be a distributed.Client, a scheduler address or None, got {client!r}")
        with distributed.Client(address) as c:
            yield c
        return
    import dask

    n = n_workers or min(os.cpu_count() or 1, 4)
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers: every large temporary
    # array of a frame is then unmapped and faulted in again (measured: the first frame of a
    # 48k-tet step 0.65-0.75 s in a worker, 0.33-0.44 s with glibc's default).
    with dask.config.set({"distributed.worker.multiprocessing-method": "spawn",
                          "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
        with distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                                      silence_logs=logging.ERROR) as cluster, distributed.Client(cluster) as c:
            yield c


# One renderer per worker process and settings, kept across tasks: one GL context, its
# shaders, tables and mesh buffers, never one per frame.
_RENDERERS: dict[RenderSettings, Any] = {}
_RENDERERS_LOCK = threading.Lock()


def worker_renderer(settings: RenderSettings | None = None) -> Any:
    """This process's :class:`~tetvr.gl.Renderer` for ``settings``, made on first use."""
    from .gl.renderer import Renderer

    settings = settings or RenderSettings()
    with _RENDERERS_LOCK:
        r = _RENDERERS.get(settings)
        if r is None:
            r = _RENDERERS[settings] = Renderer(settings)
        return r


# ---- time series ----

# A step: a mesh, a mesh file, (a .pvd, a step index) or ("xdmf", an XDMF file, a step index).
Source = Union[TetMesh, str, tuple[str, int], tuple[str, str, int]]
_XDMF = (".xdmf", ".xmf")
_GLOB = ("*", "?", "[")


@dataclasses.dataclass(frozen=True)
class _Step:
    source: Source
    time: float


def series_sources(steps: Any) -> list[_Step]:
    """The steps of a series: a ``.pvd`` path or :class:`~tetvr.collections.Collection`
    (its times), an XDMF time series (its times), a glob pattern (``"run/step_*.vtu"``,
    the files in natural order: ``s2`` before ``s10``), or a sequence of meshes or mesh
    files (time = index). Only the collection's own file is read here, never a mesh."""
    from .collections import Collection, read_pvd

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
    """Step ``k`` of an XDMF time series, as :func:`tetvr.animate.read_time_series` reads it."""
    import itertools
    from pathlib import Path

    from .animate import _read_xdmf_series

    # Through the serial reader, so a frame is the same bits as the serial path's; the
    # steps before k cost one field array each (the geometry is read once).
    return next(itertools.islice(_read_xdmf_series(Path(path), scalars, component), k, None))[1]


def _load(source: Source, scalars: str | None, component: int | None) -> TetMesh:
    from .collections import read_step
    from .mesh import read

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
    from .image import write_png

    write_png(image, output, background=background)  # atomic: no half-written PNG after a failure
    return output


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
    steps : a ``.pvd`` file or :class:`~tetvr.collections.Collection`, or a list of mesh
        files (each read on the worker that renders it) or of :class:`TetMesh` es.
    camera : default: fitted to the union of the steps' bounds.
    tf : default: :func:`tetvr.render.default_transfer_function` over the union of the
        steps' scalar ranges (a first pass on the cluster), so colours mean the same value
        in every frame.
    output : None to return the premultiplied float images; else a PNG name pattern with
        ``{index}`` and/or ``{time}`` (``"frames/f_{index:04d}.png"``), written on the
        workers, atomically; the names are returned.
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

    from .render import _tf_range

    distributed = _dask()
    items = series_sources(steps)
    settings = settings or RenderSettings()
    size = image_size(size)
    names: list[str | None] = [None] * len(items)
    if output is not None:
        pattern = os.fspath(output)
        if len(items) > 1 and "{" not in pattern:
            raise ValueError(f"output must be a pattern with {{index}} or {{time}} for {len(items)} steps, "
                             f"got {pattern!r}")
        names = [pattern.format(index=i, time=s.time) for i, s in enumerate(items)]
        if len(set(names)) != len(names):
            raise ValueError(f"the output pattern {pattern!r} gives two steps the same file name")
    with cluster_client(client) as c:
        if camera is None or tf is None:
            got = c.gather([c.submit(_summary, s.source, scalars, component, pure=False) for s in items])
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
            for fut in distributed.as_completed(futures):
                results[index[fut.key]] = fut.result()  # a failed step raises here, naming its error
                bar.update(1)
    return results


# ---- sort-last bricks ----

def _render_brick(brick: TetMesh, index: int, label: str, camera: Camera, tf: TransferFunction,
                  size: tuple[int, int], settings: RenderSettings) -> NDArray[np.float32]:
    try:
        return worker_renderer(settings).render(brick, camera, tf, size=size)
    except Exception as exc:
        # Named, so that a failed frame says which brick (and which pieces) it was.
        raise RuntimeError(f"brick {index} ({label}) could not be rendered: {exc}") from exc


def _hold(brick: TetMesh) -> TetMesh:
    return brick


def _brick_facts(brick: TetMesh) -> tuple[int, bool]:
    """A brick's cell count and whether it is tangled (folded faces), which "auto" reads."""
    from .marching import folded_faces

    return brick.n_tets, folded_faces(brick) > 0


class ClusterBricks:
    """One mesh as k-d bricks (:mod:`tetvr.bricks`) held by a cluster's workers, each
    worker only its bricks; :meth:`render` renders a view on the workers and composites
    it on the client. Made by :func:`distribute_mesh` or :func:`distribute_pieces`.

    Attributes
    ----------
    root : the k-d tree (its planes order the bricks for each view).
    whole : what the bricks share with the whole mesh (:class:`tetvr.bricks.Whole`).
    labels : each brick's name in error messages (the pieces it came from).
    brick_tets : each brick's cell count (cut pieces included).
    tangled : whether any brick has folded faces (:func:`tetvr.marching.folded_faces`).
    """

    def __init__(self, client: Any, futures: dict[int, Any], root: "Split | Brick", whole: Whole,
                 labels: dict[int, str]) -> None:
        self.client = client
        self.futures = futures
        self.root = root
        self.whole = whole
        self.labels = labels
        # Counted and checked on the workers, where the bricks are.
        facts = dict(zip(futures, client.gather([client.submit(_brick_facts, f, pure=False)
                                                 for f in futures.values()])))
        self.brick_tets = {i: n for i, (n, _) in facts.items()}
        self.tangled = any(t for _, t in facts.values())

    @property
    def n_bricks(self) -> int:
        return len(self.futures)

    def settings_for(self, settings: RenderSettings, camera: Camera, size: tuple[int, int]) -> RenderSettings:
        """``settings`` with ``method="auto"`` resolved once for every brick (a brick alone
        could choose another): tet marching wherever it can render the bricks, projected
        tetrahedra only for settings only they implement
        (:data:`tetvr.method.PROJECTED_ONLY`), a tangled mesh, or a brick above
        :data:`tetvr.method.AUTO_MAX_TETS` cells (memory: the limit is per brick, as a
        worker renders one brick at a time). Unlike a single mesh, bricks never take
        projected tetrahedra for speed: the planes' cuts make new faces, and projected
        tetrahedra err on isolated pixels where a ray grazes a face seen edge-on
        (docs/distributed.md, "Where the composite is exact"). ``camera`` and ``size`` do
        not enter the choice."""
        from .method import AUTO_MAX_TETS, choose

        if settings.method != "auto":
            return settings
        method = choose(settings)  # what the settings alone decide
        if method == "raymarch" and (self.tangled or max(self.brick_tets.values(), default=0) > AUTO_MAX_TETS):
            method = "projected"
        return dataclasses.replace(settings, method=method)  # type: ignore[arg-type]

    def render(self, camera: Camera, tf: TransferFunction, *, size: tuple[int, int] = (512, 512),
               settings: RenderSettings | None = None) -> NDArray[np.float32]:
        """The (height, width, 4) premultiplied float32 image of the whole mesh."""
        size = image_size(size)
        settings = self.settings_for(settings or RenderSettings(), camera, size)
        c = self.client
        futures = {i: c.submit(_render_brick, f, i, self.labels[i], camera, tf, size, settings, pure=False)
                   for i, f in self.futures.items()}
        images = dict(zip(futures, c.gather(list(futures.values()))))
        return composite_over([images[i] for i in visibility_order(self.root, camera)])

    def release(self) -> None:
        """Let the workers drop the bricks."""
        for f in self.futures.values():
            f.release()
        self.futures = {}


def distribute_mesh(mesh: TetMesh, n_bricks: int, client: Any, *, tree: BrickTree | None = None) -> ClusterBricks:
    """Split ``mesh`` (held here) into ``n_bricks`` k-d bricks (:func:`tetvr.bricks.kd_bricks`)
    and hand them to the workers of ``client`` (a ``distributed.Client``)."""
    tree = tree if tree is not None else kd_bricks(mesh, n_bricks)
    if tree.mesh is not mesh:
        raise ValueError("tree was split from another mesh")
    if len(tree.bricks()) != n_bricks:
        raise ValueError(f"tree has {len(tree.bricks())} bricks, n_bricks is {n_bricks}")
    if not tree.separable:
        warnings.warn("some k-d split planes run through cells (kd_bricks(cut=False)): the composite is "
                      "approximate within a cell's width of those planes", stacklevel=3)
    # Each brick travels inside its task (not scattered): a worker that dies loses no
    # data, the scheduler reruns the task elsewhere. Dask warns of such large tasks; here
    # they are the point (a mesh too large for that is one for distribute_pieces).
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Sending large graph")
        futures = {b.index: client.submit(_hold, tree.brick_mesh(b), pure=False) for b in tree.bricks()}
    labels = {i: f"{len(tree.bricks())} k-d bricks of the mesh" for i in futures}
    return ClusterBricks(client, futures, tree.root, tree.whole, labels)


def render_bricks(
    mesh: TetMesh,
    camera: Camera,
    tf: TransferFunction,
    *,
    n_bricks: int,
    size: tuple[int, int] = (512, 512),
    settings: RenderSettings | None = None,
    client: Any = None,
    tree: BrickTree | None = None,
) -> NDArray[np.float32]:
    """Render ``mesh`` as ``n_bricks`` k-d bricks (:func:`tetvr.bricks.kd_bricks`) on the
    cluster's workers and composite them "over" on the client in visibility order. For
    several views, keep the bricks on the workers: :func:`distribute_mesh`.

    Returns the (height, width, 4) premultiplied float32 image.

    Examples
    --------
    >>> image = render_bricks(mesh, camera, tf, n_bricks=4, size=(256, 256))  # doctest: +SKIP
    """
    with cluster_client(client) as c:
        bricks = distribute_mesh(mesh, n_bricks, c, tree=tree)
        try:
            return bricks.render(camera, tf, size=size, settings=settings)
        finally:
            bricks.release()


# ---- solver pieces, redistributed into k-d bricks on the workers ----

def _read_piece(path: str, scalars: str | None, component: int | None) -> TetMesh:
    from .mesh import read

    try:
        return read(path, scalars, component=component)
    except Exception as exc:
        raise ValueError(f"piece {path!r} could not be read: {exc}") from exc


def _piece_summary(piece: TetMesh, n_segments: int) -> dict[str, Any]:
    from .tablesize import sample_segments

    seg = sample_segments(piece, n_segments)
    return {"n_tets": piece.n_tets, "bounds": piece.bounds, "scalar_range": piece.scalar_range,
            "max_edge": piece.max_edge, "segments": seg, "scalar_name": piece.scalar_name,
            "cell_data": piece.cell_data}


def _piece_sample(piece: TetMesh, k: int) -> NDArray[np.float64]:
    ids = np.linspace(0, piece.n_tets - 1, max(1, min(k, piece.n_tets))).round().astype(np.int64)
    return piece.points[piece.tets[ids]]


def _piece_part(piece: TetMesh, box: NDArray[np.float64]) -> Part:
    return select_cells(piece, box)


def _assemble_brick(index: int, label: str, path: list[tuple[int, float, bool]], whole: Whole, scalar_name: str,
                    *parts: Part) -> TetMesh:
    part, _ = clip_to_box(merge_parts(parts), path)
    if len(part.tets) == 0:
        raise ValueError(f"brick {index} ({label}) holds no cells: fewer bricks, or a larger sample")
    return part_mesh(part.points, part.tets, part.scalars, whole, scalar_name=scalar_name, cell_scalars=part.cells)


def _combined_sample(summaries: list[dict[str, Any]]) -> Any:
    """The pieces' segment samples as one, each piece weighted by its share of the cells."""
    from .tablesize import SegmentSample

    total = sum(s["n_tets"] for s in summaries)
    segs = [s["segments"] for s in summaries]
    w = np.concatenate([g.weight * (s["n_tets"] / total) for g, s in zip(segs, summaries)])
    return SegmentSample(front=np.concatenate([g.front for g in segs]), back=np.concatenate([g.back for g in segs]),
                         length=np.concatenate([g.length for g in segs]), weight=w / w.sum())


def distribute_pieces(pieces: Any, n_bricks: int, client: Any, *, scalars: str | None = None,
                      component: int | None = None, sample: int = 20_000) -> ClusterBricks:
    """Read a mesh's solver pieces on the workers and redistribute them into ``n_bricks``
    k-d bricks there; the client holds only a sample of the cells.

    ``pieces``: a ``.pvtu`` (or ``.vtm``) file, or a list of mesh files that together make
    one mesh (points on the pieces' shared faces with equal coordinates are joined). Solver
    partitions are not convex and cannot be ordered as wholes; the bricks are boxes
    (ParaView's ``vtkRedistributeDataSet`` before IceT does the same).

    1. each piece is read on a worker (a piece that cannot be read fails naming its file);
       its summary (bounds, scalar range, longest edge, a segment sample) and a sample of
       ``sample`` cells in all, drawn evenly, come back;
    2. the k-d planes are chosen on the sample (:func:`tetvr.bricks.plan_bricks`);
    3. each piece sends every brick the cells that overlap its box; the brick's worker
       joins them and cuts them at its box's planes (:func:`tetvr.bricks.clip_to_box`).

    Examples
    --------
    >>> with cluster_client() as c:                                      # doctest: +SKIP
    ...     bricks = distribute_pieces("run_0042.pvtu", 8, c)
    ...     image = bricks.render(camera, tf, size=(1024, 1024))
    """
    from .collections import pieces as piece_files
    from .tablesize import _N_SEGMENTS

    if isinstance(pieces, (str, os.PathLike)):
        files = [os.path.abspath(f) for f in piece_files(pieces)]
    else:
        files = [os.path.abspath(os.fspath(f)) for f in pieces]
    if not files:
        raise ValueError("no pieces given")
    read = [client.submit(_read_piece, f, scalars, component, pure=False) for f in files]
    per_piece = max(256, _N_SEGMENTS // len(files))
    summaries = client.gather([client.submit(_piece_summary, r, per_piece, pure=False) for r in read])
    total = sum(s["n_tets"] for s in summaries)
    _check_n_bricks(n_bricks, total)
    kinds = {(s["scalar_name"], s["cell_data"]) for s in summaries}
    if len(kinds) > 1:
        raise ValueError("the pieces do not carry one field: " + ", ".join(
            f"{os.path.basename(f)}: {s['scalar_name']!r} ({'cell' if s['cell_data'] else 'point'} data)"
            for f, s in zip(files, summaries)))
    corners = np.concatenate(client.gather([
        client.submit(_piece_sample, r, max(1, -(-sample * s["n_tets"] // total)), pure=False)
        for r, s in zip(read, summaries)]))
    bounds = np.stack([np.min([s["bounds"][0] for s in summaries], axis=0),
                       np.max([s["bounds"][1] for s in summaries], axis=0)])
    whole = Whole(bounds=bounds, float32_origin=bounds.mean(axis=0),
                  scalar_range=(min(s["scalar_range"][0] for s in summaries),
                                max(s["scalar_range"][1] for s in summaries)),
                  max_edge=max(s["max_edge"] for s in summaries), segment_sample=_combined_sample(summaries),
                  n_tets=total)
    root = plan_bricks(corners, n_bricks)
    boxes = leaf_boxes(root, bounds)
    paths = leaf_paths(root)
    name = summaries[0]["scalar_name"]
    futures, labels = {}, {}
    for i, box in boxes.items():
        # A piece's cells may overlap the box's bounds but not its inside: such a piece
        # sends nothing useful, and is named anyway (the label says where cells came from).
        pieces_in = [k for k, s in enumerate(summaries)
                     if np.all(s["bounds"][0] < box[1]) and np.all(s["bounds"][1] > box[0])]
        labels[i] = "pieces " + ", ".join(os.path.basename(files[k]) for k in pieces_in)
        parts = [client.submit(_piece_part, read[k], box, pure=False) for k in pieces_in]
        futures[i] = client.submit(_assemble_brick, i, labels[i], paths[i], whole, name, *parts, pure=False)
    # Made (and any error raised, naming its piece) before the pieces go; waited for, not
    # gathered: the bricks stay on the workers.
    _dask().wait(list(futures.values()))
    for f in futures.values():
        if f.status == "error":
            f.result()
    del read
    return ClusterBricks(client, futures, root, whole, labels)


def render_pieces(
    pieces: Any,
    camera: Camera,
    tf: TransferFunction,
    *,
    n_bricks: int,
    size: tuple[int, int] = (512, 512),
    settings: RenderSettings | None = None,
    scalars: str | None = None,
    component: int | None = None,
    client: Any = None,
) -> NDArray[np.float32]:
    """Render a mesh given as solver pieces (a ``.pvtu``, or a list of files) as
    ``n_bricks`` k-d bricks on the cluster (:func:`distribute_pieces`); the client never
    reads the mesh.

    Examples
    --------
    >>> image = render_pieces("run_0042.pvtu", camera, tf, n_bricks=8)  # doctest: +SKIP
    """
    with cluster_client(client) as c:
        bricks = distribute_pieces(pieces, n_bricks, c, scalars=scalars, component=component)
        try:
            return bricks.render(camera, tf, size=size, settings=settings)
        finally:
            bricks.release()


def animate_series(scene: Any, steps: Any, out: str | os.PathLike[str], *, client: Any = None, fps: float = 12.0,
                   size: tuple[int, int] | None = None, progress: bool = True) -> list[Any]:
    """``tetvr animate``'s time series on a Dask cluster: every step of ``steps`` (see
    :func:`series_sources`) with the scene's camera, transfer function and settings, as
    PNG frames ``out/frame_0000.png``, ... written on the workers, atomically, or as one
    video (the frames gathered here, in order). Returns the files written."""
    from pathlib import Path

    from .animate import VIDEO_SUFFIXES, write_frames

    out = Path(out)
    kw = dict(camera=scene.camera, tf=scene.tf, size=tuple(size or scene.size), settings=scene.settings,
              scalars=scene.scalars, component=scene.component, client=client, progress=progress)
    if out.suffix.lower() in VIDEO_SUFFIXES:
        return write_frames(render_series(steps, **kw), out, background=scene.background, fps=fps)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} exists and is not a folder; give a folder for PNG frames or a video file "
                         f"({', '.join(VIDEO_SUFFIXES)})")
    out.mkdir(parents=True, exist_ok=True)
    names = render_series(steps, output=str(out / "frame_{index:04d}.png"), background=scene.background, **kw)
    return [Path(n) for n in names]

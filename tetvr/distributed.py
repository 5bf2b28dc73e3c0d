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
* **Sort-last bricks** (:func:`render_bricks`; Molnar et al. 1994, "A sorting
  classification of parallel rendering"): a k-d tree of axis-aligned planes splits the
  mesh into bricks (:func:`kd_bricks`), each worker renders one brick to a premultiplied
  float image with the shared camera, transfer function and table (each brick keeps the
  whole mesh's points, so its float32 origin, scalar range and table are the whole's), and
  the client composites them "over" in the tree's visibility order. Two bricks on either
  side of a plane are crossed in the same order by every ray — the side of the plane the
  eye is on first (in parallel projection: the side the view direction comes from) — so
  the order is exact for any camera, inside the mesh included, as long as no cell reaches
  across a plane.

Where the composite is exact
----------------------------
:func:`kd_bricks` puts a plane where no cell straddles it when one lies near the median
(a grid's face, a block boundary): the bricks hold the mesh's own cells, and the composite
equals the single-process image to float32 rounding (measured <= 2.4e-7, both methods,
``tests/test_distributed.py``). Elsewhere it cuts the straddling cells at the plane into
conforming tets on either side (the field is linear on a tet, so the pieces carry it
exactly): the CPU reference's composite then equals its whole image to float32 rounding,
but the GPU's pre-integration table is looked up per segment, and a ray's segment cut in
two is looked up twice, so the GPU composite differs from the GPU whole image by the
table's own error (measured 2e-5..8e-5 on a rotated grid; as close to or closer to the
reference than the whole image). Cells assigned to a side by centroid instead
(``cut=False``) leave jagged boundaries that rays can cross back and forth: errors up to
~0.1 (``docs/distributed.md``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import threading
import warnings
from typing import Any, Iterator, Sequence, Union

import numpy as np
from numpy.typing import NDArray

from .camera import Camera
from .image import image_size
from .mesh import TetMesh
from .settings import RenderSettings
from .transfer import TransferFunction

__all__ = ["Brick", "BrickTree", "Split", "kd_bricks", "visibility_order", "composite_over", "render_bricks", "render_series",
           "series_sources", "cluster_client", "worker_renderer"]

_EXTRA = 'tetvr.distributed needs dask.distributed: pip install "tetvr[dask]"'
#: A split plane whose straddle-free position is this far (as a fraction of the node's cells)
#: from the balanced rank is not taken; the centroid median is, unseparated.
SEPARABLE_IMBALANCE = 0.25
# A cutting plane goes in the widest gap between vertex coordinates among this many on
# either side of the median centroid.
_GAP_WINDOW = 32


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

# A step: a mesh, a mesh file, or (a .pvd, a step index).
Source = Union[TetMesh, str, tuple[str, int]]


@dataclasses.dataclass(frozen=True)
class _Step:
    source: Source
    time: float


def series_sources(steps: Any) -> list[_Step]:
    """The steps of a series: a ``.pvd`` path or :class:`~tetvr.collections.Collection`
    (its times), or a sequence of meshes or mesh files (time = index)."""
    from .collections import Collection, read_pvd

    if isinstance(steps, (str, os.PathLike)) and os.fspath(steps).lower().endswith(".pvd"):
        steps = read_pvd(steps)
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


def _load(source: Source, scalars: str | None, component: int | None) -> TetMesh:
    from .collections import read_step
    from .mesh import read

    if isinstance(source, TetMesh):
        return source
    if isinstance(source, tuple):
        return read_step(source[0], source[1], scalars, component=component)
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
                diag = float(np.linalg.norm(hi - lo))
                tf = TransferFunction.preset("viridis", (s_lo, s_hi), opacity=0.5, unit_distance=max(diag / 20, 1e-30))
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

@dataclasses.dataclass(frozen=True, eq=False)
class Brick:
    """A leaf of the k-d tree: its tets, as ids of the tree's points."""

    index: int
    tets: NDArray[np.int64]


@dataclasses.dataclass(frozen=True, eq=False)
class Split:
    """A node: what lies below ``plane`` on ``axis`` goes to ``low``, the rest to ``high``.
    ``n_cut``: cells cut in two at the plane; ``separable``: no cell reaches across the
    plane (true when every straddling cell was cut), so the two sides composite exactly in
    plane order."""

    axis: int
    plane: float
    low: "Brick | Split"
    high: "Brick | Split"
    n_cut: int
    separable: bool

    def bricks(self) -> list[Brick]:
        return [b for side in (self.low, self.high) for b in (side.bricks() if isinstance(side, Split) else [side])]


@dataclasses.dataclass(frozen=True, eq=False)
class BrickTree:
    """A mesh split into bricks (:func:`kd_bricks`): the tree, and the points and scalars
    its bricks index (the mesh's own, then the points made where planes cut cells)."""

    root: "Split | Brick"
    points: NDArray[np.float64]
    scalars: NDArray[np.float64]
    mesh: TetMesh

    def bricks(self) -> list[Brick]:
        return self.root.bricks() if isinstance(self.root, Split) else [self.root]

    @property
    def separable(self) -> bool:
        return _all_separable(self.root)

    @property
    def n_cut(self) -> int:
        return _count_cut(self.root)

    def brick_mesh(self, brick: Brick) -> TetMesh:
        """One brick as a mesh that renders like a part of the whole: it keeps every point
        (so its bounds, float32 origin and scalar range are the whole mesh's) and the
        whole mesh's longest edge and segment sample, which size the table."""
        from .tablesize import segment_sample

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # slivers of a cut below the flatness bound: dropped
            sub = TetMesh.from_arrays(self.points, brick.tets, self.scalars, scalar_name=self.mesh.scalar_name)
        object.__setattr__(sub, "max_edge", self.mesh.max_edge)
        object.__setattr__(sub, "_segment_sample", segment_sample(self.mesh))
        return sub

    def visibility_order(self, camera: Camera) -> list[int]:
        return visibility_order(self.root, camera)


def kd_bricks(mesh: TetMesh, n_bricks: int, *, cut: bool = True) -> BrickTree:
    """Split ``mesh`` into ``n_bricks`` bricks by a k-d tree of axis-aligned planes.

    Each plane balances the bricks' cell counts. It moves to the nearest plane no cell
    straddles when one lies within :data:`SEPARABLE_IMBALANCE` of the node's cells (on the
    longest axis of the node's centroids, else another): a grid's face, a block boundary.
    Where there is none it crosses the longest axis at the median centroid (nudged off
    the vertices) and, with ``cut``, the cells it crosses are cut there into tets on
    either side (the field is linear on a tet, so the pieces carry it exactly; the pieces
    conform, :func:`tetvr.cells.split_cells`), so every brick is a box of the mesh. Without
    ``cut`` they are assigned by centroid and the split is not separable.

    Examples
    --------
    >>> from tetvr import synthetic
    >>> tree = kd_bricks(synthetic.cube(4, rotate=False), 4)
    >>> [len(b.tets) for b in tree.bricks()], tree.separable, tree.n_cut
    ([96, 96, 96, 96], True, 0)
    """
    if isinstance(n_bricks, bool) or not isinstance(n_bricks, (int, np.integer)) or n_bricks < 1:
        raise ValueError(f"n_bricks must be a positive integer, got {n_bricks!r}")
    if n_bricks > mesh.n_tets:
        raise ValueError(f"n_bricks ({n_bricks}) is more than the mesh's {mesh.n_tets} cells")
    state = {"points": mesh.points, "scalars": mesh.scalars}
    counter = iter(range(n_bricks))

    def build(tets: NDArray[np.int64], n: int) -> "Split | Brick":
        if n == 1:
            return Brick(next(counter), tets)
        pts = state["points"]
        corners = pts[tets]
        lo, hi, c = corners.min(axis=1), corners.max(axis=1), corners.mean(axis=1)
        n_low = n // 2
        want = len(tets) * n_low // n  # cells below the plane for balanced bricks
        for axis in np.argsort(-(c.max(axis=0) - c.min(axis=0)), kind="stable").tolist():
            plane, low = _separating_plane(lo[:, axis], hi[:, axis], want)
            if plane is not None:
                return Split(axis, plane, build(tets[low], n_low), build(tets[~low], n - n_low), 0, True)
        axis = int(np.argmax(c.max(axis=0) - c.min(axis=0)))
        order = np.argsort(c[:, axis], kind="stable")
        plane = 0.5 * (c[order[want - 1], axis] + c[order[want], axis])
        if not cut:
            low = np.zeros(len(tets), dtype=bool)
            low[order[:want]] = True
            separable = not np.any((lo[:, axis] < plane) & (hi[:, axis] > plane))
            return Split(axis, float(plane), build(tets[low], n_low), build(tets[~low], n - n_low), 0, separable)
        plane = _plane_off_vertices(pts[np.unique(tets), axis], plane)
        state["points"], state["scalars"], below, above, n_cut = _cut_at_plane(
            state["points"], state["scalars"], tets, axis, float(plane))
        if len(below) == 0 or len(above) == 0:
            raise ValueError(f"cannot split {len(tets)} cells into {n} bricks: a plane leaves one side empty")
        return Split(axis, float(plane), build(below, n_low), build(above, n - n_low), n_cut, True)

    root = build(mesh.tets.astype(np.int64), int(n_bricks))
    return BrickTree(root, state["points"], state["scalars"], mesh)


def _plane_off_vertices(coords: NDArray[np.float64], plane: float, window: int = _GAP_WINDOW) -> float:
    """The middle of the widest gap between vertex coordinates within ``window`` of
    ``plane``: every cut is then a clean 1|3 or 2|2 one, far (for this mesh) from its
    vertices, so no piece is a sliver flat to rounding."""
    c = np.unique(coords)
    i = int(np.searchsorted(c, plane))
    lo, hi = max(1, i - window), min(len(c), i + window)
    if hi <= lo:
        return plane
    gaps = c[lo:hi] - c[lo - 1:hi - 1]
    j = lo + int(np.argmax(gaps))
    return float(0.5 * (c[j - 1] + c[j]))


def _separating_plane(lo: NDArray[np.float64], hi: NDArray[np.float64], want: int
                      ) -> tuple[float | None, NDArray[np.bool_]]:
    """The plane no cell straddles (``lo < plane < hi``) whose count of cells below is
    nearest ``want``, if within the imbalance allowed; else ``(None, ...)``."""
    n = len(lo)
    cand = np.unique(hi)
    below = np.searchsorted(np.sort(hi), cand, side="right")  # cells wholly at or below the plane
    started = np.searchsorted(np.sort(lo), cand, side="left")  # cells starting below it
    ok = (started == below) & (below > 0) & (below < n)
    if not ok.any():
        return None, np.zeros(n, dtype=bool)
    k = np.flatnonzero(ok)[np.argmin(np.abs(below[ok] - want))]
    if abs(int(below[k]) - want) > SEPARABLE_IMBALANCE * n:
        return None, np.zeros(n, dtype=bool)
    plane = float(cand[k])
    return plane, hi <= plane


def _cut_at_plane(points: NDArray[np.float64], scalars: NDArray[np.float64], tets: NDArray[np.int64], axis: int,
                  plane: float) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.int64],
                                         NDArray[np.int64], int]:
    """Cut ``tets`` at the plane ``x[axis] = plane`` (on no vertex). Returns the points
    and scalars with the edge crossings appended, the tets below and above, and how many
    cells were cut.

    A cut tet with one vertex on one side leaves a tet there and a wedge on the other; one
    with two on each side, two wedges. Each crossing point is made once per edge, so the
    pieces of neighbouring cells share it, and wedges are split into tets by the smallest
    global id on each quad (:func:`tetvr.cells.split_cells`), so the pieces conform.
    """
    from .cells import split_cells

    d = points[tets, axis] - plane
    below = d < 0
    n_below = below.sum(axis=1)
    keep_low, keep_high = tets[n_below == 4], tets[n_below == 0]
    straddle = (n_below > 0) & (n_below < 4)
    if not straddle.any():
        return points, scalars, keep_low, keep_high, 0
    # Each cut tet's vertices, those below first.
    order = np.argsort(~below[straddle], axis=1, kind="stable")
    t = np.take_along_axis(tets[straddle], order, axis=1)
    nb = n_below[straddle]
    # One new point per crossed edge.
    pairs = np.concatenate([t[:, [i, j]] for i in range(4) for j in range(i + 1, 4)])
    pairs = pairs[(points[pairs[:, 0], axis] < plane) != (points[pairs[:, 1], axis] < plane)]
    n_pts = points.shape[0]
    keys = np.unique(np.minimum(pairs[:, 0], pairs[:, 1]) * n_pts + np.maximum(pairs[:, 0], pairs[:, 1]))
    u, v = keys // n_pts, keys % n_pts
    du, dv = points[u, axis] - plane, points[v, axis] - plane
    w = (du / (du - dv))[:, None]
    new_pts = points[u] + w * (points[v] - points[u])
    new_pts[:, axis] = plane
    new_s = scalars[u] + w[:, 0] * (scalars[v] - scalars[u])

    def x(a: NDArray[np.int64], b: NDArray[np.int64]) -> NDArray[np.int64]:
        k = np.minimum(a, b) * n_pts + np.maximum(a, b)
        return n_pts + np.searchsorted(keys, k)

    pieces_tet: list[NDArray[np.int64]] = []
    pieces_wedge: list[NDArray[np.int64]] = []
    side_tet: list[NDArray[np.bool_]] = []
    side_wedge: list[NDArray[np.bool_]] = []
    one = t[nb == 1]  # one below: a tet below, a wedge above
    if len(one):
        v0, a, b, c = one.T
        xa, xb, xc = x(v0, a), x(v0, b), x(v0, c)
        pieces_tet.append(np.stack([v0, xa, xb, xc], 1))
        side_tet.append(np.ones(len(one), dtype=bool))
        pieces_wedge.append(np.stack([a, b, c, xa, xb, xc], 1))
        side_wedge.append(np.zeros(len(one), dtype=bool))
    three = t[nb == 3]  # one above: a wedge below, a tet above
    if len(three):
        a, b, c, v0 = three.T
        xa, xb, xc = x(a, v0), x(b, v0), x(c, v0)
        pieces_tet.append(np.stack([v0, xa, xb, xc], 1))
        side_tet.append(np.zeros(len(three), dtype=bool))
        pieces_wedge.append(np.stack([a, b, c, xa, xb, xc], 1))
        side_wedge.append(np.ones(len(three), dtype=bool))
    two = t[nb == 2]  # two on each side: a wedge each
    if len(two):
        a, b, c, dd = two.T
        xac, xad, xbc, xbd = x(a, c), x(a, dd), x(b, c), x(b, dd)
        pieces_wedge += [np.stack([a, xac, xad, b, xbc, xbd], 1), np.stack([c, xac, xbc, dd, xad, xbd], 1)]
        side_wedge += [np.ones(len(two), dtype=bool), np.zeros(len(two), dtype=bool)]
    all_pts = np.concatenate([points, new_pts])
    all_s = np.concatenate([scalars, new_s])
    tet_in = np.concatenate(pieces_tet) if pieces_tet else np.zeros((0, 4), dtype=np.int64)
    wedge_in = np.concatenate(pieces_wedge) if pieces_wedge else np.zeros((0, 6), dtype=np.int64)
    split = split_cells(all_pts, [("tetra", tet_in), ("wedge", wedge_in)])
    is_low = np.concatenate(side_tet + side_wedge)[split.parent]
    all_pts = split.points
    all_s = split.extend(all_s)
    cut_tets = split.tets.astype(np.int64)
    low = np.concatenate([keep_low, cut_tets[is_low]])
    high = np.concatenate([keep_high, cut_tets[~is_low]])
    return all_pts, all_s, low, high, int(straddle.sum())


def visibility_order(tree: "BrickTree | Split | Brick", camera: Camera) -> list[int]:
    """Brick indices front to back for ``camera``: at each split, the side the eye is on
    first (parallel projection: the side the view direction comes from)."""
    if isinstance(tree, BrickTree):
        tree = tree.root
    if isinstance(tree, Brick):
        return [tree.index]
    if camera.parallel_projection:
        d = np.asarray(camera.focal_point) - np.asarray(camera.position)
        low_first = d[tree.axis] >= 0  # looking towards +axis: the low side is nearer
    else:
        low_first = camera.position[tree.axis] <= tree.plane
    first, second = (tree.low, tree.high) if low_first else (tree.high, tree.low)
    return visibility_order(first, camera) + visibility_order(second, camera)


def composite_over(images_front_to_back: Sequence[NDArray[Any]]) -> NDArray[np.float32]:
    """Premultiplied RGBA images composited "over", the first in front (in float64)."""
    if not images_front_to_back:
        raise ValueError("nothing to composite")
    out = np.asarray(images_front_to_back[0], dtype=np.float64).copy()
    for img in images_front_to_back[1:]:
        out += (1.0 - out[..., 3:4]) * np.asarray(img, dtype=np.float64)
    return out.astype(np.float32)


def _render_brick(brick: TetMesh, camera: Camera, tf: TransferFunction, size: tuple[int, int],
                  settings: RenderSettings) -> NDArray[np.float32]:
    return worker_renderer(settings).render(brick, camera, tf, size=size)


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
    """Render ``mesh`` as ``n_bricks`` k-d bricks (:func:`kd_bricks`) on the cluster's
    workers and composite them "over" on the client in visibility order.

    Returns the (height, width, 4) premultiplied float32 image.

    Examples
    --------
    >>> image = render_bricks(mesh, camera, tf, n_bricks=4, size=(256, 256))  # doctest: +SKIP
    """
    settings = settings or RenderSettings()
    size = image_size(size)
    tree = tree if tree is not None else kd_bricks(mesh, n_bricks)
    if tree.mesh is not mesh:
        raise ValueError("tree was split from another mesh")
    if len(tree.bricks()) != n_bricks:
        raise ValueError(f"tree has {len(tree.bricks())} bricks, n_bricks is {n_bricks}")
    if not tree.separable:
        warnings.warn("some k-d split planes run through cells (kd_bricks(cut=False)): the composite is "
                      "approximate within a cell's width of those planes", stacklevel=2)
    leaves = tree.bricks()
    order = tree.visibility_order(camera)
    with cluster_client(client) as c:
        # Each brick travels inside its task (not scattered ahead): a worker that dies
        # loses no data, and its task reruns elsewhere.
        futures = [c.submit(_render_brick, tree.brick_mesh(b), camera, tf, size, settings, pure=False)
                   for b in leaves]
        images = dict(zip([b.index for b in leaves], c.gather(futures)))
    return composite_over([images[i] for i in order])


def _all_separable(tree: "Split | Brick") -> bool:
    if isinstance(tree, Brick):
        return True
    return tree.separable and _all_separable(tree.low) and _all_separable(tree.high)


def _count_cut(tree: "Split | Brick") -> int:
    if isinstance(tree, Brick):
        return 0
    return tree.n_cut + _count_cut(tree.low) + _count_cut(tree.high)

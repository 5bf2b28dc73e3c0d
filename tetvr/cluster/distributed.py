"""Rendering one mesh on a Dask cluster as sort-last bricks.

About this technique
--------------------
A k-d tree of axis-aligned planes splits the mesh into bricks (the bricks themselves are
:mod:`tetvr.cluster.bricks`), each worker holds its bricks (:class:`ClusterBricks`) and
renders them to premultiplied float images with the shared camera, transfer function,
table and float32 origin, and the workers composite them "over" in the tree's visibility
order (radix-k, :mod:`tetvr.cluster.compositing`), so that the client receives one image.
A mesh held here is split here and its bricks sent (:func:`distribute_mesh`); a mesh in
solver pieces (a ``.pvtu``) is read and redistributed into bricks on the workers
(:func:`distribute_pieces`: each piece's bytes sent from here, or fetched by the workers
from a URL, :mod:`tetvr.cluster.inputs`), the client holding only a sample of its cells.
The cluster is ``dask.distributed``'s (:func:`tetvr.cluster.workers.cluster_client`); a
time series is rendered one task per step by :mod:`tetvr.cluster.timeseries`.

Where the composite is exact, and what it costs: ``docs/distributed.md``.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import warnings
from concurrent.futures import CancelledError
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from tetvr.cluster.bricks import (Brick, BrickTree, Part, Split, Whole, _check_n_bricks, clip_to_box, composite_over, kd_bricks,
                                  leaf_boxes, leaf_paths, merge_parts, part_mesh, plan_bricks, select_cells, visibility_order)
from tetvr.cluster.compositing import composite_on_workers, final_regions, runs, stitch, subtree_owners
from tetvr.cluster.inputs import Files, is_url, local_files, materialised, read_error, url_files, url_leaf_files
from tetvr.cluster.workers import cluster_client, gather, wait, wait_for_workers, worker_renderer
from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.core.image import image_size
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.transfer import TransferFunction
from tetvr.settings import RenderSettings

__all__ = ["ClusterBricks", "COMPOSITE", "distribute_mesh", "distribute_pieces", "render_bricks", "render_pieces",
           # the bricks themselves (tetvr.cluster.bricks), here too for one import
           "Brick", "BrickTree", "Split", "Whole", "kd_bricks", "visibility_order", "composite_over"]


#: Where :meth:`ClusterBricks.render` composites: on the workers (radix-k; the client
#: receives one image) or on the client (every brick's image comes to it).
COMPOSITE = ("workers", "client")


# ---- sort-last bricks ----

def _render_brick(brick: TetMesh, index: int, labels: dict[int, str], camera: Camera, tf: TransferFunction,
                  size: tuple[int, int], settings: RenderSettings) -> NDArray[np.float32]:
    label = labels[index]
    try:
        return worker_renderer(settings).render(brick, camera, tf, size=size)
    except Exception as exc:
        # Named, so that a failed frame says which brick (and which pieces) it was.
        raise RuntimeError(f"brick {index} ({label}) could not be rendered: {exc}") from exc


def _render_run(labels: dict[int, str], camera: Camera, tf: TransferFunction, size: tuple[int, int],
                settings: RenderSettings, indices: list[int], *bricks: TetMesh) -> NDArray[np.float32]:
    """Bricks consecutive in visibility order (front first), all held by this worker,
    rendered one at a time and composited "over" as they come (in float64, as
    :func:`tetvr.cluster.bricks.composite_over`)."""
    out: NDArray[np.float64] | None = None
    for index, brick in zip(indices, bricks):
        image = _render_brick(brick, index, labels, camera, tf, size, settings)
        if out is None:
            out = image.astype(np.float64)
        else:
            out += (1.0 - out[..., 3:4]) * image
    assert out is not None
    return out.astype(np.float32)


def _brick_facts(brick: TetMesh, index: int) -> tuple[int, bool]:
    """A brick's cell count and whether it is tangled (folded faces), which "auto" reads."""
    from tetvr.mesh.records import folded_faces

    return brick.n_tets, folded_faces(brick) > 0


class ClusterBricks:
    """One mesh as k-d bricks (:mod:`tetvr.cluster.bricks`) held by a cluster's workers, each
    worker only its bricks; :meth:`render` renders a view and composites it on the
    workers. Made by :func:`distribute_mesh` or :func:`distribute_pieces`.

    Attributes
    ----------
    root : the k-d tree (its planes order the bricks for each view).
    whole : what the bricks share with the whole mesh (:class:`tetvr.cluster.bricks.Whole`).
    labels : each brick's name in error messages (the pieces it came from).
    brick_tets : each brick's cell count (cut pieces included).
    tangled : whether any brick has folded faces (:func:`tetvr.mesh.records.folded_faces`),
        checked on the workers when first asked.
    """

    def __init__(self, client: Any, futures: dict[int, Any], root: "Split | Brick", whole: Whole,
                 labels: dict[int, str], *, brick_tets: dict[int, int] | None = None,
                 remake: Callable[[int], Any] | None = None) -> None:
        self.client = client
        self.futures = futures
        self.root = root
        self.whole = whole
        self.labels = labels
        self._brick_tets = brick_tets
        self._tangled: bool | None = None
        # A brick whose worker died: remade by remake(index) -> its future (scattered data,
        # which Dask cannot recompute); None where Dask recomputes it from its tasks.
        self._remake = remake

    def _run(self, tasks: Callable[[dict[int, Any]], list[Any]], what: str) -> list[Any]:
        """The results of the futures ``tasks(bricks)`` submits from the bricks' futures.
        Bricks whose worker died are remade first, and again (twice at most) where a worker
        dies under the tasks and takes its bricks with it (the tasks are cancelled)."""
        for attempt in range(3):
            self._replace_lost(ask=attempt > 0)
            futures = tasks(dict(self.futures))
            try:
                return gather(self.client, futures, what)
            except CancelledError:
                if self._remake is None or attempt == 2:
                    raise
        raise AssertionError("unreachable")  # pragma: no cover

    def _on_bricks(self, fn: Callable[..., Any], *args: Any, what: str) -> dict[int, Any]:
        """``fn(brick, index, *args)`` run on each brick's worker: the results by brick."""
        order = sorted(self.futures)
        got = self._run(lambda bricks: [self.client.submit(fn, bricks[i], i, *args, pure=False) for i in order], what)
        return dict(zip(order, got))

    def _facts(self) -> None:
        # Counted and checked on the workers, where the bricks are.
        facts = self._on_bricks(_brick_facts, what="checking the bricks")
        self._brick_tets = {i: n for i, (n, _) in facts.items()}
        self._tangled = any(t for _, t in facts.values())

    @property
    def brick_tets(self) -> dict[int, int]:
        if self._brick_tets is None:
            self._facts()
        assert self._brick_tets is not None
        return self._brick_tets

    @property
    def tangled(self) -> bool:
        if self._tangled is None:
            self._facts()
        return bool(self._tangled)

    @property
    def n_bricks(self) -> int:
        return len(self.futures)

    def settings_for(self, settings: RenderSettings, camera: Camera, size: tuple[int, int]) -> RenderSettings:
        """``settings`` with ``method="auto"`` resolved once for every brick (a brick alone
        could choose another): tet marching wherever it can render the bricks, projected
        tetrahedra only for settings only they implement
        (:data:`tetvr.order.method.PROJECTED_ONLY`), a tangled mesh, or a brick above
        :data:`tetvr.order.method.AUTO_MAX_TETS` cells (memory: the limit is per brick, as a
        worker renders one brick at a time). Unlike a single mesh, bricks never take
        projected tetrahedra for speed: the planes' cuts make new faces, and projected
        tetrahedra err on isolated pixels where a ray grazes a face seen edge-on
        (docs/distributed.md, "Where the composite is exact"). ``camera`` and ``size`` do
        not enter the choice."""
        from tetvr.order.method import AUTO_MAX_TETS, choose

        if settings.method != "auto":
            return settings
        method = choose(settings)  # what the settings alone decide
        if method == "raymarch" and (self.tangled or max(self.brick_tets.values(), default=0) > AUTO_MAX_TETS):
            method = "projected"
        return dataclasses.replace(settings, method=method)  # type: ignore[arg-type]

    def render(self, camera: Camera, tf: TransferFunction, *, size: tuple[int, int] = (512, 512),
               settings: RenderSettings | None = None, composite: str = "workers") -> NDArray[np.float32]:
        """The (height, width, 4) premultiplied float32 image of the whole mesh.

        ``composite`` (:data:`COMPOSITE`): ``"workers"`` composites the bricks' images on
        the workers, "over" in the k-d tree's visibility order for this view, by radix-k
        (:mod:`tetvr.cluster.compositing`), each worker's bricks that are consecutive in
        that order first composited where they are: the client receives one image.
        ``"client"`` brings every brick's full image here and composites them in order
        (:func:`tetvr.cluster.bricks.composite_over`): P images received. The two differ
        by float32 rounding (under 1e-6).
        """
        size = image_size(size)
        if composite not in COMPOSITE:
            raise ValueError(f"composite must be one of {COMPOSITE}, got {composite!r}")
        camera = resolve_clipping_range(camera, self.whole.bounds)  # one range for every brick: the whole mesh's
        settings = self.settings_for(settings or RenderSettings(), camera, size)
        order = visibility_order(self.root, camera)
        c = self.client
        n_pixels = size[0] * size[1]

        n_runs = [0]

        def tasks(bricks: dict[int, Any]) -> list[Any]:
            if composite == "client":
                return [c.submit(_render_brick, bricks[i], i, self.labels, camera, tf, size, settings, pure=False)
                        for i in order]
            # Bricks consecutive in this view's order and held by one worker render and
            # composite there as one run; radix-k then composites the runs across workers.
            held = c.who_has([bricks[i] for i in order])
            owners = [next(iter(held.get(bricks[i].key) or ()), None) for i in order]
            groups = runs(owners)
            where = [owners[g[0]] for g in groups]
            images = [c.submit(_render_run, self.labels, camera, tf, size, settings, [order[s] for s in g],
                               *[bricks[order[s]] for s in g], pure=False, workers=None if w is None else [w],
                               allow_other_workers=True) for g, w in zip(groups, where)]
            n_runs[0] = len(groups)
            return composite_on_workers(c, images, n_pixels, workers=where)[0]

        parts = self._run(tasks, "rendering the bricks")
        if composite == "client":
            return composite_over(parts)
        return stitch(parts, final_regions(n_runs[0], n_pixels), size[1], size[0])

    def _replace_lost(self, ask: bool = False) -> None:
        """Scatter again the bricks whose workers died (scattered data is lost with them):
        those whose futures say so, and with ``ask`` those no worker holds, as the
        scheduler says (it may know before this client does)."""
        if self._remake is None:
            return
        lost = {i for i, f in self.futures.items() if f.status in ("lost", "cancelled")}
        if ask:
            held = self.client.who_has([f for i, f in self.futures.items() if i not in lost])
            lost |= {i for i, f in self.futures.items() if i not in lost and not held.get(f.key)}
        for i in sorted(lost):
            self.futures[i] = self._remake(i)

    def release(self) -> None:
        """Let the workers drop the bricks."""
        for f in self.futures.values():
            f.release()
        self.futures = {}
        self._remake = None


def distribute_mesh(mesh: TetMesh, n_bricks: int, client: Any, *, tree: BrickTree | None = None) -> ClusterBricks:
    """Split ``mesh`` (held here) into ``n_bricks`` k-d bricks (:func:`tetvr.cluster.bricks.kd_bricks`)
    and hand them to the workers of ``client`` (a ``distributed.Client``).

    Each brick is scattered to one worker (``client.scatter``: straight to the worker
    unless the client was made with ``direct_to_workers=False``, then through the
    scheduler, which forwards it), each worker's bricks one subtree of the k-d tree
    (:func:`tetvr.cluster.compositing.subtree_owners`): they are consecutive in every
    view's order, so they are composited where they are before any image travels. No
    brick travels inside a task, so the scheduler holds only their keys, never the mesh.
    A worker that dies takes its bricks with it: the next :meth:`ClusterBricks.render`
    makes them again here from the k-d tree, which the client keeps, and scatters them to
    the workers left.
    """
    tree = tree if tree is not None else kd_bricks(mesh, n_bricks)
    if tree.mesh is not mesh:
        raise ValueError("tree was split from another mesh")
    if len(tree.bricks()) != n_bricks:
        raise ValueError(f"tree has {len(tree.bricks())} bricks, n_bricks is {n_bricks}")
    if not tree.separable:
        warnings.warn("some k-d split planes run through cells (kd_bricks(cut=False)): the composite is "
                      "approximate within a cell's width of those planes", stacklevel=3)
    by_index = {b.index: b for b in tree.bricks()}
    direct = True if client.direct_to_workers is None else bool(client.direct_to_workers)
    counts: dict[int, int] = {}
    turn = itertools.count()  # a brick made again: to the workers left, in turn
    first = wait_for_workers(client, "handing the bricks to the workers")
    owner = subtree_owners(tree.root, len(first))

    def scatter(i: int, at: str | None = None) -> Any:
        workers = wait_for_workers(client, f"handing brick {i} to the workers")
        brick = tree.brick_mesh(by_index[i])  # made here one at a time, dropped once sent
        counts[i] = brick.n_tets
        address = at if at is not None else workers[next(turn) % len(workers)]
        return client.scatter(brick, workers=[address], direct=direct, hash=False)

    futures = {i: scatter(i, first[owner[i]]) for i in sorted(by_index)}
    labels = {i: f"{n_bricks} k-d bricks of the mesh" for i in futures}
    return ClusterBricks(client, futures, tree.root, tree.whole, labels, brick_tets=counts, remake=scatter)


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
    """Render ``mesh`` as ``n_bricks`` k-d bricks (:func:`tetvr.cluster.bricks.kd_bricks`) on the
    cluster's workers and composite them "over" there in visibility order. For
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

def _read_piece(files: Files, scalars: str | None, component: int | None) -> TetMesh:
    from tetvr.io.meshfile import read

    with materialised(files) as path:
        try:
            return read(path, scalars, component=component)
        except Exception as exc:
            raise ValueError(read_error(exc, files, path, "piece")) from exc


def _piece_sender(client: Any) -> Callable[[str], Any]:
    """``send(name)``: what a worker reads a piece from. A URL is fetched by the worker; a
    path's bytes are read here and handed to the workers in turn (``client.scatter``, as
    :func:`distribute_mesh` hands its bricks), one piece at a time."""
    workers = wait_for_workers(client, "handing the pieces to the workers")
    direct = True if client.direct_to_workers is None else bool(client.direct_to_workers)
    turn = itertools.count()

    def send(name: str) -> Any:
        if is_url(name):
            return url_files(name)
        return client.scatter(local_files(name, "piece"), workers=[workers[next(turn) % len(workers)]],
                              direct=direct, hash=False)

    return send


def _piece_summary(piece: TetMesh, n_segments: int) -> dict[str, Any]:
    from tetvr.optics.tablesize import sample_segments

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
    from tetvr.optics.tablesize import SegmentSample

    total = sum(s["n_tets"] for s in summaries)
    segs = [s["segments"] for s in summaries]
    w = np.concatenate([g.weight * (s["n_tets"] / total) for g, s in zip(segs, summaries)])
    return SegmentSample(front=np.concatenate([g.front for g in segs]), back=np.concatenate([g.back for g in segs]),
                         length=np.concatenate([g.length for g in segs]), weight=w / w.sum())


def _piece_names(pieces: Any) -> list[str]:
    """The files of ``pieces``: a collection's (a path's listed here, a URL's from its XML),
    or the list given."""
    from tetvr.io.collections import pieces as piece_files

    if isinstance(pieces, (str, os.PathLike)):
        name = os.fspath(pieces)
        files = url_leaf_files(name) if is_url(name) else piece_files(name)
    else:
        files = [os.fspath(f) for f in pieces]
    if not files:
        raise ValueError("no pieces given")
    return files


def _whole_of(summaries: list[dict[str, Any]]) -> Whole:
    """What the bricks share with the whole mesh, from its pieces' summaries."""
    bounds = np.stack([np.min([s["bounds"][0] for s in summaries], axis=0),
                       np.max([s["bounds"][1] for s in summaries], axis=0)])
    return Whole(bounds=bounds, float32_origin=bounds.mean(axis=0),
                 scalar_range=(min(s["scalar_range"][0] for s in summaries),
                               max(s["scalar_range"][1] for s in summaries)),
                 max_edge=max(s["max_edge"] for s in summaries), segment_sample=_combined_sample(summaries),
                 n_tets=sum(s["n_tets"] for s in summaries))


def distribute_pieces(pieces: Any, n_bricks: int, client: Any, *, scalars: str | None = None,
                      component: int | None = None, sample: int = 20_000) -> ClusterBricks:
    """Read a mesh's solver pieces on the workers and redistribute them into ``n_bricks``
    k-d bricks there; the client holds only a sample of the cells.

    ``pieces``: a ``.pvtu`` (or ``.vtm``) file, or a list of mesh files that together make
    one mesh (points on the pieces' shared faces with equal coordinates are joined). A path
    names files here: each piece is read here, one at a time, and its bytes sent to a
    worker; a URL (``s3://...``, ``file:///shared/...``) names files the workers fetch
    themselves (:mod:`tetvr.cluster.inputs`). Solver
    partitions are not convex and cannot be ordered as wholes; the bricks are boxes
    (ParaView's ``vtkRedistributeDataSet`` before IceT does the same).

    1. each piece is parsed on a worker (a piece that cannot be read fails naming its file);
       its summary (bounds, scalar range, longest edge, a segment sample) and a sample of
       ``sample`` cells in all, drawn evenly, come back;
    2. the k-d planes are chosen on the sample (:func:`tetvr.cluster.bricks.plan_bricks`);
    3. each piece sends every brick the cells that overlap its box; the brick's worker
       joins them and cuts them at its box's planes (:func:`tetvr.cluster.bricks.clip_to_box`).

    Examples
    --------
    >>> with cluster_client() as c:                                      # doctest: +SKIP
    ...     bricks = distribute_pieces("run_0042.pvtu", 8, c)
    ...     image = bricks.render(camera, tf, size=(1024, 1024))
    """
    from tetvr.optics.tablesize import _N_SEGMENTS

    files = _piece_names(pieces)
    send = _piece_sender(client)
    read = [client.submit(_read_piece, send(f), scalars, component, pure=False) for f in files]
    per_piece = max(256, _N_SEGMENTS // len(files))
    summaries = gather(client, [client.submit(_piece_summary, r, per_piece, pure=False) for r in read],
                       "reading the pieces")
    total = sum(s["n_tets"] for s in summaries)
    _check_n_bricks(n_bricks, total)
    kinds = {(s["scalar_name"], s["cell_data"]) for s in summaries}
    if len(kinds) > 1:
        raise ValueError("the pieces do not carry one field: " + ", ".join(
            f"{os.path.basename(f)}: {s['scalar_name']!r} ({'cell' if s['cell_data'] else 'point'} data)"
            for f, s in zip(files, summaries)))
    corners = np.concatenate(gather(client, [
        client.submit(_piece_sample, r, max(1, -(-sample * s["n_tets"] // total)), pure=False)
        for r, s in zip(read, summaries)], "sampling the pieces"))
    whole = _whole_of(summaries)
    root = plan_bricks(corners, n_bricks)
    boxes = leaf_boxes(root, whole.bounds)
    paths = leaf_paths(root)
    name = summaries[0]["scalar_name"]
    # A piece's cells may overlap the box's bounds but not its inside: such a piece sends
    # nothing useful, and is named anyway (the label says where cells came from).
    pieces_in = {i: [k for k, s in enumerate(summaries)
                     if np.all(s["bounds"][0] < box[1]) and np.all(s["bounds"][1] > box[0])]
                 for i, box in boxes.items()}
    labels = {i: "pieces " + ", ".join(os.path.basename(files[k]) for k in ks) for i, ks in pieces_in.items()}

    workers = wait_for_workers(client, "making the bricks")
    owner = subtree_owners(root, len(workers))  # each worker one subtree of bricks

    def make(i: int, read: dict[int, Any], at: str | None = None) -> Any:
        parts = [client.submit(_piece_part, read[k], boxes[i], pure=False) for k in pieces_in[i]]
        return client.submit(_assemble_brick, i, labels[i], paths[i], whole, name, *parts, pure=False,
                             workers=None if at is None else [at], allow_other_workers=True)

    def remake(i: int) -> Any:
        # A brick lost with its worker, whose pieces' bytes are gone too: read and sent again.
        again = _piece_sender(client)
        return make(i, {k: client.submit(_read_piece, again(files[k]), scalars, component, pure=False)
                        for k in pieces_in[i]})

    futures = {i: make(i, dict(enumerate(read)), workers[owner[i]]) for i in boxes}
    # Made (and any error raised, naming its piece) before the pieces go; waited for, not
    # gathered: the bricks stay on the workers.
    wait(client, list(futures.values()), "making the bricks")
    for f in futures.values():
        if f.status == "error":
            f.result()
    del read
    return ClusterBricks(client, futures, root, whole, labels, remake=remake)


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

"""Rendering on Dask: time series and sort-last bricks, measured against one process.

Six parts, each written to ``<out>/distributed.json`` (and charts, ``distributed.png`` and
``distributed_compositing.png``):

* **series** -- S steps of a synthetic mesh written as ``.vtu`` files, each read and
  rendered (256x256): a plain serial loop in this process against
  :func:`tetvr.cluster.timeseries.render_series` on a LocalCluster of 1 and of 2 workers,
  alternated for R rounds (the best of each kept: on a shared machine the rounds differ);
  frames compared bit for bit. Dask's own cost per frame: a trivial frame (one tet, 8x8)
  through the same path, minus the same frame rendered here.
* **composite** -- :func:`tetvr.cluster.bricks.composite_over` alone: ns per pixel per brick.
* **bricks** -- a synthetic (rotated, so planes cut cells) cube of ~1M (and with
  ``--tets 1e6,1e7`` ~10M) tets split into P = 1, 2, 4, 8 k-d bricks held by a fresh
  2-worker cluster (:func:`tetvr.cluster.distributed.distribute_mesh`): the split's time on the
  client, the first frame, the median time per view change (an orbit), and each worker's
  peak resident memory (``ru_maxrss``, a fresh cluster per P).
* **compositing** -- P = 2, 4, 8, 16 images (512x512 and 1024x1024 float RGBA, and 8x8 for
  Dask's cost per task) held by 2 workers in turn, composited on the client (all P
  gathered, :func:`tetvr.cluster.bricks.composite_over`) and on the workers (radix-k,
  :func:`tetvr.cluster.compositing.composite_on_workers`): time, the bytes the workers send
  the client and each other (Dask's transfer logs), the difference between the two.
* **frames** -- whole frames of a grid cube in P = 2 .. 16 k-d bricks on 2 workers
  (:meth:`tetvr.cluster.distributed.ClusterBricks.render`, ``composite="client"`` and
  ``"workers"``): the median time of a few views and the bytes the client receives.
* **accuracy** -- the acceptance matrix: a grid cube, the interlocking rings (non-convex)
  and bluntfin (when ``../shared`` has it), P = 2, 4, 8, perspective / parallel / inside,
  both methods: the composite's max abs difference from the single-process image, and
  its PSNR against the CPU reference minus the single image's.
* **big** (``--only big``, not in the default run) -- one mesh of ~10M tets (``--big``) from
  solver pieces, in one run: the rotated grid cube written as 8 ``.vtu`` pieces by the
  workers (as a solver writes its parts), made into 8 k-d bricks on them
  (:func:`tetvr.cluster.distributed.distribute_pieces` of a ``file://`` URL: the client never
  reads a piece) and rendered there, composited on the workers; then the same frames by one
  process holding the whole mesh (the largest grid that fits, where the whole would not).
  The scheduler and the 2 workers are processes of their own (``dask scheduler``,
  ``dask worker --no-nanny``), so each one's peak resident memory (VmHWM) is its own; all
  share this machine's cores. First frame, time per view change, their ratio to the single
  process, the composite's max abs difference from its image, each process's peak memory
  (``distributed_big.png``).

Ratios carry between machines; seconds are this machine's (llvmpipe; ``machine`` in the
JSON says how many cores). The projection to 64 / 1,024 workers and 10^9 tets in
bench/README.md, and the compositing model for P = 1,024 in docs/distributed.md, are
computed from these numbers by ``bench/doc_tables.py``.

(This file is named like the ``distributed`` package: it takes its own folder off
``sys.path`` before anything imports Dask.)

Usage::

    python bench/distributed.py [--quick] [--tets 1e6[,1e7]] [--rounds R] [--only compositing,frames]
                                [--out bench/results]
    python bench/distributed.py --only big [--big 1e7] [--big-size 512] [--views 3]
"""

from __future__ import annotations

import sys
from pathlib import Path

_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]  # before "import distributed"
sys.path.insert(0, str(_HERE.parent))

import argparse  # noqa: E402
import datetime as _dt  # noqa: E402
import importlib.util  # noqa: E402
import os  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402


def _common():
    spec = importlib.util.spec_from_file_location("_common", _HERE / "_common.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


def _peak_rss_mib() -> float:
    """This process's peak resident memory (VmHWM: not ru_maxrss, which a spawned worker
    inherits from the process that started it, across exec)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return float(line.split()[1]) / 1024.0  # kB
    return float("nan")


def series(args: argparse.Namespace) -> dict:
    import meshio

    import tetvr
    from tetvr import Camera, TransferFunction
    from tetvr.mesh import synthetic
    from tetvr.cluster.timeseries import render_series
    from tetvr.cluster.workers import cluster_client
    from tetvr.gl import Renderer

    n_cube, n_steps, size = (12, 8, (128, 128)) if args.quick else (20, 16, (256, 256))
    mesh = synthetic.cube(n_cube)
    out: dict = {"mesh_tets": mesh.n_tets, "steps": n_steps, "size": list(size), "workers": {}}
    with tempfile.TemporaryDirectory() as tmp:
        files = []
        for k in range(n_steps):
            files.append(os.path.join(tmp, f"s{k}.vtu"))
            meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"f": mesh.scalars * (1 + 0.1 * k)}).write(
                files[-1])
        cam = Camera.fit(mesh)
        tf = TransferFunction.preset("viridis", (mesh.scalar_range[0], mesh.scalar_range[1] * (1 + 0.1 * n_steps)),
                                     unit_distance=0.1)
        tiny = synthetic.single_tet()
        tcam, ttf = Camera.fit(tiny), TransferFunction.preset("viridis", (0, 1))
        with Renderer() as r:
            r.render(tetvr.read(files[0]), cam, tf, size=size)
            for n_workers in (1, 2):
                rounds = []
                with cluster_client(n_workers=n_workers) as c:
                    c.wait_for_workers(n_workers)
                    render_series(files[:n_workers], camera=cam, tf=tf, size=size, client=c, progress=False)  # warm-up
                    for _ in range(args.rounds):
                        t = time.perf_counter()
                        serial = [r.render(tetvr.read(f), cam, tf, size=size) for f in files]
                        t_serial = time.perf_counter() - t
                        t = time.perf_counter()
                        frames = render_series(files, camera=cam, tf=tf, size=size, client=c, progress=False)
                        t_dask = time.perf_counter() - t
                        t = time.perf_counter()
                        for _ in range(32):
                            r.render(tiny, tcam, ttf, size=(8, 8))
                        t_tiny = time.perf_counter() - t
                        t = time.perf_counter()
                        render_series([tiny] * 32, camera=tcam, tf=ttf, size=(8, 8), client=c, progress=False)
                        t_tiny_dask = time.perf_counter() - t
                        rounds.append({"serial_s": t_serial, "dask_s": t_dask, "trivial32_serial_s": t_tiny,
                                       "trivial32_dask_s": t_tiny_dask,
                                       "identical": all(np.array_equal(a, b) for a, b in zip(frames, serial))})
                        print(f"series, {n_workers} worker(s): serial {t_serial:.2f} s, Dask {t_dask:.2f} s; "
                              f"trivial x32 {t_tiny:.3f} / {t_tiny_dask:.3f} s", flush=True)
                best_s, best_d = min(x["serial_s"] for x in rounds), min(x["dask_s"] for x in rounds)
                out["workers"][str(n_workers)] = {
                    "rounds": rounds, "serial_frames_per_s": n_steps / best_s, "dask_frames_per_s": n_steps / best_d,
                    "speedup": best_s / best_d, "identical": all(x["identical"] for x in rounds),
                    "dask_overhead_s_per_frame": (min(x["trivial32_dask_s"] for x in rounds)
                                                  - min(x["trivial32_serial_s"] for x in rounds)) / 32}
    return out


def composite() -> dict:
    from tetvr.cluster.bricks import composite_over

    rng = np.random.default_rng(0)
    out = {}
    for p in (2, 4, 8):
        imgs = [rng.random((512, 512, 4), dtype=np.float32) * 0.5 for _ in range(p)]
        best = min(_timed(lambda: composite_over(imgs)) for _ in range(3))
        out[str(p)] = {"ns_per_pixel_per_brick": best / (512 * 512 * p) * 1e9}
    return out


def _timed(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def bricks(args: argparse.Namespace, n_tets: float) -> dict:
    from tetvr import Camera, TransferFunction
    from tetvr.mesh import synthetic
    from tetvr.apps.animate import orbit
    from tetvr.cluster.bricks import kd_bricks
    from tetvr.cluster.distributed import distribute_mesh
    from tetvr.cluster.workers import cluster_client

    n = max(2, round((n_tets / 6) ** (1 / 3)))
    mesh = synthetic.cube(n)
    size = (256, 256) if args.quick else (512, 512)
    lo, hi = mesh.scalar_range
    tf = TransferFunction.preset("viridis", (lo, hi), opacity=0.5, unit_distance=0.2)
    views = orbit(Camera.fit(mesh), 1 + args.views, degrees=40.0)
    out: dict = {"n_tets": mesh.n_tets, "size": list(size), "workers": 2, "P": {}}
    for p in (int(x) for x in args.bricks_p.split(",")):
        t = time.perf_counter()
        tree = kd_bricks(mesh, p)
        t_split = time.perf_counter() - t
        with cluster_client(n_workers=2) as c:
            c.wait_for_workers(2)
            base = c.run(_peak_rss_mib)
            t = time.perf_counter()
            b = distribute_mesh(mesh, p, c, tree=tree)
            __import__("distributed").wait(list(b.futures.values()))
            t_send = time.perf_counter() - t
            t = time.perf_counter()
            b.render(views[0], tf, size=size)
            t_first = time.perf_counter() - t
            times = []
            for cam in views[1:]:
                t = time.perf_counter()
                b.render(cam, tf, size=size)
                times.append(time.perf_counter() - t)
            peaks = c.run(_peak_rss_mib)
            method = b.settings_for(__import__("tetvr").RenderSettings(), views[1], size).method
            b.release()
        out["P"][str(p)] = {"split_s": t_split, "send_s": t_send, "first_frame_s": t_first,
                            "view_change_median_s": float(np.median(times)), "view_change_s": times,
                            "cells_cut": tree.n_cut, "brick_tets": [len(x.tets) for x in tree.bricks()],
                            "worker_peak_rss_mib": sorted(peaks.values()),
                            "worker_start_rss_mib": sorted(base.values()), "method": method}
        print(f"bricks {mesh.n_tets:,} tets, P={p}: split {t_split:.2f} s, first {t_first:.2f} s, view change "
              f"{np.median(times):.2f} s, worker peak {max(peaks.values()):.0f} MiB ({method})", flush=True)
    return out


def accuracy(args: argparse.Namespace) -> dict:
    from tetvr import Camera, RenderSettings, TransferFunction
    from tetvr.mesh import synthetic
    from tetvr.cluster.distributed import distribute_mesh
    from tetvr.cluster.workers import cluster_client
    from tetvr.cluster.bricks import kd_bricks
    from tetvr.gl import Renderer
    from tetvr.core.image import psnr
    from tetvr.reference.tets import render_reference

    common = _common()
    meshes = {"cube (grid)": lambda: synthetic.cube(6, rotate=False), "interlocking rings": synthetic.interlocking_rings}
    if (common.TETS_DATA / "bluntfin_tets.vtu").is_file():
        meshes["bluntfin"] = lambda: common.load_quiet(common.TETS_DATA / "bluntfin_tets.vtu", "Density")
    size = (64, 64)
    out: dict = {"size": list(size), "cases": [],
                 "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    with cluster_client(n_workers=2) as c:
        for name, make in meshes.items():
            mesh = make()
            b = mesh.bounds
            diag = float(np.linalg.norm(b[1] - b[0]))
            tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=[(0, 0.3), (0.6, 0.9), (1, 0.5)],
                                         unit_distance=0.2 * diag)
            eye = b.mean(axis=0) + (0.13, 0.07, 0.21) * (b[1] - b[0]) / 1.5
            views = {"perspective": Camera.fit(mesh, direction=(-1.0, -0.35, -0.25), zoom=1.2),
                     "parallel": Camera.fit(mesh, direction=(-1.0, -0.35, -0.25), zoom=1.2, parallel=True),
                     "inside": Camera(position=tuple(eye), focal_point=tuple(eye - (0.4, 0.2, 0.3)), view_angle=70.0,
                                      clipping_range=(0.005 * diag, 5 * diag))}
            refs = {v: render_reference(mesh, cam, tf, size) for v, cam in views.items()}
            for method in ("auto", "projected", "exact"):
                # "exact": tet marching without the table (integration="exact").
                settings = (RenderSettings(integration="exact") if method == "exact"
                            else RenderSettings(method=method))
                with Renderer(settings) as r:
                    wholes = {v: r.render(mesh, cam, tf, size=size) for v, cam in views.items()}
                for p in (2, 4, 8):
                    tree = kd_bricks(mesh, p)
                    bricks = distribute_mesh(mesh, p, c, tree=tree)
                    for v, cam in views.items():
                        img = bricks.render(cam, tf, size=size, settings=settings)
                        out["cases"].append({
                            "mesh": name, "n_tets": mesh.n_tets, "P": p, "view": v, "method": method,
                            "resolved": bricks.settings_for(settings, cam, size).method, "cells_cut": tree.n_cut,
                            "max_abs_diff": float(np.abs(img - wholes[v]).max()),
                            "whole_max_err_vs_ref": float(np.abs(wholes[v] - refs[v]).max()),
                            "psnr_whole": psnr(wholes[v], refs[v]), "psnr_bricks": psnr(img, refs[v]),
                            "pixels_over_1e-5": int((np.abs(img - wholes[v]).max(axis=-1) > 1e-5).sum()),
                            "pixels_over_1_255": int((np.abs(img - wholes[v]).max(axis=-1) > 1 / 255).sum())})
                    bricks.release()
                    worst = max((x for x in out["cases"] if x["mesh"] == name and x["P"] == p
                                 and x["method"] == method), key=lambda x: x["max_abs_diff"])
                    print(f"accuracy {name} {method} P={p}: max diff {worst['max_abs_diff']:.1e}", flush=True)
    return out


def _transfer_log(dask_worker=None) -> list:
    """This worker's outgoing transfers (Dask's transfer log): (to whom, bytes)."""
    return [(e.get("who"), int(e["total"])) for e in dask_worker.transfer_outgoing_log]


def _moved(c, before: dict) -> tuple[int, int]:
    """Bytes the workers sent since ``before`` (their logs then): to anything that is not a
    worker (the client, or the scheduler on the client's behalf), and between workers."""
    now = c.run(_transfer_log)
    workers = set(now)
    to_client = between = 0
    for w, log in now.items():
        for who, total in log[len(before.get(w, [])):]:
            if who in workers:
                between += total
            else:
                to_client += total
    return to_client, between


def _premultiplied(rng, h: int, w: int):
    a = rng.random((h, w, 1), dtype=np.float32) * 0.6
    return np.concatenate([rng.random((h, w, 3), dtype=np.float32) * a, a], axis=-1)


def compositing(args: argparse.Namespace) -> dict:
    """The P brick images composited on the client (all P gathered) and on the workers
    (radix-k), from images already on the workers: time, bytes the client receives, bytes
    between workers, tasks; Dask's cost per task from 8x8 images."""
    from tetvr.cluster.bricks import composite_over
    from tetvr.cluster.compositing import composite_on_workers, radix_factors, stitch
    from tetvr.cluster.workers import cluster_client

    ps = [int(x) for x in args.composite_p.split(",")]
    sizes = [(8, 8), (256, 256), (512, 512)] if args.quick else [(8, 8), (512, 512), (1024, 1024)]
    rng = np.random.default_rng(0)
    out: dict = {"workers": 2, "P": ps, "cases": [],
                 "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")}
    with cluster_client(n_workers=2) as c:
        c.wait_for_workers(2)
        addrs = sorted(c.nthreads())
        for w, h in sizes:
            n = w * h
            for p in ps:
                where = [addrs[i % len(addrs)] for i in range(p)]  # bricks share the 2 workers
                futs = [c.scatter(_premultiplied(rng, h, w), workers=[where[i]], direct=True, hash=False)
                        for i in range(p)]
                __import__("distributed").wait(futs)
                runs: dict = {"client": [], "workers": []}
                images = {}
                for _ in range(args.rounds):
                    for mode in ("client", "workers"):
                        before = c.run(_transfer_log)
                        t = time.perf_counter()
                        if mode == "client":
                            got = c.gather(futs)
                            images[mode] = composite_over(got)
                        else:
                            pieces, regions = composite_on_workers(c, futs, n, workers=where)
                            got = c.gather(pieces)
                            images[mode] = stitch(got, regions, h, w)
                        dt = time.perf_counter() - t
                        received = sum(g.nbytes for g in got)
                        del got
                        to_client, between = _moved(c, before)
                        runs[mode].append({"s": dt, "gathered_bytes": received, "workers_to_client_bytes": to_client,
                                           "between_workers_bytes": between})
                tasks = sum(p * (k + 1) for k in radix_factors(p)) if p > 1 else 1
                case = {"size": [w, h], "P": p, "tasks": tasks, "factors": radix_factors(p),
                        "image_bytes": 16 * n, "max_abs_diff": float(np.abs(images["workers"] - images["client"]).max())}
                for mode, rs in runs.items():
                    best = min(rs, key=lambda r: r["s"])
                    case[mode] = {"best_s": best["s"], "runs_s": [r["s"] for r in rs], **{
                        k: v for k, v in best.items() if k != "s"}}
                out["cases"].append(case)
                print(f"compositing {w}x{h} P={p}: client {case['client']['best_s']:.3f} s "
                      f"({case['client']['workers_to_client_bytes'] / 2**20:.1f} MiB to the client), workers "
                      f"{case['workers']['best_s']:.3f} s ({case['workers']['workers_to_client_bytes'] / 2**20:.1f} "
                      f"MiB to the client, {case['workers']['between_workers_bytes'] / 2**20:.1f} MiB between "
                      f"workers, {tasks} tasks), max diff {case['max_abs_diff']:.1e}", flush=True)
                del futs
    # Dask's cost per task: the 8x8 frames' time against their task counts (least squares).
    tiny = [x for x in out["cases"] if x["size"] == [8, 8]]
    slope, icpt = np.polyfit([x["tasks"] for x in tiny], [x["workers"]["best_s"] for x in tiny], 1)
    # "Over" on one core: ns per pixel per image after the first (float32 in, float64 sums).
    a, b = _premultiplied(rng, 1024, 1024), _premultiplied(rng, 1024, 1024)
    over = min(_timed(lambda: composite_over([a, b, a, b, a])) for _ in range(3)) / (4 * 1024 * 1024)
    out["constants"] = {"s_per_task": float(slope), "s_per_frame": float(icpt), "over_ns_per_pixel": over * 1e9}
    print(f"compositing: Dask {slope * 1e3:.2f} ms per task (+{icpt * 1e3:.0f} ms a frame); over "
          f"{over * 1e9:.1f} ns per pixel", flush=True)
    return out


def frames(args: argparse.Namespace) -> dict:
    """Whole frames of a k-d split mesh (renders included), composited on the client and
    on the workers, P = 2 .. 16 bricks on 2 workers: the median time of a few views and
    the bytes the client receives."""
    from tetvr import Camera, TransferFunction
    from tetvr.apps.animate import orbit
    from tetvr.cluster.distributed import distribute_mesh
    from tetvr.cluster.workers import cluster_client
    from tetvr.mesh import synthetic

    mesh = synthetic.cube(8 if args.quick else 14)
    size = (256, 256) if args.quick else (512, 512)
    tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.5, unit_distance=0.2)
    views = orbit(Camera.fit(mesh), 1 + args.views, degrees=40.0)
    out: dict = {"n_tets": mesh.n_tets, "size": list(size), "workers": 2, "P": {}}
    with cluster_client(n_workers=2) as c:
        c.wait_for_workers(2)
        for p in (int(x) for x in args.composite_p.split(",")):
            b = distribute_mesh(mesh, p, c)
            res: dict = {"client": [], "workers": [], "client_bytes": {}, "max_abs_diff": 0.0}
            for mode in ("client", "workers"):
                b.render(views[0], tf, size=size, composite=mode)  # warm-up
            for cam in views[1:]:
                got = {}
                for mode in ("client", "workers"):
                    before = c.run(_transfer_log)
                    t = time.perf_counter()
                    got[mode] = b.render(cam, tf, size=size, composite=mode)
                    res[mode].append(time.perf_counter() - t)
                    res["client_bytes"][mode] = _moved(c, before)[0]
                res["max_abs_diff"] = max(res["max_abs_diff"], float(np.abs(got["client"] - got["workers"]).max()))
            b.release()
            res["median_s"] = {m: float(np.median(res[m])) for m in ("client", "workers")}
            out["P"][str(p)] = res
            print(f"frames P={p}: client {res['median_s']['client']:.2f} s, workers {res['median_s']['workers']:.2f} s; "
                  f"client receives {res['client_bytes']['client'] / 2**20:.1f} / "
                  f"{res['client_bytes']['workers'] / 2**20:.1f} MiB", flush=True)
    return out


# ---- --big: one mesh of ~10M tets from solver pieces, on a cluster of processes, against one process ----

#: The big run's bricks and solver pieces.
BIG_BRICKS = 8
BIG_PIECES = 8
#: What the single process is estimated to take per tet (the mesh and its generation's
#: temporaries, ~330 B, and tet marching's records, MARCH_BYTES_PER_TET), to decide
#: before the run whether it fits; and the memory left free below which a watchdog kills
#: a run of this benchmark rather than let the machine swap or the kernel kill at random.
BIG_BYTES_PER_TET = 1330
BIG_MEMORY_FLOOR = 1.5 * 2**30


def _proc_status_mib(key: str) -> float:
    """A ``/proc/self/status`` memory line in MiB (``VmHWM``: peak resident, ``VmRSS``: now)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return float(line.split()[1]) / 1024.0  # kB
    return float("nan")


def _rss_mib() -> float:
    return _proc_status_mib("VmRSS")


def _reset_peak_rss() -> float:
    """Start this process's peak resident memory again from what it holds now (Linux
    ``clear_refs`` 5), so a later peak is that of what follows. Returns the peak before."""
    peak = _peak_rss_mib()
    Path("/proc/self/clear_refs").write_text("5")
    return peak


def _available() -> int:
    from tetvr.core.image import available_memory

    return available_memory() or 0


class _Watchdog:
    """Polls the memory the system has left while a phase runs; below ``floor`` bytes it
    kills ``pids()`` (processes this benchmark started) and says so. Keeps the least seen."""

    def __init__(self, pids, floor: float = BIG_MEMORY_FLOOR) -> None:
        import threading

        self.pids, self.floor, self.killed, self.least = pids, floor, False, float("inf")
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)

    def _poll(self) -> None:
        import signal

        while not self._stop.wait(0.25):
            left = _available()
            self.least = min(self.least, left)
            if left < self.floor and not self.killed:
                self.killed = True
                print(f"!! {left / 2**30:.1f} GiB of memory left: killing {self.pids()}", flush=True)
                for pid in self.pids():
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass

    def __enter__(self) -> "_Watchdog":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def _grid_piece(n: int, i0: int, i1: int):
    """The hexes i0 <= i < i1 (along the first grid axis) of ``synthetic.cube(n)``'s
    rotated grid, 6 tets each: (points, tets, scalars). Points and field are computed
    element by element (no matrix product, whose rounding may depend on the array's
    shape), so the pieces' shared points are bitwise equal and the whole mesh,
    ``_grid_piece(n, 0, n)``, is the pieces' union."""
    from tetvr.mesh.synthetic import _KUHN, _rotation

    g = np.linspace(-0.5, 0.5, n + 1)
    x, y, z = (a.ravel() for a in np.meshgrid(g[i0:i1 + 1], g, g, indexing="ij"))
    rot = _rotation(0.5, 0.35)
    pts = np.stack([x * rot[0, j] + y * rot[1, j] + z * rot[2, j] for j in range(3)], axis=1)
    del x, y, z
    scalars = 0.6 * pts[:, 0] + 0.3 * pts[:, 1] - 0.4 * pts[:, 2] + 0.5  # synthetic.cube's field
    idx = np.arange(pts.shape[0]).reshape(i1 - i0 + 1, n + 1, n + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(i1 - i0), np.arange(n), np.arange(n), indexing="ij"))
    corners = np.stack([idx[i + (c & 1), j + (c >> 1 & 1), k + (c >> 2 & 1)] for c in range(8)], axis=1)
    return pts, corners[:, _KUHN].reshape(-1, 4), scalars


def _write_piece(folder: str, n: int, i0: int, i1: int, k: int) -> int:
    """Piece ``k`` of the big grid written as ``piece_k.vtu`` (on a worker, as a solver
    writes its part): its tet count."""
    import meshio

    pts, tets, scalars = _grid_piece(n, i0, i1)
    meshio.Mesh(pts, [("tetra", tets)], point_data={"f": scalars}).write(
        os.path.join(folder, f"piece_{k}.vtu"), binary=True, compression=None)
    return len(tets)


def _write_pieces(c, folder: str, n: int, n_pieces: int) -> str:
    """The big grid as ``big.pvtu`` of ``n_pieces`` slabs, each written by a worker: its URL."""
    cuts = np.linspace(0, n, n_pieces + 1).round().astype(int)
    futs = [c.submit(_write_piece, folder, n, int(cuts[k]), int(cuts[k + 1]), k, pure=False) for k in range(n_pieces)]
    c.gather(futs)
    rows = "".join(f'<Piece Source="piece_{k}.vtu"/>' for k in range(n_pieces))
    with open(os.path.join(folder, "big.pvtu"), "w") as f:
        f.write('<VTKFile type="PUnstructuredGrid"><PUnstructuredGrid GhostLevel="0"><PPointData>'
                '<PDataArray type="Float64" Name="f"/></PPointData><PPoints><PDataArray type="Float64" '
                'NumberOfComponents="3"/></PPoints>' + rows + "</PUnstructuredGrid></VTKFile>")
    return "file://" + os.path.join(folder, "big.pvtu")


def _start_cluster(folder: str, n_workers: int):
    """A Dask scheduler and ``n_workers`` workers (one thread each, no nanny, no memory
    limit: nothing spilled to disk), each its own process on this machine as
    ``dask scheduler`` / ``dask worker`` start them, so that each one's memory is its own:
    (client, processes)."""
    import subprocess

    import distributed

    dask = str(Path(sys.executable).with_name("dask"))
    spec = os.path.join(folder, "scheduler.json")
    log = open(os.path.join(folder, "cluster.log"), "w")
    procs = [subprocess.Popen([dask, "scheduler", "--scheduler-file", spec, "--port", "0", "--no-dashboard"],
                              stdout=log, stderr=subprocess.STDOUT)]
    for _ in range(600):
        if os.path.isfile(spec):
            break
        time.sleep(0.1)
    else:
        procs[0].kill()
        raise RuntimeError(f"the Dask scheduler did not start in 60 s: see {log.name}")
    procs += [subprocess.Popen([dask, "worker", "--scheduler-file", spec, "--nthreads", "1", "--no-nanny",
                                "--memory-limit", "0", "--no-dashboard", "--name", f"w{k}"],
                               stdout=log, stderr=subprocess.STDOUT) for k in range(n_workers)]
    try:
        client = distributed.Client(scheduler_file=spec, timeout=120)
        client.wait_for_workers(n_workers, timeout=120)
    except Exception:
        for p in procs:
            p.kill()
        raise
    return client, procs


def _stop_cluster(client, procs) -> None:
    """Close the scheduler and its workers (a worker without a nanny outlives SIGTERM
    while its scheduler is gone: what is still running after 30 s is killed)."""
    import contextlib

    with contextlib.suppress(Exception):
        client.shutdown()
    with contextlib.suppress(Exception):
        client.close()
    for p in procs:
        try:
            p.wait(timeout=30)
        except Exception:
            p.kill()
            p.wait()


def _big_cluster(args: argparse.Namespace, n: int, folder: str) -> tuple[dict, list, list, object]:
    """The big mesh written as pieces by the workers, made into bricks on them
    (``distribute_pieces``) and rendered there, composited on the workers: times, bytes
    the client receives, each process's peak memory; the frames, views and transfer function."""
    from tetvr import RenderSettings, TransferFunction
    from tetvr.apps.animate import orbit
    from tetvr.cluster.distributed import distribute_pieces
    from tetvr.core.camera import Camera

    size = (args.big_size, args.big_size)
    client, procs = _start_cluster(folder, 2)
    out: dict = {"workers": 2, "bricks": BIG_BRICKS, "pieces": BIG_PIECES, "size": list(size),
                 "load_average_1_5_15_min": {"start": os.getloadavg()}}
    try:
        with _Watchdog(lambda: [p.pid for p in procs]) as dog:
            t = time.perf_counter()
            url = _write_pieces(client, folder, n, BIG_PIECES)
            out["write_pieces_s"] = time.perf_counter() - t
            out["pieces_bytes"] = sum(os.path.getsize(os.path.join(folder, f"piece_{k}.vtu"))
                                      for k in range(BIG_PIECES))
            out["worker_peak_rss_mib_writing_pieces"] = sorted(client.run(_reset_peak_rss).values())
            _reset_peak_rss()  # the client's peak from here on
            client.run_on_scheduler(_reset_peak_rss)
            t = time.perf_counter()
            bricks = distribute_pieces(url, BIG_BRICKS, client)
            out["distribute_s"] = time.perf_counter() - t
            out["worker_peak_rss_mib_distribute"] = sorted(client.run(_peak_rss_mib).values())
            out["n_tets"] = int(bricks.whole.n_tets)
            out["brick_tets"] = [bricks.brick_tets[i] for i in sorted(bricks.brick_tets)]
            lo, hi = bricks.whole.scalar_range
            tf = TransferFunction.preset("viridis", (lo, hi), opacity=0.5, unit_distance=0.2)
            views = orbit(Camera.fit(bricks.whole), 1 + args.views, degrees=40.0)
            out["method"] = bricks.settings_for(RenderSettings(), views[0], size).method
            images, times = [], []
            for cam in views:
                before = client.run(_transfer_log)
                t = time.perf_counter()
                images.append(bricks.render(cam, tf, size=size))
                times.append(time.perf_counter() - t)
                out.setdefault("client_received_bytes", []).append(_moved(client, before)[0])
                print(f"big, {BIG_BRICKS} bricks on 2 workers: frame {len(times)} {times[-1]:.1f} s", flush=True)
            out["first_frame_s"], out["view_change_s"] = times[0], times[1:]
            out["view_change_median_s"] = float(np.median(times[1:]))
            out["worker_rss_mib_held"] = sorted(client.run(_rss_mib).values())
            out["worker_peak_rss_mib"] = sorted(client.run(_peak_rss_mib).values())
            out["scheduler_peak_rss_mib"] = client.run_on_scheduler(_peak_rss_mib)
            out["client_peak_rss_mib"] = _peak_rss_mib()
            out["load_average_1_5_15_min"]["end"] = os.getloadavg()
            bricks.release()
        out["least_available_gib"] = dog.least / 2**30
        if dog.killed:
            raise MemoryError(f"the cluster's processes were killed: under {BIG_MEMORY_FLOOR / 2**30:.1f} GiB left")
    finally:
        _stop_cluster(client, procs)
    return out, images, views, tf


def _single_run(n: int, views: list, tf, size: tuple[int, int], method: str, folder: str) -> None:
    """In a process of its own: the whole grid made here and rendered with the views; its
    times, peak memory and frames written to ``folder``."""
    import json

    from tetvr import RenderSettings, TetMesh
    from tetvr.gl import Renderer

    t = time.perf_counter()
    mesh = TetMesh.from_arrays(*_grid_piece(n, 0, n))
    made = time.perf_counter() - t
    times, images = [], []
    with Renderer(RenderSettings(method=method)) as r:
        for cam in views:
            t = time.perf_counter()
            images.append(r.render(mesh, cam, tf, size=size))
            times.append(time.perf_counter() - t)
            print(f"big, one process: frame {len(times)} {times[-1]:.1f} s", flush=True)
    np.save(os.path.join(folder, "single.npy"), np.stack(images))
    Path(folder, "single.json").write_text(json.dumps({
        "n_tets": mesh.n_tets, "make_s": made, "first_frame_s": times[0], "view_change_s": times[1:],
        "peak_rss_mib": _peak_rss_mib()}))


def _big_single(n: int, views: list, tf, size: tuple[int, int], method: str, folder: str) -> tuple[dict, object]:
    """:func:`_single_run` in a spawned process, killed if memory runs low."""
    import json
    import multiprocessing

    proc = multiprocessing.get_context("spawn").Process(target=_single_run, args=(n, views, tf, size, method, folder))
    load = {"start": os.getloadavg()}
    with _Watchdog(lambda: [proc.pid]) as dog:
        proc.start()
        proc.join()
    load["end"] = os.getloadavg()
    if dog.killed or proc.exitcode != 0:
        return {"failed": f"exit code {proc.exitcode}" + (", killed: memory ran low" if dog.killed else ""),
                "least_available_gib": dog.least / 2**30}, None
    out = json.loads(Path(folder, "single.json").read_text())
    out["view_change_median_s"] = float(np.median(out["view_change_s"]))
    out["least_available_gib"] = dog.least / 2**30
    out["method"] = method
    out["load_average_1_5_15_min"] = load
    return out, np.load(os.path.join(folder, "single.npy"))


def big(args: argparse.Namespace) -> dict:
    """One run: the ~``args.big``-tet grid from solver pieces as 8 bricks on a cluster of
    2 worker processes (and a scheduler process), then the same frames by one process
    (the largest grid that fits where the whole one would not), the ratio and the
    composite's difference from the single image."""
    _reset_peak_rss()
    n = max(2, round((args.big / 6) ** (1 / 3)))
    start = {"available_gib": _available() / 2**30, "load_average_1_5_15_min": os.getloadavg()}
    with tempfile.TemporaryDirectory(prefix="tetvr-big-") as folder:
        cluster, frames, views, tf = _big_cluster(args, n, folder)
        size = tuple(cluster["size"])
        # The single process needs the whole mesh and its records: the largest grid that fits.
        room = _available() - 2 * BIG_MEMORY_FLOOR
        n_single = n
        while n_single > 2 and 6 * n_single**3 * BIG_BYTES_PER_TET > room:
            n_single -= 1
        single, images = _big_single(n_single, views, tf, size, cluster["method"], folder)
    out: dict = {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"), "grid_n": n,
                 "start": start, "cluster": cluster, "single": single,
                 "single_same_mesh": n_single == n, "load_average_end": os.getloadavg(),
                 "estimated_single_bytes_per_tet": BIG_BYTES_PER_TET}
    if n_single != n:
        out["single_note"] = (f"the whole {cluster['n_tets']:,}-tet mesh would not fit in one process here "
                              f"({start['available_gib']:.1f} GiB available): measured at "
                              f"{single.get('n_tets', 0):,} tets")
    if images is not None and n_single == n:
        diff = np.abs(np.stack(frames) - images)
        out["accuracy"] = {"max_abs_diff": float(diff.max()),
                           "max_abs_diff_per_view": diff.max(axis=(1, 2, 3)).tolist(),
                           "pixels_over_1e-5": int((diff.max(axis=-1) > 1e-5).sum()),
                           "pixels_over_1_255": int((diff.max(axis=-1) > 1 / 255).sum()),
                           "pixels": int(diff.shape[0] * diff.shape[1] * diff.shape[2])}
        out["ratio"] = {"first_frame": single["first_frame_s"] / cluster["first_frame_s"],
                        "view_change": single["view_change_median_s"] / cluster["view_change_median_s"]}
    print(f"big: {cluster['n_tets']:,} tets: cluster first {cluster['first_frame_s']:.1f} s, view "
          f"{cluster['view_change_median_s']:.1f} s; one process {single}", flush=True)
    return out


def chart_big(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    b = result["big"]
    c, s = b["cluster"], b["single"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    one = f"one process ({s['n_tets'] / 1e6:.1f}M tets)" if "n_tets" in s else "one process (failed)"
    labels = ["first frame", "per view change"]
    x = np.arange(2)
    ax[0].bar(x - 0.2, [c["first_frame_s"], c["view_change_median_s"]], 0.4, color="#2a9d8f",
              label=f"{c['bricks']} bricks on {c['workers']} workers")
    if "n_tets" in s:
        ax[0].bar(x + 0.2, [s["first_frame_s"], s["view_change_median_s"]], 0.4, color="#888", label=one)
    ax[0].set_xticks(x, labels)
    ax[0].set_ylabel("s")
    ax[0].set_title(f"{c['n_tets'] / 1e6:.1f}M tets at {c['size'][0]}x{c['size'][1]} ({c['method']})")
    ax[0].legend()
    names = (["client", "scheduler"] + [f"worker {k}" for k in range(len(c["worker_peak_rss_mib"]))]
             + (["one process"] if "peak_rss_mib" in s else []))
    peaks = ([c["client_peak_rss_mib"], c["scheduler_peak_rss_mib"], *c["worker_peak_rss_mib"]]
             + ([s["peak_rss_mib"]] if "peak_rss_mib" in s else []))
    ax[1].bar(names, [p / 1024 for p in peaks], color=["#3b75af", "#3b75af"] + ["#2a9d8f"] * len(
        c["worker_peak_rss_mib"]) + ["#888"] * ("peak_rss_mib" in s))
    ax[1].set_ylabel("peak resident memory, GiB")
    ax[1].set_title("peak memory per process")
    fig.suptitle(f"one mesh from {c['pieces']} solver pieces, on a cluster against one process "
                 f"({result['machine'].get('cpu_count', '?')} cores shared by all, {b['date'][:10]})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def chart_compositing(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = result["compositing"]
    big = max((x["size"][0] * x["size"][1] for x in r["cases"]))
    cases = [x for x in r["cases"] if x["size"][0] * x["size"][1] == big]
    ps = [x["P"] for x in cases]
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    for mode, colour in (("client", "#888"), ("workers", "#2a9d8f")):
        label = "all images to the client" if mode == "client" else "radix-k on the workers"
        ax[0].plot(ps, [x[mode]["workers_to_client_bytes"] / 2**20 for x in cases], "o-", color=colour, label=label)
        ax[1].plot(ps, [x[mode]["best_s"] for x in cases], "o-", color=colour, label=label)
        if "frames" in result:
            f = result["frames"]["P"]
            fp = sorted(f, key=int)
            ax[2].plot([int(p) for p in fp], [f[p]["median_s"][mode] for p in fp], "o-", color=colour, label=label)
    w, h = cases[0]["size"]
    ax[0].set_title(f"client receives ({w}x{h} float RGBA)")
    ax[0].set_ylabel("MiB")
    ax[1].set_title(f"compositing ({w}x{h}, images on workers)")
    ax[1].set_ylabel("s")
    if "frames" in result:
        fw, fh = result["frames"]["size"]
        ax[2].set_title(f"whole frame ({result['frames']['n_tets']:,} tets, {fw}x{fh})")
    ax[2].set_ylabel("s")
    for a in ax:
        a.set_xscale("log", base=2)
        a.set_xticks(ps, [str(p) for p in ps])
        a.set_xlabel("bricks P (2 workers)")
        a.legend()
    fig.suptitle(f"compositing on the client and on the workers ({result['machine'].get('cpu_count', '?')} cores, "
                 f"{r['date'][:10]})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def chart(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    s = result["series"]["workers"]
    labels = ["serial"] + [f"Dask, {k} worker{'s' if k != '1' else ''}" for k in s]
    fps = [s["1"]["serial_frames_per_s"]] + [v["dask_frames_per_s"] for v in s.values()]
    ax[0].bar(labels, fps, color=["#888", "#3b75af", "#2a9d8f"][:len(fps)])
    ax[0].set_ylabel("frames / s")
    ax[0].set_title(f"time series ({result['series']['mesh_tets']:,} tets per step)")
    for res in result["bricks"]:
        ps = sorted(res["P"], key=int)
        ax[1].plot([int(p) for p in ps], [res["P"][p]["view_change_median_s"] for p in ps], "o-",
                   label=f"{res['n_tets'] / 1e6:.1f}M tets")
        ax[2].plot([int(p) for p in ps], [max(res["P"][p]["worker_peak_rss_mib"]) for p in ps], "o-",
                   label=f"{res['n_tets'] / 1e6:.1f}M tets")
    for a, title, unit in ((ax[1], "bricks: time per view change", "s"),
                           (ax[2], "bricks: peak memory per worker", "MiB")):
        a.set_xscale("log", base=2)
        a.set_yscale("log")
        a.set_xticks([1, 2, 4, 8], ["1", "2", "4", "8"])
        a.set_xlabel("bricks P (2 workers)")
        a.set_ylabel(unit)
        a.set_title(title)
        a.legend()
    fig.suptitle(f"tetvr on Dask ({result['machine'].get('cpu_count', '?')} cores, {result['date'][:10]})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller series and images")
    ap.add_argument("--tets", default="1e6", help="brick mesh sizes, comma separated (default 1e6; add 1e7)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--bricks-p", default="1,2,4,8", help="brick counts (default 1,2,4,8)")
    ap.add_argument("--views", type=int, default=3, help="view changes timed after the first frame (default 3)")
    ap.add_argument("--composite-p", default="2,4,8,16", help="brick counts for compositing (default 2,4,8,16)")
    ap.add_argument("--only", default="series,composite,bricks,accuracy,compositing,frames",
                    help="parts to run (and big: --only big)")
    ap.add_argument("--big", type=float, default=1e7, help="tets of the big run (default 1e7)")
    ap.add_argument("--big-size", type=int, default=512, help="the big run's image side (default 512)")
    ap.add_argument("--out", default=str(_HERE / "results"))
    args = ap.parse_args()
    common = _common()
    path = Path(args.out) / "distributed.json"
    result: dict = {}
    if path.is_file():  # parts not run this time keep their last numbers
        import json

        result = json.loads(path.read_text())
    only = args.only.split(",")
    result["machine"] = common.machine()
    own_date = {"accuracy", "compositing", "frames", "big"}  # parts that carry their own date
    if set(only) - own_date:  # the date of the other timed parts
        result["date"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    load = {"start": os.getloadavg()}  # other jobs on the machine: what the seconds shared it with
    if "series" in only:
        result["series"] = series(args)
    if "composite" in only:
        result["composite"] = composite()
    if "bricks" in only:
        for x in args.tets.split(","):
            res = bricks(args, float(x))
            kept = [b for b in result.get("bricks", []) if abs(b["n_tets"] - res["n_tets"]) > 1]
            result["bricks"] = sorted(kept + [res], key=lambda b: b["n_tets"])  # other sizes keep their last run
            common.write_json(path, result)  # each size as it is done
    if "compositing" in only:
        start = os.getloadavg()
        result["compositing"] = compositing(args)
        result["compositing"]["load_average_1_5_15_min"] = {"start": start, "end": os.getloadavg()}
        common.write_json(path, result)
    if "frames" in only:
        result["frames"] = frames(args)
        result["frames"]["date"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    if "accuracy" in only:
        result["accuracy"] = accuracy(args)
    if "big" in only:
        result["big"] = big(args)
    load["end"] = os.getloadavg()
    if set(only) - own_date:  # the load the timed parts shared the machine with
        result["load_average_1_5_15_min"] = load
    common.write_json(path, result)
    if all(k in result for k in ("series", "bricks")):
        chart(result, path.with_suffix(".png"))
    if "big" in result:
        chart_big(result, path.with_name("distributed_big.png"))
    if "compositing" in result:
        chart_compositing(result, path.with_name("distributed_compositing.png"))
    print(f"-> {path}")


if __name__ == "__main__":
    main()

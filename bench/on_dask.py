"""Time series and sort-last bricks on Dask, against a serial loop in the same run.

(Named on_dask.py, not distributed.py: run as a script, this folder comes first on
``sys.path`` and a ``distributed.py`` here would hide the ``distributed`` package.)

Series: S steps of a synthetic mesh written as ``.vtu`` files, each read and rendered
(256x256, the default renderer); a plain serial loop in this process against
:func:`tetvr.distributed.render_series` on a 2-worker ``LocalCluster``, alternated for R
rounds (the best of each is kept: on a shared machine the rounds differ). Dask's own cost
per frame: a trivial frame (one tet, 8x8) through the same path, minus the same frame
rendered here.

Bricks: the compositing cost alone (:func:`tetvr.distributed.composite_over` of P images),
per pixel per brick, and :func:`tetvr.distributed.kd_bricks` on the mesh (cells cut).

Writes ``<out>/on_dask.json`` and prints a summary. Ratios carry between machines;
seconds are this machine's.

Usage::

    python bench/on_dask.py [--quick] [--out bench/results] [--rounds R]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import machine, write_json  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer, smaller steps")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()

    import meshio

    import tetvr
    from tetvr import Camera, TransferFunction, synthetic
    from tetvr.distributed import cluster_client, composite_over, kd_bricks, render_series
    from tetvr.gl import Renderer

    n_cube, n_steps, size = (12, 8, (128, 128)) if args.quick else (20, 16, (256, 256))
    mesh = synthetic.cube(n_cube)
    out: dict = {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"), "machine": machine(),
                 "mesh_tets": mesh.n_tets, "steps": n_steps, "size": list(size)}
    with tempfile.TemporaryDirectory() as tmp:
        files = []
        for k in range(n_steps):
            files.append(os.path.join(tmp, f"s{k}.vtu"))
            meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"f": mesh.scalars * (1 + 0.1 * k)}).write(files[-1])
        cam = Camera.fit(mesh)
        tf = TransferFunction.preset("viridis", (mesh.scalar_range[0], mesh.scalar_range[1] * (1 + 0.1 * n_steps)),
                                     unit_distance=0.1)
        tiny = synthetic.single_tet()
        tcam, ttf = Camera.fit(tiny), TransferFunction.preset("viridis", (0, 1))
        rounds: list[dict] = []
        with Renderer() as r, cluster_client(n_workers=2) as c:
            c.wait_for_workers(2)
            render_series(files[:2], camera=cam, tf=tf, size=size, client=c, progress=False)  # warm-up
            r.render(tetvr.read(files[0]), cam, tf, size=size)
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
                rounds.append({"serial_s": t_serial, "dask2_s": t_dask, "trivial32_serial_s": t_tiny,
                               "trivial32_dask_s": t_tiny_dask,
                               "identical": all(np.array_equal(a, b) for a, b in zip(frames, serial))})
                print(f"serial {t_serial:.2f} s, 2 workers {t_dask:.2f} s; trivial x32 {t_tiny:.3f} / {t_tiny_dask:.3f} s",
                      flush=True)
        best_s, best_d = min(x["serial_s"] for x in rounds), min(x["dask2_s"] for x in rounds)
        overhead = (min(x["trivial32_dask_s"] for x in rounds) - min(x["trivial32_serial_s"] for x in rounds)) / 32
        out["series"] = {"rounds": rounds, "best_serial_s_per_frame": best_s / n_steps,
                         "best_dask2_s_per_frame": best_d / n_steps, "speedup_2_workers": best_s / best_d,
                         "dask_overhead_s_per_frame": overhead}
    # Compositing alone, and the k-d split (cells cut at the planes).
    bricks = {}
    rng = np.random.default_rng(0)
    for p in (2, 4, 8):
        imgs = [rng.random((512, 512, 4), dtype=np.float32) * 0.5 for _ in range(p)]
        t = time.perf_counter()
        composite_over(imgs)
        t_comp = time.perf_counter() - t
        t = time.perf_counter()
        tree = kd_bricks(synthetic.cube(n_cube), p)
        t_split = time.perf_counter() - t
        bricks[str(p)] = {"composite_ns_per_pixel_per_brick": t_comp / (512 * 512 * p) * 1e9, "kd_split_s": t_split,
                          "cells_cut": tree.n_cut, "brick_tets": [len(b.tets) for b in tree.bricks()]}
    out["bricks"] = bricks
    path = Path(args.out) / "on_dask.json"
    write_json(path, out)
    s = out["series"]
    print(f"series: {s['best_serial_s_per_frame']:.3f} s/frame serial, {s['best_dask2_s_per_frame']:.3f} s/frame on "
          f"2 workers ({s['speedup_2_workers']:.2f}x); Dask overhead {s['dask_overhead_s_per_frame'] * 1e3:.1f} ms/frame "
          f"-> {path}")


if __name__ == "__main__":
    main()

"""Meshing study: how many cells does a view need?

One surface (a unit icosphere), one view, one smooth field with detail at a few scales.
fTetWild (``tetvr.mesh.meshing.tetrahedralize``) meshes the sphere at target edge lengths of
``pixels_per_cell`` pixel footprints; every mesh gets the same analytic field at its points.
For each mesh we measure

* **mesh error**: the exact CPU reference image of the mesh against the reference image
  of a much finer mesh (the stand-in for the continuous field): what the cell size costs;
* **method error**: the GPU image against the same mesh's reference image: what the
  projected-tetrahedra renderer itself costs (table, float32, rasterisation);
* **total error**: the GPU image against the fine mesh's reference: what a user sees;
* **GPU frame time** (median wall time of repeated frames after a warm-up) and the cells.

More cells stop paying once the mesh error falls below the larger of the method error and
the 8-bit display quantum (uniform quantisation noise of a 1/255 step, RMSE 1/255/sqrt(12)):
past that, the total error no longer moves and the frame time keeps growing.

    python bench/meshing_study.py [--quick] [--size 64] [--out bench/results]

Needs the ``mesh`` extra (pytetwild, trimesh) and matplotlib. Writes
``meshing_study.json`` and ``meshing_study.png``. Takes about 3 minutes on 2 cores
(``--quick``: under a minute, coarser levels and a coarser "fine" mesh).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _common import loadavg, machine  # noqa: E402

import tetvr  # noqa: E402
from tetvr import Camera, TransferFunction  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402
from tetvr.core.image import psnr, rmse  # noqa: E402
from tetvr.mesh.meshing import pixel_footprint, tetrahedralize  # noqa: E402
from tetvr.reference.tets import render_reference  # noqa: E402

QUANTUM_RMSE = 1.0 / 255.0 / np.sqrt(12.0)


def field(p: np.ndarray) -> np.ndarray:
    """Smooth, with wavelengths of ~2, ~1.2 and ~0.5 world units (the sphere's radius is 1)."""
    r = np.linalg.norm(p, axis=1)
    return np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1]) + 0.5 * np.sin(5 * p[:, 2] + p[:, 0]) + 0.25 * np.sin(12 * r)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="coarser levels and fine mesh (under a minute)")
    ap.add_argument("--size", type=int, default=64, help="image width and height in pixels")
    ap.add_argument("--repeats", type=int, default=7, help="timed GPU frames per mesh")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = ap.parse_args()
    import trimesh

    size = (args.size, args.size)
    args.out.mkdir(parents=True, exist_ok=True)
    surface = trimesh.creation.icosphere(subdivisions=4 if not args.quick else 3)
    box = synthetic.cube(1, size=2.0, rotate=False)  # the sphere's bounding box, to fit the camera
    camera = Camera.fit(box, direction=(-1.0, -0.6, -1.2), zoom=1.3)
    foot = pixel_footprint(camera, size, surface.vertices)
    levels = [24.0, 12.0, 6.0, 3.0] if args.quick else [16.0, 8.0, 4.0, 2.8, 2.4, 2.0]
    fine_ppc = 2.0 if args.quick else 1.25
    print(f"view {size[0]}x{size[1]}, pixel footprint at the sphere {foot:.4f} (world units)")

    def mesh_at(ppc: float):
        res = tetrahedralize(surface, camera=camera, size=size, pixels_per_cell=ppc, field=field)
        print(f"  {ppc:5.2f} px: {res.summary()}", flush=True)
        return res

    print("fine mesh (the stand-in for the continuous field):")
    fine = mesh_at(fine_ppc)
    lo, hi = fine.mesh.scalar_range
    tf = TransferFunction.preset("viridis", (lo, hi), opacity=[(0.0, 0.02), (0.45, 0.35), (0.6, 0.05), (1.0, 0.7)],
                                 unit_distance=0.5)
    t = time.perf_counter()
    truth = render_reference(fine.mesh, camera, tf, size)
    print(f"  reference image of the fine mesh: {time.perf_counter() - t:.1f} s")

    load_before = loadavg()
    rows = []
    with tetvr.Renderer() as renderer:
        renderer.render(fine.mesh, camera, tf, size=size)  # compile and warm up
        for ppc in levels:
            res = mesh_at(ppc)
            ref = render_reference(res.mesh, camera, tf, size)
            gpu = renderer.render(res.mesh, camera, tf, size=size)
            times = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                renderer.render(res.mesh, camera, tf, size=size)
                times.append(time.perf_counter() - t)
            row = {
                "pixels_per_cell": ppc, "edge_length": res.edge_length, "cells": res.n_cells, "points": res.n_points,
                "estimated_cells": res.estimated_cells, "seconds_meshing": res.seconds_meshing,
                "gpu_ms": 1e3 * statistics.median(times), "gpu_ms_samples": [1e3 * x for x in times],
                "mesh_rmse": rmse(ref, truth), "method_rmse": rmse(gpu, ref), "total_rmse": rmse(gpu, truth),
                "mesh_psnr": psnr(ref, truth), "method_psnr": psnr(gpu, ref), "total_psnr": psnr(gpu, truth),
            }
            rows.append(row)
            print(f"     mesh error {row['mesh_rmse']:.2e}, method {row['method_rmse']:.2e}, "
                  f"total {row['total_rmse']:.2e}; GPU {row['gpu_ms']:.1f} ms", flush=True)
            if ppc == levels[-1]:
                tetvr.write_png(gpu, args.out / "meshing_study_gpu.png", background=(1, 1, 1))
        fine_gpu = renderer.render(fine.mesh, camera, tf, size=size)
        fine_row = {"pixels_per_cell": fine_ppc, "edge_length": fine.edge_length, "cells": fine.n_cells,
                    "seconds_meshing": fine.seconds_meshing, "method_rmse": rmse(fine_gpu, truth)}
        gl = renderer.gl_info

    # Where more cells stop paying: the first level whose mesh error is below the floor.
    paying = None
    for row in rows:
        floor = max(row["method_rmse"], QUANTUM_RMSE)
        row["floor_rmse"] = floor
        if paying is None and row["mesh_rmse"] <= floor:
            paying = row["pixels_per_cell"]
    # The cell count where the mesh error crosses the 8-bit quantum, log-log interpolated.
    crossing = None
    for r0, r1 in zip(rows[:-1], rows[1:]):
        e0, e1 = r0["mesh_rmse"], r1["mesh_rmse"]
        if e0 > QUANTUM_RMSE >= e1 and e0 > e1 > 0:
            f = np.log(e0 / QUANTUM_RMSE) / np.log(e0 / e1)
            crossing = {"cells": float(np.exp(np.log(r0["cells"]) + f * np.log(r1["cells"] / r0["cells"]))),
                        "gpu_ms": float(np.exp(np.log(r0["gpu_ms"]) + f * np.log(r1["gpu_ms"] / r0["gpu_ms"]))),
                        "pixels_per_cell": float(np.exp(np.log(r0["pixels_per_cell"])
                                                        + f * np.log(r1["pixels_per_cell"] / r0["pixels_per_cell"])))}
    verdict = (f"mesh error falls below max(method error, 8-bit quantum) at {paying} px per cell"
               if paying is not None else "mesh error stays above the floor at every level measured: finer still pays")
    if crossing:
        verdict += (f"; it crosses the quantum near {crossing['pixels_per_cell']:.2g} px per cell, "
                    f"~{crossing['cells'] / 1e3:.0f}k cells, ~{crossing['gpu_ms']:.0f} ms")
    print(verdict)

    out = {
        "about": __doc__.split("\n\n")[0],
        "surface": {"kind": "icosphere", "faces": int(len(surface.faces)), "radius": 1.0},
        "view": {"size": list(size), "camera": camera.to_dict(), "pixel_footprint": foot},
        "transfer_function": tf.to_dict(),
        "fine": fine_row, "levels": rows, "quantum_rmse": QUANTUM_RMSE, "stops_paying_at_pixels_per_cell": paying,
        "quantum_crossing": crossing,
        "verdict": verdict, "gl": gl,
        # llvmpipe renders on the CPU: other processes show up in the GPU times (see bench/README.md).
        "machine": {**machine(), "cpus": os.cpu_count(), "load_average_before": load_before,
                    "load_average_after": loadavg()},
        "quick": args.quick,
    }
    (args.out / "meshing_study.json").write_text(json.dumps(out, indent=2, default=str))
    chart(out, args.out / "meshing_study.png")
    print(f"wrote {args.out / 'meshing_study.json'} and meshing_study.png")


def chart(out: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = out["levels"]
    cells = [r["cells"] for r in rows]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.3))
    for key, label, style in (("mesh_rmse", "mesh error (reference vs fine mesh)", "o-"),
                              ("method_rmse", "method error (GPU vs reference, same mesh)", "s--"),
                              ("total_rmse", "total (GPU vs fine mesh)", "^-")):
        a.loglog(cells, [r[key] for r in rows], style, label=label)
    a.axhline(out["quantum_rmse"], color="grey", lw=1, ls=":", label="8-bit quantum")
    for r in rows:
        a.annotate(f"{r['pixels_per_cell']:g} px", (r["cells"], r["mesh_rmse"]), textcoords="offset points",
                   xytext=(4, 4), fontsize=8)
    a.set_xlabel("cells")
    a.set_ylabel("RMSE, premultiplied RGB")
    a.set_title(f"error vs cells ({out['view']['size'][0]}x{out['view']['size'][1]}, sphere)")
    a.legend(fontsize=8, loc="lower left")
    b.loglog([r["gpu_ms"] for r in rows], [r["total_rmse"] for r in rows], "^-", color="C2")
    for r in rows:
        b.annotate(f"{r['cells'] / 1e3:.0f}k", (r["gpu_ms"], r["total_rmse"]), textcoords="offset points",
                   xytext=(4, 4), fontsize=8)
    b.axhline(out["quantum_rmse"], color="grey", lw=1, ls=":")
    b.set_xlabel(f"GPU frame, ms ({out['gl'].get('GL_RENDERER', 'GL')})")
    b.set_ylabel("total RMSE")
    b.set_title("error vs frame time")
    fig.suptitle(out["verdict"], fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()

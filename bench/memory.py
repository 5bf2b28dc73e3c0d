"""Memory per tet: peak host memory and GPU memory of one frame, from 100k to 10M tets.

    python bench/memory.py [--max-tets 10000000] [--out bench/results]

Each mesh size runs in its own process (peak RSS is per process): it builds the mesh
(synthetic cube), renders one 512x512 frame, and reports the process's peak resident
memory and the bytes the renderer holds on the GPU (points, cells or their chunk, per-view
fans and order, the table, the target). Meshes beyond one storage buffer are drawn in
sorted chunks, so GPU memory stops growing with the mesh. For comparison: EnSight quotes
100 MB of video memory per million tets.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

from _common import machine

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, {root!r})
import tetvr
from tetvr import Camera
from tetvr.mesh import synthetic
from tetvr.render import default_transfer_function
n = {n}
t0 = time.perf_counter()
mesh = synthetic.cube(n)
t1 = time.perf_counter()
tf = default_transfer_function(mesh, opacity=0.3)
with tetvr.Renderer() as r:
    img = r.render(mesh, Camera.fit(mesh), tf, size=(512, 512))
    gpu = r.gpu_bytes()
    chunked = r._cells.chunked
    info = r.gl_info
t2 = time.perf_counter()
print(json.dumps(dict(n_tets=mesh.n_tets, n_points=mesh.n_points, peak_rss=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
                      gpu_bytes=gpu, chunked=chunked, build_s=t1 - t0, first_frame_s=t2 - t1, gl=info,
                      finite=bool((img == img).all()))))
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-tets", type=float, default=3.5e6)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    from tqdm import tqdm

    sizes = [n for n in (26, 55, 80, 119) if 6 * n**3 <= args.max_tets]
    rows = []
    try:
        for n in tqdm(sizes, desc="mesh sizes"):
            out = subprocess.run([sys.executable, "-c", CHILD.format(root=str(ROOT), n=n)], capture_output=True,
                                 text=True, check=True)
            row = json.loads(out.stdout.strip().splitlines()[-1])
            row["host_bytes_per_tet"] = row["peak_rss"] / row["n_tets"]
            row["gpu_bytes_per_tet"] = row["gpu_bytes"] / row["n_tets"]
            rows.append(row)
            print(f"{row['n_tets']:>10,d} tets: peak host {row['peak_rss'] / 2**20:7.0f} MiB "
                  f"({row['host_bytes_per_tet']:.0f} B/tet), GPU {row['gpu_bytes'] / 2**20:6.0f} MiB "
                  f"({row['gpu_bytes_per_tet']:.1f} B/tet = {row['gpu_bytes_per_tet']:.1f} MB per million), "
                  f"chunked={row['chunked']}, first frame {row['first_frame_s']:.1f} s")
    except KeyboardInterrupt:
        print("interrupted: writing what was measured")
    outdir = Path(args.out)
    outdir.mkdir(parents=True, exist_ok=True)
    report = {"created": time.strftime("%Y-%m-%dT%H:%M:%S"), "platform": platform.platform(), "machine": machine(),
              "rows": rows, "reference": "EnSight: 100 MB of video memory per million tets"}
    (outdir / "memory.json").write_text(json.dumps(report, indent=1))
    print(f"wrote {outdir / 'memory.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

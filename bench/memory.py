"""Memory per tet: peak host memory and GPU memory of one frame, and tet marching's peak,
stage by stage, against VTK's projected tetrahedra on the same ~2M tets.

    python bench/memory.py [--max-tets 3.5e6] [--compare 69] [--runs 3] [--tree DIR] [--out bench/results]

Sizes: each mesh size runs in its own process (peak RSS is per process): it builds the mesh
(synthetic cube), renders one 512x512 frame, and reports the process's peak resident
memory and the bytes the renderer holds on the GPU (points, cells or their chunk, per-view
fans and order, the table, the target). Meshes beyond one storage buffer are drawn in
sorted chunks, so GPU memory stops growing with the mesh. For comparison: EnSight quotes
100 MB of video memory per million tets.

Against VTK (``--compare n``: ``synthetic.cube(n)``, 6 n^3 tets; 69 gives 1,971,054), one
512x512 frame from ``Camera.fit`` with ``default_transfer_function(opacity=0.3)``, each in a
fresh process, its peak resident memory (``VmHWM``; the median of ``--runs`` processes):

* tet marching (``method="raymarch"``) and projected tetrahedra (``method="projected"``): a
  process that builds the mesh, its transfer function and a renderer, and renders;
* the same tet-marching frame stage by stage, one stage after the other on one thread, the
  peak reset (``/proc/self/clear_refs``) as each starts: the peak while it ran and what is
  resident after it (the mesh with its canonical form; the transfer function; the GL
  context; the walk check with the face adjacency; the records the walk keeps per mesh; the
  table; the first frame, which builds the per-tet records block by block into their
  textures, then draws);
* VTK's ``vtkProjectedTetrahedraMapper`` in the child process of
  :class:`tetvr.apps.vtkrender.VTKProcess`, which receives the mesh's arrays over a pipe,
  makes a ``vtkUnstructuredGrid`` of them and renders (its peak, read from ``/proc``).

``--tree DIR`` measures another checkout of tetvr (an older commit, unpacked) in the
children instead of this one. Linux only (``/proc``).
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

# One frame by one method, the whole process's peak (the records built beside the table, as a
# frame builds them).
WHOLE = r"""
import json, sys, time
sys.path.insert(0, {root!r})
import tetvr
from tetvr import Camera, RenderSettings
from tetvr.mesh import synthetic
from tetvr.render import default_transfer_function

def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key + ":"))

mesh = synthetic.cube({n})
tf = default_transfer_function(mesh, opacity=0.3)
t0 = time.perf_counter()
with tetvr.Renderer(RenderSettings(method={method!r})) as r:
    img = r.render(mesh, Camera.fit(mesh), tf, size=(512, 512))
    seconds = time.perf_counter() - t0
    rss = status("VmRSS")
print(json.dumps(dict(n_tets=mesh.n_tets, peak_rss=status("VmHWM"), rss_after=rss, first_frame_s=seconds,
                      alpha_max=float(img[..., 3].max()))))
"""

# The tet-marching frame stage by stage, each stage's peak on its own.
STAGES = r"""
import json, sys, time
sys.path.insert(0, {root!r})
import tetvr
from tetvr import Camera, RenderSettings
from tetvr.mesh import synthetic
from tetvr.order.walkable import walk_check
from tetvr.render import default_transfer_function

def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key + ":"))

rows = []
def stage(name, fn):
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # the resident peak back to what is resident now
    t0 = time.perf_counter()
    out = fn()
    rows.append(dict(stage=name, peak_rss=status("VmHWM"), rss_after=status("VmRSS"), seconds=time.perf_counter() - t0))
    return out

start = status("VmRSS")
mesh = stage("mesh", lambda: synthetic.cube({n}))
tf = stage("transfer function", lambda: default_transfer_function(mesh, opacity=0.3))
r = stage("renderer", lambda: tetvr.Renderer(RenderSettings(method="raymarch")))
stage("walk check", lambda: walk_check(mesh))
stage("records", lambda: (r._march.prefetch(mesh), r._march.settle(mesh, keep=True)))
stage("table", lambda: r.table(mesh, tf))
stage("first frame", lambda: r.render(mesh, Camera.fit(mesh), tf, size=(512, 512)))
r.release()
print(json.dumps(dict(n_tets=mesh.n_tets, interpreter_rss=start, stages=rows)))
"""

STAGE_WORDS = {"mesh": "`synthetic.cube`: the arrays and `TetMesh.from_arrays`' canonical form",
               "transfer function": "`default_transfer_function`: the field's volume-weighted range",
               "renderer": "`tetvr.Renderer`: the GL context",
               "walk check": "`walk_check`: the face adjacency, repeated cells, folded faces",
               "records": "`march_records`: each tet's point ids and the boundary faces",
               "table": "the pre-integration table",
               "first frame": "the first frame: the per-tet planes and links, block by block into their "
                              "textures, then the passes"}


def _child(code: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def sizes(max_tets: float, root: Path) -> list[dict]:
    """The default frame's peak memory at each cube size up to ``max_tets``."""
    from tqdm import tqdm

    rows = []
    for n in tqdm([n for n in (26, 55, 80, 119) if 6 * n**3 <= max_tets], desc="mesh sizes"):
        row = _child(CHILD.format(root=str(root), n=n))
        row["host_bytes_per_tet"] = row["peak_rss"] / row["n_tets"]
        row["gpu_bytes_per_tet"] = row["gpu_bytes"] / row["n_tets"]
        rows.append(row)
        print(f"{row['n_tets']:>10,d} tets: peak host {row['peak_rss'] / 2**20:7.0f} MiB "
              f"({row['host_bytes_per_tet']:.0f} B/tet), GPU {row['gpu_bytes'] / 2**20:6.0f} MiB "
              f"({row['gpu_bytes_per_tet']:.1f} B/tet = {row['gpu_bytes_per_tet']:.1f} MB per million), "
              f"chunked={row['chunked']}, first frame {row['first_frame_s']:.1f} s", flush=True)
    return rows


def vtk_peak(n: int, root: Path) -> dict:
    """VTK's projected tetrahedra on ``synthetic.cube(n)``: the peak resident memory of the
    :class:`~tetvr.apps.vtkrender.VTKProcess` child over its setup and first frame."""
    sys.path.insert(0, str(root))
    from tetvr import Camera
    from tetvr.apps.vtkrender import VTKProcess, VTKUnavailableError
    from tetvr.mesh import synthetic
    from tetvr.render import default_transfer_function

    mesh = synthetic.cube(n)
    tf = default_transfer_function(mesh, opacity=0.3)
    try:
        with VTKProcess(mesh, tf, mapper="pt", size=(512, 512)) as vtk:
            image = vtk.render(Camera.fit(mesh))
            status = Path(f"/proc/{vtk._proc.pid}/status").read_text().splitlines()
            peak = next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmHWM:"))
            return dict(peak_rss=peak, first_frame_s=vtk.first_seconds, version=vtk.info.get("version"),
                        alpha_max=float(image[..., 3].max()))
    except (VTKUnavailableError, RuntimeError) as exc:
        return dict(peak_rss=None, error=str(exc))


def _median_run(runs: list[dict]) -> dict:
    """The run of median peak (of an odd number), with every run's peak beside it."""
    ranked = sorted(runs, key=lambda r: r["peak_rss"] or 0)
    return dict(ranked[len(ranked) // 2], peak_rss_runs=[r["peak_rss"] for r in runs])


def against_vtk(n: int, root: Path, runs: int = 3) -> dict:
    """Tet marching's peak (whole, and stage by stage), projected tetrahedra's and VTK's, on
    ``cube(n)``; the whole processes ``runs`` times each (their peaks vary by tens of MB from
    run to run with the timing of threads, theirs and the GL's), the median kept."""
    march = _median_run([_child(WHOLE.format(root=str(root), n=n, method="raymarch")) for _ in range(runs)])
    projected = _median_run([_child(WHOLE.format(root=str(root), n=n, method="projected")) for _ in range(runs)])
    vtk = _median_run([vtk_peak(n, root) for _ in range(runs)])
    staged = _child(STAGES.format(root=str(root), n=n))
    out = dict(n=n, n_tets=march["n_tets"], size=[512, 512], runs=runs, raymarch=march, projected=projected,
               vtk_pt=vtk, interpreter_rss=staged["interpreter_rss"], stages=staged["stages"])
    if vtk["peak_rss"]:
        out["raymarch_to_vtk"] = march["peak_rss"] / vtk["peak_rss"]
        out["projected_to_vtk"] = projected["peak_rss"] / vtk["peak_rss"]
    mib = lambda b: f"{b / 2**20:.0f} MiB" if b else "-"  # noqa: E731
    print(f"{out['n_tets']:,} tets at 512x512: tet marching peak {mib(march['peak_rss'])}, projected tetrahedra "
          f"{mib(projected['peak_rss'])}, VTK's projected tetrahedra {mib(vtk['peak_rss'])}"
          + (f" (tet marching / VTK {out['raymarch_to_vtk']:.2f})" if vtk["peak_rss"] else f": {vtk.get('error')}"))
    for row in out["stages"]:
        print(f"  {row['stage']:>18}: peak {mib(row['peak_rss'])}, after {mib(row['rss_after'])}, {row['seconds']:.1f} s")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-tets", type=float, default=3.5e6)
    ap.add_argument("--compare", type=int, default=69, help="cube(n) measured against VTK (0: none)")
    ap.add_argument("--runs", type=int, default=3, help="runs of each whole process against VTK (the median kept)")
    ap.add_argument("--tree", type=Path, default=ROOT, help="the tetvr checkout the children import")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    rows: list[dict] = []
    vs_vtk = None
    try:
        rows = sizes(args.max_tets, args.tree)
        vs_vtk = against_vtk(args.compare, args.tree, args.runs) if args.compare else None
    except KeyboardInterrupt:
        print("interrupted: writing what was measured")
    outdir = Path(args.out)
    outdir.mkdir(parents=True, exist_ok=True)
    report = {"created": time.strftime("%Y-%m-%dT%H:%M:%S"), "platform": platform.platform(), "machine": machine(),
              "tree": "this checkout" if args.tree.resolve() == ROOT else str(args.tree),
              "rows": rows, "vs_vtk": vs_vtk, "stage_words": STAGE_WORDS,
              "reference": "EnSight: 100 MB of video memory per million tets"}
    (outdir / "memory.json").write_text(json.dumps(report, indent=1))
    print(f"wrote {outdir / 'memory.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

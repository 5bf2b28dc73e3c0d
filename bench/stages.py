"""Stage timings of the GPU projected-tetrahedra renderer, against its own fill-rate floor.

For meshes from ~10k to ~1M tets this renders a 512x512 perspective view
(:meth:`Camera.fit`, :func:`default_transfer_function` with opacity 0.5) with
``Renderer(profile=True)`` and records, after warm-up, the median of each per-view stage
(classify, sort, order_upload, draw, readback) over R frames (more for small meshes,
until their frames add up to MIN_TIMED_S). The first frame of each
mesh is reported on its own (upload of the mesh buffers, table build, first draw).

The peer in the same run is the *fill-rate floor*: the same mesh, camera and order drawn
with ``shader="floor"`` (constant colour, same triangles and blending). Ratios to it
(draw / floor draw, total / floor total) are what should carry between machines;
absolute seconds are only for this machine.

Also measured: the pre-integration table build (:func:`tetvr.optics.preintegrate.build_table`,
uncached, 16 slices, float32) for 128/256/512 bins, and the centroid sort alone for
~1M tets.

Writes ``<out>/stages.json`` (also after each section, and on Ctrl-C, so a partial run
keeps what it measured) and ``<out>/stages.png``, and prints a table.

Usage::

    python bench/stages.py [--quick] [--out bench/results] [--repeats R] [--data DIR]
"""

from __future__ import annotations

import argparse
import json
import datetime as _dt
import functools
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

# Meshes (CUBE_NS, REAL_MESHES, QUICK_MAX_TETS), the data folder, JSON writing and machine info.
from _common import (
    CUBE_NS,
    QUICK_MAX_TETS,
    REAL_MESHES,
    TETS_DATA,
    kept_records,
    load_quiet,
    loadavg,
    machine,
    timed_repeats,
    write_json,
)
import corpus
from tqdm import tqdm

from tetvr.mesh import synthetic
from tetvr.core.camera import Camera
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.preintegrate import build_table
from tetvr.render import default_transfer_function
from tetvr.settings import RenderSettings
from tetvr.order.sort import centroid_order

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = TETS_DATA

SIZE = (512, 512)
#: Target size of the geometry-only floor (same draw, almost no fragments).
GEOMETRY_SIZE = (16, 16)
OPACITY = 0.5
#: Per-view stages, in pipeline order; their sum is the per-view frame total.
VIEW_STAGES = ("classify", "sort", "order_upload", "draw", "readback")
#: Small meshes get more repeats (until their tet frames add up to MIN_TIMED_S), at most this many.
MAX_REPEATS = 60
#: Meshes above this many tets get fewer repeats (a 1M-tet frame takes seconds on llvmpipe).
BIG_TETS = 500_000
BIG_REPEATS = 3
#: Projected tetrahedra's stages, with the sort pinned to the one the targets are about.
SETTINGS = RenderSettings(sort="centroid", method="projected")
#: The tet-marching ray caster, timed on the same meshes and views (``raymarch`` in the JSON).
MARCH_SETTINGS = RenderSettings(method="raymarch")
TABLE_BINS = (128, 256, 512)
TABLE_SLICES = 16
TABLE_REPEATS = 3
SORT_N = 55  # cube(55): 998,250 tets
SORT_REPEATS = 10

TARGETS: dict[str, dict[str, Any]] = {
    "sort_1m_s": {"limit": 0.050, "what": "centroid sort of ~1M tets <= 50 ms (median of 10, centroids cached)"},
    "table_256_s": {"limit": 2.0, "what": "256x256x16 float32 table build <= 2 s (median of 3, uncached)"},
    "frame_vs_floor": {"limit": 2.0, "what": "per-view frame total <= 2x the fill-rate floor's total, every mesh"},
}


# ---------------------------------------------------------------- helpers
def _median(xs: list[float]) -> float:
    return float(statistics.median(xs)) if xs else float("nan")


def _ms(x: float | None) -> str:
    if x is None or not np.isfinite(x):
        return "-"
    return f"{x * 1e3:.1f}" if x < 10 else f"{x * 1e3:.0f}"


def _label(n_tets: int) -> str:
    return f"{n_tets / 1e6:.2f}M" if n_tets >= 1e6 else f"{n_tets / 1e3:.0f}k"


def _mesh_specs(quick: bool, data_dir: Path) -> tuple[list[tuple[str, int, Callable[[], TetMesh]]], list[str]]:
    """(name, expected tets, loader) in ascending size, and notes about what was skipped."""
    specs: list[tuple[str, int, Callable[[], TetMesh]]] = []
    notes: list[str] = []
    for n in CUBE_NS:
        specs.append((f"cube({n})", 6 * n**3, functools.partial(synthetic.cube, n)))
    if data_dir.is_dir():
        for fname, field in REAL_MESHES:
            path = data_dir / fname
            if not path.exists():
                notes.append(f"skipped {fname}: not in {data_dir}")
                continue

            # Size is unknown until read; the real meshes here are ~200k tets.
            specs.append((f"{path.stem.removesuffix('_tets')} ({field})", -1, functools.partial(load_quiet, path, field)))
    else:
        notes.append(f"skipped real meshes: {data_dir} does not exist")
    # The unstructured meshes made here (bench/corpus.py: a torus fTetWild fills, ~200k tets;
    # a Delaunay pipe with a boundary layer, ~900k), cached after the first run.
    specs += [(name, 10**6, load) for name, load in corpus.meshes()]
    if quick:
        kept = [s for s in specs if s[1] <= QUICK_MAX_TETS]
        notes += [f"--quick: skipped {s[0]} ({s[1]} tets > {QUICK_MAX_TETS})" for s in specs if s not in kept]
        specs = kept
    return specs, notes


# ---------------------------------------------------------------- measurements
def _frame(renderer: Any, mesh: TetMesh, cam: Camera, tf: Any, shader: str) -> tuple[dict[str, float], float, np.ndarray]:
    c0, t0 = time.process_time(), time.perf_counter()
    image = renderer.render(mesh, cam, tf, size=SIZE, shader=shader)
    wall = time.perf_counter() - t0
    st = renderer.last_stats
    stages = {k: float(getattr(st, k)) for k in ("upload", "table", *VIEW_STAGES)}
    stages["total"] = sum(stages[k] for k in VIEW_STAGES)
    # CPU seconds of the whole process (llvmpipe's raster threads included). On a software
    # rasteriser this is the work done; wall time also counts waiting for cores that other
    # processes hold, so cpu / wall well below 1 flags a contended run.
    stages["cpu"] = time.process_time() - c0
    return stages, wall, image


def bench_mesh(renderer: Any, name: str, mesh: TetMesh, repeats: int, bar: tqdm) -> dict[str, Any]:
    cam = Camera.fit(mesh)
    tf = default_transfer_function(mesh, opacity=OPACITY)
    rec: dict[str, Any] = {"name": name, "n_tets": mesh.n_tets, "n_points": mesh.n_points, "repeats": repeats}

    # First frame of a new mesh: buffer upload and table build happen here, once.
    renderer.profile = True
    first, first_wall, image = _frame(renderer, mesh, cam, tf, "tet")
    rec["first_frame"] = {"upload": first["upload"], "table": first["table"], "per_view_total": first["total"],
                          "wall": first_wall}
    alpha = image[..., 3]
    rec["image"] = {"covered_fraction": float(np.mean(alpha > 1e-4)), "mean_alpha": float(alpha.mean()),
                    "max_alpha": float(alpha.max())}
    _frame(renderer, mesh, cam, tf, "floor")  # warm-up of the floor's path
    bar.update(2)
    # Small meshes render in tens of ms, where a few repeats leave the ratio to chance.
    extra = timed_repeats(first["total"], repeats, MAX_REPEATS) - repeats
    if extra:
        repeats += extra
        bar.total += 4 * extra
        rec["repeats"] = repeats

    samples: dict[str, list[dict[str, float]]] = {"tet": [], "floor": []}
    walls: dict[str, list[float]] = {"tet": [], "floor": [], "tet_unprofiled": []}
    # Interleave the real shader and the floor so drift (other load, clocks) hits both alike.
    for _ in range(repeats):
        for shader in ("tet", "floor"):
            st, wall, _ = _frame(renderer, mesh, cam, tf, shader)
            samples[shader].append(st)
            walls[shader].append(wall)
            bar.update(1)
        # The same frame without the per-stage glFinish: what an application sees.
        renderer.profile = False
        t0 = time.perf_counter()
        renderer.render(mesh, cam, tf, size=SIZE)
        walls["tet_unprofiled"].append(time.perf_counter() - t0)
        renderer.profile = True
        bar.update(1)

    # The floor shader at a tiny target: vertex fetch, fan expansion and triangle setup with
    # almost no fragments, i.e. what draw costs when it is not fill-bound.
    geometry: list[float] = []
    for i in range(repeats + 1):
        renderer.render(mesh, cam, tf, size=GEOMETRY_SIZE, shader="floor")
        if i:  # the first one resizes the target and is a warm-up
            geometry.append(float(renderer.last_stats.draw))
        bar.update(1)
    # (The next mesh's first frame resizes the target back; it is not in any median.)

    def medians(rows: list[dict[str, float]]) -> dict[str, float]:
        return {k: _median([r[k] for r in rows]) for k in ("table", *VIEW_STAGES, "total", "cpu")}

    rec["median"] = medians(samples["tet"])
    rec["floor_median"] = medians(samples["floor"])
    rec["median"]["table_lookup"] = rec["median"].pop("table")  # the cached-table hit, every frame
    rec["floor_median"]["table_lookup"] = rec["floor_median"].pop("table")
    rec["wall_median"] = {k: _median(v) for k, v in walls.items()}
    rec["ratio"] = {"draw": rec["median"]["draw"] / rec["floor_median"]["draw"],
                    "total": rec["median"]["total"] / rec["floor_median"]["total"]}
    # Each repeat pairs a tet frame with a floor frame rendered right after it; the median
    # of the per-pair ratios is less sensitive to load that drifts during the run.
    rec["ratio_paired"] = {k: _median([t[k] / f[k] for t, f in zip(samples["tet"], samples["floor"])])
                           for k in ("draw", "total", "cpu")}
    rec["cpu_utilisation"] = {k: _median([r["cpu"] / w for r, w in zip(samples[k], walls[k])]) for k in ("tet", "floor")}
    rec["geometry_floor_draw"] = _median(geometry)
    rec["samples"] = {"tet": samples["tet"], "floor": samples["floor"], "wall": walls, "geometry_floor_draw": geometry}
    return rec


def lane_utilisation(counts: np.ndarray, block: int = 4) -> float:
    """The segments rays walk over what blocks of ``block`` x ``block`` pixels walk when
    each pixel runs as long as its block's longest ray (llvmpipe shades a block together),
    over the blocks any ray enters: 1 where neighbouring rays cross as many cells."""
    h, w = (counts.shape[0] // block) * block, (counts.shape[1] // block) * block
    g = counts[:h, :w].reshape(h // block, block, w // block, block).swapaxes(1, 2).reshape(-1, block * block)
    longest = g.max(axis=1)
    return float(g.sum() / max(int(longest.sum()) * block * block, 1))


def bench_raymarch(renderer: Any, mesh: TetMesh, repeats: int) -> dict[str, Any]:
    """The ray caster on the same mesh and view: first frame (records and boundary faces),
    per-view stages (entry passes, march passes, readback), and the cost per segment."""
    cam = Camera.fit(mesh)
    tf = default_transfer_function(mesh, opacity=OPACITY)
    renderer.profile = True
    t0 = time.perf_counter()
    renderer.render(mesh, cam, tf, size=SIZE)
    rec: dict[str, Any] = {"first_frame": {"wall": time.perf_counter() - t0,
                                           "upload": float(renderer.last_stats.upload),
                                           "table": float(renderer.last_stats.table)}}
    rows: list[dict[str, float]] = []
    walls: list[float] = []
    for _ in range(repeats):
        renderer.profile = True
        c0 = time.process_time()
        renderer.render(mesh, cam, tf, size=SIZE)
        st = renderer.last_stats
        rows.append({"entry": st.entry, "march": st.march, "readback": st.readback,
                     "total": st.entry + st.march + st.readback, "cpu": time.process_time() - c0})
        renderer.profile = False
        t0 = time.perf_counter()
        renderer.render(mesh, cam, tf, size=SIZE)
        walls.append(time.perf_counter() - t0)
    rec["median"] = {k: _median([r[k] for r in rows]) for k in rows[0]}
    rec["wall_median"] = _median(walls)
    rec["layers"] = renderer._marcher.last_stats.layers
    counts = renderer.segment_counts(mesh, cam, size=SIZE)
    rec["segments"] = int(counts.sum())
    rec["segments_per_covered_pixel"] = float(counts[counts > 0].mean()) if counts.any() else 0.0
    rec["segments_per_tet"] = rec["segments"] / mesh.n_tets
    rec["lane_utilisation"] = lane_utilisation(counts)
    rec["ns_per_segment"] = {"march_wall": rec["median"]["march"] / max(rec["segments"], 1) * 1e9,
                             "frame_cpu": rec["median"]["cpu"] / max(rec["segments"], 1) * 1e9}
    rec["samples"] = {"rows": rows, "wall": walls}
    return rec


def bench_tables(repeats: int, bar: tqdm) -> dict[str, Any]:
    mesh = synthetic.cube(12)
    tf = default_transfer_function(mesh, opacity=OPACITY)
    out: dict[str, Any] = {"n_slices": TABLE_SLICES, "dtype": "float32", "encoding": "normalized",
                           "repeats": repeats, "by_bins": {}}
    for n_bins in TABLE_BINS:
        times, cpu = [], []
        for _ in range(repeats):
            c0, t0 = time.process_time(), time.perf_counter()
            build_table(tf, mesh.scalar_range, mesh.max_edge, n_bins=n_bins, n_slices=TABLE_SLICES, dtype="float32")
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            bar.update(1)
        out["by_bins"][str(n_bins)] = {"median": _median(times), "cpu_median": _median(cpu), "samples": times}
    return out


def bench_sort(mesh: TetMesh | None, repeats: int, bar: tqdm) -> dict[str, Any]:
    mesh = mesh if mesh is not None and mesh.n_tets == 6 * SORT_N**3 else synthetic.cube(SORT_N)
    cam = Camera.fit(mesh)
    fresh = mesh.__dict__.get("centroids") is None
    t0 = time.perf_counter()
    centroid_order(mesh, cam)  # warm-up; also fills the cached centroids
    first = time.perf_counter() - t0
    bar.update(1)
    times, cpu = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        centroid_order(mesh, cam)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        bar.update(1)
    # numpy runs the sort on one thread, so its CPU time is close to what the wall time would
    # be on an idle machine.
    return {"n_tets": mesh.n_tets, "repeats": repeats, "median": _median(times), "cpu_median": _median(cpu),
            "samples": times,
            "first_call": first, "first_call_includes_centroids": fresh}


def evaluate_targets(res: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    sort = res.get("sort")
    if sort:
        v = sort["median"]
        out["sort_1m_s"] = {**TARGETS["sort_1m_s"], "value": v, "pass": v <= TARGETS["sort_1m_s"]["limit"]}
    tab = (res.get("table") or {}).get("by_bins", {}).get("256")
    if tab:
        v = tab["median"]
        out["table_256_s"] = {**TARGETS["table_256_s"], "value": v, "pass": v <= TARGETS["table_256_s"]["limit"]}
    meshes = res.get("meshes", [])
    if meshes:
        per = {m["name"]: m["ratio"]["total"] for m in meshes}
        worst = max(per.values())
        out["frame_vs_floor"] = {**TARGETS["frame_vs_floor"], "value": worst, "per_mesh": per,
                                 "pass": worst <= TARGETS["frame_vs_floor"]["limit"]}
    return out


# ---------------------------------------------------------------- output
def print_table(res: dict[str, Any]) -> None:
    meshes = res.get("meshes", [])
    if meshes:
        head = (f"{'mesh':<20}{'tets':>9}{'R':>3} | {'upload':>7}{'table':>7} | {'classify':>8}{'sort':>7}"
                f"{'order':>7}{'draw':>8}{'readbk':>7}{'total':>8} | {'floor':>7}{'draw/fl':>8}{'tot/fl':>7}{'cpu/fl':>7}{'geom':>7} | {'wall':>7}{'util':>5}")
        print(f"\nper-view stage medians at {SIZE[0]}x{SIZE[1]}, ms.  upload/table: first frame only; floor: total of "
              f"the floor shader;\ngeom: floor draw at {GEOMETRY_SIZE[0]}x{GEOMETRY_SIZE[1]} (no fill); "
              "cpu/fl: process-CPU-time ratio tet/floor;\nwall: whole render() with profile=False; "
              f"util: CPU s per wall s (< 1: other processes held the cores; {os.cpu_count()} cores here)")
        print(head)
        print("-" * len(head))
        for m in meshes:
            md, fl, r, ff = m["median"], m["floor_median"], m["ratio"], m["first_frame"]
            print(f"{m['name']:<20}{m['n_tets']:>9}{m['repeats']:>3} | {_ms(ff['upload']):>7}{_ms(ff['table']):>7} | "
                  f"{_ms(md['classify']):>8}{_ms(md['sort']):>7}{_ms(md['order_upload']):>7}{_ms(md['draw']):>8}"
                  f"{_ms(md['readback']):>7}{_ms(md['total']):>8} | {_ms(fl['total']):>7}{r['draw']:>8.2f}"
                  f"{r['total']:>7.2f}{m['ratio_paired']['cpu']:>7.2f}{_ms(m['geometry_floor_draw']):>7} | "
                  f"{_ms(m['wall_median']['tet_unprofiled']):>7}{m['cpu_utilisation']['tet']:>5.1f}")
    marched = [m for m in meshes if "raymarch" in m]
    if marched:
        print(f"\ntet-marching ray caster at {SIZE[0]}x{SIZE[1]}, ms: entry, march, readback, wall (unprofiled); "
              "segments per covered pixel; ns per segment (march wall, frame CPU); projected wall / ray caster wall")
        for m in marched:
            rm = m["raymarch"]
            md = rm["median"]
            print(f"{m['name']:<20}{m['n_tets']:>9} | {_ms(md['entry']):>7}{_ms(md['march']):>8}{_ms(md['readback']):>7}"
                  f"{_ms(rm['wall_median']):>8} | {rm['segments_per_covered_pixel']:>6.1f} | "
                  f"{rm['ns_per_segment']['march_wall']:>6.1f}{rm['ns_per_segment']['frame_cpu']:>7.1f} | "
                  f"{rm['speedup_vs_projected']:>5.2f}x")
    tab = res.get("table")
    if tab:
        cells = ", ".join(f"{k}: {v['median']:.3f} s (cpu {v['cpu_median']:.3f})" for k, v in tab["by_bins"].items())
        print(f"\ntable build (NxNx{tab['n_slices']} float32, median of {tab['repeats']}): {cells}")
    sort = res.get("sort")
    if sort:
        print(f"centroid sort, {sort['n_tets']} tets: median {sort['median'] * 1e3:.1f} ms "
              f"(cpu {sort['cpu_median'] * 1e3:.1f} ms) "
              f"(first call {sort['first_call'] * 1e3:.0f} ms incl. centroids)")
    targets = res.get("targets", {})
    if targets:
        print("\ntargets:")
        for key, t in targets.items():
            unit = "x" if key == "frame_vs_floor" else " s"
            print(f"  [{'PASS' if t['pass'] else 'FAIL'}] {t['what']}: {t['value']:.3f}{unit}")
    if res.get("interrupted"):
        print("\n(interrupted: partial results)")


def plot(res: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    meshes = sorted(res.get("meshes", []), key=lambda m: m["n_tets"])
    fig, axes = plt.subplots(2, 2, figsize=(14, 10))
    colours = dict(zip(VIEW_STAGES, ("#4c72b0", "#dd8452", "#937860", "#c44e52", "#55a868")))
    # "beam_tet4_result_100 (VonMises_stress)" -> "beam": ten full names overlap under the bars.
    labels = [f"{m['name'].split(' ')[0].split('_')[0]}\n{_label(m['n_tets'])}" for m in meshes]
    x = np.arange(len(meshes))
    gl = res.get("gl", {}).get("GL_RENDERER", "?")

    # (a) grouped stage medians, log scale, with the floor's draw and totals.
    ax = axes[0, 0]
    width = 0.8 / (len(VIEW_STAGES) + 1)
    for i, stage in enumerate(VIEW_STAGES):
        vals = [max(m["median"][stage], 1e-6) * 1e3 for m in meshes]
        ax.bar(x + (i - len(VIEW_STAGES) / 2) * width, vals, width, color=colours[stage], label=stage)
    vals = [m["floor_median"]["draw"] * 1e3 for m in meshes]
    ax.bar(x + len(VIEW_STAGES) / 2 * width, vals, width, color="white", edgecolor="black", hatch="//",
           label="floor draw")
    ax.plot(x + len(VIEW_STAGES) / 2 * width, [m["geometry_floor_draw"] * 1e3 for m in meshes], "k_", ms=12, mew=2,
            label=f"floor draw at {GEOMETRY_SIZE[0]}x{GEOMETRY_SIZE[1]}")
    for xi, m in zip(x, meshes):
        lo, hi = xi - 0.42, xi + 0.42
        ax.hlines(m["median"]["total"] * 1e3, lo, hi, colors="black", lw=1.5)
        ax.hlines(m["floor_median"]["total"] * 1e3, lo, hi, colors="black", lw=1.2, linestyles="--")
        ax.annotate(f"x{m['ratio']['total']:.2f}", (xi, m["median"]["total"] * 1e3), textcoords="offset points",
                    xytext=(0, 4), ha="center", fontsize=9, fontweight="bold")
    ax.plot([], [], color="black", lw=1.5, label="frame total")
    ax.plot([], [], color="black", lw=1.2, ls="--", label="floor total")
    ax.set_yscale("log")
    if meshes:
        ax.set_ylim(top=max(m["median"]["total"] for m in meshes) * 1e3 * 100)  # room for the legend
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylabel("median per frame, ms (log)")
    ax.set_title(f"Per-view stages at {SIZE[0]}x{SIZE[1]} (x = total / floor total)")
    ax.legend(fontsize=8, ncol=4, loc="upper left")
    ax.grid(axis="y", which="both", alpha=0.3)

    # (b) composition of the frame, stacked to 100 %, with the floor's share marked.
    ax = axes[0, 1]
    bottom = np.zeros(len(meshes))
    # Shares of the sum of the stage medians (the median of the totals differs slightly).
    sums = np.array([sum(m["median"][k] for k in VIEW_STAGES) for m in meshes])
    for stage in VIEW_STAGES:
        share = np.array([m["median"][stage] for m in meshes]) / sums * 100
        ax.bar(x, share, 0.6, bottom=bottom, color=colours[stage], label=stage)
        bottom += share
    for xi, m, total in zip(x, meshes, sums):
        f = m["floor_median"]["total"] / total * 100
        ax.hlines(f, xi - 0.38, xi + 0.38, colors="black", lw=2, linestyles="--")
    ax.plot([], [], color="black", lw=2, ls="--", label="floor total")
    ax.hlines(50, -0.5, len(meshes) - 0.5, colors="grey", lw=0.8, linestyles=":")
    ax.set_xticks(x, labels, fontsize=8)
    ax.set_ylim(0, 118)
    ax.set_yticks(range(0, 101, 20))
    ax.set_ylabel("% of per-view frame total")
    ax.set_title("Where the frame goes (target: floor line at or above 50 %)")
    ax.legend(fontsize=8, loc="upper center", ncol=6, framealpha=0.9, columnspacing=1.0, handlelength=1.5)

    # (c) table build vs bins.
    ax = axes[1, 0]
    tab = (res.get("table") or {}).get("by_bins", {})
    if tab:
        ns = np.array([int(k) for k in tab])
        ts = np.array([v["median"] for v in tab.values()])
        ax.loglog(ns, ts, "o-", color="#4c72b0", label=f"build_table, {TABLE_SLICES} slices, float32")
        cpu = np.array([v.get("cpu_median", np.nan) for v in tab.values()])
        if np.all(np.isfinite(cpu)):
            ax.loglog(ns, cpu, "o--", color="#4c72b0", mfc="none", label="same, process CPU time")
        for n, t in zip(ns, ts):
            ax.annotate(f"{t:.2f} s", (n, t), textcoords="offset points", xytext=(6, -12), fontsize=9)
        ref = ts[0] * (ns / ns[0]) ** 2
        ax.loglog(ns, ref, ":", color="grey", label="~N^2 from the first point")
        ax.plot([256], [TARGETS["table_256_s"]["limit"]], "v", color="#c44e52", ms=10, label="target for N=256: <= 2 s")
        ax.set_xticks(ns, [str(n) for n in ns])
        ax.minorticks_off()
    ax.set_xlabel("N (scalar bins per axis)")
    ax.set_ylabel("seconds (median)")
    ax.set_title("Pre-integration table build (uncached)")
    if tab:
        ax.legend(fontsize=8)
    else:  # a run at another size, or merged into one: the build does not depend on the frame size
        ax.text(0.5, 0.5, "not measured in this run (see stages.json)", ha="center", va="center",
                transform=ax.transAxes, color="0.4")
    ax.grid(which="both", alpha=0.3)

    # (d) scaling with mesh size: cubes as lines, real meshes as open markers of the same colour.
    ax = axes[1, 1]
    cubes = [m for m in meshes if m["name"].startswith("cube")]
    real = [m for m in meshes if not m["name"].startswith("cube")]
    series = (("frame total", "o-", "C0", lambda m: m["median"]["total"]),
              ("floor total", "o--", "black", lambda m: m["floor_median"]["total"]),
              (f"floor draw at {GEOMETRY_SIZE[0]}x{GEOMETRY_SIZE[1]}", "x:", "grey", lambda m: m["geometry_floor_draw"]),
              ("classify", "v-", "C3", lambda m: m["median"]["classify"]),
              ("sort (in frame)", "^-", "C2", lambda m: m["median"]["sort"]))
    for lab, style, colour, get in series:
        if cubes:
            ax.loglog([m["n_tets"] for m in cubes], [get(m) * 1e3 for m in cubes], style, color=colour, label=lab)
        if real:
            ax.loglog([m["n_tets"] for m in real], [get(m) * 1e3 for m in real], style[0], color=colour, mfc="none",
                      ms=9)
    if real:
        ax.plot([], [], "o", color="black", mfc="none", ms=9, label="open: real meshes")
    sort = res.get("sort")
    if sort:
        ax.loglog([sort["n_tets"]], [sort["median"] * 1e3], "*", ms=14, color="#dd8452",
                  label=f"centroid sort alone: {sort['median'] * 1e3:.1f} ms")
        ax.plot([sort["n_tets"]], [TARGETS["sort_1m_s"]["limit"] * 1e3], "v", color="#c44e52", ms=10,
                label="sort target at 1M: <= 50 ms")
    if meshes:  # room under the curves for the legend
        lowest = min(min(m["median"]["sort"], m["median"]["classify"]) for m in meshes) * 1e3
        ax.set_ylim(bottom=lowest / 300)
    ax.set_xlabel("tets")
    ax.set_ylabel("ms per frame (median)")
    ax.set_title("Scaling with mesh size")
    ax.legend(fontsize=8, loc="lower right", ncol=2)
    ax.grid(which="both", alpha=0.3)

    when = res.get("timestamp", "")[:16].replace("T", " ")
    util = _median([m["cpu_utilisation"]["tet"] for m in meshes]) if meshes else float("nan")
    fig.suptitle(f"tetvr stage benchmark - {gl} - {res.get('machine', {}).get('cpu_count', '?')} CPUs "
                 f"(this process kept {util:.1f} of them busy) - {when}"
                 + ("  (PARTIAL)" if res.get("interrupted") else ""), fontsize=12)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help=f"3 repeats, meshes <= {QUICK_MAX_TETS} tets")
    ap.add_argument("--out", type=Path, default=REPO / "bench" / "results", help="output folder")
    ap.add_argument("--repeats", type=int, default=None, help="frames per mesh after warm-up (default 5, 3 with --quick)")
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder with the real .vtu meshes")
    ap.add_argument("--replot", action="store_true", help="only draw the chart again from the JSON in --out")
    ap.add_argument("--size", type=int, default=SIZE[0],
                    help=f"frame size (square; default {SIZE[0]}); another size writes stages_<size>.json and "
                         "leaves out the table and sort parts")
    ap.add_argument("--only", nargs="+", default=None, metavar="NAME",
                    help="run only the meshes whose names contain one of these and put their records in place of "
                         "those in the existing JSON (the table and sort parts are kept from it)")
    args = ap.parse_args(argv)
    suffix = "" if args.size == SIZE[0] else f"_{args.size}"
    json_path, png_path = args.out / f"stages{suffix}.json", args.out / f"stages{suffix}.png"
    if suffix:
        globals()["SIZE"] = (args.size, args.size)  # the size every stage renders at
    if args.replot:
        plot(json.loads(json_path.read_text()), png_path)
        return 0
    repeats = args.repeats or (3 if args.quick else 5)
    if repeats < 1:
        ap.error("--repeats must be >= 1")

    from tetvr.gl.renderer import Renderer

    specs, notes = _mesh_specs(args.quick, args.data)
    order = [name for name, _, _ in specs]
    old = json.loads(json_path.read_text()) if args.only and json_path.exists() else None
    if args.only:
        specs = [spec for spec in specs if any(o in spec[0] for o in args.only)]
    res: dict[str, Any] = {
        "timestamp": _dt.datetime.now().astimezone().isoformat(timespec="seconds"),
        "command": " ".join([Path(sys.argv[0]).name, *(argv if argv is not None else sys.argv[1:])]),
        "quick": args.quick, "size": list(SIZE), "opacity": OPACITY, "repeats": repeats,
        "big_mesh_repeats": {"above_tets": BIG_TETS, "repeats": min(repeats, BIG_REPEATS)},
        "settings": SETTINGS.to_dict(), "machine": machine(), "notes": notes, "loadavg_start": loadavg(),
        "meshes": [], "interrupted": False, "complete": False,
        "definitions": {
            "per_view_stages": list(VIEW_STAGES),
            "total": "sum of the per-view stages (profile=True: glFinish after each stage)",
            "first_frame": "the first frame after switching to a mesh: upload = mesh buffers, table = table build",
            "table_lookup": "per frame, the cached table_for lookup (not in total)",
            "floor": "same mesh, camera and sort, shader='floor' (constant colour): the fill-rate floor",
            "wall_median.tet_unprofiled": "wall time of render() with profile=False (no per-stage glFinish)",
            "ratio": "median tet / median floor; ratio_paired: median of per-repeat tet / floor",
            "cpu": "process CPU seconds of the frame (all threads; llvmpipe rasterises on the CPU)",
            "cpu_utilisation": ("median cpu / wall per frame; llvmpipe shades vertices and bins on one thread and "
                                "rasterises on all cores, so 1..cores when nothing competes; well below 1: contended"),
            "cpu_median": "table and sort: median process CPU seconds (both run on one thread)",
            "geometry_floor_draw": f"draw stage of the floor shader at {GEOMETRY_SIZE}: the non-fill part of draw",
            "raymarch": ("the tet-marching ray caster (method='raymarch') on the same mesh and view: stage medians "
                         "(entry: boundary passes; march: the walks), wall_median without profiling, segments: "
                         "ray-tet segments walked per frame, ns_per_segment: march time (and frame CPU time) "
                         "per segment; speedup_vs_projected: projected wall / ray caster wall; "
                         "lane_utilisation: segments walked over what 4x4 pixel blocks walk at their longest ray's "
                         "count"),
        },
    }
    if old is not None:
        res["meshes"], res["notes"] = kept_records(old, old["timestamp"], [name for name, _, _ in specs],
                                                   res["timestamp"], notes)
        notes = res["notes"]  # what the run adds below goes with them
    n_frames = sum(3 + 4 * (min(repeats, BIG_REPEATS) if t > BIG_TETS else repeats) for _, t, _ in specs)
    total_work = 1 + n_frames + len(TABLE_BINS) * TABLE_REPEATS + 1 + SORT_REPEATS
    big_mesh: TetMesh | None = None
    status = 0
    bar = tqdm(total=total_work, unit="step", dynamic_ncols=True, file=sys.stderr)
    try:
        with Renderer(SETTINGS, profile=True) as renderer, Renderer(MARCH_SETTINGS, profile=True) as marcher:
            res["gl"] = dict(renderer.gl_info)
            # Compile every program once on a tiny mesh so no mesh's first frame pays for it.
            t0 = time.perf_counter()
            tiny = synthetic.single_tet()
            tf_tiny = default_transfer_function(tiny, opacity=OPACITY)
            for shader in ("tet", "floor"):
                renderer.render(tiny, Camera.fit(tiny), tf_tiny, size=SIZE, shader=shader)
            res["compile_and_first_use_s"] = time.perf_counter() - t0
            bar.update(1)
            for name, expected, load in specs:
                bar.set_description(f"load {name}")
                t0 = time.perf_counter()
                mesh = load()
                load_s = time.perf_counter() - t0
                if args.quick and mesh.n_tets > QUICK_MAX_TETS:
                    notes.append(f"--quick: skipped {name} ({mesh.n_tets} tets > {QUICK_MAX_TETS})")
                    bar.total -= 3 + 4 * repeats
                    continue
                r = min(repeats, BIG_REPEATS) if mesh.n_tets > BIG_TETS else repeats
                if expected < 0:  # size was unknown when the bar was sized
                    bar.total += 4 * r - 4 * repeats
                bar.set_description(f"{name} {_label(mesh.n_tets)}")
                start = _dt.datetime.now().astimezone().isoformat(timespec="seconds")
                rec = bench_mesh(renderer, name, mesh, r, bar)
                rec["load_s"], rec["date"] = load_s, start
                bar.set_description(f"{name} ray caster")
                rec["raymarch"] = bench_raymarch(marcher, mesh, r)
                rec["raymarch"]["speedup_vs_projected"] = (rec["wall_median"]["tet_unprofiled"]
                                                           / rec["raymarch"]["wall_median"])
                res["meshes"].append(rec)
                res["meshes"].sort(key=lambda m: order.index(m["name"]) if m["name"] in order else len(order))
                res["targets"] = evaluate_targets(res)
                write_json(json_path, res)
                if mesh.n_tets == 6 * SORT_N**3:
                    big_mesh = mesh
                del mesh
        if old is not None:  # the table and sort parts of the run merged into
            res["table"], res["sort"] = old.get("table"), old.get("sort")
        elif suffix:
            notes.append(f"at {args.size}x{args.size}: the table and sort parts are in stages.json")
        else:
            bar.set_description("table build")
            res["table"] = bench_tables(TABLE_REPEATS, bar)
            res["targets"] = evaluate_targets(res)
            write_json(json_path, res)
            bar.set_description("centroid sort 1M")
            res["sort"] = bench_sort(big_mesh, SORT_REPEATS, bar)
        res["complete"] = True
    except KeyboardInterrupt:
        res["interrupted"] = True
        status = 130
    finally:
        bar.close()
    res["targets"] = evaluate_targets(res)
    res["loadavg_end"] = loadavg()
    write_json(json_path, res)
    print_table(res)
    try:
        plot(res, png_path)
        print(f"\nwrote {json_path} and {png_path}")
    except KeyboardInterrupt:
        print(f"\nwrote {json_path} (chart skipped)")
        status = 130
    return status


if __name__ == "__main__":
    sys.exit(main())

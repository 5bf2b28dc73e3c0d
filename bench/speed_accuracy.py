"""Speed against accuracy, method by method: a Pareto chart per scene.

Every scene is rendered by the CPU reference once and by each method variant of the GPU
renderer; for each variant we record the median frame time per view change (classify,
sort, draw, readback; as process CPU time, llvmpipe's threads included, and as wall time;
variants interleaved round by round) and its error against the reference: RMSE and PSNR on premultiplied
RGB, and the HAPT metrics (max error, mean error over covered pixels, % of covered pixels
off by more than 1/255), and the CPU time to build its pre-integration table, paid again on
every transfer-function change. A variant is on the Pareto front when no other is at
least as good in frame time and RMSE and better in one (5 % ties; errors below the
rounding noise of a 16-bit image, ERROR_FLOOR, tie too); the front of all three costs
(frame time, table time, RMSE) and the front without the error floor are recorded too.
The stability cases (tetvr.scene.stability) are measured the same way.

    python bench/speed_accuracy.py [--quick] [--size 256] [--out bench/results]

Writes ``speed_accuracy.json`` and ``speed_accuracy.png`` (and one picture per scene of
the default, the weakest variant and the reference).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _common import REAL_MESHES, TETS_DATA, load_quiet, machine, timed_repeats  # noqa: E402

import tetvr  # noqa: E402
from tetvr import Camera, RenderSettings, TransferFunction  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402
from tetvr.optics.table import aligned_scalar_range, table_scalar_range  # noqa: E402
from tetvr.reference.tets import render_reference  # noqa: E402
from tetvr.settings import SORT_METHODS  # noqa: E402
from tetvr.order.sort import SORTERS, auto_method  # noqa: E402
from tetvr.scene.stability import CASES, case  # noqa: E402
from tetvr.optics.tablesize import resolve as resolve_table_size  # noqa: E402

DEFAULT = RenderSettings()
#: Small scenes are timed for more rounds (until the default's frames add up to
#: MIN_TIMED_S), at most this many.
MAX_REPEATS = 40
#: The table-size sweep (``table_convergence`` in the JSON): scalar bins N and
#: (slices K, log base) pairs from coarse to fine, each combination against the reference.
SWEEP_BINS = (128, 256, 512, 1024)
SWEEP_SLICES = ((8, 2.5), (16, 1.6), (24, 1.4), (32, 1.3), (48, 1.2))
#: ... skipping tables above this many entries N * N * K (the build's float64 temporaries
#: take ~100 bytes per entry).
SWEEP_MAX_ENTRIES = 1024 * 1024 * 16


def variants() -> dict[str, RenderSettings]:
    v = {"default": DEFAULT}
    # The two GPU methods ("auto" is the ray caster where both apply; bench/README.md).
    v["projected tetrahedra"] = dataclasses.replace(DEFAULT, method="projected")
    v["tet marching"] = dataclasses.replace(DEFAULT, method="raymarch")
    v["tet marching, no table (integration exact)"] = dataclasses.replace(DEFAULT, method="raymarch",
                                                                         integration="exact")
    v["screen-linear interpolation"] = dataclasses.replace(DEFAULT, perspective_correct=False)
    v["premultiplied table"] = dataclasses.replace(DEFAULT, table_encoding="premultiplied")
    v["uint8 table"] = dataclasses.replace(DEFAULT, table_dtype="uint8")
    v["cubic thickness filter"] = dataclasses.replace(DEFAULT, table_filter="cubic")
    v["premultiplied table, cubic"] = dataclasses.replace(DEFAULT, table_encoding="premultiplied", table_filter="cubic")
    v["uint8 framebuffer"] = dataclasses.replace(DEFAULT, framebuffer="uint8")
    v["uniform table nodes"] = dataclasses.replace(DEFAULT, table_align_nodes=False)
    v["even table nodes (table_warp off)"] = dataclasses.replace(DEFAULT, table_warp="off")
    v["fixed table N=256, K=16 (the 0.x default)"] = dataclasses.replace(
        DEFAULT, table_scalar_bins=256, table_thickness_slices=16, table_log_base=1.6, table_align_nodes=False)
    # One axis fixed, the other left to the "auto" size.
    for n in (64, 128, 512):
        v[f"N={n}"] = dataclasses.replace(DEFAULT, table_scalar_bins=n)
    for k, base in ((8, 2.5), (16, 2.0), (24, 1.4)):
        v[f"K={k}, base {base}"] = dataclasses.replace(DEFAULT, table_thickness_slices=k, table_log_base=base)
    for method in SORTERS:
        if method not in (DEFAULT.sort, "auto") and method in SORT_METHODS:
            v[f"sort={method}"] = dataclasses.replace(DEFAULT, sort=method, method="projected")
    v["premultiplied, uint8, screen-linear (VTK-like)"] = dataclasses.replace(
        DEFAULT, table_encoding="premultiplied", table_dtype="uint8", perspective_correct=False, framebuffer="uint8")
    return v


def _tf(mesh, opacity, units, preset="viridis"):
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    return TransferFunction.preset(preset, mesh.scalar_range, opacity=opacity, unit_distance=diag / units)


def scenes(quick: bool):
    m = synthetic.cube(8)
    yield "convex, close perspective", m, Camera.fit(m, direction=(-0.3, -0.2, -1.0), view_angle=60, zoom=1.6), \
        _tf(m, [(0, 0.2), (0.5, 0.6), (1, 0.9)], 4)
    r = synthetic.interlocking_rings(10, 1)
    yield "interlocking rings", r, Camera.fit(r, direction=(-0.5, -1.0, -0.6), view_up=(0, 0, 1)), \
        _tf(r, [(0, 0.9), (1, 0.9)], 6)
    c = case("camera_inside")
    yield "camera inside", c.mesh, c.camera, c.tf
    # Cell data: an element field, constant in each cell and jumping at faces (four levels
    # of a smooth field at the cells' centroids, as a material or stress-class map).
    g = synthetic.cube(16)
    x = g.centroids
    levels = np.floor(4.0 * (0.5 + 0.5 * np.sin(5.0 * x[:, 0]) * np.cos(4.0 * x[:, 1] + 2.0 * x[:, 2]))) / 4.0
    g = g.with_cell_scalars(levels, name="level")
    yield "cell data (4 levels)", g, Camera.fit(g, direction=(-0.6, -0.4, -1.0)), \
        _tf(g, [(0, 0.05), (0.5, 0.3), (1, 0.7)], 6)
    for name, field in REAL_MESHES:
        if quick and name.startswith("combustor"):
            continue
        path = TETS_DATA / name
        if not path.is_file():
            print(f"skipping {name}: {path} not found")
            continue
        mesh = load_quiet(path, field)
        lo, hi = mesh.scalar_range
        q30, q60 = ((q - lo) / (hi - lo) for q in np.quantile(mesh.scalars, [0.3, 0.6]))
        op = [(0, 0.02), (q30 - 0.03, 0.05), (q30, 0.9), (q30 + 0.03, 0.05), (q60, 0.3), (1, 0.9)]
        yield name, mesh, Camera.fit(mesh, direction=(-1.0, -0.5, -0.7), zoom=1.2), _tf(mesh, op, 20, "cool-to-warm")
        # Isosurface-like: two opacity spikes 0.6 % of the range wide, nothing else (issue 22;
        # the default warps its table's nodes to them, tetvr.optics.tablewarp).
        spikes = [(0, 0.0), (q30 - 0.003, 0.0), (q30, 0.9), (q30 + 0.003, 0.0), (q60 - 0.003, 0.0), (q60, 0.9),
                  (q60 + 0.003, 0.0), (1, 0.0)]
        yield f"{name}, spiky TF", mesh, Camera.fit(mesh, direction=(-1.0, -0.5, -0.7), zoom=1.2), \
            _tf(mesh, spikes, 20, "cool-to-warm")


def errors(img: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    d = np.abs(img[..., :3].astype(np.float64) - ref[..., :3]).max(axis=-1)
    covered = (ref[..., 3] > 1e-4) | (img[..., 3] > 1e-4)
    n = max(int(covered.sum()), 1)
    return {"rmse": tetvr.rmse(img, ref), "psnr": min(tetvr.psnr(img, ref), 200.0),
            "max_error": float(d.max()), "mean_error": float(d[covered].sum() / n),
            "pct_over_1_255": float(100.0 * np.sum(d[covered] > 1 / 255) / n)}


def time_variants(renderers, mesh, camera, tf, size, repeats):
    """Frame times of every variant, measured in interleaved rounds so that a change in
    the machine's load hits all variants alike. Returns images and, per variant, the
    median wall time and the median CPU time of the process (llvmpipe's threads
    included), which other processes' load inflates less than wall time.

    Small scenes get more rounds, until the default's frames add up to MIN_TIMED_S (at
    most MAX_REPEATS): with a handful of 5 ms frames, 5 % differences are chance."""
    images = {key: r.render(mesh, camera, tf, size=size) for key, r in renderers.items()}  # warm-up
    t1 = time.perf_counter()
    images["default"] = renderers["default"].render(mesh, camera, tf, size=size)
    one = time.perf_counter() - t1
    repeats = timed_repeats(one, repeats, MAX_REPEATS)
    wall = {key: [] for key in renderers}
    cpu = {key: [] for key in renderers}
    for _ in range(repeats):
        for key, r in renderers.items():
            c0, t0 = time.process_time(), time.perf_counter()
            images[key] = r.render(mesh, camera, tf, size=size)
            t1, c1 = time.perf_counter(), time.process_time()
            st = r.last_stats
            # Per view change: drop the cached table lookup and the (no-op) mesh upload.
            wall[key].append(t1 - t0 - st.table - st.upload)
            cpu[key].append(c1 - c0)
    return (images, {k: statistics.median(v) for k, v in wall.items()},
            {k: statistics.median(v) for k, v in cpu.items()}, repeats)


def resolved(s: RenderSettings, mesh, tf) -> RenderSettings:
    """The settings with ``sort="auto"`` and an "auto" table size made concrete for this scene."""
    size = resolve_table_size(s, tf, mesh)
    # Aligned nodes that land where uniform ones do are the same table.
    rng = table_scalar_range(mesh.scalar_range, tf)
    align = s.table_align_nodes and aligned_scalar_range(rng, tf, size.n_bins) != rng
    from tetvr.order.method import choose

    return dataclasses.replace(s, method=choose(s, mesh), sort=auto_method(mesh) if s.sort == "auto" else s.sort,
                               table_scalar_bins=size.n_bins, table_thickness_slices=size.n_slices,
                               table_log_base=round(size.log_base, 9), table_tolerance=1.0, table_align_nodes=align)


def same_as_default(vs: dict[str, RenderSettings], mesh, tf) -> dict[str, str]:
    """Variants that are the default itself in this scene once ``sort="auto"`` and the
    "auto" table size are resolved (e.g. ``sort=xmpvo`` where auto picks xmpvo, ``N=512``
    where the auto size is 512 bins): timing them again only adds noise, and one of two
    identical settings would "beat" the other by chance."""
    mine = resolved(DEFAULT, mesh, tf)
    why = (f"identical to the default here (method=auto picks {mine.method}, sort=auto {mine.sort}; the auto table is "
           f"N={mine.table_scalar_bins}, K={mine.table_thickness_slices})")
    return {key: why for key, s in vs.items() if key != "default" and resolved(s, mesh, tf) == mine}


def table_times(vs, mesh, tf) -> dict[str, float]:
    """CPU seconds to size (an "auto" size: :mod:`tetvr.optics.tablesize`) and build each
    variant's pre-integration table, both paid again on every transfer-function change;
    uncached. (The mesh's segment sample is paid once per mesh, not per transfer
    function, and is not counted.)

    Sizing is timed per distinct setting (median of 3). The build's work depends only
    on the table's shape (N, K), encoding, storage and optics, so it is timed once per
    such shape, as the fastest of 3 builds: on this shared machine the same table took
    0.70-0.94 s from one build to the next, and variants that build the same shape
    (e.g. another log base) must not differ by that noise."""
    from tetvr.optics.preintegrate import build_table, table_for
    from tetvr.optics.tablesize import cache_clear, segment_sample

    segment_sample(mesh)
    sizing: dict[tuple, tuple[float, dict]] = {}
    builds: dict[tuple, float] = {}
    out = {}
    for key, st in vs.items():
        if st.integration == "exact":  # no table: the transfer function's points are uploaded as they are
            out[key] = 0.0
            continue
        sig = (st.table_scalar_bins, st.table_thickness_slices, st.table_log_base, st.table_tolerance,
               st.table_encoding, st.table_dtype, st.optics, st.table_align_nodes)
        if sig not in sizing:
            runs = []
            for _ in range(3):
                cache_clear()
                c0 = time.process_time()
                size = resolve_table_size(st, tf, mesh)
                runs.append(time.process_time() - c0)
            params = dict(n_bins=size.n_bins, n_slices=size.n_slices, log_base=size.log_base,
                          encoding=st.table_encoding, dtype=st.table_dtype, optics=st.optics)
            sizing[sig] = (statistics.median(runs), params)
        resolve_s, params = sizing[sig]
        shape = (params["n_bins"], params["n_slices"], params["encoding"], params["dtype"], params["optics"])
        if shape not in builds:
            # the renderer's exact inputs (its scalar range includes the node alignment)
            t = table_for(tf, mesh.scalar_range, mesh.max_edge, align_nodes=st.table_align_nodes, **params)
            runs = []
            for _ in range(3):
                c0 = time.process_time()
                build_table(tf, t.scalar_range, t.d_max, **params)
                runs.append(time.process_time() - c0)
            builds[shape] = min(runs)
        out[key] = resolve_s + builds[shape]
    return out


def table_sweep(mesh, camera, tf, size, ref) -> list[dict[str, float]]:
    """PSNR of every table size in SWEEP_BINS x SWEEP_SLICES (the default's other settings),
    and its uncached build time: where each scene's table error comes from."""
    from tetvr.optics.preintegrate import build_table

    out = []
    for n_bins in SWEEP_BINS:
        for k, base in SWEEP_SLICES:
            if n_bins * n_bins * k > SWEEP_MAX_ENTRIES:
                continue
            s = dataclasses.replace(DEFAULT, table_scalar_bins=n_bins, table_thickness_slices=k, table_log_base=base)
            with tetvr.Renderer(s) as r:
                img = r.render(mesh, camera, tf, size=size)
                t = r.table(mesh, tf)
            c0 = time.process_time()
            build_table(tf, t.scalar_range, t.d_max, n_bins=n_bins, n_slices=k, log_base=base,
                        encoding=s.table_encoding, dtype=s.table_dtype, optics=s.optics)
            out.append({"n_bins": n_bins, "n_slices": k, "log_base": base, "table_s": time.process_time() - c0,
                        "table_mib": n_bins * n_bins * (k + 1) * 16 / 2**20, **errors(img, ref)})
    return out


#: Two errors below this RMSE tie: the rounding noise of the finest integer image a
#: user can write (16 bits: a step of 1/65535, rounding error uniform in half a step
#: either way, so RMSE = 1/(65535 * sqrt(12)) = 4.4e-6, 107.1 dB). Below it two
#: renderings cannot be told apart in any written image, as frame times within 5 % cannot
#: be told apart on this machine. ``pareto_strict`` in the JSON is the front without it.
ERROR_FLOOR = 1.0 / (65535.0 * 12.0 ** 0.5)


def pareto(points: list[tuple[float, ...]], tol: float = 0.05) -> list[bool]:
    """True where no other point is no worse in every coordinate and better in one, both
    by more than ``tol`` (relative): times within 5 % are a tie on a shared machine.

    The coordinates are costs, e.g. (frame time per view change, RMSE), the chart's front,
    or (frame time, table build time per transfer-function change, RMSE); pass errors
    through :func:`error_cost` for the output-precision tie.

    >>> pareto([(1.0, 2.0), (1.02, 1.0), (0.5, 3.0), (2.0, 2.0)])
    [False, True, True, False]
    """
    def dominates(a, b):
        no_worse = all(x <= y * (1 + tol) for x, y in zip(a, b))
        better = any(x < y * (1 - tol) for x, y in zip(a, b))
        return no_worse and better

    return [not any(dominates(q, p) for q in points if q is not p) for p in points]


def error_cost(rmse: float) -> float:
    """The error as a Pareto cost: RMSE, with every error below :data:`ERROR_FLOOR` a tie."""
    return max(rmse, ERROR_FLOOR)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats, skip the largest scene")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    size = (args.size, args.size)
    repeats = 2 if args.quick else 5
    from tqdm import tqdm

    vs = variants()
    report = {"created": time.strftime("%Y-%m-%dT%H:%M:%S"), "size": size, "repeats": repeats,
              "machine": machine(),
              "variants": {k: dataclasses.asdict(s) for k, s in vs.items()}, "scenes": {}, "stability": {}}
    renderers = {}
    try:
        for key, s in vs.items():
            renderers[key] = tetvr.Renderer(s, profile=True)
        report["gl"] = renderers["default"].gl_info
        for name, mesh, cam, tf in scenes(args.quick):
            t0 = time.perf_counter()
            ref = render_reference(mesh, cam, tf, size)
            ref_time = time.perf_counter() - t0
            dup = same_as_default(vs, mesh, tf)
            timed = {key: r for key, r in renderers.items() if key not in dup}
            images, wall, cpu, rounds = time_variants(timed, mesh, cam, tf, size, repeats)
            tables = table_times({k: s for k, s in vs.items() if k not in dup}, mesh, tf)
            rows = {key: {"frame_s": cpu[key], "frame_wall_s": wall[key], "table_s": tables[key],
                          **errors(images[key], ref)} for key in timed}
            np.save(out / "_tmp_default.npy", images["default"])
            np.save(out / "_tmp_premult.npy", images["premultiplied, uint8, screen-linear (VTK-like)"])
            front = pareto([(r["frame_s"], error_cost(r["rmse"])) for r in rows.values()])
            front_table = pareto([(r["frame_s"], r["table_s"], error_cost(r["rmse"])) for r in rows.values()])
            front_strict = pareto([(r["frame_s"], r["rmse"]) for r in rows.values()])
            for (key, r), f, ft, fs in zip(rows.items(), front, front_table, front_strict):
                r["pareto"] = f
                r["pareto_with_table"] = ft
                r["pareto_strict"] = fs
            auto = resolve_table_size(DEFAULT, tf, mesh)
            report["scenes"][name] = {"n_tets": mesh.n_tets, "reference_s": ref_time, "rounds": rounds,
                                      "auto_table": {**dataclasses.asdict(auto), "error": auto.error},
                                      "variants": rows, "same_as_default": dup,
                                      "table_convergence": table_sweep(mesh, cam, tf, size, ref)}
            _picture(out, name, ref)
            d = rows["default"]
            print(f"{name:28s} {mesh.n_tets:7d} tets  default (N={auto.n_bins}, K={auto.n_slices}) "
                  f"{d['frame_s'] * 1e3:7.1f} ms  PSNR {d['psnr']:6.1f} dB  "
                  f"pareto={d['pareto']} (with table time: {d['pareto_with_table']}; "
                  f"without the error floor: {d['pareto_strict']})")
        for name in tqdm(sorted(CASES), desc="stability cases", leave=False):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                c = case(name)
            ref = render_reference(c.mesh, c.camera, c.tf, (96, 96))
            report["stability"][name] = {}
            for key in vs:
                try:
                    image = renderers[key].render(c.mesh, c.camera, c.tf, size=(96, 96))
                except ValueError as exc:  # tet marching refuses a mesh it cannot walk (tangled slivers)
                    report["stability"][name][key] = {"psnr": None, "refused": str(exc)}
                    continue
                report["stability"][name][key] = errors(image, ref)
    except KeyboardInterrupt:
        print("interrupted: writing what was measured")
    finally:
        for r in renderers.values():
            r.release()
        for tmp in out.glob("_tmp_*.npy"):
            tmp.unlink()
    (out / "speed_accuracy.json").write_text(json.dumps(report, indent=1))
    _chart(report, out / "speed_accuracy.png")
    _sweep_chart(report, out / "table_convergence.png")
    print(f"wrote {out / 'speed_accuracy.json'}, {out / 'speed_accuracy.png'} and {out / 'table_convergence.png'}")
    return 0


def _picture(out: Path, name: str, ref: np.ndarray) -> None:
    default = np.load(out / "_tmp_default.npy")
    weak = np.load(out / "_tmp_premult.npy")
    slug = "".join(ch if ch.isalnum() else "_" for ch in name)[:30]
    tetvr.write_png(np.concatenate([default, weak, ref], axis=1), out / f"scene_{slug}.png", background=(0, 0, 0))


def _chart(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = report["scenes"]
    if not scenes:
        return
    n = len(scenes)
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(6.2 * cols, 4.8 * rows), squeeze=False)
    names = list(report["variants"])
    cmap = plt.get_cmap("tab20")
    for ax, (scene, data) in zip(axes.flat, scenes.items()):
        for i, key in enumerate(names):
            r = data["variants"].get(key)
            if r is None:
                continue
            marker = "*" if key == "default" else ("o" if r["pareto"] else "x")
            ax.scatter(r["frame_s"] * 1e3, max(r["rmse"], 1e-7), s=160 if key == "default" else 45,
                       color="black" if key == "default" else cmap(i % 20), marker=marker,
                       label=key, zorder=3 if key == "default" else 2)
        front = sorted((r["frame_s"] * 1e3, max(r["rmse"], 1e-7)) for r in data["variants"].values() if r["pareto"])
        if front:
            ax.plot(*zip(*front), color="grey", lw=1, ls="--", zorder=1)
        ax.axhline(ERROR_FLOOR, color="grey", lw=0.8, ls=":", zorder=1)
        ax.annotate("16-bit rounding noise: errors below tie", (0.02, ERROR_FLOOR), xycoords=("axes fraction", "data"),
                    xytext=(0, -9), textcoords="offset points", fontsize=7, color="grey")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("frame CPU time per view change [ms]")
        ax.set_ylabel("RMSE vs reference (premultiplied RGB)")
        ax.set_title(f"{scene} ({data['n_tets']} tets)")
        ax.grid(True, which="both", alpha=0.3)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle(f"tetvr: speed vs accuracy at {report['size'][0]}x{report['size'][1]} "
                 f"({report.get('gl', {}).get('GL_RENDERER', '?')}); * default, o Pareto front, x dominated")
    fig.tight_layout(rect=(0, 0.08 + 0.02 * (len(names) // 4), 1, 0.96))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _sweep_chart(report: dict, path: Path) -> None:
    """PSNR against scalar bins N, one line per (K, base), one panel per scene."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = {k: v for k, v in report["scenes"].items() if v.get("table_convergence")}
    if not scenes:
        return
    fig, axes = plt.subplots(1, len(scenes), figsize=(4.2 * len(scenes), 3.9), squeeze=False)
    for ax, (scene, data) in zip(axes.flat, scenes.items()):
        rows = data["table_convergence"]
        for k, base in SWEEP_SLICES:
            pts = sorted((r["n_bins"], r["psnr"]) for r in rows if (r["n_slices"], r["log_base"]) == (k, base))
            ax.plot(*zip(*pts), marker="o", label=f"K={k}, base {base}")
        d = DEFAULT
        mine = [r["psnr"] for r in rows if (r["n_bins"], r["n_slices"], r["log_base"]) ==
                (d.table_scalar_bins, d.table_thickness_slices, d.table_log_base)]
        if mine:
            ax.scatter([d.table_scalar_bins], mine, s=180, marker="*", color="black", zorder=3, label="default")
        ax.set_xscale("log", base=2)
        ax.set_xlabel("scalar bins N")
        ax.set_ylabel("PSNR vs reference [dB]")
        ax.set_title(scene, fontsize=10)
        ax.grid(True, alpha=0.3)
    axes.flat[0].legend(fontsize=7)
    fig.suptitle("Where the table error comes from: PSNR by scalar bins N and thickness slices (K, log base)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())

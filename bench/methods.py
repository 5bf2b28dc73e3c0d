"""tetvr's two methods against each other on this machine's GL: made for a lent GPU.

``vs_vtk.py`` needs VTK, whose wheel does not travel to a lent GPU machine (nothing can be
installed there but what is carried, 64 MiB in all). Here the peer in the same run is the
other method: for each corpus mesh (``vs_vtk.py``'s cubes and the data's meshes,
``bench/corpus.py``'s made meshes where they are cached, and cubes past 2M tets) and each
``--sizes``, tet marching and projected tetrahedra, each in its own ``Renderer`` kept for
the mesh, take frames **in turn**, every frame a view change (``--step`` degrees about the
view up, as ``vs_vtk.py``); after a warm-up frame, the median of R frames (more for fast
frames, :func:`_common.timed_repeats`). Each renderer's first frame of each mesh is timed on
its own (the records or the table, the upload; for the first mesh the driver's shader
compiles too). ``auto``'s pick is recorded for every timed view.

Accuracy is measured apart, where the exact CPU reference can take its time: the first view
of each mesh at ``--image-size`` from both methods is kept (16-bit fixed point, ``methods_images_*.npz``),
and ``python bench/methods.py --accuracy RESULTS`` (on any machine with the meshes) renders
the reference and adds, per image, the largest per-pixel error, the pixels beyond 1/255
and PSNR to the JSON; with ``--fit`` it also fits :class:`tetvr.order.method.CostModel`'s
constants for that GL from the timings (as ``cost_model.py`` does for llvmpipe).

    python bench/methods.py [--sizes 512 1024] [--out DIR] [--only NAME ...]
    python bench/methods.py --accuracy DIR [--fit]
    python bench/methods.py --chart bench/results/methods_gpu.json

Writes ``methods.json`` (after every mesh) and the images; ``--accuracy`` adds the chart
(``methods.png``; ``--chart`` draws it for any run's JSON). ``bench/device_check.sh`` runs it
on a lent NVIDIA machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import datetime as _dt
import functools
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import corpus  # noqa: E402
from _common import CUBE_NS, REAL_MESHES, TETS_DATA, load_quiet, machine, timed_repeats, write_json  # noqa: E402

from tetvr import Camera, Renderer  # noqa: E402
from tetvr.apps.animate import azimuth  # noqa: E402
from tetvr.gl.context import create_context  # noqa: E402
from tetvr.gl.filtering import filter_error, filter_in_shader  # noqa: E402
from tetvr.gl.interpolation import interpolate_in_shader, interpolation_error  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402
from tetvr.order.method import choose  # noqa: E402
from tetvr.render import default_transfer_function  # noqa: E402
from tetvr.settings import RenderSettings  # noqa: E402

#: Cubes past auto's old 2M-tet threshold (6 n^3 tets: 2.53M, 6M).
BIG_CUBE_NS = (75, 100)
METHODS = ("raymarch", "projected")
OPACITY = 0.5
#: Meshes per images file (a returned file is at most 16 MB).
IMAGES_PER_FILE = 5


def mesh_specs() -> list[tuple[str, Callable[[], Any]]]:
    """(name, loader) of every mesh whose source is here, the names as in ``vs_vtk.py``."""
    specs: list[tuple[str, Callable[[], Any]]] = [(f"cube({n})", functools.partial(synthetic.cube, n))
                                                   for n in CUBE_NS]
    for fname, field in REAL_MESHES:
        path = TETS_DATA / fname
        if path.exists():
            specs.append((f"{path.stem.removesuffix('_tets')} ({field})", functools.partial(load_quiet, path, field)))
    specs.extend(corpus.meshes())
    specs.extend((f"cube({n})", functools.partial(synthetic.cube, n)) for n in BIG_CUBE_NS)
    return specs


def bench_mesh(name: str, mesh: Any, sizes: list[int], image_size: int, step: float
               ) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Both methods on one mesh at every size, frames in turn; the record and the first
    view's images at ``image_size``."""
    tf = default_transfer_function(mesh, opacity=OPACITY)
    cam0 = Camera.fit(mesh)
    rec: dict[str, Any] = {"name": name, "n_tets": mesh.n_tets, "camera": cam0.to_dict(),
                           "transfer_function": tf.to_dict(), "first_frame_s": {}, "sizes": {}}
    renderers = {m: Renderer(RenderSettings(method=m)) for m in METHODS}
    images: dict[str, np.ndarray] = {}
    try:
        for m, r in renderers.items():
            t0 = time.perf_counter()
            images[m] = r.render(mesh, cam0, tf, size=(image_size, image_size))
            rec["first_frame_s"][m] = time.perf_counter() - t0
        for s in sizes:
            size = (s, s)
            warm = {}
            for m, r in renderers.items():  # warm-up view change at this size
                t0 = time.perf_counter()
                r.render(mesh, azimuth(cam0, step), tf, size=size)
                warm[m] = time.perf_counter() - t0
            repeats = timed_repeats(max(warm.values()), 5, 40)
            cams = [azimuth(cam0, step * (i + 2)) for i in range(repeats)]
            samples: dict[str, list[float]] = {m: [] for m in METHODS}
            for cam in cams:
                for m, r in renderers.items():
                    t0 = time.perf_counter()
                    r.render(mesh, cam, tf, size=size)
                    samples[m].append(time.perf_counter() - t0)
            med = {m: float(statistics.median(v)) for m, v in samples.items()}
            auto = [choose(RenderSettings(), mesh, cam, size) for cam in cams]
            faster = min(med, key=med.__getitem__)
            rec["sizes"][str(s)] = {
                "step_deg": step, "repeats": repeats, "median_s": med, "samples_s": samples,
                "auto_method": auto, "faster": faster,
                "auto_loss": med[max(set(auto), key=auto.count)] / med[faster] - 1.0}
            print(f"{name} {s}: march {med['raymarch'] * 1e3:.1f} ms, projected {med['projected'] * 1e3:.1f} ms,"
                  f" auto {sorted(set(auto))}", flush=True)
        rec["gl"] = renderers["raymarch"].gl_info
    finally:
        for r in renderers.values():
            r.release()
    return rec, images


def profile_frames(mesh: Any, size: int, step: float, top: int = 14) -> dict[str, Any]:
    """Where a view change's time goes, per method: the renderer's stage times
    (``Renderer(profile=True)``, which waits for the GPU after each stage) and the Python
    functions of most cumulative time (cProfile) over three view changes after a warm-up."""
    import cProfile
    import dataclasses as dc
    import io
    import pstats

    tf = default_transfer_function(mesh, opacity=OPACITY)
    cam0 = Camera.fit(mesh)
    out: dict[str, Any] = {}
    for m in METHODS:
        with Renderer(RenderSettings(method=m), profile=True) as r:
            r.render(mesh, cam0, tf, size=(size, size))
            r.render(mesh, azimuth(cam0, step), tf, size=(size, size))
            prof = cProfile.Profile()
            stages = []
            for i in range(3):
                cam = azimuth(cam0, step * (i + 2))
                prof.enable()
                r.render(mesh, cam, tf, size=(size, size))
                prof.disable()
                stages.append({k: v for k, v in dc.asdict(r.last_stats).items() if isinstance(v, float)})
            text = io.StringIO()
            pstats.Stats(prof, stream=text).sort_stats("cumulative").print_stats(top)
            out[m] = {"stages_s": {k: float(np.median([st[k] for st in stages])) for k in stages[0]},
                      "cprofile_3_frames": text.getvalue().splitlines()}
            marcher = getattr(r, "_marcher", None)
            if marcher is not None:
                out[m]["march_stats"] = {k: v for k, v in dc.asdict(marcher.last_stats).items()
                                         if isinstance(v, (int, float, bool))}
    return out


def run(args: argparse.Namespace) -> int:
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    res: dict[str, Any] = {"date": _dt.datetime.now().isoformat(timespec="seconds"), "machine": machine(),
                           "sizes": args.sizes, "image_size": args.image_size, "opacity": OPACITY, "meshes": []}
    ctx = create_context()
    try:  # what tetvr.gl.filtering and tetvr.gl.interpolation decided for this GL, and why
        res["linear_filter_error"] = filter_error(ctx)
        res["filter_in_shader"] = filter_in_shader(ctx)  # from the same probe, or TETVR_FILTER
        res["interpolation_error_px"] = interpolation_error(ctx)
        res["interpolate_in_shader"] = interpolate_in_shader(ctx)  # or TETVR_INTERPOLATE
    finally:
        ctx.release()
    pending: dict[str, dict[str, np.ndarray]] = {}
    part = 0

    def flush_images(force: bool) -> None:
        nonlocal part
        if pending and (force or len(pending) >= IMAGES_PER_FILE):
            arrays = {f"{m}|{name}": np.round(np.clip(img, 0.0, 1.0) * 65535.0).astype(np.uint16)
                      for name, imgs in pending.items() for m, img in imgs.items()}
            np.savez_compressed(out / f"methods_images_{part}.npz", **arrays)
            pending.clear()
            part += 1

    for name, load in mesh_specs():
        if args.only and not any(o in name for o in args.only):
            continue
        t0 = time.perf_counter()
        mesh = load()
        load_s = time.perf_counter() - t0
        rec, images = bench_mesh(name, mesh, args.sizes, args.image_size, args.step)
        rec["load_s"] = load_s
        if args.profile:
            rec["profile"] = profile_frames(mesh, args.sizes[0], args.step)
            for m, prof in rec["profile"].items():
                print(f"{name} {m}: " + ", ".join(f"{k} {v * 1e3:.1f} ms" for k, v in prof["stages_s"].items() if v),
                      flush=True)
                print("\n".join(prof["cprofile_3_frames"][:40]), flush=True)
        res["meshes"].append(rec)
        res.setdefault("gl", rec["gl"])
        pending[name] = images
        flush_images(False)
        write_json(out / "methods.json", res)
        del mesh
    flush_images(True)
    return 0


def accuracy(out: Path, fit: bool = False) -> None:
    """Add each kept image's error against the exact reference to ``out/methods.json``;
    with ``fit``, also the cost model's constants for that GL fitted on its timings (as
    ``cost_model.py``). Each mesh is loaded once for both."""
    from tetvr.core.image import psnr
    from tetvr.optics.transfer import TransferFunction
    from tetvr.reference.tets import render_reference

    import cost_model

    path = out / "methods.json"
    res = json.loads(path.read_text())
    images: dict[str, np.ndarray] = {}
    for f in sorted(out.glob("methods_images_*.npz")):
        with np.load(f) as z:
            images.update({k: z[k].astype(np.float32) / 65535.0 for k in z.files})
    loaders = dict(mesh_specs())
    size = (res["image_size"],) * 2
    rows = []
    for rec in res["meshes"]:
        kept = f"raymarch|{rec['name']}" in images
        if rec["name"] not in loaders or not (kept or fit):
            continue
        mesh, cam0 = loaders[rec["name"]](), Camera.from_dict(rec["camera"])
        if kept:
            ref = render_reference(mesh, cam0, TransferFunction.from_dict(rec["transfer_function"]), size)
            rec["accuracy"] = {}
            for m in METHODS:
                image = images[f"{m}|{rec['name']}"]
                err = np.abs(image - ref).max(axis=-1)
                # Kept as 16-bit fixed point: its rounding (7.6e-6) is far inside 1/255.
                rec["accuracy"][m] = {"max_error": float(err.max()), "pixels_beyond_1_255": int((err > 1 / 255).sum()),
                                      "psnr_db": psnr(image, ref)}
            print(rec["name"], rec["accuracy"], flush=True)
            write_json(path, res)
        if fit:
            for s, run_ in rec["sizes"].items():
                cams = [azimuth(cam0, run_["step_deg"] * (i + 2)) for i in range(run_["repeats"])]
                rows.append(cost_model._row(rec["name"], mesh, cams, (int(s), int(s)), run_["median_s"]))
        del mesh
    if fit:
        model = cost_model.fit(rows)
        res["cost_model"] = {"fitted_ns": dataclasses.asdict(model), "rows": rows}
        print(model, flush=True)
        write_json(path, res)


def plot(res: dict[str, Any], path: Path) -> None:
    """The run's chart: each method's time per view change at each size (log scale), and
    its first view's PSNR against the reference where ``--accuracy`` measured it."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no chart (pip install -e '.[bench]')")
        return
    meshes = res["meshes"]
    names = [f"{m['name'].split(' ')[0].split('_')[0]}\n{m['n_tets'] / 1e3:.0f}k" for m in meshes]
    x = np.arange(len(meshes))
    fig, ax = plt.subplots(1, 2, figsize=(16, 5.4))
    colors = {"raymarch": ("#1f77b4", "#9ecae1"), "projected": ("#2ca02c", "#a1d99b")}
    labels = {"raymarch": "tet marching", "projected": "projected tetrahedra"}
    bars = [(m, s) for m in METHODS for s in res["sizes"]]
    w = 0.8 / len(bars)
    for i, (method, size) in enumerate(bars):
        ax[0].bar(x + (i - (len(bars) - 1) / 2) * w, [r["sizes"][str(size)]["median_s"][method] * 1e3 for r in meshes],
                  w, color=colors[method][res["sizes"].index(size) % 2], label=f"{labels[method]}, {size}x{size}")
    ax[0].set_yscale("log")
    ax[0].set_ylabel("ms per view change (median)")
    ax[0].set_title("Frame time per view change, frames in turn")
    ax[0].legend()
    if all("accuracy" in m for m in meshes):
        for i, method in enumerate(METHODS):
            ax[1].bar(x + (i - 0.5) * 0.4, [m["accuracy"][method]["psnr_db"] for m in meshes], 0.4,
                      color=colors[method][0], label=labels[method])
        ax[1].axhline(90.0, color="k", lw=0.8, ls="--", label="90 dB")
        ax[1].set_ylabel(f"PSNR vs exact reference (dB), {res['image_size']}x{res['image_size']}")
        ax[1].set_title("Accuracy of the first view (premultiplied RGB)")
        ax[1].legend(loc="lower right")
    for a in ax:
        a.set_xticks(x)
        a.set_xticklabels(names, fontsize=7)
    fig.suptitle(f"tetvr's two methods on {res['gl']['GL_RENDERER']} ({res['date'][:10]})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 1024], help="frame sizes (square)")
    ap.add_argument("--image-size", type=int, default=512, help="size of the kept first-view images")
    ap.add_argument("--step", type=float, default=3.0, help="degrees the camera turns per frame")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "methods")
    ap.add_argument("--only", nargs="+", default=None, metavar="NAME", help="meshes whose names contain NAME")
    ap.add_argument("--accuracy", type=Path, default=None, metavar="DIR",
                    help="add the kept images' errors against the reference to DIR/methods.json")
    ap.add_argument("--fit", action="store_true", help="with --accuracy: also fit the cost model")
    ap.add_argument("--chart", type=Path, default=None, metavar="JSON",
                    help="draw the chart of a run's JSON beside it (JSON with .png)")
    ap.add_argument("--profile", action="store_true",
                    help="also profile three view changes per method (stage times, cProfile) at the first size")
    args = ap.parse_args(argv)
    if args.chart is not None:
        plot(json.loads(args.chart.read_text()), args.chart.with_suffix(".png"))
        return 0
    if args.accuracy is not None:
        accuracy(args.accuracy, fit=args.fit)
        plot(json.loads((args.accuracy / "methods.json").read_text()), args.accuracy / "methods.png")
        return 0
    return run(args)


if __name__ == "__main__":
    raise SystemExit(main())

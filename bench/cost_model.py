"""The cost model ``method="auto"`` chooses by, fitted on the corpus's measured view changes.

``tetvr.order.method.CostModel`` predicts a view change's seconds by each method from what
each pays for: tet marching per ray--tet segment, per entering ray and per tet; projected
tetrahedra per tet, per fragment (a segment) and per frame. This script takes the view
changes ``bench/vs_vtk.py`` measured (``vs_vtk.json`` and ``vs_vtk_1024.json``: every corpus
mesh, grids and unstructured, at 512x512 and 1024x1024, both methods timed in turn), computes
the inputs the model sees at run time for the same cameras (estimated segments,
:func:`~tetvr.order.method.segments_per_tet`; entering rays,
:func:`~tetvr.order.method.entering_rays`; averaged over the timed views), and fits each
method's coefficients by least squares on relative error with non-negative coefficients
(``scipy.optimize.nnls``).

It writes ``cost_model.json``: the fitted coefficients, and per scene the measured and
predicted seconds, the faster method measured, what ``auto`` takes with the coefficients
in ``tetvr.order.method.LLVMPIPE`` (projected tetrahedra only where their cell order is
exact, :func:`~tetvr.order.method.order_exact`, and predicted ``AUTO_MARGIN`` times
faster) and how much slower that is than the faster method; and ``cost_model.png``
(predicted against measured).

``--held-out`` also times both methods, in turn (a warm-up and 5 view changes of 3 degrees,
medians), on scenes the fit did not see (:func:`held_out_scenes`: coarse cubes at
1024x1024, a close perspective, cell data, the beam zoomed in) and assesses the model on
them (``held_out`` in the JSON): run it on a quiet machine.
``tests/test_cost_model.py`` checks that ``LLVMPIPE`` holds the fitted coefficients.

    python bench/cost_model.py [--results bench/results] [--held-out]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from tetvr import Camera  # noqa: E402
from tetvr.order.method import (AUTO_MARGIN, LLVMPIPE, CostModel, entering_rays, order_exact,  # noqa: E402
                                segments_per_tet)
from tetvr.settings import RenderSettings  # noqa: E402

#: The runs the model is fitted on.
RUNS = ("vs_vtk.json", "vs_vtk_1024.json")
#: Each method's inputs, in the order of its coefficients in CostModel.
MARCH_TERMS = ("segments", "rays", "tets")
PROJECTED_TERMS = ("tets", "segments", "frame")


def _row(name: str, mesh: Any, cams: list[Camera], size: tuple[int, int],
         measured: dict[str, float]) -> dict[str, Any]:
    """A scene's row: the model's inputs averaged over its timed views, and its times."""
    return {"name": name, "size": list(size), "tets": mesh.n_tets,
            "segments": float(np.mean([segments_per_tet(mesh, c, size) for c in cams]) * mesh.n_tets),
            "rays": float(np.mean([entering_rays(mesh, c, size) for c in cams])),
            "order_exact": order_exact(RenderSettings(), mesh), "measured_s": measured}


def scene_rows(results: Path, known: list[dict[str, Any]] = ()) -> list[dict[str, Any]]:
    """One row per (mesh, size) timed by both methods: the model's inputs and the times
    (each mesh loaded once for all the runs). A row of ``known`` (the last fit's) with the
    same name, size and measured times is taken as it is: its inputs were computed from
    the mesh those times were measured on (a remade fTetWild mesh differs in its cells,
    and takes an hour to make)."""
    import vs_vtk
    from tetvr.apps.vtkcompare import orbit

    loaders = dict(vs_vtk._mesh_specs(False, vs_vtk.DEFAULT_DATA)[0])
    def key(name: str, size: int, measured: dict[str, float]) -> tuple[Any, ...]:
        return name, size, measured["raymarch"], measured["projected"]

    kept = {key(r["name"], r["size"][0], r["measured_s"]): r for r in known}
    timed: dict[str, list[tuple[dict[str, Any], dict[str, Any], dict[str, float]]]] = {}
    for run in RUNS:
        res = json.loads((results / run).read_text())
        for m in res["meshes"]:
            times = m["view_change_median_s"]
            march = times.get("tetvr_march", times["tetvr"] if set(m.get("auto_method", ["raymarch"])) == {"raymarch"}
                              else None)
            if "tetvr_projected" in times and march is not None:
                measured = {"raymarch": march, "projected": times["tetvr_projected"]}
                timed.setdefault(m["name"], []).append((res, m, measured))
    rows = []
    for name, records in timed.items():
        rows.extend(kept[k] for k in (key(name, res["size"][0], measured) for res, _, measured in records) if k in kept)
        todo = [rec for rec in records if key(name, rec[0]["size"][0], rec[2]) not in kept]
        if not todo or name not in loaders:
            continue
        mesh = loaders[name]()
        for res, m, measured in todo:
            cam0, size = Camera.from_dict(m["camera"]), tuple(res["size"])
            cams = [orbit(cam0, res["step_deg"] * (i + 1)) for i in range(1, res["repeats"] + 1)]
            rows.append(_row(name, mesh, cams, size, measured))
            print(f"{name} {size[0]}: {rows[-1]['segments']:.3g} segments, {rows[-1]['rays']:.3g} rays", flush=True)
        del mesh
    order = list(timed)
    return sorted(rows, key=lambda r: (r["size"][0], order.index(r["name"])))


def held_out_scenes() -> list[tuple[str, Any, Camera, Any, tuple[int, int]]]:
    """Scenes outside the fit: (name, mesh, camera, transfer function, size)."""
    import speed_accuracy
    from tetvr.mesh import synthetic
    from tetvr.render import default_transfer_function

    out = []
    for n in (3, 6, 8, 12):
        mesh = synthetic.cube(n)
        out.append((f"cube({n})", mesh, Camera.fit(mesh), default_transfer_function(mesh, opacity=0.5), (1024, 1024)))
    wanted = ("convex, close perspective", "cell data (4 levels)", "beam_tet4_result_100.vtu")
    for name, mesh, camera, tf in speed_accuracy.scenes():
        if name in wanted:
            out.extend((f"{name} (speed_accuracy.py)", mesh, camera, tf, (s, s)) for s in (512, 1024))
    return out


def time_held_out(repeats: int = 5, step: float = 3.0) -> list[dict[str, Any]]:
    """Both methods on :func:`held_out_scenes`, frames in turn: the model's inputs and the
    medians, as :func:`scene_rows` gives them."""
    import statistics
    import time

    import tetvr
    from tetvr.apps.vtkcompare import orbit

    rows = []
    for name, mesh, cam0, tf, size in held_out_scenes():
        renderers = {m: tetvr.Renderer(RenderSettings(method=m)) for m in ("raymarch", "projected")}
        times: dict[str, list[float]] = {m: [] for m in renderers}
        cams = [orbit(cam0, step * (i + 1)) for i in range(repeats + 1)]
        try:
            for i, cam in enumerate(cams):
                for method, r in renderers.items():
                    t0 = time.perf_counter()
                    r.render(mesh, cam, tf, size=size)
                    if i:
                        times[method].append(time.perf_counter() - t0)
        finally:
            for r in renderers.values():
                r.release()
        rows.append(_row(name, mesh, cams[1:], size, {m: float(statistics.median(v)) for m, v in times.items()}))
        print(f"held out: {name} {size[0]}: {rows[-1]['measured_s']}", flush=True)
    return rows


def fit(rows: list[dict[str, Any]]) -> CostModel:
    """Both methods' coefficients (ns), least squares on relative error, non-negative."""
    from scipy.optimize import nnls

    def solve(method: str, terms: tuple[str, ...]) -> np.ndarray:
        x = np.array([[1.0 if t == "frame" else r[t] for t in terms] for r in rows])
        t = np.array([r["measured_s"][method] for r in rows])
        coef, _ = nnls(x / t[:, None], np.ones_like(t))
        return coef * 1e9

    m, p = solve("raymarch", MARCH_TERMS), solve("projected", PROJECTED_TERMS)
    return CostModel(*(float(f"{v:.3g}") for v in (*m, *p)))


def assess(rows: list[dict[str, Any]], model: CostModel) -> None:
    """Per row: the predicted seconds, the faster method measured, what "auto" takes with
    ``model`` (projected only where its order is exact) and its loss against the faster."""
    for r in rows:
        pred = model.seconds(r["tets"], r["segments"], r["rays"])
        meas = r["measured_s"]
        auto = "projected" if r["order_exact"] and AUTO_MARGIN * pred["projected"] < pred["raymarch"] else "raymarch"
        faster = min(meas, key=meas.get)
        r.update(predicted_s=pred, faster=faster, auto=auto, auto_loss=meas[auto] / meas[faster] - 1.0,
                 faster_if_exact=faster == "raymarch" or r["order_exact"])


def plot(rows: list[dict[str, Any]], held: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    for method, marker in (("raymarch", "o"), ("projected", "s")):
        for size, colour in ((512, "tab:blue"), (1024, "tab:orange")):
            sel = [r for r in rows if r["size"][0] == size]
            ax.scatter([r["measured_s"][method] for r in sel], [r["predicted_s"][method] for r in sel],
                       marker=marker, color=colour, facecolors="none" if method == "projected" else colour,
                       label=f"{'tet marching' if method == 'raymarch' else 'projected tetrahedra'}, {size}x{size}")
    for method, marker in (("raymarch", "o"), ("projected", "s")):
        ax.scatter([r["measured_s"][method] for r in held], [r["predicted_s"][method] for r in held],
                   marker=marker, color="tab:red", facecolors="none" if method == "projected" else "tab:red",
                   label=f"{'tet marching' if method == 'raymarch' else 'projected tetrahedra'}, held out")
    lo = min(min(r["measured_s"].values()) for r in rows + held) * 0.8
    hi = max(max(r["measured_s"].values()) for r in rows + held) * 1.25
    ax.plot([lo, hi], [lo, hi], color="0.5", lw=0.8)
    ax.set(xscale="log", yscale="log", xlim=(lo, hi), ylim=(lo, hi), xlabel="measured s per view change",
           ylabel="predicted s (tetvr.order.method.LLVMPIPE)",
           title="auto's cost model against the corpus (llvmpipe)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", type=Path, default=ROOT / "bench" / "results")
    ap.add_argument("--held-out", action="store_true", help="also time both methods on scenes outside the fit")
    args = ap.parse_args(argv)
    path = args.results / "cost_model.json"
    last = json.loads(path.read_text()) if path.exists() else {}
    held = time_held_out() if args.held_out else last.get("held_out", [])
    rows = scene_rows(args.results, last.get("scenes", []))
    fitted = fit(rows)
    assess(rows, LLVMPIPE)
    assess(held, LLVMPIPE)
    worst = max(r["auto_loss"] for r in rows)
    out = {"what": __doc__.split("\n\n")[0], "runs": list(RUNS), "fitted_ns": fitted.__dict__,
           "llvmpipe_ns": LLVMPIPE.__dict__, "auto_margin": AUTO_MARGIN, "max_auto_loss": worst,
           "max_prediction_error": max(abs(r["predicted_s"][k] / r["measured_s"][k] - 1) for r in rows
                                       for k in ("raymarch", "projected")),
           "scenes": rows, "held_out": held}
    path.write_text(json.dumps(out, indent=1) + "\n")
    plot(rows, held, args.results / "cost_model.png")
    for r in rows + held:
        print(f"{r['name'][:30]:30s} {r['size'][0]:5d} measured p/m {r['measured_s']['projected'] / r['measured_s']['raymarch']:.2f}"
              f" predicted {r['predicted_s']['projected'] / r['predicted_s']['raymarch']:.2f} auto {r['auto']:9s}"
              f" loss {r['auto_loss']:.0%}")
    print(f"fitted (ns): {fitted}\nauto's largest loss against the faster method: {worst:.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

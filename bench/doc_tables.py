"""The benchmark tables the docs quote, generated from the JSON in bench/results.

Every table sits in a Markdown file between ``<!-- table:NAME -->`` and
``<!-- /table:NAME -->``, every number in a sentence between ``<!-- value:NAME -->`` and
``<!-- /value -->`` (bench/doc_values.py, which also reads the numbers docs/make_images.py
writes beside its pictures); this script rewrites them from the JSON (``--write``) or
checks that they agree (the default; ``tests/test_doc_tables.py`` runs the check), so the
README, the docs and bench/README.md cannot quote numbers the JSON does not hold.

    python bench/doc_tables.py [--write]
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
sys.path.insert(0, str(Path(__file__).resolve().parent))
import doc_values  # noqa: E402 - the numbers in sentences, beside this module

#: Files whose table blocks and value spans this script owns.
DOCS = (ROOT / "README.md", ROOT / "bench" / "README.md", *sorted((ROOT / "docs").glob("*.md")))


def _load(name: str) -> dict[str, Any]:
    return json.loads((RESULTS / name).read_text())


def methods_vs_vtk(name: str = "vs_vtk.json") -> str:
    """Per view change at the benchmark's size: both tetvr methods against VTK's PT, and
    their accuracy against the exact reference (bench/vs_vtk.py); the first frames' ratio
    and the target where the JSON has them."""
    r = _load(name)
    first = all("first_frame_vs_vtk_pt" in m for m in r["meshes"])
    rows = ["| mesh | tets | default ms | projected tetrahedra ms | VTK PT ms | VTK / default "
            "| VTK / projected |" + (" VTK / default, first frame | target |" if first else "")
            + " PSNR default | PSNR projected | PSNR VTK |",
            "|---|---:|---:|---:|---:|---:|---:|" + ("---:|---|" if first else "") + "---:|---:|---:|"]
    for m in sorted(r["meshes"], key=lambda m: m["n_tets"]):
        v, s, p = m["view_change_median_s"], m["speedup_vs_vtk_pt"], m["psnr"]
        if "tetvr_projected" not in v:
            continue
        extra = ""
        if first:
            t = m["target"]
            missed = ([f"view change ({t['speedup_wanted']:g}x)"] if doc_values.view_change_missed(m) else []) \
                + ([] if t["first_frame_met"] else ["first frame (1x)"])
            extra = f" {m['first_frame_vs_vtk_pt']['tetvr']:.2f} | {'missed: ' + ', '.join(missed) if missed else 'met'} |"
        rows.append(f"| {m['name']} | {m['n_tets']:,} | {v['tetvr'] * 1e3:.0f} | {v['tetvr_projected'] * 1e3:.0f} "
                    f"| {v['vtk_pt'] * 1e3:.0f} | {s['tetvr']:.2f} | {s['tetvr_projected']:.2f} |{extra}"
                    f" {p['tetvr']['exact']:.1f} | {p['tetvr_projected']['exact']:.1f} | {p['vtk_pt']['exact']:.1f} |")
    size = "x".join(str(x) for x in r["size"])
    counts = {len(m.get("first_frame_samples_s", {}).get("tetvr", [None])) for m in r["meshes"]}
    n_first = counts.pop() if len(counts) == 1 else 1  # the same count on every mesh, else not said
    firsts = (f"first frames the median of {n_first} of the default and of VTK's, each on the mesh loaded again, "
              if first and n_first > 1 else "")
    return (f"{size}; default: `method=\"auto\"` (tet marching unless the scene needs projected tetrahedra or the cost model predicts them clearly faster, see above); "
            f"median of {r['repeats']} view changes, frames in turn, {firsts}{r.get('gl_renderer', '?')}, "
            f"VTK {r.get('vtk_version', '?')}; PSNR (dB) of premultiplied RGB against the exact reference "
            f"({r['date']}, `bench/results/{name}`).\n\n" + "\n".join(rows))


def methods_vs_vtk_inside() -> str:
    """Views from inside each mesh (bench/vs_vtk.py's ``inside``): the default and VTK's PT
    per view change at both sizes, and their accuracy against the exact reference."""
    runs = [r for r in (_load("vs_vtk.json"), _load("vs_vtk_1024.json")) if any("inside" in m for m in r["meshes"])]
    if not runs:
        return "No run of `bench/vs_vtk.py` with views from inside yet."
    by_name: dict[str, dict[str, Any]] = {}
    for r in runs:
        for m in r["meshes"]:
            if "inside" in m:
                by_name.setdefault(m["name"], {"n_tets": m["n_tets"]})[r["size"][0]] = m["inside"]
    sizes = [r["size"][0] for r in runs]
    head = "| mesh | tets |" + "".join(f" {s}²: default ms | VTK PT ms | VTK / default |" for s in sizes)
    rows = [head + " PSNR default | PSNR VTK | largest error, default | VTK |",
            "|---|---:|" + "---:|---:|---:|" * len(sizes) + "---:|---:|---:|---:|"]
    acc_size = None
    for name, per in sorted(by_name.items(), key=lambda kv: kv[1]["n_tets"]):
        cells = ""
        for s in sizes:
            ins = per.get(s)
            cells += (f" {ins['view_change_median_s']['tetvr'] * 1e3:.0f} | {ins['view_change_median_s']['vtk_pt'] * 1e3:.0f}"
                      f" | {ins['speedup_vs_vtk_pt']:.2f} |") if ins else " | | |"
        acc = per[sizes[0]] if sizes[0] in per else per[sizes[-1]]
        acc_size = "x".join(str(v) for v in acc["accuracy_size"])
        rows.append(f"| {name} | {per['n_tets']:,} |{cells} {acc['psnr']['tetvr']:.1f} | {acc['psnr']['vtk_pt']:.1f} "
                    f"| {acc['max_error']['tetvr']:.1e} | {acc['max_error']['vtk_pt']:.2f} |")
    dates = ", ".join(f"{r['date'][:10]} `bench/results/{'vs_vtk' if r['size'][0] == 512 else 'vs_vtk_' + str(r['size'][0])}.json`"
                      for r in runs)
    return (f"The eye inside each mesh (at the centroid of the cell nearest its bounding box's centre, looking "
            f"along the box's longest axis, 60 degrees), the view turned {runs[0]['meshes'][0]['inside']['step_deg']:g} "
            f"degrees about the eye per frame; median of {runs[0]['repeats']} view changes, frames in turn; accuracy "
            f"(PSNR in dB, largest per-pixel error) against the exact reference at {acc_size} ({dates}).\n\n"
            + "\n".join(rows))


def methods_vs_vtk_1024() -> str:
    """:func:`methods_vs_vtk` at 1024x1024 (``bench/vs_vtk.py --size 1024``)."""
    return methods_vs_vtk("vs_vtk_1024.json")


def vs_paraview() -> str:
    """The README's one line against ParaView: the blunt fin, tetvr's default method
    against VTK's projected tetrahedra (ParaView's volume mapper for unstructured grids)."""
    r = _load("vs_vtk.json")
    m = next(m for m in r["meshes"] if m["name"].startswith("bluntfin"))
    v, p = m["view_change_median_s"], m["psnr"]
    size = "x".join(str(x) for x in r["size"])
    return (f"Against ParaView's renderer for unstructured grids (VTK {r.get('vtk_version', '?')}'s projected "
            f"tetrahedra), on the blunt fin's {m['n_tets']:,} tets at {size}: {p['tetvr']['exact']:.0f} dB against "
            f"the exact image where VTK reaches {p['vtk_pt']['exact']:.0f} dB, at {v['tetvr'] * 1e3:.0f} ms per "
            f"view change to VTK's {v['vtk_pt'] * 1e3:.0f} ms on the same software GL "
            f"(`bench/results/vs_vtk.json`, {r['date'][:10]}).")


_ANATOMY_TFS = {"linear": "linear", "default": "viridis (9 points)", "spike": "spike"}


def parity_anatomy() -> str:
    """VTK parity against VTK's own projected tetrahedra on bluntfin, and both against the
    reference in VTK's convention (bench/vs_vtk.py --anatomy)."""
    r = _load("vs_vtk_anatomy.json")
    rows = ["| transfer function, view | VTK PT vs tetvr parity | max difference | pixels beyond 1/255 "
            "| VTK PT vs reference in its own convention | tetvr parity vs that reference |",
            "|---|---:|---:|---:|---:|---:|"]
    for proj in ("parallel", "perspective"):
        for key, label in _ANATOMY_TFS.items():
            c = r["cases"][f"{key}, {proj}"]
            rows.append(f"| {label}, {proj} | {c['VTK PT vs tetvr parity']:.1f} dB "
                        f"| {c['VTK PT vs tetvr parity, max (1/255)']:.0f}/255 "
                        f"| {c['VTK PT vs tetvr parity, pixels beyond 1/255']} "
                        f"| {c['VTK PT vs reference in its own convention']:.1f} dB "
                        f"| {c['tetvr parity vs vtk reference']:.1f} dB |")
    size = "x".join(str(x) for x in r["size"])
    return (f"{r['mesh']}, {r['n_tets']:,} tets, {size}, `Camera.fit`; PSNR of premultiplied RGB, tetvr's "
            f"image rounded to 8 bits like VTK's window ({r['date'][:10]}, `bench/results/vs_vtk_anatomy.json`, "
            f"{r['vtk_status']}).\n\n" + "\n".join(rows))


def parity_vs_exact() -> str:
    """VTK's projected tetrahedra and tetvr's default against the exact image (bluntfin;
    bench/vs_vtk.py --anatomy)."""
    r = _load("vs_vtk_anatomy.json")
    size = "x".join(str(x) for x in r["size"])
    cases = r["cases"]
    rows = [f"| {r['mesh'].split()[0]}, {size} | " + " | ".join(f"{v} TF" if k == "linear" else v
                                                               for k, v in _ANATOMY_TFS.items()) + " |",
            "|---|---|---|---|"]
    for label, key in (("VTK projected tetra", "VTK PT vs exact reference"),
                       ("tetvr (default settings)", "tetvr vs exact reference")):
        rows.append(f"| {label}, parallel / perspective | " + " | ".join(
            f"{cases[f'{k}, parallel'][key]:.1f} / {cases[f'{k}, perspective'][key]:.1f} dB" for k in _ANATOMY_TFS)
            + " |")
    return "\n".join(rows)


def compare_demo() -> str:
    """All of tetvr's GPU modes and VTK's three mappers on the bundled demo (tetvr compare)."""
    r = json.loads((RESULTS / "compare_demo" / "comparison.json").read_text())
    names = {"tetvr": "tetvr GPU (default)", "tetvr_parity": "tetvr GPU, VTK parity",
             "vtk_pt": 'VTK "Projected tetra"', "vtk_bunyk": 'VTK "Bunyk ray cast"', "vtk_zsweep": 'VTK "Z sweep"'}
    rows = ["| method | first frame | view change | PSNR vs exact | vs reference in VTK's convention | vs VTK PT |",
            "|---|---|---|---|---|---|"]
    for m in r["methods"]:
        if m["key"] not in names:
            continue
        vs_pt = "" if m["key"] == "vtk_pt" else f"{m['psnr_vs_vtk_pt']:.1f} dB"
        rows.append(f"| {names[m['key']]} | {m['first_frame_s']:.2f} s | {m['view_change_s']:.3f} s "
                    f"| {m['psnr']['exact']:.1f} dB | {m['psnr']['vtk']:.1f} dB | {vs_pt} |")
    w, h = r["scene"]["size"]
    return (f"{r['scene']['n_tets']:,} tets, {w}x{h}, median of {r['timing']['views']} view changes; "
            f"{r['vtk'].get('status', '')} (`bench/results/compare_demo/comparison.json`).\n\n" + "\n".join(rows))


def raymarch_stages(name: str = "stages.json") -> str:
    """The ray caster's stages and cost per segment beside projected tetrahedra's frame
    (bench/stages.py)."""
    r = _load(name)
    rows = ["| mesh | tets | entry ms | march ms | frame ms | segments per tet | ns per segment (march) "
            "| layers | projected tetrahedra ms | projected / marching |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for m in r["meshes"]:
        rm = m.get("raymarch")
        if rm is None:
            continue
        md = rm["median"]
        rows.append(f"| {m['name']} | {m['n_tets']:,} | {md['entry'] * 1e3:.1f} | {md['march'] * 1e3:.1f} "
                    f"| {rm['wall_median'] * 1e3:.0f} | {rm['segments_per_tet']:.1f} "
                    f"| {rm['ns_per_segment']['march_wall']:.0f} | {rm['layers']} "
                    f"| {m['wall_median']['tet_unprofiled'] * 1e3:.0f} | {rm['speedup_vs_projected']:.2f} |")
    size = "x".join(str(x) for x in r["size"])
    return (f"{size}, `Camera.fit`, median of the repeats, wall time without per-stage waits "
            f"({r['timestamp']}, `bench/results/{name}`).\n\n" + "\n".join(rows))


def raymarch_stages_1024() -> str:
    """:func:`raymarch_stages` at 1024x1024 (``bench/stages.py --size 1024``)."""
    return raymarch_stages("stages_1024.json")


def spiky_tf() -> str:
    """Isosurface-like transfer functions: even against warped tables (bench/spiky_tf.py)."""
    r = _load("spiky_tf.json")
    rows = ["| scene | method | transfer function | table nodes | N | PSNR (dB) | max error | pixels > 1/255 | frame (ms) "
            "| frame / smooth TF's |", "|---|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for row in r["rows"]:
        t = row["table"]
        nodes = "warped" if t["warp"] else "even"
        label = "defaults" if row["table_warp"] == "auto" else 'table_warp="off"'
        rows.append(f"| {row['scene']} | {row['method']} | {row['tf']} | {nodes} ({label}) | {t['n_bins']} "
                    f"| {row['psnr']:.1f} | {row['max_error']:.4f} | {row['pixels_over_1_255']} "
                    f"| {row['frame_s'] * 1e3:.0f} | {row['frame_vs_smooth']:.2f} |")
    return (f"Measured by `bench/spiky_tf.py` at {r['size'][0]}x{r['size'][1]} against the CPU reference "
            f"({r['created']}, `bench/results/spiky_tf.json`; frame: process CPU time per view change, "
            "median of 3).\n\n" + "\n".join(rows))


def degenerate() -> str:
    """Faces through the eye: the sweep of sizes and jittered cameras (bench/degenerate.py)."""
    r = _load("degenerate.json")
    names = {"raymarch": "tet marching (default)", "projected": "projected tetrahedra"}
    rows = ["| method | views | NaN pixels | worst forward error | views with a pixel > 0.05 | pixels > 0.05 "
            "| worst backward error |", "|---|---:|---:|---:|---:|---:|---:|"]
    for method, s in r["summary"].items():
        back = f"{s['backward_max']:.2g}"
        if s.get("backward_not_computed"):
            back += f" ({s['backward_not_computed']} views not computed)"
        rows.append(f"| {names.get(method, method)} | {s['views']} | {s['nan_pixels']} | {s['forward_max']:.2g} "
                    f"| {s['views_with_forward_over_005']} | {s['pixels_with_forward_over_005']} | {back} |")
    sizes = r.get("sizes_done", r["sizes"])
    return (f"Measured by `bench/degenerate.py`: image sizes {sizes[0]} to {sizes[-1]} "
            f"({len(sizes)} sizes), {r['cameras_per_scene']} jittered cameras per scene, two scenes; backward error "
            f"over rays within 1/{round(1 / r['jitter_px'])} px (`bench/results/degenerate.json`).\n\n" + "\n".join(rows))


def _dist() -> dict[str, Any]:
    return _load("distributed.json")


def _when(r: dict[str, Any], part: dict[str, Any] | None = None) -> str:
    """The machine, the load it shared and the date of a run (``part``: of that part, which
    carries its own date and load)."""
    m = r.get("machine", {})
    r = part if part is not None else r
    load = r.get("load_average_1_5_15_min")
    shared = f", shared with other jobs (load average {load['start'][2]:.0f} at the last run)" if load else ""
    return f"{m.get('cpu_count', '?')} cores{shared}, {r['date'][:10]}, `bench/results/distributed.json`"


def distributed_series() -> str:
    """Time series on Dask against a serial loop (bench/distributed.py)."""
    r = _dist()
    s = r["series"]
    rows = ["| workers | serial frames/s | Dask frames/s | Dask / serial | Dask's own cost per frame | frames identical |",
            "|---:|---:|---:|---:|---:|---|"]
    for k, v in sorted(s["workers"].items(), key=lambda kv: int(kv[0])):
        rows.append(f"| {k} | {v['serial_frames_per_s']:.2f} | {v['dask_frames_per_s']:.2f} | {v['speedup']:.2f}x "
                    f"| {v['dask_overhead_s_per_frame'] * 1e3:.0f} ms | {'yes' if v['identical'] else 'NO'} |")
    size = "x".join(str(x) for x in s["size"])
    n_rounds = len(next(iter(s["workers"].values()))["rounds"])
    return (f"{s['steps']} steps of {s['mesh_tets']:,} tets, each read from its `.vtu` and rendered at {size}; "
            f"best of {n_rounds} alternated rounds ({_when(r)}).\n\n" + "\n".join(rows))


def distributed_bricks() -> str:
    """Sort-last bricks on 2 workers: split, first frame, view change, memory (bench/distributed.py)."""
    r = _dist()
    rows = ["| tets | P | method | cells cut | split (client) s | first frame s | per view change s (views) "
            "| peak memory per worker MiB |",
            "|---:|---:|---|---:|---:|---:|---:|---:|"]
    for res in r["bricks"]:
        for p, v in sorted(res["P"].items(), key=lambda kv: int(kv[0])):
            rows.append(f"| {res['n_tets']:,} | {p} | {v['method']} | {v['cells_cut']:,} | {v['split_s']:.2f} "
                        f"| {v['first_frame_s']:.2f} | {v['view_change_median_s']:.2f} ({len(v['view_change_s'])}) "
                        f"| {max(v['worker_peak_rss_mib']):.0f} |")
    size = "x".join(str(x) for x in r["bricks"][0]["size"])
    comp = r["composite"]
    c = ", ".join(f"{comp[p]['ns_per_pixel_per_brick']:.1f}" for p in sorted(comp, key=int))
    return (f"{size}, a rotated synthetic cube (planes cut cells), 2 worker processes on a fresh LocalCluster "
            f"per P, the median of the views of an orbit after the first ({_when(r)}). Compositing alone on the "
            f"client: {c} ns per pixel per brick (P = {', '.join(sorted(comp, key=int))}).\n\n" + "\n".join(rows))


def distributed_accuracy() -> str:
    """The acceptance matrix: composite vs single-process image and vs the reference."""
    r = _dist()["accuracy"]
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for c in r["cases"]:
        groups.setdefault((c["mesh"], c["method"]), []).append(c)
    counted = all("pixels_over_1e-5" in c for c in r["cases"])
    rows = ["| mesh | tets | method | cells cut (P = 2 / 4 / 8) | max abs difference vs one process "
            + ("| pixels beyond 1e-5 / 1/255 " if counted else "")
            + "| one process's max error vs the reference | PSNR bricks - one process (dB) |",
            "|---|---:|---|---|---:|" + ("---:|" if counted else "") + "---:|---|"]
    for (mesh, method), cs in groups.items():
        cut = " / ".join(str(next(c["cells_cut"] for c in cs if c["P"] == p)) for p in (2, 4, 8))
        d = [c["psnr_bricks"] - c["psnr_whole"] for c in cs]
        resolved = "/".join(sorted({c["resolved"] for c in cs}))
        name = {"auto": f"default ({resolved})", "exact": "tet marching, no table (integration exact)"}.get(method, method)
        count = (f"| {sum(c['pixels_over_1e-5'] for c in cs)} / {sum(c['pixels_over_1_255'] for c in cs)} "
                 if counted else "")
        rows.append(f"| {mesh} | {cs[0]['n_tets']:,} | {name} | {cut} | {max(c['max_abs_diff'] for c in cs):.1e} "
                    f"{count}| {max(c['whole_max_err_vs_ref'] for c in cs):.1e} | {min(d):+.2f} .. {max(d):+.2f} |")
    size = "x".join(str(x) for x in r["size"])
    when = f", {r['date']}" if "date" in r else ""
    return (f"{size}; P = 2, 4, 8; perspective, parallel and the eye inside: the worst of the 9, pixels summed "
            f"over the 27 (`bench/results/distributed.json`{when}).\n\n" + "\n".join(rows))


def _big_load(b: dict[str, Any]) -> str:
    """The 1-minute load average the big run's phases started and ended with (other jobs
    on the machine: what the seconds shared it with)."""
    phases = [(name, b[key].get("load_average_1_5_15_min")) for name, key in (("the cluster", "cluster"),
                                                                               ("the one process", "single"))]
    if not all(load for _, load in phases):
        return f"load average {b['start']['load_average_1_5_15_min'][0]:.0f} at the start"
    return "load average " + ", ".join(f"{load['start'][0]:.1f} to {load['end'][0]:.1f} over {name}"
                                       for name, load in phases)


def distributed_big() -> str:
    """One mesh of ~10M tets from solver pieces: bricks on a cluster of processes against
    one process, in one run (bench/distributed.py --only big)."""
    r = _dist()
    b = r["big"]
    c, s = b["cluster"], b["single"]
    w, h = c["size"]
    one = "one process" + ("" if b["single_same_mesh"] else f" ({s.get('n_tets', 0):,} tets)")
    rows = ["| | first frame s | per view change s (median of views) | peak resident memory MiB |",
            "|---|---:|---:|---|"]
    workers = " / ".join(f"{m:.0f}" for m in c["worker_peak_rss_mib"])
    rows.append(f"| {c['bricks']} bricks on {c['workers']} workers | {c['first_frame_s']:.1f} "
                f"| {c['view_change_median_s']:.1f} ({len(c['view_change_s'])}) | workers {workers}; scheduler "
                f"{c['scheduler_peak_rss_mib']:.0f}; client {c['client_peak_rss_mib']:.0f} |")
    if "first_frame_s" in s:
        rows.append(f"| {one} | {s['first_frame_s']:.1f} | {s['view_change_median_s']:.1f} "
                    f"({len(s['view_change_s'])}) | {s['peak_rss_mib']:.0f} |")
    else:
        rows.append(f"| {one} | failed: {s.get('failed', '?')} | | |")
    if "ratio" in b:
        rows.append(f"| one process's time / the bricks' | {b['ratio']['first_frame']:.2f} "
                    f"| {b['ratio']['view_change']:.2f} | |")
    text = (f"{c['n_tets']:,} tets (the rotated grid cube), written by the workers as {c['pieces']} `.vtu` pieces "
            f"and made into {c['bricks']} k-d bricks on them by `distribute_pieces` from a `file://` URL, so the "
            f"client reads no piece ({c['distribute_s']:.0f} s; each worker's peak "
            f"{max(c['worker_peak_rss_mib_distribute']):.0f} MiB by then); {w}x{h}, {c['method']}, composited on "
            f"the workers (the client received {max(c['client_received_bytes']) / 2**20:.0f} MiB a frame). The "
            f"scheduler and the {c['workers']} workers are processes of their own, and with the client and, after "
            f"them, the one process rendering the same frames, they share the same "
            f"{r['machine'].get('cpu_count', '?')} cores ({b['date'][:10]}, {_big_load(b)}; "
            f"`bench/results/distributed.json`, chart `bench/results/distributed_big.png`).")
    if "accuracy" in b:
        a = b["accuracy"]
        text += (f" The composite against the one process's image: at most {a['max_abs_diff']:.1e} per pixel, "
                 f"{a['pixels_over_1_255']} of the {a['pixels']:,} pixels of the {len(a['max_abs_diff_per_view'])} frames "
                 f"beyond 1/255 ({a['pixels_over_1e-5']} beyond 1e-5).")
    if "single_note" in b:
        text += f" {b['single_note'][0].upper()}{b['single_note'][1:]}."
    return text + "\n\n" + "\n".join(rows)


#: What the projection assumes beyond the measurements.
PROJECTION_PIXELS = 1024 * 1024
PROJECTION_LINK_BYTES_PER_S = 1.25e9  # 10 Gb/s Ethernet
PROJECTION_TETS = 1e9


def distributed_projection() -> str:
    """64 and 1,024 workers on a 10^9-tet mesh, on paper from the measured costs."""
    r = _dist()
    one = min(r["bricks"], key=lambda x: abs(x["n_tets"] - 1e6))
    p1 = one["P"]["1"]
    px = one["size"][0] * one["size"][1]
    # A view's cost grows with the cells and with the pixels; taken here as proportional to
    # their geometric mean (segments per tet fall as tets shrink on screen): a rough model.
    s_per_unit = p1["view_change_median_s"] / (one["n_tets"] * px) ** 0.5
    mib_per_tet = (max(p1["worker_peak_rss_mib"]) - max(p1["worker_start_rss_mib"])) / one["n_tets"]
    ns_comp = max(v["ns_per_pixel_per_brick"] for v in r["composite"].values())
    image_bytes = 16 * PROJECTION_PIXELS
    rows = ["| workers | tets per worker | render per view, each worker s | memory per worker GiB "
            "| compositing on the client s | images to the client s | binary swap: compositing s "
            "| binary swap: network s |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for w in (64, 1024):
        n = PROJECTION_TETS / w
        render = s_per_unit * (n * PROJECTION_PIXELS) ** 0.5
        mem = mib_per_tet * n / 1024
        client = w * PROJECTION_PIXELS * ns_comp * 1e-9
        net = w * image_bytes / PROJECTION_LINK_BYTES_PER_S
        # Binary swap: log2(w) rounds, each worker sending and compositing half of what it
        # holds; summed over the rounds, less than one image each way per worker.
        swap_comp = PROJECTION_PIXELS * ns_comp * 1e-9
        swap_net = image_bytes / PROJECTION_LINK_BYTES_PER_S
        rows.append(f"| {w:,} | {n / 1e6:.1f}M | {render:.1f} | {mem:.1f} | {client:.1f} | {net:.1f} "
                    f"| {swap_comp:.3f} | {swap_net:.3f} |")
    return (f"A 10^9-tet mesh, a 1024x1024 float32 RGBA image (16 MiB per brick), 10 Gb/s links; from the "
            f"{one['n_tets']:,}-tet mesh on one worker ({p1['view_change_median_s']:.2f} s per view at "
            f"{one['size'][0]}x{one['size'][1]}, {mib_per_tet * 1e6:.0f} MiB per million tets above the idle "
            f"worker) and {ns_comp:.1f} ns per pixel per brick of compositing ({_when(r)}).\n\n" + "\n".join(rows))



def _size(nbytes: float) -> str:
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{nbytes:.0f} B"


def distributed_compositing() -> str:
    """P images composited on the client (all gathered) and on the workers (radix-k), from
    images already on the workers; and whole frames both ways (bench/distributed.py)."""
    r = _dist()
    comp = r["compositing"]
    rows = ["| image | P | radix-k rounds | Dask tasks | client receives: all / radix-k | between workers (radix-k) "
            "| time s: all to the client / radix-k | max difference |",
            "|---|---:|---|---:|---:|---:|---:|---:|"]
    for x in comp["cases"]:
        cl, wk = x["client"], x["workers"]
        rows.append(f"| {x['size'][0]}x{x['size'][1]} | {x['P']} | {' x '.join(str(k) for k in x['factors'])} "
                    f"| {x['tasks']} | {_size(cl['workers_to_client_bytes'])} / {_size(wk['workers_to_client_bytes'])} "
                    f"| {_size(wk['between_workers_bytes'])} | {cl['best_s']:.3f} / {wk['best_s']:.3f} "
                    f"| {x['max_abs_diff']:.1e} |")
    c = comp["constants"]
    text = (f"P images held by {comp['workers']} workers in turn (slot i on worker i mod 2, as if each of P workers "
            f"held one), best of {len(comp['cases'][0]['client']['runs_s'])} alternated runs; bytes from Dask's "
            f"transfer logs ({_when(r, comp)}). Fitted on the 8x8 rows: {c['s_per_task'] * 1e3:.2f} ms per Dask task "
            f"(scheduler and workers together on these cores); \"over\" {c['over_ns_per_pixel']:.1f} ns per pixel "
            f"per image on one core.\n\n" + "\n".join(rows))
    if "frames" in r:
        f = r["frames"]
        frows = ["| P | frame s: all to the client / on the workers | client receives: all / on the workers "
                 "| max difference |", "|---:|---:|---:|---:|"]
        for p, v in sorted(f["P"].items(), key=lambda kv: int(kv[0])):
            frows.append(f"| {p} | {v['median_s']['client']:.2f} / {v['median_s']['workers']:.2f} "
                         f"| {_size(v['client_bytes']['client'])} / {_size(v['client_bytes']['workers'])} "
                         f"| {v['max_abs_diff']:.1e} |")
        text += (f"\n\nWhole frames, renders included: a grid cube of {f['n_tets']:,} tets in P k-d bricks on "
                 f"{f['workers']} workers at {f['size'][0]}x{f['size'][1]}, the median of "
                 f"{len(next(iter(f['P'].values()))['workers'])} views of an orbit.\n\n" + "\n".join(frows))
    return text


def _radix_factors(p: int, k: int = 4) -> list[int]:
    # tetvr.cluster.compositing.radix_factors, without importing tetvr here
    out, left = [], p
    while left > 1:
        f = next((d for d in range(min(k, left), 1, -1) if left % d == 0), None) or next(
            d for d in range(k + 1, left + 1) if left % d == 0)
        out.append(f)
        left //= f
    return out


def distributed_compositing_model() -> str:
    """Compositing P = 64 and 1,024 full-size images, on paper from the measured constants."""
    r = _dist()
    c = r["compositing"]["constants"]
    n = PROJECTION_PIXELS
    image = 16 * n
    link = PROJECTION_LINK_BYTES_PER_S
    over = c["over_ns_per_pixel"] * 1e-9
    rows = ["| P | all to the client: client receives | its network s | its compositing s "
            "| radix-k: client receives | each worker sends and composites | its network s | its compositing s "
            "| Dask tasks | scheduling s (at most) |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for p in (16, 64, 1024):
        factors = _radix_factors(p)
        tasks = p + p * sum(k + 1 for k in factors)
        share = 1 - 1 / p  # of one image, summed over the rounds
        rows.append(f"| {p:,} | {_size(p * image)} | {p * image / link:.1f} | {p * n * over:.1f} | {_size(image)} "
                    f"| {_size(share * image)} | {share * image / link:.3f} | {share * n * over:.3f} "
                    f"| {tasks:,} | {tasks * c['s_per_task']:.1f} |")
    return (f"A {int(n ** 0.5)}x{int(n ** 0.5)} float32 RGBA image ({_size(image)}) per brick, one brick per worker, "
            f"{link * 8 / 1e9:.0f} Gb/s links; radix-k in rounds of k = 4; {c['over_ns_per_pixel']:.1f} ns per pixel "
            f"per \"over\" and {c['s_per_task'] * 1e3:.2f} ms per Dask task as measured above (the tasks: one render "
            f"per brick, and per round and slot a slice per group member and a composite).\n\n" + "\n".join(rows))


def volume_accuracy() -> str:
    """The volume ray caster's defaults (and the commit before its "auto" sizing) against
    the reference at fine settings, with finer settings (bench/volume_accuracy.py)."""
    r = _load("volume_accuracy.json")
    rows = ["| volume | mode | default: PSNR (dB) | max error | pixels > 1/255 | step (voxels) | integration "
            "| frame (ms) | before: PSNR (dB) | max error | frame (ms) | finest: PSNR (dB) | frame (ms) |",
            "|---|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|"]
    for s in r["scenes"]:
        v = s["variants"]
        d = v["default"]
        before = next((x for k, x in v.items() if k.startswith("before")), None)
        fine = v[next(k for k in v if k.startswith("fine") or k == "step 1/16 voxel")]
        how = d.get("integration", "-")
        if how == "table":
            how = f"table, {d['table_scalar_bins']} bins"
        b = (f"{before['psnr']:.1f} | {before['max_error']:.4f} | {before['frame_s'] * 1e3:.0f}" if before
             else "- | - | -")
        rows.append(f"| {s['scene']} ({'x'.join(map(str, s['dims']))} {s['dtype']}) "
                    f"| {s['mode'].replace('emission_absorption', 'emission-absorption')} | {d['psnr']:.1f} "
                    f"| {d['max_error']:.4f} | {d['pixels_beyond_1_255']} of {d['covered_pixels']} "
                    f"| {d['step_voxels']:.3g} | {how} | {d['frame_s'] * 1e3:.0f} | {b} "
                    f"| {fine['psnr']:.1f} | {fine['frame_s'] * 1e3:.0f} |")
    size = "x".join(str(x) for x in r["size"])
    before = next((k for s in r["scenes"] for k in s["variants"] if k.startswith("before")), "before")
    return (f"Measured by `bench/volume_accuracy.py` at {size} against the CPU reference at 1/16-voxel pieces "
            f"({r['created']}, {r['gl'].get('GL_RENDERER', '?')}, `bench/results/volume_accuracy.json`; frame: wall "
            f"time, median of {r['repeats']}, variants interleaved). Before: the defaults of {before[8:-1] or 'the commit before'}"
            f" (half-voxel steps, a 256-bin table, 8-bit textures, termination 0.99), timed in a subprocess just "
            f"before the others (llvmpipe shares the cores with other work: compare frame times loosely); finest: 1/8-voxel steps, "
            f"exact integration and no early termination (MIP: 1/16-voxel steps).\n\n" + "\n".join(rows))


def viewer_latency() -> str:
    """The Jupyter viewer's latency in Chromium, from the input event to pixels on the page
    (bench/viewer.py)."""
    r = _load("viewer.json")
    labels = {"after": "`tetvr.apps.viewer.Viewer` (jupyter_rfb, render loop, render process)",
              "before": "ipywidgets.Image + ipyevents, rendering in the event handler"}
    rows = ["| mesh | tets | viewer | input → first pixels ms | mouse-up → full frame ms | frames shown during the drag "
            "| drag ms |", "|---|---:|---|---:|---:|---:|---:|"]

    def ms(x: float | None) -> str:
        return "never" if x is None else f"{x:.0f}"

    for name, m in r["meshes"].items():
        for variant in ("after", "before"):
            v = m.get(variant)
            if v is None:
                continue
            if "skipped" in v:
                rows.append(f"| {name} | {m['n_tets']:,} | {labels[variant]} | not measured: {v['skipped']} | | |")
                continue
            md, n = v["median"], len(v["runs"])
            frames = "–" if md["frames_in_drag"] is None else f"{md['frames_in_drag']:.0f}"
            rows.append(f"| {name} | {m['n_tets']:,} | {labels[variant]} ({n} drags) | {ms(md['first_pixels_ms'])} "
                        f"| {ms(md['full_frame_ms'])} | {frames} | {ms(md.get('drag_ms'))} |")
    size = "x".join(str(x) for x in r["size"])
    la = r.get("loadavg_start")
    load = f"1-minute load average {la[0]:.1f} on {r['machine'].get('cpu_count', '?')} cores" if la else "load unknown"
    goal = r.get("goal")
    aim = (f" Goal: the first pixels within {goal['first_pixels_ms']:.0f} ms of the input, the full frame within "
           f"{goal['full_frame_ms']:.0f} ms of mouse-up." if goal else "")
    return (f"{size} picture; {r['gesture']}; medians; headless Chromium and JupyterLab on the same machine, "
            f"Mesa llvmpipe, {load} ({r['date']}, `bench/results/viewer.json`).{aim}\n\n" + "\n".join(rows))


#: The stability table's columns: speed_accuracy.py variant -> heading.
_STABILITY_COLUMNS = {"projected tetrahedra": "projected tetrahedra",
                      "tet marching, no table (integration exact)": "tet marching, no table",
                      "uniform table nodes": "uniform table nodes",
                      "screen-linear interpolation": "screen-linear interpolation",
                      "premultiplied table": "premultiplied table", "uint8 framebuffer": "uint8 framebuffer",
                      "N=64": "N=64", "sort=centroid": "sort=centroid", "sort=none": "sort=none"}


def stability_cases() -> str:
    """docs/limits.md: every stability case (tetvr.scene.stability) with the default settings
    (PSNR, largest per-pixel error, pixels beyond 1/255) and with one setting changed (PSNR),
    from bench/speed_accuracy.py."""
    import warnings

    sys.path.insert(0, str(ROOT))
    from tetvr.scene.stability import CASES, case

    r = _load("speed_accuracy.json")

    def db(rec: dict[str, Any] | None) -> str:
        if rec is None or rec.get("psnr") is None:
            return "–"
        return "exact" if rec["psnr"] >= 150 else f"{rec['psnr']:.1f}"

    cols = [c for c in _STABILITY_COLUMNS if any(c in v for v in r["stability"].values())]
    rows = ["| case | what | default: PSNR | max error | % pixels > 1/255 | "
            + " | ".join(_STABILITY_COLUMNS[c] for c in cols) + " |",
            "|---|---|---:|---:|---:|" + "---:|" * len(cols)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, rec in sorted(r["stability"].items()):
            what = case(name).what if name in CASES else ""
            d = rec["default"]
            rows.append(f"| `{name}` | {what} | {db(d)} | {d['max_error']:.1e} | {d['pct_over_1_255']:.2f} | "
                        + " | ".join(db(rec.get(c)) for c in cols) + " |")
    return (f"PSNR (dB, premultiplied RGB) against the exact reference at 96x96 (speed_accuracy.py renders "
            f"the stability cases at that size), the default settings and one "
            f"setting changed per column ({r['created']}, `bench/results/speed_accuracy.json`).\n\n"
            + "\n".join(rows))


def imperfect_meshes() -> str:
    """docs/limits.md: each imperfect-mesh class, what ``auto`` chose, and every method's
    largest per-pixel error against the reference (bench/imperfect.py)."""
    r = _load("imperfect.json")

    def cell(rec: dict[str, Any]) -> str:
        if "refused" in rec:
            return "refused"
        return f"{rec['max_error']:.1e} ({rec['beyond']})"

    rows = ["| class | mesh | view | `auto` chose | default: max error (px > 1/255) | tet marching | projected tetrahedra |",
            "|---|---|---:|---|---:|---:|---:|"]
    for row in r["rows"]:
        chose = "tet marching" if row["auto_chose"] == "raymarch" else "projected tetrahedra, warns"
        rows.append(f"| {row['class']} | {row['mesh']} | {row['view']} | {chose} | {cell(row['auto'])} "
                    f"| {cell(row['raymarch'])} | {cell(row['projected'])} |")
    size = "x".join(str(x) for x in r["size"])
    return (f"Largest per-pixel error (RGBA) against `method=\"reference\"` at {size}, and in brackets the "
            f"pixels beyond 1/255; \"refused\": `method=\"raymarch\"` raised its error "
            f"({r['date']}, `bench/results/imperfect.json`, by `bench/imperfect.py`).\n\n" + "\n".join(rows))


def _sa_label(r: dict[str, Any], key: str) -> str:
    return r["peers"]["labels"].get(key, key)


def _sa_order(r: dict[str, Any]) -> list[str]:
    """tetvr's variants in their groups' order, then the peers."""
    return list(r["variants"]) + list(r["peers"]["labels"])


def speed_accuracy_summary() -> str:
    """docs/limits.md: every renderer over all scenes, per image size, as the summary chart
    draws it (bench/speed_accuracy.py)."""
    r = _load("speed_accuracy.json")
    sizes = list(r["summary"])
    rows = ["| group | renderer | " + " | ".join(sizes) + " |", "|---|---|" + "---:|" * len(sizes)]
    for key in _sa_order(r):
        cells = []
        for size in sizes:
            s = r["summary"][size]["renderers"].get(key)
            if s is None:
                cells.append("–")
                continue
            if key != "default" and s["same_as_default"] == s["n_scenes"]:
                cells.append("the default itself in every scene")
                continue
            cell = (f"{s['time_ratio']:.2f}x · {s['max_error_median']:.1e} (worst {s['max_error_worst']:.1e}) · "
                    f"{min(s['psnr_median'], 150):.0f} dB")
            cells.append(f"**{cell}**" if s["pareto_max"] else cell)
        group = r["groups"].get(key, "VTK")
        rows.append(f"| {group} | {_sa_label(r, key)} | " + " | ".join(cells) + " |")
    n = {size: len(s["scenes"]) for size, s in r["summary"].items()}
    return (f"Per cell: CPU time per view change relative to the default's (geometric mean over the scenes), "
            f"the median (and the worst) of each scene's largest per-pixel error, the median PSNR; **bold**: on the "
            f"Pareto front of time and largest error. "
            + ", ".join(f"{k}: {v} scenes" for k, v in n.items())
            + f"; {r['subsample']}; {r.get('gl', {}).get('GL_RENDERER', '?')}, {r['machine'].get('cpu_count', '?')} "
              f"cores, frames in turn ({r['created']}, `bench/results/speed_accuracy.json`).\n\n" + "\n".join(rows))


def speed_accuracy_peers() -> str:
    """docs/limits.md: per scene and size, tetvr's default beside VTK's three mappers, with
    links to each scene's chart (bench/speed_accuracy.py)."""
    sys.path.insert(0, str(ROOT / "bench"))
    from speed_charts import runs, slug

    r = _load("speed_accuracy.json")
    peers = list(r["peers"]["labels"])
    rows = ["| scene | tets | size | tetvr default | " + " | ".join(_sa_label(r, k) for k in peers) + " |",
            "|---|---:|---|" + "---:|" * (len(peers) + 1)]

    def cell(row: dict[str, Any] | None) -> str:
        if not row or "frame_s" not in row:
            return "failed" if row else "–"
        return f"{row['frame_s'] * 1e3:.0f} ms · {row['max_error']:.1e} · {min(row['psnr'], 150):.0f} dB"

    for size, scenes in runs(r).items():
        for name, rec in scenes.items():
            chart = f"[{name}](../bench/results/speed_accuracy_{slug(name)}.png)"
            rows.append(f"| {chart} | {rec['n_tets']:,} | {size} | {cell(rec['variants']['default'])} | "
                        + " | ".join(cell(rec["peers"].get(k)) for k in peers) + " |")
    return (f"Per cell: median CPU time per view change (all threads of the process that renders) · largest "
            f"per-pixel error · PSNR, against the exact "
            f"reference; each scene's name links to its chart ({r['created']}, "
            f"`bench/results/speed_accuracy.json`; {r['peers']['vtk']}; ParaView: {r['paraview']['reason']}).\n\n"
            + "\n".join(rows))


def speed_accuracy_stability() -> str:
    """docs/limits.md: the stability chart's numbers: per failure class, each method's
    largest per-pixel error (bench/speed_accuracy.py)."""
    r = _load("speed_accuracy.json")
    classes = r["stability_summary"]
    methods = list(classes[0]["methods"])

    def cell(rec: dict[str, Any]) -> str:
        text = "–" if rec["max_error"] is None else f"{rec['max_error']:.1e}"
        if rec["refused"]:
            text += f" (refused {rec['refused']}/{rec['of']})" if rec["max_error"] is not None else " refused"
        if rec["failed"]:
            text += f" (failed {rec['failed']}/{rec['of']})" if rec["max_error"] is not None else " failed"
        return text

    # within 1/255 in every view it drew; a refusal (tet marching, saying why) draws nothing wrong
    within = {m: sum((c["methods"][m]["max_error"] is None or c["methods"][m]["max_error"] <= 1 / 255)
                     and not c["methods"][m]["failed"] for c in classes) for m in methods}
    rows = ["| class | views | " + " | ".join("tetvr default" if m == "default" else _sa_label(r, m) for m in methods)
            + " |", "|---|---:|" + "---:|" * len(methods)]
    for c in classes:
        name = f"`{c['name']}`" if c["kind"] == "stability case" else c["name"]
        rows.append(f"| {name} | {c['views']} | " + " | ".join(cell(c["methods"][m]) for m in methods) + " |")
    n_cases = sum(c["kind"] == "stability case" for c in classes)
    size = "x".join(str(v) for v in r["stability_size"])
    return (f"Largest per-pixel error against the exact reference at {size}, over {n_cases} stability cases and "
            f"{len(classes) - n_cases} imperfect-mesh classes (the worst of each class's meshes and views). Within "
            f"1/255 in every view drawn (refused: raised an error saying why; failed: VTK drew nothing): "
            + ", ".join(f"{'tetvr default' if m == 'default' else _sa_label(r, m)} {within[m]} of {len(classes)}"
                        for m in methods)
            + f" ({r['created']}, `bench/results/speed_accuracy.json`).\n\n" + "\n".join(rows))


_FRAME_KINDS = {"raymarch": 'tet marching (`method="auto"` on this mesh, `"raymarch"`)',
                "projected": 'projected tetrahedra (`method="projected"`)',
                "raycast": "the volume ray caster (`tetvr.gl.Raycaster`)",
                "annotate": "`tetvr render`'s picture: legend and PNG, beyond the frame",
                "png": "the plain PNG (`--no-annotations`), beyond the frame"}


def frame_memory() -> str:
    """docs/limits.md: the host memory one frame adds per pixel, per method and for its
    picture, and per tet, measured (bench/frame_memory.py) beside the estimate
    tetvr.gl.framesize refuses frames by."""
    sys.path.insert(0, str(ROOT))
    from tetvr.gl import framesize as fs

    r = _load("frame_memory.json")
    rows = ["| what | measured: bytes a pixel | at the largest size | estimate: bytes a pixel |",
            "|---|---:|---:|---:|"]
    for kind, label in _FRAME_KINDS.items():
        m = r["per_pixel"][kind]
        last = m["rows"][-1]
        if kind in fs.TARGET_BYTES_PER_PIXEL:
            per_px, fixed = fs.TARGET_BYTES_PER_PIXEL[kind] + fs.READBACK_BYTES_PER_PIXEL, fs.FRAME_FIXED_BYTES
        else:
            per_px = fs.PICTURE_BYTES_PER_PIXEL[kind]
            fixed = fs.PNG_BLOCK_BYTES if kind == "png" else fs.ANNOTATE_FIXED_BYTES
        rows.append(f"| {label} | {m['rss_bytes_per_pixel']:.1f} | {last['rss_added'] / 2**20:.0f} MiB at "
                    f"{last['size'][0]}x{last['size'][1]} | {per_px} + {fixed >> 20} MiB |")
    c = r["context"]
    rows.append(f"| a renderer: its GL context and first small frame | | {c['rss_added'] / 2**20:.0f} MiB "
                f"({c['address_space_added'] / 2**20:.0f} MiB of address space) | {fs.CONTEXT_BYTES >> 20} MiB "
                f"({fs.CONTEXT_ADDRESS_SPACE >> 20} MiB of address space) |")
    tets = ["| method | mesh: bytes a tet | one frame adds: bytes a tet |", "|---|---:|---:|"]
    for kind in ("raymarch", "projected"):
        m = r["per_tet"][kind]
        tets.append(f"| {_FRAME_KINDS[kind].split(' (')[0]} | {m['mesh_bytes_per_tet']:.0f} "
                    f"| {m['frame_rss_bytes_per_tet']:.0f} |")
    sizes = ", ".join(f"{s}x{s}" for s in r["sizes"])
    n_tets = " and ".join(f"{row['n_tets']:,}" for row in r["per_tet"]["raymarch"]["rows"])
    png_sizes = ", ".join(f"{row['size'][0]}x{row['size'][1]}" for row in r["per_pixel"]["png"]["rows"])
    return (f"Measured by `bench/frame_memory.py` on {r['gl_renderer']} ({r['date']}, "
            f"`bench/results/frame_memory.json`): what one frame adds to a warm process's peak resident memory, "
            f"fitted over {sizes} (the PNG over {png_sizes}, "
            f"past its block of rows); the estimate is `tetvr.gl.framesize`'s on a GL that keeps its "
            f"targets in host memory.\n\n" + "\n".join(rows)
            + f"\n\nPer tet, on cubes of {n_tets} tets at 256x256: what the mesh holds, and what its first "
              "frame adds (tet marching's records and walk checks, projected tetrahedra's buffers and sort).\n\n"
            + "\n".join(tets))


def marching_memory() -> str:
    """docs/limits.md: the peak memory of a process that draws one frame of ~2M tets, tet
    marching's stage by stage, beside VTK's projected tetrahedra (bench/memory.py)."""
    r = _load("memory.json")
    v = r["vs_vtk"]
    mib = lambda b: f"{b / 2**20:.0f}"  # noqa: E731
    vtk = v["vtk_pt"]["peak_rss"]
    rows = ["| process | peak resident MiB (median) | the runs' range MiB | / VTK's |", "|---|---:|---:|---:|"]
    for key, label in (("raymarch", 'tetvr, tet marching (`method="raymarch"`)'),
                       ("projected", 'tetvr, projected tetrahedra (`method="projected"`)'),
                       ("vtk_pt", f"VTK {v['vtk_pt'].get('version', '')}, `vtkProjectedTetrahedraMapper`")):
        runs = v[key]["peak_rss_runs"]
        rows.append(f"| {label} | {mib(v[key]['peak_rss'])} | {mib(min(runs))}-{mib(max(runs))} "
                    f"| {v[key]['peak_rss'] / vtk:.2f} |")
    stages = ["| tet marching, stage by stage | peak while it ran MiB | resident after MiB | s |", "|---|---:|---:|---:|"]
    for row in v["stages"]:
        stages.append(f"| {r['stage_words'][row['stage']]} | {mib(row['peak_rss'])} | {mib(row['rss_after'])} "
                      f"| {row['seconds']:.1f} |")
    return (f"Measured by `bench/memory.py` ({r['created']}, `bench/results/memory.json`): the peak resident "
            f"memory of a process that builds `synthetic.cube({v['n']})` ({v['n_tets']:,} tets), its default "
            f"transfer function and a renderer, and draws one {v['size'][0]}x{v['size'][1]} frame (the median of "
            f"{v['runs']} processes); VTK's process receives the mesh's arrays and renders them. Below, the same "
            f"tet-marching frame one stage after another on one thread, each stage's peak on its own (the "
            f"interpreter with tetvr imported takes {mib(v['interpreter_rss'])} MiB).\n\n"
            + "\n".join(rows) + "\n\n" + "\n".join(stages))


def grazing() -> str:
    """Cameras beside the boundary of a mesh and its bricks (bench/grazing.py)."""
    r = _load("grazing.json")
    rows = ["| mesh | tets | cells cut by the bricks | views | whole mesh: worst error | views beyond 1/255 "
            "| 8 bricks composited: worst error | views beyond 1/255 |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, m in r["meshes"].items():
        n = {key: len({b["trial"] for b in m["beyond"] if b["image"] == key}) for key in ("whole", "bricks")}
        rows.append(f"| {name} | {m['n_tets']:,} | {m['cut_cells']:,} | {m['trials']} | {m['worst']['whole']:.1e} "
                    f"| {n['whole']} | {m['worst']['bricks']:.1e} | {n['bricks']} |")
    size = "x".join(str(v) for v in r["size"])
    return (f"Measured by `bench/grazing.py` at {size} with the defaults, against `method=\"reference\"` "
            f"({r['date'][:10]}, `bench/results/grazing.json`).\n\n" + "\n".join(rows))


def cost_model() -> str:
    """``auto``'s cost model on each corpus scene and the held-out ones (bench/cost_model.py):
    measured and predicted ratio of the methods, what auto takes and its loss."""
    r = _load("cost_model.json")
    rows = ["| scene | size | tets | tet marching ms | projected ms | projected / marching, measured | predicted "
            "| auto takes | slower than the faster by |",
            "|---|---:|---:|---:|---:|---:|---:|---|---:|"]
    for tag, scenes in (("", r["scenes"]), (" (held out)", r["held_out"])):
        for m in scenes:
            t, p = m["measured_s"], m["predicted_s"]
            rows.append(f"| {m['name']}{tag} | {m['size'][0]} | {m['tets']:,} | {t['raymarch'] * 1e3:.0f} "
                        f"| {t['projected'] * 1e3:.0f} | {t['projected'] / t['raymarch']:.2f} "
                        f"| {p['projected'] / p['raymarch']:.2f} "
                        f"| {'tet marching' if m['auto'] == 'raymarch' else 'projected tetrahedra'} "
                        f"| {m['auto_loss']:.0%} |")
    c = r["llvmpipe_ns"]
    return (f"Coefficients (ns): tet marching {c['march_ns_per_segment']:g} a segment, {c['march_ns_per_ray']:g} "
            f"an entering ray, {c['march_ns_per_tet']:g} a tet; projected tetrahedra {c['projected_ns_per_tet']:g} "
            f"a tet, {c['projected_ns_per_fragment']:g} a fragment, {c['projected_ns_per_frame'] / 1e6:g} ms a "
            f"frame; margin {r['auto_margin']:g}; fitted on `{'`, `'.join(r['runs'])}` "
            f"(`bench/results/cost_model.json`).\n\n" + "\n".join(rows))


def gpu_methods() -> str:
    """Both methods on a lent GPU, frames in turn, and their first views against the exact
    reference (bench/methods.py on the device; --accuracy here)."""
    r = _load("methods_gpu.json")
    sizes = [str(s) for s in r["sizes"]]
    head = "| mesh | tets |" + "".join(f" {s}²: marching ms | projected ms | projected / marching |" for s in sizes)
    rows = [head + " auto takes | first frame s, marching / projected | largest error, marching / projected "
            "| pixels > 1/255 | PSNR dB |",
            "|---|---:|" + "---:|---:|---:|" * len(sizes) + "---|---:|---:|---:|---:|"]
    names = {"raymarch": "tet marching", "projected": "projected tetrahedra"}
    for m in r["meshes"]:
        cells = ""
        for s in sizes:
            t = m["sizes"][s]["median_s"]
            cells += f" {t['raymarch'] * 1e3:.1f} | {t['projected'] * 1e3:.1f} | {t['projected'] / t['raymarch']:.2f} |"
        auto = ", ".join(names[a] for a in sorted({a for s in sizes for a in m["sizes"][s]["auto_method"]}))
        cells += f" {auto} |"
        f, a = m["first_frame_s"], m.get("accuracy")
        acc = (f" {a['raymarch']['max_error']:.1e} / {a['projected']['max_error']:.1e} "
               f"| {a['raymarch']['pixels_beyond_1_255']} / {a['projected']['pixels_beyond_1_255']} "
               f"| {a['raymarch']['psnr_db']:.1f} / {a['projected']['psnr_db']:.1f} |") if a else " | | |"
        rows.append(f"| {m['name']} | {m['n_tets']:,} |{cells} {f['raymarch']:.2f} / {f['projected']:.2f} |{acc}")
    gl = r["gl"]
    where = "in the shader" if r["filter_in_shader"] else "by the texture unit"
    return (f"{gl['GL_RENDERER']} ({gl['GL_VERSION']}), {r['machine']['cpu_count']} cores; its linear filtering "
            f"errs by {r['linear_filter_error']:.2g} on a 0-to-1 ramp (`tetvr.gl.filtering`): 3D textures filtered "
            f"{where}; median of the view "
            f"changes (each {r['meshes'][0]['sizes'][sizes[0]]['step_deg']:g} degrees), the two methods' frames in "
            f"turn; the first frame of the first mesh holds the driver's shader compiles; accuracy of the first view "
            f"at {r['image_size']}x{r['image_size']} against the exact reference ({r['date'][:10]}, "
            f"`bench/results/methods_gpu.json`).{_gpu_model(r)}\n\n" + "\n".join(rows))


def gpu_interpolation() -> str:
    """Projected tetrahedra's fan varyings interpolated by a GPU's rasteriser and by the shader
    (bench/methods.py on the device, once with each TETVR_INTERPOLATE; --accuracy here)."""
    r = _load("methods_gpu_interpolation.json")
    runs = r["runs"]
    sizes = [str(s) for s in runs["shader"]["sizes"]]
    rows = ["| mesh | tets | varyings by |" + "".join(f" {s}²: projected ms | marching ms |" for s in sizes)
            + " projected: largest error | pixels > 1/255 | PSNR dB |",
            "|---|---:|---|" + "---:|---:|" * len(sizes) + "---:|---:|---:|"]
    for i, m in enumerate(runs["shader"]["meshes"]):
        for mode in ("rasteriser", "shader"):
            mm = runs[mode]["meshes"][i]
            assert mm["name"] == m["name"]
            cells = "".join(f" {mm['sizes'][s]['median_s']['projected'] * 1e3:.1f} | "
                            f"{mm['sizes'][s]['median_s']['raymarch'] * 1e3:.1f} |" for s in sizes)
            a = mm["accuracy"]["projected"]
            rows.append(f"| {m['name']} | {m['n_tets']:,} | {mode} |{cells} {a['max_error']:.1e} | "
                        f"{a['pixels_beyond_1_255']} | {a['psnr_db']:.1f} |")
    gl = runs["shader"]["gl"]
    return (f"{gl['GL_RENDERER']} ({gl['GL_VERSION']}); its rasteriser's interpolation errs by "
            f"{r['interpolation_error_px']:.2g} pixel (`tetvr.gl.interpolation`'s probe; llvmpipe's "
            f"{r['llvmpipe_interpolation_error_px']:.1g}); median of the view changes; accuracy of the first view at "
            f"{runs['shader']['image_size']}x{runs['shader']['image_size']} against the exact reference "
            f"({runs['shader']['date'][:10]}, `bench/results/methods_gpu_interpolation.json`).\n\n" + "\n".join(rows))


def _gpu_model(r: dict[str, Any]) -> str:
    """The cost model fitted on a GPU run (bench/methods.py --fit), as a sentence."""
    c = r.get("cost_model", {}).get("fitted_ns")
    if not c:
        return ""
    return (f" The cost model fitted on these timings (`methods.py --fit`; llvmpipe's is in the table above): tet "
            f"marching {c['march_ns_per_segment']:g} ns a segment, {c['march_ns_per_ray']:g} an entering ray, "
            f"{c['march_ns_per_tet']:g} a tet; projected tetrahedra {c['projected_ns_per_tet']:g} a tet, "
            f"{c['projected_ns_per_fragment']:g} a fragment, {c['projected_ns_per_frame'] / 1e6:g} ms a frame.")


TABLES: dict[str, Callable[[], str]] = {"cost_model": cost_model, "gpu_methods": gpu_methods,
                                        "gpu_interpolation": gpu_interpolation, "imperfect_meshes": imperfect_meshes, "frame_memory": frame_memory, "marching_memory": marching_memory, "parity_anatomy": parity_anatomy, "stability_cases": stability_cases, "parity_vs_exact": parity_vs_exact,
                                        "compare_demo": compare_demo,
                                        "viewer_latency": viewer_latency, "vs_paraview": vs_paraview, "methods_vs_vtk": methods_vs_vtk, "methods_vs_vtk_1024": methods_vs_vtk_1024, "methods_vs_vtk_inside": methods_vs_vtk_inside, "raymarch_stages": raymarch_stages, "raymarch_stages_1024": raymarch_stages_1024,
                                        "volume_accuracy": volume_accuracy,
                                        "spiky_tf": spiky_tf, "degenerate": degenerate, "grazing": grazing,
                                        "distributed_series": distributed_series,
                                        "distributed_bricks": distributed_bricks,
                                        "distributed_big": distributed_big,
                                        "distributed_accuracy": distributed_accuracy,
                                        "distributed_projection": distributed_projection,
                                        "distributed_compositing": distributed_compositing,
                                        "distributed_compositing_model": distributed_compositing_model}
TABLES.update(speed_accuracy_summary=speed_accuracy_summary, speed_accuracy_peers=speed_accuracy_peers,
              speed_accuracy_stability=speed_accuracy_stability)
_BLOCK = re.compile(r"(<!-- table:(?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /table:(?P=name) -->)", re.S)


def render(text: str) -> str:
    """``text`` with every known table block and every value span
    (``<!-- value:NAME -->...<!-- /value -->``, bench/doc_values.py) regenerated."""
    def sub(m: re.Match[str]) -> str:
        make = TABLES.get(m.group("name"))
        return m.group(0) if make is None else m.group(1) + make() + "\n" + m.group(4)

    return doc_values.render(_BLOCK.sub(sub, text))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", action="store_true", help="rewrite the blocks (default: check them)")
    args = ap.parse_args(argv)
    stale = []
    for path in DOCS:
        text = path.read_text()
        new = render(text)
        if new != text:
            if args.write:
                path.write_text(new)
                print(f"rewrote the tables of {path.relative_to(ROOT)}")
            else:
                stale.append(str(path.relative_to(ROOT)))
    if stale:
        print("tables out of date with bench/results (run python bench/doc_tables.py --write): " + ", ".join(stale))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

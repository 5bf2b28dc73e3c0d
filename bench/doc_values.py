"""The numbers the docs quote in their sentences, generated from the JSON the benchmarks
and docs/make_images.py write.

A number in a sentence sits between ``<!-- value:NAME -->`` and ``<!-- /value -->`` on one
line; bench/doc_tables.py rewrites it from :data:`VALUES` (``--write``) or checks it, like
its tables. A value that states a comparison ("worse", "better") says it from the numbers,
so a sentence cannot claim the opposite of what was measured.

    python bench/doc_tables.py [--write]
"""

from __future__ import annotations

import json
import re
import statistics
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "bench" / "results"
PICTURES = ROOT / "docs" / "images" / "guide"
SPAN = re.compile(r"<!-- value:(?P<name>[\w.:-]+) -->(?P<body>.*?)<!-- /value -->")


def _load(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text())


# ---------------------------------------------------------------- the method pictures
def _methods() -> dict[str, Any]:
    return _load(PICTURES / "methods" / "psnr.json")


def picture(name: str) -> str:
    """The PSNRs in the titles of docs/images/guide/methods/NAME.png: the baseline's, then the
    variant's, each named (the variant by the settings it changes from the baseline)."""
    p = _methods()[name]
    changed = {k: v for k, v in p["variant_settings"].items() if p["base_settings"].get(k) != v}
    label = ", ".join(f"`{k}={v}`" for k, v in changed.items())
    return f"{p['base']} {p['base_psnr']:.1f} dB, {label} {p['variant_psnr']:.1f} dB"


def _db_range(values: list[float]) -> str:
    lo, hi = min(values), max(values)
    return f"{lo:.1f} dB" if round(lo, 1) == round(hi, 1) else f"{lo:.1f}–{hi:.1f} dB"


# ---------------------------------------------------------------- bench/speed_accuracy.py
def _speed() -> dict[str, Any]:
    return _load(RESULTS / "speed_accuracy.json")


def _psnr(scene: dict[str, Any], variant: str) -> float | None:
    rec = scene["variants"].get(variant)
    return None if rec is None else rec.get("psnr")


def _pairs(base: str, variant: str, *, scenes: str = "scenes") -> list[tuple[str, float, float]]:
    """(scene, base PSNR, variant PSNR) where both were measured."""
    out = []
    for name, s in _speed()[scenes].items():
        rec = s if scenes == "scenes" else {"variants": s}
        a, b = _psnr(rec, base), _psnr(rec, variant)
        if a is not None and b is not None:
            out.append((name, a, b))
    return out


def _verdict(pairs: list[tuple[str, float, float]], what: str) -> str:
    """How ``what`` (the second of each pair) compares with the first over the scenes, in
    words chosen by the numbers: better, worse or the same (within 0.05 dB)."""
    diffs = [b - a for _, a, b in pairs]
    n = len(diffs)
    if not n:
        raise ValueError(f"no scene measured {what} (bench/results/speed_accuracy.json)")
    better, worse = [d for d in diffs if d > 0.05], [-d for d in diffs if d < -0.05]
    same = n - len(better) - len(worse)
    if len(worse) == n:
        return f"{what} is worse on all {n} scenes (by {_db_range(worse)})"
    if len(better) == n:
        return f"{what} is better on all {n} scenes (by {_db_range(better)})"
    parts = ([f"better on {len(better)} (by up to {max(better):.1f} dB)"] if better else []) \
        + ([f"worse on {len(worse)} (by up to {max(worse):.1f} dB)"] if worse else []) \
        + ([f"the same on {same}"] if same else [])
    return f"{what} is " + ", ".join(parts[:-1]) + (" and " if len(parts) > 1 else "") + parts[-1] + f" of {n} scenes"


def table_filter() -> str:
    """``table_filter="cubic"`` with each encoding, over the benchmark's scenes."""
    norm = _pairs("default", "cubic thickness filter")
    pre = _pairs("premultiplied table", "premultiplied table, cubic")
    # The benchmark measures cubic with the premultiplied table only where it has that variant.
    return (f"with the normalized table, {_verdict(norm, 'cubic')}"
            + (f"; with the premultiplied table, {_verdict(pre, 'cubic')}" if pre else ""))


def smooth_tf_psnr() -> str:
    """The default's PSNR range over the benchmark scenes whose transfer function is smooth."""
    return _db_range([a for name, a, _ in _pairs("default", "default") if "spiky" not in name])


def framebuffer_vs_table() -> str:
    """The two 8-bit choices side by side, scene by scene."""
    fb = _pairs("uint8 table", "uint8 framebuffer")
    return (f"an 8-bit framebuffer gives {_db_range([b for _, _, b in fb])} and an 8-bit table "
            f"{_db_range([a for _, a, _ in fb])}: {_verdict(fb, 'the 8-bit framebuffer')}")


def auto_table_sizes() -> str:
    """The auto table sizes the benchmark's scenes got, and what the table took to build
    against the former fixed 256 x 16."""
    sizes: dict[tuple[int, int], list[str]] = {}
    ratios = []
    for name, s in _speed()["scenes"].items():
        t = s["auto_table"]
        sizes.setdefault((t["n_bins"], t["n_slices"] + 1, bool(t.get("warp"))), []).append(name)
        fixed = s["variants"].get("fixed table N=256, K=16 (the 0.x default)")
        if fixed and fixed.get("table_s") and s["variants"]["default"].get("table_s") is not None:
            ratios.append(s["variants"]["default"]["table_s"] / fixed["table_s"])
    parts = [f"{n} × {n} × {k}{' (warped)' if warped else ''} on {len(v)} of {sum(map(len, sizes.values()))}"
             for (n, k, warped), v in sorted(sizes.items(), key=lambda kv: -len(kv[1]))]
    return ("; ".join(parts) + f", built in {min(ratios):.2f}–{max(ratios):.2f} times the time of the fixed "
            "256 × 256 × 17")


def table_build() -> str:
    """Table build times by scalar bins (bench/stages.py)."""
    r = _load(RESULTS / "stages.json")["table"]
    by = r["by_bins"]
    times = ", ".join(f"{by[n]['median']:.2f} s for N = {n}" for n in sorted(by, key=int))
    return f"{times} (K = {r['n_slices']}, `bench/results/stages.json`)"


def scalar_bins_auto() -> str:
    """The auto table's scalar bins in the table_scalar_bins picture."""
    p = _methods()["table_scalar_bins"]
    return f"N = {p['base_table'][0]}" + (", nodes warped towards the spike" if p.get("base_table_warped") else "")


def align_nodes() -> str:
    """``table_align_nodes``: even nodes against the default's aligned nodes, per scene."""
    scenes = "; ".join(f"{name} {a:.1f} → {b:.1f} dB" for name, a, b in _pairs("uniform table nodes", "default"))
    stab = [p for p in _pairs("uniform table nodes", "default", scenes="stability") if max(p[1:]) < 150]
    return f"{scenes}; over the stability cases, {_verdict(stab, 'aligned')}".replace(" scenes", " cases")


def slices_vs_fixed() -> str:
    """The auto table's thickness axis against K = 8, base 2.5 (bench/speed_accuracy.py)."""
    return _verdict(_pairs("default", "K=8, base 2.5"), "K = 8 with base 2.5")


def centroid_sort() -> str:
    """The centroid sort's time on the largest mesh (bench/stages.py)."""
    r = _load(RESULTS / "stages.json")["sort"]
    return f"{r['median'] * 1e3:.0f} ms for {r['n_tets']:,} tets, `bench/results/stages.json`"


# ---------------------------------------------------------------- other benchmarks
def large_meshes() -> str:
    """docs/limits.md: a frame of the largest mesh of bench/vs_vtk.py, each method."""
    r = _load(RESULTS / "vs_vtk.json")
    m = max(r["meshes"], key=lambda m: m["n_tets"])
    v = m["view_change_median_s"]
    size = "x".join(str(x) for x in r["size"])
    return (f"{v['tetvr'] * 1e3:.0f} ms per view change for {m['n_tets']:,} tets at {size} by the default "
            f"(tet marching) and {v['tetvr_projected'] * 1e3:.0f} ms by projected tetrahedra, on "
            f"{r['machine']['cpu_count']} cores (`bench/results/vs_vtk.json`)")


def _vs_vtk_both() -> tuple[dict[str, Any], dict[str, Any], list[tuple[dict[str, Any], dict[str, Any]]]]:
    """Both sizes' runs of bench/vs_vtk.py and their meshes paired by name."""
    small, large = _load(RESULTS / "vs_vtk.json"), _load(RESULTS / "vs_vtk_1024.json")
    at = {m["name"]: m for m in large["meshes"]}
    return small, large, [(m, at[m["name"]]) for m in small["meshes"] if m["name"] in at]


def vs_vtk_pixels() -> str:
    """bench/README.md: how each renderer's view change grows from the first size to the
    second (4x the pixels), median over the meshes measured at both."""
    small, large, pairs = _vs_vtk_both()
    ratio = {k: sorted(b["view_change_median_s"][k] / a["view_change_median_s"][k] for a, b in pairs)
             for k in ("tetvr", "vtk_pt")}
    med = {k: statistics.median(v) for k, v in ratio.items()}
    return (f"from {small['size'][0]}² to {large['size'][0]}² (4x the pixels) the default's view change takes "
            f"{med['tetvr']:.1f}x as long ({ratio['tetvr'][0]:.1f}–{ratio['tetvr'][-1]:.1f}x) and VTK's "
            f"{med['vtk_pt']:.1f}x ({ratio['vtk_pt'][0]:.1f}–{ratio['vtk_pt'][-1]:.1f}x), median over the "
            f"{len(pairs)} meshes measured at both (`bench/results/vs_vtk.json`, `vs_vtk_1024.json`)")


def vs_vtk_below_90() -> str:
    """bench/README.md: the corpus scenes where the default is below 90 dB against the
    exact reference (bench/vs_vtk.py, outside and inside, both sizes)."""
    found = []
    for name in ("vs_vtk.json", "vs_vtk_1024.json"):
        r = _load(RESULTS / name)
        for m in r["meshes"]:
            label = m["name"].split(" (")[0]
            if m["psnr"]["tetvr"]["exact"] < 90:
                found.append(f"{label} at {r['size'][0]}² ({m['psnr']['tetvr']['exact']:.1f} dB)")
            inside = m.get("inside", {}).get("psnr", {}).get("tetvr")
            if inside is not None and inside < 90 and name == "vs_vtk.json":  # inside: one accuracy size
                found.append(f"{label} from inside ({inside:.1f} dB at {m['inside']['accuracy_size'][0]}²)")
    return ", ".join(found) or "none"


def march_lanes() -> str:
    """bench/README.md: how evenly the rays of a pixel block walk (bench/stages.py)."""
    r = _load(RESULTS / "stages.json")
    u = sorted(m["raymarch"]["lane_utilisation"] for m in r["meshes"] if "lane_utilisation" in m.get("raymarch", {}))
    return (f"in 4x4 blocks the rays walk {u[0]:.0%}–{u[-1]:.0%} of what the blocks' longest rays do "
            f"(median {statistics.median(u):.0%}, the {len(u)} meshes of `stages.py` at "
            f"{r['size'][0]}x{r['size'][1]})")


def march_parts() -> str:
    """bench/README.md: what each part of a tet-marching step costs (bench/march_parts.py)."""
    r = _load(RESULTS / "march_parts.json")
    meshes = r["meshes"]
    parts = []
    for part in meshes[0]["parts"]:
        shares = sorted(m["parts"][part]["share"] for m in meshes)
        parts.append(f"the {part} {shares[0]:.0%} to {shares[-1]:.0%}")
    names = ", ".join(m["name"].split("_")[0] for m in meshes)
    return (f"with one part of every step replaced by arithmetic on the same inputs, the march's view change "
            f"at {r['size'][0]}x{r['size'][1]} ({names}; medians of {r['rounds']} processes of {r['repeats']} "
            f"frames each, `bench/results/march_parts.json`) is shorter by: {'; '.join(parts)}")


def march_ceiling() -> str:
    """bench/README.md: what the default could reach against VTK at 1024x1024 were every
    measured part of a step but the walk free (bench/march_parts.py, bench/vs_vtk.py)."""
    parts, run = _load(RESULTS / "march_parts.json"), _load(RESULTS / "vs_vtk_1024.json")
    runs = {m["name"].split(" (")[0]: m for m in run["meshes"]}
    found = []
    for m in parts["meshes"]:
        name = m["name"].removesuffix(".vtu").removesuffix("_tets")
        rec = runs.get(name)
        if rec is None:
            continue
        ratio = rec["speedup_vs_vtk_pt"].get("tetvr_march", rec["speedup_vs_vtk_pt"]["tetvr"])
        free = sum(max(p["share"], 0.0) for p in m["parts"].values())
        found.append((name.split('_')[0], ratio / (1.0 - free), ratio))
    wanted = run["target"]["speedup"]
    below = [n for n, ceiling, _ in found if ceiling < wanted]
    return (", ".join(f"{n} {c:.1f}x (now {r:.2f}x)" for n, c, r in found)
            + (f"; below the {wanted:g}x target even so: {', '.join(below)}" if below else ""))


def tile_coherence() -> str:
    """bench/README.md: how often a tile's corner rays cross the same cells (bench/tile_coherence.py)."""
    r = _load(RESULTS / "tile_coherence.json")
    meshes = r["meshes"]
    tiles = sorted(meshes[0]["tiles"], key=int)
    adjacent = sorted(m["adjacent"] for m in meshes)
    most = max(meshes, key=lambda m: m["adjacent"])["name"].split(" (")[0]
    parts = []
    for s in tiles:
        seg = sorted(m["tiles"][s]["segments_skipped"] for m in meshes)
        parts.append(f"{s}x{s} tiles {seg[0]:.2%}–{seg[-1]:.2%} (median {statistics.median(seg):.2%})")
    return (f"at {r['size'][0]}x{r['size'][1]} (the fitted view, the {len(meshes)} meshes of "
            f"`bench/results/tile_coherence.json`, from the exact reference's segments) a pixel's right neighbour "
            f"crosses the same cells for {adjacent[0]:.1%}–{adjacent[-1]:.1%} of pixels (median "
            f"{statistics.median(adjacent):.1%}; the most on {most}), and the rays of the tiles whose four corner "
            f"rays agree hold, of all the segments: {'; '.join(parts)}")


def view_change_missed(m: dict[str, Any]) -> bool:
    """Whether a mesh of bench/vs_vtk.py missed its view-change target (where one applies)."""
    t = m["target"]
    return bool(t["applies"] and t["speedup"] < t["speedup_wanted"])


def vs_vtk_missed() -> str:
    """bench/README.md: the targets of bench/vs_vtk.py missed, mesh by mesh, at both sizes."""
    parts = []
    for name in ("vs_vtk.json", "vs_vtk_1024.json"):
        r = _load(RESULTS / name)
        size = f"{r['size'][0]}²"
        view = [f"{m['name'].split(' (')[0]} {m['target']['speedup']:.2f}x of {m['target']['speedup_wanted']:g}x"
                for m in r["meshes"] if view_change_missed(m)]
        first = [f"{m['name'].split(' (')[0]} {m['target']['first_frame']:.2f}x" for m in r["meshes"]
                 if not m["target"]["first_frame_met"]]
        parts.append(f"at {size}, per view change " + (", ".join(view) or "none")
                     + "; first frame " + (", ".join(first) or "none"))
    return "; ".join(parts)


def spiky_even() -> str:
    """docs/limits.md: the spiky transfer functions on even tables (bench/spiky_tf.py)."""
    rows = [r for r in _load(RESULTS / "spiky_tf.json")["rows"] if r["tf"] != "smooth" and not r["table"]["warp"]]
    bins = sorted({r["table"]["n_bins"] for r in rows})
    return f"{_db_range([r['psnr'] for r in rows])} with {' or '.join(map(str, bins))} even nodes"


def rings_bricks() -> str:
    """docs/distributed.md: the rings' bricks by projected tetrahedra, the case furthest below
    the single image."""
    cases = [c for c in _load(RESULTS / "distributed.json")["accuracy"]["cases"]
             if c["mesh"] == "interlocking rings" and c["method"] == "projected"]
    c = min(cases, key=lambda c: c["psnr_bricks"] - c["psnr_whole"])
    return (f"pixels up to {c['max_abs_diff']:.1e} off at P = {c['P']} in {c['view']} view "
            f"(the {c['psnr_bricks'] - c['psnr_whole']:+.0f} dB in the table")


def _anatomy(key: str, tf: str, view: str) -> float:
    return _load(RESULTS / "vs_vtk_anatomy.json")["cases"][f"{tf}, {view}"][key]


def anatomy_own() -> str:
    """docs/paraview.md: VTK PT against its own formula, linear TF, per view."""
    key = "VTK PT vs reference in its own convention"
    return (f"{_anatomy(key, 'linear', 'perspective'):.0f} dB in perspective against "
            f"{_anatomy(key, 'linear', 'parallel'):.0f} dB in parallel, linear transfer function")


def anatomy_convention() -> str:
    """docs/paraview.md: what VTK's optical convention alone costs (exact vs linear reference)."""
    key = "convention: exact vs linear reference"
    cases = _load(RESULTS / "vs_vtk_anatomy.json")["cases"]
    lin = [c[key] for k, c in cases.items() if k.startswith("linear")]
    spike = [c[key] for k, c in cases.items() if k.startswith("spike")]
    alpha = cases["linear, perspective"]["mean alpha over covered pixels"]
    return (f"{_db_range(lin)} with the linear transfer function, {_db_range(spike)} with the spike; mean alpha "
            f"{alpha['vtk_convention']:.2f} against {alpha['exact']:.2f}")


def anatomy_colour() -> str:
    """docs/paraview.md: what averaging a segment's end colours costs on bluntfin."""
    cases = _load(RESULTS / "vs_vtk_anatomy.json")["cases"]
    return _db_range([c["colour averaging: linear vs vtk reference"] for c in cases.values()])


# ---------------------------------------------------------------- bench/first_hour.py
def _first_hour(part: str) -> dict[str, Any]:
    return _load(RESULTS / "first_hour.json")[part]  # type: ignore[no-any-return]


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.1f} min"


def _where(part: dict[str, Any]) -> str:
    m, load = part["machine"], part["loadavg_before"]
    return (f"{m['cpu_count']} CPU cores at load average {load[0]:.1f}, {part['created'][:10]}, "
            "`bench/results/first_hour.json`")


def install_time() -> str:
    """README: the test command's install into a fresh virtual environment (bench/first_hour.py)."""
    r = _first_hour("install")
    off, full = r["no_cache"], r["full_cache"]
    built = off["built_from_source"]
    largest = ", ".join(f"{name} {mb:.0f} MB" for name, mb in list(off["largest_downloads_mb"].items())[:3])
    return (f"{_duration(off['total_s'])} with pip's cache off and {_duration(full['total_s'])} with it full "
            f"(pip's CPU time {off['cpu_s']:.0f} s and {full['cpu_s']:.0f} s, "
            f"{r['installed_size']['all_mb'] / 1e3:.1f} GB installed, the largest downloads {largest}); "
            + ("no package is built from source" if not built else "built from source: " + ", ".join(built))
            + f" ({_where(r)})")


def extras_sizes() -> str:
    """docs/quickstart.md: the disk each extra of the test command adds on its own."""
    r = _first_hour("install")["installed_size"]
    extras = sorted(r["extras"].items(), key=lambda kv: -kv[1]["only_this_extra_mb"])
    some = [f"`{name}` adds {e['only_this_extra_mb']:.0f} MB" for name, e in extras if e["only_this_extra_mb"] >= 0.5]
    none = [f"`{name}`" for name, e in extras if e["only_this_extra_mb"] < 0.5]
    return (f"tetvr and its dependencies take {r['base_mb']:.0f} MB; of the test command's extras, " + ", ".join(some)
            + (f" ({' and '.join(none)} {'needs' if len(none) == 1 else 'need'} nothing the others do not)"
               if none else "")
            + "; an extra's size is that of the packages only it pulls in (`bench/results/first_hour.json`)")


def notebook_times() -> str:
    """docs/quickstart.md: each notebook from kernel start to shutdown, as its test runs it."""
    r = _first_hour("notebooks")
    books = r["notebooks"]
    wall = ", ".join(f"{rec['wall_s']:.0f} s" for rec in books.values())
    cpu = ", ".join(f"{rec['kernel_cpu_s']:.0f} s" for rec in books.values())
    cold = ", ".join(f"{rec['cold_shader_cache']['wall_s']:.0f} s" for rec in books.values())
    return (f"{wall} ({'–'.join(n[:2] for n in (min(books), max(books)))}, best of {r['repeats']} runs; "
            f"kernel CPU time {cpu}; the first run on a machine, with Mesa's shader cache empty, {cold}; "
            f"{_where(r)})")


def VALUES() -> dict[str, Callable[[], str]]:  # noqa: N802 - read like the TABLES dict
    """Every value a doc may quote, by name."""
    values: dict[str, Callable[[], str]] = {
        "table_filter": table_filter, "smooth_tf_psnr": smooth_tf_psnr, "framebuffer_vs_table": framebuffer_vs_table,
        "auto_table_sizes": auto_table_sizes, "table_build": table_build, "scalar_bins_auto": scalar_bins_auto,
        "align_nodes": align_nodes, "slices_vs_fixed": slices_vs_fixed, "centroid_sort": centroid_sort,
        "large_meshes": large_meshes, "vs_vtk_pixels": vs_vtk_pixels, "march_lanes": march_lanes, "march_parts": march_parts, "tile_coherence": tile_coherence, "march_ceiling": march_ceiling, "vs_vtk_below_90": vs_vtk_below_90, "vs_vtk_missed": vs_vtk_missed,
        "spiky_even": spiky_even, "rings_bricks": rings_bricks,
        "anatomy_own": anatomy_own, "anatomy_convention": anatomy_convention, "anatomy_colour": anatomy_colour,
        "install_time": install_time, "extras_sizes": extras_sizes, "notebook_times": notebook_times}
    for name in _methods():
        values[f"picture:{name}"] = (lambda n=name: picture(n))
    return values


def render(text: str) -> str:
    """``text`` with every value span regenerated; an unknown name is an error."""
    known = VALUES()

    def sub(m: re.Match[str]) -> str:
        make = known.get(m.group("name"))
        if make is None:
            raise KeyError(f"<!-- value:{m.group('name')} -->: no such value in bench/doc_values.py")
        return f"<!-- value:{m.group('name')} -->{make()}<!-- /value -->"

    return SPAN.sub(sub, text)

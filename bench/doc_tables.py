"""The benchmark tables the docs quote, generated from the JSON in bench/results.

Every table sits in a Markdown file between ``<!-- table:NAME -->`` and
``<!-- /table:NAME -->``; this script rewrites those blocks from the JSON (``--write``) or
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
#: Files whose table blocks this script owns.
DOCS = (ROOT / "docs" / "interactive.md", ROOT / "README.md", ROOT / "bench" / "README.md", ROOT / "docs" / "methods.md", ROOT / "docs" / "limits.md")


def _load(name: str) -> dict[str, Any]:
    return json.loads((RESULTS / name).read_text())


def methods_vs_vtk() -> str:
    """Per view change at the benchmark's size: both tetvr methods against VTK's PT, and
    their accuracy against the exact reference (bench/vs_vtk.py)."""
    r = _load("vs_vtk.json")
    rows = ["| mesh | tets | default ms | projected tetrahedra ms | VTK PT ms | VTK / default "
            "| VTK / projected | PSNR default | PSNR projected | PSNR VTK |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for m in sorted(r["meshes"], key=lambda m: m["n_tets"]):
        v, s, p = m["view_change_median_s"], m["speedup_vs_vtk_pt"], m["psnr"]
        if "tetvr_projected" not in v:
            continue
        rows.append(f"| {m['name']} | {m['n_tets']:,} | {v['tetvr'] * 1e3:.0f} | {v['tetvr_projected'] * 1e3:.0f} "
                    f"| {v['vtk_pt'] * 1e3:.0f} | {s['tetvr']:.2f} | {s['tetvr_projected']:.2f} "
                    f"| {p['tetvr']['exact']:.1f} | {p['tetvr_projected']['exact']:.1f} | {p['vtk_pt']['exact']:.1f} |")
    size = "x".join(str(x) for x in r["size"])
    return (f"{size}; default: `method=\"auto\"` (tet marching where it measures faster, see above); "
            f"median of {r['repeats']} view changes, frames in turn, {r.get('gl_renderer', '?')}, "
            f"VTK {r.get('vtk_version', '?')}; PSNR (dB) of premultiplied RGB against the exact reference "
            f"({r['date']}, `bench/results/vs_vtk.json`).\n\n" + "\n".join(rows))


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


def raymarch_stages() -> str:
    """The ray caster's stages and cost per segment beside projected tetrahedra's frame
    (bench/stages.py)."""
    r = _load("stages.json")
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
            f"({r['timestamp']}, `bench/results/stages.json`).\n\n" + "\n".join(rows))


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


def viewer_latency() -> str:
    """The Jupyter viewer's latency in Chromium, from the input event to pixels on the page
    (bench/viewer.py)."""
    r = _load("viewer.json")
    labels = {"after": "`tetvr.widget.Viewer` (jupyter_rfb, render loop, render process)",
              "before": "ipywidgets.Image + ipyevents, rendering in the event handler"}
    rows = ["| mesh | tets | viewer | input → first pixels ms | mouse-up → full frame ms | frames shown in the 1 s drag |",
            "|---|---:|---|---:|---:|---:|"]

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
                        f"| {ms(md['full_frame_ms'])} | {frames} |")
    size = "x".join(str(x) for x in r["size"])
    la = r.get("loadavg_start")
    load = f"1-minute load average {la[0]:.1f} on {r['machine'].get('cpu_count', '?')} cores" if la else "load unknown"
    return (f"{size} picture; {r['gesture']}; medians; headless Chromium and JupyterLab on the same machine, "
            f"Mesa llvmpipe, {load} ({r['date']}, `bench/results/viewer.json`).\n\n" + "\n".join(rows))


TABLES: dict[str, Callable[[], str]] = {"viewer_latency": viewer_latency, "vs_paraview": vs_paraview, "methods_vs_vtk": methods_vs_vtk, "raymarch_stages": raymarch_stages,
                                        "spiky_tf": spiky_tf}
_BLOCK = re.compile(r"(<!-- table:(?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /table:(?P=name) -->)", re.S)


def render(text: str) -> str:
    """``text`` with every known table block regenerated."""
    def sub(m: re.Match[str]) -> str:
        make = TABLES.get(m.group("name"))
        return m.group(0) if make is None else m.group(1) + make() + "\n" + m.group(4)

    return _BLOCK.sub(sub, text)


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

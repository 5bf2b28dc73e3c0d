"""Markdown tables from bench/results/speed_accuracy.json (printed; paste into README).

    python bench/report.py [bench/results/speed_accuracy.json]
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str]) -> int:
    path = Path(argv[0]) if argv else ROOT / "bench" / "results" / "speed_accuracy.json"
    r = json.loads(path.read_text())
    scenes = r["scenes"]
    names = list(r["variants"])
    print(f"Speed against accuracy at {r['size'][0]}x{r['size'][1]} on {r.get('gl', {}).get('GL_RENDERER', '?')} "
          f"({r['created']}): PSNR in dB against the reference / frame CPU time in ms / table build in s; "
          "**bold**: on the Pareto front of frame time and error; *(t)*: on the front of frame time, table time and error "
          "(5 % ties; errors below the 16-bit rounding noise, RMSE 4.4e-6, tie); *(s)*: on the frame time/error front "
          "without that error floor.\n")
    print("| variant | " + " | ".join(f"{s} ({d['n_tets']} tets)" for s, d in scenes.items()) + " |")
    print("|---|" + "---|" * len(scenes))
    for key in names:
        cells = []
        for d in scenes.values():
            v = d["variants"].get(key)
            if v is None:
                cells.append("= default (auto)" if key in d.get("same_as_default", {}) else "–")
                continue
            cell = f"{v['psnr']:.1f} / {v['frame_s'] * 1e3:.0f}"
            if "table_s" in v:
                cell += f" / {v['table_s']:.2f}"
            cell = f"**{cell}**" if v["pareto"] else cell
            cells.append(cell + (" *(t)*" if v.get("pareto_with_table") else "") + (" *(s)*" if v.get("pareto_strict") else ""))
        print(f"| {key} | " + " | ".join(cells) + " |")
    print("\nHAPT metrics (max error, mean error over covered pixels, % of covered pixels off by > 1/255):\n")
    hapt = [k for k in ("default", "sort=centroid", "sort=mpvonc", "sort=xmpvo", "sort=none") if k in names]
    print("| scene | " + " | ".join(hapt) + " |")
    print("|---|" + "---|" * len(hapt))
    for s, d in scenes.items():
        cells = []
        for k in hapt:
            v = d["variants"].get(k, d["variants"]["default"] if k in d.get("same_as_default", {}) else None)
            cells.append("–" if v is None else f"{v['max_error']:.3f}, {v['mean_error']:.5f}, {v['pct_over_1_255']:.2f} %")
        print(f"| {s} | " + " | ".join(cells) + " |")
    if r.get("stability"):
        print("\nStability cases (PSNR, dB, 96x96): the default and the worst variant\n")
        print("| case | default | worst variant |")
        print("|---|---|---|")
        for n, d in r["stability"].items():
            worst = min(d, key=lambda k: math.inf if d[k].get("psnr") is None else d[k]["psnr"])  # refused: none
            print(f"| {n} | {d['default']['psnr']:.1f} | {worst}: {d[worst]['psnr']:.1f} |")
    sweeps = {s: d["table_convergence"] for s, d in scenes.items() if d.get("table_convergence")}
    if sweeps:
        combos = sorted({(row["n_slices"], row["log_base"]) for rows in sweeps.values() for row in rows})
        bins = sorted({row["n_bins"] for rows in sweeps.values() for row in rows})
        print("\nTable-size sweep (PSNR, dB; rows: K slices at log base b; columns: scalar bins N):\n")
        print("| scene | K, b | " + " | ".join(f"N={n}" for n in bins) + " |")
        print("|---|---|" + "---|" * len(bins))
        for s, rows in sweeps.items():
            for k, b in combos:
                got = {row["n_bins"]: row["psnr"] for row in rows if (row["n_slices"], row["log_base"]) == (k, b)}
                print(f"| {s} | {k}, {b} | " + " | ".join(f"{got[n]:.1f}" if n in got else "–" for n in bins) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))

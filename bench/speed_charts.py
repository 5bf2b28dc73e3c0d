"""The charts of bench/speed_accuracy.py, drawn from its JSON alone.

* ``speed_accuracy.png``: the summary, every renderer over all scenes (frame time relative to
  tetvr's default, median error), per image size;
* ``speed_accuracy_<scene>.png``: one scene, frame time against the largest per-pixel error
  and against PSNR, per image size;
* ``speed_accuracy_stability.png``: per failure class, each method's largest per-pixel error.

Each group of renderers (what a variant changes; VTK's mappers) has its own marker and its
own colour family, the default is a large star, the Pareto front a dashed staircase, and the
legend has one block per group.

    python bench/speed_charts.py [bench/results/speed_accuracy.json]
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

#: group -> (marker, matplotlib colour map, shades used, legend heading).
GROUPS: dict[str, tuple[str, str, tuple[float, float], str]] = {
    "method": ("o", "Blues", (0.5, 0.95), "tetvr: method"),
    "integration": ("s", "Purples", (0.5, 0.95), "tetvr: integration, interpolation, framebuffer"),
    "table size": ("^", "Greens", (0.45, 0.9), "tetvr: table size"),
    "table storage": ("v", "Oranges", (0.45, 0.9), "tetvr: table storage and nodes"),
    "order": ("P", "Greys", (0.3, 0.85), "tetvr: visibility order (projected tetrahedra)"),
    "peer": ("D", "Reds", (0.5, 0.95), "peers: VTK's unstructured-grid mappers"),
}
DEFAULT_STYLE = {"marker": "*", "color": "#ffd000", "s": 300, "label": 'default (method="auto")', "group": "method"}
#: Errors below this are drawn at it (log axis); PSNR above CAP_DB at it.
ERROR_AXIS_FLOOR = 1e-7
CAP_DB = 150.0
#: Where refused or failed renderings sit on the stability chart's error axis.
NO_IMAGE_X = 3.0


def runs(report: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The scenes measured at each image size, the first size first: ``{"512x512": scenes, ...}``."""
    first = "x".join(str(v) for v in report["size"])
    more = {k: v for k, v in report.get("scenes_at", {}).items() if v}
    return {first: report["scenes"], **more}


def slug(name: str) -> str:
    """A scene's name as a file name part: ``"bluntfin_tets.vtu, spiky TF"`` -> ``"bluntfin_spiky_tf"``."""
    name = name.replace("_tets.vtu", "").replace(".vtu", "")
    return re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")


def styles(report: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Marker, colour, size, label and group of every renderer in the report."""
    import matplotlib

    members: dict[str, list[str]] = {}
    for key, group in report["groups"].items():
        if key != "default":
            members.setdefault(group, []).append(key)
    members["peer"] = list(report["peers"]["labels"])
    out: dict[str, dict[str, Any]] = {"default": dict(DEFAULT_STYLE)}
    for group, keys in members.items():
        marker, cmap, (lo, hi), _ = GROUPS[group]
        shades = [0.5 * (lo + hi)] if len(keys) == 1 else np.linspace(lo, hi, len(keys))
        for key, shade in zip(keys, shades):
            out[key] = {"marker": marker, "color": matplotlib.colors.to_hex(matplotlib.colormaps[cmap](shade)),
                        "s": 70 if group == "peer" else 48, "label": report["peers"]["labels"].get(key, key),
                        "group": group}
    return out


def _legend(fig: Any, report: dict[str, Any], st: dict[str, dict[str, Any]], y: float) -> None:
    """One block per group, two blocks per column, each headed by the group's name."""
    from matplotlib.lines import Line2D

    blocks: dict[str, list[str]] = {g: [] for g in GROUPS}
    for key, s in st.items():
        blocks[s["group"]].append(key)
    rows = max(len(v) for v in blocks.values()) + 1 + 1  # heading, and one spare for ParaView's line
    handles, labels, headings = [], [], []
    blank = Line2D([], [], linestyle="none")
    for group, keys in blocks.items():
        headings.append(len(labels))
        handles.append(blank)
        labels.append(GROUPS[group][3])
        for key in keys:
            s = st[key]
            handles.append(Line2D([], [], linestyle="none", marker=s["marker"], markerfacecolor=s["color"],
                                  markeredgecolor="black", markeredgewidth=0.5,
                                  markersize=14 if key == "default" else 8))
            labels.append(s["label"])
        if group == "peer":
            pv = report.get("paraview", {})
            handles.append(blank)
            labels.append("ParaView: " + ("measured" if pv.get("measured") else "installed, not driven" if pv.get("available") else "not installed here, skipped"))
        while len(labels) % rows:
            handles.append(blank)
            labels.append("")
    leg = fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, y), ncol=3,
                     fontsize=8, frameon=False, handletextpad=0.4, columnspacing=1.6)
    for i in headings:
        leg.get_texts()[i].set_fontweight("bold")


def _scatter(ax: Any, points: dict[str, tuple[float, float, bool]], st: dict[str, dict[str, Any]],
             label_peers: bool = True) -> None:
    """Draw ``points`` (key -> x, y, on the front) and the front as a dashed staircase."""
    for key, (x, y, _) in points.items():
        s = st[key]
        ax.scatter(x, y, marker=s["marker"], color=s["color"], s=s["s"], edgecolors="black", linewidths=0.5,
                   zorder=5 if key == "default" else 4 if s["group"] == "peer" else 3)
        if key == "default" or (label_peers and s["group"] == "peer"):
            ax.annotate(s["label"].replace("VTK ", "VTK\n") if key != "default" else "default", (x, y),
                        xytext=(7, 5) if key == "default" else (7, -3), textcoords="offset points", fontsize=7.5,
                        fontweight="bold" if key == "default" else "normal", zorder=6)
    front = sorted((x, y) for x, y, on in points.values() if on)
    if front:
        xs, ys = zip(*front)
        ax.plot(xs, ys, drawstyle="steps-post", color="black", lw=1.0, ls="--", alpha=0.55, zorder=2,
                label="Pareto front")


def _panels(ax_max: Any, ax_db: Any, rows: dict[str, dict[str, Any]], st: dict[str, dict[str, Any]],
            x_of: Any) -> None:
    pts_max, pts_db = {}, {}
    for key, r in rows.items():
        if key not in st or r.get("x") is None:
            continue
        pts_max[key] = (r["x"], max(r["max_error"], ERROR_AXIS_FLOOR), bool(r.get("pareto_max")))
        pts_db[key] = (r["x"], min(r["psnr"], CAP_DB), bool(r.get("pareto")))
    _scatter(ax_max, pts_max, st)
    _scatter(ax_db, pts_db, st)
    ax_max.axhline(1 / 255, color="tab:red", lw=0.8, ls=":", zorder=1, label="1/255 (one 8-bit step)")
    ax_max.set_yscale("log")
    for ax in (ax_max, ax_db):
        ax.set_xscale("log")
        _plain_log_ticks(ax.xaxis)
        ax.set_xlabel(x_of)
        ax.grid(True, which="major", alpha=0.3)
    ax_max.set_ylabel("largest per-pixel error vs reference (lower is better)")
    ax_db.set_ylabel("PSNR vs reference [dB] (higher is better)")


def _plain_log_ticks(axis: Any) -> None:
    """Ticks at 1, 2 and 5 times powers of ten, written as plain numbers."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def _line_legend(fig: Any) -> None:
    """The lines every panel shares, once, under the title."""
    from matplotlib.lines import Line2D

    fig.legend([Line2D([], [], color="black", lw=1.0, ls="--", alpha=0.55),
                Line2D([], [], color="tab:red", lw=0.8, ls=":")],
               ["Pareto front (no other renderer is faster and more accurate, 5 % ties)",
                "1/255: one 8-bit step"], loc="upper center", bbox_to_anchor=(0.5, 0.965), ncol=2, fontsize=8,
               frameon=False)


def _scene_rows(rec: dict[str, Any]) -> dict[str, dict[str, Any]]:
    rows = {**rec["variants"], **rec["peers"]}
    return {k: {**r, "x": r["frame_s"] * 1e3} for k, r in rows.items() if "frame_s" in r and "max_error" in r}


def scene_chart(report: dict[str, Any], name: str, path: Path) -> None:
    """One scene: per image size, frame time against the largest error and against PSNR."""
    import matplotlib.pyplot as plt

    here = [(label, scenes[name]) for label, scenes in runs(report).items() if name in scenes]
    st = styles(report)
    fig, axes = plt.subplots(len(here), 2, figsize=(14, 4.6 * len(here) + 2.8), squeeze=False)
    for (label, rec), (ax_max, ax_db) in zip(here, axes):
        _panels(ax_max, ax_db, _scene_rows(rec), st, "frame CPU time per view change [ms] (all threads of the renderer's process)")
        same = len(rec.get("same_as_default", {}))
        failed = [st[k]["label"] for k, r in rec["peers"].items() if "frame_s" not in r]
        note = (f"; {same} variant{'s' * (same > 1)} identical to the default here, not drawn" if same else "") + (
            f"; failed: {', '.join(failed)}" if failed else "")
        ax_max.set_title(f"{label}: largest per-pixel error{note}", fontsize=9)
        ax_db.set_title(f"{label}: PSNR of premultiplied RGB", fontsize=9)
    n_tets = here[0][1]["n_tets"]
    fig.suptitle(f"{name} ({n_tets:,} tets): speed against accuracy, tetvr and VTK, same machine and GL "
                 f"({report.get('gl', {}).get('GL_RENDERER', '?')}), frames in turn ({report['created'][:10]})",
                 fontsize=10)
    _finish(fig, report, st, path)


def _finish(fig: Any, report: dict[str, Any], st: Any, path: Path) -> None:
    """Lay out a speed chart above its legends, save it and close it."""
    import matplotlib.pyplot as plt

    legend_h = 2.6 / fig.get_figheight()
    fig.tight_layout(rect=(0, legend_h, 1, 0.94))
    _legend(fig, report, st, legend_h)
    _line_legend(fig)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def summary_chart(report: dict[str, Any], path: Path) -> None:
    """Every renderer over all scenes of each size: frame time relative to the default
    (geometric mean) against the median largest error and the median PSNR."""
    import matplotlib.pyplot as plt

    summary = report["summary"]
    st = styles(report)
    fig, axes = plt.subplots(len(summary), 2, figsize=(14, 4.8 * len(summary) + 2.8), squeeze=False)
    for (label, s), (ax_max, ax_db) in zip(summary.items(), axes):
        # a variant that is the default itself in every scene would hide under the star
        rows = {k: {**r, "x": r["time_ratio"], "max_error": r["max_error_median"], "psnr": r["psnr_median"]}
                for k, r in s["renderers"].items() if k == "default" or r["same_as_default"] < r["n_scenes"]}
        _panels(ax_max, ax_db, rows, st, "frame CPU time per view change / the default's (geometric mean over scenes)")
        ax_max.set_title(f"{label}, {len(s['scenes'])} scenes: median of each scene's largest per-pixel error",
                         fontsize=9)
        ax_db.set_title(f"{label}, {len(s['scenes'])} scenes: median PSNR", fontsize=9)
    fig.suptitle(f"tetvr's methods and settings and VTK's mappers over all scenes: speed against accuracy "
                 f"({report.get('gl', {}).get('GL_RENDERER', '?')}, {report['created'][:10]}; one chart per "
                 f"scene: speed_accuracy_<scene>.png)", fontsize=10)
    _finish(fig, report, st, path)


def stability_chart(report: dict[str, Any], path: Path) -> None:
    """Per failure class (stability cases, then imperfect-mesh classes), each method's
    largest per-pixel error on a log axis; refused or failed renderings in their own column."""
    import matplotlib.pyplot as plt

    classes = report.get("stability_summary", [])
    if not classes:
        return
    st = styles(report)
    methods = list(classes[0]["methods"])
    fig, ax = plt.subplots(figsize=(11, 0.36 * len(classes) + 2.6))
    offsets = np.linspace(-0.3, 0.3, len(methods))
    for m, dy in zip(methods, offsets):
        s = st[m]
        xs, ys, nx, ny = [], [], [], []
        for i, c in enumerate(classes):
            rec = c["methods"][m]
            if rec["max_error"] is not None:
                xs.append(max(rec["max_error"], ERROR_AXIS_FLOOR))
                ys.append(i + dy)
            if rec["refused"] or rec["failed"]:
                nx.append(NO_IMAGE_X)
                ny.append(i + dy)
        label = s["label"] if m != "default" else "tetvr default"
        ax.scatter(xs, ys, marker=s["marker"], color=s["color"], s=110 if m == "default" else 42,
                   edgecolors="black", linewidths=0.5, label=label, zorder=4 if m == "default" else 3)
        ax.scatter(nx, ny, marker=s["marker"], color=s["color"], s=42, edgecolors="black", linewidths=0.5,
                   zorder=3)
    ax.axvline(1 / 255, color="tab:red", lw=0.8, ls=":", label="1/255 (one 8-bit step)")
    ax.axvspan(1.6, 6.0, color="0.92", zorder=0)
    ax.text(NO_IMAGE_X, -0.95, "refused /\nfailed", ha="center", va="top", fontsize=7.5)
    kinds = [c["kind"] for c in classes]
    split = kinds.index("imperfect mesh") if "imperfect mesh" in kinds else len(classes)
    if 0 < split < len(classes):
        ax.axhline(split - 0.5, color="black", lw=0.8)
    ax.set_yticks(range(len(classes)))
    ax.set_yticklabels([c["name"] + (f" ({c['views']} views)" if c["views"] > 1 else "") for c in classes],
                       fontsize=8)
    for tick, kind in zip(ax.get_yticklabels(), kinds):
        tick.set_color("black" if kind == "stability case" else "#6a3d9a")
    ax.set_ylim(len(classes) - 0.5, -1.0)
    ax.set_xscale("log")
    ax.set_xlim(ERROR_AXIS_FLOOR / 2, 6.0)
    ax.set_xlabel("largest per-pixel error against the exact reference (premultiplied RGB; log; below 1e-7 drawn at 1e-7)")
    ax.grid(True, axis="x", alpha=0.3)
    size = "x".join(str(v) for v in report.get("stability_size", (96, 96)))
    ax.set_title(f"Failure classes at {size}: stability cases (black), imperfect meshes (purple, the worst of "
                 f"their meshes and views); {report['created'][:10]}", fontsize=9)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.75 / fig.get_figheight(), 1, 1))
    fig.savefig(path, dpi=90)
    plt.close(fig)


def sweep_chart(report: dict[str, Any], path: Path) -> None:
    """PSNR against scalar bins N, one line per (K, base), one panel per scene."""
    import matplotlib.pyplot as plt

    scenes = {k: v for k, v in report["scenes"].items() if v.get("table_convergence")}
    if not scenes:
        return
    cols = min(len(scenes), 6)
    rows = -(-len(scenes) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.4 * rows + 0.6), squeeze=False)
    for ax, (scene, data) in zip(axes.flat, scenes.items()):
        conv = data["table_convergence"]
        for k, base in dict.fromkeys((r["n_slices"], r["log_base"]) for r in conv):
            pts = sorted((r["n_bins"], r["psnr"]) for r in conv if (r["n_slices"], r["log_base"]) == (k, base))
            if pts:
                ax.plot(*zip(*pts), marker="o", ms=3, label=f"K={k}, base {base}")
        ax.set_xscale("log", base=2)
        ax.set_xlabel("scalar bins N")
        ax.set_ylabel("PSNR vs reference [dB]")
        ax.set_title(scene.replace("_tets.vtu", "").replace(".vtu", ""), fontsize=9)
        ax.grid(True, alpha=0.3)
    for ax in list(axes.flat)[len(scenes):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    size = "x".join(str(v) for v in report["size"])
    fig.suptitle(f"Where the table error comes from: PSNR by scalar bins N and thickness slices (K, log base), {size}")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def draw_all(report: dict[str, Any], out: Path) -> list[Path]:
    """Every chart of the report into ``out``; stale per-scene charts are removed. Returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    written = [out / "speed_accuracy.png"]
    summary_chart(report, written[0])
    names = list(dict.fromkeys(name for scenes in runs(report).values() for name in scenes))
    for name in names:
        path = out / f"speed_accuracy_{slug(name)}.png"
        scene_chart(report, name, path)
        written.append(path)
    if report.get("stability_summary"):
        written.append(out / "speed_accuracy_stability.png")
        stability_chart(report, written[-1])
    for old in out.glob("speed_accuracy_*.png"):
        if old not in written:
            old.unlink()
    return written


if __name__ == "__main__":
    src = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent / "results" / "speed_accuracy.json"
    for p in draw_all(json.loads(src.read_text()), src.parent):
        print(p)

"""The Jupyter viewer's latency in a real browser: input to first pixels, input to the full frame.

JupyterLab on 127.0.0.1 and headless Chromium (the launchers of tests/browser) show the viewer
on each mesh in a notebook; Selenium drags on the picture: mouse down, 30 moves over 1 s,
mouse up. The page logs when each input happened and when each frame was decoded in the
<img> (its ``load`` event), so every time here is the browser's clock, from the input event
to pixels on the page:

* **first pixels**: from the drag's first move to the first new frame;
* **full frame**: from mouse-up to the first full-size frame after it;
* **frames in the drag**: how many frames the page showed during the 1 s of moves, and
  their widths (the previews' sizes).

The goal (``GOAL``): the first pixels within 100 ms of the input, the full frame within 2 s
of mouse-up, on bluntfin at 560x420 (the viewer's default size); the chart draws it.

Variants: ``after`` is :class:`tetvr.apps.viewer.Viewer` (jupyter_rfb + the render loop);
``before`` is the viewer this one replaced (ipywidgets.Image + ipyevents, rendering in the
event handler), loaded from git (``--before-rev``) with ipyevents installed, else left out
with the reason in the JSON.

    python bench/viewer.py [--repeats 5] [--meshes post bluntfin] [--variants after before]

Writes bench/results/viewer.json and bench/results/viewer.png.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import ROOT, TETS_DATA, loadavg, machine, write_json  # noqa: E402

from tests.browser.lab import missing, open_and_run, start_browser, start_lab, write_notebook  # noqa: E402

RESULTS = ROOT / "bench" / "results"
MESHES = {"post": "post.vtk", "bluntfin": "bluntfin_tets.vtu"}
SIZE = (560, 420)
#: The latencies the viewer aims for (ms).
GOAL = {"first_pixels_ms": 100.0, "full_frame_ms": 2000.0}
#: The last commit with the ipywidgets.Image + ipyevents viewer.
BEFORE_REV = "fab485f~1"

_WATCH_JS = """
const img = document.querySelector(arguments[0]);
if (!img) return false;
window.__frames = []; window.__inputs = [];
if (!img.__tetvrWatched) {
  img.__tetvrWatched = true;
  img.addEventListener('load', () => window.__frames.push(
      {t: performance.now(), nw: img.naturalWidth, nh: img.naturalHeight}));
  for (const kind of ['pointerdown', 'pointermove', 'pointerup']) {
    img.addEventListener(kind, () => window.__inputs.push({t: performance.now(), kind}), true);
  }
}
return true;
"""


def _cells(variant: str, mesh_path: Path) -> tuple[str, ...]:
    if variant == "after":
        return (f"from tetvr.apps.viewer import Viewer\nviewer = Viewer({str(mesh_path)!r}, size={SIZE!r})\nviewer",)
    return ("import importlib.util, sys\n"
            "spec = importlib.util.spec_from_file_location('tetvr._widget_before', '_widget_before.py')\n"
            "before = importlib.util.module_from_spec(spec); sys.modules[spec.name] = before\n"
            "spec.loader.exec_module(before)\n"
            "from tetvr.apps.viewer.model import scene_of\n"
            f"viewer = before.Viewer(scene_of({str(mesh_path)!r}, size={SIZE!r}))\n"
            "viewer.image.add_class('tetvr-image')\n"
            "display(viewer.widget)",)


def _selector(variant: str) -> str:
    return ".tetvr-image img" if variant == "after" else "img.tetvr-image"


def _wait(driver: Any, cond: str, timeout: float) -> Any:
    """Poll a JS expression until it is truthy (its value) or ``timeout`` (None)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = driver.execute_script(f"return {cond}")
        if value:
            return value
        time.sleep(0.05)
    return None


def _drag(driver: Any, selector: str, moves: int = 30, seconds: float = 1.0, step: tuple[int, int] = (4, 1)) -> None:
    from selenium.webdriver.common.action_chains import ActionChains

    el = driver.find_element("css selector", selector)
    chain = ActionChains(driver, duration=0).move_to_element(el).click_and_hold()
    for _ in range(moves):
        chain = chain.move_by_offset(*step).pause(seconds / moves)
    chain.release().perform()


def _measure(driver: Any, selector: str, timeout: float) -> dict[str, Any]:
    """One 1 s drag: first pixels after the first move, full frame after mouse-up (ms)."""
    driver.execute_script(_WATCH_JS, selector)
    _drag(driver, selector)
    full = f"window.__frames.filter(f => f.nw === {SIZE[0]} && f.nh === {SIZE[1]} && " \
           "window.__inputs.some(i => i.kind === 'pointerup' && f.t > i.t))[0]"
    got = _wait(driver, full, timeout)
    frames, inputs = driver.execute_script("return [window.__frames, window.__inputs]")
    moves = [i["t"] for i in inputs if i["kind"] == "pointermove"]
    up = [i["t"] for i in inputs if i["kind"] == "pointerup"]
    if not moves or not up:
        return {"error": "the page saw no drag"}
    first = [f["t"] for f in frames if f["t"] > moves[0]]
    in_drag = [f for f in frames if moves[0] < f["t"] <= up[-1]]
    out: dict[str, Any] = {
        "first_pixels_ms": (first[0] - moves[0]) if first and first[0] < up[-1] else None,
        "full_frame_ms": (got["t"] - up[-1]) if got else None,
        "frames_in_drag": len(in_drag),
        "widths_in_drag": [f["nw"] for f in in_drag],
        "first_width": in_drag[0]["nw"] if in_drag else None,
        "drag_ms": up[-1] - moves[0],  # Selenium's pauses add up to 1 s; its own overhead comes on top
    }
    if got is None:
        out["error"] = f"no full frame within {timeout:.0f} s of mouse-up"
    return out


def _median(values: list[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    return statistics.median(vals) if vals else None


def _stop_kernels(url: str, token: str) -> None:
    import json

    with urllib.request.urlopen(f"{url}/api/sessions?token={token}", timeout=10) as r:
        sessions = json.load(r)
    for s in sessions:
        req = urllib.request.Request(f"{url}/api/sessions/{s['id']}?token={token}", method="DELETE")
        urllib.request.urlopen(req, timeout=30).close()


#: The old viewer (tetvr/widget.py) imports its neighbours relatively, from the package's
#: layout of the time: where each of them lives now.
_OLD_IMPORTS = (("from .camera import", "from tetvr.core.camera import"),
                ("from .image import", "from tetvr.core.image import"),
                ("from .mesh import TetMesh", "from tetvr.mesh.tetmesh import TetMesh"),
                ("from .mesh import read", "from tetvr.io.meshfile import read"),
                ("from .render import", "from tetvr.render import"),
                ("from .scene import Scene, load_scene",
                 "from tetvr.scene.scene import Scene\nfrom tetvr.scene.load import load_scene"),
                ("from .settings import", "from tetvr.settings import"),
                ("from .transfer import", "from tetvr.optics.transfer import"),
                ("from .animate import", "from tetvr.apps.animate import"),
                ("from .colormaps import", "from tetvr.optics.colormaps import"),
                ("from .gl.", "from tetvr.gl."),
                ("from .sort import", "from tetvr.order.sort import"),
                ("from .method import", "from tetvr.order.method import"))


def _before_available(rev: str, root: Path) -> str | None:
    if importlib.util.find_spec("ipyevents") is None:
        return "ipyevents is not installed (pip install ipyevents): the old viewer's mouse input needs it"
    try:
        text = subprocess.run(["git", "show", f"{rev}:tetvr/widget.py"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout
    except subprocess.CalledProcessError as exc:
        return f"git show {rev}:tetvr/widget.py failed: {exc.stderr.strip()}"
    for old, new in _OLD_IMPORTS:
        text = text.replace(old, new)
    (root / "_widget_before.py").write_text(text)
    return None


def chart(result: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
    names = list(result["meshes"])
    variants = [v for v in ("before", "after") if any(v in result["meshes"][n] for n in names)]
    for ax, key, title in zip(axes, ("first_pixels_ms", "full_frame_ms"),
                              ("input -> first pixels", "mouse-up -> full frame")):
        shown = [(result["meshes"][n].get(v) or {}).get("median", {}).get(key) for n in names for v in variants]
        shown = [y for y in shown if y]
        for k, variant in enumerate(variants):
            xs = [i + (k - (len(variants) - 1) / 2) * 0.38 for i in range(len(names))]
            ys = [(result["meshes"][n].get(variant) or {}).get("median", {}).get(key) for n in names]
            bars = ax.bar([x for x, y in zip(xs, ys) if y], [y for y in ys if y], width=0.36, label=variant)
            ax.bar_label(bars, fmt="%.0f", fontsize=8)
        goal = result.get("goal", {}).get(key)
        if goal:
            ax.axhline(goal, color="#c00", lw=1, ls="--")
            ax.annotate(f"goal: {goal:.0f} ms", (0.01, goal), xycoords=("axes fraction", "data"), ha="left",
                        va="top", fontsize=8, color="#c00", xytext=(0, -2), textcoords="offset points")
            shown.append(goal)
        if shown:
            ax.set_ylim(min(shown) / 2, max(shown) * 4)  # room for the labels and the legend
        ax.set_xticks(range(len(names)), names)
        ax.set_yscale("log")
        ax.set_ylabel("ms (median)")
        ax.set_title(title, fontsize=10)
    axes[0].legend(fontsize=8, loc="upper left")
    fig.suptitle(f"Jupyter viewer in Chromium, {SIZE[0]}x{SIZE[1]}, 1 s drag of 30 moves", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=list(MESHES), choices=list(MESHES))
    ap.add_argument("--variants", nargs="+", default=["after", "before"], choices=["after", "before"])
    ap.add_argument("--repeats", type=int, default=5, help="drags per mesh and variant")
    ap.add_argument("--before-repeats", type=int, default=2, help="drags per mesh for 'before' (slow)")
    ap.add_argument("--before-rev", default=BEFORE_REV)
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds to wait for the full frame")
    ap.add_argument("--out", type=Path, default=RESULTS / "viewer.json")
    args = ap.parse_args(argv)
    why = missing()
    if why:
        print(f"cannot drive a browser here: {why}", file=sys.stderr)
        return 2
    result: dict[str, Any] = {
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "command": " ".join(sys.argv),
        "size": list(SIZE), "gesture": "mouse down, 30 moves of (4, 1) px 1/30 s apart, mouse up", "goal": GOAL,
        "machine": machine(), "loadavg_start": loadavg(), "meshes": {}}
    with tempfile.TemporaryDirectory(prefix="tetvr-bench-viewer-") as tmp:
        root = Path(tmp)
        skipped = {}
        if "before" in args.variants:
            reason = _before_available(args.before_rev, root)
            if reason:
                skipped["before"] = reason
                print(f"before: left out ({reason})")
        url, token, stop_lab = start_lab(root)
        (root / "profile").mkdir()
        driver, stop_browser = start_browser(root / "profile")
        try:
            for name in args.meshes:
                mesh_path = TETS_DATA / MESHES[name]
                if not mesh_path.is_file():
                    print(f"{name}: {mesh_path} not found, left out")
                    continue
                import tetvr

                entry: dict[str, Any] = {"file": MESHES[name], "n_tets": tetvr.read(mesh_path).n_tets}
                for variant in args.variants:
                    if variant in skipped:
                        entry[variant] = {"skipped": skipped[variant]}
                        continue
                    nb = root / f"{variant}_{name}.ipynb"
                    write_notebook(nb, *_cells(variant, mesh_path))
                    open_and_run(driver, f"{url}/lab/tree/{nb.name}?token={token}", _selector(variant), 180)
                    # The first full frame, then the drags.
                    driver.execute_script(_WATCH_JS, _selector(variant))
                    ready = _wait(driver, f"(() => {{ const i = document.querySelector('{_selector(variant)}');"
                                          f" return i && i.naturalWidth === {SIZE[0]}; }})()", 180)
                    runs = []
                    if ready:
                        n = args.repeats if variant == "after" else args.before_repeats
                        for _ in range(n):
                            runs.append(_measure(driver, _selector(variant), args.timeout))
                            print(f"{name} {variant}: {runs[-1]}", flush=True)
                            time.sleep(0.5)
                    entry[variant] = {
                        "runs": runs,
                        "median": {k: _median([r.get(k) for r in runs])
                                   for k in ("first_pixels_ms", "full_frame_ms", "frames_in_drag", "drag_ms",
                                             "first_width")},
                        **({} if ready else {"error": "the first full frame never came"}),
                    }
                    _stop_kernels(url, token)
                result["meshes"][name] = entry
            result["console_severe"] = [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        finally:
            stop_browser()
            stop_lab()
    result["loadavg_end"] = loadavg()
    write_json(args.out, result)
    chart(result, args.out.with_suffix(".png"))
    print(f"wrote {args.out} and {args.out.with_suffix('.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""What a newcomer's first hour costs: installing the test command's extras, and running each notebook.

Two parts, each written into ``bench/results/first_hour.json`` (a part not run keeps its
previous numbers):

* **notebooks**: every ``notebooks/*.ipynb`` executed as ``tests/test_notebooks.py`` runs it
  (nbclient, a fresh ``python3`` kernel, ``notebooks/`` as its working directory): wall time
  from kernel start to shutdown, the kernel's CPU time (user + system, from the resource use
  of this process's reaped children; the viewer's render process in notebook 1 is not
  counted) and each cell's wall time. Each notebook runs once with an empty Mesa shader
  cache, as on a new machine, then ``--repeats`` times with it filled (the best counts).
  llvmpipe rasterises on the CPU: other work on the same cores stretches the wall time and,
  less, the CPU time, so the load averages are recorded with each run;
* **install**: the README's test install, ``pip install -e ".[test,...]"`` after
  ``pip install --upgrade pip``, in a fresh virtual environment under the temporary folder,
  three times: with pip's cache off (``--no-cache-dir``), with an empty cache (which it fills)
  and with that cache full. It records which packages pip built from source (an sdist), what
  it fetched from an index (pip logs files from its HTTP cache as downloads too) and the disk
  each extra adds (the installed size of the packages only that extra pulls in).

    python bench/first_hour.py                       # both parts
    python bench/first_hour.py --part notebooks      # the notebooks only (~5 minutes on 2 cores)
    python bench/first_hour.py --part install        # the installs only (tens of minutes on 2 cores)

Absolute seconds hold for the machine and load that produced them; the JSON records both
(CPU model and count, the load averages before and after each part).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import ROOT, loadavg, machine, write_json  # noqa: E402

RESULTS = ROOT / "bench" / "results"
OUT = RESULTS / "first_hour.json"
NOTEBOOKS = ROOT / "notebooks"
#: The README's test command installs these extras (``.ci/run`` does the same).
TEST_EXTRAS = ("test", "volumes", "notebooks", "widget", "browser", "animate", "compare", "mesh", "dask")


def _children_cpu_s() -> float:
    """User + system CPU seconds of this process's children that have been waited for."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _cell_seconds(cell: Any) -> float | None:
    """A cell's wall time from the timestamps nbclient records (busy to execute_reply)."""
    ex = cell.get("metadata", {}).get("execution", {})
    start, end = ex.get("iopub.status.busy"), ex.get("shell.execute_reply")
    if not (start and end):
        return None
    parse = (lambda s: datetime.fromisoformat(s.replace("Z", "+00:00")))
    return (parse(end) - parse(start)).total_seconds()


def time_notebook(path: Path, env: dict[str, str] | None = None) -> dict[str, Any]:
    """Execute one notebook as tests/test_notebooks.py does (``env`` added to the kernel's
    environment); its wall, kernel CPU and cell times."""
    import nbclient
    import nbformat

    book = nbformat.read(path, as_version=4)
    saved = dict(os.environ)
    os.environ.update(env or {})
    os.environ.setdefault("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    load, cpu0, t0 = loadavg(), _children_cpu_s(), time.perf_counter()
    try:
        nbclient.NotebookClient(book, timeout=600, kernel_name="python3",
                                resources={"metadata": {"path": str(NOTEBOOKS)}}).execute()
    finally:
        os.environ.clear()
        os.environ.update(saved)
    wall, cpu = time.perf_counter() - t0, _children_cpu_s() - cpu0
    cells = [{"index": i, "first_line": c.source.splitlines()[0] if c.source else "", "wall_s": round(s, 3)}
             for i, c in enumerate(book.cells) if c.cell_type == "code" and (s := _cell_seconds(c)) is not None]
    in_cells = sum(c["wall_s"] for c in cells)
    return {"wall_s": round(wall, 2), "kernel_cpu_s": round(cpu, 2), "loadavg_1min": load[0] if load else None,
            "cells_wall_s": round(in_cells, 2), "kernel_start_and_stop_s": round(wall - in_cells, 2),
            "slowest_cells": sorted(cells, key=lambda c: -c["wall_s"])[:3], "cells": cells}


def measure_notebooks(names: list[str] | None, repeats: int) -> dict[str, Any]:
    """Time every notebook (or those named), one after the other: once with an empty shader
    cache (Mesa keeps the shaders it compiled on disk; a new machine starts without them),
    then ``repeats`` times with that cache filled. The best of those is the notebook's time."""
    paths = [p for p in sorted(NOTEBOOKS.glob("*.ipynb")) if not names or p.stem in names or p.name in names]
    out: dict[str, Any] = {"created": _now(), "machine": machine(), "loadavg_before": loadavg(), "repeats": repeats,
                           "notebooks": {}}
    for path in paths:
        with tempfile.TemporaryDirectory(prefix="tetvr-shader-cache-") as cache:
            env = {"MESA_SHADER_CACHE_DIR": cache}
            cold = time_notebook(path, env)
            warm = [time_notebook(path, env) for _ in range(repeats)]
        best = min(warm, key=lambda r: r["wall_s"])
        rec = {**best, "cold_shader_cache": {k: cold[k] for k in ("wall_s", "kernel_cpu_s", "loadavg_1min")},
               "runs": [{k: r[k] for k in ("wall_s", "kernel_cpu_s", "loadavg_1min")} for r in warm]}
        out["notebooks"][path.name] = rec
        print(f"{path.name}: {rec['wall_s']:.1f} s wall, {rec['kernel_cpu_s']:.1f} s kernel CPU "
              f"(empty shader cache: {cold['wall_s']:.1f} s, {cold['kernel_cpu_s']:.1f} s); slowest cell "
              f"{rec['slowest_cells'][0]['wall_s']:.1f} s", flush=True)
    out["loadavg_after"] = loadavg()
    return out


# ---------------------------------------------------------------- the install
_BUILT = re.compile(r"Building wheel for (\S+)")
_DOWNLOAD = re.compile(r"Downloading (\S+?)-(\d\S*?)(?:-py\d|-cp\d|\.tar\.gz|\.zip)\S* \(([\d.]+) ([kM]B)\)")


def _pip(venv: Path, args: list[str], log: Path) -> float:
    """Run the venv's pip with ``args``, its output appended to ``log``; the wall seconds."""
    t0 = time.perf_counter()
    with log.open("a") as f:
        subprocess.run([str(venv / "bin" / "python"), "-m", "pip", *args], cwd=ROOT, check=True,
                       stdout=f, stderr=subprocess.STDOUT)
    return time.perf_counter() - t0


def _one_install(tmp: Path, label: str, cache: list[str]) -> dict[str, Any]:
    """A fresh venv, pip upgraded, then the test extras; the seconds of each step and what pip built."""
    venv, log = tmp / f"venv-{label}", tmp / f"pip-{label}.log"
    load, cpu0, t0 = loadavg(), _children_cpu_s(), time.perf_counter()
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    venv_s = time.perf_counter() - t0
    pip_s = _pip(venv, ["install", *cache, "--upgrade", "pip"], log)
    spec = f".[{','.join(TEST_EXTRAS)}]"
    extras_s = _pip(venv, ["install", *cache, "-e", spec], log)
    text = log.read_text()
    downloads = sorted(((m.group(1), float(m.group(3)) * (1 if m.group(4) == "MB" else 1e-3))
                        for m in _DOWNLOAD.finditer(text)), key=lambda d: -d[1])
    local = re.findall(r"^Processing (/\S+\.whl)", text, re.M)  # from a find-links folder or a file:// index
    return {"cache": " ".join(cache) or "pip's default cache", "loadavg_before": load, "venv_s": round(venv_s, 1),
            "pip_upgrade_s": round(pip_s, 1), "install_s": round(extras_s, 1),
            "total_s": round(venv_s + pip_s + extras_s, 1), "cpu_s": round(_children_cpu_s() - cpu0, 1),
            "built_from_source": sorted(set(_BUILT.findall(text)) - {"tetvr"}),
            "downloaded_mb": round(sum(mb for _, mb in downloads), 1), "downloads": len(downloads),
            "local_wheels": len(local),
            "largest_downloads_mb": {name: round(mb, 1) for name, mb in downloads[:8]}}


_SIZES_SCRIPT = r"""
import json, re, sys
from importlib import metadata
def norm(n): return re.sub(r"[-_.]+", "-", n).lower()
dists = {norm(d.metadata["Name"]): d for d in metadata.distributions()}
def size(d):
    return sum((f.size or 0) for f in (d.files or []))
def deps(name, extra=None):
    d = dists.get(norm(name))
    out = []
    for req in (d.requires or []) if d else []:
        m = re.match(r"\s*([A-Za-z0-9_.\-]+)\s*(\[([^\]]*)\])?", req)
        marker = req.split(";", 1)[1] if ";" in req else ""
        wanted = re.search(r"extra\s*==\s*['\"]([^'\"]+)['\"]", marker)
        if (wanted.group(1) if wanted else None) != extra:
            continue
        out.append((m.group(1), [e.strip() for e in (m.group(3) or "").split(",") if e.strip()]))
    return out
def closure(roots):
    seen, todo = set(), list(roots)
    while todo:
        name, extras = todo.pop()
        key = norm(name)
        if key not in dists:
            continue
        new = key not in seen
        seen.add(key)
        for e in extras:
            todo.extend(deps(name, e))
        if new:
            todo.extend(deps(name))
    return seen
base = closure([("tetvr", [])])
every = closure([("tetvr", sys.argv[1:])])
out = {"base_mb": round(sum(size(dists[n]) for n in base) / 1e6, 1),
       "all_mb": round(sum(size(dists[n]) for n in every) / 1e6, 1), "extras": {}}
for extra in sys.argv[1:]:
    others = closure([("tetvr", [e for e in sys.argv[1:] if e != extra])])
    only = (closure([("tetvr", [extra])]) - others)
    out["extras"][extra] = {"only_this_extra_mb": round(sum(size(dists[n]) for n in only) / 1e6, 1),
                            "packages": sorted(only, key=lambda n: -size(dists[n]))[:6]}
print(json.dumps(out))
"""


def _sizes(venv: Path) -> dict[str, Any]:
    """Installed megabytes: tetvr's base, everything, and what each extra alone adds."""
    out = subprocess.run([str(venv / "bin" / "python"), "-c", _SIZES_SCRIPT, *TEST_EXTRAS],
                         check=True, capture_output=True, text=True, cwd=tempfile.gettempdir()).stdout
    return json.loads(out)


def measure_install() -> dict[str, Any]:
    """The three installs (no cache, empty cache, full cache) and the installed sizes."""
    config = subprocess.run([sys.executable, "-m", "pip", "config", "list"], capture_output=True, text=True).stdout
    out: dict[str, Any] = {"created": _now(), "machine": machine(), "loadavg_before": loadavg(),
                           "extras": list(TEST_EXTRAS), "python": sys.version.split()[0],
                           # Where pip found the packages: a local mirror or find-links folder shortens the downloads.
                           "pip_config": [x for x in config.splitlines() if "index" in x or "find-links" in x]}
    with tempfile.TemporaryDirectory(prefix="tetvr-first-hour-") as name:
        tmp = Path(name)
        cache = tmp / "pip-cache"
        for label, args in (("no_cache", ["--no-cache-dir"]), ("empty_cache", ["--cache-dir", str(cache)]),
                            ("full_cache", ["--cache-dir", str(cache)])):
            out[label] = _one_install(tmp, label, args)
            print(f"install, {label}: {out[label]['total_s']:.0f} s; built from source: "
                  f"{out[label]['built_from_source'] or 'nothing'}", flush=True)
            if label == "full_cache":
                out["installed_size"] = _sizes(tmp / f"venv-{label}")
            shutil.rmtree(tmp / f"venv-{label}")
    out["loadavg_after"] = loadavg()
    return out


def _now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("notebooks", "install", "both"), default="both")
    ap.add_argument("--notebooks", nargs="*", help="notebook names or stems (default: all)")
    ap.add_argument("--repeats", type=int, default=2, help="runs of each notebook with the shader cache filled")
    ap.add_argument("--out", type=Path, default=OUT, help=f"the JSON (default {OUT.relative_to(ROOT)})")
    args = ap.parse_args(argv)
    data = json.loads(args.out.read_text()) if args.out.is_file() else {}
    if args.part in ("notebooks", "both"):
        fresh = measure_notebooks(args.notebooks, args.repeats)
        if args.notebooks and "notebooks" in data:  # keep the notebooks not run this time
            fresh["notebooks"] = {**data["notebooks"]["notebooks"], **fresh["notebooks"]}
        data["notebooks"] = fresh
    if args.part in ("install", "both"):
        data["install"] = measure_install()
    write_json(args.out, data)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

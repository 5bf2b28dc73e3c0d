"""What a step of tet marching costs on this GL, part by part.

Tet marching pays per ray--tet segment (``stages.py`` gives its time per segment). This
script times the march's view changes with one part of every step replaced by arithmetic
on the same inputs -- the picture is then wrong, the rest of the work the same -- and takes
what the frame loses as that part's cost:

* ``table fetch``: the trilinear fetch from the 3D pre-integration table (``lookup.glsl``);
* ``opacity exp2``: the ``exp2`` that makes the table's mean extinction an opacity;
* ``slice log2``: the ``log2`` that places a segment's length among the table's slices;
* ``tie rule``: ``side()``'s two cross products per edge (``march.frag``), which decide a
  ray exactly in a face's plane.

What is left is the walk itself: per step one link and one point read from the records,
the point seen across the ray, three cross products, the exit's weights, compositing.
Each variant runs in a process of its own (the shaders are read once a process), the
variants in turn, ``--rounds`` times; each process times ``--repeats`` view changes of 3
degrees after a warm-up frame, per mesh; the medians are over all of a variant's frames.
A substitution that no longer matches its shader's text is an error, not a variant that
measures nothing. Writes ``<out>/march_parts.json``; ``bench/README.md`` quotes it.

    python bench/march_parts.py [--size 1024] [--rounds 3] [--repeats 6] [--out bench/results]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import statistics
import subprocess
import sys
import time
import warnings
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]

#: Each variant: per shader file, (text, replacement) pairs; "whole" is the shaders as they are.
VARIANTS: dict[str, dict[str, list[tuple[str, str]]]] = {
    "whole": {},
    "table fetch": {"lookup.glsl": [("    vec4 t = trilinear(u_table, vec3(z, st));\n#endif",
                                     "    vec4 t = vec4(z, st, z * st.x + st.y);\n#endif")]},
    "opacity exp2": {"lookup.glsl": [("    float alpha = 1.0 - exp2(-d * t.a * u_optical_scale);",
                                      "    float alpha = min(d * t.a * u_optical_scale, 1.0);")]},
    "slice log2": {"lookup.glsl": [(": log2(x) * u_slices.w + u_slices_log;", ": x * u_slices.w + u_slices_log;")]},
    "tie rule": {"march.frag": [("precise float sa_ = side(fa, pa, pn), sb_ = side(fb, pb, pn), sc_ = side(fc, pc, pn);",
                                 "precise float sa_ = fa, sb_ = fb, sc_ = fc;")]},
}
#: The meshes (shared data file, field): real ones, whose walks the targets are about.
MESHES = (("bluntfin_tets.vtu", "Density"), ("combustor_tets.vtu", "Density"), ("pipe_flow_init_flow.vtu", "Pressure"))


def patch_shaders(variant: str) -> None:
    """Make tetvr read its shaders with ``variant``'s substitutions (this process only)."""
    import tetvr.gl.shaders as shaders

    edits = VARIANTS[variant]
    read = shaders._read.__wrapped__

    def patched(name: str) -> str:
        text = read(name)
        for old, new in edits.get(name, ()):
            if text.count(old) != 1:
                raise RuntimeError(f"{variant}: {name} no longer holds {old!r} once: update march_parts.py")
            text = text.replace(old, new)
        return text

    patched.__wrapped__ = read  # type: ignore[attr-defined]  # a later patch starts from the files again
    shaders._read = patched  # type: ignore[assignment]


def child(variant: str, size: int, repeats: int, data: Path) -> dict[str, list[float]]:
    """View-change seconds of each mesh with ``variant``'s shaders, in this process."""
    patch_shaders(variant)
    import tetvr
    from _common import load_quiet
    from tetvr import Camera, RenderSettings
    from tetvr.apps.vtkcompare import orbit
    from tetvr.render import default_transfer_function

    out = {}
    with tetvr.Renderer(RenderSettings(method="raymarch")) as r:
        for name, field in MESHES:
            mesh = load_quiet(data / name, field)
            tf = default_transfer_function(mesh, opacity=0.5)
            cam0 = Camera.fit(mesh)
            times = []
            for i in range(repeats + 1):
                t0 = time.perf_counter()
                r.render(mesh, orbit(cam0, 3.0 * (i + 1)), tf, size=(size, size))
                if i:
                    times.append(time.perf_counter() - t0)
            out[name] = times
    return out


def main(argv: list[str] | None = None) -> int:
    from _common import TETS_DATA, loadavg, machine, write_json

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--rounds", type=int, default=3, help="times each variant's process runs, in turn")
    ap.add_argument("--repeats", type=int, default=6, help="view changes per mesh and process")
    ap.add_argument("--data", type=Path, default=TETS_DATA)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        warnings.simplefilter("ignore")
        print(json.dumps(child(args.child, args.size, args.repeats, args.data)))
        return 0
    missing = [name for name, _ in MESHES if not (args.data / name).is_file()]
    if missing:
        print(f"march_parts.py needs {', '.join(missing)} in {args.data} (../shared/data/tets): pass --data")
        return 2
    start = loadavg()
    samples: dict[str, dict[str, list[float]]] = {v: {} for v in VARIANTS}
    for k in range(args.rounds):
        for variant in VARIANTS:
            cmd = [sys.executable, __file__, "--child", variant, "--size", str(args.size),
                   "--repeats", str(args.repeats), "--data", str(args.data)]
            got = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout.splitlines()[-1])
            for name, times in got.items():
                samples[variant].setdefault(name, []).extend(times)
            print(f"round {k + 1}: {variant}: " + ", ".join(f"{n.split('_')[0]} {statistics.median(t) * 1e3:.0f} ms"
                                                          for n, t in got.items()), flush=True)
    meshes = []
    for name, _ in MESHES:
        whole = statistics.median(samples["whole"][name])
        parts = {v: {"median_s": statistics.median(samples[v][name]),
                     "share": 1.0 - statistics.median(samples[v][name]) / whole}
                 for v in VARIANTS if v != "whole"}
        meshes.append({"name": name, "whole_s": whole, "parts": parts,
                       "samples_s": {v: samples[v][name] for v in VARIANTS}})
    res = {"what": __doc__.split("\n\n")[0], "date": _dt.datetime.now().isoformat(timespec="seconds"),
           "size": [args.size, args.size], "rounds": args.rounds, "repeats": args.repeats, "machine": machine(),
           "loadavg_start": start, "loadavg_end": loadavg(),
           "variants": {v: {f: [list(p) for p in edits] for f, edits in e.items()} for v, e in VARIANTS.items()},
           "meshes": meshes}
    args.out.mkdir(parents=True, exist_ok=True)
    write_json(args.out / "march_parts.json", res)
    for m in meshes:
        print(f"{m['name']}: whole {m['whole_s'] * 1e3:.0f} ms; " +
              ", ".join(f"{v} {p['share']:.0%}" for v, p in m["parts"].items()))
    return 0


if __name__ == "__main__":
    # Run as a script (bench/ is then first on the path): the checkout's tetvr. Not on
    # import: a test's workers would then import bench/distributed.py as Dask's package.
    sys.path.insert(1, str(ROOT))
    raise SystemExit(main())

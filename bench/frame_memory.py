"""Host memory of one frame: bytes per pixel of each method and of the picture, bytes per tet.

    python bench/frame_memory.py [--sizes 512 1024 2048] [--cubes 26 41] [--out bench/results]

Every measurement runs in its own process, since peak memory is per process. The process
makes its renderer and draws a small warm-up frame (the GL context, the shaders, the mesh's
records). It then resets its resident peak (``VmHWM``, through ``/proc/self/clear_refs``),
draws one frame of the size measured, and notes how far its resident peak and its
address-space peak (``VmPeak``, which cannot be reset: a lower bound) rose. What the frame
added, fitted by least squares over the sizes, is its cost per pixel; the estimates of
:mod:`tetvr.gl.framesize` must cover every size measured (``tests/badinput/
test_frame_memory.py`` checks). The scene is a 3x3x3 cube (``synthetic.cube(3)``) with
``method`` "raymarch" (what "auto" chooses for it) and "projected", and a 32^3 volume for
the volume ray caster; "annotate" is the legend and PNG that ``tetvr render`` writes,
"png" the plain PNG, each beyond the frame's image. "context" is what a renderer and its
first small frame take. Memory per tet: cubes of about 100k and 400k tets at 256x256,
what the mesh holds (its arrays' bytes) and what its first frame adds (tet marching's records, projected
tetrahedra's buffers and sort), fitted over the two sizes. Linux only (``/proc``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from _common import machine, write_json

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys
sys.path.insert(0, {root!r})
import numpy as np
import tetvr
from tetvr import Camera, RenderSettings
from tetvr.mesh import synthetic
from tetvr.render import default_transfer_function
spec = json.loads({spec!r})

def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key + ":"))

def start():
    # The resident peak (VmHWM) back to what is resident now, so that an earlier peak (the
    # warm-up's shader compilation) does not hide the frame's; the address space's peak
    # (VmPeak) cannot be reset, so its growth is a lower bound where an earlier peak was higher.
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    return status("VmRSS"), status("VmPeak")

def peak():
    return status("VmHWM"), status("VmPeak")

kind, size = spec["kind"], tuple(spec["size"])
out = dict(spec)
if kind == "context":  # what making a renderer and drawing a first small frame takes
    mesh = synthetic.cube(3)
    tf = default_transfer_function(mesh, opacity=0.3)
    before = start()
    with tetvr.Renderer() as r:
        r.render(mesh, Camera.fit(mesh), tf, size=size)
        after = peak()
elif kind in ("raymarch", "projected"):
    mesh = synthetic.cube(3)
    tf = default_transfer_function(mesh, opacity=0.3)
    with tetvr.Renderer(RenderSettings(method=kind)) as r:
        r.render(mesh, Camera.fit(mesh), tf, size=(64, 64))
        before = start()
        if spec.get("n", 3) > 3:  # memory per tet: what the mesh holds, then the frame's peak over it
            mesh = synthetic.cube(spec["n"])
            tf = default_transfer_function(mesh, opacity=0.3)
            out["n_tets"] = mesh.n_tets
            # What its arrays hold: the resident growth says little once freed memory is reused.
            out["mesh_held"] = sum(a.nbytes for a in (mesh.points, mesh.tets, mesh.scalars, mesh.cell_scalars)
                                   if a is not None)
            held = start()[0]
        r.render(mesh, Camera.fit(mesh), tf, size=size)
        if spec.get("n", 3) > 3:
            out["frame_added"] = status("VmHWM") - held
        after = peak()
elif kind == "raycast":
    from tetvr.gl.raycaster import Raycaster
    from tetvr.volume.volume import Volume
    from tetvr.optics.colormaps import colormap
    g = np.linspace(-1, 1, 32)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    vol = Volume.from_array((1000 * (1 - np.sqrt(x * x + y * y + z * z))).astype(np.int16))
    tf = colormap("viridis", (0.0, 1000.0), opacity=0.5, unit_distance=8.0)
    cam = Camera.fit(vol)
    with Raycaster() as rc:
        rc.render(vol, cam, tf, size=(64, 64))
        before = start()
        rc.render(vol, cam, tf, size=size)
        after = peak()
else:  # the picture of a finished frame
    from tetvr.core.image import png_bytes
    from tetvr.apps.annotate import annotate
    mesh = synthetic.cube(3)
    tf = default_transfer_function(mesh, opacity=0.3)
    cam = Camera.fit(mesh)
    rng = np.random.default_rng(0)
    small = rng.random((64, 64, 4), dtype=np.float32) * 0.5
    (png_bytes if kind == "png" else lambda im: annotate(im, tf, field="f", camera=cam, bounds=mesh.bounds))(small)
    image = np.empty((size[1], size[0], 4), np.float32)
    rng.random(out=image, dtype=np.float32)  # in place: no temporary raises the peak before the picture
    image *= 0.5
    before = start()
    if kind == "png":
        png_bytes(image)
    else:
        annotate(image, tf, field="f", title="t", camera=cam, bounds=mesh.bounds)
    after = peak()
out.update(before=before, after=after)
print(json.dumps(out))
"""

KINDS = ("raymarch", "projected", "raycast", "annotate", "png")


def run(spec: dict) -> dict:
    """One measurement in a fresh process."""
    code = CHILD.format(root=str(ROOT), spec=json.dumps(spec))
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=900)
    if res.returncode != 0:
        raise RuntimeError(f"{spec}: exit {res.returncode}\n{res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares slope of ys over xs."""
    return float(np.polyfit(np.asarray(xs, float), np.asarray(ys, float), 1)[0])


def fit(pixels: list[int], rows: list[dict], key: str, name: str) -> dict[str, float]:
    """``{name}_bytes_per_pixel`` and ``{name}_fixed_bytes``: the least-squares line of ``key`` over pixels."""
    b, a = np.polyfit(np.asarray(pixels, float), np.asarray([r[key] for r in rows], float), 1)
    return {f"{name}_bytes_per_pixel": float(b), f"{name}_fixed_bytes": float(a)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 1024, 2048])
    ap.add_argument("--png-sizes", type=int, nargs="+", default=[1024, 2048, 4096],
                    help="the PNG is converted in blocks of rows: sizes past one block show its cost per pixel")
    ap.add_argument("--cubes", type=int, nargs="+", default=[26, 41], help="cube(n): 6 n^3 tets")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    per_pixel = {}
    for kind in KINDS:
        rows = []
        for s in (args.png_sizes if kind == "png" else args.sizes):
            r = run({"kind": kind, "size": [s, s]})
            rows.append(dict(size=[s, s], pixels=s * s, rss_added=r["after"][0] - r["before"][0],
                             address_space_added=r["after"][1] - r["before"][1]))
            print(kind, s, rows[-1], flush=True)
        px = [r["pixels"] for r in rows]
        per_pixel[kind] = dict(rows=rows, **fit(px, rows, "rss_added", "rss"),
                               **fit(px, rows, "address_space_added", "address_space"))
    r = run({"kind": "context", "size": [64, 64]})
    context = dict(rss_added=r["after"][0] - r["before"][0], address_space_added=r["after"][1] - r["before"][1])
    per_tet = {}
    for kind in ("raymarch", "projected"):
        rows = []
        for n in args.cubes:
            r = run({"kind": kind, "size": [256, 256], "n": n})
            rows.append(dict(n_tets=r["n_tets"], mesh_rss_held=r["mesh_held"], frame_rss_added=r["frame_added"]))
            print(kind, n, rows[-1], flush=True)
        nt = [r["n_tets"] for r in rows]
        per_tet[kind] = dict(rows=rows, mesh_bytes_per_tet=slope(nt, [r["mesh_rss_held"] for r in rows]),
                             frame_rss_bytes_per_tet=slope(nt, [r["frame_rss_added"] for r in rows]))
    data = dict(date=time.strftime("%Y-%m-%dT%H:%M:%S"), sizes=args.sizes, machine=machine(),
                gl_renderer=_gl_renderer(), per_pixel=per_pixel, context=context, per_tet=per_tet)
    write_json(Path(args.out) / "frame_memory.json", data)
    print(json.dumps({k: round(v["rss_bytes_per_pixel"], 1) for k, v in per_pixel.items()}))
    return 0


def _gl_renderer() -> str:
    code = (f"import sys; sys.path.insert(0, {str(ROOT)!r}); import tetvr\n"
            "with tetvr.Renderer() as r: print(r.ctx.info['GL_RENDERER'])")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    return res.stdout.strip() or "?"


if __name__ == "__main__":
    sys.exit(main())

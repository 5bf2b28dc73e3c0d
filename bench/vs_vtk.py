"""tetvr against VTK's projected tetrahedra (ParaView's "Projected tetra"), same run, same GL.

For meshes from ~10k to ~1M tets (``synthetic.cube(n)`` and, when ``../shared/data/tets``
exists, bluntfin and combustor, field "Density") this renders a 512x512 perspective view
(:meth:`Camera.fit`, :func:`default_transfer_function` with opacity 0.5) with

* tetvr's GPU renderer, default settings (``Renderer``);
* tetvr in VTK parity (:data:`tetvr.settings.PARITY_SETTINGS`: VTK's convention);
* VTK's ``vtkProjectedTetrahedraMapper`` in an offscreen EGL window, in a child process
  (:class:`tetvr.apps.vtkrender.VTKProcess`: VTK's EGL window and moderngl's context cannot
  share a process),

all on the same OpenGL (Mesa llvmpipe here). The three renderers stay
alive for the whole mesh and take frames **in turn** (tetvr, parity, VTK, tetvr, ...),
so background load falls on all of them alike. Every frame turns the camera by
``--step`` degrees about its view-up axis, so each one is a view change: VTK re-sorts and
re-projects every cell on the CPU, tetvr re-classifies on the GPU and re-sorts. Each
frame is timed from the camera change to the image read back into numpy. The first
frame (window/context, upload, table build) is reported on its own: the median of
``--first-frames`` first frames of the default and of VTK (the later ones in turn, each
on the mesh loaded again and with tetvr's table caches emptied; VTK in a new process),
then one warm-up frame, then the median of R frames. The ratio VTK / tetvr of those medians is the
result; absolute seconds only hold for this machine.

Accuracy: each renderer's first-view image against tetvr's exact CPU reference
(``render_reference``) at ``--ref-size`` (default: the frame size), PSNR and RMSE of
premultiplied RGB; also against the reference in VTK's own convention (``optics="vtk"``),
which shows how well each one does what it sets out to do.

The meshes: the cubes and the data's meshes above, and the unstructured meshes of
``bench/corpus.py`` (a torus fTetWild fills at ~200k and ~1M tets, a Delaunay pipe
with a graded boundary layer; made once and cached, not with ``--quick``). ``--only NAME``
reruns the meshes whose names contain NAME and puts their records in place of those in
the existing JSON (each record carries its own date and load average).

Where ``auto`` takes projected tetrahedra for a timed view (``auto_method`` in the JSON),
tet marching is timed on its own too (``tetvr_march``), for ``bench/cost_model.py``.

Views from inside (``inside`` in the JSON): per mesh, the eye at the centroid of the cell
nearest the bounding box's centre, looking along the box's longest axis (60 degrees), the
view turned by :data:`INSIDE_STEP` degrees about the eye per frame; tetvr's default and
VTK's PT per view change, frames in turn, and their accuracy against the exact reference at
:data:`INSIDE_ACCURACY_SIZE` (VTK leaves out the cells the near plane cuts). Reported
beside the target, not part of it.

Target (:data:`TARGET`): tetvr's default at least 2x faster per view change than VTK's PT on
every mesh of >= 150k tets, at 512x512 and 1024x1024 (3x on bluntfin and combustor at
512x512), its first frame no later than VTK's on every mesh, and more accurate. The JSON
says per mesh whether it was met and by how much; the chart marks each target.

    python bench/vs_vtk.py [--quick] [--repeats 5] [--size 512] [--ref-size 512] [--out bench/results]

Writes ``vs_vtk.json`` (``vs_vtk_<size>.json`` at other sizes; after every mesh, and on
Ctrl-C), ``vs_vtk.png`` (chart) and ``vs_vtk_<mesh>.png`` (exact reference, tetvr, tetvr
parity, VTK PT; then |difference| from the reference x10 for the three renderers), and
prints a table. Needs ``pip install -e ".[compare,bench]"``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as _dt
import functools
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import tetvr  # noqa: E402
from tetvr import Camera  # noqa: E402
from tetvr.core.camera import default_view_up  # noqa: E402
from tetvr.apps.animate import azimuth  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402
from tetvr.core.image import psnr, rmse, write_png  # noqa: E402
from tetvr.mesh.tetmesh import TetMesh  # noqa: E402
from tetvr.reference.tets import render_reference  # noqa: E402
from tetvr.order.method import choose  # noqa: E402
from tetvr.render import default_transfer_function  # noqa: E402
from tetvr.settings import RenderSettings  # noqa: E402
from tetvr.apps.vtkcompare import orbit, quantize8, tile_images  # noqa: E402
from tetvr.apps.vtkrender import VTKProcess, vtk_status  # noqa: E402
from tetvr.settings import PARITY_SETTINGS

import corpus  # noqa: E402
from _common import (  # noqa: E402
    CUBE_NS, QUICK_MAX_TETS, REAL_MESHES, TETS_DATA, kept_records, load_quiet, loadavg, machine, write_json,
)

DEFAULT_DATA = TETS_DATA
OPACITY = 0.5
TARGET: dict[str, Any] = {
    "min_tets": 150_000, "speedup": 2.0, "grids": {"bluntfin": 3.0, "combustor": 3.0}, "grids_size": 512,
    "first_frame": 1.0,
    "what": "tetvr's default >= 2x faster than VTK's PT per view change on every mesh of >= 150k tets (>= 3x on "
            "bluntfin and combustor at 512x512), its first frame no later than VTK's on every mesh, and more accurate"}
#: Degrees a view from inside turns per frame (about its view up, through the eye).
INSIDE_STEP = 10.0
#: Size of the accuracy images of the views from inside (a reference of a 1M-tet mesh from
#: inside at 1024x1024 takes minutes).
INSIDE_ACCURACY_SIZE = (256, 256)
RENDERERS = ("tetvr", "tetvr_projected", "tetvr_parity", "vtk_pt")
LABELS = {"tetvr": "tetvr default (method=\"auto\")", "tetvr_projected": "tetvr projected tetrahedra",
          "tetvr_parity": "tetvr, VTK parity", "vtk_pt": "VTK projected tetra"}


def _mesh_specs(quick: bool, data_dir: Path, made: bool = True) -> tuple[list[tuple[str, Callable[[], TetMesh]]], list[str]]:
    specs: list[tuple[str, Callable[[], TetMesh]]] = []
    notes: list[str] = []
    for n in CUBE_NS:
        if quick and 6 * n**3 > QUICK_MAX_TETS:
            notes.append(f"--quick: skipped cube({n})")
            continue
        specs.append((f"cube({n})", functools.partial(synthetic.cube, n)))
    for fname, field in REAL_MESHES:
        path = data_dir / fname
        if not path.exists():
            notes.append(f"skipped {fname}: not in {data_dir}")
            continue
        specs.append((f"{path.stem.removesuffix('_tets')} ({field})", functools.partial(load_quiet, path, field)))
    if made and not quick:  # the unstructured meshes made here (bench/corpus.py; minutes the first time)
        specs.extend(corpus.meshes())
    elif made:
        notes.append("--quick: skipped the meshes of bench/corpus.py")
    return specs, notes


class _Tetvr:
    def __init__(self, settings: RenderSettings, quantize: bool) -> None:
        self.renderer = tetvr.Renderer(settings)
        self.quantize = quantize

    def frame(self, mesh: TetMesh, cam: Camera, tf: Any, size: tuple[int, int]) -> np.ndarray:
        image = self.renderer.render(mesh, cam, tf, size=size)
        return quantize8(image) if self.quantize else image

    def release(self) -> None:
        self.renderer.release()


class _Vtk:
    """VTK in its own process (see tetvr.apps.vtkrender): the frame time is measured there,
    from the camera change to the image in numpy, without moving the image across."""

    def __init__(self, mesh: TetMesh, tf: Any, size: tuple[int, int]) -> None:
        self.renderer = VTKProcess(mesh, tf, mapper="pt", size=size)

    def frame(self, mesh: TetMesh, cam: Camera, tf: Any, size: tuple[int, int]) -> np.ndarray:
        return self.renderer.render(cam)

    def release(self) -> None:
        self.renderer.release()


def _make(key: str, mesh: TetMesh, tf: Any, size: tuple[int, int]) -> Any:
    if key == "tetvr":
        return _Tetvr(RenderSettings(), quantize=False)
    if key == "tetvr_projected":
        return _Tetvr(RenderSettings(method="projected"), quantize=False)
    if key == "tetvr_march":
        return _Tetvr(RenderSettings(method="raymarch"), quantize=False)
    if key == "tetvr_parity":
        return _Tetvr(PARITY_SETTINGS, quantize=True)
    return _Vtk(mesh, tf, size)


def bench_mesh(name: str, mesh: TetMesh, size: tuple[int, int], ref_size: tuple[int, int], repeats: int,
               step: float) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    tf = default_transfer_function(mesh, opacity=OPACITY)
    cam0 = Camera.fit(mesh)
    rec: dict[str, Any] = {"name": name, "n_tets": mesh.n_tets, "n_points": mesh.n_points,
                           "scalars": mesh.scalar_name, "max_edge": mesh.max_edge,
                           "camera": cam0.to_dict(), "transfer_function": tf.to_dict()}
    cams = [orbit(cam0, step * (i + 1)) for i in range(repeats + 1)]
    keys = RENDERERS
    renderers: dict[str, Any] = {}
    first: dict[str, float] = {}
    images: dict[str, np.ndarray] = {}
    try:
        # First frames, the default's on the mesh as loaded (what tetvr works out about a mesh
        # it keeps with it). Then what "auto" takes for each timed view; where it is not tet
        # marching, that is timed too.
        for key in keys:
            renderers[key], images[key], first[key] = _first_frame(key, mesh, cam0, tf, size)
        rec["auto_method"] = [choose(RenderSettings(), mesh, cam, size) for cam in cams[1:]]
        if set(rec["auto_method"]) != {"raymarch"}:
            keys += ("tetvr_march",)
            renderers[keys[-1]], images[keys[-1]], first[keys[-1]] = _first_frame(keys[-1], mesh, cam0, tf, size)
        samples: dict[str, list[float]] = {k: [] for k in keys}
        cpu: dict[str, list[float]] = {k: [] for k in keys}
        # Warm-up view change, then R timed view changes, renderers in turn.
        for i, cam in enumerate(cams):
            for key in keys:
                c0, t0 = time.process_time(), time.perf_counter()
                renderers[key].frame(mesh, cam, tf, size)
                wall = time.perf_counter() - t0
                if key == "vtk_pt":
                    wall = renderers[key].renderer.last_seconds
                if i:
                    samples[key].append(wall)
                    if key != "vtk_pt":  # the VTK process's CPU time is not this process's
                        cpu[key].append((time.process_time() - c0) / wall)
        if ref_size != size:  # accuracy images at the reference's size
            for key in keys:
                renderers[key].release()
                renderers[key] = _make(key, mesh, tf, ref_size)
                images[key] = renderers[key].frame(mesh, cam0, tf, ref_size)
                if key == "vtk_pt":
                    renderers[key].frame(mesh, cam0, tf, ref_size)
    finally:
        for r in renderers.values():
            r.release()

    refs = {}
    for optics in ("exact", "vtk"):
        t0 = time.perf_counter()
        refs[optics] = render_reference(mesh, cam0, tf, ref_size, optics=optics)
        rec[f"reference_{optics}_s"] = time.perf_counter() - t0
    med = {k: float(statistics.median(v)) for k, v in samples.items()}
    rec["first_frame_s"] = first
    rec["view_change_median_s"] = med
    rec["view_change_samples_s"] = samples
    rec["cpu_utilisation"] = {k: float(statistics.median(v)) for k, v in cpu.items() if v}
    rec["speedup_vs_vtk_pt"] = {k: med["vtk_pt"] / med[k] for k in keys}
    rec["psnr"] = {k: {o: psnr(images[k], r) for o, r in refs.items()} for k in keys}
    rec["rmse"] = {k: {o: rmse(images[k], r) for o, r in refs.items()} for k in keys}
    rec["psnr_parity_vs_vtk_pt"] = psnr(images["tetvr_parity"], images["vtk_pt"])
    rec["first_frame_vs_vtk_pt"] = {k: first["vtk_pt"] / first[k] for k in keys}
    rec["target"] = target(name, mesh.n_tets, size, rec)
    pics = {"reference": refs["exact"], **images}
    return rec, pics


def _first_frame(key: str, mesh: TetMesh, camera: Camera, tf: Any, size: tuple[int, int]
                 ) -> tuple[Any, np.ndarray, float]:
    """A new renderer ``key``, its first image and its first frame's seconds: creation,
    upload, table / colour mapping, first sort and draw (VTK's from its window's creation,
    in its process)."""
    t0 = time.perf_counter()
    renderer = _make(key, mesh, tf, size)
    try:
        image = renderer.frame(mesh, camera, tf, size)
    except BaseException:
        renderer.release()
        raise
    seconds = time.perf_counter() - t0
    return renderer, image, renderer.renderer.first_seconds if key == "vtk_pt" else seconds


def first_frames_again(rec: dict[str, Any], load: Callable[[], TetMesh], size: tuple[int, int], times: int) -> None:
    """``times`` more first frames of tetvr's default and of VTK's PT, in turn (which goes
    first alternates), each on the mesh loaded afresh with tetvr's table caches emptied, as a
    new process would meet it (its GL context aside); ``rec``'s first frames and their ratio
    become the medians with the first one's samples (``first_frame_samples_s``)."""
    from tetvr.optics import preintegrate, tablesize

    samples = {k: [rec["first_frame_s"][k]] for k in ("tetvr", "vtk_pt")}
    for i in range(times):
        mesh = load()
        tf = default_transfer_function(mesh, opacity=OPACITY)
        cam = Camera.fit(mesh)
        for key in (("tetvr", "vtk_pt") if i % 2 else ("vtk_pt", "tetvr")):
            preintegrate.cache_clear()
            tablesize.cache_clear()
            renderer, _, seconds = _first_frame(key, mesh, cam, tf, size)
            renderer.release()
            samples[key].append(seconds)
        del mesh
    rec["first_frame_samples_s"] = samples
    for key, values in samples.items():
        rec["first_frame_s"][key] = float(statistics.median(values))
    rec["first_frame_vs_vtk_pt"] = {k: rec["first_frame_s"]["vtk_pt"] / v for k, v in rec["first_frame_s"].items()}


def inside_camera(mesh: TetMesh) -> Camera:
    """A view from inside ``mesh``: the eye at the centroid of the cell nearest the bounding
    box's centre, looking along the box's longest axis (tilted off it a little, so that no
    face of a grid is seen edge-on by construction), 60 degrees."""
    lo, hi = mesh.bounds
    centroid = mesh.centroids
    eye = centroid[int(np.argmin(np.linalg.norm(centroid - (lo + hi) / 2.0, axis=1)))]
    axis = int(np.argmax(hi - lo))
    d = np.zeros(3)
    d[axis], d[(axis + 1) % 3], d[(axis + 2) % 3] = 1.0, 0.2, 0.1
    return Camera(position=tuple(eye), focal_point=tuple(eye + d), view_up=default_view_up(d), view_angle=60.0)


def turn(camera: Camera, degrees: float) -> Camera:
    """``camera`` with its view turned by ``degrees`` about its view up, through the eye:
    :func:`~tetvr.apps.animate.azimuth` (which turns the eye about the focal point) with the
    two points swapped."""
    swapped = dataclasses.replace(camera, position=camera.focal_point, focal_point=camera.position)
    turned = azimuth(swapped, degrees)
    return dataclasses.replace(camera, focal_point=turned.position)


def bench_inside(mesh: TetMesh, tf: Any, size: tuple[int, int], repeats: int) -> dict[str, Any]:
    """tetvr's default and VTK's PT on views from inside ``mesh`` (:func:`inside_camera`),
    frames in turn: the median of ``repeats`` view changes after a first frame and a
    warm-up, and each one's accuracy at :data:`INSIDE_ACCURACY_SIZE`."""
    cam0 = inside_camera(mesh)
    keys = ("tetvr", "vtk_pt")
    samples: dict[str, list[float]] = {k: [] for k in keys}
    renderers = {k: _make(k, mesh, tf, size) for k in keys}
    images: dict[str, np.ndarray] = {}
    try:
        for k in keys:
            renderers[k].frame(mesh, cam0, tf, size)
        for i in range(repeats + 1):
            cam = turn(cam0, INSIDE_STEP * (i + 1))
            for k in keys:
                t0 = time.perf_counter()
                renderers[k].frame(mesh, cam, tf, size)
                wall = renderers[k].renderer.last_seconds if k == "vtk_pt" else time.perf_counter() - t0
                if i:
                    samples[k].append(wall)
        for k in keys:
            renderers[k].release()
            renderers[k] = _make(k, mesh, tf, INSIDE_ACCURACY_SIZE)
            images[k] = renderers[k].frame(mesh, cam0, tf, INSIDE_ACCURACY_SIZE)
    finally:
        for r in renderers.values():
            r.release()
    ref = render_reference(mesh, cam0, tf, INSIDE_ACCURACY_SIZE)
    med = {k: float(statistics.median(v)) for k, v in samples.items()}
    return {"camera": cam0.to_dict(), "step_deg": INSIDE_STEP, "view_change_median_s": med,
            "view_change_samples_s": samples, "speedup_vs_vtk_pt": med["vtk_pt"] / med["tetvr"],
            "accuracy_size": list(INSIDE_ACCURACY_SIZE), "psnr": {k: psnr(images[k], ref) for k in keys},
            "max_error": {k: float(np.abs(images[k].astype(np.float64) - ref).max()) for k in keys}}


def target(name: str, n_tets: int, size: tuple[int, int], rec: dict[str, Any]) -> dict[str, Any]:
    """What :data:`TARGET` asks of this mesh at this size, and whether it was met: the view
    change ratio where it applies (>= 150k tets), the first frame on every mesh."""
    grid = next((v for k, v in TARGET["grids"].items() if name.startswith(k)), None)
    wanted = grid if grid is not None and size[0] == TARGET["grids_size"] else TARGET["speedup"]
    speedup, first = rec["speedup_vs_vtk_pt"]["tetvr"], rec["first_frame_vs_vtk_pt"]["tetvr"]
    more_accurate = rec["psnr"]["tetvr"]["exact"] > rec["psnr"]["vtk_pt"]["exact"]
    applies = n_tets >= TARGET["min_tets"]
    return {"applies": applies, "speedup_wanted": wanted, "speedup": speedup, "more_accurate": more_accurate,
            "first_frame": first, "first_frame_met": bool(first >= TARGET["first_frame"]),
            "met": bool((speedup >= wanted or not applies) and more_accurate and first >= TARGET["first_frame"])}


def _picture(pics: dict[str, np.ndarray], path: Path) -> None:
    ref = pics["reference"]
    tiles = [ref] + [pics[k] for k in RENDERERS]
    diffs = []
    for k in RENDERERS:
        d = np.zeros_like(ref)
        d[..., :3] = np.clip(np.abs(pics[k][..., :3] - ref[..., :3]) * 10.0, 0, 1)
        d[..., 3] = 1
        diffs.append(d)
    black = np.zeros_like(ref)
    black[..., 3] = 1
    write_png(tile_images(tiles + [black] + diffs, cols=4), path, background=(0, 0, 0))


def print_table(res: dict[str, Any]) -> None:
    print(f"\n{'mesh':<22}{'tets':>9} | view change ms: {'tetvr':>7}{'PT':>7}{'parity':>8}{'VTK PT':>8} | "
          f"VTK/tetvr  VTK/PT | PSNR exact: {'tetvr':>6}{'PT':>6}{'parity':>7}{'VTK':>6} | target")
    for m in res["meshes"]:
        v, p, r = m["view_change_median_s"], m["psnr"], m["speedup_vs_vtk_pt"]
        tgt = "met" if m["target"]["met"] else f"NOT met (first frame {m['target']['first_frame']:.2f}x)"
        print(f"{m['name']:<22}{m['n_tets']:>9} | {'':16}{v['tetvr'] * 1e3:>7.0f}{v['tetvr_projected'] * 1e3:>7.0f}"
              f"{v['tetvr_parity'] * 1e3:>8.0f}{v['vtk_pt'] * 1e3:>8.0f} | {r['tetvr']:>9.2f}"
              f"{r['tetvr_projected']:>8.2f} | {'':12}{p['tetvr']['exact']:>6.1f}{p['tetvr_projected']['exact']:>6.1f}"
              f"{p['tetvr_parity']['exact']:>7.1f}{p['vtk_pt']['exact']:>6.1f} | {tgt}")
        if "inside" in m:
            ins = m["inside"]
            print(f"{'  from inside':<31} | {'':16}{ins['view_change_median_s']['tetvr'] * 1e3:>7.0f}{'':15}"
                  f"{ins['view_change_median_s']['vtk_pt'] * 1e3:>8.0f} | {ins['speedup_vs_vtk_pt']:>9.2f}{'':8} | "
                  f"{'':12}{ins['psnr']['tetvr']:>6.1f}{'':13}{ins['psnr']['vtk_pt']:>6.1f} | (at "
                  f"{ins['accuracy_size'][0]}x{ins['accuracy_size'][1]})")


def plot(res: dict[str, Any], path: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no chart (pip install -e '.[bench]')")
        return
    meshes = sorted(res["meshes"], key=lambda m: m["n_tets"])
    if not meshes:
        return
    # "beam_tet4_result_100 (VonMises_stress)" -> "beam": the file's first word fits under a bar.
    names = [f"{m['name'].split(' ')[0].split('_')[0]}\n{m['n_tets'] / 1e3:.0f}k" for m in meshes]
    x = np.arange(len(meshes))
    fig, ax = plt.subplots(1, 3, figsize=(20, 5.4))
    w = 0.2
    colors = {"tetvr": "#1f77b4", "tetvr_projected": "#2ca02c", "tetvr_parity": "#9ecae1", "vtk_pt": "#d62728"}
    for i, k in enumerate(RENDERERS):
        ax[0].bar(x + (i - 1.5) * w, [m["view_change_median_s"][k] * 1e3 for m in meshes], w, label=LABELS[k],
                  color=colors[k])
    ax[0].set_yscale("log")
    ax[0].set_ylabel("ms per view change (median)")
    ax[0].set_title(f"Frame time per view change, {res['size'][0]}x{res['size'][1]}")
    ax[0].legend()
    for i, k in enumerate(("tetvr", "tetvr_projected", "tetvr_parity")):
        ax[1].bar(x + (i - 1.5) * w, [m["speedup_vs_vtk_pt"][k] for m in meshes], w, label=LABELS[k],
                  color=colors[k])
    if all("first_frame_vs_vtk_pt" in m for m in meshes):
        ax[1].bar(x + 1.5 * w, [m["first_frame_vs_vtk_pt"]["tetvr"] for m in meshes], w, color="white",
                  edgecolor=colors["tetvr"], hatch="///", label="tetvr default, first frame")
    inside = [(i, m["inside"]["speedup_vs_vtk_pt"]) for i, m in enumerate(meshes) if "inside" in m]
    if inside:
        ax[1].scatter([x[i] - 1.5 * w for i, _ in inside], [v for _, v in inside], marker="v", s=40, color="k",
                      zorder=4, label="tetvr default, view from inside")
    ax[1].axhline(1.0, color="k", lw=0.8)
    wanted = [(i, m["target"].get("speedup_wanted", TARGET["speedup"])) for i, m in enumerate(meshes)
              if m["target"]["applies"]]
    if wanted:  # each mesh's target for the default's view change, beside its bar
        ax[1].scatter([x[i] - 1.5 * w for i, _ in wanted], [v for _, v in wanted], marker="_", s=300, color="g",
                      linewidths=2.5, zorder=3, label=f"target per view change (>= {TARGET['min_tets'] // 1000}k tets)")
    ax[1].set_ylabel("VTK PT time / tetvr time  (>1: tetvr faster)")
    ax[1].set_title("Speed relative to VTK's projected tetra")
    top = max([m["speedup_vs_vtk_pt"][k] for m in meshes for k in ("tetvr", "tetvr_projected", "tetvr_parity")]
              + [v for _, v in wanted] + [v for _, v in inside]
              + [m.get("first_frame_vs_vtk_pt", {}).get("tetvr", 0.0) for m in meshes])
    ax[1].set_ylim(0, 1.5 * top)  # room above the bars for the legend
    ax[1].legend(loc="upper left", ncol=2, fontsize=8)
    for i, k in enumerate(RENDERERS):
        ax[2].bar(x + (i - 1.5) * w, [m["psnr"][k]["exact"] for m in meshes], w, label=LABELS[k], color=colors[k])
    ax[2].set_ylabel("PSNR vs exact reference (dB)")
    ax[2].set_title("Accuracy (premultiplied RGB)")
    top = max(m["psnr"][k]["exact"] for m in meshes for k in RENDERERS)
    ax[2].set_ylim(0, 1.45 * top)  # room above the bars for the legend
    ax[2].legend(loc="upper center", ncol=2, fontsize=8)
    for a in ax:
        a.set_xticks(x)
        a.set_xticklabels(names, fontsize=8)
    gl = res.get("gl_renderer", "")
    fig.suptitle(f"tetvr vs VTK {res.get('vtk_version', '?')} projected tetrahedra, same machine and GL ({gl}), "
                 "frames taken in turn", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------- where VTK's error comes from
def _anatomy_tfs(mesh: TetMesh) -> dict[str, Any]:
    """Three transfer functions: linear in the scalar (VTK's colour-at-vertex mapping is then
    exact), the default (viridis, 9 control points, constant opacity) and a spike."""
    lo, hi = mesh.scalar_range
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    q30, q60 = ((q - lo) / (hi - lo) for q in np.quantile(mesh.scalars, [0.3, 0.6]))
    return {
        "linear": tetvr.TransferFunction(color=((lo, 0.1, 0.2, 0.9), (hi, 1.0, 0.8, 0.1)),
                                         opacity=((lo, 0.2), (hi, 0.9)), unit_distance=diag / 20),
        "default": default_transfer_function(mesh, opacity=OPACITY),
        "spike": tetvr.TransferFunction.preset(
            "cool-to-warm", (lo, hi), unit_distance=diag / 20,
            opacity=[(0.0, 0.02), (q30 - 0.03, 0.05), (q30, 0.9), (q30 + 0.03, 0.05), (q60, 0.3), (1.0, 0.9)]),
    }


def _class2_bug() -> dict[str, Any]:
    """One tet seen so that two opposite edges cross off their midpoints (Shirley-Tuchman
    class 2), opacity varying along the second: VTK's mapper interpolates that edge's
    opacity with the first edge's parameter (alpha for beta), so its thick vertex is off."""
    pts = np.array([[-1, 0, 0.5], [1, 0, 0.5], [0, -0.3, -0.5], [0, 1.2, -0.5]], float)
    tf = tetvr.TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)), opacity=((0, 0.0), (1, 1.0)), unit_distance=1.0)
    out = {}
    for scalars in ([0, 0, 0, 1], [0, 0, 1, 0], [0, 0, 1, 1]):
        mesh = TetMesh.from_arrays(pts, [[0, 1, 2, 3]], scalars)
        cam = Camera.fit(mesh, direction=(0.001, 0.002, -1.0), parallel=True)
        with VTKProcess(mesh, tf, size=(64, 64)) as r:
            vtk = r.render(cam)
        ref = render_reference(mesh, cam, tf, (64, 64), optics="vtk")
        with tetvr.Renderer(PARITY_SETTINGS) as t:
            ours = quantize8(t.render(mesh, cam, tf, size=(64, 64)))
        out[str(scalars)] = {"centre_alpha": {"vtk_pt": float(vtk[32, 32, 3]), "reference_vtk": float(ref[32, 32, 3]),
                                              "tetvr_parity": float(ours[32, 32, 3])},
                             "psnr_vs_reference_vtk": {"vtk_pt": psnr(vtk, ref), "tetvr_parity": psnr(ours, ref)}}
    return out


def anatomy(name: str, mesh: TetMesh, size: tuple[int, int], out: Path) -> dict[str, Any]:
    """Split the error of VTK's projected tetrahedra into its causes, by PSNR between
    tetvr's references in each convention, VTK's image and tetvr's parity image."""
    rec: dict[str, Any] = {"mesh": name, "n_tets": mesh.n_tets, "size": list(size), "cases": {}}
    for tf_name, tf in _anatomy_tfs(mesh).items():
        for proj in ("perspective", "parallel"):
            cam = Camera.fit(mesh, parallel=proj == "parallel")
            refs = {o: render_reference(mesh, cam, tf, size, optics=o) for o in ("exact", "linear", "vtk")}
            with VTKProcess(mesh, tf, size=size) as r:
                vtk = r.render(cam)
            with tetvr.Renderer() as t:
                ours = t.render(mesh, cam, tf, size=size)
            with tetvr.Renderer(PARITY_SETTINGS) as t:
                parity = quantize8(t.render(mesh, cam, tf, size=size))
            cov = refs["exact"][..., 3] > 1 / 255
            case = {
                "convention: exact vs linear reference": psnr(refs["exact"], refs["linear"]),
                "colour averaging: linear vs vtk reference": psnr(refs["linear"], refs["vtk"]),
                "VTK PT vs reference in its own convention": psnr(vtk, refs["vtk"]),
                "VTK PT vs tetvr parity": psnr(vtk, parity),
                # Never PSNR alone: the largest channel difference (in 8-bit steps) and the pixels beyond one step.
                "VTK PT vs tetvr parity, max (1/255)": float(np.abs(vtk.astype(np.float64) - parity).max() * 255),
                "VTK PT vs tetvr parity, pixels beyond 1/255": int(
                    (np.abs(vtk.astype(np.float64) - parity).max(axis=-1) > 1.5 / 255).sum()),
                "tetvr parity vs vtk reference": psnr(parity, refs["vtk"]),
                "VTK PT vs exact reference": psnr(vtk, refs["exact"]),
                "tetvr vs exact reference": psnr(ours, refs["exact"]),
                "mean alpha over covered pixels": {"exact": float(refs["exact"][..., 3][cov].mean()),
                                                   "vtk_convention": float(refs["vtk"][..., 3][cov].mean()),
                                                   "vtk_pt": float(vtk[..., 3][cov].mean())},
            }
            rec["cases"][f"{tf_name}, {proj}"] = case
            print(f"  {tf_name:8s} {proj:11s} " + "  ".join(
                f"{v:5.1f}" for v in case.values() if isinstance(v, float)), flush=True)
            if proj == "perspective":
                _anatomy_picture(refs, vtk, ours, out / f"vs_vtk_anatomy_{tf_name}.png")
    rec["class2_opacity_bug"] = _class2_bug()
    return rec


def _anatomy_picture(refs: dict[str, np.ndarray], vtk: np.ndarray, ours: np.ndarray, path: Path) -> None:
    """Top: exact reference, reference in VTK's convention, VTK PT, tetvr. Bottom, x10:
    convention + averaging (vtk ref - exact), VTK's own error (PT - vtk ref), VTK's total
    error (PT - exact), tetvr's error (tetvr - exact)."""
    def diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        d = np.zeros_like(a)
        d[..., :3] = np.clip(np.abs(a[..., :3] - b[..., :3]) * 10.0, 0, 1)
        d[..., 3] = 1
        return d

    ex, vr = refs["exact"], refs["vtk"]
    tiles = [ex, vr, vtk, ours, diff(vr, ex), diff(vtk, vr), diff(vtk, ex), diff(ours, ex)]
    write_png(tile_images(tiles, cols=4), path, background=(0, 0, 0))


def _slug(name: str) -> str:
    """A mesh's picture name: its first word, and its size where the name gives one
    (``"torus by fTetWild, 1M (swirl)"`` -> ``torus_1M``)."""
    words = [name.split(" ")[0]] + ([name.split(", ")[1].split(" ")[0]] if ", " in name else [])
    return "_".join("".join(c if c.isalnum() else "_" for c in w).strip("_") for w in words)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help=f"meshes <= {QUICK_MAX_TETS} tets, 3 repeats")
    ap.add_argument("--repeats", type=int, default=None, help="timed view changes per mesh (default 5, quick 3)")
    ap.add_argument("--size", type=int, default=512, help="frame size (square)")
    ap.add_argument("--ref-size", type=int, default=None, help="size of the accuracy images (default: --size)")
    ap.add_argument("--step", type=float, default=3.0, help="degrees the camera turns per frame")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    ap.add_argument("--no-inside", action="store_true", help="leave out the views from inside the meshes")
    ap.add_argument("--first-frames", type=int, default=3,
                    help="first frames of the default and of VTK per mesh, the median reported (default 3)")
    ap.add_argument("--only", nargs="+", default=None, metavar="NAME",
                    help="run only the meshes whose names contain one of these, and put their records in "
                         "place of those in the existing JSON (each record has its own date and load)")
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--anatomy", action="store_true",
                    help="instead: split VTK's error into its causes (bluntfin, or cube(20) without the data), "
                         "at 256x256; writes vs_vtk_anatomy.json and vs_vtk_anatomy_<tf>.png")
    args = ap.parse_args(argv)
    ok, why = vtk_status()
    if not ok:
        print(f"VTK unavailable: {why}")
        return 2
    if args.anatomy:
        args.out.mkdir(parents=True, exist_ok=True)
        path = args.data / "bluntfin_tets.vtu"
        if path.exists():
            name, mesh = "bluntfin (Density)", load_quiet(path, "Density")
        else:
            name, mesh = "cube(20)", synthetic.cube(20)
        print(f"{name}: PSNR (dB) of: convention | colour averaging | VTK PT vs own-convention reference | "
              "VTK PT vs tetvr parity | tetvr parity vs reference | VTK PT vs exact | tetvr vs exact")
        rec = anatomy(name, mesh, (256, 256), args.out)
        rec.update(vtk_status=why, date=_dt.datetime.now().isoformat(timespec="seconds"))
        write_json(args.out / "vs_vtk_anatomy.json", rec)
        print(json.dumps(rec["class2_opacity_bug"], indent=1))
        return 0
    repeats = args.repeats or (3 if args.quick else 5)
    size = (args.size, args.size)
    ref_size = (args.ref_size or args.size,) * 2
    specs, notes = _mesh_specs(args.quick, args.data)
    if args.only:
        specs = [(name, load) for name, load in specs if any(o in name for o in args.only)]
    with tetvr.Renderer() as r:
        gl = r.gl_info.get("GL_RENDERER", "")
    res: dict[str, Any] = {
        "what": __doc__.split("\n\n")[0], "target": TARGET, "date": _dt.datetime.now().isoformat(timespec="seconds"),
        "size": list(size), "ref_size": list(ref_size), "repeats": repeats, "step_deg": args.step,
        "opacity": OPACITY, "tetvr_settings": RenderSettings().to_dict(), "parity_settings": PARITY_SETTINGS.to_dict(),
        "vtk_status": why, "vtk_version": why.split(",")[0].removeprefix("VTK "), "gl_renderer": gl,
        "machine": machine(), "loadavg_start": loadavg(), "notes": notes, "meshes": [],
        "fields": {"cpu_utilisation": "median CPU seconds per wall second of this process over the timed tetvr "
                                      "frames (llvmpipe rasterises on every core); VTK runs in a child process",
                   "vtk_timing": "VTK frames are timed inside the VTK process, from the camera change to the "
                                 "image read back into numpy, like tetvr's"},
    }
    suffix = "" if args.size == 512 else f"_{args.size}"  # 512x512 is the main table's size
    out_json = args.out / f"vs_vtk{suffix}.json"
    args.out.mkdir(parents=True, exist_ok=True)
    if args.only and out_json.exists():
        old = json.loads(out_json.read_text())
        res["meshes"], res["notes"] = kept_records(old, old["date"], [name for name, _ in specs], res["date"],
                                                   res["notes"])
    order = [name for name, _ in _mesh_specs(args.quick, args.data)[0]]
    try:
        for name, load in specs:
            mesh = load()
            print(f"{name}: {mesh.n_tets} tets ...", flush=True)
            start = {"date": _dt.datetime.now().isoformat(timespec="seconds"), "loadavg_start": loadavg()}
            rec, pics = bench_mesh(name, mesh, size, ref_size, repeats, args.step)
            if args.first_frames > 1:
                first_frames_again(rec, load, size, args.first_frames - 1)
                rec["target"] = target(name, mesh.n_tets, size, rec)
            if not args.no_inside:
                rec["inside"] = bench_inside(mesh, default_transfer_function(mesh, opacity=OPACITY), size, repeats)
            res["meshes"].append({**start, **rec})
            res["meshes"].sort(key=lambda m: order.index(m["name"]) if m["name"] in order else len(order))
            slug = _slug(name)
            _picture(pics, args.out / f"vs_vtk_{slug}{suffix}.png")
            write_json(out_json, res)
            del mesh, pics
    except KeyboardInterrupt:
        res["interrupted"] = True
    res["loadavg_end"] = loadavg()
    res["target_met_on_all_meshes"] = bool(res["meshes"]) and all(m["target"]["met"] for m in res["meshes"])
    write_json(out_json, res)
    print_table(res)
    plot(res, args.out / f"vs_vtk{suffix}.png")
    print(f"\nwrote {out_json} and {args.out / f'vs_vtk{suffix}.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

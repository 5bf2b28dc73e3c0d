"""Speed against accuracy: every tetvr method and setting, and VTK's three mappers, per scene.

Every scene is rendered by the exact CPU reference (:mod:`tetvr.reference`) once per image
size and, in the same run, by each tetvr variant (:func:`variant_groups`: the default, each
method and its main settings, grouped by what they change) and by VTK's unstructured-grid
mappers (``bench/peers.py``: projected tetrahedra, Bunyk ray cast, Z sweep, each in a child
process on the same OpenGL; real ParaView where installed). All renderers stay alive for
the scene and take frames **in turn**; every frame turns the camera by STEP_DEG about its
view-up axis, so each one is a view change (VTK re-sorts or re-casts, tetvr re-classifies or
re-marches). After the first frame (kept for accuracy) and one warm-up view change, each
renderer's median time per view change is recorded, from the camera change to the image in
numpy: as CPU time of the process that renders (``frame_s``; llvmpipe's threads and VTK's
included), which the other work on a shared machine inflates far less than wall time, and as
wall time (``frame_wall_s``).

Accuracy: each first frame against the reference, as RMSE and PSNR of premultiplied RGB and
the largest per-pixel error (with the mean error over covered pixels and the share of them
off by more than 1/255). A renderer is on the Pareto front when no other is at least as good
in frame time and error and better in one (5 % ties; errors below the rounding of a 16-bit
image tie too): ``pareto`` by RMSE (the PSNR chart), ``pareto_max`` by the largest error.

The stability cases (:mod:`tetvr.scene.stability`) and the imperfect-mesh classes
(``bench/imperfect.py``) are rendered by every variant and every VTK mapper at 96x96.

    python bench/speed_accuracy.py [--quick] [--sizes 512 1024] [--out bench/results]
    python bench/speed_accuracy.py --redraw      # summary and charts again from the JSON

Writes ``speed_accuracy.json`` (after every scene), the charts of ``bench/speed_charts.py``
(``speed_accuracy.png``: the summary; ``speed_accuracy_<scene>.png``; ``speed_accuracy_stability.png``),
``table_convergence.png`` and one picture per scene (default, weakest variant, reference).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import imperfect as imperfect_bench  # noqa: E402  (bench/imperfect.py: the imperfect-mesh classes)
import peers  # noqa: E402
import speed_charts  # noqa: E402
from _common import REAL_MESHES, TETS_DATA, load_quiet, loadavg, machine, timed_repeats, write_json  # noqa: E402

import tetvr  # noqa: E402
from tetvr import Camera, RenderSettings, TransferFunction  # noqa: E402
from tetvr.apps.vtkcompare import orbit  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402
from tetvr.optics.table import aligned_scalar_range, table_scalar_range  # noqa: E402
from tetvr.optics.tablesize import resolve as resolve_table_size  # noqa: E402
from tetvr.order.method import choose  # noqa: E402
from tetvr.order.sort import auto_method  # noqa: E402
from tetvr.reference.tets import render_reference  # noqa: E402
from tetvr.render import default_transfer_function  # noqa: E402
from tetvr.scene.stability import CASES, case  # noqa: E402
from tetvr.settings import PARITY_SETTINGS  # noqa: E402

DEFAULT = RenderSettings()
#: Degrees the camera turns between frames.
STEP_DEG = 2.0
#: Small scenes are timed for more rounds (until the default's frames add up to
#: MIN_TIMED_S), at most this many.
MAX_REPEATS = 12
#: A renderer whose frames take longer than this (wall) is timed over one view change ...
SLOW_FRAME_S = 10.0
#: ... and one whose first frame took longer than this, by that frame (its setup, a few
#: seconds, is then a few per cent of it; ``timed_by_first_frame`` in the JSON).
VERY_SLOW_FRAME_S = 90.0
#: The real meshes of the scenes (of _common.REAL_MESHES): the blunt fin's CFD grid and the
#: unstructured SimVascular FEM meshes. The combustor, as large as the blunt fin and also a
#: structured grid split into tets, is left out so that the run stays affordable on two cores
#: (bench/vs_vtk.py times it against VTK).
SCENE_MESHES = ("bluntfin_tets.vtu", "pipe_flow_init_flow.vtu", "beam_tet4_result_100.vtu")
#: The scenes also measured at the larger sizes (the run must stay affordable on two cores):
#: the two synthetic grids and the two SimVascular meshes (per-pixel costs grow 4x, per-cell
#: ones do not).
LARGE_SCENES = ("convex, close perspective", "cell data (4 levels)", "pipe_flow_init_flow.vtu",
                "beam_tet4_result_100.vtu")
#: The stability cases and imperfect-mesh classes are rendered at this size.
STABILITY_SIZE = (96, 96)
#: The methods the stability chart compares (tetvr's; VTK's three are added).
STABILITY_METHODS = ("default", "projected tetrahedra", "tet marching", "tet marching, no table (integration exact)")
#: The table-size sweep (``table_convergence`` in the JSON, at the first size): scalar bins N
#: and (slices K, log base) pairs from coarse to fine, each combination against the reference.
SWEEP_BINS = (128, 256, 512, 1024)
SWEEP_SLICES = ((8, 2.5), (16, 1.6), (24, 1.4), (32, 1.3), (48, 1.2))
#: ... skipping tables above this many entries N * N * K (the build's float64 temporaries
#: take ~100 bytes per entry).
SWEEP_MAX_ENTRIES = 1024 * 1024 * 16


def variant_groups() -> dict[str, dict[str, RenderSettings]]:
    """The tetvr variants, by what they change: the method, how a segment is integrated and
    composited, the table's size, the table's storage and nodes, and the visibility order
    (projected tetrahedra only). Each group has one marker in the charts."""
    r = dataclasses.replace
    return {
        "method": {"default": DEFAULT, "projected tetrahedra": r(DEFAULT, method="projected"),
                   "tet marching": r(DEFAULT, method="raymarch"), "VTK parity (optics=\"vtk\")": PARITY_SETTINGS},
        "integration": {
            "tet marching, no table (integration exact)": r(DEFAULT, method="raymarch", integration="exact"),
            "screen-linear interpolation": r(DEFAULT, perspective_correct=False),
            "uint8 framebuffer": r(DEFAULT, framebuffer="uint8"),
            "premultiplied, uint8, screen-linear (VTK-like)": r(
                DEFAULT, table_encoding="premultiplied", table_dtype="uint8", perspective_correct=False,
                framebuffer="uint8")},
        "table size": {"N=64": r(DEFAULT, table_scalar_bins=64), "N=512": r(DEFAULT, table_scalar_bins=512),
                       "K=8, base 2.5": r(DEFAULT, table_thickness_slices=8, table_log_base=2.5),
                       "fixed table N=256, K=16 (the 0.x default)": r(
                           DEFAULT, table_scalar_bins=256, table_thickness_slices=16, table_log_base=1.6,
                           table_align_nodes=False)},
        "table storage": {"premultiplied table": r(DEFAULT, table_encoding="premultiplied"),
                          "uint8 table": r(DEFAULT, table_dtype="uint8"),
                          "cubic thickness filter": r(DEFAULT, table_filter="cubic"),
                          "uniform table nodes": r(DEFAULT, table_align_nodes=False),
                          "even table nodes (table_warp off)": r(DEFAULT, table_warp="off")},
        "order": {f"sort={m}": r(DEFAULT, sort=m, method="projected") for m in ("centroid", "mpvonc", "xmpvo", "none")},
    }


def variants() -> dict[str, RenderSettings]:
    """All variants of :func:`variant_groups` in one dict, the default first."""
    return {key: s for group in variant_groups().values() for key, s in group.items()}


def _tf(mesh, opacity, units, preset="viridis"):
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    return TransferFunction.preset(preset, mesh.scalar_range, opacity=opacity, unit_distance=diag / units)


def scenes():
    m = synthetic.cube(8)
    yield "convex, close perspective", m, Camera.fit(m, direction=(-0.3, -0.2, -1.0), view_angle=60, zoom=1.6), \
        _tf(m, [(0, 0.2), (0.5, 0.6), (1, 0.9)], 4)
    r = synthetic.interlocking_rings(10, 1)
    yield "interlocking rings", r, Camera.fit(r, direction=(-0.5, -1.0, -0.6), view_up=(0, 0, 1)), \
        _tf(r, [(0, 0.9), (1, 0.9)], 6)
    c = case("camera_inside")
    yield "camera inside", c.mesh, c.camera, c.tf
    # Cell data: an element field, constant in each cell and jumping at faces (four levels
    # of a smooth field at the cells' centroids, as a material or stress-class map).
    g = synthetic.cube(16)
    x = g.centroids
    levels = np.floor(4.0 * (0.5 + 0.5 * np.sin(5.0 * x[:, 0]) * np.cos(4.0 * x[:, 1] + 2.0 * x[:, 2]))) / 4.0
    g = g.with_cell_scalars(levels, name="level")
    yield "cell data (4 levels)", g, Camera.fit(g, direction=(-0.6, -0.4, -1.0)), \
        _tf(g, [(0, 0.05), (0.5, 0.3), (1, 0.7)], 6)
    for name, field in REAL_MESHES:
        if name not in SCENE_MESHES:
            continue
        path = TETS_DATA / name
        if not path.is_file():
            print(f"skipping {name}: {path} not found")
            continue
        mesh = load_quiet(path, field)
        lo, hi = mesh.scalar_range
        q30, q60 = ((q - lo) / (hi - lo) for q in np.quantile(mesh.scalars, [0.3, 0.6]))
        op = [(0, 0.02), (q30 - 0.03, 0.05), (q30, 0.9), (q30 + 0.03, 0.05), (q60, 0.3), (1, 0.9)]
        yield name, mesh, Camera.fit(mesh, direction=(-1.0, -0.5, -0.7), zoom=1.2), _tf(mesh, op, 20, "cool-to-warm")
        # Isosurface-like: two opacity spikes 0.6 % of the range wide, nothing else (the
        # default warps its table's nodes to them, tetvr.optics.tablewarp).
        spikes = [(0, 0.0), (q30 - 0.003, 0.0), (q30, 0.9), (q30 + 0.003, 0.0), (q60 - 0.003, 0.0), (q60, 0.9),
                  (q60 + 0.003, 0.0), (1, 0.0)]
        yield f"{name}, spiky TF", mesh, Camera.fit(mesh, direction=(-1.0, -0.5, -0.7), zoom=1.2), \
            _tf(mesh, spikes, 20, "cool-to-warm")


def errors(img: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    d = np.abs(img[..., :3].astype(np.float64) - ref[..., :3]).max(axis=-1)
    covered = (ref[..., 3] > 1e-4) | (img[..., 3] > 1e-4)
    n = max(int(covered.sum()), 1)
    return {"rmse": tetvr.rmse(img, ref), "psnr": min(tetvr.psnr(img, ref), 200.0),
            "max_error": float(d.max()), "mean_error": float(d[covered].sum() / n),
            "pct_over_1_255": float(100.0 * np.sum(d[covered] > 1 / 255) / n)}


class TetvrFrames:
    """One tetvr variant rendering one scene view after view; times each frame."""

    def __init__(self, renderer: tetvr.Renderer, mesh, tf, size: tuple[int, int]) -> None:
        self.renderer, self.mesh, self.tf, self.size = renderer, mesh, tf, size
        self.last_wall = self.last_cpu = math.nan
        self.first_s: float | None = None

    def frame(self, camera: Camera) -> np.ndarray:
        c0, t0 = time.process_time(), time.perf_counter()
        image = self.renderer.render(self.mesh, camera, self.tf, size=self.size)
        self.last_wall, self.last_cpu = time.perf_counter() - t0, time.process_time() - c0
        return image


def time_frames(frames: dict[str, Any], camera: Camera, repeats: int) -> tuple[dict[str, dict[str, Any]], int]:
    """Each renderer's first image of ``camera`` and its frame times over view changes,
    renderers in turn, so that a change in the machine's load hits all alike.

    Each renderer is timed over ``repeats`` view changes, fast ones over more, until they add
    up to MIN_TIMED_S (at most MAX_REPEATS: with a handful of 5 ms frames, 5 % differences
    are chance); one whose warm-up took over SLOW_FRAME_S (wall) over one, and one whose first
    frame took over VERY_SLOW_FRAME_S by that frame. A renderer that fails is dropped and says
    why (``failed``)."""
    out: dict[str, dict[str, Any]] = {key: {"wall": [], "cpu": []} for key in frames}
    live = dict(frames)

    def take(key: str, cam: Camera) -> np.ndarray | None:
        try:
            return live[key].frame(cam)
        except peers.FAILURES as exc:
            out[key]["failed"] = f"{type(exc).__name__}: {exc}"
            del live[key]
            return None

    for key in list(live):
        t0 = time.perf_counter()
        image = take(key, camera)
        if image is not None:
            out[key]["image"] = image
            out[key]["first_frame_s"] = live[key].first_s or time.perf_counter() - t0
    warm = {}
    for key in list(live):  # one warm-up view change, but not for a renderer that is slow anyway
        if live[key].last_wall > VERY_SLOW_FRAME_S:
            out[key].update(wall=[live[key].last_wall], cpu=[live[key].last_cpu], timed_by_first_frame=True)
            del live[key]
        elif live[key].last_wall > SLOW_FRAME_S:
            warm[key] = live[key].last_wall
        elif take(key, orbit(camera, STEP_DEG)) is not None:
            warm[key] = live[key].last_wall
    need = {key: 1 if w > SLOW_FRAME_S else timed_repeats(w, repeats, MAX_REPEATS) for key, w in warm.items()}
    rounds = max(need.values(), default=0)
    for i in range(rounds):
        cam = orbit(camera, STEP_DEG * (i + 2))
        for key in list(live):
            if i >= need[key]:
                continue
            if take(key, cam) is not None:
                out[key]["wall"].append(live[key].last_wall)
                out[key]["cpu"].append(live[key].last_cpu)
    return out, rounds


def resolved(s: RenderSettings, mesh, tf, camera=None, image_size=None) -> RenderSettings:
    """The settings with ``method="auto"`` (for this view, where given: the cost model may
    choose by it), ``sort="auto"`` and an "auto" table size made concrete for this scene."""
    size = resolve_table_size(s, tf, mesh)
    # Aligned nodes that land where uniform ones do are the same table.
    rng = table_scalar_range(mesh.scalar_range, tf)
    align = s.table_align_nodes and aligned_scalar_range(rng, tf, size.n_bins) != rng
    return dataclasses.replace(s, method=choose(s, mesh, camera, image_size), sort=auto_method(mesh) if s.sort == "auto" else s.sort,
                               table_scalar_bins=size.n_bins, table_thickness_slices=size.n_slices,
                               table_log_base=round(size.log_base, 9), table_tolerance=1.0, table_align_nodes=align)


def same_as_default(vs: dict[str, RenderSettings], mesh, tf, camera=None, size=None) -> dict[str, str]:
    """Variants that are the default itself in this scene once ``method="auto"``,
    ``sort="auto"`` and the "auto" table size are resolved (e.g. ``tet marching`` where
    auto picks it, ``N=512`` where the auto size is 512 bins): timing them again only adds
    noise, and one of two identical settings would "beat" the other by chance."""
    mine = resolved(DEFAULT, mesh, tf, camera, size)
    why = (f"identical to the default here (method=auto picks {mine.method}, sort=auto {mine.sort}; the auto table is "
           f"N={mine.table_scalar_bins}, K={mine.table_thickness_slices})")
    return {key: why for key, s in vs.items() if key != "default" and resolved(s, mesh, tf, camera, size) == mine}


def table_times(vs, mesh, tf) -> dict[str, float]:
    """CPU seconds to size (an "auto" size: :mod:`tetvr.optics.tablesize`) and build each
    variant's pre-integration table, both paid again on every transfer-function change;
    uncached. (The mesh's segment sample is paid once per mesh, not per transfer
    function, and is not counted.)

    Sizing is timed per distinct setting (median of 3). The build's work depends only
    on the table's shape (N, K), encoding, storage and optics, so it is timed once per
    such shape, as the fastest of 3 builds: on this shared machine the same table took
    0.70-0.94 s from one build to the next, and variants that build the same shape
    (e.g. another log base) must not differ by that noise."""
    from tetvr.optics.preintegrate import build_table, table_for
    from tetvr.optics.tablesize import cache_clear, segment_sample

    segment_sample(mesh)
    sizing: dict[tuple, tuple[float, dict]] = {}
    builds: dict[tuple, float] = {}
    out = {}
    for key, st in vs.items():
        if st.integration == "exact" or st.optics == "vtk":  # no table / VTK's own per-vertex colours and table
            out[key] = 0.0
            continue
        sig = (st.table_scalar_bins, st.table_thickness_slices, st.table_log_base, st.table_tolerance,
               st.table_encoding, st.table_dtype, st.optics, st.table_align_nodes)
        if sig not in sizing:
            runs = []
            for _ in range(3):
                cache_clear()
                c0 = time.process_time()
                size = resolve_table_size(st, tf, mesh)
                runs.append(time.process_time() - c0)
            params = dict(n_bins=size.n_bins, n_slices=size.n_slices, log_base=size.log_base,
                          encoding=st.table_encoding, dtype=st.table_dtype, optics=st.optics)
            sizing[sig] = (statistics.median(runs), params)
        resolve_s, params = sizing[sig]
        shape = (params["n_bins"], params["n_slices"], params["encoding"], params["dtype"], params["optics"])
        if shape not in builds:
            # the renderer's exact inputs (its scalar range includes the node alignment)
            t = table_for(tf, mesh.scalar_range, mesh.max_edge, align_nodes=st.table_align_nodes, **params)
            runs = []
            for _ in range(3):
                c0 = time.process_time()
                build_table(tf, t.scalar_range, t.d_max, **params)
                runs.append(time.process_time() - c0)
            builds[shape] = min(runs)
        out[key] = resolve_s + builds[shape]
    return out


def table_sweep(mesh, camera, tf, size, ref) -> list[dict[str, float]]:
    """PSNR of every table size in SWEEP_BINS x SWEEP_SLICES (the default's other settings),
    and its uncached build time: where each scene's table error comes from."""
    from tetvr.optics.preintegrate import build_table

    out = []
    for n_bins in SWEEP_BINS:
        for k, base in SWEEP_SLICES:
            if n_bins * n_bins * k > SWEEP_MAX_ENTRIES:
                continue
            s = dataclasses.replace(DEFAULT, table_scalar_bins=n_bins, table_thickness_slices=k, table_log_base=base)
            with tetvr.Renderer(s) as r:
                img = r.render(mesh, camera, tf, size=size)
                t = r.table(mesh, tf)
            c0 = time.process_time()
            build_table(tf, t.scalar_range, t.d_max, n_bins=n_bins, n_slices=k, log_base=base,
                        encoding=s.table_encoding, dtype=s.table_dtype, optics=s.optics)
            out.append({"n_bins": n_bins, "n_slices": k, "log_base": base, "table_s": time.process_time() - c0,
                        "table_mib": n_bins * n_bins * (k + 1) * 16 / 2**20, **errors(img, ref)})
    return out


#: Two errors below this RMSE tie: the rounding noise of the finest integer image a
#: user can write (16 bits: a step of 1/65535, rounding error uniform in half a step
#: either way, so RMSE = 1/(65535 * sqrt(12)) = 4.4e-6, 107.1 dB). Below it two
#: renderings cannot be told apart in any written image, as frame times within 5 % cannot
#: be told apart on this machine. ``pareto_strict`` in the JSON is the front without it.
ERROR_FLOOR = 1.0 / (65535.0 * 12.0 ** 0.5)
#: The same for the largest per-pixel error: half a 16-bit step, the most rounding moves a pixel.
MAX_ERROR_FLOOR = 0.5 / 65535.0


def pareto(points: list[tuple[float, ...]], tol: float = 0.05) -> list[bool]:
    """True where no other point is no worse in every coordinate and better in one, both
    by more than ``tol`` (relative): times within 5 % are a tie on a shared machine.

    The coordinates are costs, e.g. (frame time per view change, RMSE), the chart's front,
    or (frame time, table build time per transfer-function change, RMSE); pass errors
    through :func:`error_cost` for the output-precision tie.

    >>> pareto([(1.0, 2.0), (1.02, 1.0), (0.5, 3.0), (2.0, 2.0)])
    [False, True, True, False]
    """
    def dominates(a, b):
        no_worse = all(x <= y * (1 + tol) for x, y in zip(a, b))
        better = any(x < y * (1 - tol) for x, y in zip(a, b))
        return no_worse and better

    return [not any(dominates(q, p) for q in points if q is not p) for p in points]


def error_cost(rmse: float) -> float:
    """The error as a Pareto cost: RMSE, with every error below :data:`ERROR_FLOOR` a tie."""
    return max(rmse, ERROR_FLOOR)


def mark_fronts(rows: dict[str, dict[str, Any]]) -> None:
    """Set the Pareto flags of every row that was timed: ``pareto`` (frame time, RMSE),
    ``pareto_max`` (frame time, largest error), ``pareto_strict`` (without the error floor),
    and, among tetvr's variants, ``pareto_with_table`` (frame time, table time, RMSE)."""
    keys = [k for k, r in rows.items() if "frame_s" in r]
    fronts = {"pareto": [(rows[k]["frame_s"], error_cost(rows[k]["rmse"])) for k in keys],
              "pareto_max": [(rows[k]["frame_s"], max(rows[k]["max_error"], MAX_ERROR_FLOOR)) for k in keys],
              "pareto_strict": [(rows[k]["frame_s"], rows[k]["rmse"]) for k in keys]}
    for flag, points in fronts.items():
        for k, on in zip(keys, pareto(points)):
            rows[k][flag] = on
    mine = [k for k in keys if "table_s" in rows[k]]
    points = [(rows[k]["frame_s"], rows[k]["table_s"], error_cost(rows[k]["rmse"])) for k in mine]
    for k, on in zip(mine, pareto(points)):
        rows[k]["pareto_with_table"] = on


def measure_scene(mesh, cam, tf, size, vs, renderers, repeats, with_peers) -> tuple[dict[str, Any], dict, np.ndarray]:
    """One scene at one size: the reference, every variant not identical to the default
    here, and the VTK peers, timed in turn; their rows, images and the reference."""
    t0 = time.perf_counter()
    ref = render_reference(mesh, cam, tf, size)
    ref_s = time.perf_counter() - t0
    dup = same_as_default(vs, mesh, tf, cam, size)
    frames: dict[str, Any] = {k: TetvrFrames(renderers[k], mesh, tf, size) for k in vs if k not in dup}
    started, peer_failed = peers.open_peers(mesh, tf, size) if with_peers else ({}, {})
    try:
        timing, rounds = time_frames({**frames, **started}, cam, repeats)
        info = {k: p.info for k, p in started.items()}
    finally:
        for p in started.values():
            p.release()
    tables = table_times({k: vs[k] for k in frames}, mesh, tf)
    rows: dict[str, dict[str, Any]] = {}
    images = {}
    for key, t in timing.items():
        row: dict[str, Any] = {"failed": t["failed"]} if "failed" in t else {}
        if t["wall"]:
            row.update(frame_s=statistics.median(t["cpu"]), frame_wall_s=statistics.median(t["wall"]),
                       frames_timed=len(t["wall"]), first_frame_s=t["first_frame_s"])
            if t.get("timed_by_first_frame"):
                row["timed_by_first_frame"] = True
        if "image" in t:
            images[key] = t["image"]
            row.update(errors(t["image"], ref))
        if key in tables:
            row["table_s"] = tables[key]
        rows[key] = row
    rows.update({k: {"failed": why} for k, why in peer_failed.items()})
    mark_fronts(rows)
    auto = resolve_table_size(DEFAULT, tf, mesh)
    rec = {"n_tets": mesh.n_tets, "size": list(size), "reference_s": ref_s, "rounds": rounds,
           "auto_table": {**dataclasses.asdict(auto), "error": auto.error},
           "variants": {k: r for k, r in rows.items() if k in vs},
           "peers": {k: {**r, **info.get(k, {})} for k, r in rows.items() if k not in vs},
           "same_as_default": dup}
    return rec, images, ref


def stability(vs, renderers, with_peers, out: dict[str, dict[str, Any]], save) -> None:
    """Every stability case at STABILITY_SIZE not yet in ``out``: each variant's and each VTK
    mapper's errors, into ``out``, calling ``save()`` after each case."""
    for name in sorted(CASES):
        if name in out:  # --resume
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            c = case(name)
        ref = render_reference(c.mesh, c.camera, c.tf, STABILITY_SIZE)
        rec: dict[str, Any] = {}
        for key in vs:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    image = renderers[key].render(c.mesh, c.camera, c.tf, size=STABILITY_SIZE)
            except ValueError as exc:  # tet marching refuses a mesh it cannot walk (tangled slivers)
                rec[key] = {"psnr": None, "refused": str(exc)}
                continue
            rec[key] = errors(image, ref)
        if with_peers:
            for key, (image,) in peers.peer_images(c.mesh, c.tf, [c.camera], STABILITY_SIZE).items():
                rec[key] = {"psnr": None, "failed": image} if isinstance(image, str) else errors(image, ref)
        out[name] = rec
        save()
        print(f"  stability {name:20s} default max {rec['default'].get('max_error', float('nan')):.1e}"
              + "".join(f", {k} {rec[k].get('max_error', float('nan')):.1e}" for k in peers.PEERS if k in rec),
              flush=True)


def imperfect(renderers, with_peers, data: Path, rows: list[dict[str, Any]], save) -> None:
    """Every view of every imperfect-mesh case (bench/imperfect.py) at STABILITY_SIZE not yet
    in ``rows``, by STABILITY_METHODS and the VTK mappers, against ``method="reference"``;
    appended to ``rows``, calling ``save()`` after each case."""
    done = {(r["class"], r["mesh"]) for r in rows}
    for cls, label, build, cameras in imperfect_bench.cases(data):
        if (cls, label) in done:  # --resume
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mesh = build()
        tf = default_transfer_function(mesh)
        cams = [make(mesh) for make in cameras]
        vtk = peers.peer_images(mesh, tf, cams, STABILITY_SIZE) if with_peers else {}
        for k, cam in enumerate(cams):
            ref = tetvr.render(mesh, camera=cam, tf=tf, size=STABILITY_SIZE, method="reference")
            row: dict[str, Any] = {"class": cls, "mesh": label, "view": k, "n_tets": mesh.n_tets, "methods": {}}
            for key in STABILITY_METHODS:
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        image = renderers[key].render(mesh, cam, tf, size=STABILITY_SIZE)
                except ValueError as exc:
                    row["methods"][key] = {"refused": str(exc)}
                    continue
                row["methods"][key] = errors(image, ref)
            for key, images in vtk.items():
                image = images[k]
                row["methods"][key] = {"failed": image} if isinstance(image, str) else errors(image, ref)
            rows.append(row)
            print(f"  imperfect {cls:30s} {label:34s} view {k}: " + ", ".join(
                f"{key[:14]} {m.get('max_error', float('nan')):.1e}" for key, m in row["methods"].items()),
                flush=True)
        save()


def summarize(report: dict[str, Any]) -> dict[str, Any]:
    """Per image size, each renderer over the scenes: its frame time relative to the
    default's (geometric mean of the per-scene ratios), the median and the worst of its
    largest per-pixel error and of its PSNR, the scenes where it is on the Pareto front, and
    whether it is on the front of these summary points. A variant identical to the default in
    a scene counts there with the default's numbers."""
    out: dict[str, Any] = {}
    keys = list(report["variants"]) + list(peers.PEERS)
    for label, scenes in speed_charts.runs(report).items():
        per: dict[str, dict[str, Any]] = {}
        for key in keys:
            ratios, maxes, psnrs, front, same = [], [], [], 0, 0
            for rec in scenes.values():
                d = rec["variants"]["default"]
                row = rec["variants"].get(key) or rec["peers"].get(key)
                if row is None and key in rec["same_as_default"]:
                    row, same = d, same + 1
                if not row or "frame_s" not in row or "frame_s" not in d:
                    continue
                ratios.append(row["frame_s"] / d["frame_s"])
                maxes.append(row["max_error"])
                psnrs.append(row["psnr"])
                front += bool(row.get("pareto_max"))
            if ratios:
                per[key] = {"time_ratio": math.exp(statistics.fmean(math.log(r) for r in ratios)),
                            "max_error_median": statistics.median(maxes), "max_error_worst": max(maxes),
                            "psnr_median": statistics.median(psnrs), "psnr_worst": min(psnrs),
                            "n_scenes": len(ratios), "same_as_default": same, "on_front_max": front}
        keys_here = list(per)
        by_max = pareto([(per[k]["time_ratio"], max(per[k]["max_error_median"], MAX_ERROR_FLOOR)) for k in keys_here])
        by_psnr = pareto([(per[k]["time_ratio"], error_cost(10 ** (-per[k]["psnr_median"] / 20))) for k in keys_here])
        for k, a, b in zip(keys_here, by_max, by_psnr):
            per[k].update(pareto_max=a, pareto=b)
        out[label] = {"scenes": list(scenes), "renderers": per}
    return out


def _worst(recs: list[dict[str, Any] | None]) -> dict[str, Any]:
    recs = [r for r in recs if r is not None]
    rendered = [r["max_error"] for r in recs if "max_error" in r]
    why = next((r.get("refused") or r.get("failed") for r in recs if "max_error" not in r), None)
    return {"max_error": max(rendered) if rendered else None, "of": len(recs),
            "refused": sum("refused" in r for r in recs), "failed": sum("failed" in r for r in recs),
            **({"why": why[:300]} if why else {})}


def stability_summary(report: dict[str, Any]) -> list[dict[str, Any]]:
    """Per failure class (each stability case; each imperfect-mesh class over its meshes and
    views) and method: the largest per-pixel error, and how many of its views were refused
    (tetvr says why) or failed (VTK)."""
    methods = STABILITY_METHODS + tuple(peers.PEERS)
    out = [{"name": name, "kind": "stability case", "views": 1,
            "methods": {m: _worst([rec.get(m)]) for m in methods}}
           for name, rec in sorted(report.get("stability", {}).items())]
    by_class: dict[str, list[dict[str, Any]]] = {}
    for row in report.get("imperfect", []):
        by_class.setdefault(row["class"], []).append(row)
    for cls, rows in by_class.items():
        out.append({"name": cls, "kind": "imperfect mesh", "views": len(rows),
                    "meshes": sorted({r["mesh"] for r in rows}),
                    "methods": {m: _worst([r["methods"].get(m) for r in rows]) for m in methods}})
    return out


def _new_report(args: argparse.Namespace, vs: dict[str, RenderSettings], with_peers: bool, vtk_why: str) -> dict:
    sizes = [[s, s] for s in args.sizes]
    large = [s for s in args.sizes[1:]]
    return {
        "what": __doc__.split("\n\n")[0], "created": time.strftime("%Y-%m-%dT%H:%M:%S"), "sizes": sizes,
        "size": sizes[0], "repeats": args.repeats, "repeats_larger_sizes": args.large_repeats,
        "max_repeats": MAX_REPEATS, "slow_frame_s": SLOW_FRAME_S, "very_slow_frame_s": VERY_SLOW_FRAME_S,
        "step_deg": STEP_DEG,
        "subsample": (f"all scenes at {args.sizes[0]}x{args.sizes[0]}" + "".join(
            f"; at {s}x{s} only {', '.join(args.large_scenes)}" for s in large)
            + " (the run stays affordable on this machine's cores); the combustor of _common.REAL_MESHES is left out"),
        "timing": "per view change, camera change to image in numpy, renderers in turn, medians: frame_s is the "
                  "CPU time of the process that renders (tetvr's, or VTK's child process; all threads, llvmpipe's "
                  "included), frame_wall_s the wall time",
        "machine": machine(), "loadavg_start": loadavg(), "stability_size": list(STABILITY_SIZE),
        "variants": {k: dataclasses.asdict(s) for k, s in vs.items()},
        "groups": {k: g for g, members in variant_groups().items() for k in members},
        "peers": {"vtk": vtk_why, "measured": with_peers, "labels": peers.LABELS,
                  "classes": {k: peers.MAPPERS[m][0] for k, m in peers.PEERS.items()}},
        "paraview": peers.paraview_status(), "scenes": {}, "scenes_at": {f"{s}x{s}": {} for s in large},
        "stability": {}, "imperfect": []}


def _run_scenes(report, args, vs, renderers, with_peers, path: Path, out: Path, sizes: list[int]) -> None:
    """Measure every scene at each of ``sizes`` (the larger sizes: LARGE_SCENES only) that the
    report does not hold yet, writing the JSON after each."""
    primary = args.sizes[0]
    for s in sizes:
        for name, mesh, cam, tf in scenes():
            if (args.only and name not in args.only) or (s != primary and name not in args.large_scenes):
                continue
            slot = report["scenes"] if s == primary else report["scenes_at"][f"{s}x{s}"]
            if name in slot:  # --resume
                continue
            t0 = time.perf_counter()
            repeats = args.repeats if s == primary else args.large_repeats
            rec, images, ref = measure_scene(mesh, cam, tf, (s, s), vs, renderers, repeats, with_peers)
            if s == primary:
                if args.sweep:
                    rec["table_convergence"] = table_sweep(mesh, cam, tf, (s, s), ref)
                weak = images.get("premultiplied, uint8, screen-linear (VTK-like)", images["default"])
                _picture(out, name, images["default"], weak, ref)
            rec["elapsed_s"] = time.perf_counter() - t0  # the whole scene: reference, frames, tables, sweep
            rec["loadavg"] = loadavg()
            slot[name] = rec
            write_json(path, report)
            d = rec["variants"]["default"]
            print(f"{name:34s} {s}x{s} {mesh.n_tets:7d} tets ({rec['elapsed_s']:.0f} s, reference "
                  f"{rec['reference_s']:.0f} s, {rec['rounds']} rounds)  default {d['frame_s'] * 1e3:7.1f} ms "
                  f"max {d['max_error']:.1e} PSNR {d['psnr']:6.1f} dB" + "".join(
                      f" | {k} {p['frame_s'] * 1e3:.0f} ms max {p['max_error']:.1e} {p['psnr']:.1f} dB"
                      if "frame_s" in p else f" | {k} failed" for k, p in rec["peers"].items()), flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="256x256, 2 repeats, no larger sizes")
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 1024],
                    help="square image sizes: every scene at the first, LARGE_SCENES at the others")
    ap.add_argument("--large-scenes", nargs="*", default=list(LARGE_SCENES))
    ap.add_argument("--repeats", type=int, default=3, help="timed view changes at least (small scenes get more)")
    ap.add_argument("--large-repeats", type=int, default=2, help="the same at the larger sizes")
    ap.add_argument("--only", nargs="*", help="measure only these scenes (and no stability cases)")
    ap.add_argument("--no-peers", action="store_true", help="tetvr only")
    ap.add_argument("--sweep", action="store_true", help="also the table-size sweep (table_convergence.png)")
    ap.add_argument("--resume", action="store_true", help="keep what the JSON already holds at the same sizes")
    ap.add_argument("--redraw", action="store_true", help="only the summary and the charts, from the JSON")
    ap.add_argument("--data", type=Path, default=TETS_DATA, help="the real meshes of the imperfect-mesh classes")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = ap.parse_args(argv)
    if args.quick:
        args.sizes, args.repeats = [256], 2
    out, path = args.out, args.out / "speed_accuracy.json"
    if args.redraw:
        report = json.loads(path.read_text())
        _finish(report, path, out)
        return 0
    vs = variants()
    ok, vtk_why = (False, "not measured (--no-peers)") if args.no_peers else peers.vtk_available()
    with_peers = ok
    report = _new_report(args, vs, with_peers, vtk_why)
    if args.resume and path.is_file():
        old = json.loads(path.read_text())
        if old.get("sizes") == report["sizes"]:
            for key in ("scenes", "scenes_at", "stability", "imperfect", "created", "loadavg_start"):
                report[key] = old.get(key, report[key])
            report["resumed"] = old.get("resumed", []) + [time.strftime("%Y-%m-%dT%H:%M:%S")]
    out.mkdir(parents=True, exist_ok=True)
    renderers = {key: tetvr.Renderer(s) for key, s in vs.items()}
    try:
        report["gl"] = renderers["default"].gl_info
        # The first size, the failure classes, then the larger sizes (the most expensive part last).
        _run_scenes(report, args, vs, renderers, with_peers, path, out, args.sizes[:1])
        if not args.only:
            def save() -> None:
                write_json(path, report)

            stability(vs, renderers, with_peers, report["stability"], save)
            imperfect(renderers, with_peers, args.data, report["imperfect"], save)
        _run_scenes(report, args, vs, renderers, with_peers, path, out, args.sizes[1:])
    except KeyboardInterrupt:
        report["interrupted"] = True
        print("interrupted: writing what was measured")
    finally:
        for r in renderers.values():
            r.release()
    report["loadavg_end"] = loadavg()
    _finish(report, path, out)
    return 0


def _finish(report: dict[str, Any], path: Path, out: Path) -> None:
    report["summary"] = summarize(report)
    report["stability_summary"] = stability_summary(report)
    write_json(path, report)
    written = speed_charts.draw_all(report, out)
    if any(rec.get("table_convergence") for rec in report["scenes"].values()):
        written.append(out / "table_convergence.png")
        speed_charts.sweep_chart(report, written[-1])
    print("wrote " + ", ".join(str(p) for p in [path, *written]))


def _picture(out: Path, name: str, default: np.ndarray, weak: np.ndarray, ref: np.ndarray) -> None:
    slug = "".join(ch if ch.isalnum() else "_" for ch in name)[:30]
    tetvr.write_png(np.concatenate([default, weak, ref], axis=1), out / f"scene_{slug}.png", background=(0, 0, 0))


if __name__ == "__main__":
    raise SystemExit(main())

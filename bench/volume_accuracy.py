"""The volume ray caster's speed against its accuracy: defaults and finer settings on real volumes.

Every scene (CT head, MR head, the aneurism; the CT head with a spiky transfer function)
is rendered by the CPU reference at fine settings (1/16-voxel pieces, also cut at the
voxel-index planes, exact integration, no early termination) and by the GPU ray caster
with its defaults and with coarser and finer settings; for each variant we record the
median frame time (wall, after a warm-up; variants interleaved round by round, since
llvmpipe's timings follow the load of the shared cores) and its error against the
reference: PSNR on premultiplied RGB, the max per-pixel error and the number of pixels
off by more than 1/255. With ``--baseline TREE`` the defaults of another checkout (e.g.
``git archive`` of the commit before the volume caster's "auto" sizing) are measured
against the same references, in a subprocess, in the same run.

    python bench/volume_accuracy.py [--size 96] [--repeats 5] [--baseline TREE] [--out bench/results]

Writes ``volume_accuracy.json`` and ``volume_accuracy.png`` (time against error, one panel
per scene and mode). Needs ``../shared/data/volumes``; scenes whose file is missing are skipped.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _common import SHARED_DATA, loadavg, machine, write_json  # noqa: E402

#: Pieces of the reference, in voxels of the smallest spacing.
REFERENCE_STEP = 1.0 / 16


def _camera(vol: Any, direction: tuple[float, float, float], up: tuple[float, float, float] = (0, 0, 1)) -> Any:
    from tetvr import Camera

    c, r = vol.center, vol.diagonal / 2
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    dist = r / math.sin(math.radians(15))
    return Camera(position=tuple(c - d * dist), focal_point=tuple(c), view_up=up, view_angle=30.0,
                  clipping_range=(dist - 1.5 * r, dist + 1.5 * r))


def scenes() -> dict[str, tuple[Any, Any, Any, tuple[str, ...]]]:
    """name -> (volume, transfer function, camera, modes); only the TransferFunction,
    Camera and read_volume of tetvr are used, so an older checkout runs them too."""
    from tetvr import TransferFunction
    from tetvr.io.volume_file import read_volume as read

    def read_volume(path: Path) -> Any:
        try:
            return read(path)
        except ImportError as exc:  # an optional reader (SimpleITK) is missing
            print(f"skipping {path.name}: {exc}")
            return None

    out: dict[str, tuple[Any, Any, Any, tuple[str, ...]]] = {}
    vols = SHARED_DATA / "volumes"
    both = ("emission_absorption", "mip")
    ct = read_volume(vols / "headsq" / "quarter.nhdr") if (vols / "headsq" / "quarter.nhdr").is_file() else None
    if ct is not None:  # int16, 0..3926
        cam = _camera(ct, (-0.3, 1.0, -0.4), up=(0, 0, -1))
        out["CT head"] = (ct, TransferFunction(
            color=((0, 0.2, 0.1, 0.05), (600, 0.9, 0.5, 0.3), (1200, 1, 0.9, 0.8), (3926, 1, 1, 1)),
            opacity=((0, 0), (500, 0), (700, 0.3), (1000, 0.05), (1150, 0.0), (1300, 0.6), (3926, 0.9)),
            unit_distance=10.0), cam, both)
        out["CT head, spiky TF"] = (ct, TransferFunction(
            color=((0, 0.2, 0.1, 0.05), (700, 0.9, 0.5, 0.3), (1200, 1, 0.9, 0.8), (3926, 1, 1, 1)),
            opacity=((0, 0), (1123, 0), (1143, 0.6), (1163, 0.0), (3926, 0.0)), unit_distance=5.0),
            cam, ("emission_absorption",))
    mr = read_volume(vols / "HeadMRVolume.mhd") if (vols / "HeadMRVolume.mhd").is_file() else None
    if mr is not None:  # uint8
        out["MR head"] = (mr, TransferFunction(
            color=((0, 0, 0, 0), (60, 0.6, 0.4, 0.3), (140, 1, 0.8, 0.7), (255, 1, 1, 1)),
            opacity=((0, 0), (40, 0), (90, 0.15), (160, 0.4), (255, 0.8)), unit_distance=8.0),
            _camera(mr, (0.8, -1.0, 0.3)), both)
    an = read_volume(vols / "aneurism.vti") if (vols / "aneurism.vti").is_file() else None
    if an is not None:  # uint8, 256^3
        out["aneurism"] = (an, TransferFunction(
            color=((0, 0.8, 0.2, 0.1), (100, 0.9, 0.4, 0.2), (255, 1, 1, 0.9)),
            opacity=((0, 0), (40, 0), (120, 0.5), (255, 0.9)), unit_distance=2.0),
            _camera(an, (1.2, 0.8, 1.6)), both)
    return out


def variants(mode: Any, voxel: float) -> dict[str, Any]:
    """Settings to compare: the defaults first."""
    from tetvr import RaycastSettings

    d = RaycastSettings(mode=mode)
    if mode == "mip":
        return {"default": d, "step 1/2 voxel": dataclasses.replace(d, step=voxel / 2),
                "step 1/16 voxel": dataclasses.replace(d, step=voxel / 16)}
    return {"default": d,
            "table": dataclasses.replace(d, integration="table"),
            "exact": dataclasses.replace(d, integration="exact"),
            "coarse (1/2 voxel, 256 bins, termination 0.99)": dataclasses.replace(
                d, step=voxel / 2, table_scalar_bins=256, integration="table", termination_tolerance=0.01),
            "fine (1/8 voxel, exact, no termination)": dataclasses.replace(
                d, step=voxel / 8, integration="exact", termination_tolerance=0.0)}


def errors(img: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    from tetvr.core.image import psnr

    d = np.abs(img.astype(np.float64) - ref).max(axis=-1)
    return {"psnr": psnr(img, ref), "max_error": float(d.max()), "pixels_beyond_1_255": int((d > 1 / 255).sum()),
            "covered_pixels": int((ref[..., 3] > 1e-3).sum())}


def _timed(rc: Any, jobs: dict[str, tuple], size: tuple[int, int], repeats: int) -> tuple[dict, dict]:
    """Median wall time of each job's frame, rounds interleaved. Each job has its own
    Raycaster on ``rc``'s context, so its volume texture and table stay cached as in an
    application that keeps its settings (one Raycaster alternating settings would upload
    a table every frame)."""
    from tetvr.gl.raycaster import Raycaster

    casters = {k: Raycaster(ctx=rc.ctx) for k in jobs}
    images: dict[str, np.ndarray] = {}
    times: dict[str, list[float]] = {k: [] for k in jobs}
    try:
        for k, (vol, cam, tf, s) in jobs.items():  # warm-up: upload, table, program
            images[k] = casters[k].render(vol, cam, tf, size=size, settings=s)
        for _ in range(repeats):
            for k, (vol, cam, tf, s) in jobs.items():
                t0 = time.perf_counter()
                casters[k].render(vol, cam, tf, size=size, settings=s)
                times[k].append(time.perf_counter() - t0)
    finally:
        for c in casters.values():
            c.release()
    return images, {k: statistics.median(v) for k, v in times.items()}


_BASELINE = r"""
import importlib.util, json, os, sys, numpy as np
sys.path.insert(0, os.path.dirname(sys.argv[1]))  # _common
spec = importlib.util.spec_from_file_location("va", sys.argv[1]); va = importlib.util.module_from_spec(spec)
spec.loader.exec_module(va)
sys.path.remove(str(va.ROOT))  # the checkout under test comes from PYTHONPATH, not this one
from tetvr import RaycastSettings
from tetvr.gl.raycaster import Raycaster
size = (int(sys.argv[2]), int(sys.argv[2])); repeats = int(sys.argv[3]); out = {}
with Raycaster() as rc:
    for name, (vol, tf, cam, modes) in va.scenes().items():
        jobs = {f"{name}|{m}": (vol, cam, tf, RaycastSettings(mode=m)) for m in modes}  # one Raycaster each (_timed)
        images, times = va._timed(rc, jobs, size, repeats)
        for k in jobs:
            np.save(f"{sys.argv[4]}/{len(out)}.npy", images[k]); out[k] = [times[k], f"{len(out)}.npy"]
json.dump(out, open(f"{sys.argv[4]}/times.json", "w"))
"""


def baseline(tree: Path, size: int, repeats: int) -> dict[str, tuple[np.ndarray, float]]:
    """The defaults of the checkout ``tree``: key "scene|mode" -> (image, frame seconds)."""
    check = subprocess.run([sys.executable, "-c", "import tetvr; print(tetvr.__file__)"], capture_output=True,
                           text=True, check=True, env=dict(os.environ, PYTHONPATH=str(tree)), cwd=tree)
    if not Path(check.stdout.strip()).resolve().is_relative_to(tree):
        raise RuntimeError(f"--baseline {tree}: python imports tetvr from {check.stdout.strip()} there, not from it")
    with tempfile.TemporaryDirectory() as tmp:
        print(f"measuring the defaults of {tree} ...", flush=True)
        subprocess.run([sys.executable, "-c", _BASELINE, str(Path(__file__).resolve()), str(size), str(repeats), tmp],
                       check=True, env=dict(os.environ, PYTHONPATH=str(tree)), cwd=tree)
        runs = json.loads((Path(tmp) / "times.json").read_text())
        return {k: (np.load(Path(tmp) / f), t) for k, (t, f) in runs.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=96)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--baseline", type=Path, default=None, help="a checkout whose defaults to measure too")
    ap.add_argument("--baseline-name", default="before")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    from tetvr import RaycastSettings
    from tetvr.gl.raycaster import Raycaster
    from tetvr.reference.volume import render_volume_reference

    size = (args.size, args.size)
    found = scenes()
    if not found:
        print(f"no volumes in {SHARED_DATA / 'volumes'}: nothing to measure")
        return 1
    base = baseline(args.baseline.resolve(), args.size, args.repeats) if args.baseline else {}
    report: dict[str, Any] = {"created": time.strftime("%Y-%m-%dT%H:%M:%S"), "size": list(size),
                              "reference_step_voxels": REFERENCE_STEP, "repeats": args.repeats,
                              "machine": machine(), "loadavg_before": loadavg(), "scenes": []}
    with Raycaster() as rc:
        report["gl"] = rc.gl_info
        for name, (vol, tf, cam, modes) in found.items():
            voxel = float(vol.spacing.min())
            for mode in modes:

                t0 = time.perf_counter()
                # The full integral: the reference stops rays early by the settings' rule too.
                fine = RaycastSettings(mode=mode, termination_tolerance=0.0)  # type: ignore[arg-type]
                ref = render_volume_reference(vol, cam, tf, size, settings=fine, fine_step=voxel * REFERENCE_STEP)
                ref_s = time.perf_counter() - t0
                vs = variants(mode, voxel)
                images, times = _timed(rc, {k: (vol, cam, tf, s) for k, s in vs.items()}, size, args.repeats)
                rows = {}
                for k, s in vs.items():
                    rows[k] = {"frame_s": times[k], **errors(images[k], ref),
                               "step_voxels": s.step_for(vol, tf) / voxel}
                    if mode == "emission_absorption":
                        rows[k]["integration"] = s.integration_for(vol, tf)
                        if rows[k]["integration"] == "table":
                            rows[k]["table_scalar_bins"] = s.bins_for(vol, tf)
                if f"{name}|{mode}" in base:
                    img, t = base[f"{name}|{mode}"]
                    rows[args.baseline_name] = {"frame_s": t, **errors(img, ref)}
                report["scenes"].append({"scene": name, "mode": mode, "dims": list(vol.dims), "dtype": str(vol.dtype),
                                         "reference_s": ref_s, "variants": rows})
                for k, r in rows.items():
                    print(f"{name:18s} {mode:20s} {k:48s} {r['psnr']:6.1f} dB  max {r['max_error']:.4f}  "
                          f"{r['pixels_beyond_1_255']:4d} px > 1/255  {r['frame_s'] * 1e3:7.1f} ms", flush=True)
    report["loadavg_after"] = loadavg()
    out = Path(args.out)
    write_json(out / "volume_accuracy.json", report)
    _chart(report, out / "volume_accuracy.png")
    print(f"wrote {out / 'volume_accuracy.json'}")
    return 0


def _chart(report: dict[str, Any], path: Path) -> None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no chart")
        return
    panels = report["scenes"]
    cols = min(3, len(panels))
    rows = -(-len(panels) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False)
    for ax, p in zip(axes.flat, panels):
        for k, r in p["variants"].items():
            marker = "*" if k == "default" else ("x" if k == "before" else "o")
            ax.scatter(r["frame_s"] * 1e3, r["psnr"], marker=marker, s=80 if marker == "*" else 30, label=k)
        ax.axhline(60, color="grey", lw=0.8, ls="--")
        ax.set_title(f"{p['scene']}, {p['mode'].replace('emission_absorption', 'EA')}", fontsize=9)
        ax.set_xlabel("frame ms")
        ax.set_ylabel("PSNR dB")
        ax.set_xscale("log")
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())

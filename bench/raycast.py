"""Volume ray caster speed: frame time at 512x512 for a 256^3 volume, with and without
early ray termination, per mode, and the error early termination costs.

    python bench/raycast.py [--repeats 5] [--out bench/results]

Volume: ../shared/data/volumes/aneurism.vti (256^3 uint8) when present, else a synthetic
256^3 float32 field. The peer in the same run is the same renderer with termination off
(termination=1.0). Writes raycast.json.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _common import SHARED_DATA  # noqa: E402

import tetvr  # noqa: E402
from tetvr import Camera, RaycastSettings, TransferFunction, Volume  # noqa: E402


def volume() -> tuple[str, Volume]:
    path = SHARED_DATA / "volumes" / "aneurism.vti"
    if path.is_file():
        return "aneurism.vti", tetvr.read_volume(path)
    g = np.linspace(-1.0, 1.0, 256, dtype=np.float32)
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    data = (np.sin(6 * x) * np.cos(5 * y) * np.sin(4 * z) * 0.5 + 0.5).astype(np.float32)
    return "synthetic 256^3", Volume.from_array(data, spacing=(1.0, 1.0, 1.0))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    name, vol = volume()
    lo, hi = vol.scalar_range
    tf = TransferFunction(color=((lo, 0.9, 0.3, 0.2), (hi, 1.0, 1.0, 0.9)),
                          opacity=((lo, 0.0), (lo + 0.3 * (hi - lo), 0.0), (lo + 0.5 * (hi - lo), 0.6), (hi, 1.0)),
                          unit_distance=2.0)
    box_lo, box_hi = vol.bounds
    centre = 0.5 * (box_lo + box_hi)
    radius = 0.5 * float(np.linalg.norm(box_hi - box_lo))
    cam = Camera(position=tuple(centre + np.array([1.2, 0.8, 1.6]) * radius), focal_point=tuple(centre),
                 view_up=(0, 0, 1), view_angle=30, clipping_range=(radius * 0.2, radius * 6))
    size = (512, 512)
    rows = {}
    with tetvr.Raycaster() as rc:
        info = rc.gl_info
        for mode in ("emission_absorption", "mip", "xray", "isosurface"):
            for term in (0.99, 1.0):
                s = RaycastSettings(mode=mode, termination=term)
                img = rc.render(vol, cam, tf, size=size, settings=s)  # warm-up: upload, table, program
                times = []
                for _ in range(args.repeats):
                    t0 = time.perf_counter()
                    img = rc.render(vol, cam, tf, size=size, settings=s)
                    times.append(time.perf_counter() - t0)
                rows[f"{mode}, termination {term}"] = {"frame_s": statistics.median(times), "image": img}
                print(f"{mode:20s} termination {term:4}: {statistics.median(times) * 1e3:8.1f} ms")
    out = {"created": time.strftime("%Y-%m-%dT%H:%M:%S"), "volume": name, "dims": list(vol.dims), "size": size,
           "gl": info, "frames": {}}
    for mode in ("emission_absorption", "mip", "xray", "isosurface"):
        on, off = rows[f"{mode}, termination 0.99"], rows[f"{mode}, termination 1.0"]
        err = float(np.abs(on["image"].astype(np.float64) - off["image"]).max())
        out["frames"][mode] = {"with_termination_s": on["frame_s"], "without_termination_s": off["frame_s"],
                               "speedup": off["frame_s"] / on["frame_s"], "max_abs_difference": err}
        print(f"{mode:20s} early termination: {off['frame_s'] / on['frame_s']:.2f}x faster, max difference {err:.4f}")
    path = Path(args.out)
    path.mkdir(parents=True, exist_ok=True)
    (path / "raycast.json").write_text(json.dumps(out, indent=1))
    print(f"wrote {path / 'raycast.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

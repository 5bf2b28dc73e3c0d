"""Isosurface-like (spiky) transfer functions on the real meshes: even against warped tables.

Each scene (bluntfin from outside, pipe flow from outside and with the camera inside) is
rendered with two opacity spikes to 0.9 at data quantiles, 1 % and 0.3 % of the range wide,
the narrower spikes reaching opacity 1 (extinction -ln(1 - a), log-singular at the peak),
and a smooth ramp for comparison; by both GPU methods, with the table's nodes even
(``table_warp="off"``, the former default) and as the defaults choose (``"auto"``: a warped
table where even nodes fall short, :mod:`tetvr.optics.tablewarp`). Recorded per row: PSNR, the
largest per-pixel error and the count of pixels off by more than 1/255 against the CPU
reference, the median frame time per view change (process CPU time, llvmpipe's threads
included, after a warm-up frame) and its ratio to the smooth transfer function's frame in
the same run and method, and the table size chosen.

    python bench/spiky_tf.py [--size 128] [--out bench/results]

Writes ``spiky_tf.json``; docs/limits.md quotes it through ``bench/doc_tables.py``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _common import TETS_DATA, load_quiet, machine, write_json  # noqa: E402

import tetvr  # noqa: E402
from tetvr import Camera, RenderSettings, TransferFunction  # noqa: E402
from tetvr.reference.tets import render_reference  # noqa: E402
from tetvr.optics.tablesize import resolve  # noqa: E402

#: Spike half-widths, as fractions of the data range.
WIDTHS = (0.01, 0.003)


def spiky_tf(mesh, centers, width, units=20.0, peak=0.9) -> TransferFunction:
    """Opacity 0 but for a spike of height ``peak`` at each centre (fractions of the range)."""
    op = [(0.0, 0.0)]
    for c in centers:
        op += [(c - width, 0.0), (c, peak), (c + width, 0.0)]
    op.append((1.0, 0.0))
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    return TransferFunction.preset("cool-to-warm", mesh.scalar_range, opacity=op, unit_distance=diag / units)


def smooth_tf(mesh, units=20.0) -> TransferFunction:
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    return TransferFunction.preset("cool-to-warm", mesh.scalar_range, opacity=[(0, 0.05), (0.5, 0.3), (1, 0.9)],
                                   unit_distance=diag / units)


def scenes():
    for file, field, quantiles, views in (
            ("bluntfin_tets.vtu", "Density", (0.3, 0.6), ("outside",)),
            ("pipe_flow_init_flow.vtu", "Velocity", (0.5, 0.8), ("outside", "camera inside"))):
        path = TETS_DATA / file
        if not path.is_file():
            print(f"skipping {file}: {path} not found")
            continue
        mesh = load_quiet(path, field)
        lo, hi = mesh.scalar_range
        centers = [(v - lo) / (hi - lo) for v in np.quantile(mesh.scalars, quantiles)]
        for view in views:
            if view == "outside":
                cam = Camera.fit(mesh, direction=(-1.0, -0.5, -0.7), zoom=1.2)
            else:
                cam = Camera(position=(0.3, 0.2, 3.0), focal_point=(0, 0, 15), view_angle=60, clipping_range=(0.01, 40))
            yield f"{file.split('_')[0]}, {view}", mesh, cam, centers


def errors(img, ref):
    d = np.abs(img[..., :3].astype(np.float64) - ref[..., :3]).max(axis=-1)
    return {"psnr": min(tetvr.psnr(img, ref), 200.0), "max_error": float(d.max()),
            "pixels_over_1_255": int(np.sum(d > 1 / 255)), "nan": int(np.isnan(img).sum())}


def frame(settings, mesh, cam, tf, size, repeats=3):
    with tetvr.Renderer(settings) as r:
        t0 = time.perf_counter()
        img = r.render(mesh, cam, tf, size=size)
        first = time.perf_counter() - t0
        times = []
        for _ in range(repeats):
            t0 = time.process_time()
            img = r.render(mesh, cam, tf, size=size)
            times.append(time.process_time() - t0)
    return img, float(np.median(times)), first


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = ap.parse_args(argv)
    size = (args.size, args.size)
    rows = []
    for name, mesh, cam, centers in scenes():
        tfs = {"smooth": smooth_tf(mesh), **{f"spikes {100 * w:g} %": spiky_tf(mesh, centers, w) for w in WIDTHS},
               f"opaque spikes {100 * WIDTHS[-1]:g} %": spiky_tf(mesh, centers, WIDTHS[-1], peak=1.0)}
        refs = {k: render_reference(mesh, cam, tf, size) for k, tf in tfs.items()}
        for method in ("projected", "raymarch"):
            smooth_s = None
            for tf_name, tf in tfs.items():
                for warp in ("off", "auto"):
                    s = RenderSettings(method=method, table_warp=warp)
                    img, frame_s, first_s = frame(s, mesh, cam, tf, size)
                    if tf_name == "smooth" and warp == "auto":
                        smooth_s = frame_s
                    t = resolve(s, tf, mesh)
                    row = {"scene": name, "method": method, "tf": tf_name, "table_warp": warp, "n_tets": mesh.n_tets,
                           "table": {"n_bins": t.n_bins, "n_slices": t.n_slices, "warp": t.warp},
                           "frame_s": frame_s, "first_frame_s": first_s, **errors(img, refs[tf_name])}
                    rows.append(row)
                    print(f"{name:24s} {method:9s} {tf_name:13s} {warp:4s} N={t.n_bins:3d}{'w' if t.warp else ' '} "
                          f"{row['psnr']:6.1f} dB  max {row['max_error']:.4f}  >1/255 {row['pixels_over_1_255']:5d}  "
                          f"{frame_s * 1e3:6.0f} ms", flush=True)
            for row in rows:
                if row["scene"] == name and row["method"] == method:
                    row["frame_vs_smooth"] = row["frame_s"] / smooth_s
    write_json(Path(args.out) / "spiky_tf.json", {"created": time.strftime("%Y-%m-%dT%H:%M:%S"), "size": size,
                                                 "machine": machine(), "rows": rows})
    print(f"wrote {Path(args.out) / 'spiky_tf.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

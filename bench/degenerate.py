"""Faces through the eye: a sweep of image sizes and jittered cameras where every view
holds faces seen exactly edge-on, both methods against the exact reference.

Scenes: ``cube(1)`` (6 tets) with axis-aligned faces and the eye on the plane of one of its
boundary faces (x = 0.5, outside the cube), and a single tet with integer vertices whose
face plane x + y - z = -16 holds the eye; 50 cameras per scene (the eye moved within that
plane, the focal point jittered), at image sizes 64, 128, ..., 640.

A pixel centre within rounding of such a face's plane (float32 rays, the rasteriser's
1/256-pixel snapping) is ill-conditioned: the exact segment jumps there from nothing to
the whole face's chord. Besides the forward error (GPU against the reference at the
pixel centre) the sweep reports the backward error: the distance of the GPU's value from
the range of exact values over rays moved by up to ``JITTER_PX`` pixels, which is zero
where the GPU's answer is exact for a ray that near. It is computed (4 more reference
images) for a view where the default method, tet marching, is off by more than 0.05, and
for projected tetrahedra only in those views.

    python bench/degenerate.py            # writes bench/results/degenerate.json and .png
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import _common  # noqa: E402

#: Rays moved by this many pixels bound the backward error (the rasteriser snaps to 1/256).
JITTER_PX = 1.0 / 128.0
SIZES = tuple(range(64, 641, 64))
N_CAMERAS = 50
METHODS = ("raymarch", "projected")


def scenes(n_cameras: int) -> list[tuple[str, object, list[object], object]]:
    from tetvr import Camera, TetMesh, TransferFunction
    from tetvr.mesh import synthetic

    rng = np.random.default_rng(2026)
    cube = synthetic.cube(1, rotate=False)
    tf_cube = TransferFunction.preset("viridis", cube, opacity=[(0.0, 0.4), (1.0, 0.9)], unit_distance=0.3)
    cams_cube = []
    for _ in range(n_cameras):
        y, z = rng.uniform(-1.5, 1.5, 2)
        if max(abs(y), abs(z)) < 0.7:  # keep the eye outside the cube, on its face's plane
            y = 0.7 * np.sign(y) + y
        focal = rng.uniform(-0.3, 0.3, 3)
        cams_cube.append(Camera(position=(0.5, float(y), float(z)), focal_point=tuple(focal), view_up=(0, 0, 1),
                                view_angle=40.0, clipping_range=(0.05, 10.0)))
    pts = np.array([[0.0, 0.0, 16.0], [10.0, 0.0, 26.0], [0.0, 10.0, 26.0], [5.0, 5.0, 10.0]])
    tet = TetMesh.from_arrays(pts, [[0, 1, 2, 3]], [0.0, 1.0, 0.5, 0.2])
    tf_tet = TransferFunction.preset("viridis", (0.0, 1.0), opacity=[(0.0, 0.5), (1.0, 0.9)], unit_distance=2.0)
    eye0 = np.array([31.0, -22.0, 25.0])
    in_plane = np.array([[1.0, -1.0, 0.0], [1.0, 0.0, 1.0]])  # directions within x + y - z = const
    cams_tet = []
    for _ in range(n_cameras):
        eye = eye0 + rng.integers(-3, 4, 2) @ in_plane  # integer moves keep the eye exactly in the plane
        focal = tet.centroids[0] + rng.normal(0.0, 1.0, 3)
        cams_tet.append(Camera(position=tuple(eye), focal_point=tuple(focal), view_up=(0, 0, 1), view_angle=30.0,
                               clipping_range=(1.0, 200.0)))
    return [("cube_face_plane", cube, cams_cube, tf_cube), ("integer_tet", tet, cams_tet, tf_tet)]


def _turned(camera: object, dx_px: float, dy_px: float, size: int) -> object:
    """The camera turned about the eye so that its rays move by about (dx, dy) pixels."""
    import dataclasses

    pos = np.asarray(camera.position)
    fp = np.asarray(camera.focal_point)
    dist = float(np.linalg.norm(fp - pos))
    forward = (fp - pos) / dist
    right = np.cross(forward, np.asarray(camera.view_up, dtype=float))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    per_px = 2.0 * dist * np.tan(np.radians(camera.view_angle) / 2.0) / size
    return dataclasses.replace(camera, focal_point=tuple(fp + (dx_px * right + dy_px * up) * per_px))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="3 sizes and 8 cameras")
    parser.add_argument("--out", type=Path, default=_common.ROOT / "bench" / "results" / "degenerate.json")
    args = parser.parse_args()
    from tetvr import RenderSettings
    from tetvr.gl import Renderer
    from tetvr.reference.tets import render_reference

    sizes = (64, 304, 640) if args.quick else SIZES
    n_cameras = 8 if args.quick else N_CAMERAS
    rows = []
    start = time.perf_counter()
    renderers = {m: Renderer(RenderSettings(method=m)) for m in METHODS}
    try:
        all_scenes = scenes(n_cameras)
        for size in sizes:  # every scene at one size, then the next: the JSON written so far covers both
            for scene, mesh, cameras, tf in all_scenes:
                for k, camera in enumerate(cameras):
                    want = render_reference(mesh, camera, tf, (size, size))
                    envelope = None
                    for method, renderer in renderers.items():
                        got = renderer.render(mesh, camera, tf, size=(size, size)).astype(np.float64)
                        finite = np.isfinite(got)
                        forward = np.abs(np.where(finite, got, 0.0) - want).max(axis=-1)
                        backward = None
                        # The envelope (4 more reference images) only where the default crosses the bar:
                        # projected tetrahedra's backward error is reported where it was computed.
                        if forward.max() > 0.05 and (method == METHODS[0] or envelope is not None):
                            if envelope is None:
                                near = [render_reference(mesh, _turned(camera, dx, dy, size), tf, (size, size))
                                        for dx, dy in ((JITTER_PX, 0), (-JITTER_PX, 0), (0, JITTER_PX),
                                                       (0, -JITTER_PX))]
                                envelope = np.minimum.reduce([want, *near]), np.maximum.reduce([want, *near])
                            lo, hi = envelope
                            backward = np.maximum(np.maximum(lo - got, got - hi), 0.0).max(axis=-1)
                        rows.append(dict(scene=scene, size=size, camera=k, method=method,
                                         nan=int((~finite).any(axis=-1).sum()),
                                         forward_max=float(forward.max()),
                                         forward_over_005=int((forward > 0.05).sum()),
                                         backward_max=None if backward is None else
                                         float(np.where(finite.all(axis=-1), backward, 1.0).max())))
                print(f"{scene} {size}: done ({time.perf_counter() - start:.0f} s)", flush=True)
                _write(rows, sizes, n_cameras, args.out)
    finally:
        for r in renderers.values():
            r.release()

    _write(rows, sizes, n_cameras, args.out)


def _write(rows: list[dict], sizes: tuple[int, ...], n_cameras: int, out: Path) -> None:
    """The JSON (a summary per method, then every view) and the chart, from the rows so far."""
    summary = {}
    for method in METHODS:
        mine = [r for r in rows if r["method"] == method]
        if not mine:
            continue
        summary[method] = dict(
            views=len(mine),
            nan_pixels=sum(r["nan"] for r in mine),
            forward_max=max(r["forward_max"] for r in mine),
            views_with_forward_over_005=sum(r["forward_over_005"] > 0 for r in mine),
            pixels_with_forward_over_005=sum(r["forward_over_005"] for r in mine),
            # Views whose forward error stays within 0.05 need no envelope: their backward error is at most that.
            backward_max=max((r["backward_max"] if r["backward_max"] is not None else min(r["forward_max"], 0.05))
                             for r in mine if r["backward_max"] is not None or r["forward_max"] <= 0.05),
            backward_not_computed=sum(r["backward_max"] is None and r["forward_max"] > 0.05 for r in mine),
        )
    done = sorted({r["size"] for r in rows})
    data = dict(benchmark="degenerate", jitter_px=JITTER_PX, sizes=list(sizes), sizes_done=done,
                cameras_per_scene=n_cameras, machine=_common.machine(), loadavg=_common.loadavg(),
                summary=summary, rows=rows)
    _common.write_json(out, data)
    _chart(rows, out.with_suffix(".png"))


def _value(row: dict, key: str) -> float | None:
    """A row's error; a backward error not computed is bounded by a forward error within 0.05."""
    if key == "backward_max" and row[key] is None:
        return row["forward_max"] if row["forward_max"] <= 0.05 else None
    return row[key]


def _chart(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for method, colour in zip(METHODS, ("tab:blue", "tab:orange")):
        mine = [r for r in rows if r["method"] == method]
        sizes = sorted({r["size"] for r in mine})
        over = [sum(r["forward_over_005"] for r in mine if r["size"] == s) for s in sizes]
        axes[0].plot(sizes, np.maximum(over, 0.5), "o-", color=colour, label=method)
    axes[0].set_yscale("log")
    axes[0].set_xlabel("image size (pixels a side)")
    axes[0].set_ylabel("pixels off by more than 0.05, all cameras")
    axes[0].set_title("pixels beyond 0.05 (at the pixel centre)", fontsize=10)
    axes[0].legend(fontsize=8)
    for ax, key, title in ((axes[1], "forward_max", "worst forward error (at the pixel centre)"),
                           (axes[2], "backward_max", f"worst backward error (rays within 1/{round(1 / JITTER_PX)} px)")):
        for method, colour in zip(METHODS, ("tab:blue", "tab:orange")):
            mine = [r for r in rows if r["method"] == method]
            sizes = sorted({r["size"] for r in mine})
            worst = []
            for s in sizes:
                values = [_value(r, key) for r in mine if r["size"] == s]
                worst.append(np.nan if any(v is None for v in values) else max(values))
            ax.plot(sizes, np.maximum(worst, 1e-7), "o-", color=colour,
                    label=method if key == "forward_max" else f"{method} (gaps: not computed)")
        ax.axhline(0.05, color="grey", ls="--", lw=1, label="0.05")
        ax.set_yscale("log")
        ax.set_xlabel("image size (pixels a side)")
        ax.set_title(title, fontsize=10)
    axes[1].set_ylabel("largest per-pixel error over all cameras")
    axes[1].legend(fontsize=8)
    axes[2].legend(fontsize=8)
    fig.suptitle("Faces through the eye, per image size over all cameras of both scenes: both methods against the "
                 "exact reference (bench/degenerate.py)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()

"""Where the walk is most easily wrong: random cameras beside the boundary of a mesh and of
its k-d bricks, every image against the exact reference.

Tet marching decides, per pixel, which boundary face a ray enters by and which face it
leaves each cell by. The cases that go wrong are rays that run almost along a face: the
eye a rounding beside a brick's cut plane or a mesh's flat side, faces of almost no area in
a cut plane, rays that leave a curved boundary and enter it again at once. This sweep puts
the eye there on purpose: for each trial it picks a brick and, seven times in ten, moves one
of the eye's coordinates to 1e-8..1e-2 of the mesh's diagonal outside one of that brick's
box faces; the view direction, angle and projection are random. Each trial renders

* the whole mesh with the defaults (tet marching), and
* the mesh's 8 k-d bricks (cut cells included), composited in visibility order,

and both against ``method="reference"`` at SIZE. The JSON lists every trial beyond 1/255
(its camera, so that it can be rendered again) and per mesh the worst errors.

    python bench/grazing.py [--trials 40] [--seed 0] [--out bench/results]
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from _common import TETS_DATA, load_quiet, loadavg, machine, write_json  # noqa: E402

from tetvr import Camera, RenderSettings, TransferFunction  # noqa: E402
from tetvr.cluster.bricks import composite_over, kd_bricks  # noqa: E402
from tetvr.gl import Renderer  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402
from tetvr.mesh.tetmesh import TetMesh  # noqa: E402
from tetvr.reference.tets import render_reference  # noqa: E402

SIZE = (40, 40)
N_BRICKS = 8
#: What "right" means: one step of an 8-bit image.
BOUND = 1.0 / 255.0


def _tetwild_torus() -> TetMesh:
    import trimesh

    from tetvr.mesh.meshing import tetrahedralize

    surface = trimesh.creation.torus(major_radius=1.0, minor_radius=0.35, major_sections=32, minor_sections=16)
    return tetrahedralize(surface, edge_length=0.1,
                          field=lambda p: 0.5 + 0.5 * np.sin(2.0 * p[:, 0]) * p[:, 2] + 0.3 * p[:, 1]).mesh


def meshes() -> dict[str, Callable[[], TetMesh]]:
    """The swept meshes: a torus and interlocking rings (grids bent round), a torus as
    fTetWild fills it (where pytetwild is installed), and the SimVascular beam (where the
    shared data is)."""
    out: dict[str, Callable[[], TetMesh]] = {"torus": synthetic.torus,
                                             "interlocking rings": lambda: synthetic.interlocking_rings(8)}
    if all(importlib.util.find_spec(m) is not None for m in ("pytetwild", "trimesh")):
        out["torus by fTetWild"] = _tetwild_torus
    if (TETS_DATA / "beam_tet4_result_100.vtu").exists():
        out["beam"] = lambda: load_quiet(TETS_DATA / "beam_tet4_result_100.vtu", "VonMises_stress")
    return out


def _camera(rng: np.random.Generator, mesh: TetMesh, boxes: list[np.ndarray], diag: float) -> Camera:
    box = boxes[int(rng.integers(len(boxes)))]
    eye = mesh.points[int(rng.integers(mesh.n_points))] + rng.normal(0.0, 0.02 * diag, 3)
    if rng.random() < 0.7:  # beside one of the brick's box faces, just outside it
        axis, side = int(rng.integers(3)), int(rng.integers(2))
        eye[axis] = box[side][axis] + (1 if side else -1) * 10 ** rng.uniform(-8, -2) * diag
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    return Camera(position=tuple(eye), focal_point=tuple(eye + direction), view_angle=float(rng.uniform(20, 80)),
                  parallel_projection=bool(rng.random() < 0.2), parallel_scale=0.2 * diag,
                  clipping_range=(1e-3 * diag, 5 * diag))


def sweep(name: str, mesh: TetMesh, trials: int, seed: int, renderer: Renderer) -> dict[str, Any]:
    """``trials`` random cameras on ``mesh``: the whole image's and the bricks' composite's
    largest error against the reference, and every trial beyond BOUND."""
    lo, hi = mesh.scalar_range
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    tf = TransferFunction.preset("viridis", (lo, hi), opacity=[(0, 0.3), (0.6, 0.9), (1, 0.5)],
                                 unit_distance=0.1 * diag)
    tree = kd_bricks(mesh, N_BRICKS)
    bricks = {b.index: tree.brick_mesh(b) for b in tree.bricks()}
    rng = np.random.default_rng(seed)
    worst = {"whole": 0.0, "bricks": 0.0}
    beyond: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    for trial in range(trials):
        camera = _camera(rng, mesh, [m.bounds for m in bricks.values()], diag)
        ref = render_reference(mesh, camera, tf, SIZE)
        parts = {i: renderer.render(m, camera, tf, size=SIZE) for i, m in bricks.items()}
        images = {"whole": renderer.render(mesh, camera, tf, size=SIZE),
                  "bricks": composite_over([parts[i] for i in tree.visibility_order(camera)])}
        for key, image in images.items():
            err = np.abs(image.astype(np.float64) - ref).max(axis=-1)
            worst[key] = max(worst[key], float(err.max()))
            if err.max() > BOUND:
                beyond.append({"trial": trial, "image": key, "max_error": float(err.max()),
                               "pixels": int((err > BOUND).sum()), "camera": camera.to_dict()})
        print(f"  {name:20s} trial {trial:3d}: whole {worst['whole']:.1e}, bricks {worst['bricks']:.1e}", flush=True)
    return {"n_tets": mesh.n_tets, "cut_cells": int(tree.n_cut), "trials": trials, "worst": worst,
            "beyond": beyond, "seconds": time.perf_counter() - t0}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = ap.parse_args(argv)
    report: dict[str, Any] = {"what": __doc__.splitlines()[0], "size": SIZE, "bricks": N_BRICKS, "bound": BOUND,
                              "seed": args.seed, "date": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": machine(),
                              "loadavg_start": loadavg(), "meshes": {}}
    path = args.out / "grazing.json"
    with warnings.catch_warnings(), Renderer(RenderSettings()) as renderer:
        warnings.simplefilter("ignore")
        for name, make in meshes().items():
            report["meshes"][name] = sweep(name, make(), args.trials, args.seed, renderer)
            write_json(path, report)
    report["loadavg_end"] = loadavg()
    write_json(path, report)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

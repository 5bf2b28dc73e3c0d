"""Imperfect meshes: what the default does with each class, against the exact reference.

For every class of :mod:`tetvr.scene.imperfect` (duplicated interface nodes with a continuous
or jumping field, repeated cells, copies with other values, overlapping parts, extreme sizes,
a clipping range beyond float32), on synthetic meshes and, when ``../shared/data/tets``
exists, on the beam and the SimVascular pipe cut into two regions, this renders each view with
``method="auto"`` (the default), ``"raymarch"`` and ``"projected"`` and records the largest
per-pixel error against ``method="reference"``, the pixels beyond 1/255, PSNR, the method
``auto`` chose and whether ``raymarch`` refused. Writes ``bench/results/imperfect.json``;
``python bench/doc_tables.py --write`` puts the table in docs/limits.md.

    python bench/imperfect.py [--size 128] [--out bench/results]
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as _dt
import json
import sys
import time
import warnings
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import tetvr  # noqa: E402
from tetvr import Camera, RenderSettings, TetMesh  # noqa: E402
from tetvr.core.image import psnr  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402
from tetvr.order.method import choose  # noqa: E402
from tetvr.order.walkable import walk_check  # noqa: E402
from tetvr.render import default_transfer_function  # noqa: E402
from tetvr.scene import imperfect  # noqa: E402

Case = tuple[str, str, Callable[[], TetMesh], list[Callable[[TetMesh], Camera]]]


def _views(*directions: tuple[float, float, float]) -> list[Callable[[TetMesh], Camera]]:
    return [lambda m, d=d: Camera.fit(m, direction=d) for d in directions]


def _long_axis(mesh: TetMesh) -> int:
    return int(np.argmax(mesh.bounds[1] - mesh.bounds[0]))


def _across(mesh: TetMesh) -> tuple[float, float, float]:
    d = np.array([0.1, 0.31, -0.05])
    d[_long_axis(mesh)] = 1.0
    return (float(d[0]), float(d[1]), float(d[2]))


def _huge_clip(mesh: TetMesh) -> Camera:
    return dataclasses.replace(Camera.fit(mesh, parallel=True), clipping_range=(-1e308, 1.7e308))


def cases(data: Path) -> list[Case]:
    """(class, mesh, builder, cameras) for every case that can be built here."""
    cube = lambda: synthetic.cube(4, imperfect.field, rotate=False)  # noqa: E731
    out: list[Case] = [
        ("duplicated interface nodes", "cube(4), 2 regions", lambda: imperfect.regions(cube(), 0),
         _views((1.0, 0.2, 0.3), (-1.0, -0.6, -1.2))),
        ("duplicated nodes, field jumps", "cube(4), 2 regions", lambda: imperfect.regions(cube(), 0, jump=True),
         _views((1.0, 0.2, 0.3), (-1.0, -0.6, -1.2))),
        ("repeated cells", "cube(3), every cell twice",
         lambda: imperfect.copies(synthetic.cube(3, imperfect.field, rotate=False), 2), _views((0.3, -0.5, -1.0))),
        ("repeated cells", "cube(1), every cell 200 times",
         lambda: imperfect.copies(synthetic.cube(1, imperfect.field, rotate=False), 200), _views((0.3, -0.5, -1.0))),
        ("copies with other values", "cube(4), twice", lambda: imperfect.conflicting_copies(cube()),
         _views((0.3, -0.5, -1.0))),
        ("overlapping parts", "refined block in a coarse cube", imperfect.embedded_block, _views((0.3, -0.5, -1.0))),
        ("overlapping parts", "one cell laid over a cube", imperfect.cell_laid_over, _views((0.3, -0.5, -1.0))),
        ("gaps between cells", "12 layers, faces not matching between", imperfect.gaps,
         _views((0.3, 0.2, 1.0), (1.0, 0.4, 0.2))),
        ("extreme extent", "cube(3) x 1.7e17", lambda: imperfect.scaled(synthetic.cube(3, imperfect.field), 1.7e17),
         _views((-1.0, -0.6, -1.2))),
        ("extreme extent", "cube(3) x 2.4e-13", lambda: imperfect.scaled(synthetic.cube(3, imperfect.field), 2.4e-13),
         _views((-1.0, -0.6, -1.2))),
        ("clipping range beyond float32", "cube(3), parallel, (-1e308, 1.7e308)",
         lambda: synthetic.cube(3, imperfect.field), [_huge_clip]),
    ]
    for name, file, field in (("beam", "beam_tet4_result_100.vtu", "VonMises_stress"),
                              ("pipe", "pipe_flow_init_flow.vtu", "Pressure")):
        path = data / file
        if not path.exists():
            continue

        def read(path: Path = path, field: str = field) -> TetMesh:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return tetvr.read(path, scalars=field)

        for jump in (False, True):
            cls = "duplicated nodes, field jumps" if jump else "duplicated interface nodes"
            out.append((cls, f"{name}, 2 regions", lambda read=read, jump=jump: imperfect.regions(
                read(), _long_axis(read()), jump=jump), [lambda m: Camera.fit(m, direction=_across(m)),
                                                         lambda m: Camera.fit(m)]))
        out.append(("repeated cells", f"{name}, every cell twice", lambda read=read: imperfect.copies(read(), 2),
                    [lambda m: Camera.fit(m)]))
    return out


def _render(mesh: TetMesh, camera: Camera, tf: Any, size: tuple[int, int], method: str) -> tuple[Any, list[str]]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            image = tetvr.render(mesh, camera=camera, tf=tf, size=size, settings=RenderSettings(method=method))
        except ValueError as exc:
            return str(exc), []
    return image, [str(w.message) for w in caught]


def measure(cls: str, label: str, mesh: TetMesh, camera: Camera, size: tuple[int, int]) -> dict[str, Any]:
    """One view of one case: every method against the reference."""
    tf = default_transfer_function(mesh)
    t0 = time.perf_counter()
    ref = tetvr.render(mesh, camera=camera, tf=tf, size=size, method="reference")
    row: dict[str, Any] = {"class": cls, "mesh": label, "n_tets": mesh.n_tets, "reference_s": time.perf_counter() - t0,
                           "reasons": list(walk_check(mesh).reasons)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        row["auto_chose"] = choose(RenderSettings(), mesh, camera, size)
    for method in ("auto", "raymarch", "projected"):
        image, said = _render(mesh, camera, tf, size, method)
        if isinstance(image, str):
            row[method] = {"refused": image}
            continue
        diff = np.abs(image.astype(np.float64) - ref).max(axis=-1)
        row[method] = {"max_error": float(diff.max()), "beyond": int(np.count_nonzero(diff > 1 / 255)),
                       "psnr": float(psnr(image, ref)), "warnings": said}
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "tets")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = ap.parse_args(argv)
    size = (args.size, args.size)
    rows = []
    for cls, label, build, cameras in cases(args.data):
        mesh = build()
        for k, make_camera in enumerate(cameras):
            row = measure(cls, label, mesh, make_camera(mesh), size)
            row["view"] = k
            rows.append(row)
            a = row["auto"]
            print(f"{cls:32s} {label:38s} view {k}: auto ({row['auto_chose']}) "
                  f"{a.get('max_error', float('nan')):.2e}, {a.get('beyond', -1)} px > 1/255", flush=True)
    result = {"what": "imperfect meshes: every method against the exact reference", "size": list(size),
              "date": _dt.datetime.now().isoformat(timespec="seconds"), "rows": rows}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "imperfect.json").write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

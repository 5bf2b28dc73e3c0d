"""Digests of the images the bench scenes render, to show that a change leaves them bit-identical.

Renders the six meshes of ``vs_vtk.py`` (``synthetic.cube(n)`` for n = 12, 26, 38, 55 and, when
``../shared/data/tets`` exists, bluntfin and combustor, field "Density") from ``Camera.fit`` with
``default_transfer_function(opacity=0.5)`` at 256x256, by tet marching and by projected
tetrahedra, plus the bundled fusion demo's CT volume by the GPU ray caster, and records the SHA-256
of each float32 image. A code change that should not change a picture (a move, a split, a rename)
is checked by writing the digests before it and comparing after:

    python bench/image_digest.py --out before.json        # on the old commit
    python bench/image_digest.py --check before.json      # on the new one: exit 1 on any difference

The digests hold for one machine and one GL driver only (llvmpipe's results depend on its
build and the CPU's vector width), so they are compared within one machine, never committed as truth.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import tetvr  # noqa: E402
from tetvr import Camera, RenderSettings  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402
from tetvr.scene.examples import carotid_fusion  # noqa: E402
from tetvr.render import default_transfer_function  # noqa: E402

SIZE = (256, 256)
METHODS = ("raymarch", "projected")


def _meshes(data: Path) -> list[tuple[str, tetvr.TetMesh]]:
    out = [(f"cube({n})", synthetic.cube(n)) for n in (12, 26, 38, 55)]
    for name in ("bluntfin", "combustor"):
        path = data / f"{name}_tets.vtu"
        if path.exists():
            out.append((name, tetvr.read(path, scalars="Density")))
    return out


def _digest(image: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(image, dtype=np.float32).tobytes()).hexdigest()


def digests(data: Path) -> dict[str, str]:
    """The SHA-256 of every bench image, keyed by scene and method."""
    result: dict[str, str] = {}
    with tetvr.Renderer() as renderer:
        for name, mesh in _meshes(data):
            tf = default_transfer_function(mesh, opacity=0.5)
            cam = Camera.fit(mesh)
            for method in METHODS:
                renderer.settings = RenderSettings(method=method)
                result[f"{name}/{method}"] = _digest(renderer.render(mesh, cam, tf, size=SIZE))
                print(f"{name:>12} {method:>9} {result[f'{name}/{method}'][:16]}", flush=True)
        renderer.settings = RenderSettings()
        scene = carotid_fusion()
        with tetvr.Raycaster(ctx=renderer.ctx) as caster:
            result["carotid/volume"] = _digest(caster.render(scene.volume, scene.camera, scene.volume_tf, size=SIZE))
            w, h = SIZE
            end = np.ones((h, w))
            end[:, : w // 2] = 0.5
            textures = tetvr.RayTextures(np.zeros((h, w)), end)
            for mode in tetvr.FUSION_MODES:
                image = tetvr.fuse(scene.mesh, scene.volume, scene.camera, scene.mesh_tf, scene.volume_tf, size=SIZE,
                                   mode=mode, renderer=renderer, raycaster=caster,
                                   ray_textures=textures if mode == "ray_textures" else None)
                result[f"carotid/{mode}"] = _digest(image)
        print(f"{'carotid':>12} volume and {len(tetvr.FUSION_MODES)} fusion modes", flush=True)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data" / "tets")
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--out", type=Path, help="write the digests to this JSON file")
    group.add_argument("--check", type=Path, help="compare with the digests in this JSON file")
    args = parser.parse_args(argv)
    found = digests(args.data)
    if args.out:
        args.out.write_text(json.dumps(found, indent=1) + "\n")
        return 0
    expected = json.loads(args.check.read_text())
    differ = sorted(k for k in expected.keys() | found.keys() if expected.get(k) != found.get(k))
    for key in differ:
        print(f"DIFFERENT {key}: {expected.get(key)} -> {found.get(key)}")
    print(f"{len(expected) - len(differ)} of {len(expected)} images bit-identical")
    return 1 if differ else 0


if __name__ == "__main__":
    raise SystemExit(main())

"""How often a tile's rays cross the same cells: what an exact coarse-to-fine pass could skip.

A coarse-to-fine pass traces one ray at each corner of an s x s tile of pixels and fills
the tile's other pixels from those four where it may. It may without interpolating
between different walks only where every ray of the tile crosses the same cells, and the
corners can prove that: the rays through a triangle form a convex set (a convex region of
the image for parallel rays, a convex cone of directions for rays from an eye), so the
rays that cross one sequence of faces -- an intersection of such sets -- form a convex
set too, and where the four corner rays cross the same cells of a conforming mesh, every
ray between them does.

This script counts how often that holds, from the exact reference's ray--tet segments
(:func:`tetvr.reference.segments.ray_segments`) at the benchmark's fitted view: for each
covered pixel, its number of segments and a hash of the set of tets it crosses (a sum of
random 64-bit words, one a tet); for each tile size s, the tiles whose four corner rays
agree, the pixels a pass would then not trace (those of agreeing tiles off the coarse
grid), and the segments those pixels' rays hold (the march's work, which is paid per
segment). ``adjacent`` is the most a pass could hope for: the covered pixels whose right
neighbour crosses the same cells. Writes ``<out>/tile_coherence.json``; bench/README.md
quotes it.

    python bench/tile_coherence.py [--size 1024] [--tiles 2 4 8] [--out bench/results] [--quick]
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: Tile sizes (pixels between corner rays).
TILES = (2, 4, 8)


def cell_sets(mesh: Any, camera: Any, size: tuple[int, int], seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel (rows of ``size[1]``, columns of ``size[0]``): the number of ray--tet
    segments and a hash of the set of tets crossed (0 and 0 where the ray misses the mesh)."""
    from tetvr.reference.segments import ray_segments

    width, height = size
    seg = ray_segments(mesh, camera, size)
    words = np.random.default_rng(seed).integers(1, 2**63, size=mesh.n_tets, dtype=np.uint64)
    count = np.bincount(seg.pixel, minlength=width * height)
    # A sum modulo 2^64: equal sets give equal sums; unequal ones collide with chance ~2^-64.
    order = np.argsort(seg.pixel, kind="stable")
    pixel, word = seg.pixel[order], words[seg.tet[order]]
    starts = np.flatnonzero(np.r_[True, pixel[1:] != pixel[:-1]]) if pixel.size else np.zeros(0, np.int64)
    hashes = np.zeros(width * height, dtype=np.uint64)
    if pixel.size:
        with np.errstate(over="ignore"):
            hashes[pixel[starts]] = np.add.reduceat(word, starts)
    return count.reshape(height, width), hashes.reshape(height, width)


def coherence(count: np.ndarray, hashes: np.ndarray, tiles: tuple[int, ...] = TILES) -> dict[str, Any]:
    """What agreeing corner rays would let a coarse-to-fine pass skip, per tile size."""
    covered = count > 0
    n_pixels, n_segments = int(covered.sum()), int(count.sum())
    same_right = covered[:, :-1] & (count[:, :-1] == count[:, 1:]) & (hashes[:, :-1] == hashes[:, 1:])
    out: dict[str, Any] = {
        "covered_pixels": n_pixels, "segments": n_segments,
        "segments_per_ray": n_segments / n_pixels if n_pixels else 0.0,
        "adjacent": float(same_right.sum() / max(int(covered[:, :-1].sum()), 1)),
        "tiles": {},
    }
    height, width = count.shape
    for s in tiles:
        ny, nx = (height - 1) // s, (width - 1) // s  # whole tiles between corner rays
        c = count[: ny * s + 1: s, : nx * s + 1: s]
        h = hashes[: ny * s + 1: s, : nx * s + 1: s]
        corners = [(slice(None, -1), slice(None, -1)), (slice(None, -1), slice(1, None)),
                   (slice(1, None), slice(None, -1)), (slice(1, None), slice(1, None))]
        agree = c[corners[0]] > 0
        for rows, cols in corners[1:]:
            agree &= (c[rows, cols] == c[corners[0]]) & (h[rows, cols] == h[corners[0]])
        # Pixels of a tile: rows ty*s .. ty*s + s - 1 (the next tile's corner row belongs to it).
        body = covered[: ny * s, : nx * s].reshape(ny, s, nx, s)
        tile_covered = body.any(axis=(1, 3))
        off_grid = np.ones((s, s), bool)
        off_grid[0, 0] = False  # the tile's own corner is traced
        skipped = agree[:, None, :, None] & off_grid[None, :, None, :] & body
        skipped_segments = (count[: ny * s, : nx * s].reshape(ny, s, nx, s) * skipped).sum()
        out["tiles"][str(s)] = {
            "tiles_covered": int(tile_covered.sum()),
            "tiles_agreeing": float(agree.sum() / max(int(tile_covered.sum()), 1)),
            "pixels_skipped": float(skipped.sum() / max(n_pixels, 1)),
            "segments_skipped": float(skipped_segments / max(n_segments, 1)),
        }
    return out


def _specs(quick: bool) -> list[tuple[str, Callable[[], Any]]]:
    import corpus
    from _common import CUBE_NS, REAL_MESHES, TETS_DATA, load_quiet

    from tetvr.mesh import synthetic

    specs: list[tuple[str, Callable[[], Any]]] = [(f"cube({n})", lambda n=n: synthetic.cube(n)) for n in CUBE_NS[:2]]
    for fname, field in REAL_MESHES:
        path = TETS_DATA / fname
        if path.exists():
            specs.append((f"{path.stem.removesuffix('_tets')} ({field})", lambda p=path, f=field: load_quiet(p, f)))
        else:
            print(f"skipped {fname}: not in {TETS_DATA}", file=sys.stderr)
    if not quick:
        specs.append(("torus by fTetWild (swirl)", corpus.torus_tetwild))
        specs.append(("boundary layer (velocity)", corpus.boundary_layer))
    return specs


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--tiles", type=int, nargs="+", default=list(TILES))
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    ap.add_argument("--quick", action="store_true", help="the cubes and the shared meshes only")
    args = ap.parse_args(argv)
    from _common import machine, write_json

    from tetvr import Camera

    size = (args.size, args.size)
    result: dict[str, Any] = {
        "what": "how often the rays of an s x s tile cross the same cells (the exact reference's segments), "
                "the condition under which a coarse-to-fine pass may fill a tile from its corner rays",
        "date": _dt.datetime.now().isoformat(timespec="seconds"), "size": list(size), "view": "Camera.fit(mesh)",
        "machine": machine(), "meshes": [],
    }
    for name, make in _specs(args.quick):
        t0 = time.perf_counter()
        mesh = make()
        count, hashes = cell_sets(mesh, Camera.fit(mesh), size)
        rec = {"name": name, "n_tets": int(mesh.n_tets), **coherence(count, hashes, tuple(args.tiles)),
               "seconds": time.perf_counter() - t0}
        result["meshes"].append(rec)
        tiles = ", ".join(f"{s}: {t['tiles_agreeing']:.1%} of tiles, {t['segments_skipped']:.2%} of segments"
                          for s, t in rec["tiles"].items())
        print(f"{name}: {rec['segments_per_ray']:.1f} segments a ray; right neighbour the same cells "
              f"{rec['adjacent']:.1%}; {tiles}", flush=True)
        write_json(args.out / "tile_coherence.json", result)
    return 0


if __name__ == "__main__":
    sys.path[:0] = [str(ROOT), str(ROOT / "bench")]
    raise SystemExit(main())

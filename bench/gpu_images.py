"""The GL tests' images, kept on one GL and compared with another's: a lent GPU's with llvmpipe's.

A test's failure on a GPU says by how much, not where. As a pytest plugin
(``-p bench.gpu_images`` from the repository's root, ``TETVR_TEST_IMAGES=DIR``) this keeps every image
:meth:`tetvr.gl.renderer.Renderer.render` returns during each test (those of at most
:data:`MAX_PIXELS` pixels), keyed ``<test node id>#<its place among the test's images>``,
in ``DIR/<xdist worker or main>.npz``. Run the same tests with it here and on the GPU
(``bench/device_check.sh`` with ``IMAGES=1``), then compare the two folders:

    python bench/gpu_images.py GPU_DIR HERE_DIR [--pixels 1e-4]

which prints, per image both kept, the largest per-pixel difference, the pixels that differ
by more than 1/255 and by more than ``--pixels``, and the first of those pixels (x, y from
the image's bottom row). Found this way on an H200: projected tetrahedra differing across
whole fans, not at their edges (the rasteriser's interpolation, ``tetvr.gl.interpolation``).
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

#: The environment variable naming the folder the plugin keeps the images in.
IMAGES_ENV = "TETVR_TEST_IMAGES"
#: Images with more pixels than this are not kept (a 16 MiB download holds the suite's).
MAX_PIXELS = 512 * 512

_KEPT: dict[str, np.ndarray] = {}
_COUNT: Counter[str] = Counter()  # images kept so far per test


def keep(image: Any, test: str) -> None:
    """Keep ``image`` (an (h, w, 4) array) as the next image of ``test``."""
    image = np.asarray(image, dtype=np.float32)
    if image.shape[0] * image.shape[1] > MAX_PIXELS:
        return
    _KEPT[f"{test}#{_COUNT[test]}"] = image
    _COUNT[test] += 1


def pytest_configure(config: Any) -> None:
    if not os.environ.get(IMAGES_ENV):
        return
    from tetvr.gl.renderer import Renderer

    render = Renderer.render

    @functools.wraps(render)
    def kept(self: Any, *args: Any, **kwargs: Any) -> Any:
        image = render(self, *args, **kwargs)
        keep(image, os.environ.get("PYTEST_CURRENT_TEST", "?").rsplit(" ", 1)[0])
        return image

    Renderer.render = kept


def pytest_unconfigure(config: Any) -> None:
    folder = os.environ.get(IMAGES_ENV)
    if folder and _KEPT:
        os.makedirs(folder, exist_ok=True)
        np.savez_compressed(Path(folder) / f"{os.environ.get('PYTEST_XDIST_WORKER', 'main')}.npz", **_KEPT)


def load(folder: Path) -> dict[str, np.ndarray]:
    """Every image kept in ``folder``'s ``.npz`` files, by key."""
    images: dict[str, np.ndarray] = {}
    for path in sorted(Path(folder).glob("*.npz")):
        with np.load(path) as z:
            images.update({k: z[k] for k in z.files})
    return images


def compare(a: dict[str, np.ndarray], b: dict[str, np.ndarray], pixels: float = 1e-4) -> list[dict[str, Any]]:
    """Per key in both: the largest per-pixel difference (over the channels), the pixels
    beyond 1/255 and beyond ``pixels``, and the first pixel beyond 1/255 (x, y), or None;
    images whose shapes differ are reported with ``shape`` and no difference."""
    rows = []
    for key in sorted(a.keys() & b.keys()):
        x, y = a[key], b[key]
        if x.shape != y.shape:
            rows.append({"key": key, "shape": (x.shape, y.shape)})
            continue
        d = np.abs(x.astype(np.float64) - y).max(axis=-1)
        rows_, cols = np.nonzero(d > 1 / 255)
        rows.append({"key": key, "max": float(d.max()), "beyond_1_255": int(rows_.size),
                     "beyond": int(np.count_nonzero(d > pixels)),
                     "first": (int(cols[0]), int(rows_[0])) if rows_.size else None})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("first", type=Path)
    ap.add_argument("second", type=Path)
    ap.add_argument("--pixels", type=float, default=1e-4, help="the smaller difference to count pixels beyond")
    args = ap.parse_args(argv)
    a, b = load(args.first), load(args.second)
    rows = compare(a, b, args.pixels)
    for r in rows:
        if "shape" in r:
            print(f"{r['key']}: shapes differ {r['shape']}")
        else:
            print(f"{r['key']}: largest {r['max']:.2e}, {r['beyond_1_255']} pixels > 1/255, {r['beyond']} > "
                  f"{args.pixels:g}" + (f", first at {r['first']}" if r["first"] else ""))
    only = sorted(a.keys() ^ b.keys())
    print(f"{len(rows)} images in both; {len(only)} in one only" + (f" (first: {only[0]})" if only else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())

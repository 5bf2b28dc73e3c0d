"""Bad images out: write_png and the error measures refuse NaN, wrong shapes and empty
images with a ValueError, instead of writing a broken PNG or broadcasting silently."""

from __future__ import annotations

import numpy as np
import pytest

from tetvr.core.image import psnr, rmse, write_png

GOOD = np.zeros((4, 5, 4), dtype=np.float32)


def _nan_image() -> np.ndarray:
    img = GOOD.copy()
    img[1, 2, 0] = np.nan
    return img


@pytest.mark.parametrize("image,kwargs,match", [
    (_nan_image(), {}, "image contains NaN or Inf"),
    (np.full((2, 2, 4), np.inf, np.float32), {"background": None}, "image contains NaN or Inf"),
    (np.zeros((4, 5, 3)), {}, r"image must have shape \(H, W, 4\), got \(4, 5, 3\)"),
    (np.zeros((4, 5)), {}, r"image must have shape \(H, W, 4\)"),
    (np.zeros((0, 5, 4)), {}, "a PNG needs at least one pixel"),
    (GOOD, {"background": (2, 0, 0)}, r"background must be an RGB triple in \[0, 1\]"),
    (GOOD, {"background": (1, 1)}, "background must be an RGB triple"),
], ids=["nan", "inf-translucent", "rgb-only", "2d", "empty", "background-above-one", "background-two"])
def test_bad_image_for_png(tmp_path, image, kwargs, match):
    path = tmp_path / "out.png"
    with pytest.raises(ValueError, match=match):
        write_png(image, path, **kwargs)
    assert not path.exists()


@pytest.mark.parametrize("a,b", [(GOOD, GOOD[:3]), (GOOD, GOOD[..., :3].copy()[None]), (GOOD[:0], GOOD[:0])],
                         ids=["rows", "rank", "empty"])
def test_error_measures_need_matching_images(a, b):
    for measure in (psnr, rmse):
        with pytest.raises(ValueError, match="images must have the same shape"):
            measure(a, b)


def test_one_pixel_png(tmp_path):
    path = tmp_path / "one.png"
    write_png(np.array([[[0.25, 0.0, 0.0, 0.5]]], dtype=np.float32), path)
    assert path.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")

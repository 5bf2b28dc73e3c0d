"""Images out: premultiplied float RGBA -> PNG, with no imaging dependency."""

from __future__ import annotations

import os
import struct
import zlib
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["image_size", "write_png", "png_bytes", "to_rgba8", "composite_over", "psnr", "rmse"]


def image_size(size: Any) -> tuple[int, int]:
    """``(width, height)`` as two positive ints; bools and fractional values are refused."""
    try:
        width, height = size
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height), got {size!r}") from None
    if not all(isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) for v in (width, height)):
        raise ValueError(f"size must be two integers (width, height), got {size!r}")
    if width < 1 or height < 1:
        raise ValueError(f"size must be two positive integers (width, height), got {size!r}")
    return int(width), int(height)


def composite_over(image: ArrayLike, background: Sequence[float] | None) -> NDArray[np.float64]:
    """Premultiplied RGBA over an opaque background colour (or kept translucent if None)."""
    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 3 or img.shape[2] != 4:
        raise ValueError(f"image must have shape (H, W, 4), got {img.shape}")
    if background is None:
        return img
    bg = np.asarray(background, dtype=np.float64).reshape(-1)
    if bg.shape != (3,) or np.any(bg < 0) or np.any(bg > 1):
        raise ValueError(f"background must be an RGB triple in [0, 1], got {background!r}")
    out = np.empty_like(img)
    out[..., :3] = img[..., :3] + (1.0 - img[..., 3:4]) * bg
    out[..., 3] = 1.0
    return out


def to_rgba8(image: ArrayLike, background: Sequence[float] | None = None) -> NDArray[np.uint8]:
    """8-bit straight (non-premultiplied) RGBA, for display."""
    img = composite_over(image, background)
    if not np.all(np.isfinite(img)):
        raise ValueError("image contains NaN or Inf")
    rgb = img[..., :3]
    a = img[..., 3:4]
    with np.errstate(invalid="ignore", divide="ignore"):
        straight = np.where(a > 0, rgb / np.maximum(a, 1e-12), 0.0)
    out = np.concatenate([straight, a], axis=-1)
    return np.round(np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)


def write_png(image: ArrayLike, path: str | os.PathLike[str], *, background: Sequence[float] | None = (1.0, 1.0, 1.0)) -> None:
    """Write a premultiplied float RGBA image (row 0 at the top) as an 8-bit PNG.

    ``background`` is composited under the image; ``None`` writes a translucent RGBA PNG.
    """
    data = png_bytes(image, background=background)  # first: a rejected image leaves no empty file
    with open(path, "wb") as f:
        f.write(data)


def png_bytes(image: ArrayLike, background: Sequence[float] | None = (1.0, 1.0, 1.0), *, level: int = 6) -> bytes:
    """The PNG file of a premultiplied float RGBA image, as bytes (see :func:`write_png`)."""
    rgba = to_rgba8(image, background)
    h, w, _ = rgba.shape
    if h < 1 or w < 1:
        raise ValueError(f"a PNG needs at least one pixel, got an image of shape {rgba.shape}")
    raw = b"".join(b"\x00" + rgba[i].tobytes() for i in range(h))

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, level)) + chunk(b"IEND", b"")
    return png


def rmse(a: ArrayLike, b: ArrayLike) -> float:
    """Root-mean-square difference of premultiplied RGB."""
    x, y = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if x.shape != y.shape or x.ndim < 1 or x.shape[-1] < 3 or x.size == 0:
        raise ValueError(f"images must have the same shape (..., 3 or 4), got {x.shape} and {y.shape}")
    d = x[..., :3] - y[..., :3]
    return float(np.sqrt(np.mean(d * d)))


def psnr(a: ArrayLike, b: ArrayLike) -> float:
    """Peak signal-to-noise ratio (dB, peak 1) of premultiplied RGB; inf if identical."""
    e = rmse(a, b)
    return float("inf") if e == 0 else float(20.0 * np.log10(1.0 / e))

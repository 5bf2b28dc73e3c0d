"""Frames written out: a folder of PNGs, or one video file through imageio."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Iterable, Sequence

from numpy.typing import ArrayLike

from tetvr.core.image import to_rgba8, write_png

__all__ = ["VIDEO_SUFFIXES", "write_frames"]

#: Output suffixes written as one video file (imageio; mp4/webm/mkv/mov/avi need imageio-ffmpeg).
VIDEO_SUFFIXES = (".mp4", ".webm", ".mkv", ".mov", ".avi", ".gif")


def write_frames(images: Iterable[ArrayLike], out: str | os.PathLike[str], *,
                 background: Sequence[float] | None = (1.0, 1.0, 1.0), fps: float = 12.0,
                 prefix: str = "frame_") -> list[Path]:
    """Write images as ``out/frame_0000.png``, ... (a folder), or as one video when
    ``out`` ends in a :data:`VIDEO_SUFFIXES` suffix. Returns the files written."""
    out = Path(out)
    if out.suffix.lower() in VIDEO_SUFFIXES:
        return [_write_video(images, out, background, fps)]
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} exists and is not a folder; give a folder for PNG frames or a video file "
                         f"({', '.join(VIDEO_SUFFIXES)})")
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for i, image in enumerate(images):
        path = out / f"{prefix}{i:04d}.png"
        write_png(image, path, background=background)
        written.append(path)
    return written


def _write_video(images: Iterable[ArrayLike], out: Path, background: Sequence[float] | None, fps: float) -> Path:
    try:
        import imageio.v2 as imageio
    except ImportError:
        raise ImportError(f"writing {out.suffix} needs imageio (and imageio-ffmpeg for video): "
                          "pip install imageio imageio-ffmpeg; or give a folder for PNG frames") from None
    if out.suffix.lower() != ".gif":
        try:
            import imageio_ffmpeg  # noqa: F401
        except ImportError:
            raise ImportError(f"writing {out.suffix} needs imageio-ffmpeg: pip install imageio-ffmpeg; "
                              "or write a .gif, or a folder of PNG frames") from None
    out.parent.mkdir(parents=True, exist_ok=True)
    bg = (1.0, 1.0, 1.0) if background is None and out.suffix.lower() != ".gif" else background
    kw: dict[str, Any] = {"duration": 1.0 / fps, "loop": 0} if out.suffix.lower() == ".gif" else {"fps": fps, "macro_block_size": 1}
    with imageio.get_writer(out, **kw) as writer:
        for image in images:
            rgba = to_rgba8(image, bg)
            writer.append_data(rgba if out.suffix.lower() == ".gif" else rgba[..., :3])  # type: ignore[attr-defined]
    return out

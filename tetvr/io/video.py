"""Frames written out: a folder of PNGs, or one video file through imageio."""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any, Iterable, Sequence

from numpy.typing import ArrayLike

from tetvr.core.image import to_rgba8, write_png
from tetvr.core.outputs import check_outputs, check_outputs_in, check_writable, check_writable_folder

__all__ = ["VIDEO_SUFFIXES", "check_frames_output", "write_frames"]

#: Output suffixes written as one video file (imageio; mp4/webm/mkv/mov/avi need imageio-ffmpeg).
VIDEO_SUFFIXES = (".mp4", ".webm", ".mkv", ".mov", ".avi", ".gif")


def write_frames(images: Iterable[ArrayLike], out: str | os.PathLike[str], *,
                 background: Sequence[float] | None = (1.0, 1.0, 1.0), fps: float = 12.0,
                 prefix: str = "frame_", inputs: Iterable[tuple[str, str | os.PathLike[str]]] = ()) -> list[Path]:
    """Write images as ``out/frame_0000.png``, ... (a folder), or as one video when
    ``out`` ends in a :data:`VIDEO_SUFFIXES` suffix. Returns the files written.

    ``out`` is checked (:func:`check_frames_output`) against ``inputs``, ``(what, path)``
    pairs of the files the frames are made from, before the first image is taken from
    ``images`` (which may render each frame as it is asked for)."""
    out = check_frames_output(out, inputs, by="write_frames", prefix=prefix)
    if out.suffix.lower() in VIDEO_SUFFIXES:
        return [_write_video(images, out, background, fps)]
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for i, image in enumerate(images):
        path = out / f"{prefix}{i:04d}.png"
        write_png(image, path, background=background)
        written.append(path)
    return written


def check_frames_output(out: str | os.PathLike[str], inputs: Iterable[tuple[str, str | os.PathLike[str]]] = (), *,
                        by: str = "this command", prefix: str = "frame_") -> Path:
    """``out`` as a Path, if frames may be written there (see :func:`write_frames`): a
    video file that is no input and no folder, or a folder (made if missing) holding no
    input under a frame's name (``frame_0000.png``, ...); either where files can be made.
    ``by`` names whose inputs they are in the message."""
    out = Path(out)
    inputs = list(inputs)
    if out.suffix.lower() in VIDEO_SUFFIXES:  # its folder is made if missing
        if out.is_dir():
            raise IsADirectoryError(f"the video {str(out)!r} is a directory; give a file name")
        check_outputs([("video", out)], inputs, by=by)
        check_writable(out, "video", make_folder=True)
        return out
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} exists and is not a folder; give a folder for PNG frames or a video file "
                         f"({', '.join(VIDEO_SUFFIXES)})")
    names = re.compile(re.escape(prefix) + r"\d{4,}\.png")
    check_outputs_in(out, names.fullmatch, "frames", inputs, by=by)  # type: ignore[arg-type]
    check_writable_folder(out, f"frames into {str(out)!r}")
    return out


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

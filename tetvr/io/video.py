"""Frames written out: a folder of PNGs, or one video file through imageio."""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.image import to_rgba8, write_png
from tetvr.core.outputs import check_outputs, check_outputs_in, check_writable, check_writable_folder

__all__ = ["VIDEO_SUFFIXES", "check_frames_output", "video_background", "write_frames"]

#: Output suffixes written as one video file (imageio; mp4/webm/mkv/mov/avi need imageio-ffmpeg).
VIDEO_SUFFIXES = (".mp4", ".webm", ".mkv", ".mov", ".avi", ".gif")


def write_frames(images: Iterable[ArrayLike], out: str | os.PathLike[str], *,
                 background: Sequence[float] | None = (1.0, 1.0, 1.0), fps: float = 12.0,
                 prefix: str = "frame_", inputs: Iterable[tuple[str, str | os.PathLike[str]]] = ()) -> list[Path]:
    """Write images as ``out/frame_0000.png``, ... (a folder), or as one video when
    ``out`` ends in a :data:`VIDEO_SUFFIXES` suffix. Returns the files written.

    ``out`` is checked (:func:`check_frames_output`) against ``inputs``, ``(what, path)``
    pairs of the files the frames are made from, before the first image is taken from
    ``images`` (which may render each frame as it is asked for). Each image is let go
    before the next is taken: a PNG is written, a video frame piped to ffmpeg (a GIF's are
    kept by Pillow, as 8-bit RGBA, until the file is closed). A video also
    takes 8-bit frames, ``uint8`` (H, W, 4) straight RGBA already composited over
    :func:`video_background` (:func:`~tetvr.core.image.to_rgba8`), written as given."""
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


def video_background(out: str | os.PathLike[str], background: Sequence[float] | None) -> Sequence[float] | None:
    """The background a video at ``out`` composites its frames over: ``background``, but
    white for None except in a GIF (the one format here with transparency).

    Examples
    --------
    >>> video_background("a.mp4", None), video_background("a.gif", None)
    ((1.0, 1.0, 1.0), None)
    """
    if background is None and Path(out).suffix.lower() != ".gif":
        return (1.0, 1.0, 1.0)
    return background


def _rgba8(image: ArrayLike, background: Sequence[float] | None) -> NDArray[np.uint8]:
    """A frame as 8-bit RGBA: a ``uint8`` one as given, a float one through :func:`to_rgba8`."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        return to_rgba8(img, background)
    if img.ndim != 3 or img.shape[2] != 4:
        raise ValueError(f"an 8-bit frame must be RGBA of shape (H, W, 4), got {img.shape}")
    return img


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
    bg = video_background(out, background)
    kw: dict[str, Any] = {"duration": 1.0 / fps, "loop": 0} if out.suffix.lower() == ".gif" else {"fps": fps, "macro_block_size": 1}
    with imageio.get_writer(out, **kw) as writer:
        for image in images:
            rgba = _rgba8(image, bg)
            image = None  # noqa: F841 - not held while the next frame is made
            writer.append_data(rgba if out.suffix.lower() == ".gif" else rgba[..., :3])  # type: ignore[attr-defined]
    return out

"""Images out: premultiplied float RGBA -> PNG, with no imaging dependency; files
written atomically; the memory an image of a given size may take, and the memory a spike
of temporaries leaves behind given back."""

from __future__ import annotations

import contextlib
import ctypes
import errno
import functools
import io
import os
import secrets
import stat
import struct
import sys
import zlib
from typing import IO, Any, Iterator, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["image_size", "write_png", "png_bytes", "to_rgba8", "composite_over", "psnr", "rmse",
           "atomic_output", "available_memory", "check_memory", "release_free_memory"]

#: Rows of a PNG converted at once: bounds the float64 temporaries of a large image.
_PNG_BLOCK_BYTES = 64 << 20


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


#: The background every picture tetvr writes is composited over unless told otherwise
#: (CLI, scene files, ``tetvr.plot``, the demos, the docs' pictures): white, as in print.
DEFAULT_BACKGROUND: tuple[float, float, float] = (1.0, 1.0, 1.0)


def write_png(image: ArrayLike, path: str | os.PathLike[str], *,
              background: Sequence[float] | None = DEFAULT_BACKGROUND) -> None:
    """Write a premultiplied float RGBA image (row 0 at the top) as an 8-bit PNG.

    ``background`` is composited under the image; ``None`` writes a translucent RGBA PNG.
    The file is written atomically (:func:`atomic_output`): a failure leaves any earlier
    file of that name as it was.
    """
    data = png_bytes(image, background=background)  # first: a rejected image leaves no file
    with atomic_output(path) as f:
        f.write(data)


def png_bytes(image: ArrayLike, background: Sequence[float] | None = DEFAULT_BACKGROUND, *, level: int = 6) -> bytes:
    """The PNG file of a premultiplied float RGBA image, as bytes (see :func:`write_png`)."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 4:
        raise ValueError(f"image must have shape (H, W, 4), got {img.shape}")
    h, w, _ = img.shape
    if h < 1 or w < 1:
        raise ValueError(f"a PNG needs at least one pixel, got an image of shape {img.shape}")
    # Converted a block of rows at a time: to_rgba8 holds ~200 bytes of float64 per pixel,
    # 50 GiB for a 16384 x 16384 image taken whole.
    rows = max(1, _PNG_BLOCK_BYTES // (w * 200))
    deflate = zlib.compressobj(level)
    idat = []
    for r0 in range(0, h, rows):
        rgba = to_rgba8(img[r0:r0 + rows], background)
        raw = np.zeros((rgba.shape[0], 1 + 4 * w), dtype=np.uint8)  # column 0: filter type 0 per row
        raw[:, 1:] = rgba.reshape(rgba.shape[0], 4 * w)
        idat.append(deflate.compress(raw.tobytes()))
    idat.append(deflate.flush())

    def chunk(tag: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
    png += chunk(b"IDAT", b"".join(idat)) + chunk(b"IEND", b"")
    return png


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str]) -> Iterator[IO[bytes]]:
    """A binary file to write ``path`` through, atomically: the bytes go to a temporary
    file in the same folder, which replaces ``path`` (``os.replace``) only when the block
    ends without an error; on an error it is removed and ``path`` is left as it was.

    Readers never see a half-written file, and a file that is also an input of the
    command (a hard link, say) is replaced, not written through.

    Two kinds of path are not renamed over:

    * A **symbolic link** is followed: the file it points to is replaced (atomically, as
      above), so the link survives and points at the new file.
    * A path that is **not a regular file** -- a FIFO, a device, ``/dev/stdout`` (a link
      to a pipe or a terminal) -- is written through: opened and written, all at once
      when the block ends without an error (nothing is written after an error). Opening
      a FIFO waits, as for any program, until a reader opens it.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "x.bin"
    >>> with atomic_output(out) as f:
    ...     _ = f.write(b"data")
    >>> out.read_bytes()
    b'data'
    """
    target = os.fspath(path)
    if isinstance(target, bytes):
        target = os.fsdecode(target)
    if not os.path.basename(target) or os.path.isdir(target):
        raise IsADirectoryError(f"cannot write {target!r}: it is a directory, not a file name")
    if _is_special(target):
        buffer = io.BytesIO()
        yield buffer
        with open(target, "wb") as f:
            f.write(buffer.getbuffer())
        return
    if os.path.islink(target):
        target = os.path.realpath(target)
    folder, name = os.path.split(target)
    folder = folder or "."
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"cannot write {target!r}: the folder {folder!r} does not exist")
    while True:
        tmp = os.path.join(folder, f".{name[:200]}.{secrets.token_hex(6)}.tmp")
        try:
            # 0o666 less the umask, as open() would make it (mkstemp's 0o600 would not).
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
            break
        except FileExistsError:  # pragma: no cover - 48 random bits
            continue
        except OSError as exc:  # said of the output, not of the hidden temporary file
            if exc.errno not in (errno.EACCES, errno.EPERM, errno.EROFS):
                raise
            why = "read-only file system" if exc.errno == errno.EROFS else "permission denied"
            raise PermissionError(f"cannot write {target!r}: the folder {folder!r} is not writable ({why}); "
                                  "choose another folder, or make it writable") from None
    try:
        with os.fdopen(fd, "wb") as f:
            yield f
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _is_special(path: str) -> bool:
    """Whether ``path`` (links followed) exists and is neither a regular file nor a folder."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def available_memory() -> int | None:
    """Bytes of memory this process may still take without swapping or being killed, as
    far as the system tells (Linux: ``MemAvailable``, within a cgroup's limit), or None."""
    found: list[int] = []
    with contextlib.suppress(OSError, ValueError, IndexError):
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    found.append(int(line.split()[1]) * 1024)
                    break
    # A container's own limit (cgroup v2, then v1) is often far below the machine's.
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        with contextlib.suppress(OSError, ValueError):
            with open(limit_file) as f:
                limit = f.read().strip()
            if limit != "max" and int(limit) < 1 << 60:
                with open(usage_file) as f:
                    found.append(max(int(limit) - int(f.read().strip()), 0))
            break
    if not found:
        with contextlib.suppress(AttributeError, ValueError, OSError):
            found.append(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    return min(found) if found else None


def check_memory(need: int, what: str) -> None:
    """Raise ``MemoryError`` naming ``what`` and the sizes if ``need`` bytes are more than
    :func:`available_memory` (nothing is checked where the system does not say)."""
    have = available_memory()
    if have is not None and need > have:
        raise MemoryError(f"{what} needs about {_gib(need)} of memory; {_gib(have)} is available")


def release_free_memory() -> bool:
    """Give the C heap's free pages back to the system (glibc's ``malloc_trim``; elsewhere
    nothing), and say whether any were. numpy takes arrays of up to 32 MB from the heap,
    and glibc keeps the pages they leave free resident (up to 64 MB at the top of each
    thread's arena, and every free page between live blocks); a later array of more than
    32 MB, or the GL's textures, cannot use them. Called once after a spike of temporaries
    (a new mesh's walk check and records), not per frame, as Dask advises for its workers.

    >>> isinstance(release_free_memory(), bool)
    True
    """
    trim = _malloc_trim()
    return bool(trim(0)) if trim is not None else False


@functools.lru_cache(maxsize=1)
def _malloc_trim() -> Any:
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL("libc.so.6").malloc_trim  # glibc; musl has no malloc_trim
    except (OSError, AttributeError):
        return None


def _gib(n: float) -> str:
    return f"{n / 2**30:.3g} GiB" if n >= 2**30 else f"{n / 2**20:.3g} MiB"


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

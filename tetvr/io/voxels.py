"""What a volume file's header claims, checked against what the file holds.

A header is a claim, not a fact: every size it declares is checked, before anything of
that size is allocated (by numpy here or by ITK in :mod:`tetvr.io.volume_file`), against what
the file can hold (its bytes; 1032 times its bytes for deflate data, the most deflate can
compress) and against this machine's memory. Compressed data are inflated no further
than the declared size, and a pattern of data file names is counted before a name is
built. The readers in :mod:`tetvr.io.volume_file` and :mod:`tetvr.io.volume_vtk` share these.
"""

from __future__ import annotations

import bz2
import lzma
import math
import os
import stat
import zlib
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.core.checks import check_input_file
from tetvr.volume.volume import Volume

# deflate (zlib, gzip) never compresses by more than 1032:1 (RFC 1951's longest match
# costs at least 2 bits per 258 bytes), so deflate data of n bytes hold at most 1032 n.
_DEFLATE_MAX_RATIO = 1032


def _is_dir(p: Path) -> bool:
    try:
        return stat.S_ISDIR(os.stat(p).st_mode)
    except (OSError, ValueError):
        return False  # check_input_file says why


def _to_space(vol: Volume, space: str) -> Volume:
    return vol.in_space(space) if vol.space and vol.space != space else vol


def _check_file(path: Path, what: str) -> Path:
    return Path(check_input_file(path, what))


def _dims(value: Any, name: str = "dims") -> tuple[int, int, int]:
    try:
        dims = tuple(int(v) for v in value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be 3 positive integers (nx, ny, nz), got {value!r}") from None
    if len(dims) != 3 or any(d < 1 for d in dims) or tuple(float(v) for v in value) != tuple(map(float, dims)):
        raise ValueError(f"{name} must be 3 positive integers (nx, ny, nz), got {value!r}")
    return dims  # type: ignore[return-value]


def _from_bytes(buf: bytes, dtype: np.dtype[Any], dims: tuple[int, int, int], what: str) -> NDArray[Any]:
    nx, ny, nz = dims
    need = nx * ny * nz * dtype.itemsize
    if len(buf) != need:
        raise ValueError(
            f"{what} holds {len(buf)} bytes of voxel data, but dims {dims} x {dtype.name} "
            f"({dtype.itemsize} bytes) need {need}"
        )
    arr = np.frombuffer(buf, dtype=dtype).reshape(nz, ny, nx)
    return arr.astype(dtype.newbyteorder("="), copy=True)


def _next_line(raw: bytes, pos: int) -> tuple[str, int]:
    """The line of ``raw`` starting at ``pos`` (latin-1, without its ``\\r\\n``), and where the next begins."""
    end = raw.find(b"\n", pos)
    end = len(raw) if end < 0 else end
    return raw[pos:end].decode("latin-1").rstrip("\r"), end + 1


def _size_text(nbytes: int) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes} bytes"


def _memory_limit() -> int:
    """This machine's physical memory in bytes: no volume larger than it can be read."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - platforms without sysconf
        return 1 << 40


def _check_declared(dims: Sequence[int], dtype: np.dtype[Any], what: str, *, holds: int | None = None,
                    how: str = "") -> int:
    """The bytes that ``dims`` voxels of ``dtype`` take, if the file can hold them (``holds``
    bytes at most, ``how`` says why) and this machine's memory can; else a ValueError
    naming the declared dimensions. Called before anything of that size is allocated."""
    n = math.prod(int(d) for d in dims) * dtype.itemsize
    declared = f"{what} declares {' x '.join(str(int(d)) for d in dims)} voxels of {dtype.name} ({_size_text(n)})"
    if holds is not None and n > holds:
        raise ValueError(f"{declared}, but its data{how} can hold at most {_size_text(holds)}: "
                         "the header is wrong or the data are truncated")
    limit = _memory_limit()
    if n > limit:
        raise ValueError(f"{declared}, more than this machine's memory ({_size_text(limit)})")
    return n


def _inflate(data: bytes, codec: str, limit: int, what: str) -> bytes:
    """Decompress ``data`` (``zlib``, ``gzip``, ``bz2`` or ``lzma``) to at most ``limit``
    bytes, the size its header declares: a bomb stops there instead of filling memory."""
    return b"".join(_inflate_pieces(data, codec, limit, what))


def _check_inflates_to(data: bytes, codec: str, size: int, what: str) -> None:
    """Check that ``data`` inflate to exactly ``size`` bytes, holding a few MiB at a time:
    the guard run before a library inflates them into a buffer of the declared size."""
    got = sum(len(piece) for piece in _inflate_pieces(data, codec, size, what))
    if got != size:
        raise ValueError(f"{what}: the {codec} data inflate to {got} bytes, but the header declares {size}")


def _inflate_pieces(data: bytes, codec: str, limit: int, what: str, step: int = 1 << 22) -> Iterator[bytes]:
    def new() -> Any:
        if codec == "zlib":
            return zlib.decompressobj()
        if codec == "gzip":
            return zlib.decompressobj(wbits=31)
        return bz2.BZ2Decompressor() if codec == "bz2" else lzma.LZMADecompressor()

    d, pending, total = new(), data, 0
    try:
        while True:
            piece = d.decompress(pending, min(step, limit + 1 - total))
            pending = getattr(d, "unconsumed_tail", b"")
            total += len(piece)
            if total > limit:
                raise ValueError(f"{what}: the {codec} data inflate to more than the {limit} bytes the header "
                                 "declares (a decompression bomb, or a header that understates the size)")
            if piece:
                yield piece
            if d.eof:
                # gzip and bzip2 files may hold several members one after the other.
                if codec in ("gzip", "bz2") and d.unused_data.strip(b"\x00"):
                    d, pending = new(), d.unused_data
                    continue
                return
            if not piece and not pending and getattr(d, "needs_input", True):
                raise ValueError(f"{what}: the {codec} data end before their end-of-stream marker "
                                 f"({total} of {limit} bytes inflated): the file is truncated")
    except (zlib.error, OSError, EOFError, lzma.LZMAError) as exc:
        raise ValueError(f"{what}: the {codec} data cannot be inflated ({exc})") from None


def _header_int(fields: dict[str, str], key: str, fmt: str, fname: str, *, shown: str | None = None,
                minimum: int | None = None, default: int | None = None) -> int:
    """Field ``key`` of a NRRD/MetaImage header as an integer; errors name the field and the file."""
    shown = shown or key
    if key not in fields:
        if default is not None:
            return default
        raise ValueError(f"{fmt} file {fname!r} has no '{shown}' field")
    try:
        value = int(fields[key])
    except ValueError:
        raise ValueError(f"{fmt} file {fname!r}: field '{shown}' must be an integer, got {fields[key]!r}") from None
    if minimum is not None and value < minimum:
        raise ValueError(f"{fmt} file {fname!r}: field '{shown}' must be >= {minimum}, got {value}")
    return value


def _header_numbers(text: str, key: str, fmt: str, fname: str, kind: type = float) -> list[Any]:
    try:
        return [kind(v) for v in text.replace(",", " ").split()]
    except ValueError:
        what = "integers" if kind is int else "numbers"
        raise ValueError(f"{fmt} file {fname!r}: field '{key}' must be {what}, got {text!r}") from None


def _pattern_names(pattern: str, lo: int, hi: int, step: int, count_needed: int, fmt: str, field: str,
                   fname: str, needed_by: str) -> list[str]:
    """The data file names ``pattern % i`` for i from ``lo`` to ``hi`` by ``step``: counted
    (without building any) against the ``count_needed`` the sizes imply, before they are made."""
    if step == 0:
        raise ValueError(f"{fmt} file {fname!r}: field '{field}' has step 0")
    count = len(range(lo, hi + (1 if step > 0 else -1), step))
    if count != count_needed:
        raise ValueError(f"{fmt} file {fname!r}: field '{field}' names {count} files ({lo} to {hi} by {step}), "
                         f"but {needed_by} need {count_needed}")
    try:
        return [pattern % i for i in range(lo, hi + (1 if step > 0 else -1), step)]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{fmt} file {fname!r}: field '{field}' has a bad file name pattern {pattern!r} ({exc})") from None


def _existing_data_files(header: Path, names: list[str], what: str) -> list[Path]:
    """The data files ``names`` (relative to ``header``'s folder); each must be a regular file."""
    return [Path(check_input_file(header.parent / n, f"{what} data file", named_by=header.name)) for n in names]


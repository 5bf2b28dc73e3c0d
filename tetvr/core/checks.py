"""Argument checks shared by the public entry points."""

from __future__ import annotations

import errno
import os
import stat
import sys
import warnings
from typing import Any

__all__ = ["check_input_file", "check_instances", "short_path", "warn"]

# The tetvr package folder (this file is tetvr/core/checks.py).
_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep


def warn(message: str, category: type[Warning] = UserWarning) -> None:
    """``warnings.warn`` attributed to the first caller outside tetvr: the file and line a
    warning shows are the user's (their script, their notebook cell), never tetvr's own."""
    level = 2
    frame: Any = sys._getframe(1)
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_PACKAGE):
        frame, level = frame.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)


def check_instances(**named: tuple[object, type]) -> None:
    """Raise ``TypeError("NAME must be a CLS, got TYPE")`` for the first argument that is
    not an instance of its class, e.g. ``check_instances(camera=(camera, Camera))``."""
    for name, (value, cls) in named.items():
        if not isinstance(value, cls):
            raise TypeError(f"{name} must be a {cls.__name__}, got {type(value).__name__}")


def short_path(name: str, keep: int = 120) -> str:
    """``name`` for a message: whole if short, else its start and end around ``...``."""
    return name if len(name) <= keep else f"{name[:keep // 2]}...{name[-keep // 2:]} ({len(name)} characters)"


_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))


def check_input_file(path: str | os.PathLike[str], what: str, *, named_by: str = "") -> str:
    """``path`` as a str if it names a regular file, else an error that says truthfully why not.

    ``FileNotFoundError`` when nothing is there (or a symbolic link points nowhere);
    ``ValueError`` for a directory, a FIFO, socket or device, a loop of symbolic links, a
    name or path longer than the file system allows. The file is only ``stat``-ed, never
    opened, so a FIFO cannot block. ``what`` names the file's role ("mesh file");
    ``named_by`` (a header file's name) is added to the message.

    Examples
    --------
    >>> check_input_file("/nonexistent/mesh.vtu", "mesh file")
    Traceback (most recent call last):
    FileNotFoundError: mesh file not found: '/nonexistent/mesh.vtu'
    """
    name = os.fspath(path)
    if isinstance(name, bytes):
        name = os.fsdecode(name)
    by = f" (named by {named_by!r})" if named_by else ""
    shown = short_path(name)
    try:
        st = os.stat(name)
    except (FileNotFoundError, NotADirectoryError) as exc:
        if os.path.islink(name):
            raise FileNotFoundError(f"{what} not found: {shown!r} is a symbolic link to "
                                    f"{os.readlink(name)!r}, which does not exist{by}") from None
        if isinstance(exc, NotADirectoryError):
            raise FileNotFoundError(f"{what} not found: {shown!r} (a part of the path is a file, "
                                    f"not a directory){by}") from None
        raise FileNotFoundError(f"{what} not found: {shown!r}{by}") from None
    except OSError as exc:
        raise ValueError(f"cannot read {what} {shown!r}{by}: {_os_reason(exc, name)}") from exc
    if stat.S_ISDIR(st.st_mode):
        raise ValueError(f"cannot read {what} {shown!r}{by}: it is a directory")
    if not stat.S_ISREG(st.st_mode):
        kind = next((k for test, k in _KINDS if test(st.st_mode)), "a special file")
        raise ValueError(f"cannot read {what} {shown!r}{by}: it is {kind}, not a regular file")
    return name


def _os_reason(exc: OSError, name: str) -> str:
    if exc.errno == errno.ELOOP:
        return "its symbolic links form a loop (too many levels of symbolic links)"
    if exc.errno == errno.ENAMETOOLONG:
        longest = max((len(os.fsencode(part)) for part in name.split(os.sep)), default=0)
        name_max, path_max = _limit("PC_NAME_MAX", 255), _limit("PC_PATH_MAX", 4096)
        if longest > name_max:
            return (f"the file name is too long (one part of the path has {longest} bytes; "
                    f"the file system allows {name_max})")
        return f"the path is too long ({len(os.fsencode(name))} bytes; the system allows {path_max})"
    if isinstance(exc, PermissionError):
        return "permission denied"
    return f"{exc.strerror or type(exc).__name__}"


def _limit(key: str, default: int) -> int:
    try:
        return int(os.pathconf("/", key))
    except (OSError, ValueError):  # pragma: no cover - platforms without pathconf
        return default

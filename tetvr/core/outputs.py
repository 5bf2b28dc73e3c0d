"""The checks every entry point that writes files runs before its work.

An output is compared with the inputs as files (``os.path.samefile``), so hard links,
symbolic links and other spellings of one file count, and two outputs may not be one
file; an output's folder must exist (or be one the entry point makes) and be writable.
All of it is checked before anything is read or rendered, so a refused call costs
nothing and leaves every file as it was. The command line (:mod:`tetvr.apps.cli`),
:func:`tetvr.cluster.timeseries.render_series`, :func:`tetvr.apps.animate.animate`,
:func:`tetvr.io.video.write_frames` and :meth:`tetvr.scene.scene.Scene.save` share them.
How the bytes then go to the file (atomically, or through a FIFO) is
:func:`tetvr.core.image.atomic_output`'s.

Examples
--------
>>> check_outputs([("PNG", "/nonexistent/out.png")], [("mesh file", "/nonexistent/mesh.vtu")])
>>> check_writable("/nonexistent/folder/out.png", "PNG")
Traceback (most recent call last):
FileNotFoundError: cannot write the PNG '/nonexistent/folder/out.png': its folder '/nonexistent/folder' does not exist; create it first, or choose another folder
"""

from __future__ import annotations

import os
import stat
from typing import Callable, Iterable, Sequence, Union

from tetvr.core.checks import short_path

__all__ = ["check_outputs", "check_outputs_in", "check_writable", "check_writable_folder", "same_file"]

PathLike = Union[str, "os.PathLike[str]"]
#: ``(what, path)`` pairs: "mesh file", "PNG", ... and the file.
Named = Iterable[tuple[str, PathLike]]


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether ``a`` and ``b`` name one existing file (links and other spellings count)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # either one missing (a new output is no input), or a bad name
        return False


def _shown(path: PathLike) -> str:
    name = os.fspath(path)
    return short_path(os.fsdecode(name) if isinstance(name, bytes) else name)


def check_outputs(outputs: Sequence[tuple[str, PathLike]], inputs: Named, *, by: str = "this command") -> None:
    """``ValueError`` if an output file is one of the inputs, or two outputs are one file.

    ``by`` names whose inputs they are in the message ("this command", "render_series").
    Two outputs that are one character device (``/dev/null``) are allowed.
    """
    inputs = list(inputs)
    for label, out in outputs:
        for in_label, src in inputs:
            if same_file(out, src):
                raise ValueError(f"refusing to write the {label} {_shown(out)!r} over the {in_label} {_shown(src)!r}, "
                                 f"an input of {by}; choose another output path")
    for i, (label_a, a) in enumerate(outputs):
        for label_b, b in outputs[i + 1:]:
            if _is_device(a):
                continue
            if os.path.realpath(a) == os.path.realpath(b) or same_file(a, b):
                raise ValueError(f"the {label_a} and the {label_b} are the same file {_shown(a)!r}; "
                                 "give each output its own name")


def check_outputs_in(folder: PathLike, written: Callable[[str], bool], what: str, inputs: Named, *,
                     by: str = "this command") -> None:
    """``ValueError`` if a file in ``folder`` under a name ``written`` says is written there
    is one of the inputs (the input itself, or a link to it)."""
    try:
        names = [e.name for e in os.scandir(folder) if written(e.name)]
    except OSError:  # no folder yet (it is made), or not one (the writer says so)
        return
    inputs = list(inputs)
    for name in names:
        for in_label, src in inputs:
            if same_file(os.path.join(folder, name), src):
                via = "" if os.path.basename(src) == name else f" (as {name!r} there)"
                raise ValueError(f"refusing to write {what} into {_shown(folder)!r}: it would overwrite the {in_label} "
                                 f"{_shown(src)!r}{via}, an input of {by}; choose another folder")


def check_writable(path: PathLike, what: str, *, make_folder: bool = False) -> None:
    """Fail before the work, not after it, if ``path`` cannot be written.

    ``IsADirectoryError`` if ``path`` names a folder; ``FileNotFoundError`` if its folder
    does not exist (unless ``make_folder``: then the nearest folder that exists must be
    writable); ``PermissionError`` if the folder is not writable, or ``path`` is a FIFO or
    a device (written through, not replaced: :func:`tetvr.core.image.atomic_output`) that
    is not writable. A symbolic link is checked where it points.
    """
    name = os.fsdecode(os.fspath(path))
    if not os.path.basename(name) or os.path.isdir(name):
        raise IsADirectoryError(f"the {what} {_shown(name)!r} is a directory; give a file name")
    try:
        mode = os.stat(name).st_mode
    except OSError:
        mode = 0
    if mode and not stat.S_ISREG(mode):  # a FIFO, a device, /dev/stdout: written through
        if not os.access(name, os.W_OK):
            raise PermissionError(f"cannot write the {what} {_shown(name)!r}: it is a special file (FIFO or device) "
                                  "you may not write to; choose another output path")
        return
    real = os.path.realpath(name) if os.path.islink(name) else os.path.abspath(name)
    via = f" (where the symbolic link {_shown(name)!r} points)" if real != os.path.abspath(name) else ""
    folder = os.path.dirname(real)
    if not os.path.isdir(folder) and not make_folder:
        raise FileNotFoundError(f"cannot write the {what} {_shown(name)!r}: its folder {_shown(folder)!r}{via} does not "
                                "exist; create it first, or choose another folder")
    check_writable_folder(folder, f"the {what} {_shown(name)!r}{via}")


def check_writable_folder(folder: PathLike, what: str) -> None:
    """``PermissionError`` if files cannot be made in ``folder`` (or, where it does not
    exist yet, in the nearest folder above it that does); ``NotADirectoryError`` if that
    is a file. ``what`` says what would be written ("the frames", "the PNG 'x.png'")."""
    here = os.path.abspath(os.fspath(folder))
    while not os.path.exists(here) and os.path.dirname(here) != here:
        here = os.path.dirname(here)
    if not os.path.isdir(here):
        raise NotADirectoryError(f"cannot write {what}: {_shown(here)!r} is a file, not a folder; "
                                 "choose another folder")
    if not os.access(here, os.W_OK | os.X_OK):
        raise PermissionError(f"cannot write {what}: the folder {_shown(here)!r} is not writable "
                              f"({_why_unwritable(here)}); choose another folder, or make it writable")


def _why_unwritable(folder: str) -> str:
    try:
        if os.statvfs(folder).f_flag & os.ST_RDONLY:
            return "it is on a read-only file system"
    except (OSError, AttributeError):  # pragma: no cover - platforms without statvfs
        pass
    return "permission denied"


def _is_device(path: PathLike) -> bool:
    try:
        return stat.S_ISCHR(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False

"""The command line's inputs and outputs: which files a command reads, and the checks that
keep its outputs off its inputs (compared as files, so links and other spellings count)
and fail before the work when an output cannot be written."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

#: Nothing public: the commands' own helpers (:mod:`tetvr.apps.cli.commands`).
__all__: list[str] = []


def _same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # either one missing (a new output is no input), or a bad name
        return False


def _refuse_overwrite(outputs: Sequence[tuple[str, str | os.PathLike[str]]],
                      inputs: Iterable[tuple[str, str | os.PathLike[str]]]) -> None:
    """``ValueError`` if an output file is one of the inputs, or two outputs are one file."""
    inputs = list(inputs)
    for label, out in outputs:
        for in_label, src in inputs:
            if _same_file(out, src):
                raise ValueError(f"refusing to write the {label} {os.fspath(out)!r} over the {in_label} "
                                 f"{os.fspath(src)!r}, an input of this command; choose another output path")
    for i, (label_a, a) in enumerate(outputs):
        for label_b, b in outputs[i + 1:]:
            if os.path.realpath(a) == os.path.realpath(b) or _same_file(a, b):
                raise ValueError(f"the {label_a} and the {label_b} are the same file {os.fspath(a)!r}")


def _refuse_overwrite_in(folder: str | os.PathLike[str], written: Callable[[str], bool], label: str,
                         inputs: Iterable[tuple[str, str | os.PathLike[str]]]) -> None:
    """``ValueError`` if an input lies in ``folder`` under a name the command writes there."""
    for in_label, src in inputs:
        parent = os.path.dirname(os.path.abspath(src))
        if written(os.path.basename(src)) and _same_file(parent, folder):
            raise ValueError(f"refusing to write {label} into {os.fspath(folder)!r}: it would overwrite the "
                             f"{in_label} {os.fspath(src)!r}, an input of this command; choose another folder")


def _check_writable(path: str | os.PathLike[str], label: str) -> None:
    """Fail before the work, not after it: the output's folder must exist and the name
    must not be a folder."""
    if os.path.isdir(path):
        raise IsADirectoryError(f"the {label} {os.fspath(path)!r} is a directory; give a file name")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"cannot write the {label} {os.fspath(path)!r}: the folder {folder!r} does not exist")


def _scene_inputs(scene_path: str | os.PathLike[str], scene: Any) -> list[tuple[str, str]]:
    return [("scene file", os.fspath(scene_path))] + [("mesh file", p) for p in scene.input_paths()]


def _series_inputs(series: Sequence[str] | None) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    for name in series or ():
        out.append(("time-series file", name))
        if Path(name).suffix.lower() in (".xdmf", ".xmf"):
            out += [("time-series data file", p) for p in _xdmf_data_files(name)]
    return out


def _xdmf_data_files(path: str) -> list[str]:
    """The HDF5 files an XDMF file's data items name (``file.h5:/dataset``), best effort:
    an unreadable XDMF file is the reader's to report."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError, ValueError):
        return []
    folder = os.path.dirname(os.path.abspath(path))
    files = set()
    for item in root.iter():
        if item.tag.rsplit("}", 1)[-1] == "DataItem" and item.get("Format", "").upper() == "HDF" and item.text:
            files.add(os.path.join(folder, item.text.strip().split(":", 1)[0]))
    return sorted(files)


def _npy_path(npy: str) -> str:
    return npy if npy.endswith(".npy") else npy + ".npy"  # where np.save(name) would write


def _step_name(pattern: str, label: str, index: int, t: float, n_steps: int) -> str:
    """``pattern`` with ``{time}`` and ``{index}`` filled in; one name per step required."""
    if n_steps > 1 and not any(k in pattern for k in ("{time", "{index")):
        raise ValueError(f"the scene's .pvd has {n_steps} time steps: put {{time}} or {{index}} in the {label} "
                         f"name (e.g. frame_{{time}}.png) to write one file per step, got {pattern!r}")
    try:
        return pattern.format(time=t, index=index)
    except (KeyError, IndexError, ValueError) as exc:
        raise ValueError(f"the {label} name {pattern!r} may use only {{time}} and {{index}} fields: {exc}") from None

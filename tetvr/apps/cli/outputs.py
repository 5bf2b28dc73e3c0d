"""The command line's inputs and outputs: which files a command reads (the checks that keep
its outputs off them and fail before the work when an output cannot be written are
:mod:`tetvr.core.outputs`, shared with the API), the names of its outputs, and where its
report line goes."""

from __future__ import annotations

import io
import os
import sys
from typing import Any, Sequence, TextIO

from tetvr.io.series import series_input_paths

#: Nothing public: the commands' own helpers (:mod:`tetvr.apps.cli.commands`).
__all__: list[str] = []


def _scene_inputs(scene_path: str | os.PathLike[str], scene: Any) -> list[tuple[str, str]]:
    return [("scene file", os.fspath(scene_path))] + [("mesh file", p) for p in scene.input_paths()]


def _series_inputs(series: str | Sequence[str] | None) -> list[tuple[str, str]]:
    """The files ``--time-series`` reads (its globs expanded: :func:`commands._expand_series`)."""
    return series_input_paths(series or ())


def _report_stream(*paths: str | None) -> TextIO:
    """Where a command's report line goes: stdout, unless an output is stdout itself
    (``-o /dev/stdout``), where the line would end up inside the file; then stderr."""
    try:
        out = os.fstat(sys.stdout.fileno())
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):  # captured, closed, replaced
        return sys.stdout
    for path in paths:
        try:
            if path is not None and os.path.samestat(os.stat(path), out):
                return sys.stderr
        except (OSError, ValueError):
            continue
    return sys.stdout


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

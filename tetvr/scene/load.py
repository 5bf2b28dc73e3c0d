"""One entry for a scene file of either kind: tetvr's scene JSON (:mod:`tetvr.scene.scene`)
or a ParaView state (:mod:`tetvr.scene.paraview`)."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from tetvr.scene.paraview import load_state
from tetvr.scene.scene import Scene

__all__ = ["load_scene"]


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Read a scene JSON file (see the module docstring for the schema), or a ParaView
    state file (``.pvsm``, :func:`tetvr.scene.paraview.load_state`)."""
    if Path(path).suffix.lower() == ".pvsm":
        return load_state(path)  # type: ignore[no-any-return]
    if os.path.isdir(path):
        raise ValueError(f"{path}: is a directory, not a scene JSON file")
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f, object_pairs_hook=_no_duplicate_keys)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from exc
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON (not UTF-8 text: {exc})") from exc
    except RecursionError:
        raise ValueError(f"{path}: not a scene (JSON nested too deeply to read)") from None
    return Scene.from_dict(data, base_dir=Path(path).resolve().parent)


def _no_duplicate_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    # json.load keeps the last of repeated keys silently; a scene says one thing once.
    keys = [k for k, _ in pairs]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise ValueError(f"repeated keys {dup} in a scene object")
    return dict(pairs)

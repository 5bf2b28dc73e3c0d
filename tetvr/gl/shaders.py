"""Loading GLSL from the ``shaders/`` folder: ``#include`` + ``#define`` only.

Each included file is given its own GLSL source-string number with ``#line``, so a compile
error's ``N:LINE`` is translated back to ``file:line`` in the exception.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path
from typing import Mapping

__all__ = ["shader_dir", "assemble", "ShaderCompileError"]

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')


class ShaderCompileError(RuntimeError):
    """A shader failed to compile or link; the message names the file and line."""


@functools.lru_cache(maxsize=1)
def shader_dir() -> Path:
    """The shaders folder: inside the installed package, else the source checkout's."""
    here = Path(__file__).resolve().parent.parent
    for candidate in (here / "shaders", here.parent / "shaders"):
        if (candidate / "common.glsl").is_file():
            return candidate
    raise FileNotFoundError(f"tetvr's shaders were not found next to {here}; the installation is incomplete")


@functools.lru_cache(maxsize=64)
def _read(name: str) -> str:
    return (shader_dir() / name).read_text()


def assemble(name: str, defines: Mapping[str, int | float | str] | None = None) -> tuple[str, list[str]]:
    """Source of shader ``name`` with includes expanded and ``defines`` after ``#version``.

    Returns the source and the list of file names by GLSL source-string number.
    """
    files: list[str] = []
    out = _expand(name, files, set())
    lines = out.splitlines()
    if not lines or not lines[0].startswith("#version"):
        raise ShaderCompileError(f"{name}: the first line must be #version")
    extra = [f"#define {k} {v}" for k, v in (defines or {}).items()]
    # Put the defines after #version, and restore the line numbering of the main file.
    return "\n".join([lines[0], *extra, "#line 2 0", *lines[1:]]) + "\n", files


def _expand(name: str, files: list[str], stack: set[str]) -> str:
    if name in stack:
        raise ShaderCompileError(f"recursive #include of {name}")
    index = len(files)
    files.append(name)
    result: list[str] = []
    for lineno, line in enumerate(_read(name).splitlines(), start=1):
        m = _INCLUDE.match(line)
        if m:
            result.append(f"#line 1 {len(files)}")
            result.append(_expand(m.group(1), files, stack | {name}))
            result.append(f"#line {lineno + 1} {index}")
        else:
            result.append(line)
    return "\n".join(result)


def explain(error: Exception, files: list[str]) -> str:
    """Rewrite ``N:LINE(COL)`` / ``N(LINE)`` positions in a compiler log as ``file:LINE``."""

    def repl(m: re.Match[str]) -> str:
        idx, line = int(m.group(1)), m.group(2)
        return f"{files[idx] if idx < len(files) else idx}:{line}"

    text = str(error)
    text = re.sub(r"\b(\d+):(\d+)\(\d+\)", repl, text)  # Mesa: 0:12(5)
    return re.sub(r"\b(\d+)\((\d+)\)", repl, text)  # NVIDIA: 0(12)

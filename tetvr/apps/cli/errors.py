"""How a command line failure ends: the exit statuses (the table in :mod:`tetvr.apps.cli`)
and the one line ``tetvr: error: ...`` (or ``tetvr: warning: ...``) on stderr."""

from __future__ import annotations

import os
import sys
from typing import Any

__all__ = ["EXIT_OK", "EXIT_INTERNAL", "EXIT_USAGE", "EXIT_ENVIRONMENT", "EXIT_MEMORY", "EXIT_INTERRUPTED"]

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_ENVIRONMENT = 3
EXIT_MEMORY = 4
EXIT_INTERRUPTED = 130


class _UsageError(Exception):
    """Bad command-line arguments (argparse's complaint)."""


def _one_line(text: str) -> str:
    return "; ".join(line.strip() for line in text.splitlines() if line.strip())


def _classify(exc: BaseException) -> tuple[int, str]:
    """The exit status and message of a failure (the table in :mod:`tetvr.apps.cli`)."""
    text = _one_line(str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc))
    if isinstance(exc, _UsageError):
        return EXIT_USAGE, text
    if isinstance(exc, MemoryError):
        return EXIT_MEMORY, f"out of memory: {text}" if text else "out of memory"
    gl = sys.modules.get("moderngl")  # only if the GL package imported it: it is not ours to import
    if gl is not None and isinstance(exc, gl.Error):
        status = EXIT_MEMORY if "OUT_OF_MEMORY" in text else EXIT_ENVIRONMENT
        return status, f"OpenGL: {text}"
    if isinstance(exc, OSError):  # unreadable input, unwritable output
        if exc.filename is not None and exc.strerror and str(exc.filename) not in text:
            text = f"{exc.strerror}: {exc.filename!r}"
        return EXIT_USAGE, text
    if isinstance(exc, ImportError):  # an optional dependency (imageio, moderngl-window, vtk)
        return EXIT_ENVIRONMENT, text
    if isinstance(exc, (ValueError, KeyError, TypeError)):
        return EXIT_USAGE, text
    if isinstance(exc, RuntimeError) and not isinstance(exc, (RecursionError, NotImplementedError)):
        # GLUnavailableError, ShaderCompileError, GL errors after a frame, no display, no VTK
        return (EXIT_MEMORY if "OUT_OF_MEMORY" in text else EXIT_ENVIRONMENT), text
    if isinstance(exc, SystemExit):
        return EXIT_INTERNAL, f"internal error: a library tried to exit the program (status {exc.code!r})"
    return EXIT_INTERNAL, (f"internal error: {type(exc).__name__}: {text} (a bug in tetvr: please report it; "
                           "TETVR_TRACEBACK=1 shows the traceback)")


def _fail(status: int, message: str) -> int:
    if os.environ.get("TETVR_TRACEBACK") and sys.exc_info()[0] is not None:
        import traceback

        traceback.print_exc(file=sys.stderr)
    print(f"tetvr: error: {message}", file=sys.stderr)
    return status


def _show_warning(message: Any, category: Any, filename: str, lineno: int, file: Any = None, line: Any = None) -> None:
    # What happened, in the user's terms: no source file and line of tetvr's.
    print(f"tetvr: warning: {_one_line(str(message))}", file=sys.stderr)

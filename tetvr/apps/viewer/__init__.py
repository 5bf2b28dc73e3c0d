"""The interactive viewer: a front-end-free model, its render loop and worker process, the
transfer-function editor, and the Jupyter front end (``Viewer``)."""

from typing import Any

__all__ = ["Viewer"]


def __getattr__(name: str) -> Any:
    # The Jupyter front end imports jupyter_rfb; it loads only when asked for.
    if name == "Viewer":
        from tetvr.apps.viewer.jupyter import Viewer

        return Viewer
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

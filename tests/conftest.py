"""Shared fixtures: one GL renderer per module, the shared data folder, failure images."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

SHARED = Path(os.environ.get("TETVR_SHARED_DATA", Path(__file__).resolve().parents[1].parent / "shared" / "data"))
ARTIFACTS = Path(__file__).resolve().parent / "_failures"


def shared_file(rel: str) -> Path:
    """A file of ../shared/data, or skip the test with the reason."""
    path = SHARED / rel
    if not path.is_file():
        pytest.skip(f"shared data not available: {path} (clone with ../shared beside the repo)")
    return path


def gl_object(make: Callable[[], Any], what: str) -> Iterator[Any]:
    """Fixture body for a GL object with its own context: ``make()`` it (fail the test with
    ``what`` if there is no context), yield it, check that GL reported no error, release it."""
    from tetvr.gl import GLUnavailableError

    try:
        obj = make()
    except GLUnavailableError as exc:  # pragma: no cover - CI has Mesa's EGL
        pytest.fail(f"{what}: {exc}")
    yield obj
    from tetvr.gl.context import current_in_thread

    with current_in_thread(obj.ctx):  # the context is current nowhere between calls
        assert obj.ctx.error == "GL_NO_ERROR"
    obj.release()


@pytest.fixture(scope="module", params=["projected", "raymarch"])
def renderer(request):
    """A GL renderer of each method: every test that takes it runs for both."""
    from tetvr import RenderSettings
    from tetvr.gl import Renderer

    yield from gl_object(lambda: Renderer(RenderSettings(method=request.param)), "no OpenGL 4.3 context")


def save_failure(name: str, got: np.ndarray, want: np.ndarray) -> Path:
    """Write got / want / magnified |difference| PNGs for a failed image comparison."""
    from tetvr.core.image import write_png

    ARTIFACTS.mkdir(exist_ok=True)
    diff = np.abs(got.astype(np.float64) - want)
    scale = 1.0 / max(diff[..., :3].max(), 1e-12)
    mag = np.zeros_like(diff)
    mag[..., :3] = np.clip(diff[..., :3] * scale, 0, 1)
    mag[..., 3] = 1.0
    write_png(got, ARTIFACTS / f"{name}_gpu.png", background=(0, 0, 0))
    write_png(want, ARTIFACTS / f"{name}_reference.png", background=(0, 0, 0))
    write_png(mag, ARTIFACTS / f"{name}_diff_x{scale:.0f}.png", background=None)
    return ARTIFACTS

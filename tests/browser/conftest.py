"""Fixtures for the viewer's browser tests: JupyterLab and Chromium (tests/browser/lab.py),
each stopped by its finalizer."""

from __future__ import annotations

import pytest

from tests.browser.lab import missing, start_browser, start_lab, write_notebook
from tests.conftest import SHARED

POST = SHARED / "tets" / "post.vtk"
SIZE = (480, 360)
#: How long the second cell keeps the kernel busy.
BUSY_S = 8
#: Cells the tests run one by one after the viewer's: one that prints "busy", keeps the
#: kernel busy and asks for a frame 1 s into it; one that prints the number of frames drawn.
CELLS = ("import time\n"
         "print('busy', flush=True)\n"
         "time.sleep(1)  # from here on the kernel takes no message and runs no callback\n"
         "viewer.loop.update(lambda m: m.control.azimuth(30.0), final=True)\n"
         f"time.sleep({BUSY_S})",
         "viewer.loop.wait_idle(60)\nprint(f'frames drawn: {viewer.loop.frames}')")


@pytest.fixture(scope="session")
def lab(tmp_path_factory):
    """A JupyterLab server on 127.0.0.1 serving a notebook with the viewer on post.vtk (and
    :data:`CELLS` after it): yields the notebook's URL (with the token) and its path."""
    why = missing()
    if why:
        pytest.skip(why)
    if not POST.is_file():
        pytest.skip(f"shared data not available: {POST} (clone with ../shared beside the repo)")
    root = tmp_path_factory.mktemp("lab")
    write_notebook(root / "viewer.ipynb", f"from tetvr.apps.viewer import Viewer\nviewer = Viewer({str(POST)!r}, size={SIZE!r})\nviewer",
                   *CELLS)
    try:
        url, token, stop = start_lab(root)
    except RuntimeError as exc:
        pytest.fail(str(exc))
    try:
        yield f"{url}/lab/tree/viewer.ipynb?token={token}", root / "viewer.ipynb"
    finally:
        stop()


@pytest.fixture(scope="session")
def browser(lab, tmp_path_factory):
    """Headless Chromium (fresh profile, no network services) through the system chromedriver."""
    driver, stop = start_browser(tmp_path_factory.mktemp("chromium-profile"))
    try:
        yield driver
    finally:
        stop()

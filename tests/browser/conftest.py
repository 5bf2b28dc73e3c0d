"""Fixtures for the viewer's browser tests: JupyterLab and Chromium (tests/browser/lab.py),
each stopped by its finalizer."""

from __future__ import annotations

import pytest

from tests.browser.lab import missing, start_browser, start_lab, write_notebook
from tests.conftest import SHARED

POST = SHARED / "tets" / "post.vtk"
SIZE = (480, 360)


@pytest.fixture(scope="session")
def lab(tmp_path_factory):
    """A JupyterLab server on 127.0.0.1 serving a notebook with the viewer on post.vtk:
    yields the notebook's URL (with the token) and its path."""
    why = missing()
    if why:
        pytest.skip(why)
    if not POST.is_file():
        pytest.skip(f"shared data not available: {POST} (clone with ../shared beside the repo)")
    root = tmp_path_factory.mktemp("lab")
    write_notebook(root / "viewer.ipynb", f"from tetvr.apps.viewer import Viewer\nviewer = Viewer({str(POST)!r}, size={SIZE!r})\nviewer")
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

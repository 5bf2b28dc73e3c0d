"""Background work that nobody will use is not started, and never holds the process.

The records of tet marching are built in a background thread while the frame's table is
built. A mesh that ``method="auto"`` sends to projected tetrahedra by its size alone starts
no such build (10M tets' records passed 4.5 GB before being thrown away), and the thread is a
daemon: an interrupted script exits at once instead of waiting for a build it will not use.
"""

from __future__ import annotations

import threading

import pytest

import tetvr
import tetvr.gl.renderer as renderer_module
import tetvr.order.method as method_module
from tetvr import Camera, RenderSettings
from tetvr.gl import prefetch, raymarch
from tetvr.mesh import synthetic
from tetvr.render import default_transfer_function

pytestmark = pytest.mark.gl


def test_no_records_are_built_for_a_mesh_auto_sends_to_projected_tetrahedra(monkeypatch):
    mesh = synthetic.cube(3)
    too_large = lambda n_tets: n_tets < mesh.n_tets  # noqa: E731 - its records would not fit in memory
    monkeypatch.setattr(renderer_module, "march_fits", too_large)
    monkeypatch.setattr(method_module, "march_fits", too_large)
    started = []
    monkeypatch.setattr(raymarch, "Prefetch", lambda m: started.append(m))
    with tetvr.Renderer(RenderSettings()) as r:
        r.render(mesh, Camera.fit(mesh), default_transfer_function(mesh), size=(16, 16))
    assert started == []


def test_the_records_are_built_in_a_daemon_thread(monkeypatch):
    seen = []
    build = prefetch.records

    def records(mesh):
        seen.append(threading.current_thread())
        return build(mesh)

    monkeypatch.setattr(prefetch, "records", records)
    mesh = synthetic.cube(3)
    with tetvr.Renderer(RenderSettings()) as r:
        r.render(mesh, Camera.fit(mesh), default_transfer_function(mesh), size=(16, 16))
    assert seen and all(t.daemon and t is not threading.main_thread() for t in seen)

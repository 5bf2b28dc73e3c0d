"""A process forked from one that made a GL context refuses GL with a clear error.

llvmpipe's (and most drivers') threads do not survive ``fork``: a forked child used to hang
for ever in its first compute dispatch, even with a new Renderer. Every child here runs
under a timeout, so a regression fails the test instead of hanging it.
"""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tetvr import Camera, RenderSettings
from tetvr.mesh import synthetic
from tetvr.gl import Renderer
from tetvr.render import default_transfer_function

pytestmark = [pytest.mark.gl, pytest.mark.skipif(not hasattr(os, "fork"), reason="needs os.fork")]

TIMEOUT = 120
SETTINGS = RenderSettings(table_scalar_bins=32, table_thickness_slices=4)


def _scene() -> tuple[Any, Camera, Any]:
    mesh = synthetic.cube(2)
    return mesh, Camera.fit(mesh), default_transfer_function(mesh, opacity=0.6)


def _outcome(fn: Any) -> tuple[str, str, bool]:
    try:
        fn()
    except Exception as exc:  # noqa: BLE001 - reported to the parent
        return type(exc).__name__, str(exc), isinstance(exc, RuntimeError)
    return "ok", "", False


def _forked_child(conn: Any, inherited: Renderer) -> None:
    mesh, cam, tf = _scene()
    conn.send({
        "new renderer": _outcome(lambda: Renderer(SETTINGS).render(mesh, cam, tf, size=(8, 8))),
        "inherited render": _outcome(lambda: inherited.render(mesh, cam, tf, size=(8, 8))),
        "inherited release": _outcome(inherited.release),
        "cpu work": _outcome(lambda: inherited.table(mesh, tf)),
    })
    conn.close()


def _spawned_child(conn: Any) -> None:
    mesh, cam, tf = _scene()
    with Renderer(SETTINGS) as r:
        conn.send(r.render(mesh, cam, tf, size=(16, 16)))
    conn.close()


def _run(ctx: multiprocessing.context.BaseContext, target: Any, *args: Any) -> Any:
    """Run ``target(conn, *args)`` in a child of ``ctx``; what it sends, or fail on a hang."""
    recv, send = ctx.Pipe(duplex=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # Python >= 3.12: fork with threads
        proc = ctx.Process(target=target, args=(send, *args), daemon=True)
        proc.start()
    send.close()
    try:
        if not recv.poll(TIMEOUT):
            pytest.fail(f"the {ctx.get_start_method()} child sent nothing in {TIMEOUT} s (hung in GL?)")
        got = recv.recv()
        proc.join(TIMEOUT)
        assert proc.exitcode == 0, f"the child exited with {proc.exitcode}"
        return got
    finally:
        if proc.is_alive():
            proc.kill()
            proc.join()


def test_forked_child_refuses_gl_with_a_clear_error():
    mesh, cam, tf = _scene()
    with Renderer(SETTINGS) as r:
        r.render(mesh, cam, tf, size=(8, 8))  # the driver's threads are running now
        got = _run(multiprocessing.get_context("fork"), _forked_child, r)
        r.render(mesh, cam, tf, size=(8, 8))  # the parent is unaffected
    for what in ("new renderer", "inherited render"):
        name, message, is_runtime_error = got[what]
        assert name == "ForkedProcessError" and is_runtime_error, (what, got[what])
        assert "forked" in message and "'spawn'" in message and "'forkserver'" in message, message
        assert "multiprocessing.get_context('spawn')" in message, message
    assert got["inherited release"][0] == "ok", got["inherited release"]  # drops its references, no GL
    assert got["cpu work"][0] == "ok", got["cpu work"]  # what needs no GL still works


def test_spawned_child_renders_the_same_image():
    mesh, cam, tf = _scene()
    with Renderer(SETTINGS) as r:
        want = r.render(mesh, cam, tf, size=(16, 16))
        got = _run(multiprocessing.get_context("spawn"), _spawned_child)
    assert np.array_equal(got, want)


def test_fork_before_any_context_is_not_refused():
    # The guard is armed by the first context, not by importing tetvr.
    code = textwrap.dedent("""
        import os, sys
        from tetvr.gl.context import create_context
        pid = os.fork()
        if pid == 0:
            code = 3
            try:
                create_context().release()
                code = 0
            finally:
                os._exit(code)
        _, status = os.waitpid(pid, 0)
        sys.exit(os.waitstatus_to_exitcode(status))
    """)
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True, text=True, timeout=TIMEOUT)
    assert proc.returncode == 0, proc.stderr

"""One renderer, several threads: every frame equals the single-threaded frame, exactly.

An EGL context is current in one thread at a time, and a renderer's GL state (its
buffers, targets, bound programs) is one per renderer. Each public GL method therefore
holds the context's lock and makes the context current in the calling thread for the
call only. Before that, a second thread's frames were silently wrong (its
``eglMakeCurrent`` failed, its GL calls went nowhere, and ``ctx.error`` stayed clean).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.gl import Raycaster, Renderer
from tetvr.gl.context import current_in_thread
from tetvr.reference.volume import RaycastSettings
from tetvr.render import default_transfer_function
from tetvr.volume.volume import Volume

pytestmark = pytest.mark.gl

FRAMES = 20
SIZE = (32, 24)
SETTINGS = RenderSettings(table_scalar_bins=32, table_thickness_slices=8)


def _mesh_scene() -> tuple[Any, TransferFunction, list[Camera]]:
    mesh = synthetic.cube(3)
    tf = default_transfer_function(mesh, opacity=0.6)
    return mesh, tf, [Camera.fit(mesh), Camera.fit(mesh, direction=(1.0, 0.4, -0.7), zoom=1.3)]


def _volume_scene() -> tuple[Volume, TransferFunction, list[Camera]]:
    """A 12^3 distance field (shells of opacity), seen from two sides."""
    g = np.linspace(-1.0, 1.0, 12)
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    vol = Volume.from_array(np.sqrt(x**2 + y**2 + z**2).astype(np.float32), spacing=(2 / 11,) * 3,
                            origin=(-1.0, -1.0, -1.0))
    lo, hi = vol.scalar_range
    tf = TransferFunction.preset("viridis", (lo, hi), opacity=[(0.0, 0.9), (0.45, 0.05), (0.7, 0.4), (1.0, 0.0)],
                                 unit_distance=vol.diagonal / 8)
    cams = []
    for d in ((-1.0, -0.5, -0.8), (0.6, 1.0, -0.3)):
        d = np.asarray(d) / np.linalg.norm(d)
        dist = 6.0
        cams.append(Camera(position=tuple(-d * dist), focal_point=(0.0, 0.0, 0.0), view_up=(0.0, 0.0, 1.0),
                           view_angle=30.0, clipping_range=(dist - 2.0, dist + 2.0)))
    return vol, tf, cams


def _run_threads(jobs: list[Callable[[], list[np.ndarray]]]) -> list[list[np.ndarray]]:
    """Run each job in its own thread, all released at once; re-raise the first error."""
    start = threading.Barrier(len(jobs))
    results: list[list[np.ndarray] | None] = [None] * len(jobs)
    errors: list[BaseException] = []

    def run(i: int) -> None:
        try:
            start.wait(timeout=60)
            results[i] = jobs[i]()
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread
            errors.append(exc)

    threads = [threading.Thread(target=run, args=(i,), daemon=True) for i in range(len(jobs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=300)
        assert not t.is_alive(), "a rendering thread did not finish"
    if errors:
        raise errors[0]
    return [r for r in results if r is not None]


def _assert_exact(frames: list[np.ndarray], want: np.ndarray, what: str) -> None:
    assert len(frames) == FRAMES
    for k, got in enumerate(frames):
        if not np.array_equal(got, want, equal_nan=True):  # max |difference| 0, the infinities included
            finite = np.isfinite(got) & np.isfinite(want)
            raise AssertionError(f"{what}, frame {k}: {np.count_nonzero(got != want)} values differ, the finite ones "
                                 f"by up to {np.abs(got - want, where=finite, out=np.zeros(got.shape)).max()}")


def _assert_no_gl_error(ctx: Any) -> None:
    # Between calls the context is current in no thread, where glGetError answers
    # GL_NO_ERROR whatever happened: read it with the context current.
    with current_in_thread(ctx):
        assert ctx.error == "GL_NO_ERROR"


def test_one_renderer_two_threads_render_exactly_the_single_threaded_frames():
    mesh, tf, cams = _mesh_scene()
    with Renderer(SETTINGS) as r:
        # The threads are the first to use it: the creating thread must not hold the context.
        frames = _run_threads([lambda c=c: [r.render(mesh, c, tf, size=SIZE) for _ in range(FRAMES)] for c in cams])
        _assert_no_gl_error(r.ctx)
        wants = [r.render(mesh, c, tf, size=SIZE) for c in cams]
        assert np.abs(wants[0] - wants[1]).max() > 0.1  # the two views differ: a mix-up would show
        for i, (got, want) in enumerate(zip(frames, wants)):
            _assert_exact(got, want, f"camera {i}")
        _assert_no_gl_error(r.ctx)


def test_render_and_depth_extent_from_two_threads():
    # What fuse() calls, interleaved: the two methods use different targets and programs.
    mesh, tf, cams = _mesh_scene()
    with Renderer(SETTINGS) as r:
        want_image = r.render(mesh, cams[0], tf, size=SIZE)
        want_front, want_back = r.depth_extent(mesh, cams[1], size=SIZE)
        images, depths = _run_threads([
            lambda: [r.render(mesh, cams[0], tf, size=SIZE) for _ in range(FRAMES)],
            lambda: [np.stack(r.depth_extent(mesh, cams[1], size=SIZE)) for _ in range(FRAMES)],
        ])
        _assert_exact(images, want_image, "render")
        _assert_exact(depths, np.stack([want_front, want_back]), "depth_extent")
        _assert_no_gl_error(r.ctx)


def test_one_raycaster_two_threads_render_exactly_the_single_threaded_frames():
    vol, tf, cams = _volume_scene()
    with Raycaster(RaycastSettings(table_scalar_bins=64, table_thickness_slices=8)) as rc:
        wants = [rc.render(vol, c, tf, size=SIZE) for c in cams]
        assert np.abs(wants[0] - wants[1]).max() > 0.05 and wants[0][..., 3].max() > 0.1
        frames = _run_threads([lambda c=c: [rc.render(vol, c, tf, size=SIZE) for _ in range(FRAMES)] for c in cams])
        for i, (got, want) in enumerate(zip(frames, wants)):
            _assert_exact(got, want, f"camera {i}")
        _assert_no_gl_error(rc.ctx)


def test_renderer_and_raycaster_sharing_a_context_in_two_threads():
    # One context, two owners: the lock is the context's, not the owner's.
    mesh, mesh_tf, cams = _mesh_scene()
    vol, vol_tf, vol_cams = _volume_scene()
    with Renderer(SETTINGS) as r, Raycaster(RaycastSettings(table_scalar_bins=64, table_thickness_slices=8),
                                            ctx=r.ctx) as rc:
        want_mesh = r.render(mesh, cams[0], mesh_tf, size=SIZE)
        want_vol = rc.render(vol, vol_cams[0], vol_tf, size=SIZE)
        meshes, volumes = _run_threads([
            lambda: [r.render(mesh, cams[0], mesh_tf, size=SIZE) for _ in range(FRAMES)],
            lambda: [rc.render(vol, vol_cams[0], vol_tf, size=SIZE) for _ in range(FRAMES)],
        ])
        _assert_exact(meshes, want_mesh, "mesh")
        _assert_exact(volumes, want_vol, "volume")
        _assert_no_gl_error(r.ctx)


def test_renderer_made_in_a_thread_that_has_ended_works_here():
    mesh, tf, cams = _mesh_scene()
    made: list[Any] = []
    _run_threads([lambda: made.append(Renderer(SETTINGS)) or [made[0].render(mesh, cams[0], tf, size=SIZE)]])
    r = made[0]
    try:
        img = r.render(mesh, cams[0], tf, size=SIZE)
        assert img[..., 3].max() > 0.1
        _assert_no_gl_error(r.ctx)
    finally:
        r.release()


def test_release_while_another_thread_renders_gives_a_clear_error():
    mesh, tf, cams = _mesh_scene()
    r = Renderer(SETTINGS)
    first = threading.Event()
    outcome: list[BaseException] = []

    def loop() -> None:
        try:
            for _ in range(10_000):
                r.render(mesh, cams[0], tf, size=SIZE)
                first.set()
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread
            outcome.append(exc)
        finally:
            first.set()

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    assert first.wait(timeout=120)
    r.release()
    t.join(timeout=120)
    assert not t.is_alive()
    assert len(outcome) == 1 and isinstance(outcome[0], RuntimeError), outcome
    assert "has been released" in str(outcome[0])

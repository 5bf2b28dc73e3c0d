"""A series rendered on Dask (a 2-worker LocalCluster) streams: a video's frames reach the
encoder one by one in step order as the workers finish them; a finished frame waits on its
worker for its turn, so the client holds one at a time, never the series (its traced
memory, tracemalloc, against one frame's bytes; the same instrument sees every frame where a
caller asks for all of them); frames lost with a killed worker are made again; the frames
are the serial ones. The timer that ends a wait with no worker left raises as it did."""

from __future__ import annotations

import json
import time
import tracemalloc
import types

import meshio
import numpy as np
import pytest

pytest.importorskip("distributed", reason='needs dask.distributed: pip install "tetvr[dask]"')

from tetvr.cluster.workers import cluster_client  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402

N = 24
SIZE = (640, 480)


@pytest.fixture(scope="module")
def client():
    with cluster_client(n_workers=2) as c:
        c.wait_for_workers(2, timeout=120)
        yield c


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    """N steps of a small cube (its field grows step by step) as .vtu files and a .pvd, and a
    scene for them."""
    folder = tmp_path_factory.mktemp("series")
    mesh = synthetic.cube(4)
    rows = []
    for k in range(N):
        meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"f": mesh.scalars * (1 + 0.1 * k)}).write(
            folder / f"s{k}.vtu")
        rows.append(f'<DataSet timestep="{k}" part="0" file="s{k}.vtu"/>')
    (folder / "run.pvd").write_text('<VTKFile type="Collection"><Collection>' + "".join(rows)
                                    + "</Collection></VTKFile>")
    scene = folder / "scene.json"
    scene.write_text(json.dumps({"mesh": str(folder / f"s{N - 1}.vtu"), "scalars": "f", "size": list(SIZE)}))
    return folder


def _client_peak(work):
    """Bytes the client process allocated at most while ``work()`` ran (tracemalloc: numpy
    arrays and Dask's receive buffers included), and what ``work`` returned."""
    tracemalloc.start()
    try:
        got = work()
        return tracemalloc.get_traced_memory()[1], got
    finally:
        tracemalloc.stop()


def _video(path):
    import imageio.v2 as imageio

    with imageio.get_reader(path) as r:
        return [np.asarray(f) for f in r]


@pytest.mark.gl
def test_a_video_on_the_cluster_holds_the_window_not_the_series(client, series, tmp_path, monkeypatch):
    """``tetvr animate --time-series ... --scheduler`` to an .mp4 with a window of 2: the
    client's traced memory peaks below 6 of the 8-bit frames it receives (gathering the
    series, it held all 24 float frames). The video decodes to the serial command's frames."""
    pytest.importorskip("imageio_ffmpeg", reason="an .mp4 needs imageio-ffmpeg")
    from tetvr.apps.cli import main
    from tetvr.cluster.timeseries import render_series

    scene, pvd = str(series / "scene.json"), str(series / "run.pvd")
    assert main(["animate", scene, "--time-series", pvd, "-o", str(tmp_path / "serial.mp4"), "--no-progress"]) == 0
    rgba8 = SIZE[0] * SIZE[1] * 4
    # The instrument sees frames held here: all N float frames, asked for as a list.
    from tetvr.scene.load import load_scene

    s = load_scene(scene)
    everything, images = _client_peak(lambda: render_series(pvd, camera=s.camera, tf=s.tf, size=SIZE, scalars="f",
                                                            client=client, progress=False))
    assert len(images) == N and everything >= N * images[0].nbytes, (everything, images[0].nbytes)
    del images

    monkeypatch.setenv("TETVR_SCHEDULER", client.scheduler.address)
    monkeypatch.setenv("TETVR_SERIES_WINDOW", "2")
    streamed, rc = _client_peak(lambda: main(["animate", scene, "--time-series", pvd, "-o", str(tmp_path / "dask.mp4"),
                                              "--no-progress"]))
    assert rc == 0
    assert streamed < 6 * rgba8, f"the client held {streamed / rgba8:.1f} frames' bytes at once (window 2)"
    serial, dask = _video(tmp_path / "serial.mp4"), _video(tmp_path / "dask.mp4")
    assert len(serial) == len(dask) == N
    for k, (a, b) in enumerate(zip(serial, dask)):
        assert np.array_equal(a, b), k
    assert not np.array_equal(serial[0], serial[-1])


@pytest.mark.gl
@pytest.mark.parametrize("window", [1, 3])
def test_streamed_frames_come_in_step_order_as_the_serial_renders(client, series, window):
    """``iter_series`` yields each step's image in step order, the serial renderer's bits,
    to a consumer slower than the workers (frames that finish early wait for their turn)."""
    from tetvr.cluster.timeseries import iter_series
    from tetvr.gl import Renderer
    from tetvr.io.series import read_step
    from tetvr.scene.load import load_scene

    s = load_scene(str(series / "scene.json"))
    size = (64, 48)
    frames = iter_series(str(series / "run.pvd"), camera=s.camera, tf=s.tf, size=size, scalars="f", client=client,
                         window=window, progress=False)
    with Renderer() as r:
        for k, image in enumerate(frames):
            want = r.render(read_step(str(series / "run.pvd"), k, "f"), s.camera, s.tf, size=size)
            assert np.array_equal(image, want), k
            time.sleep(0.02)
    assert k == N - 1


@pytest.mark.gl
def test_frames_waiting_on_a_killed_worker_are_made_again(client):
    """A worker is killed while finished frames wait on it for their turn: they are made
    again (on the other worker, or the one its nanny restarts) and every frame still comes,
    once, in step order, the serial frame's 8-bit pixels."""
    import os
    import signal

    from tetvr import Camera, TransferFunction
    from tetvr.cluster.timeseries import iter_series
    from tetvr.core.image import to_rgba8
    from tetvr.gl import Renderer

    mesh = synthetic.cube(6)
    steps = [mesh.with_scalars(mesh.scalars * (1 + 0.1 * k), "f") for k in range(12)]
    camera, tf, size = Camera.fit(mesh), TransferFunction.preset("viridis", (0, 2)), (96, 72)
    address, victim = min(client.run(os.getpid).items(), key=lambda kv: kv[1])
    frames = iter_series(steps, camera=camera, tf=tf, size=size, pixels="rgba8", client=client, window=4,
                         progress=False)
    got = []
    for k, frame in enumerate(frames):
        got.append(frame)
        if k == 1:
            time.sleep(1.0)  # the window's later frames finish and wait on the workers
            waiting = [k for k in client.has_what()[address] if str(k).startswith("_render_step")]
            os.kill(victim, signal.SIGKILL)
    assert waiting, "no finished frame waited on the killed worker"
    assert len(got) == 12
    with Renderer() as r:
        for k, m in enumerate(steps):
            assert np.array_equal(got[k], to_rgba8(r.render(m, camera, tf, size=size), (1.0, 1.0, 1.0))), k
    client.wait_for_workers(2, timeout=60)
    assert victim not in client.run(os.getpid).values()


def test_a_window_must_be_a_positive_count(series, monkeypatch):
    from tetvr.cluster.timeseries import iter_series

    for bad in (0, -2, 1.5, "4"):
        with pytest.raises((ValueError, TypeError), match=rf"window must be a positive integer.*{bad!r}"):
            iter_series(str(series / "run.pvd"), window=bad)
    monkeypatch.setenv("TETVR_SERIES_WINDOW", "none")
    with pytest.raises(ValueError, match="TETVR_SERIES_WINDOW must be a positive integer.*'none'"):
        iter_series(str(series / "run.pvd"))


def _fake_client(workers):
    return types.SimpleNamespace(nthreads=lambda: dict(workers), scheduler=types.SimpleNamespace(address="tcp://x:1"))


def test_the_no_worker_timer_counts_only_time_without_workers():
    """Workers present: never raises, however long; none: raises once none has been seen
    for the limit, naming what waited; a worker back starts the count again."""
    from tetvr.cluster.workers import _NoWorkerTimer as NoWorkerTimer

    now = [0.0]
    workers = {"tcp://w:1": 1}
    timer = NoWorkerTimer(_fake_client(workers), "a frame", 5.0, clock=lambda: now[0])
    for now[0] in (0.0, 100.0, 1000.0):
        timer.check()
    workers.clear()
    for now[0] in (1000.0, 1004.9):
        timer.check()
    workers["tcp://w:2"] = 1
    now[0] = 1006.0
    timer.check()
    workers.clear()
    for now[0] in (1007.0, 1011.9):
        timer.check()
    now[0] = 1012.0
    with pytest.raises(TimeoutError, match=r"a frame: no Dask worker .* tcp://x:1 for 5 s"):
        timer.check()


def test_wait_and_as_completed_give_up_with_no_worker(monkeypatch):
    """Both waits raise the timer's TimeoutError where Dask alone would wait for ever."""
    import distributed

    from tetvr.cluster import workers as w

    def never(futures, timeout=None, return_when=None):
        time.sleep(min(timeout, 0.01))
        raise TimeoutError

    monkeypatch.setattr(distributed, "wait", never)
    c = _fake_client({})
    with pytest.raises(TimeoutError, match="the steps: no Dask worker"):
        w.wait(c, [object()], "the steps", timeout=0.05)
    with pytest.raises(TimeoutError, match="the bricks: no Dask worker"):
        next(w.as_completed(c, [object()], "the bricks", timeout=0.05))


def test_a_step_made_again_after_it_finished_waits_for_its_turn(monkeypatch):
    """A step whose worker is lost between finishing and being looked at is made again
    (its status no longer "finished"): in step order it still comes at its turn, once
    (it had been handed out at once, ahead of its turn, and its turn then never came)."""
    from concurrent.futures import CancelledError

    from tetvr.cluster import timeseries, workers

    class Future:
        def __init__(self, i, status):
            self.i, self.status = i, status

        def result(self):
            if self.status == "lost for good":
                raise CancelledError
            return f"frame {self.i}"

    # Step 1 is looked at after its worker was lost (made again: "pending" until its result
    # is asked for); step 0 finishes after it; a first try of step 2 is lost for good.
    statuses = {(0, 0): "finished", (1, 0): "pending", (2, 0): "lost for good", (2, 1): "finished"}
    sent, first = [], {}

    class Sender:
        def __init__(self, c, items, submit):
            self.shared = {}

        def __call__(self, i, tries):
            sent.append((i, tries))
            return Future(i, statuses[i, tries])

    def as_completed(c, futures, what):
        # The latest step first where two wait: step 1 before step 0.
        yield max(futures, key=lambda f: f.i)

    monkeypatch.setattr(timeseries, "_StepSender", Sender)
    monkeypatch.setattr(workers, "as_completed", as_completed)
    monkeypatch.setattr(workers, "wait", lambda c, futures, what: None)
    got = list(timeseries._steps_done(None, [None] * 3, None, "the steps", window=2, ordered=True))
    assert got == [(0, "frame 0"), (1, "frame 1"), (2, "frame 2")]
    assert sent == [(0, 0), (1, 0), (2, 0), (2, 1)]

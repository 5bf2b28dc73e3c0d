"""Bricks on a cluster of separate worker processes (a LocalCluster of 2 spawned workers, one
thread each, on 127.0.0.1), the way a user runs them: several meshes held on the same
workers at once and rendered in alternation from two clients, each composite checked
against the single-process image at every pixel; the scheduler holding no brick; each
worker's GL context on the EGL device it was given; a frame with every worker gone
failing with a clear error instead of waiting for ever."""

from __future__ import annotations

import os
import pickle
import re
import threading
import time

import numpy as np
import pytest

distributed = pytest.importorskip("distributed", reason='needs dask.distributed: pip install "tetvr[dask]"')

from tetvr import Camera, RenderSettings, TransferFunction  # noqa: E402
from tetvr.cluster.bricks import kd_bricks  # noqa: E402
from tetvr.cluster.distributed import distribute_mesh  # noqa: E402
from tetvr.cluster.workers import cluster_client, worker_egl_device, worker_renderer  # noqa: E402
from tetvr.gl.context import context_device  # noqa: E402
from tetvr.mesh import synthetic  # noqa: E402

pytestmark = pytest.mark.gl
SIZE = (128, 128)


@pytest.fixture(scope="module")
def client():
    with cluster_client(n_workers=2) as c:
        c.wait_for_workers(2, timeout=60)
        yield c


@pytest.fixture(scope="module")
def second_client(client):
    """Another client of the same scheduler: its tasks run on the same workers."""
    with distributed.Client(client.scheduler.address) as c:
        yield c


def _view(mesh, inside: bool):
    lo, hi = mesh.scalar_range
    b = mesh.bounds
    diag = float(np.linalg.norm(b[1] - b[0]))
    tf = TransferFunction.preset("viridis", (lo, hi), opacity=[(0, 0.3), (0.6, 0.9), (1, 0.5)],
                                 unit_distance=0.2 * diag)
    if inside:
        eye = b.mean(axis=0) + (0.13, 0.07, 0.21) * (b[1] - b[0]) / 1.5
        camera = Camera(position=tuple(eye), focal_point=tuple(eye - (0.4, 0.2, 0.3)), view_angle=70.0,
                        clipping_range=(0.005 * diag, 5 * diag))
    else:
        camera = Camera.fit(mesh, direction=(-1.0, -0.35, -0.25), zoom=1.2)
    return camera, tf


# Meshes whose k-d planes all run along cell faces (nothing cut): the composite is the
# single image to float32 rounding. (name, mesh, bricks)
MESHES = [("cube8", lambda: synthetic.cube(8, rotate=False), 2),
          ("cube13", lambda: synthetic.cube(13, rotate=False), 4),
          ("torus", lambda: synthetic.torus(n_around=48, n_cross=3), 3)]


def test_meshes_in_alternation_composite_to_the_single_image(client, second_client):
    """Three meshes (grid cubes of 3k and 13k tets and a ring of 2.6k, none from
    tetvr.meshing) are distributed at once, so each worker holds bricks of several meshes,
    and rendered in alternation by two clients from outside and from inside, twice over:
    every worker's one renderer goes from one mesh to another between frames. Each
    composite is the single-process image within 1e-4 at every pixel (measured <= 3e-5:
    float32 rounding), none beyond 1/255; the second round gives the first's bits."""
    from tetvr.gl import Renderer

    meshes = [(name, make(), p) for name, make, p in MESHES]
    assert all(m.n_tets <= 20_000 for _, m, _ in meshes)
    scenes = {}
    with Renderer(RenderSettings()) as local:
        for name, m, _ in meshes:
            for inside in (False, True):
                camera, tf = _view(m, inside)
                scenes[name, inside] = (camera, tf, local.render(m, camera, tf, size=SIZE))
    held = {}
    try:
        for k, (name, m, p) in enumerate(meshes):
            c = (client, second_client)[k % 2]
            tree = kd_bricks(m, p)
            assert tree.n_cut == 0, name
            held[name] = distribute_mesh(m, p, c, tree=tree)
        owners = client.who_has([f for b in held.values() for f in b.futures.values()])
        workers = {w for ws in owners.values() for w in ws}
        assert len(workers) == 2
        for w in workers:  # each worker holds bricks of more than one mesh
            assert sum(any(w in owners[f.key] for f in b.futures.values()) for b in held.values()) >= 2
        first = {}
        for rnd in range(2):
            for inside in (False, True):
                for name, _, _ in meshes:
                    camera, tf, whole = scenes[name, inside]
                    image = held[name].render(camera, tf, size=SIZE)
                    d = np.abs(image.astype(np.float64) - whole).max(axis=-1)
                    assert d.max() <= 1e-4, (rnd, name, inside, float(d.max()))
                    assert int((d > 1 / 255).sum()) == 0
                    if rnd == 0:
                        first[name, inside] = image
                    else:
                        assert np.array_equal(image, first[name, inside]), (name, inside)
    finally:
        for b in held.values():
            b.release()


def _live_meshes(dask_worker=None):
    """TetMesh objects alive in this worker but not held as data, and its renderers."""
    import gc

    from tetvr.cluster.workers import _RENDERERS
    from tetvr.mesh.tetmesh import TetMesh

    gc.collect()
    held = {id(v) for v in dask_worker.data.values()}
    return sum(isinstance(o, TetMesh) and id(o) not in held for o in gc.get_objects()), len(_RENDERERS)


def test_released_bricks_leave_the_workers(client):
    """After release(), a worker keeps no brick but the last one each of its renderers drew
    (its GPU buffers' source): bricks of meshes rendered and released before are freed."""
    for n in (4, 5, 6):
        mesh = synthetic.cube(n, rotate=False)
        camera, tf = _view(mesh, inside=False)
        bricks = distribute_mesh(mesh, 4, client)
        bricks.render(camera, tf, size=(32, 32))
        bricks.release()
    for address, (alive, renderers) in client.run(_live_meshes).items():
        assert alive <= 2 * renderers, (address, alive, renderers)


def _task_spec_bytes(dask_scheduler=None):
    """Bytes of every task's spec the scheduler holds (pickled): what it keeps to rerun them."""
    return sum(len(pickle.dumps(ts.run_spec)) for ts in dask_scheduler.tasks.values() if ts.run_spec is not None)


def _scheduler_keys(dask_scheduler=None):
    return len(dask_scheduler.tasks)


def test_the_scheduler_holds_no_brick(client):
    """distribute_mesh hands the bricks to the workers without putting them in a task: the
    scheduler holds their keys, not the mesh. Measured: the task specs it holds grow by
    under 1% of the 16 MB mesh (they held all of it when each brick travelled in its task),
    and the workers hold every brick."""
    mesh = synthetic.cube(50, rotate=False)  # 750k tets
    nbytes = mesh.points.nbytes + mesh.tets.nbytes + mesh.scalars.nbytes
    assert nbytes > 15e6
    tree = kd_bricks(mesh, 2)
    before = client.run_on_scheduler(_task_spec_bytes)
    bricks = distribute_mesh(mesh, 2, client, tree=tree)
    try:
        held = client.run_on_scheduler(_task_spec_bytes) - before
        assert held < 0.01 * nbytes, (held, nbytes)
        on_workers = sum(client.run(lambda dask_worker: sum(  # noqa: E731
            v.points.nbytes + v.tets.nbytes for v in dask_worker.data.values() if hasattr(v, "tets"))).values())
        assert on_workers >= 0.9 * (mesh.points.nbytes + mesh.tets.nbytes)
        assert bricks.brick_tets == {b.index: len(b.tets) for b in tree.bricks()}
    finally:
        bricks.release()


def test_a_brick_keeps_the_wholes_values_through_serialisation():
    """A brick travels to its worker by Dask's serialisation (pickle protocol 5): the
    values it shares with the whole mesh (float32 origin, scalar range, longest edge,
    segment sample), kept in the instance, arrive with it, and it renders the same bits."""
    from distributed.protocol import deserialize, serialize

    from tetvr.gl import Renderer

    mesh = synthetic.cube(6, rotate=False)
    tree = kd_bricks(mesh, 2)
    brick = tree.brick_mesh(tree.bricks()[0])
    assert not np.array_equal(brick.bounds.mean(axis=0), mesh.float32_origin)  # its own centre is elsewhere
    copy = deserialize(*serialize(brick))
    assert np.array_equal(copy.float32_origin, mesh.float32_origin)
    assert copy.scalar_range == mesh.scalar_range and copy.max_edge == mesh.max_edge
    assert np.array_equal(copy.__dict__["_segment_sample"].length, tree.whole.segment_sample.length)
    camera, tf = _view(mesh, inside=True)
    with Renderer() as r:
        assert np.array_equal(r.render(brick, camera, tf, size=(48, 48)), r.render(copy, camera, tf, size=(48, 48)))


# ---- the EGL device of a worker ----

def test_egl_device_from_the_environment():
    """TETVR_EGL_DEVICE names the device; else CUDA_VISIBLE_DEVICES' first GPU, which the
    worker numbers CUDA device 0, is the EGL device NVIDIA's EGL says is CUDA device 0;
    nothing (or no EGL device that is a CUDA device: Mesa) leaves the driver's first."""
    assert worker_egl_device({"TETVR_EGL_DEVICE": "3", "CUDA_VISIBLE_DEVICES": "1"}, cuda_devices=[0, 1]) == 3
    # dask-cuda's second worker of four: its GPU listed first; EGL lists the GPUs in another order.
    assert worker_egl_device({"CUDA_VISIBLE_DEVICES": "1,2,3,0"}, cuda_devices=[2, 0, 3, 1]) == 1
    assert worker_egl_device({"CUDA_VISIBLE_DEVICES": "GPU-8d2c1f0e"}, cuda_devices=[None, 0]) == 1  # a UUID
    assert worker_egl_device({"CUDA_VISIBLE_DEVICES": "0"}, cuda_devices=[None]) is None  # Mesa: no CUDA device
    assert worker_egl_device({"CUDA_VISIBLE_DEVICES": ""}, cuda_devices=[0]) is None
    assert worker_egl_device({"CUDA_VISIBLE_DEVICES": "-1"}, cuda_devices=[0]) is None
    assert worker_egl_device({}, cuda_devices=[1, 0]) is None
    for bad in ("-1", "gpu1", "1.5"):
        with pytest.raises(ValueError, match=f"TETVR_EGL_DEVICE must be a non-negative integer.*{bad!r}"):
            worker_egl_device({"TETVR_EGL_DEVICE": bad})


@pytest.fixture(scope="module")
def lone():
    """A cluster of one worker started with TETVR_EGL_DEVICE=0, which the last test of this
    module takes away."""
    import dask

    with dask.config.set({"distributed.worker.multiprocessing-method": "spawn"}):
        with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                                      env={"TETVR_EGL_DEVICE": "0"}) as cluster, distributed.Client(cluster) as c:
            c.wait_for_workers(1, timeout=60)
            yield c


def _set_env(name, value):
    os.environ[name] = value


def _worker_device(settings):
    return context_device(worker_renderer(settings).ctx)


def test_a_worker_renders_on_the_egl_device_it_is_given(lone):
    """The worker's environment names EGL device 0 (llvmpipe's one device): its renderer's
    context is made on it and renders. Named a device that does not exist, a new renderer
    fails the frame saying so: the choice reaches EGL."""
    mesh = synthetic.cube(4, rotate=False)
    camera, tf = _view(mesh, inside=False)
    bricks = distribute_mesh(mesh, 2, lone)
    try:
        assert bricks.render(camera, tf, size=(32, 32))[..., 3].max() > 0.3
        assert list(lone.run(_worker_device, RenderSettings()).values()) == [0]
        lone.run(_set_env, "TETVR_EGL_DEVICE", "7")
        other = RenderSettings(table_scalar_bins=128, table_thickness_slices=8)  # a new renderer, made now
        with pytest.raises(RuntimeError, match=r"brick \d .*context on EGL device 7.*requested device index 7"):
            bricks.render(camera, tf, size=(32, 32), settings=other)
        lone.run(_set_env, "TETVR_EGL_DEVICE", "0")
    finally:
        bricks.release()


def test_a_frame_with_every_worker_gone_fails_clearly(lone, monkeypatch):
    """Every worker gone (the cluster scaled to none), a frame of bricks and a time series
    raise a TimeoutError that says so, after TETVR_NO_WORKERS_TIMEOUT seconds, instead of
    waiting for ever."""
    monkeypatch.setenv("TETVR_NO_WORKERS_TIMEOUT", "2")
    mesh = synthetic.cube(4, rotate=False)
    camera, tf = _view(mesh, inside=False)
    bricks = distribute_mesh(mesh, 2, lone)
    bricks.render(camera, tf, size=(32, 32))
    lone.cluster.scale(0)
    deadline = time.monotonic() + 30
    while lone.nthreads() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not lone.nthreads()
    outcome: list[BaseException] = []

    def frame():
        try:
            bricks.render(camera, tf, size=(32, 32))
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            outcome.append(exc)

    t = threading.Thread(target=frame, daemon=True)
    started = time.monotonic()
    t.start()
    t.join(30)
    assert not t.is_alive(), "the frame still waits for workers after 30 s"
    assert time.monotonic() - started >= 2
    assert len(outcome) == 1 and isinstance(outcome[0], TimeoutError), outcome
    assert "no Dask worker has been connected" in str(outcome[0])
    assert "TETVR_NO_WORKERS_TIMEOUT" in str(outcome[0])
    # A time series alike (its steps' tasks wait for a worker that never comes).
    from tetvr.cluster.timeseries import render_series

    with pytest.raises(TimeoutError, match="rendering the steps: no Dask worker has been connected"):
        render_series([mesh], camera=camera, tf=tf, size=(32, 32), client=lone, progress=False)


# ---- no file system shared with the client ----

# A dask worker whose process may open no file under the folder TETVR_TEST_HIDDEN names
# (a Python audit hook refuses it, as if the folder were on another machine).
_SANDBOXED_WORKER = """
import os, sys
hidden = os.environ["TETVR_TEST_HIDDEN"]
def hook(event, args):
    if event == "open" and isinstance(args[0], (str, bytes)):
        path = os.path.abspath(os.fsdecode(args[0]))
        if path == hidden or path.startswith(hidden + os.sep):
            raise PermissionError(13, "not on this worker's machine", path)
sys.addaudithook(hook)
from distributed.cli.dask_worker import main
sys.argv = ["dask-worker", sys.argv[1], "--nthreads", "1", "--no-nanny", "--no-dashboard"]
main()
"""


@pytest.fixture(scope="module")
def elsewhere(tmp_path_factory):
    """A scheduler and 2 workers that share no files with this client: each worker runs in
    its own working directory and may open nothing under this test session's temporary
    folder, where the tests write their inputs. Yields (client, the workers' directory)."""
    import shutil
    import subprocess
    import sys
    import tempfile

    hidden = str(tmp_path_factory.getbasetemp().resolve())
    folder = tempfile.mkdtemp(prefix="tetvr-workers-")
    assert not folder.startswith(hidden + os.sep)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # for this module's functions
    env = dict(os.environ, TETVR_TEST_HIDDEN=hidden, PYTHONPATH=root)
    with distributed.LocalCluster(n_workers=0, dashboard_address=":0") as cluster:
        procs = [subprocess.Popen([sys.executable, "-c", _SANDBOXED_WORKER, cluster.scheduler_address], cwd=folder,
                                  env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for _ in range(2)]
        try:
            with distributed.Client(cluster) as c:
                c.wait_for_workers(2, timeout=90)
                yield c, folder
        finally:
            for p in procs:
                p.terminate()
            for p in procs:
                p.wait(30)
            shutil.rmtree(folder, ignore_errors=True)


def _opened(path):
    try:
        with open(path, "rb"):
            return "read"
    except OSError as exc:
        return type(exc).__name__


def _write_pieces(folder, mesh, n_pieces):
    """``mesh`` as ``mesh.pvtu`` of ``n_pieces`` slabs along x, each with its own points."""
    import meshio

    x = mesh.centroids[:, 0]
    part = np.searchsorted(np.quantile(x, np.linspace(0, 1, n_pieces + 1)[1:-1]), x)
    rows = []
    for k in range(n_pieces):
        used, local = np.unique(mesh.tets[part == k], return_inverse=True)
        meshio.Mesh(mesh.points[used], [("tetra", local.reshape(-1, 4))],
                    point_data={"f": mesh.scalars[used]}).write(os.path.join(folder, f"piece_{k}.vtu"))
        rows.append(f'<Piece Source="piece_{k}.vtu"/>')
    with open(os.path.join(folder, "mesh.pvtu"), "w") as f:
        f.write('<VTKFile type="PUnstructuredGrid"><PUnstructuredGrid GhostLevel="0"><PPointData>'
                '<PDataArray type="Float64" Name="f"/></PPointData><PPoints><PDataArray type="Float64" '
                'NumberOfComponents="3"/></PPoints>' + "".join(rows) + "</PUnstructuredGrid></VTKFile>")


def _write_steps(folder, mesh, n_steps):
    import meshio

    rows = []
    for k in range(n_steps):
        meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"f": mesh.scalars * (1 + 0.5 * k)}).write(
            os.path.join(folder, f"s{k}.vtu"))
        rows.append(f'<DataSet timestep="{k}" part="0" file="s{k}.vtu"/>')
    with open(os.path.join(folder, "run.pvd"), "w") as f:
        f.write('<VTKFile type="Collection"><Collection>' + "".join(rows) + "</Collection></VTKFile>")


def test_pieces_by_a_relative_path_reach_workers_that_cannot_see_them(elsewhere, tmp_path, monkeypatch):
    """A .pvtu named relative to the client's working directory, which the workers can
    neither open (checked) nor resolve (their working directory holds a different mesh
    under the same names): its pieces are read here and sent as bytes, and the composite
    is the merged mesh's single image (planes along the grid's faces: float32 rounding)."""
    import tetvr
    from tetvr.cluster.distributed import distribute_pieces
    from tetvr.gl import Renderer

    c, folder = elsewhere
    mesh = synthetic.cube(6, rotate=False)
    _write_pieces(str(tmp_path), mesh, 3)
    _write_pieces(folder, synthetic.cube(3, rotate=False), 3)  # what a worker would find at the same names
    assert set(c.run(_opened, str(tmp_path / "mesh.pvtu")).values()) == {"PermissionError"}
    monkeypatch.chdir(tmp_path)
    camera, tf = _view(mesh, inside=False)
    bricks = distribute_pieces("mesh.pvtu", 2, c)
    try:
        image = bricks.render(camera, tf, size=(48, 40))
    finally:
        bricks.release()
    with Renderer() as r:
        whole = r.render(tetvr.read(tmp_path / "mesh.pvtu"), camera, tf, size=(48, 40))
    assert whole[..., 3].max() > 0.3
    assert np.abs(image - whole).max() <= 1e-5


def test_series_by_relative_paths_with_frames_written_here(elsewhere, tmp_path, monkeypatch):
    """A .pvd and a list of files named relative to the client's working directory reach
    workers that cannot see them (bytes sent); the PNG frames, encoded on the workers,
    are written here, relative to the client's working directory, and are the bytes of
    this process's renders."""
    import tetvr
    from tetvr.cluster.timeseries import render_series
    from tetvr.core.image import png_bytes
    from tetvr.gl import Renderer
    from tetvr.io.series import read_step

    c, folder = elsewhere
    mesh = synthetic.cube(4)
    _write_steps(str(tmp_path), mesh, 2)
    _write_steps(folder, synthetic.cube(3), 2)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "frames").mkdir()
    camera, tf = Camera.fit(mesh), TransferFunction.preset("viridis", (0.0, 1.5), unit_distance=0.2)
    with Renderer() as r:  # this process's frames of the steps, read as the serial readers read them
        want = {"run.pvd": [png_bytes(r.render(read_step("run.pvd", k), camera, tf, size=(40, 32))) for k in range(2)],
                "files": [png_bytes(r.render(tetvr.read(f"s{k}.vtu"), camera, tf, size=(40, 32))) for k in range(2)]}
    for steps in ("run.pvd", ["s0.vtu", "s1.vtu"]):
        names = render_series(steps, camera=camera, tf=tf, size=(40, 32), output="frames/f_{index}.png", client=c,
                              progress=False)
        assert names == ["frames/f_0.png", "frames/f_1.png"]
        assert [(tmp_path / n).read_bytes() for n in names] == want["run.pvd" if steps == "run.pvd" else "files"]
        assert set(c.run(os.path.exists, "frames").values()) == {False}  # nothing written where the workers are


def test_urls_are_read_and_written_by_the_workers(elsewhere, tmp_path):
    """Steps given as file:// URLs of the workers' own file system are read there in
    place, and frames given as a URL pattern are written there by the workers; a URL the
    workers cannot read, or a path missing here, fails naming it."""
    from tetvr.cluster.timeseries import render_series

    c, folder = elsewhere
    mesh = synthetic.cube(3)
    _write_steps(folder, mesh, 2)
    os.mkdir(os.path.join(folder, "out"))
    camera, tf = Camera.fit(mesh), TransferFunction.preset("viridis", (0.0, 1.5), unit_distance=0.2)
    steps = [f"file://{folder}/s{k}.vtu" for k in range(2)]
    pattern = f"file://{folder}/out/f_{{index}}.png"
    names = render_series(steps, camera=camera, tf=tf, size=(40, 32), output=pattern, client=c, progress=False)
    assert names == [pattern.format(index=k) for k in range(2)]
    assert sorted(os.listdir(os.path.join(folder, "out"))) == ["f_0.png", "f_1.png"]
    images = render_series(f"file://{folder}/run.pvd", camera=camera, tf=tf, size=(40, 32), client=c,
                           progress=False)
    assert len(images) == 2 and images[0][..., 3].max() > 0.2 and not np.array_equal(images[0], images[1])
    _write_steps(str(tmp_path), mesh, 1)
    hidden = f"file://{tmp_path}/s0.vtu"
    with pytest.raises((OSError, ValueError), match=re.escape(repr(hidden))):
        render_series([hidden], camera=camera, tf=tf, size=(40, 32), client=c, progress=False)
    with pytest.raises(FileNotFoundError, match=r"mesh file not found on the client: 'missing\.vtu' \(in '.*'"):
        render_series(["missing.vtu"], camera=camera, tf=tf, size=(40, 32), client=c, progress=False)

"""Rendering on Dask (a 2-worker LocalCluster): time series frames equal serial renders bit
for bit; k-d bricks rendered on the workers and composited 'over' on the client equal the
whole image to float rounding where the split planes separate the cells."""

from __future__ import annotations

import os

import meshio
import numpy as np
import pytest

pytest.importorskip("distributed", reason='needs dask.distributed: pip install "tetvr[dask]"')

from tetvr import Camera, RenderSettings, TransferFunction, synthetic  # noqa: E402
from tetvr.collections import read_pvd, read_step  # noqa: E402
from tetvr.distributed import (  # noqa: E402
    cluster_client, kd_bricks, render_bricks, render_series, visibility_order)

pytestmark = pytest.mark.gl
SIZE = (64, 48)
SETTINGS = {"auto": RenderSettings(), "projected": RenderSettings(method="projected")}


@pytest.fixture(scope="module")
def client():
    with cluster_client(n_workers=2) as c:
        c.wait_for_workers(2, timeout=60)
        yield c


@pytest.fixture(scope="module")
def local():
    """Renderers in this process, one per method (the single-process images)."""
    from tetvr.gl import Renderer

    made = {k: Renderer(s) for k, s in SETTINGS.items()}
    yield made
    for r in made.values():
        r.release()


def _scene(mesh, view: str):
    lo, hi = mesh.scalar_range
    tf = TransferFunction.preset("viridis", (lo, hi), opacity=[(0, 0.3), (0.6, 0.9), (1, 0.5)], unit_distance=0.4)
    if view == "inside":  # perspective, the eye inside the mesh, off every split plane
        camera = Camera(position=(0.13, 0.07, 0.21), focal_point=(-0.4, -0.2, -0.3), view_angle=70.0,
                        clipping_range=(0.01, 10.0))
    else:
        camera = Camera.fit(mesh, direction=(-1.0, -0.35, -0.25), zoom=1.2, parallel=view == "parallel")
    return camera, tf


@pytest.mark.parametrize("method", ["auto", "projected"])
@pytest.mark.parametrize("view", ["perspective", "parallel", "inside"])
@pytest.mark.parametrize("n_bricks", [2, 4, 8])
def test_bricks_composite_to_the_whole_image(client, local, n_bricks, view, method):
    mesh = synthetic.cube(6, rotate=False)  # grid planes: every split separates the cells
    camera, tf = _scene(mesh, view)
    tree = kd_bricks(mesh, n_bricks)
    assert len(tree.bricks()) == n_bricks and tree.separable and tree.n_cut == 0  # grid planes: nothing cut
    assert sorted(visibility_order(tree, camera)) == list(range(n_bricks))
    whole = local[method].render(mesh, camera, tf, size=SIZE)
    parts = render_bricks(mesh, camera, tf, n_bricks=n_bricks, size=SIZE, settings=SETTINGS[method], client=client,
                          tree=tree)
    assert whole[..., 3].max() > 0.5
    # float32 blending in another association: rounding only
    assert np.abs(parts - whole).max() < 1e-5


def test_reverse_order_is_wrong(local):
    """The visibility order is what makes the composite exact (a check that the test can fail)."""
    from tetvr.distributed import composite_over

    mesh = synthetic.cube(6, rotate=False)
    camera, tf = _scene(mesh, "perspective")
    tree = kd_bricks(mesh, 2)
    order = tree.visibility_order(camera)
    bricks = {b.index: local["auto"].render(tree.brick_mesh(b), camera, tf, size=SIZE) for b in tree.bricks()}
    whole = local["auto"].render(mesh, camera, tf, size=SIZE)
    assert np.abs(composite_over([bricks[i] for i in order]) - whole).max() < 1e-5
    assert np.abs(composite_over([bricks[i] for i in order[::-1]]) - whole).max() > 1e-2


@pytest.mark.parametrize("view", ["perspective", "parallel", "inside"])
@pytest.mark.parametrize("name", ["rotated cube", "rings"])
def test_cut_bricks_tile_the_mesh_exactly(name, view):
    """No straddle-free plane (a rotated grid; two interlocking rings, non-convex): the
    cells a plane crosses are cut there. The exact CPU renderer's composite of the bricks
    equals its whole image to float32 rounding: the cut pieces tile the mesh, carry the
    field, and the order is right."""
    from tetvr.distributed import composite_over
    from tetvr.reference import render_reference

    mesh = synthetic.cube(4) if name == "rotated cube" else synthetic.interlocking_rings()
    camera, tf = _scene(mesh, view)
    whole = render_reference(mesh, camera, tf, SIZE)
    assert whole[..., 3].max() > 0.2
    for n in (2, 4, 8):
        tree = kd_bricks(mesh, n)
        assert tree.separable and tree.n_cut > 0
        parts = [render_reference(tree.brick_mesh(b), camera, tf, SIZE) for b in tree.bricks()]
        got = composite_over([parts[i] for i in tree.visibility_order(camera)])
        assert np.abs(got - whole).max() < 1e-6, n


@pytest.mark.parametrize("view", ["perspective", "parallel", "inside"])
def test_cut_bricks_on_the_gpu_are_as_close_to_the_reference(client, local, view):
    """On the GPU a cut segment is two table lookups instead of one: the composite differs
    from the whole image by the table's own error, and is as close to the reference."""
    from tetvr.image import psnr
    from tetvr.reference import render_reference

    mesh = synthetic.cube(6)
    camera, tf = _scene(mesh, view)
    whole = local["auto"].render(mesh, camera, tf, size=SIZE)
    ref = render_reference(mesh, camera, tf, SIZE)
    for n in (2, 4, 8):
        parts = render_bricks(mesh, camera, tf, n_bricks=n, size=SIZE, client=client)
        assert np.abs(parts - whole).max() < 2e-4, n  # measured 2e-5..8e-5
        assert psnr(parts, ref) >= psnr(whole, ref) - 0.5, n


def test_centroid_splits_warn_and_are_approximate(client, local):
    """Cells assigned by centroid (no cutting) leave jagged boundaries that rays cross back
    and forth: 'over' in plane order is then off near the planes (what cutting fixes)."""
    mesh = synthetic.cube(6)
    camera, tf = _scene(mesh, "perspective")
    tree = kd_bricks(mesh, 2, cut=False)
    assert not tree.separable
    whole = local["auto"].render(mesh, camera, tf, size=SIZE)
    with pytest.warns(UserWarning, match="run through cells"):
        parts = render_bricks(mesh, camera, tf, n_bricks=2, size=SIZE, client=client, tree=tree)
    assert 1e-3 < np.abs(parts - whole).max() < 0.5


def _write_series(folder, n_steps: int):
    mesh = synthetic.cube(4)
    rows = []
    for k in range(n_steps):
        name = f"s{k}.vtu"
        meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"f": mesh.scalars * (1 + 0.25 * k)}).write(
            folder / name)
        rows.append(f'<DataSet timestep="{0.5 * k}" part="0" file="{name}"/>')
    path = folder / "run.pvd"
    path.write_text('<VTKFile type="Collection"><Collection>' + "".join(rows) + "</Collection></VTKFile>")
    return path


def test_series_frames_equal_serial_renders_bit_for_bit(client, local, tmp_path):
    path = _write_series(tmp_path, 4)
    images = render_series(path, size=SIZE, client=client, progress=False)
    assert len(images) == 4
    coll = read_pvd(path)
    # the series' fixed transfer function: over the union of the steps' ranges
    lo = min(read_step(coll, k).scalar_range[0] for k in range(4))
    hi = max(read_step(coll, k).scalar_range[1] for k in range(4))
    meshes = [read_step(coll, k) for k in range(4)]
    from tetvr.distributed import _Bounds
    from tetvr.render import _tf_range

    bounds = np.stack([np.min([m.bounds[0] for m in meshes], axis=0), np.max([m.bounds[1] for m in meshes], axis=0)])
    camera = Camera.fit(_Bounds(bounds))
    diag = float(np.linalg.norm(bounds[1] - bounds[0]))
    tf = TransferFunction.preset("viridis", _tf_range(lo, hi), opacity=0.5, unit_distance=diag / 20)
    for k, m in enumerate(meshes):
        assert np.array_equal(images[k], local["auto"].render(m, camera, tf, size=SIZE)), k
    assert images[0][..., 3].max() > 0.2 and not np.array_equal(images[0], images[3])


def test_series_writes_pngs_named_by_time(client, tmp_path):
    path = _write_series(tmp_path, 3)
    out = tmp_path / "frames"
    out.mkdir()
    names = render_series(path, size=SIZE, client=client, output=str(out / "f_{time}.png"), progress=True)
    assert [os.path.basename(n) for n in names] == ["f_0.0.png", "f_0.5.png", "f_1.0.png"]
    assert sorted(os.listdir(out)) == ["f_0.0.png", "f_0.5.png", "f_1.0.png"]
    with pytest.raises(ValueError, match="pattern"):
        render_series(path, size=SIZE, client=client, output=str(out / "one.png"), progress=False)


def test_a_bad_step_fails_the_run_naming_it(client, tmp_path):
    path = _write_series(tmp_path, 2)
    (tmp_path / "s1.vtu").write_text("not a mesh")
    with pytest.raises(ValueError, match="s1.vtu"):
        render_series(path, size=SIZE, client=client, progress=False,
                      camera=Camera.fit(synthetic.cube(4)), tf=TransferFunction.preset("viridis", (0, 1)))


def test_a_killed_worker_loses_no_frame(client, tmp_path):
    """One worker process is killed mid-run: its tasks rerun on the other (and on the
    worker its nanny restarts); all 12 frames arrive, each written once, atomically."""
    import signal
    import threading
    import time

    mesh = synthetic.cube(10)
    folder = tmp_path / "frames"
    folder.mkdir()
    steps = [mesh.with_scalars(mesh.scalars * (1 + 0.1 * k), "f") for k in range(12)]
    killed: list[int] = []
    victim = min(client.run(os.getpid).values())  # a worker process this test's cluster started

    def kill_one():
        deadline = time.monotonic() + 60
        while not any(folder.iterdir()) and time.monotonic() < deadline:
            time.sleep(0.01)
        killed.append(len(list(folder.glob("*.png"))))
        os.kill(victim, signal.SIGKILL)

    killer = threading.Thread(target=kill_one)
    killer.start()
    names = render_series(steps, camera=Camera.fit(mesh), tf=TransferFunction.preset("viridis", (0, 2)),
                          size=(160, 120), client=client, output=str(folder / "f_{index:02d}.png"), progress=False)
    killer.join()
    assert killed and killed[0] < 12  # the kill came mid-run
    assert [os.path.basename(n) for n in names] == [f"f_{k:02d}.png" for k in range(12)]
    assert sorted(p.name for p in folder.iterdir()) == [f"f_{k:02d}.png" for k in range(12)]  # no temporaries left
    client.wait_for_workers(2, timeout=60)  # the nanny restarts the killed worker
    assert victim not in client.run(os.getpid).values()

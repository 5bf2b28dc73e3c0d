"""A tet-marching frame checks its own walk (march.frag) and traces again, on the CPU,
the pixels whose walk went wrong (tetvr.gl.selfcheck): the image is right and says how
many it traced. A clean mesh gives none."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import tetvr
from tetvr.core.clip import Clip
from tetvr.gl import march_layout, raymarch
from tetvr.gl.renderer import Renderer
from tetvr.mesh import synthetic
from tetvr.reference.tets import render_reference, render_reference_pixels

SIZE = (40, 32)


def _scene(mesh):
    tf = tetvr.TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.8, mesh=mesh)
    return tetvr.Camera.fit(mesh), tf


@pytest.mark.parametrize("inside", [False, True])
def test_a_clean_mesh_has_no_walk_gone_wrong(inside):
    mesh = synthetic.cube(6)
    camera, tf = _scene(mesh)
    if inside:
        camera = tetvr.Camera(position=(0.1, 0.05, 0.0), focal_point=(1.0, 0.3, 0.2), view_angle=70.0)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as r:
        r.render(mesh, camera, tf, size=SIZE)
        assert r._march.last_stats.n_suspect == 0


def test_walks_gone_wrong_are_traced_again_exactly(monkeypatch):
    """The check made to fail (no slack: every exit of the walk by points counts as behind its
    entry): the pixels of those rays are listed and traced again, to the reference's values,
    and the others are left as drawn."""
    mesh = synthetic.cube(4)
    camera, tf = _scene(mesh)
    clip = Clip.plane((0.05, 0.0, 0.0), (1.0, 0.2, 0.0))
    ref = render_reference(mesh, camera, tf, SIZE, clip=clip)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as r:
        plain = r.render(mesh, camera, tf, size=SIZE, clip=clip)
        monkeypatch.setattr(raymarch, "_slack", lambda mesh, camera: -1e30)
        checked = r.render(mesh, camera, tf, size=SIZE, clip=clip)
        stats = r._march.last_stats
    width, height = SIZE
    rows, cols = stats.suspect_pixels // width, stats.suspect_pixels % width
    traced = np.zeros((height, width), dtype=bool)
    traced[height - 1 - rows, cols] = True  # the list's rows count from the bottom
    covered = ref[..., 3] > 0
    assert stats.n_suspect > 0 and traced.sum() > covered.sum() // 2
    assert np.abs(checked[traced] - ref[traced]).max() <= 1e-6  # traced: the reference's own values
    np.testing.assert_array_equal(checked[~traced], plain[~traced])  # the others as drawn
    assert np.abs(plain - ref)[traced].max() > 1e-6  # drawn, they were the table's values
    assert np.abs(plain - ref).max() <= 1 / 255


def test_more_walks_gone_wrong_than_listed_are_said(monkeypatch):
    mesh = synthetic.cube(4)
    camera, tf = _scene(mesh)
    monkeypatch.setattr(raymarch, "_slack", lambda mesh, camera: -1e30)
    monkeypatch.setattr(march_layout, "SUSPECT_LENGTH", 16)
    monkeypatch.setattr(raymarch, "SUSPECT_LENGTH", 16)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as r, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r.render(mesh, camera, tf, size=SIZE)
    assert any("walk went wrong" in str(w.message) and "traced again exactly" in str(w.message) for w in caught)


def test_reference_pixels_are_the_reference_images_pixels():
    mesh = synthetic.cube(3)
    camera, tf = _scene(mesh)
    full = render_reference(mesh, camera, tf, SIZE).reshape(-1, 4)
    pixels = np.array([0, 5, 5, 17 * 40 + 20, SIZE[0] * SIZE[1] - 1, 600])
    np.testing.assert_array_equal(render_reference_pixels(mesh, camera, tf, SIZE, pixels), full[pixels])
    with pytest.raises(ValueError, match="pixels must lie in the 40x32 image"):
        render_reference_pixels(mesh, camera, tf, SIZE, [SIZE[0] * SIZE[1]])


@pytest.mark.parametrize("boxes", [False, True], ids=["tet by tet", "runs' boxes first"])
@pytest.mark.parametrize("chunk", [1 << 18, 64], ids=["by tiles", "pixel by pixel"])
@pytest.mark.parametrize("view", ["inside", "parallel", "outside"])
def test_reference_pixels_of_a_few_pixels_cull_no_tet_they_need(monkeypatch, view, chunk, boxes):
    """The pixels' tets are found first by their vertices' boxes (every tet the near plane
    cuts kept), then through the screen tiles the boxes cover (or, where the boxes would
    cover too many tiles for the chunk, pixel by pixel): the values are the full image's,
    bit for bit. On a large mesh the boxes of runs of tets near in space come first
    (tetvr.reference.boxes; here forced on a small one, runs of 8): the same values."""
    from tetvr.reference import boxes as run_boxes

    if boxes:
        monkeypatch.setattr(run_boxes, "MIN_TETS", 0)
        monkeypatch.setattr(run_boxes, "RUN", 8)
    mesh = synthetic.torus()
    if boxes:
        run_boxes.tet_boxes(mesh)  # else a mesh's first pixels are found tet by tet
    camera = tetvr.Camera.fit(mesh, direction=(0.3, -0.8, -0.5), parallel=view == "parallel")
    if view == "inside":  # the eye in the tube: the near plane cuts cells
        camera = tetvr.Camera(position=(1.0, 0.0, 0.05), focal_point=(1.0, 1.0, 0.0), view_angle=70.0)
    tf = tetvr.TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.8, mesh=mesh)
    full = render_reference(mesh, camera, tf, SIZE).reshape(-1, 4)
    assert np.count_nonzero(full[:, 3] > 0.01) > 100
    pixels = np.random.default_rng(3).choice(SIZE[0] * SIZE[1], 60, replace=False)
    np.testing.assert_array_equal(render_reference_pixels(mesh, camera, tf, SIZE, pixels, chunk=chunk),
                                  full[pixels])


def test_runs_boxes_keep_every_tet_a_pixel_may_need_and_few_others():
    """One pixel's candidates by the boxes of runs of tets: a superset of the tets whose own
    boxes may hold it, and a small part of the mesh."""
    from tetvr.core.camera import resolve_clipping_range
    from tetvr.core.rays import EyeRays
    from tetvr.reference import boxes as run_boxes
    from tetvr.reference.segments import _held_by, _may_cover, _pixel_coords

    mesh = synthetic.cube(20)  # 48,000 tets: above MIN_TETS
    assert mesh.n_tets >= run_boxes.MIN_TETS
    camera = resolve_clipping_range(tetvr.Camera.fit(mesh, direction=(0.3, -0.8, -0.5)), mesh.bounds)
    rays = EyeRays.from_camera(camera, 256, 256)
    view = camera.view_matrix()
    pts = (mesh.points - np.asarray(camera.position)) @ view[:3, :3].T
    for pixel in (256 * 128 + 128, 256 * 60 + 100):
        held = _held_by(np.array([pixel]), rays)
        some = run_boxes.candidates(mesh, np.asarray(camera.position, dtype=np.float64), view[:3, :3], rays, _pixel_coords,
                                        held)
        needed = np.flatnonzero(_may_cover(pts, mesh.tets, rays, held))
        assert needed.size > 0 and np.isin(needed, some).all()
        assert some.size < mesh.n_tets / 4


def test_a_mesh_s_first_pixels_are_found_tet_by_tet_while_its_boxes_are_built(monkeypatch):
    """Without its boxes yet, a mesh's pixels are found by projecting every tet (cheaper
    than the boxes), and the boxes are built in the background for the frames after."""
    import threading

    from tetvr.core.camera import resolve_clipping_range
    from tetvr.core.rays import EyeRays
    from tetvr.reference import boxes as run_boxes
    from tetvr.reference.segments import _held_by, _pixel_coords

    mesh = synthetic.cube(20)
    camera = resolve_clipping_range(tetvr.Camera.fit(mesh), mesh.bounds)
    rays = EyeRays.from_camera(camera, 64, 64)
    view = camera.view_matrix()
    args = (mesh, np.asarray(camera.position, dtype=np.float64), view[:3, :3], rays, _pixel_coords,
            _held_by(np.array([64 * 32 + 32]), rays))
    built = threading.Event()
    real = run_boxes.TetBoxes

    def slow(m):
        built.wait(10)  # held until the test has seen the first answer
        return real(m)

    monkeypatch.setattr(run_boxes, "TetBoxes", slow)
    assert run_boxes.candidates(*args, wait=False) is None
    assert run_boxes.candidates(*args, wait=False) is None  # still building: one thread
    assert [t.name for t in threading.enumerate()].count("tetvr-boxes") == 1
    built.set()
    for t in threading.enumerate():
        if t.name == "tetvr-boxes":
            t.join(10)
    some = run_boxes.candidates(*args, wait=False)
    assert some is not None and 0 < some.size < mesh.n_tets / 4
    np.testing.assert_array_equal(some, run_boxes.candidates(*args))


def test_rays_past_the_last_layer_are_traced_again(monkeypatch):
    """A ray that would enter the mesh again after the march's last layer is not cut off:
    its pixel is traced again exactly (here with 1 layer on a torus, entered twice)."""
    mesh = synthetic.torus()
    camera, tf = tetvr.Camera.fit(mesh, direction=(1.0, 0.05, -0.1)), _scene(mesh)[1]
    ref = render_reference(mesh, camera, tf, SIZE)
    monkeypatch.setattr(raymarch, "MAX_LAYERS", 1)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as r:
        image = r.render(mesh, camera, tf, size=SIZE)
        st = r._marcher.last_stats
    assert st.layers_exhausted and st.n_suspect > 0
    assert np.abs(image - ref).max() <= 1 / 255


def test_a_walk_gone_astray_stops_and_is_traced_again():
    """A Delaunay pipe with a graded wall layer has slivers where a few walks go astray; such
    a walk once circled for the rest of its step bound (the mesh's cell count: 44k steps,
    most of a frame of a 924k-tet pipe). It stops where it goes astray, and the ray is traced
    again exactly. (Here a view in which one walk goes astray: from the pipe's other
    views, the walk by planes leaving a sliver by the face that holds the ray took the
    rest off that path.)"""
    pytest.importorskip("scipy", reason="the Delaunay pipe needs scipy: pip install -e '.[mesh]'")
    from tetvr.apps.vtkcompare import orbit
    from tetvr.scene.imperfect import delaunay_pipe

    mesh = delaunay_pipe(16, 20)
    camera, tf = orbit(tetvr.Camera.fit(mesh), 165.0), tetvr.TransferFunction.preset(
        "viridis", mesh.scalar_range, opacity=0.5, mesh=mesh)
    size = (128, 128)
    with Renderer() as r:
        counts = r.segment_counts(mesh, camera, size=size)
        image = r.render(mesh, camera, tf, size=size)
        n_suspect = r._marcher.last_stats.n_suspect
    assert n_suspect > 0  # the scene has walks that go astray
    assert counts.max() < 1000  # none walks on: the longest ray crosses ~130 cells
    ref = render_reference(mesh, camera, tf, size)
    assert np.abs(image - ref).max() <= 1 / 255


def test_rays_entering_slivers_at_the_hull_walk_by_points():
    """The hull of a Delaunay pipe's jittered wall points is faced by slivers (the wall
    points just inside it): a ray that enters one face-on and left it by the nearest of its
    face planes (all nearly one plane: the choice was rounding) went astray, to be traced
    again on the CPU (71 rays in 12 views here; 400-700 a frame of the 924k-tet pipe at
    512x512). Where the entry face holds the ray clear of its edges, the walk goes by points
    from the first tet: a few rays in 12 views."""
    pytest.importorskip("scipy", reason="the Delaunay pipe needs scipy: pip install -e '.[mesh]'")
    from tetvr.apps.vtkcompare import orbit
    from tetvr.scene.imperfect import delaunay_pipe

    mesh = delaunay_pipe(16, 20)
    tf = tetvr.TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.5, mesh=mesh)
    with Renderer() as r:
        suspects = 0
        for degrees in range(0, 360, 30):
            r.render(mesh, orbit(tetvr.Camera.fit(mesh), degrees), tf, size=(128, 128))
            suspects += r._marcher.last_stats.n_suspect
    assert suspects <= 4

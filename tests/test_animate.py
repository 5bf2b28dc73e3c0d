"""Animations: orbit cameras (pure numpy), frames through the GL renderer, time series,
frame/video writing and the ``tetvr animate`` command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TransferFunction
from tetvr.mesh import synthetic
from tetvr.apps.animate import animate, azimuth, orbit, render_frames
from tetvr.io.video import write_frames
from tetvr.io.series import read_time_series
from tetvr.apps.cli import main
from tetvr.core.image import psnr

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small():
    mesh = synthetic.cube(3)
    cam = Camera.fit(mesh, direction=(-0.4, -0.3, -1.0), view_up=(0, 1, 0))
    tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.6, unit_distance=0.3)
    return mesh, cam, tf


# ---- cameras (no GL) ----
def test_orbit_turns_about_view_up_through_the_focal_point(small):
    _, cam, _ = small
    cams = orbit(cam, 8)
    focal, up = np.asarray(cam.focal_point), np.asarray(cam.view_up)
    dist = np.linalg.norm(np.subtract(cam.position, focal))
    height = np.dot(np.subtract(cam.position, focal), up)
    for c in cams:
        assert c.focal_point == cam.focal_point and c.view_up == cam.view_up
        off = np.subtract(c.position, focal)
        assert np.linalg.norm(off) == pytest.approx(dist, rel=1e-12)
        assert np.dot(off, up) == pytest.approx(height, abs=1e-12 * dist)  # stays on its circle
    # Consecutive frames 45 degrees apart about the up axis.
    def flat(c):
        v = np.subtract(c.position, focal)
        return v - np.dot(v, up) * up
    a, b = flat(cams[0]), flat(cams[1])
    assert np.degrees(np.arccos(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b))) == pytest.approx(45.0)
    assert cams[0] is cam  # angle 0 is the camera itself


def test_orbit_endpoints():
    cam = Camera(position=(0, -5, 0), view_up=(0, 0, 1))
    loop = orbit(cam, 36)                       # 0, 10, ..., 350: loops without a repeat
    assert len(loop) == 36 and loop[-1] is not cam
    closed = orbit(cam, 7, endpoint=True)       # 0, 60, ..., 360: the last is the first
    assert closed[-1] is cam and closed[0] is cam
    partial = orbit(cam, 3, degrees=90.0, endpoint=True)
    np.testing.assert_allclose(partial[-1].position, (5, 0, 0), atol=1e-12)
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="n_frames"):
            orbit(cam, bad)
    with pytest.raises(ValueError, match="endpoint"):
        orbit(cam, 1, endpoint=True)


def test_quarter_turns_compose_to_a_full_turn(small):
    _, cam, _ = small
    c = cam
    for _ in range(4):
        c = azimuth(c, 90.0)
    np.testing.assert_allclose(c.position, cam.position, atol=1e-12 * np.linalg.norm(cam.position))
    # About another axis, the view up turns with the camera.
    tilted = azimuth(cam, 90.0, axis=(1, 0, 0))
    assert np.dot(tilted.view_up, (1, 0, 0)) == pytest.approx(np.dot(cam.view_up, (1, 0, 0)))
    with pytest.raises(ValueError, match="axis"):
        azimuth(cam, 10.0, axis=(0, 0, 0))


# ---- frames (GL) ----
@pytest.mark.gl
def test_full_orbit_returns_the_first_image_bit_exactly(small):
    """A 360-degree orbit whose last frame is at the start angle redraws the first frame
    bit for bit, although the renderer drew four other views (other orders, other fans)
    in between."""
    mesh, cam, tf = small
    frames = list(render_frames(((mesh, c) for c in orbit(cam, 5, endpoint=True)), tf, size=(64, 48),
                                progress=False))
    assert len(frames) == 5 and frames[0].shape == (48, 64, 4)
    assert np.array_equal(frames[0], frames[-1])
    assert frames[0][..., 3].max() > 0.3
    assert not np.array_equal(frames[0], frames[1])
    # Four composed quarter turns land within rounding of the start: the same picture.
    with tetvr.Renderer() as r:
        c = cam
        for _ in range(4):
            c = azimuth(c, 90.0)
        assert psnr(r.render(mesh, c, tf, size=(64, 48)), frames[0]) > 60.0


@pytest.mark.gl
def test_write_frames_and_video(tmp_path, small):
    mesh, cam, tf = small
    images = list(render_frames(((mesh, c) for c in orbit(cam, 3)), tf, size=(32, 24), progress=False))
    files = write_frames(images, tmp_path / "frames")
    assert [f.name for f in files] == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    assert all(f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for f in files)
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match="not a folder"):
        write_frames(images, tmp_path / "file")
    imageio = pytest.importorskip("imageio.v2", reason="GIF/MP4 output needs the animate extra (pip install tetvr[animate])")
    gif = write_frames(images, tmp_path / "orbit.gif", fps=5)[0]
    assert len(imageio.mimread(gif)) == 3
    pytest.importorskip("imageio_ffmpeg", reason="MP4 output needs imageio-ffmpeg (pip install tetvr[animate])")
    mp4 = write_frames(images, tmp_path / "orbit.mp4", fps=5)[0]
    reader = imageio.get_reader(mp4)
    assert reader.count_frames() == 3
    reader.close()


def _series(tmp_path, mesh, steps=3):
    import meshio

    path = tmp_path / "series.xdmf"
    with meshio.xdmf.TimeSeriesWriter(str(path), data_format="XML") as w:
        w.write_points_cells(mesh.points, [("tetra", mesh.tets)])
        for k in range(steps):
            w.write_data(0.5 * k, point_data={"u": mesh.scalars * (1.0 + k)},
                         cell_data={"c": [np.full(mesh.n_tets, float(k))]})
    return path


def test_read_time_series_xdmf_and_file_lists(tmp_path, small):
    import meshio

    mesh, _, _ = small
    path = _series(tmp_path, mesh)
    steps = list(read_time_series(path))
    assert [t for t, _ in steps] == [0.0, 0.5, 1.0]
    for k, (_, m) in enumerate(steps):
        assert m.scalar_name == "u" and m.n_tets == mesh.n_tets
        np.testing.assert_allclose(m.scalars, mesh.scalars * (1 + k))
        assert m.tets is steps[0][1].tets  # one geometry, canonicalised once
    cells = list(read_time_series(path, "c"))  # cell data -> point data
    np.testing.assert_allclose(cells[2][1].scalars, 2.0)
    with pytest.raises(KeyError, match="no field 'nope'"):
        list(read_time_series(path, "nope"))
    files = []
    for k in range(2):
        f = tmp_path / f"step{k}.vtu"
        meshio.write(f, meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"p": mesh.scalars + k}))
        files.append(f)
    listed = list(read_time_series(files, "p"))
    assert [t for t, _ in listed] == [0.0, 1.0]
    np.testing.assert_allclose(listed[1][1].scalars, mesh.scalars + 1)
    with pytest.raises(ValueError, match="empty"):
        list(read_time_series([]))


def _scene_file(tmp_path, mesh_name="post.vtk", size=(48, 36)):
    scene = {"mesh": str(ROOT / "meshes" / mesh_name), "size": list(size),
             "transfer_function": {"preset": "viridis", "opacity": 0.4},
             "camera": {"fit": {"direction": [-1, -0.9, -0.9], "view_up": [0, 0, 1]}}}
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))
    return path


@pytest.mark.gl
def test_animate_time_series_keeps_the_scene_transfer_function(tmp_path, small):
    mesh, _, _ = small
    import meshio

    series = _series(tmp_path, mesh)
    # The scene (camera, colour range) comes from the first step, saved on its own.
    meshio.write(tmp_path / "first.vtu", meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"u": mesh.scalars}))
    scene_path = tmp_path / "s.json"
    scene_path.write_text(json.dumps({"mesh": "first.vtu", "scalars": "u", "size": [40, 30]}))
    files = animate(scene_path, tmp_path / "steps", time_series=series, progress=False)
    assert len(files) == 3
    frames = [tetvr_png(f) for f in files]
    assert not np.array_equal(frames[0], frames[2])  # u doubles and triples: other colours
    with pytest.raises(ValueError, match="nothing to animate"):
        animate(scene_path, tmp_path / "none")


def tetvr_png(path):
    from PIL import Image

    return np.asarray(Image.open(path))


@pytest.mark.gl
def test_cli_animate_orbit(tmp_path, capsys):
    scene = _scene_file(tmp_path)
    out = tmp_path / "frames"
    assert main(["animate", str(scene), "--orbit", "4", "-o", str(out), "--no-progress"]) == 0
    files = sorted(out.glob("frame_*.png"))
    assert len(files) == 4
    assert "wrote 4 file(s)" in capsys.readouterr().out
    first, second = tetvr_png(files[0]), tetvr_png(files[1])
    assert first.shape == (36, 48, 4) and not np.array_equal(first, second)


def test_cli_animate_errors(tmp_path, capsys):
    scene = _scene_file(tmp_path)
    assert main(["animate", str(scene), "-o", str(tmp_path / "x")]) == 2
    assert "nothing to animate" in capsys.readouterr().err
    assert main(["animate", str(tmp_path / "missing.json"), "--orbit", "2"]) == 2

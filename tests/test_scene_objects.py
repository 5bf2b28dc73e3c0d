"""Pure-numpy tests of the scene's value objects: mesh, camera, transfer function, JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TetMesh, TransferFunction
from tetvr.mesh import synthetic
from tetvr.scene.scene import Scene
from tetvr.scene.load import load_scene

from .conftest import shared_file


def _tet():
    return np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 2, 1, 3]])


def test_mesh_normalises_orientation_without_touching_inputs():
    pts, tets = _tet()
    s = np.arange(4.0)
    before = (pts.copy(), tets.copy(), s.copy())
    m = TetMesh.from_arrays(pts, tets, s)
    assert m.report.inverted_fixed == 1
    p = m.points[m.tets[0]]
    assert np.linalg.det(np.stack([p[1] - p[0], p[2] - p[0], p[3] - p[0]])) > 0
    for a, b in zip((pts, tets, s), before):
        assert np.array_equal(a, b)
    with pytest.raises(ValueError):
        m.points[0, 0] = 5.0  # read-only


def test_mesh_drops_flat_tets_with_count():
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]])
    with pytest.warns(UserWarning, match="dropped 1 zero-volume"):
        m = TetMesh.from_arrays(pts, [[0, 1, 2, 3], [0, 1, 2, 4]], np.zeros(5))
    assert m.n_tets == 1 and m.report.dropped_degenerate == 1


@pytest.mark.parametrize("tets,msg", [([[0, 1, 2, 9]], "outside"), ([[0, 1, 1, 2]], "repeats"),
                                      (np.zeros((0, 4), int), "no tetrahedra")])
def test_mesh_rejects_bad_tets(tets, msg):
    pts, _ = _tet()
    with pytest.raises(ValueError, match=msg):
        TetMesh.from_arrays(pts, np.asarray(tets), np.zeros(4))


def test_mesh_rejects_nan_and_wrong_length_scalars():
    pts, tets = _tet()
    with pytest.raises(ValueError, match="NaN"):
        TetMesh.from_arrays(pts, tets, [0, 1, np.nan, 2])
    with pytest.raises(ValueError, match="one value per point"):
        TetMesh.from_arrays(pts, tets, [0, 1, 2])
    with pytest.raises(TypeError, match="complex"):
        TetMesh.from_arrays(pts, tets, np.ones(4, complex))


def test_read_post_vtk_and_cell_data_average(tmp_path):
    import meshio

    mesh = tetvr.read(tetvr.demo_scene_path().parent / "post.vtk")
    assert mesh.n_tets == 8750 and mesh.scalar_name == "Pressure"
    # Cell data becomes point data by volume-weighted averaging: two tets of volume 1/6 and 1/3.
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -2]])
    cells = [("tetra", np.array([[0, 1, 2, 3], [0, 2, 1, 4]]))]
    path = tmp_path / "two.vtu"
    meshio.write_points_cells(path, pts, cells, cell_data={"T": [np.array([1.0, 4.0])]})
    m = tetvr.read(path, "T")
    assert m.report.scalar_source == "cell"
    by_point = dict(zip(map(tuple, m.points), m.scalars))
    assert by_point[(0.0, 0.0, 0.0)] == pytest.approx((1 / 6 * 1 + 2 / 6 * 4) / (3 / 6))
    assert by_point[(0.0, 0.0, 1.0)] == pytest.approx(1.0)
    with pytest.raises(KeyError, match="point fields"):
        tetvr.read(path, "nope")
    assert m.report.fields == ("T",)  # the file's fields, for pickers (tetvr.apps.viewer.model)
    assert TetMesh.from_arrays(*_tet(), np.ones(4)).report.fields == ()


def test_read_reports_and_normalises_inverted_real_mesh():
    mesh = tetvr.read(shared_file("tets/beam_tet4_result_100.vtu"), "VonMises_stress")
    assert mesh.report.inverted_fixed == 21756


def test_camera_frame_and_validation():
    cam = Camera(position=(0, 0, 5), focal_point=(0, 0, 0), view_up=(0, 1, 0), clipping_range=(1, 10))
    v = cam.view_matrix()
    np.testing.assert_allclose(v @ [0, 0, 0, 1], [0, 0, -5, 1])
    o, d = cam.rays(4, 2)
    assert o.shape == (8, 3) and np.allclose(d[:, 2], -1)  # t equals eye depth
    assert d[0, 1] > 0 and d[-1, 1] < 0  # row 0 is the top
    for bad in (dict(position=(0, 0, 0)), dict(view_up=(0, 0, 1)), dict(view_angle=0),
                dict(clipping_range=(5, 1)), dict(clipping_range=(0, 1))):
        kw = dict(position=(0, 0, 5), focal_point=(0, 0, 0), view_up=(0, 1, 0))
        kw.update(bad)
        with pytest.raises(ValueError):
            Camera(**kw)


def test_bounding_sphere_and_where_fit_looks():
    from tetvr.core.camera import bounding_sphere

    mesh = synthetic.cube(2)
    centre, radius = bounding_sphere(mesh.bounds)
    np.testing.assert_array_equal(centre, 0.5 * (mesh.bounds[0] + mesh.bounds[1]))
    assert radius == pytest.approx(0.5 * np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    # fit frames the projected extent (tests/test_defaults.py): its focal point is the
    # extent's centre, on the plane through the bounding sphere's centre across the view.
    cam = Camera.fit(mesh)
    offset = np.subtract(cam.focal_point, centre)
    assert abs(offset @ np.asarray(cam.direction)) < 1e-12 and np.linalg.norm(offset) < 0.1 * radius
    assert cam.parallel_scale == radius
    assert bounding_sphere([(1, 2, 3), (1, 2, 3)])[1] == 1e-30  # a point still has a radius


def test_camera_fit_contains_mesh():
    mesh = synthetic.cube(2)
    for parallel in (False, True):
        cam = Camera.fit(mesh, parallel=parallel)
        p = np.c_[mesh.points, np.ones(mesh.n_points)] @ cam.view_matrix().T
        clip = p @ cam.projection_matrix(1.0).T
        ndc = clip[:, :3] / clip[:, 3:]
        assert np.all(np.abs(ndc) <= 1.0)


def test_transfer_function_validation_and_json():
    tf = TransferFunction.preset("hot", (2.0, 4.0), opacity=[(0, 0.0), (1, 1.0)], unit_distance=0.5)
    assert tf.domain == (2.0, 4.0)
    assert TransferFunction.from_dict(json.loads(json.dumps(tf.to_dict()))) == tf
    rgb, a = tf.evaluate([1.0, 3.0, 9.0])
    assert a.tolist() == [0.0, 0.5, 1.0]
    with pytest.raises(ValueError, match="sorted"):
        TransferFunction(color=((1, 0, 0, 0), (0, 1, 1, 1)), opacity=((0, 1),))
    with pytest.raises(ValueError, match="duplicate"):
        TransferFunction(color=((0, 0, 0, 0), (0, 1, 1, 1)), opacity=((0, 1),))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        TransferFunction(color=((0, 0, 0, 0),), opacity=((0, 1.5),))
    with pytest.raises(ValueError, match="unknown preset"):
        TransferFunction.preset("rainbow", (0, 1))


def test_scene_json_round_trip(tmp_path):
    scene = load_scene(tetvr.demo_scene_path())
    path = tmp_path / "scene.json"
    scene.save(path)
    again = load_scene(path)
    assert again.tf == scene.tf and again.camera == scene.camera and again.size == scene.size
    assert again.settings == scene.settings and again.mesh.n_tets == scene.mesh.n_tets


@pytest.mark.parametrize("patch,msg", [({"colour": 1}, "unknown scene keys"), ({"mesh": None}, None),
                                       ({"camera": {"fit": {"zoomm": 2}}}, "unknown camera.fit"),
                                       ({"settings": {"sort": "magic"}}, "sort")])
def test_scene_json_errors(tmp_path, patch, msg):
    data = json.loads(tetvr.demo_scene_path().read_text())
    data["mesh"] = str(tetvr.demo_scene_path().parent / data["mesh"])
    data.update(patch)
    if patch.get("mesh", 1) is None:
        del data["mesh"]
        msg = "no 'mesh'"
    with pytest.raises(ValueError, match=msg):
        Scene.from_dict(data)

"""The defaults that show the data: one rule (tetvr.optics.transfer) for the range, the opacity
ramp and the unit distance, and Camera.fit framing the projected extent; each tested on
meshes of 1e-3 and 1e3 extent, where the picture must come out the same.

Images here come from the CPU reference (no GL needed): the defaults are what is tested,
not the rasteriser.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import tetvr
from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.core.camera import _fit
from tetvr.render import default_transfer_function
from tetvr.optics.transfer import DEFAULT_UNIT_FRACTION, default_unit_distance, point_weights, robust_range

SCALES = [1e-3, 1e3]


def scaled(mesh: tetvr.TetMesh, scale: float) -> tetvr.TetMesh:
    return tetvr.TetMesh.from_arrays(mesh.points * scale, mesh.tets, mesh.scalars, scalar_name=mesh.scalar_name)


def coarse_and_refined() -> tetvr.TetMesh:
    """A unit cube with a field 0..1 along x, and a tiny, finely meshed cube beside it
    holding 10: most points, almost no volume."""
    coarse = synthetic.cube(3, synthetic.linear_field((1.0, 0.0, 0.0), 0.5), rotate=False)
    fine = synthetic.cube(6, lambda p: np.full(len(p), 10.0), size=0.05, rotate=False)
    fine = tetvr.TetMesh.from_arrays(fine.points + 0.6, fine.tets, fine.scalars)
    return synthetic.merge(coarse, fine)


def pipe(scale: float = 1.0) -> tetvr.TetMesh:
    """A 4 x 4 x 30 box (the pipe-flow's shape), a field rising along it."""
    m = synthetic.cube(4, synthetic.linear_field((0.0, 0.0, 1.0), 0.5), rotate=False)
    return tetvr.TetMesh.from_arrays(m.points * np.array([4.0, 4.0, 30.0]) * scale, m.tets, m.scalars)


# ---- range ----

@pytest.mark.parametrize("scale", SCALES)
def test_range_is_robust_and_weighted_by_volume(scale):
    mesh = scaled(coarse_and_refined(), scale)
    assert np.sum(mesh.scalars == 10.0) > mesh.n_points / 2  # most points say 10 ...
    lo, hi = default_transfer_function(mesh).domain
    assert 0.0 <= lo < 0.05 and 0.95 < hi <= 1.0  # ... but hardly any volume does
    # Unweighted, the refined corner would set the top of the range.
    assert robust_range(mesh.scalars)[1] == 10.0
    # An outlier point does not stretch the range either.
    fine = scaled(synthetic.cube(6, synthetic.linear_field((1.0, 0.0, 0.0), 0.5), rotate=False), scale)
    spiky = fine.with_scalars(np.where(np.arange(fine.n_points) == 0, 1e6, fine.scalars), "spiky")
    assert default_transfer_function(spiky).domain[1] <= 1.0


def test_point_weights_sum_to_the_volume():
    mesh = scaled(synthetic.cube(2), 1e3)
    vol = np.abs(np.linalg.det(mesh.points[mesh.tets[:, 1:]] - mesh.points[mesh.tets[:, :1]])).sum() / 6
    assert point_weights(mesh.points, mesh.tets).sum() == pytest.approx(vol, rel=1e-12)


def test_constant_field_gets_a_small_range_above_it():
    mesh = synthetic.cube(1, lambda p: np.full(len(p), 7.0))
    lo, hi = default_transfer_function(mesh).domain
    assert lo == 7.0 and 7.0 < hi <= 7.01


# ---- ramp ----

@pytest.mark.parametrize("scale", SCALES)
def test_opacity_ramp_lets_high_values_stand_out(scale):
    mesh = scaled(synthetic.cube(2, synthetic.linear_field((1.0, 0.0, 0.0), 0.5), rotate=False), scale)
    tf = default_transfer_function(mesh)
    lo, hi = tf.domain
    s = np.linspace(lo, hi, 101)
    a = tf.evaluate(s)[1]
    assert a[0] == 0.0 and a[-1] == 0.9 and np.all(np.diff(a) >= 0)  # transparent low, 0.9 at the top
    assert a[50] <= 0.3  # the middle of the range is a faint context, not fog
    # In the picture: the high half of the field is more opaque than the low half.
    cam = Camera.fit(mesh, direction=(0.0, 1.0, 0.0), view_up=(0, 0, 1), parallel=True)  # x to the right
    img = tetvr.render(mesh, camera=cam, tf=tf, size=(24, 24), method="reference")
    row = img[12, :, 3]  # across the cube, low values on the left
    assert row[0] < 0.05 and row[-1] > 0.9 and np.all(np.diff(row) >= -1e-6)
    assert img[..., 3][:, 12:].sum() > 1.5 * img[..., 3][:, :12].sum()


def test_explicit_opacity_still_means_constant():
    mesh = synthetic.cube(2)
    tf = default_transfer_function(mesh, opacity=0.5)  # what the benchmarks ask for
    assert {a for _, a in tf.opacity} == {0.5}


# ---- unit distance ----

@pytest.mark.parametrize("scale", SCALES)
def test_unit_distance_follows_the_mesh_size(scale):
    mesh = scaled(synthetic.cube(2), scale)
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    want = diag * DEFAULT_UNIT_FRACTION
    assert default_transfer_function(mesh).unit_distance == pytest.approx(want)
    assert default_unit_distance(mesh.bounds) == pytest.approx(want)
    assert TransferFunction.preset("viridis", mesh).unit_distance == pytest.approx(want)
    assert TransferFunction.preset("viridis", mesh.scalar_range, mesh=mesh).unit_distance == pytest.approx(want)


def test_the_same_picture_at_every_scale():
    """The default scene (camera, transfer function) of a mesh in millimetres and of the
    same mesh in kilometres give one picture: nothing in the defaults depends on units."""
    base = synthetic.cube(2, synthetic.linear_field((1.0, 0.5, 0.0), 0.2))
    images = [tetvr.render(scaled(base, s), size=(24, 20), method="reference") for s in SCALES]
    assert images[0][..., 3].max() > 0.3  # not blank
    np.testing.assert_allclose(images[0], images[1], atol=1e-6)


def test_a_unit_distance_in_other_units_is_warned_about():
    mesh = scaled(synthetic.cube(2), 0.02 / np.sqrt(3))  # a 2 cm mesh
    tf = TransferFunction.preset("viridis", mesh.scalar_range)  # unit_distance 1.0: a metre
    with pytest.warns(UserWarning, match=r"nearly blank.*unit_distance"):
        img = tetvr.render(mesh, tf=tf, size=(8, 8), method="reference")
    assert img[..., 3].max() < 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the default rule: no warning, a visible picture
        assert tetvr.render(mesh, size=(8, 8), method="reference")[..., 3].max() > 0.3


def test_warnings_show_the_callers_line_not_tetvrs(tmp_path):
    import meshio

    mesh = scaled(synthetic.cube(2), 0.02 / np.sqrt(3))
    # One zero-volume tet (its fourth point on the plane of three others): read() drops it and says so.
    lo = mesh.points.min(axis=0)
    pts = np.r_[mesh.points, [lo, lo + [0.01, 0, 0], lo + [0, 0.01, 0], lo + [0.01, 0.01, 0]]]
    n = mesh.n_points
    flat = np.r_[mesh.tets, [[n, n + 1, n + 2, n + 3]]]
    values = np.r_[mesh.scalars, np.zeros(4)]
    meshio.write(tmp_path / "m.vtu", meshio.Mesh(pts, [("tetra", flat)], point_data={"s": values}))
    tf = TransferFunction.preset("viridis", mesh.scalar_range)  # unit_distance 1.0 on a 2 cm mesh: warned
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read = tetvr.read(tmp_path / "m.vtu")
        tetvr.render(read, tf=tf, size=(8, 8), method="reference")
    said = {str(w.message).split(":")[0][:40]: w.filename for w in caught}
    assert len(said) >= 2 and any("zero-volume" in k for k in said), said
    assert set(said.values()) == {__file__}, said  # this test's lines, not tetvr's modules


# ---- framing ----

def _ndc(cam: Camera, mesh: tetvr.TetMesh, aspect: float = 1.0) -> np.ndarray:
    p = np.c_[mesh.points, np.ones(mesh.n_points)] @ cam.view_matrix().T
    clip = p @ cam.projection_matrix(aspect).T
    return clip[:, :3] / clip[:, 3:]


@pytest.mark.parametrize("scale", SCALES)
@pytest.mark.parametrize("parallel", [False, True])
def test_fit_frames_the_projected_extent(scale, parallel):
    mesh = pipe(scale)
    cam = Camera.fit(mesh, parallel=parallel)
    ndc = _ndc(cam, mesh)
    assert np.all(np.abs(ndc[:, :2]) <= 1.0) and np.all(np.abs(ndc[:, 2]) <= 1.0)  # all in view, not clipped
    # The extent touches the view (less the margin) on its long side, and is centred.
    assert np.abs(ndc[:, :2]).max() > 0.93
    extent = ndc[:, :2].max(axis=0) + ndc[:, :2].min(axis=0)
    assert np.abs(extent).max() < 0.06 if not parallel else np.abs(extent).max() < 1e-9


def _sphere_camera(mesh: tetvr.TetMesh) -> Camera:
    """The former Camera.fit: the bounding sphere touches the view's short side."""
    from tetvr.core.camera import bounding_sphere

    centre, radius = bounding_sphere(mesh.bounds)
    d = np.array([-1.0, -0.6, -1.2]) / np.linalg.norm([-1.0, -0.6, -1.2])
    dist = radius / np.sin(np.radians(15.0))
    return Camera(position=tuple(centre - d * dist), focal_point=tuple(centre), view_up=(0.0, 1.0, 0.0),
                  clipping_range=(dist - 1.05 * radius, dist + 1.05 * radius))


@pytest.mark.parametrize("scale", SCALES)
def test_fit_fills_more_of_the_picture_than_the_bounding_sphere(scale):
    mesh = pipe(scale)
    tf = default_transfer_function(mesh, opacity=1.0)
    covered = [float(np.mean(tetvr.render(mesh, camera=cam, tf=tf, size=(48, 48), method="reference")[..., 3] > 0.01))
               for cam in (Camera.fit(mesh, view_up=(0, 1, 0)), _sphere_camera(mesh))]  # the pipe across the view
    assert covered[0] > 1.5 * covered[1]


def test_fit_for_a_wide_image_uses_its_width():
    mesh = pipe()
    ndc = _ndc(_fit(mesh, aspect=2.0), mesh, aspect=2.0)
    assert np.abs(ndc[:, :2]).max() <= 1.0 and np.abs(ndc[:, :2]).max() > 0.93


@pytest.mark.parametrize("scale", SCALES)
def test_fit_puts_z_up_unless_looking_along_z(scale):
    mesh = pipe(scale)  # long along z: stands upright in the picture
    cam = Camera.fit(mesh)
    assert cam.view_up == (0.0, 0.0, 1.0)
    ndc = _ndc(cam, mesh)
    top, bottom = mesh.points[:, 2].argmax(), mesh.points[:, 2].argmin()
    assert ndc[top, 1] > 0.5 > -0.5 > ndc[bottom, 1]  # +z points up on the screen
    spread = ndc[:, :2].max(axis=0) - ndc[:, :2].min(axis=0)
    assert spread[1] > 2 * spread[0]  # taller than wide
    assert Camera.fit(mesh, direction=(0.1, 0, -1)).view_up == (0.0, 1.0, 0.0)  # z is (nearly) the view axis
    assert Camera.fit(mesh, view_up=(1, 0, 0)).view_up == (1.0, 0.0, 0.0)  # an explicit one is kept


def test_fit_keeps_its_keywords_and_checks_them():
    mesh = synthetic.cube(2)
    cam = Camera.fit(mesh, direction=(0, 0, -1), view_up=(0, 1, 0), view_angle=40, parallel=False, zoom=0.5)
    assert cam.view_angle == 40 and 0.45 < np.abs(_ndc(cam, mesh)[:, :2]).max() <= 0.5
    with pytest.raises(ValueError, match="zoom must be positive"):
        Camera.fit(mesh, zoom=0)
    with pytest.raises(ValueError, match="direction must not be the zero vector"):
        Camera.fit(mesh, direction=(0, 0, 0))


def test_scene_json_takes_the_rule(tmp_path):
    import json

    from tetvr.scene.scene import Scene

    mesh_path = tmp_path / "pipe.vtu"
    m = pipe(1e-3)
    import meshio

    meshio.write(mesh_path, meshio.Mesh(m.points, [("tetra", m.tets)], point_data={"v": m.scalars}))
    scene = Scene.from_dict(json.loads('{"mesh": "pipe.vtu", "transfer_function": {"preset": "magma"}}'),
                            base_dir=tmp_path)
    want = default_transfer_function(scene.mesh, preset="magma")
    assert scene.tf == want
    assert dataclasses.replace(scene.tf).unit_distance == pytest.approx(default_unit_distance(m.bounds))


def test_auto_chooses_by_the_memory_the_records_take_not_by_a_count_of_tets(monkeypatch):
    """Above 2M tets "auto" kept projected tetrahedra whatever the memory (a 2.63M-tet cube:
    22.5 s a frame where tet marching takes 0.8 s); it now takes tet marching wherever its
    records fit in half the available memory, and projected tetrahedra where they do not."""
    import tetvr.order.method as method_module
    from tetvr.order.method import MARCH_BYTES_PER_TET, choose

    class Big:  # only its size is read before the choice is made
        n_tets = 3_000_000

    monkeypatch.setattr(method_module, "walk_check", lambda mesh: type("C", (), {"reasons": ()})())
    monkeypatch.setattr(method_module, "available_memory", lambda: 4 * Big.n_tets * MARCH_BYTES_PER_TET)
    assert choose(RenderSettings(), Big()) == "raymarch"
    monkeypatch.setattr(method_module, "available_memory", lambda: Big.n_tets * MARCH_BYTES_PER_TET)
    assert choose(RenderSettings(), Big()) == "projected"
    monkeypatch.setattr(method_module, "available_memory", lambda: None)
    assert choose(RenderSettings(), Big()) == "projected"  # unknown: at most AUTO_MAX_TETS

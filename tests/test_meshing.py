"""Surfaces to tet meshes sized for the view (tetvr.mesh.meshing), and fields carried onto them.

The meshing tests need the optional ``mesh`` extra (pytetwild, trimesh) and skip with the
reason when it is missing; the interpolation tests need neither.
"""

from __future__ import annotations

import importlib.util

import math
import sys

import numpy as np
import pytest

from tetvr import Camera, TetMesh, Volume
from tetvr.mesh import meshing
from tetvr.mesh import synthetic
from tetvr.mesh.meshing import interpolate, locate, pixel_footprint, tetrahedralize


def _need_meshing():
    trimesh = pytest.importorskip("trimesh", reason="trimesh is not installed (pip install tetvr[mesh])")
    # Skip only when pytetwild is absent (not importorskip: pytetwild's own __init__ needs
    # pyvista, which tetvr.mesh.meshing works around); an installed but broken one must fail.
    if importlib.util.find_spec("pytetwild") is None:
        pytest.skip("pytetwild is not installed (pip install tetvr[mesh])")
    return trimesh


def _volume(mesh: TetMesh) -> float:
    p = mesh.points[mesh.tets]
    return float(np.abs(np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])).sum() / 6)


LINEAR = np.array([0.6, 0.3, -0.4])


# ---------------------------------------------------------------- the footprint


def test_pixel_footprint_parallel_and_perspective():
    par = Camera(position=(0, 0, 10), parallel_projection=True, parallel_scale=2.5)
    assert pixel_footprint(par, (64, 100), [[0, 0, 0]]) == pytest.approx(0.05)
    per = Camera(position=(0, 0, 10), view_angle=40.0)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    assert pixel_footprint(per, (128, 128), corners) == pytest.approx(2 * 9 * math.tan(math.radians(20)) / 128)
    # Points at or behind the near plane: the near plane takes over.
    inside = Camera(position=(0, 0, 0.5), clipping_range=(0.1, 10))
    assert pixel_footprint(inside, (128, 128), corners) == pytest.approx(2 * 0.1 * math.tan(math.radians(15)) / 128)


# ---------------------------------------------------------------- tetrahedralize


def test_sphere_meshed_at_the_screen_resolution():
    trimesh = _need_meshing()
    sphere = trimesh.creation.icosphere(subdivisions=3)
    camera = Camera(position=(0, 0, 5), focal_point=(0, 0, 0))
    res = tetrahedralize(sphere, camera=camera, size=(24, 24), pixels_per_cell=2.0,
                         field=lambda p: p @ LINEAR)
    print(res.summary())
    assert res.detail == "screen" and not res.limited
    assert res.edge_length == pytest.approx(2.0 * res.pixel_footprint)
    assert res.pixel_footprint == pytest.approx(2 * 4 * math.tan(math.radians(15)) / 24)
    assert res.n_cells == res.mesh.n_tets > 1000 and res.seconds_meshing > 0
    assert _volume(res.mesh) == pytest.approx(sphere.volume, rel=0.01)
    assert np.linalg.norm(res.mesh.points, axis=1).max() < 1.0 + 2e-3 * 2 * math.sqrt(3)  # fTetWild's envelope
    assert np.allclose(res.mesh.scalars, res.mesh.points @ LINEAR)


def test_finer_view_gives_more_cells_and_max_cells_caps_them():
    trimesh = _need_meshing()
    sphere = trimesh.creation.icosphere(subdivisions=2)
    coarse = tetrahedralize(sphere, edge_length=0.5, coarsen=True)
    fine = tetrahedralize(sphere, edge_length=0.25, coarsen=True)
    assert coarse.detail == "explicit" and coarse.pixel_footprint is None
    assert fine.n_cells > 1.5 * coarse.n_cells
    capped = tetrahedralize(sphere, edge_length=0.05, max_cells=2000, coarsen=True)
    assert capped.limited and capped.edge_length > 0.05 and capped.estimated_cells == pytest.approx(2000, rel=1e-6)
    assert capped.n_cells < 3 * 2000
    surf = tetrahedralize((sphere.vertices, sphere.faces), detail="surface")
    assert surf.edge_length == pytest.approx(np.mean(sphere.edges_unique_length), rel=0.05)


def test_field_from_another_mesh_onto_the_new_one():
    trimesh = _need_meshing()
    box = synthetic.cube(4, field=lambda p: p @ LINEAR, size=2.5, rotate=False)
    res = tetrahedralize(trimesh.creation.icosphere(subdivisions=2), edge_length=0.4, field=box,
                         scalar_name="from_box")
    assert res.mesh.scalar_name == "from_box"
    assert np.allclose(res.mesh.scalars, res.mesh.points @ LINEAR, atol=1e-12)


def test_tetrahedralize_rejects_what_it_cannot_use():
    trimesh = _need_meshing()
    sphere = trimesh.creation.icosphere(subdivisions=1)
    with pytest.raises(ValueError, match="needs camera= and size="):
        tetrahedralize(sphere)
    with pytest.raises(ValueError, match="detail must be one of"):
        tetrahedralize(sphere, detail="fine")
    with pytest.raises(ValueError, match="edge_length must be a positive"):
        tetrahedralize(sphere, edge_length=-1.0)
    with pytest.raises(TypeError, match="surface must be"):
        tetrahedralize("sphere.stl", edge_length=0.1)


def test_wrapper_loads_without_pyvista(monkeypatch):
    _need_meshing()
    for name in [m for m in sys.modules if m == "pytetwild" or m.startswith("pytetwild.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "pyvista", None)  # importing pyvista now fails
    wrapper = meshing._tetwild()
    assert hasattr(wrapper, "tetrahedralize_mesh")


# ---------------------------------------------------------------- interpolation


def test_locate_agrees_with_brute_force():
    rng = np.random.default_rng(1)
    mesh = synthetic.cube(3)
    q = rng.uniform(-0.9, 0.9, (3000, 3))
    tet, bary = locate(mesh, q)
    p = mesh.points[mesh.tets]
    m = np.linalg.inv(np.concatenate([p.transpose(0, 2, 1), np.ones((mesh.n_tets, 1, 4))], axis=1))
    all_bary = np.einsum("tij,qj->qti", m, np.c_[q, np.ones(len(q))])
    depth = all_bary.min(axis=2)
    inside = depth.max(axis=1) >= -1e-10
    assert np.array_equal(tet >= 0, inside)
    assert np.all(depth[np.nonzero(inside)[0], tet[inside]] >= -1e-10)
    assert np.allclose(bary[inside], all_bary[np.nonzero(inside)[0], tet[inside]])


def test_interpolate_from_a_mesh_is_exact_for_linear_fields_inside():
    rng = np.random.default_rng(2)
    mesh = synthetic.cube(5, field=lambda p: p @ LINEAR + 0.25)
    q = rng.uniform(-1.0, 1.0, (5000, 3))
    tet, _ = locate(mesh, q)
    got = interpolate(q, mesh)
    inside = tet >= 0
    assert 0 < inside.sum() < len(q)
    assert np.allclose(got[inside], q[inside] @ LINEAR + 0.25, atol=1e-12)
    # Outside: the nearest mesh point's value, or the fill value.
    far = np.array([[5.0, 5.0, 5.0]])
    nearest = np.argmin(np.linalg.norm(mesh.points - far, axis=1))
    assert interpolate(far, mesh)[0] == mesh.scalars[nearest]
    assert np.isnan(interpolate(far, mesh, outside=np.nan)[0])


def test_interpolate_from_scattered_points():
    rng = np.random.default_rng(3)
    src = rng.random((500, 3))
    vals = src @ LINEAR
    assert np.array_equal(interpolate(src[:20], (src, vals), method="nearest"), vals[:20])
    assert np.allclose(interpolate(src[:20], (src, vals)), vals[:20])  # IDW passes through its samples
    q = rng.random((200, 3)) * 0.8 + 0.1
    idw = interpolate(q, (src, np.full(500, 7.0)))
    assert np.allclose(idw, 7.0)  # and reproduces constants
    got = interpolate(q, (src, vals), k=16)
    assert np.abs(got - q @ LINEAR).max() < 0.15
    with pytest.raises(ValueError, match="method must be"):
        interpolate(q, (src, vals), method="kriging")


def test_interpolate_from_a_volume_and_a_function():
    data = np.fromfunction(lambda k, j, i: 0.5 * i + 2.0 * j - k, (5, 6, 7))
    vol = Volume.from_array(data, spacing=(0.5, 0.25, 1.0), origin=(1.0, 0.0, -1.0))
    q = np.array([[1.0 + 0.5 * 2.5, 0.25 * 1.5, -1.0 + 1.0 * 3.2]])
    assert interpolate(q, vol)[0] == pytest.approx(0.5 * 2.5 + 2.0 * 1.5 - 3.2)
    outside = np.array([[100.0, 0.0, -1.0]])
    assert interpolate(outside, vol)[0] == pytest.approx(0.5 * 6)  # clamped to the box's edge
    assert np.isnan(interpolate(outside, vol, outside=np.nan)[0])
    assert interpolate(q, lambda p: p[:, 0] * 2)[0] == pytest.approx(2 * q[0, 0])
    with pytest.raises(ValueError, match="returned shape"):
        interpolate(q, lambda p: np.zeros(3))
    with pytest.raises(TypeError, match="source must be"):
        interpolate(q, "field")

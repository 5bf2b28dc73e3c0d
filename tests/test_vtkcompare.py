"""tetvr against VTK's unstructured-grid mappers (tetvr.vtkcompare).

VTK is optional (``pip install "tetvr[compare]"``): the tests that render with it skip,
with the reason, where it is not installed or cannot open an offscreen (EGL) window.
VTK runs in a child process (tetvr.vtkcompare.VTKProcess), never next to a GL context of
this process.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TransferFunction, synthetic
from tetvr.image import psnr
from tetvr.reference import render_reference
from tetvr.scene import Scene
from tetvr.vtkcompare import PARITY_SETTINGS, VTKProcess, compare, orbit, quantize8, vtk_status

from .conftest import save_failure

MESHES = Path(__file__).resolve().parents[1] / "meshes"


@pytest.fixture(scope="module")
def vtk_ok() -> str:
    # Only an absent VTK (the optional "compare" extra) skips. With VTK installed, a probe
    # that fails (tetvr's VTK-side code, the child process, an empty image) is a failure.
    if importlib.util.find_spec("vtkmodules") is None:
        pytest.skip("VTK is not installed (pip install 'tetvr[compare]')")
    ok, why = vtk_status()
    if not ok:
        pytest.fail(f"VTK is installed but cannot render here: {why}")
    return why


def _linear_scene(n: int = 8):
    """A cube with a transfer function linear over the data range: VTK maps scalars to
    colours at the vertices and interpolates colours, tetvr interpolates scalars; for a
    linear function the two agree, so only the conventions under test remain."""
    mesh = synthetic.cube(n)
    lo, hi = mesh.scalar_range
    tf = TransferFunction(color=((lo, 0.1, 0.2, 0.9), (hi, 1.0, 0.8, 0.1)), opacity=((lo, 0.2), (hi, 0.9)),
                          unit_distance=0.3)
    return mesh, tf


def test_vtk_status_without_vtk(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "vtkmodules" else real(name, *a))
    ok, why = vtk_status.__wrapped__()
    assert not ok and "pip install" in why


def test_orbit_is_vtk_azimuth():
    cam = Camera(position=(0.0, 0.0, 5.0), focal_point=(0.0, 0.0, 1.0), view_up=(0.0, 1.0, 0.0))
    turned = orbit(cam, 90.0)
    np.testing.assert_allclose(turned.position, (4.0, 0.0, 1.0), atol=1e-12)
    assert turned.view_up == cam.view_up and turned.clipping_range == cam.clipping_range
    np.testing.assert_allclose(orbit(turned, -90.0).position, cam.position, atol=1e-12)


@pytest.mark.gl
def test_compare_without_vtk_mappers(tmp_path):
    """compare() with no VTK mapper still measures tetvr against its references."""
    mesh, tf = _linear_scene(3)
    scene = Scene(mesh_path="cube3", mesh=mesh, tf=tf, camera=Camera.fit(mesh), size=(32, 32))
    result = compare(scene, mappers=(), views=1, references=("exact", "vtk"), outdir=tmp_path)
    rows = {m["key"]: m for m in result["methods"]}
    assert set(rows) == {"reference_exact", "reference_vtk", "tetvr", "tetvr_parity"}
    assert rows["tetvr"]["psnr"]["exact"] > 50 and rows["tetvr_parity"]["psnr"]["vtk"] > 45
    assert (tmp_path / "comparison.md").is_file() and (tmp_path / "side_by_side.png").is_file()


def test_pt_image_is_premultiplied_with_linear_extinction(vtk_ok):
    """A slab of constant colour and opacity: VTK's window holds premultiplied colour, and
    its alpha is 1 - exp(-a L/u) (tau = a/u), not ParaView's image-data 1 - (1-a)^(L/u).
    Tolerance 2/255: 8-bit vertex opacity (truncated) and the 8-bit window."""
    mesh = synthetic.slab(thickness=0.2, width=1.0, value=0.5, n=4)
    a, u = 0.6, 0.2
    tf = TransferFunction(color=((0, 1.0, 0.5, 0.0), (1, 1.0, 0.5, 0.0)), opacity=((0, a), (1, a)), unit_distance=u)
    cam = Camera.fit(mesh, direction=(0.05, 0.03, -1.0), parallel=True)  # oblique: no face edge-on
    with VTKProcess(mesh, tf, mapper="pt", size=(32, 32)) as r:
        px = r.render(cam)[16, 16].astype(np.float64)
        assert r.info["mapper_class"] == "vtkOpenGLProjectedTetrahedraMapper"
    chord = 0.2 / abs(np.asarray(cam.direction)[2])
    assert px[3] == pytest.approx(-np.expm1(-a * chord / u), abs=2 / 255)
    assert abs(px[3] - (1 - (1 - a) ** (chord / u))) > 0.05
    np.testing.assert_allclose(px[:3], np.array([1.0, 0.5, 0.0]) * px[3], atol=2 / 255)


def test_pt_matches_tetvr_parity(vtk_ok):
    """VTK's projected tetrahedra against tetvr's PARITY_SETTINGS, parallel and perspective.

    Bar: PSNR >= 50 dB and no pixel off by more than 4/255 (measured 60 dB, 2/255 on
    cube(10)). What remains: VTK truncates vertex colours and opacities to 8 bits
    (x 255.9999, then averages two of them at the thick vertex and truncates again) and
    rounds its window to 8 bits; tetvr's image is rounded once, at the end."""
    mesh, tf = _linear_scene(8)
    cams = [Camera.fit(mesh, parallel=True), Camera.fit(mesh, direction=(0.7, -0.4, -1.0))]
    with VTKProcess(mesh, tf, mapper="pt", size=(96, 96)) as r:
        vtk_images = [r.render(c) for c in cams]
    with tetvr.Renderer(PARITY_SETTINGS) as t:
        ours = [quantize8(t.render(mesh, c, tf, size=(96, 96))) for c in cams]
    for cam, got, want in zip(cams, ours, vtk_images):
        value = psnr(got, want)
        worst = float(np.abs(got - want).max()) * 255
        if value < 50.0 or worst > 4.0:
            where = save_failure(f"vtk_pt_parallel_{cam.parallel_projection}", got, want)
            pytest.fail(f"parity vs VTK PT: {value:.1f} dB, worst {worst:.1f}/255 (images in {where})")


def test_pt_renders_the_same_cells(vtk_ok):
    """Cell data goes to VTK as cell scalars: its projected tetrahedra hold each cell's value
    constant, as tetvr does. Parity mode against VTK on random cell values (measured 59.3 dB,
    2/255 at worst; the averaged field 25 dB),
    and far from the same field averaged onto the points (so VTK did get the cells)."""
    mesh, tf = _linear_scene(6)
    mesh = mesh.with_cell_scalars(np.random.default_rng(5).uniform(*mesh.scalar_range, mesh.n_tets))
    cam = Camera.fit(mesh, direction=(0.7, -0.4, -1.0))
    with VTKProcess(mesh, tf, mapper="pt", size=(96, 96)) as r:
        want = r.render(cam)
    with tetvr.Renderer(PARITY_SETTINGS) as t:
        got = quantize8(t.render(mesh, cam, tf, size=(96, 96)))
        averaged = quantize8(t.render(mesh.averaged(), cam, tf, size=(96, 96)))
    value, worst = psnr(got, want), float(np.abs(got - want).max()) * 255
    if value < 50.0 or worst > 4.0:
        where = save_failure("vtk_pt_cell_data", got, want)
        pytest.fail(f"cell data, parity vs VTK PT: {value:.1f} dB, worst {worst:.1f}/255 (images in {where})")
    assert psnr(averaged, want) < value - 15.0


def test_pt_camera_matches_the_reference(vtk_ok):
    """Same camera semantics: VTK's silhouette is the reference's (IoU of covered pixels).
    An off-centre perspective view, non-square, with a clipping range VTK must keep."""
    mesh, tf = _linear_scene(4)
    cam = Camera.fit(mesh, direction=(-0.3, 0.8, -1.0), view_angle=40.0, zoom=1.3)
    with VTKProcess(mesh, tf, mapper="pt", size=(80, 60)) as r:
        got = r.render(cam)
    want = render_reference(mesh, cam, tf, (80, 60), optics="vtk")
    a, b = got[..., 3] > 4 / 255, want[..., 3] > 4 / 255
    assert (a & b).sum() / (a | b).sum() > 0.97
    assert psnr(got, want) > 40.0


@pytest.mark.parametrize("mapper", ["bunyk", "zsweep"])
def test_ray_casters_render_the_same_scene(vtk_ok, mapper):
    """VTK's CPU ray casters (pre-integrated, tau = a/u) follow VTK's convention: bar 33 dB
    against the reference in it (measured 37 dB Bunyk, 42 dB Z sweep at 96x96: 8 bits,
    and their silhouettes are about half a pixel off), 5 dB better than against tetvr's."""
    mesh, tf = _linear_scene(4)
    cam = Camera.fit(mesh)
    with VTKProcess(mesh, tf, mapper=mapper, size=(96, 96)) as r:
        got = r.render(cam)
    linear = psnr(got, render_reference(mesh, cam, tf, (96, 96), optics="linear"))
    assert linear > 33.0
    assert linear > psnr(got, render_reference(mesh, cam, tf, (96, 96), optics="exact")) + 5.0


def test_compare_writes_pictures_and_tables(vtk_ok, tmp_path):
    mesh, tf = _linear_scene(4)
    scene = Scene(mesh_path="cube4", mesh=mesh, tf=tf, camera=Camera.fit(mesh), size=(48, 40))
    result = compare(scene, mappers=("pt",), views=2, references=("exact", "vtk"), outdir=tmp_path)
    rows = {m["key"]: m for m in result["methods"]}
    assert rows["vtk_pt"]["mapper_class"] == "vtkOpenGLProjectedTetrahedraMapper"
    assert len(rows["vtk_pt"]["view_change_samples_s"]) == 2 and rows["vtk_pt"]["first_frame_s"] > 0
    assert rows["tetvr_parity"]["psnr_vs_vtk_pt"] > 45.0
    # VTK follows its own convention far better than tetvr's exact one.
    assert rows["vtk_pt"]["psnr"]["vtk"] > rows["vtk_pt"]["psnr"]["exact"] + 10
    assert rows["tetvr"]["psnr"]["exact"] > rows["vtk_pt"]["psnr"]["exact"]
    saved = json.loads((tmp_path / "comparison.json").read_text())
    assert saved["vtk"]["window"] and saved["scene"]["n_tets"] == mesh.n_tets
    for name in ("comparison.md", "side_by_side.png", "differences.png", "vtk_pt.png", "vtk_pt_diff.png"):
        assert (tmp_path / name).is_file(), name


def test_cli_compare(vtk_ok, tmp_path):
    from tetvr.cli import main

    scene = json.loads((MESHES / "demo.json").read_text())
    scene["mesh"] = str(MESHES / scene["mesh"])
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))
    out = tmp_path / "out"
    assert main(["compare", str(path), "-o", str(out), "--mappers", "pt", "--views", "1", "--size", "48", "36"]) == 0
    table = (out / "comparison.md").read_text()
    assert "vtkProjectedTetrahedraMapper" in table and "tetvr GPU, VTK parity" in table

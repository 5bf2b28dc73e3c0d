"""tetvr against VTK's unstructured-grid mappers (tetvr.apps.vtkcompare).

VTK is optional (``pip install "tetvr[compare]"``): the tests that render with it skip,
with the reason, where it is not installed or cannot open an offscreen (EGL) window.
VTK runs in a child process (tetvr.apps.vtkrender.VTKProcess), never next to a GL context of
this process.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TetMesh, TransferFunction
from tetvr.mesh import synthetic
from tetvr.core.image import psnr
from tetvr.reference.tets import render_reference
from tetvr.scene.scene import Scene
from tetvr.apps.vtkcompare import compare, orbit, quantize8
from tetvr.apps.vtkrender import VTKProcess, vtk_status
from tetvr.settings import PARITY_SETTINGS

from .conftest import save_failure, shared_file

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


def _spike_tf(mesh):
    """Cool to warm with a narrow opacity spike: far from linear between vertices, where
    VTK's classification at the vertices departs from the transfer function per pixel."""
    lo, hi = mesh.scalar_range
    return TransferFunction.preset("cool-to-warm", (lo, hi), unit_distance=0.3,
                                   opacity=[(0.0, 0.02), (0.37, 0.05), (0.4, 0.9), (0.43, 0.05), (1.0, 0.3)])


def _parity_error(got, want):
    """PSNR, the largest channel error in 8-bit steps, and the pixels off by more than one step."""
    err = np.abs(got.astype(np.float64) - want).max(axis=-1) * 255
    return psnr(got, want), float(err.max()), int((err > 1.5).sum())


@pytest.mark.parametrize("tf_kind", ["linear", "spike"])
def test_pt_matches_tetvr_parity(vtk_ok, tf_kind):
    """VTK's projected tetrahedra against tetvr's PARITY_SETTINGS: a parallel view, a
    perspective one and a close wide-angle perspective one (where VTK's square-root table
    for the thickness rounds most; docs/paraview.md), with a linear transfer function and a
    spike (vertex classification). Parity takes VTK's steps, so the bar is one 8-bit step:
    PSNR >= 55 dB, no channel off by more than 1/255 (float rounding in two programs, then
    VTK's 8-bit window). Measured 84.8-92.5 dB (inf where identical), max 1/255."""
    mesh, tf = _linear_scene(8)
    if tf_kind == "spike":
        tf = _spike_tf(mesh)
    cams = {"parallel": Camera.fit(mesh, parallel=True),
            "perspective": Camera.fit(mesh, direction=(0.7, -0.4, -1.0)),
            "close perspective": Camera.fit(mesh, direction=(0.2, 0.5, -1.0), view_angle=60.0, zoom=1.6)}
    with VTKProcess(mesh, tf, mapper="pt", size=(96, 96)) as r:
        vtk_images = {k: r.render(c) for k, c in cams.items()}
    with tetvr.Renderer(PARITY_SETTINGS) as t:
        ours = {k: quantize8(t.render(mesh, c, tf, size=(96, 96))) for k, c in cams.items()}
    for name, want in vtk_images.items():
        assert (want[..., 3] > 0.1).sum() > 2000  # a real picture
        value, worst, beyond = _parity_error(ours[name], want)
        if value < 55.0 or worst > 1.5 or beyond:
            where = save_failure(f"vtk_pt_{tf_kind}_{name.replace(' ', '_')}", ours[name], want)
            pytest.fail(f"{name}: parity vs VTK PT {value:.1f} dB, worst {worst:.1f}/255, {beyond} pixels beyond "
                        f"1/255 (images in {where})")


def test_pt_perspective_thickness_table(vtk_ok):
    """VTK's perspective thickness: a 2,048-entry square-root table over [0, max_edge^2],
    indexed by truncation, so a tet thinner than max_edge / 45 gets thickness 0. A small tet
    (edges 0.15) in a mesh whose longest edge is 14.1 (limit 0.31): VTK draws it in a
    parallel view (exact thickness) and not at all in perspective, and so does parity."""
    big = [[20, 0, 0], [30, 0, 0], [20, 10, 0], [20, 0, 10]]  # out of view; only sets max_edge
    small = [[0, 0, 0], [0.15, 0, 0], [0, 0.15, 0], [0, 0, 0.15]]
    mesh = TetMesh.from_arrays(np.array(big + small, float), [[0, 1, 2, 3], [4, 5, 6, 7]], np.full(8, 0.5))
    tf = TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)), opacity=((0, 1.0), (1, 1.0)), unit_distance=0.05)
    view = TetMesh.from_arrays(np.array(small, float), [[0, 1, 2, 3]], np.full(4, 0.5))
    with VTKProcess(mesh, tf, mapper="pt", size=(32, 32)) as r, tetvr.Renderer(PARITY_SETTINGS) as t:
        for parallel in (True, False):
            cam = Camera.fit(view, direction=(0.3, 0.2, -1.0), parallel=parallel)
            want = r.render(cam)
            got = quantize8(t.render(mesh, cam, tf, size=(32, 32)))
            assert (want[..., 3].max() > 0.5) if parallel else (want[..., 3].max() == 0.0)
            assert np.abs(got - want).max() <= 1.5 / 255, f"parallel={parallel}"


def test_pt_class2_opacity_bug(vtk_ok):
    """VTK interpolates the second crossing edge's opacity with the first edge's parameter
    (alpha for beta) at a class-2 tet's thick vertex. One tet whose edges cross off their
    midpoints, opacity 0 -> 1 along the second edge: parity reproduces VTK's centre alpha
    (measured equal), which is 0.045 off the formula's (tetvr's reference in VTK's
    convention). Bar: the whole image within one 8-bit step of VTK."""
    pts = np.array([[-1, 0, 0.5], [1, 0, 0.5], [0, -0.3, -0.5], [0, 1.2, -0.5]], float)
    tf = TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)), opacity=((0, 0.0), (1, 1.0)), unit_distance=1.0)
    mesh = TetMesh.from_arrays(pts, [[0, 1, 2, 3]], [0, 0, 0, 1])
    cam = Camera.fit(mesh, direction=(0.001, 0.002, -1.0), parallel=True)
    with VTKProcess(mesh, tf, size=(64, 64)) as r:
        want = r.render(cam)
    with tetvr.Renderer(PARITY_SETTINGS) as t:
        got = quantize8(t.render(mesh, cam, tf, size=(64, 64)))
    formula = render_reference(mesh, cam, tf, (64, 64), optics="vtk")
    assert abs(want[32, 32, 3] - formula[32, 32, 3]) > 0.03  # the bug is there to reproduce
    value, worst, beyond = _parity_error(got, want)
    assert worst <= 1.5 and beyond == 0, (value, worst)


def test_pt_parity_on_bluntfin(vtk_ok):
    """A real mesh whose cells span 3.6 down to far below max_edge / 45 (the perspective
    thickness table zeroes 17 % of them): bluntfin (187k tets) at 96x96, linear and spike
    transfer functions, parallel and perspective. Bar: PSNR >= 55 dB, no channel off by
    more than 1/255; measured at 256x256 88-101 dB, max 1/255."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # zero-volume tets dropped on reading
        mesh = tetvr.read(shared_file("tets/bluntfin_tets.vtu"))
    lo, hi = mesh.scalar_range
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    tfs = {"linear": TransferFunction(color=((lo, 0.1, 0.2, 0.9), (hi, 1.0, 0.8, 0.1)),
                                      opacity=((lo, 0.2), (hi, 0.9)), unit_distance=diag / 20),
           "spike": dataclasses.replace(_spike_tf(mesh), unit_distance=diag / 20)}
    for name, tf in tfs.items():
        cams = {p: Camera.fit(mesh, parallel=p == "parallel") for p in ("parallel", "perspective")}
        with VTKProcess(mesh, tf, mapper="pt", size=(96, 96)) as r:
            want = {p: r.render(c) for p, c in cams.items()}
        with tetvr.Renderer(PARITY_SETTINGS) as t:
            got = {p: quantize8(t.render(mesh, c, tf, size=(96, 96))) for p, c in cams.items()}
        for p in cams:
            value, worst, beyond = _parity_error(got[p], want[p])
            if value < 55.0 or worst > 1.5 or beyond:
                where = save_failure(f"vtk_pt_bluntfin_{name}_{p}", got[p], want[p])
                pytest.fail(f"bluntfin {name} {p}: {value:.1f} dB, worst {worst:.1f}/255, {beyond} pixels beyond "
                            f"1/255 (images in {where})")


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
    from tetvr.apps.cli import main

    scene = json.loads((MESHES / "demo.json").read_text())
    scene["mesh"] = str(MESHES / scene["mesh"])
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(scene))
    out = tmp_path / "out"
    assert main(["compare", str(path), "-o", str(out), "--mappers", "pt", "--views", "1", "--size", "48", "36"]) == 0
    table = (out / "comparison.md").read_text()
    assert "vtkProjectedTetrahedraMapper" in table and "tetvr GPU, VTK parity" in table

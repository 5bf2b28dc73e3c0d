"""VTK parity with a clip and with opaque surfaces, as ParaView draws them (tetvr.gl.vtkpt).

ParaView clips a volume with the Clip filter (vtkTableBasedClipDataSet, then the volume
representation's vtkDataSetTriangleFilter): tetvr.mesh.clipfilter takes those steps on the
CPU. "Projected tetra" depth-tests each fragment of a tet against the opaque geometry drawn
before it: parity does the same per fragment. Checked without VTK against oracles that
follow from that (the cut's geometry and field; tets wholly behind a surface vanish; a tet
across a surface is drawn whole or not at all at each pixel), and against VTK itself (its
filters' output cell for cell, and its pictures) where VTK is installed, in a child process
as in tests/test_vtkcompare.py.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import itertools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import tetvr
from tetvr import Camera, Clip, Surface, TetMesh, TransferFunction
from tetvr.core.camera import resolve_clipping_range, union_bounds
from tetvr.core.image import psnr
from tetvr.core.surface import surface_hits
from tetvr.mesh import synthetic
from tetvr.mesh.clipfilter import _PRISM, _TETRA, _WEDGE_MAP, _cut, _triangulated, clip_cells
from tetvr.settings import PARITY_SETTINGS

from .conftest import save_failure

ROOT = Path(__file__).resolve().parents[1]
RED = (1.0, 0.2, 0.2)  # 8-bit exact, so VTK's framebuffer holds it as tetvr does


def _linear_field(p: np.ndarray) -> np.ndarray:
    return 0.3 + p @ np.array([0.5, -0.25, 0.75])


def _tf(mesh: TetMesh, spike: bool = False) -> TransferFunction:
    lo, hi = mesh.scalar_range
    if spike:
        return TransferFunction.preset("cool-to-warm", (lo, hi), unit_distance=0.3,
                                       opacity=[(0.0, 0.02), (0.37, 0.05), (0.4, 0.9), (0.43, 0.05), (1.0, 0.3)])
    return TransferFunction(color=((lo, 0.1, 0.2, 0.9), (hi, 1.0, 0.8, 0.1)), opacity=((lo, 0.2), (hi, 0.9)),
                            unit_distance=0.3)


def _quad(corners, color=RED) -> Surface:
    """An opaque quad, unlit (ambient 1: its colour everywhere, as VTK's with ambient 1, diffuse 0)."""
    return Surface(np.asarray(corners, float), [[0, 1, 2], [1, 3, 2]], color=color, ambient=1.0)


# ---------------------------------------------------------------------------- the cut, no GL
def test_cut_keeps_the_clipped_box_and_the_linear_field():
    """A box of six planes on an axis-aligned cube: the pieces fill the box exactly (their
    volumes sum to its volume), every point is inside it, the field at every new point is
    the mesh's linear field there, and each piece carries the cell data of the tet it came from."""
    mesh = synthetic.cube(5, field=_linear_field, rotate=False)
    lo, hi = np.array([-0.37, -0.21, -0.43]), np.array([0.29, 0.41, 0.17])
    cut = clip_cells(mesh, Clip.box(lo, hi))
    assert cut is not None and cut.n_tets > mesh.n_tets // 4
    q = cut.points[cut.tets]
    volume = np.abs(np.einsum("ij,ij->i", np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), q[:, 3] - q[:, 0])) / 6
    assert volume.sum() == pytest.approx(np.prod(hi - lo), rel=1e-12)
    assert np.all(cut.points >= lo - 1e-12) and np.all(cut.points <= hi + 1e-12)
    np.testing.assert_allclose(cut.scalars, _linear_field(cut.points), atol=1e-12)
    cells = mesh.with_cell_scalars(np.arange(mesh.n_tets, dtype=float))
    pieces = clip_cells(cells, Clip.box(lo, hi))
    parent = mesh.tets[pieces.cell_scalars.astype(int)]
    centroid = pieces.points[pieces.tets].mean(axis=1)
    a = mesh.points[parent]
    bary = np.linalg.solve(np.transpose(a[:, 1:] - a[:, :1], (0, 2, 1)), (centroid - a[:, 0])[..., None])[..., 0]
    assert np.all(bary >= -1e-9) and np.all(bary.sum(axis=1) <= 1 + 1e-9)  # each piece inside its cell


def test_cut_edge_cases():
    """Nothing kept: None. Everything kept: the mesh. A plane through a vertex, keeping the
    rest of the tet: the slivers it may leave at the vertex are dropped without a warning,
    and the volume is the tet's."""
    import warnings

    mesh = synthetic.single_tet()
    assert clip_cells(mesh, Clip.plane((5, 0, 0), (1, 0, 0))) is None
    whole = clip_cells(mesh, Clip.plane((-5, 0, 0), (1, 0, 0)))
    assert np.array_equal(whole.tets, mesh.tets) and np.array_equal(whole.points, mesh.points)
    v = mesh.points[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        through = clip_cells(mesh, Clip.plane(v, mesh.points[1:].mean(axis=0) - v))
    q = through.points[through.tets]
    volume = np.abs(np.einsum("ij,ij->i", np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), q[:, 3] - q[:, 0])).sum()
    p = mesh.points
    assert volume == pytest.approx(abs(np.linalg.det(p[1:] - p[0])), rel=1e-9)


# ---------------------------------------------------------------------------- VTK, in a child process
_VTK_CHILD = r'''
import itertools, json, sys, types
import numpy as np

def grid_from(mods, points, cells):
    ns = mods.np_support
    g = mods.data.vtkUnstructuredGrid()
    p = mods.core.vtkPoints(); p.SetData(ns.numpy_to_vtk(np.asarray(points, float), deep=True)); g.SetPoints(p)
    for kind, ids in cells:
        l = mods.core.vtkIdList()
        for i in ids:
            l.InsertNextId(int(i))
        g.InsertNextCell(kind, l)
    return g

def tets_of(grid):
    return np.array([[grid.GetCell(i).GetPointId(j) for j in range(4)] for i in range(grid.GetNumberOfCells())])

def main(path_in, path_out):
    from tetvr.apps.vtkrender import _import_vtk
    from vtkmodules.vtkCommonDataModel import vtkPlane
    from vtkmodules.vtkFiltersGeneral import vtkDataSetTriangleFilter, vtkTableBasedClipDataSet
    mods = _import_vtk()
    ns = mods.np_support
    d = np.load(path_in)
    mode = str(d["mode"])
    out = {}
    def triangulate(g):
        f = vtkDataSetTriangleFilter(); f.SetInputData(g); f.TetrahedraOnlyOn(); f.Update()
        return tets_of(f.GetOutput())
    keep = []  # the pipeline's objects, alive until the end
    def clipped(grid_input):
        n, w = d["plane"][:3], float(d["plane"][3])
        plane = vtkPlane(); plane.SetNormal(*n); plane.SetOrigin(*(-w * n))
        clip = vtkTableBasedClipDataSet(); clip.SetInputData(grid_input); clip.SetClipFunction(plane)
        clip.InsideOutOff()
        tri = vtkDataSetTriangleFilter(); tri.SetInputConnection(clip.GetOutputPort()); tri.TetrahedraOnlyOn()
        tri.Update()
        keep.extend([grid_input, plane, clip, tri])
        return tri
    if mode == "orders":  # every order of a tet's and a wedge's point ids through the triangle filter
        tet, prism = np.asarray(d["tetra"], float), np.asarray(d["prism"], float)
        beside = (mods.data.VTK_WEDGE, range(4, 10))  # a wedge, so that the tet is triangulated too
        out["tet"] = np.array([triangulate(grid_from(mods, np.concatenate([tet[np.argsort(p)], prism + 5]),
                                                     [(mods.data.VTK_TETRA, p), beside]))[0]
                               for p in itertools.permutations(range(4))])
        out["wedge"] = np.array([triangulate(grid_from(mods, prism[np.argsort(p)], [(mods.data.VTK_WEDGE, p)]))
                                 for p in itertools.permutations(range(6))])
    elif mode == "cut":
        g = grid_from(mods, d["points"], [(mods.data.VTK_TETRA, t) for t in d["tets"]])
        s = ns.numpy_to_vtk(np.asarray(d["scalars"], float), deep=True); s.SetName("s"); g.GetPointData().SetScalars(s)
        o = clipped(g).GetOutput()
        out.update(points=ns.vtk_to_numpy(o.GetPoints().GetData()), tets=tets_of(o),
                   scalars=ns.vtk_to_numpy(o.GetPointData().GetArray("s")))
    else:  # render: VTK's projected tetrahedra, after a Clip filter and/or with an opaque actor
        from tetvr import Camera, TransferFunction
        from tetvr.apps.vtkrender import VTKRenderer
        mesh = types.SimpleNamespace(points=d["points"], tets=d["tets"], scalars=d["scalars"], scalar_name="s",
                                     cell_scalars=None, n_tets=len(d["tets"]))
        r = VTKRenderer(mesh, TransferFunction.from_dict(json.loads(str(d["tf"]))), mapper="pt",
                        size=tuple(int(v) for v in d["size"]))
        if "plane" in d.files:
            r._mapper.SetInputConnection(clipped(r._mapper.GetInput()).GetOutputPort())
        if "surface_points" in d.files:
            from vtkmodules.vtkRenderingCore import vtkActor, vtkPolyDataMapper
            poly = mods.data.vtkPolyData()
            pts = mods.core.vtkPoints(); pts.SetData(ns.numpy_to_vtk(np.asarray(d["surface_points"], float), deep=True))
            polys = mods.data.vtkCellArray()
            for tri in d["surface_triangles"]:
                polys.InsertNextCell(3, [int(i) for i in tri])
            poly.SetPoints(pts); poly.SetPolys(polys)
            m = vtkPolyDataMapper(); m.SetInputData(poly); m.ScalarVisibilityOff()
            actor = vtkActor(); actor.SetMapper(m)
            prop = actor.GetProperty(); prop.SetColor(*d["surface_color"]); prop.SetAmbient(1.0)
            prop.SetDiffuse(0.0); prop.SetSpecular(0.0)
            r._renderer.AddActor(actor)
        out["images"] = np.stack([r.render(Camera.from_dict(c)) for c in json.loads(str(d["cameras"]))])
        r.release()
    np.savez(path_out, **out)

main(sys.argv[1], sys.argv[2])
'''


def _vtk(tmp_path: Path, **data) -> dict[str, np.ndarray]:
    """Run ``_VTK_CHILD`` on ``data``; its arrays back."""
    if importlib.util.find_spec("vtkmodules") is None:
        pytest.skip("VTK is not installed (pip install 'tetvr[compare]')")
    src, dst = tmp_path / "in.npz", tmp_path / "out.npz"
    np.savez(src, **data)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p))
    run = subprocess.run([sys.executable, "-c", _VTK_CHILD, str(src), str(dst)], env=env, capture_output=True,
                         text=True, timeout=600)
    if run.returncode != 0:
        pytest.fail(f"the VTK process failed (exit code {run.returncode}): {run.stderr[-2000:]}")
    return dict(np.load(dst))


def test_triangulation_is_vtks_for_every_order_of_ids(tmp_path):
    """vtkDataSetTriangleFilter on one tet (in a grid with a wedge, so that it is
    triangulated too) and one wedge, for every order of their point ids: tetvr's emulation
    of vtkOrderedTriangulator gives the same tets, in the same order, each with the same
    vertex order (24 + 720 cases)."""
    want = _vtk(tmp_path, mode="orders", tetra=np.array(_TETRA), prism=np.array(_PRISM))
    tets = np.array(list(itertools.permutations(range(4))))
    wedges = np.array(list(itertools.permutations(range(6))))
    assert np.array_equal(_triangulated(tets, _TETRA, (0, 1, 2, 3))[:, 0], want["tet"])
    assert np.array_equal(_triangulated(wedges, _PRISM, _WEDGE_MAP), want["wedge"])


@pytest.mark.parametrize("seed", [1, 2])
def test_cut_is_vtks_clip_filter(tmp_path, seed):
    """One plane through a rotated cube(5): tetvr's cut against vtkTableBasedClipDataSet +
    vtkDataSetTriangleFilter: the same points (to float64 rounding: VTK evaluates the plane
    from an origin), the same scalars, and the same tets row for row."""
    mesh = synthetic.cube(5)
    rng = np.random.default_rng(seed)
    clip = Clip.plane(rng.normal(size=3) * 0.1, rng.normal(size=3))
    want = _vtk(tmp_path, mode="cut", points=mesh.points, tets=mesh.tets, scalars=mesh.scalars,
                plane=np.array(clip.planes[0]))
    points, tets, scalars, _ = _cut(mesh.points, mesh.tets.astype(np.int64), mesh.scalars, None,
                                    np.array(clip.planes[0]))
    assert want["tets"].shape[0] > 100
    assert np.array_equal(tets, want["tets"])
    np.testing.assert_allclose(points, want["points"], atol=1e-14)
    np.testing.assert_allclose(scalars, want["scalars"], atol=1e-14)


def _cameras(mesh: TetMesh, *bounds) -> dict[str, Camera]:
    """A parallel and a perspective view, each with the clipping range ParaView would take."""
    box = union_bounds(*bounds)
    return {"parallel": resolve_clipping_range(Camera.fit(mesh, parallel=True, direction=(0.3, -0.5, -1.0)), box),
            "perspective": resolve_clipping_range(Camera.fit(mesh, direction=(0.7, -0.4, -1.0)), box)}


@pytest.mark.gl
@pytest.mark.parametrize("case", ["surface", "clip", "clip and surface, spike"])
def test_parity_matches_vtk(tmp_path, case):
    """VTK's projected tetrahedra with an opaque actor through the volume and/or after a
    Clip filter, against parity with the same tetvr.Surface / tetvr.Clip: cube(8), a linear
    transfer function (and the spike, whose vertex classification at the cut's new points
    shows), parallel and perspective views at 96x96. Parity takes VTK's steps, so the bar is
    that of tests/test_vtkcompare.py: PSNR >= 55 dB, no channel off by more than 1/255.
    Measured: identical in the parallel views, 92.5 dB and 1/255 in the perspective ones."""
    from tetvr.apps.vtkcompare import quantize8

    mesh = synthetic.cube(8)
    tf = _tf(mesh, spike="spike" in case)
    c = mesh.bounds.mean(axis=0)
    surface = _quad(c + np.array([[-1.5, -1.5, -0.2], [1.5, -1.5, 0.25], [-1.5, 1.5, 0.1], [1.5, 1.5, 0.55]]))
    clip = Clip.plane(c + np.array([0.031, -0.017, 0.023]), (1.0, 0.35, -0.25)) if "clip" in case else None
    surfaces = [surface] if "surface" in case else []
    shown = mesh if clip is None else clip_cells(mesh, clip)
    cams = _cameras(mesh, shown.bounds, *(s.points for s in surfaces))
    data = dict(mode="render", points=mesh.points, tets=mesh.tets, scalars=mesh.scalars, size=np.array([96, 96]),
                tf=json.dumps(tf.to_dict()), cameras=json.dumps([cam.to_dict() for cam in cams.values()]))
    if clip is not None:
        data["plane"] = np.array(clip.planes[0])
    if surfaces:
        data.update(surface_points=surface.points, surface_triangles=surface.triangles,
                    surface_color=np.array(surface.color))
    want = dict(zip(cams, _vtk(tmp_path, **data)["images"]))
    with tetvr.Renderer(PARITY_SETTINGS) as r:
        got = {k: quantize8(r.render(mesh, cam, tf, size=(96, 96), clip=clip, surfaces=surfaces))
               for k, cam in cams.items()}
        plain = {k: quantize8(r.render(mesh, cam, tf, size=(96, 96))) for k, cam in cams.items()}
    for name in cams:
        assert (want[name][..., 3] > 0.1).sum() > 2000  # a real picture
        assert psnr(plain[name], want[name]) < 30.0  # which the clip or surface changes
        err = np.abs(got[name].astype(np.float64) - want[name]).max(axis=-1) * 255
        value, beyond = psnr(got[name], want[name]), int((err > 1.5).sum())
        if value < 55.0 or err.max() > 1.5 or beyond:
            where = save_failure(f"parity_{case.replace(' ', '_').replace(',', '')}_{name}", got[name], want[name])
            pytest.fail(f"{case}, {name}: parity vs VTK PT {value:.1f} dB, worst {err.max():.1f}/255, {beyond} "
                        f"pixels beyond 1/255 (images in {where})")


@pytest.mark.gl
def test_far_plane_cuts_like_vtks():
    """The fan's vertices carry their NDC depth, so GL clips a tet's triangles at the far
    plane as it clips VTK's (a hand-set clipping range through the mesh; ParaView's own
    range holds every cell). Bar as above; measured 92.5 dB and 1/255 in both views
    (34.5 / 35.8 dB, 48/255 with the depth left out)."""
    from tetvr.apps.vtkcompare import quantize8
    from tetvr.apps.vtkrender import VTKProcess

    if importlib.util.find_spec("vtkmodules") is None:
        pytest.skip("VTK is not installed (pip install 'tetvr[compare]')")
    mesh = synthetic.cube(8)
    tf = _tf(mesh)
    cams = {}
    for parallel in (True, False):
        cam = resolve_clipping_range(Camera.fit(mesh, parallel=parallel, direction=(0.7, -0.4, -1.0)), mesh.bounds)
        middle = float(np.linalg.norm(np.subtract(cam.position, cam.focal_point)))
        cams[parallel] = dataclasses.replace(cam, clipping_range=(cam.clipping_range[0], middle + 0.1))
    with VTKProcess(mesh, tf, mapper="pt", size=(96, 96)) as r:
        want = {k: r.render(cam) for k, cam in cams.items()}
    with tetvr.Renderer(PARITY_SETTINGS) as t:
        got = {k: quantize8(t.render(mesh, cam, tf, size=(96, 96))) for k, cam in cams.items()}
        whole = {k: quantize8(t.render(mesh, dataclasses.replace(cam, clipping_range=None), tf, size=(96, 96)))
                 for k, cam in cams.items()}
    for k in cams:
        assert psnr(whole[k], want[k]) < 30.0  # the far plane does cut
        err = np.abs(got[k].astype(np.float64) - want[k]).max(axis=-1) * 255
        assert psnr(got[k], want[k]) >= 55.0 and err.max() <= 1.5, (k, psnr(got[k], want[k]), err.max())


# ---------------------------------------------------------------------------- oracles without VTK
def _two_blocks() -> tuple[TetMesh, TetMesh]:
    """Two cubes of cells one behind the other along z (z in [-0.5, 0.5] and [1, 2]), and
    the front one alone."""
    block = synthetic.cube(3, field=_linear_field, rotate=False)
    back, front = block.points, block.points + np.array([0.0, 0.0, 1.5])
    both = TetMesh.from_arrays(np.concatenate([back, front]), np.concatenate([block.tets, block.tets + len(back)]),
                               np.concatenate([_linear_field(back), _linear_field(front)]))
    return both, TetMesh.from_arrays(front, block.tets, _linear_field(front))


@pytest.mark.gl
@pytest.mark.parametrize("parallel", [True, False])
def test_tets_behind_a_surface_vanish(parallel):
    """A surface in the gap between two blocks of cells, seen from the front block's side:
    every fragment of the back block is behind it and dropped, every one of the front block
    kept, so the picture is the front block alone over the surface's colour (same camera;
    the back block changes neither the drawing order of the front one nor VTK's thickness
    table, whose cells are the same size). Bar: 1e-5, float32 rounding: each mesh goes to
    the GPU relative to its own centre (measured 2e-6); a back-block fragment left would
    change it by more than 0.05."""
    both, front = _two_blocks()
    tf = _tf(both)
    quad = _quad([[-2, -2, 0.75], [2, -2, 0.75], [-2, 2, 0.75], [2, 2, 0.75]])
    cam = resolve_clipping_range(Camera.fit(both, direction=(0.2, 0.1, -1.0), parallel=parallel),
                                 union_bounds(both.bounds, quad.points))
    with tetvr.Renderer(PARITY_SETTINGS) as r:
        got = r.render(both, cam, tf, size=(64, 64), surfaces=[quad])
        alone = r.render(front, cam, tf, size=(64, 64))
        behind = r.render(both, cam, tf, size=(64, 64))
    _, rgb = surface_hits([quad], cam, (64, 64))
    hit = rgb.any(axis=-1)
    assert hit.all()  # the surface fills the view
    under = np.concatenate([rgb, np.ones((64, 64, 1))], axis=-1)
    want = alone + (1.0 - alone[..., 3:]) * under
    assert np.abs(got - want).max() < 1e-5
    assert np.abs(behind - alone).max() > 0.05  # the back block does show without the surface


@pytest.mark.gl
def test_a_tet_across_a_surface_is_drawn_whole_or_not_at_all():
    """VTK depth-tests a tet's fragments by the depth of the face its fan triangle carries
    and keeps a kept one's whole thickness: across a surface through its middle, each pixel
    is either the tet (as drawn without the surface) over the surface, or the surface alone;
    both occur. tetvr's default cut at the surface would give neither."""
    mesh = synthetic.single_tet((0.2, 0.5, 0.8, 0.4))
    tf = TransferFunction(color=((0, 0.1, 0.9, 0.3), (1, 0.9, 0.9, 0.3)), opacity=((0, 0.9), (1, 0.9)),
                          unit_distance=0.2)
    c = mesh.points.mean(axis=0)
    quad = _quad(c + np.array([[-2, -2, -0.3], [2, -2, 0.2], [-2, 2, 0.1], [2, 2, 0.6]]))
    for parallel in (True, False):
        cam = resolve_clipping_range(Camera.fit(mesh, direction=(0.15, -0.1, -1.0), parallel=parallel),
                                     union_bounds(mesh.bounds, quad.points))
        with tetvr.Renderer(PARITY_SETTINGS) as r:
            got = r.render(mesh, cam, tf, size=(64, 64), surfaces=[quad])
            tet = r.render(mesh, cam, tf, size=(64, 64))
        _, rgb = surface_hits([quad], cam, (64, 64))
        under = np.concatenate([rgb, np.ones((64, 64, 1))], axis=-1)
        over = tet + (1.0 - tet[..., 3:]) * under
        kept = np.abs(got - over).max(axis=-1) < 1e-6
        dropped = np.abs(got - under).max(axis=-1) < 1e-6
        assert np.all(kept | dropped)
        shown = tet[..., 3] > 0.05
        assert (kept & ~dropped & shown).sum() > 50 and (dropped & ~kept & shown).sum() > 50, parallel


@pytest.mark.gl
def test_parity_with_a_clip_draws_the_cut_mesh():
    """A clip in parity draws what the Clip filter makes (clip_cells), as VTK draws the
    filter's output: the same picture as that mesh drawn on its own, exactly. A clip that
    keeps nothing leaves only the surfaces; an explicit drawing order (cell ids of the uncut
    mesh) is refused."""
    mesh = synthetic.cube(4)
    tf = _tf(mesh)
    c = mesh.bounds.mean(axis=0)
    clip = Clip.plane(c, (0.4, -1.0, 0.3))
    cam = Camera.fit(mesh, direction=(0.7, -0.4, -1.0))
    cut = clip_cells(mesh, clip)
    quad = _quad(c + np.array([[-2, -2, -0.3], [2, -2, 0.2], [-2, 2, 0.1], [2, 2, 0.6]]))
    with tetvr.Renderer(PARITY_SETTINGS) as r:
        got = r.render(mesh, cam, tf, size=(48, 48), clip=clip)
        want = r.render(cut, cam, tf, size=(48, 48))
        assert np.array_equal(got, want) and (want[..., 3] > 0.05).sum() > 200
        assert np.abs(got - r.render(mesh, cam, tf, size=(48, 48))).max() > 0.1
        empty = r.render(mesh, cam, tf, size=(48, 48), clip=Clip.plane(c + 5.0, (1, 0, 0)), surfaces=[quad])
        _, rgb = surface_hits([quad], resolve_clipping_range(cam, union_bounds(mesh.bounds, quad.points)), (48, 48))
        assert np.abs(empty[..., :3] - rgb).max() < 1e-6 and np.array_equal(empty[..., 3], rgb.any(axis=-1) * 1.0)
        with pytest.raises(ValueError, match="explicit drawing order cannot go with a clip in VTK parity"):
            r.render(mesh, cam, tf, size=(8, 8), clip=clip, order=np.arange(mesh.n_tets))

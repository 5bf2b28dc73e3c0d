"""Faces seen edge-on: tet marching keeps the rays the rasteriser's snapping drops beside them.

The views are from ``bench/degenerate.py`` (the eye exactly in a boundary face's plane).
Entering only where the rasteriser covered a boundary face, tet marching lost a ray 1e-4
to 1e-3 px inside the mesh in the first five (nothing for a chord of alpha 0.86-1.0);
with float32 ray-triangle tests beside the edge-on faces it took rays 1e-6 to 5e-6 px
outside in the last three (the chord where the exact value is nothing). Those faces'
entries are now decided in float64 (:func:`tetvr.mesh.records.rim_faces`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TetMesh, TransferFunction
from tetvr.mesh import synthetic
from tetvr.mesh.records import EDGE_ON_SINE, march_records, rim_faces
from tetvr.reference.tets import render_reference

CUBE = synthetic.cube(1, rotate=False)
CUBE_TF = TransferFunction.preset("viridis", CUBE, opacity=[(0.0, 0.4), (1.0, 0.9)], unit_distance=0.3)
TET = TetMesh.from_arrays(np.array([[0.0, 0.0, 16.0], [10.0, 0.0, 26.0], [0.0, 10.0, 26.0], [5.0, 5.0, 10.0]]),
                          [[0, 1, 2, 3]], [0.0, 1.0, 0.5, 0.2])
TET_TF = TransferFunction.preset("viridis", (0.0, 1.0), opacity=[(0.0, 0.5), (1.0, 0.9)], unit_distance=2.0)


def _cube_camera(position, focal):
    return Camera(position=position, focal_point=focal, view_up=(0, 0, 1), view_angle=40.0, clipping_range=(0.05, 10.0))


def _tet_camera(position, focal):
    return Camera(position=position, focal_point=focal, view_up=(0, 0, 1), view_angle=30.0, clipping_range=(1.0, 200.0))


# (mesh, tf, camera, size): the eye on the plane x = 0.5 of the cube's face, or on the
# tet's face plane x + y - z = -16.
VIEWS = {
    "cube_320": (CUBE, CUBE_TF, _cube_camera((0.5, 1.375440341086855, 0.5967455149574659),
                                             (0.14702093198859112, 0.23369901438271706, -0.17052565434952865)), 320),
    "cube_384": (CUBE, CUBE_TF, _cube_camera((0.5, 1.4008866004871718, 1.2595504816118348),
                                             (0.08152248248679084, 0.15163925824745195, 0.009092217793411073)), 384),
    "cube_640": (CUBE, CUBE_TF, _cube_camera((0.5, 1.3535030718486942, 0.6563796150825802),
                                             (0.21033075585381306, 0.28777550931089607, -0.13471148828219895)), 640),
    "tet_576": (TET, TET_TF, _tet_camera((33.0, -21.0, 28.0),
                                         (3.2069831461249416, 3.415852227395856, 19.268731450800587)), 576),
    "tet_640": (TET, TET_TF, _tet_camera((32.0, -20.0, 28.0),
                                         (3.41074347770299, 4.2189671560440845, 19.362201552560748)), 640),
    "cube_448_outside": (CUBE, CUBE_TF, _cube_camera((0.5, 1.3535030718486942, 0.6563796150825802),
                                                     (0.21033075585381306, 0.28777550931089607, -0.13471148828219895)),
                         448),
    "cube_512_outside": (CUBE, CUBE_TF, _cube_camera((0.5, 1.1673881677656675, -0.4855414717919677),
                                                     (0.10115567304605405, -0.2229933591347679, -0.13200495348246438)),
                         512),
    "tet_320_outside": (TET, TET_TF, _tet_camera((36.0, -25.0, 27.0),
                                                 (2.8102124925169116, 2.219838312916094, 18.389430090158715)), 320),
}


@pytest.fixture(scope="module")
def marcher():
    from tetvr.gl import Renderer

    from .conftest import gl_object

    yield from gl_object(lambda: Renderer(RenderSettings(method="raymarch")), "no OpenGL 4.3 context")


@pytest.mark.gl
@pytest.mark.parametrize("name", sorted(VIEWS))
def test_tet_marching_keeps_the_rays_beside_a_face_seen_edge_on(name, marcher):
    mesh, tf, camera, size = VIEWS[name]
    want = render_reference(mesh, camera, tf, (size, size))
    got = marcher.render(mesh, camera, tf, size=(size, size))
    assert marcher._march.last_stats.n_rim_faces > 0
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    assert np.isfinite(got).all()
    # Measured 1.6e-4 to 3e-4 (the table); before, one pixel at 0.5 to 1.0 in each view.
    assert err.max() < 1e-3, f"max error {err.max():.3g} at {np.unravel_index(err.argmax(), err.shape)}"
    assert np.count_nonzero(err > 1 / 255) == 0


def test_rim_faces_are_the_faces_seen_edge_on_their_neighbours_and_a_ring_around():
    rec = march_records(CUBE)
    _, _, camera, size = VIEWS["cube_320"]
    idx, rects, exclusive = rim_faces(rec, camera, (size, size))
    normals = rec.planes[rec.boundary_slots // 4, rec.boundary_slots % 4, :3]
    edge_on = np.flatnonzero(np.isclose(normals[:, 0], 1.0))  # the faces in the plane x = 0.5, holding the eye
    assert edge_on.size == 2 and set(edge_on) <= set(idx[exclusive].tolist())
    # The rasteriser leaves out those and the faces sharing an edge with them (those in
    # view: some project outside the viewport); the ring around them is drawn both ways.
    edges = rec.boundary_edges
    core = np.isin(edges, edges[edge_on]).any(axis=1)
    assert set(idx[exclusive].tolist()) <= set(np.flatnonzero(core).tolist())
    ring = np.isin(edges, edges[core]).any(axis=1) & ~core
    assert set(idx[~exclusive].tolist()) <= set(np.flatnonzero(ring).tolist()) and (~exclusive).any()
    # Every face left out of the rasteriser has all its neighbours in view tested exactly.
    pts = rec.boundary_triangles.astype(np.float64) + rec.origin
    clip = np.concatenate([pts, np.ones((*pts.shape[:2], 1))], axis=-1) @ (
        camera.projection_matrix(1.0) @ camera.view_matrix()).T
    ndc = clip[..., :2] / clip[..., 3:]
    in_view = np.all(ndc.min(axis=1) < 1, axis=1) & np.all(ndc.max(axis=1) > -1, axis=1)
    for i in idx[exclusive]:
        neighbours = np.flatnonzero(np.isin(edges, edges[i]).any(axis=1) & in_view)
        assert set(neighbours.tolist()) <= set(idx.tolist())
    # Each rectangle holds its face's projection with a pixel to spare, within the viewport.
    assert rects.shape == (idx.size, 4) and np.all(rects[:, :2] <= rects[:, 2:]) and np.all(np.abs(rects) <= 1.0)
    # A generic view, and the same view in parallel projection, see no face edge-on.
    moved = dataclasses.replace(camera, position=(0.6, *camera.position[1:]))
    assert rim_faces(rec, moved, (size, size))[0].size == 0
    parallel = dataclasses.replace(camera, parallel_projection=True)
    assert rim_faces(rec, parallel, (size, size))[0].size == 0
    # Looking along the x = 0.5 face in parallel projection sees it edge-on.
    along = Camera(position=(0.5, 5.0, 0.0), focal_point=(0.5, 0.0, 0.0), view_up=(0, 0, 1), parallel_projection=True)
    assert rim_faces(rec, along, (size, size))[0].size > 0
    assert EDGE_ON_SINE < 0.1


@pytest.mark.data
def test_a_grazing_entry_the_ray_misses_is_walked_back_to_the_ray():
    """Beside the blunt fin's edge-on faces (380 of them in this view) the entry passes gave
    one pixel's ray a cell it misses by a rounding (a chord of 0.022 units crossing ten
    cells). Walked by points from there, with the triangle it came in by not about the
    ray, that pixel took alpha 0.024 against the exact 0.00075; the walk now goes by face
    planes until the face it leaves by holds the ray (the view and transfer function of
    bench/speed_accuracy.py, which found it)."""
    import warnings

    import tetvr
    from tests.conftest import shared_file

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the zero-volume cells dropped on reading
        mesh = tetvr.read(shared_file("tets/bluntfin_tets.vtu"))
    lo, hi = mesh.scalar_range
    q30, q60 = ((q - lo) / (hi - lo) for q in np.quantile(mesh.scalars, [0.3, 0.6]))
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    tf = TransferFunction.preset("cool-to-warm", mesh.scalar_range, unit_distance=diag / 20, opacity=[
        (0, 0.02), (q30 - 0.03, 0.05), (q30, 0.9), (q30 + 0.03, 0.05), (q60, 0.3), (1, 0.9)])
    camera = Camera.fit(mesh, direction=(-1.0, -0.5, -0.7), zoom=1.2)
    size = (256, 256)
    with tetvr.Renderer(RenderSettings(method="raymarch", integration="exact")) as r:
        got = r.render(mesh, camera, tf, size=size)
        assert r._marcher.last_stats.n_rim_faces > 0
    want = render_reference(mesh, camera, tf, size)
    err = np.abs(got - want).max(axis=-1)
    assert err[147, 232] < 1e-4, err[147, 232]
    assert err.max() < 1e-3 and np.count_nonzero(err > 1 / 255) == 0, err.max()


# Seven cells of the ~1M-tet fTetWild torus of bench/corpus.py round one pixel's entry, and
# two tiny cells at the corners of that mesh's bounding box (so that the records' origin,
# hence every float32 rounding, is the same), seen from bench/vs_vtk.py's fitted camera at
# 1024x1024. Boundary face (0, 1, 2) is a needle (height 8e-7, edges ~0.05): whatever
# its plane says, seen from the eye its corners lie on a line. Pixel (640, 938)'s ray enters
# the mesh within 1e-3 px of the needle's long edge; the rasteriser's snapping put the pixel
# centre on the needle's side of the edge, where no face facing the eye was drawn, and the
# ray lost its chord (alpha 0 against 0.86 in the whole mesh).
NEEDLE_POINTS = np.array([
    [0.08655174359041527, 1.3205244256684672, 0.13393920132778142],
    [0.17008984163268717, 1.291960614114252, 0.17499999999999996],
    [0.13241289426773137, 1.3048437629222915, 0.156480108378675],
    [0.09676002651121555, 1.296871295261771, 0.17844485168002538],
    [0.14602484170734234, 1.2808078553662259, 0.14566313394909636],
    [0.12898012927367955, 1.3061775808982217, 0.1544696006638907],
    [0.11602300766647902, 1.2726329587581517, 0.15308824819927142],
    [0.16454643267181604, 1.2915331885688817, 0.1328161134821665],
    [0.12266371580941994, 1.2848180260814315, 0.16981376211384308],
    [0.1358204451270326, 1.2923337479489483, 0.17947373122415297],
    [-1.3493051963263871, -1.349868082936403, -0.3512102596684987],
    [-1.3466061365469149, -1.349868082936403, -0.3512102596684987],
    [-1.3493051963263871, -1.3471690231569307, -0.3512102596684987],
    [-1.3493051963263871, -1.349868082936403, -0.3485111998890265],
    [1.34703003239656, 1.34649263675635, 0.34781233224069585],
    [1.3497290921760323, 1.34649263675635, 0.34781233224069585],
    [1.34703003239656, 1.3491916965358222, 0.34781233224069585],
    [1.34703003239656, 1.34649263675635, 0.35051139202016807]])
NEEDLE_TETS = [[0, 1, 2, 3], [0, 1, 3, 5], [1, 3, 5, 9], [1, 4, 5, 7], [1, 4, 9, 5], [4, 5, 6, 8], [4, 5, 8, 9],
               [10, 11, 12, 13], [14, 15, 16, 17]]
NEEDLE_CAMERA = Camera(position=(3.283617315595336, 1.9699216376429176, 3.7399815675686447),
                       focal_point=(0.08577500564968951, 0.05121625167552962, -0.0974292043661311),
                       view_up=(0.0, 0.0, 1.0), view_angle=30.0, clipping_range=(4.207077444158612, 6.494387696086293))


def _needle_mesh() -> TetMesh:
    values = np.concatenate([np.linspace(-1.78, -1.66, 10), np.zeros(8)])
    return TetMesh.from_arrays(NEEDLE_POINTS, NEEDLE_TETS, values)


def test_a_needle_on_the_boundary_is_decided_exactly_with_its_neighbours():
    rec = march_records(_needle_mesh())
    corners = [tuple(sorted(c)) for c in rec.boundary_corners.tolist()]
    needle = corners.index((0, 1, 2))
    beside = [i for i, c in enumerate(corners) if len(set(c) & {0, 1, 2}) == 2]
    assert len(beside) == 3
    for size in (1024, 64):
        idx, _, exclusive = rim_faces(rec, NEEDLE_CAMERA, (size, size))
        # Not seen edge-on by its plane's sine: by its projection, thinner than THIN_PIXELS.
        assert {needle, *beside} <= set(idx[exclusive].tolist()), size


@pytest.mark.gl
def test_tet_marching_enters_beside_a_needle_on_the_boundary(marcher):
    mesh = _needle_mesh()
    tf = TransferFunction.preset("viridis", (-1.78, -1.66), opacity=[(0.0, 0.6), (1.0, 0.9)], unit_distance=0.01)
    size = (1024, 1024)
    want = render_reference(mesh, NEEDLE_CAMERA, tf, size)
    got = marcher.render(mesh, NEEDLE_CAMERA, tf, size=size)
    assert want[640, 938, 3] > 0.01  # the ray crosses the cells
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    # Before: pixel (640, 938) had alpha 0 (its chord lost).
    assert err[640, 938] < 1e-3, (err[640, 938], got[640, 938], want[640, 938])
    assert err.max() < 1e-3 and np.count_nonzero(err > 1 / 255) == 0, err.max()

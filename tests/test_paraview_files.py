"""ParaView's files as a parallel solver and ParaView write them: a ``.pvtu`` whose pieces
carry ghost cells (VTK 9 stamps such pieces VTU version "2.x"), a ``.vtm`` of blocks cut from
one mesh, pieces whose mesh has coincident nodes, and a state (``.pvsm``) that shows more
than its volume. Each merged mesh is the single file's, cell for cell, and renders as it
does; a state's other sources are drawn as surfaces or named.

VTK (``pip install 'tetvr[compare]'``) writes the files with its own writers
(``vtkXMLPUnstructuredGridWriter`` with ghost levels, ``vtkXMLMultiBlockDataWriter``) and
makes the spheres tetvr's are checked against; the tests that need it, or bluntfin from
../shared/data, skip with the reason.
"""

from __future__ import annotations

import importlib.util
import re
import warnings
from pathlib import Path

import meshio
import numpy as np
import pytest

import tetvr
from tetvr import Camera, RenderSettings
from tetvr.io.collections import pieces as collection_pieces
from tetvr.mesh import synthetic
from tetvr.render import default_transfer_function

from .conftest import gl_object, save_failure, shared_file

HAS_VTK = importlib.util.find_spec("vtkmodules") is not None
needs_vtk = pytest.mark.skipif(not HAS_VTK, reason="VTK is not installed (pip install 'tetvr[compare]')")
BLUNTFIN_CELLS = 187_395  # in the file; 77 of them have zero volume


def _signature(mesh: tetvr.TetMesh) -> np.ndarray:
    """Each tet as (sorted corner coordinates, corner scalars), rows sorted: equal for two
    meshes that differ only in the numbering of points and cells."""
    p = np.concatenate([mesh.points[mesh.tets], mesh.scalars[mesh.tets][..., None]], axis=2)
    p = p[np.arange(len(p))[:, None], np.lexsort(p.transpose(2, 0, 1)[::-1], axis=1)]
    rows = p.reshape(len(p), -1)
    return rows[np.lexsort(rows.T[::-1])]


def _read_warned(path: Path | str) -> tuple[tetvr.TetMesh, list[str]]:
    """bluntfin's Pressure (its coincident nodes differ in it) and the warnings the read gave."""
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        mesh = tetvr.read(path, "Pressure")
    return mesh, [str(w.message) for w in said]


@pytest.fixture(scope="module")
def bluntfin() -> tuple[Path, tetvr.TetMesh, list[str]]:
    path = shared_file("tets/bluntfin_tets.vtu")
    return (path, *_read_warned(path))


# ---------------------------------------------------------------- written by VTK
def _vtk_grid(path: Path):
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    return reader


def _write_ghosted_pvtu(source: Path, out: Path, pieces: int = 4, ghost_level: int = 1) -> Path:
    """``source`` as a .pvtu of ``pieces`` pieces with ``ghost_level`` layers of ghost cells,
    as a parallel run writes it (each piece extracted by VTK, ghost cells marked)."""
    from vtkmodules.vtkFiltersParallel import vtkExtractUnstructuredGridPiece
    from vtkmodules.vtkIOParallelXML import vtkXMLPUnstructuredGridWriter

    reader = _vtk_grid(source)  # kept: a pipeline does not own its upstream
    extract = vtkExtractUnstructuredGridPiece()
    extract.SetInputConnection(reader.GetOutputPort())
    writer = vtkXMLPUnstructuredGridWriter()
    writer.SetInputConnection(extract.GetOutputPort())
    writer.SetFileName(str(out))
    writer.SetNumberOfPieces(pieces)
    writer.SetStartPiece(0)
    writer.SetEndPiece(pieces - 1)
    writer.SetGhostLevel(ghost_level)
    assert writer.Write() == 1
    return out


def _write_vtm(source: Path, out: Path, blocks: int = 3) -> Path:
    """``source``'s cells, in file order, as a .vtm of ``blocks`` blocks (each holding the
    points its cells use, as vtkExtractCells leaves them)."""
    from vtkmodules.vtkCommonCore import vtkIdList
    from vtkmodules.vtkCommonDataModel import vtkMultiBlockDataSet
    from vtkmodules.vtkIOXML import vtkXMLMultiBlockDataWriter
    try:
        from vtkmodules.vtkFiltersCore import vtkExtractCells
    except ImportError:  # VTK before 9.5
        from vtkmodules.vtkFiltersExtraction import vtkExtractCells

    reader = _vtk_grid(source)
    grid = reader.GetOutput()
    bounds = np.linspace(0, grid.GetNumberOfCells(), blocks + 1).astype(int)
    multi = vtkMultiBlockDataSet()
    multi.SetNumberOfBlocks(blocks)
    for k in range(blocks):
        ids = vtkIdList()
        for i in range(bounds[k], bounds[k + 1]):
            ids.InsertNextId(i)
        extract = vtkExtractCells()
        extract.SetInputData(grid)
        extract.SetCellList(ids)
        extract.Update()
        multi.SetBlock(k, extract.GetOutput())
    writer = vtkXMLMultiBlockDataWriter()
    writer.SetInputData(multi)
    writer.SetFileName(str(out))
    assert writer.Write() == 1
    return out


@pytest.fixture(scope="module")
def march():
    from tetvr.gl import Renderer

    yield from gl_object(lambda: Renderer(RenderSettings(method="raymarch")), "no OpenGL 4.3 context")


def _renders_alike(name: str, renderer, merged: tetvr.TetMesh, whole: tetvr.TetMesh) -> None:
    """The merged mesh's picture is the single file's: the same cells, numbered otherwise
    (tet marching walks them in the same order: 0.0 measured, 1e-6 allowed)."""
    tf = default_transfer_function(whole)
    camera = Camera.fit(whole, direction=(-1.0, -0.5, -0.7))
    want = renderer.render(whole, camera, tf, size=(64, 64))
    got = renderer.render(merged, camera, tf, size=(64, 64))
    assert want[..., 3].max() > 0.5
    diff = np.abs(got - want)
    if diff.max() > 1e-6:
        save_failure(name, got, want)
    assert diff.max() <= 1e-6
    assert int(np.sum(diff > 1 / 255)) == 0


@needs_vtk
@pytest.mark.data
@pytest.mark.gl
def test_a_ghosted_pvtu_renders_as_the_single_vtu(tmp_path, bluntfin, march):
    source, whole, whole_said = bluntfin
    path = _write_ghosted_pvtu(source, tmp_path / "bluntfin.pvtu")
    pieces = collection_pieces(path)
    assert len(pieces) == 4
    # What a parallel writer leaves: VTU version 2.x (meshio knows 0.1 and 1.0), ghost cells.
    heads = [Path(p).read_bytes()[:400] for p in pieces]
    assert all(re.search(rb'<VTKFile[^>]*version="2\.\d+"', h) for h in heads)
    readers = [_vtk_grid(Path(p)) for p in pieces]
    written = sum(r.GetOutput().GetNumberOfCells() for r in readers)
    assert written > BLUNTFIN_CELLS + 10_000  # ghost layers on every seam
    merged, said = _read_warned(path)
    # No cell twice, none lost: the single file's mesh, and its warning about the flat cells.
    assert merged.report.input_cells == BLUNTFIN_CELLS and merged.n_tets == whole.n_tets
    assert np.array_equal(_signature(merged), _signature(whole))
    assert said == whole_said == ["dropped 77 zero-volume tetrahedra"]
    # Each piece read alone (a worker's unit) drops its ghost cells too.
    alone = [_read_warned(p)[0] for p in pieces]
    assert sum(m.report.input_cells for m in alone) == BLUNTFIN_CELLS
    _renders_alike("ghosted_pvtu", march, merged, whole)


@needs_vtk
@pytest.mark.data
@pytest.mark.gl
def test_a_vtm_of_three_blocks_renders_as_the_single_vtu(tmp_path, bluntfin, march):
    """bluntfin has 39 points that coincide with another one (their Pressure differs) and
    77 flat cells on them: joined by coordinates alone, the flat cells would repeat a vertex
    and the read stop; here the merge is the single file's mesh."""
    source, whole, whole_said = bluntfin
    merged, said = _read_warned(_write_vtm(source, tmp_path / "bluntfin.vtm"))
    assert merged.n_points == whole.n_points and merged.n_tets == whole.n_tets
    assert np.array_equal(_signature(merged), _signature(whole))
    assert said == whole_said
    _renders_alike("vtm_blocks", march, merged, whole)


@needs_vtk
def test_polyhedra_in_vtk_9s_layout_are_refused_by_name(tmp_path):
    from vtkmodules.vtkCommonCore import vtkIdList, vtkPoints
    from vtkmodules.vtkCommonDataModel import VTK_POLYHEDRON, vtkUnstructuredGrid
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridWriter

    points = vtkPoints()
    for p in ((0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)):
        points.InsertNextPoint(p)
    grid = vtkUnstructuredGrid()
    grid.SetPoints(points)
    faces = vtkIdList()
    for v in (4, 3, 0, 1, 2, 3, 0, 1, 3, 3, 0, 2, 3, 3, 1, 2, 3):
        faces.InsertNextId(v)
    grid.InsertNextCell(VTK_POLYHEDRON, faces)
    writer = vtkXMLUnstructuredGridWriter()
    writer.SetInputData(grid)
    writer.SetFileName(str(tmp_path / "poly.vtu"))
    writer.Write()
    with pytest.raises(ValueError, match=r"version 2\.\d polyhedron cells \(face_connectivity\) are not read"):
        tetvr.read(tmp_path / "poly.vtu")


# ---------------------------------------------------------------- written by hand
def _write_piece(path: Path, points: np.ndarray, tets: np.ndarray, values: np.ndarray, *,
                 cell_data: dict | None = None, version: str | None = None) -> Path:
    """A .vtu of these cells with the points they use (as a solver's piece)."""
    used, local = np.unique(tets, return_inverse=True)
    meshio.Mesh(points[used], [("tetra", local.reshape(-1, 4))], point_data={"f": values[used]},
                cell_data={k: [v] for k, v in (cell_data or {}).items()}).write(path)
    if version is not None:
        text = path.read_bytes()
        path.write_bytes(text.replace(b'version="0.1"', f'version="{version}"'.encode(), 1))
    return path


def _write_pvtu(folder: Path, points: np.ndarray, tets: np.ndarray, values: np.ndarray,
                groups: list[np.ndarray]) -> Path:
    names = [_write_piece(folder / f"part_{k}.vtu", points, tets[ids], values).name for k, ids in enumerate(groups)]
    body = "".join(f'<Piece Source="{n}"/>' for n in names)
    path = folder / "grid.pvtu"
    path.write_text('<?xml version="1.0"?><VTKFile type="PUnstructuredGrid" version="0.1">'
                    f'<PUnstructuredGrid GhostLevel="0">{body}</PUnstructuredGrid></VTKFile>')
    return path


def _one_file(folder: Path, points: np.ndarray, tets: np.ndarray, values: np.ndarray) -> tetvr.TetMesh:
    meshio.Mesh(points, [("tetra", tets)], point_data={"f": values}).write(folder / "one.vtu")
    return tetvr.read(folder / "one.vtu")


def test_coincident_nodes_with_a_jump_stay_apart_when_pieces_merge(tmp_path):
    """A crack: the cells beyond x = 0 have their own copies of the nodes on that plane,
    with values 1 higher (a material interface). Pieces cut across it merge into the same
    mesh, the jump kept, where joining by coordinates alone would give both sides one value."""
    cube = synthetic.cube(4, rotate=False)
    points, tets, values = cube.points, cube.tets.astype(np.int64), cube.scalars
    on_plane = np.nonzero(np.abs(points[:, 0]) < 1e-12)[0]
    assert len(on_plane) == 25
    copy = np.full(len(points), -1)
    copy[on_plane] = len(points) + np.arange(len(on_plane))
    beyond = cube.centroids[:, 0] > 0
    tets = tets.copy()
    tets[beyond] = np.where(copy[tets[beyond]] >= 0, copy[tets[beyond]], tets[beyond])
    points = np.concatenate([points, points[on_plane]])
    values = np.concatenate([values, values[on_plane] + 1.0])
    whole = _one_file(tmp_path, points, tets, values)
    by_y = cube.centroids[:, 1] > 0  # each piece holds both sides of the crack
    merged = tetvr.read(_write_pvtu(tmp_path, points, tets, values, [np.nonzero(~by_y)[0], np.nonzero(by_y)[0]]))
    assert merged.n_points == whole.n_points == cube.n_points + 25
    assert np.array_equal(_signature(merged), _signature(whole))


def test_a_flat_cell_on_coincident_nodes_is_dropped_as_in_one_file(tmp_path):
    """A cell on two nodes at one place (equal values too): one file drops it as flat, with
    a warning; merged pieces do the same instead of stopping at a repeated vertex."""
    cube = synthetic.cube(2, rotate=False)
    points = np.concatenate([cube.points, cube.points[:1]])
    values = np.concatenate([cube.scalars, cube.scalars[:1]])
    around = cube.tets[np.any(cube.tets == 0, axis=1)][0]
    a, b = [int(v) for v in around if v != 0][:2]
    flat = np.array([[0, len(points) - 1, a, b]])  # node 0, its copy, two neighbours
    tets = np.concatenate([cube.tets.astype(np.int64), flat])
    with pytest.warns(UserWarning, match="dropped 1 zero-volume tetrahedra"):
        whole = _one_file(tmp_path, points, tets, values)
    left = np.r_[cube.centroids[:, 0] < 0, True]  # the flat cell goes with node 0's piece
    assert 0 in tets[left]
    with pytest.warns(UserWarning, match="dropped 1 zero-volume tetrahedra"):
        merged = tetvr.read(_write_pvtu(tmp_path, points, tets, values,
                                        [np.nonzero(left)[0], np.nonzero(~left)[0]]))
    assert np.array_equal(_signature(merged), _signature(whole))
    assert merged.report.dropped_degenerate == whole.report.dropped_degenerate == 1


@pytest.mark.parametrize("array, version, ghost", [("vtkGhostType", "2.2", 1), ("vtkGhostType", "2.2", 3),
                                                    ("vtkGhostLevels", "0.1", 1), ("vtkGhostLevels", "0.1", 2)])
def test_a_piece_alone_drops_its_ghost_cells(tmp_path, array, version, ghost):
    """VTK 9's bits (DUPLICATECELL = 1, version 2.x) or VTK 8's levels (version 0.1/1.0):
    the ghost cells are left out and the array is not offered as a field."""
    cube = synthetic.cube(2)
    mark = np.zeros(cube.n_tets, dtype=np.uint8)
    mark[:10] = ghost
    path = _write_piece(tmp_path / "piece.vtu", cube.points, cube.tets, cube.scalars,
                        cell_data={array: mark}, version=version)
    mesh = tetvr.read(path)
    assert mesh.n_tets == cube.n_tets - 10 and mesh.report.input_cells == cube.n_tets - 10
    assert mesh.report.fields == ("f",)


# ---------------------------------------------------------------- a state showing more than the volume
ROOT = Path(__file__).resolve().parents[1]
STATE = ROOT / "tests" / "data" / "post_volume.pvsm"


def _prop(proxy: str, name: str, *values) -> str:
    items = "".join(f'<Element index="{i}" value="{v}"/>' for i, v in enumerate(values))
    return f'<Property name="{name}" id="{proxy}.{name}" number_of_elements="{len(values)}">{items}</Property>'


def _source(pid: str, kind: str, **props) -> str:
    body = "".join(_prop(pid, k, *(v if isinstance(v, tuple) else (v,))) for k, v in props.items())
    return f'<Proxy group="sources" type="{kind}" id="{pid}" servers="1">{body}</Proxy>'


def _representation(rid: str, source: str, representation: str, **props) -> str:
    body = "".join(_prop(rid, k, *(v if isinstance(v, tuple) else (v,))) for k, v in props.items())
    return (f'<Proxy group="representations" type="GeometryRepresentation" id="{rid}" servers="21">'
            f'<Property name="Input" id="{rid}.Input" number_of_elements="1"><Proxy value="{source}"/></Property>'
            f'{_prop(rid, "Representation", representation)}{body}</Proxy>')


#: Sphere1 (Surface, orange) half in the volume, Box1 as an Outline around it (2 px), Cone1
#: (Surface: not drawn by tetvr), Sphere2 hidden, Sphere3 coloured by an array, see-through.
SOURCES = "".join([
    _source("20", "SphereSource", Center=(1.5, 0.0, 0.5), Radius=0.6, ThetaResolution=16, PhiResolution=12),
    _representation("21", "20", "Surface", DiffuseColor=(0.9, 0.5, 0.2), AmbientColor=(0.9, 0.5, 0.2),
                    ColorArrayName=("", "", "", "0", ""), Visibility=1),
    _source("30", "CubeSource", Center=(0.0, 0.0, 0.6), XLength=6.0, YLength=6.0, ZLength=1.6),
    _representation("31", "30", "Outline", AmbientColor=(1.0, 1.0, 0.0), DiffuseColor=(1.0, 1.0, 1.0), LineWidth=2,
                    Visibility=1),
    _source("40", "ConeSource", Center=(0.0, 2.0, 0.5)),
    _representation("41", "40", "Surface", Visibility=1),
    _source("50", "SphereSource", Center=(-1.5, 0.0, 0.5)),
    _representation("51", "50", "Surface", Visibility=0),
    _source("60", "SphereSource", Center=(-1.5, -1.5, 0.5), Radius=0.3),
    _representation("61", "60", "Surface", ColorArrayName=("", "", "", "0", "Normals"), Opacity=0.5, Visibility=1),
])
NAMES = "".join(f'<Item id="{i}" name="{n}"/>' for i, n in
                (("20", "Sphere1"), ("30", "Box1"), ("40", "Cone1"), ("50", "Sphere2"), ("60", "Sphere3")))


def _state_with_sources(tmp_path: Path, sources: str = SOURCES, reps: tuple[str, ...] = ("21", "31", "41", "51", "61"),
                        names: str = NAMES) -> Path:
    text = STATE.read_text()
    listed = '<Proxy value="9470"/>\n        <Proxy value="9471"/>'
    assert listed in text
    text = text.replace(listed, listed + "".join(f'<Proxy value="{r}"/>' for r in reps))
    text = text.replace('<ProxyCollection name="lookup_tables">', sources + '<ProxyCollection name="lookup_tables">')
    text = text.replace('<ProxyCollection name="sources">', '<ProxyCollection name="sources">' + names)
    path = tmp_path / "post_sources.pvsm"
    path.write_text(text)
    (tmp_path / "post.vtk").symlink_to(ROOT / "meshes" / "post.vtk")
    return path


def test_a_state_lists_what_it_shows_besides_the_volume(tmp_path):
    from tetvr.scene.paraview import read_state

    state = read_state(_state_with_sources(tmp_path))
    assert state.representation == "Volume" and state.array == "Pressure"  # the volume is still the volume
    shown = {s.name: s for s in state.others}
    assert list(shown) == ["Sphere1", "Box1", "Cone1", "Sphere3"]  # Sphere2 is hidden
    assert shown["Sphere1"].number("Resolution") == (16, 12) and shown["Sphere1"].color == (0.9, 0.5, 0.2)
    assert (shown["Box1"].representation, shown["Box1"].line_width, shown["Box1"].outline_color) == \
        ("Outline", 2.0, (1.0, 1.0, 0.0))
    assert (shown["Sphere3"].array, shown["Sphere3"].opacity) == ("Normals", 0.5)


def test_a_states_other_sources_are_drawn_or_named(tmp_path):
    """Sphere1 and Sphere3 become surfaces, Box1's outline ribbons; Cone1 is warned about
    by name, as are Sphere3's colouring and opacity. In parity, all are left out by name."""
    from tetvr.scene.paraview import load_state
    from tetvr.scene.pvsources import sphere_source

    path = _state_with_sources(tmp_path)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        scene = load_state(path)
    said = [str(w.message) for w in said]
    assert any("Cone1 (ConeSource) shown as 'Surface' is not drawn" in s for s in said), said
    assert any("Sphere3 (SphereSource) shown as 'Surface': coloured by the array 'Normals' in ParaView, drawn in "
               "its solid colour; opacity 0.5 in ParaView, drawn opaque" in s for s in said), said
    assert len(scene.surfaces) == 3
    sphere, outline, small = scene.surfaces
    points, triangles = sphere_source((1.5, 0.0, 0.5), 0.6, 16, 12)
    assert np.array_equal(sphere.points, points) and np.array_equal(sphere.triangles, triangles)
    assert sphere.color == (0.9, 0.5, 0.2) and sphere.smooth
    assert outline.n_triangles == 24 and outline.color == (1.0, 1.0, 0.0) and outline.ambient == 1.0
    assert np.allclose([outline.points.min(axis=0), outline.points.max(axis=0)],
                       [[-3.0, -3.0, -0.2], [3.0, 3.0, 1.4]], atol=0.05)
    assert small.color == (1.0, 1.0, 1.0)  # ParaView's default solid colour
    # The clipping range holds every prop, as ParaView's: the box reaches beyond the mesh.
    near, far = scene.camera.clipping_range
    depths = (outline.points - scene.camera.position) @ np.subtract(scene.camera.focal_point, scene.camera.position)
    depths /= np.linalg.norm(np.subtract(scene.camera.focal_point, scene.camera.position))
    assert near < depths.min() and depths.max() < far
    with warnings.catch_warnings():  # parity draws them too, as ParaView does with "Projected tetra"
        warnings.simplefilter("ignore")
        parity = load_state(path, parity=True)
    assert len(parity.surfaces) == 3 and parity.settings.optics == "vtk"
    assert all(np.array_equal(a.points, b.points) for a, b in zip(parity.surfaces, scene.surfaces))


def test_outline_ribbons_are_lines_of_the_width_asked(tmp_path):
    """Each edge covers about LineWidth pixels across: the hits of a 2 px outline are twice
    its edges' length in pixels (the pixel count of lines drawn 2 px wide)."""
    from tetvr.core.surface import surface_hits
    from tetvr.scene.pvsources import outline_ribbons

    camera = Camera(position=(4.0, -7.0, 5.0), focal_point=(0.0, 0.0, 0.0), view_angle=30.0)
    bounds = np.array([[-1.0, -1.5, -0.5], [1.0, 1.5, 0.5]])
    size = (160, 120)
    for width in (1.0, 2.0, 3.0):
        ribbons = outline_ribbons(bounds, camera, size, width, (1.0, 1.0, 1.0))
        depth, _ = surface_hits([ribbons], camera, size)
        corners = np.array([[bounds[x][0], bounds[y][1], bounds[z][2]] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
        px = _project(camera, corners, size)
        length = sum(np.abs(px[a] - px[b]).max() for a in range(8) for b in range(a + 1, 8)
                     if bin(a ^ b).count("1") == 1)
        hits = int(np.isfinite(depth).sum())
        assert 0.85 * width * length < hits < 1.25 * width * length, (width, hits, length)


def _project(camera: Camera, points: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Pixel coordinates (x, y) of world points."""
    view = camera.view_matrix()
    eye = points @ view[:3, :3].T + view[:3, 3]
    f = 1.0 / np.tan(np.radians(camera.view_angle) / 2)
    w, h = size
    return np.stack([(f * eye[:, 0] / -eye[:, 2] * h / w + 1) * w / 2, (f * eye[:, 1] / -eye[:, 2] + 1) * h / 2], axis=1)


@needs_vtk
def test_spheres_are_vtks_point_for_point():
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersSources import vtkSphereSource

    from tetvr.scene.pvsources import sphere_source

    for centre, radius, res, theta, phi in [((0, 0, 0), 0.5, (8, 8), (0, 360), (0, 180)),
                                            ((1, 2, 3), 2.5, (32, 17), (0, 360), (0, 180)),
                                            ((0, 0, 0), 1.0, (7, 9), (10, 300), (0, 120)),
                                            ((0, 0, 0), 1.0, (8, 8), (300, 30), (30, 150)),
                                            ((0, 0, 0), 1.0, (2, 300), (-10, 360), (20, 200))]:  # clamped as VTK does
        vtk_sphere = vtkSphereSource()
        vtk_sphere.SetCenter(*centre)
        vtk_sphere.SetRadius(radius)
        vtk_sphere.SetThetaResolution(res[0])
        vtk_sphere.SetPhiResolution(res[1])
        vtk_sphere.SetStartTheta(theta[0])
        vtk_sphere.SetEndTheta(theta[1])
        vtk_sphere.SetStartPhi(phi[0])
        vtk_sphere.SetEndPhi(phi[1])
        vtk_sphere.Update()
        out = vtk_sphere.GetOutput()
        points, triangles = sphere_source(centre, radius, res[0], res[1], theta, phi)
        assert np.array_equal(points, vtk_to_numpy(out.GetPoints().GetData()).astype(np.float64))
        assert np.array_equal(triangles, vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3))


def test_a_sphere_too_fine_is_named_and_left_out(tmp_path):
    from tetvr.scene.paraview import load_state

    path = _state_with_sources(tmp_path)
    path.write_text(path.read_text().replace('<Element index="0" value="16"/>', '<Element index="0" value="1000000"/>'))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        scene = load_state(path)
    assert any("Sphere1 (SphereSource) shown as 'Surface' is not drawn: a sphere of ThetaResolution 1000000 x "
               "PhiResolution 12 has more than" in str(w.message) for w in said)
    assert len(scene.surfaces) == 2


def test_surface_files_and_meshes_a_state_reads_are_drawn(tmp_path):
    """An STL part as a surface, a volume mesh's boundary as a surface, the same mesh's
    outline; a file the state names that is missing is named."""
    from tetvr.scene.paraview import load_state

    cube = synthetic.cube(2)
    meshio.Mesh(cube.points, [("tetra", cube.tets)], point_data={"f": cube.scalars}).write(tmp_path / "part.vtu")
    square = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]) * 0.3
    meshio.Mesh(square, [("triangle", [[0, 1, 2], [0, 2, 3]])]).write(tmp_path / "part.stl")
    sources = "".join([
        _source("70", "STLReader", FileNames="/elsewhere/part.stl"),
        _representation("71", "70", "Surface", DiffuseColor=(0.2, 0.4, 0.9), Visibility=1),
        _source("80", "XMLUnstructuredGridReader", FileName="part.vtu"),
        _representation("81", "80", "Surface", Visibility=1),
        _source("90", "XMLUnstructuredGridReader", FileName="part.vtu"),
        _representation("91", "90", "Outline", Visibility=1),
        _source("95", "XMLUnstructuredGridReader", FileName="missing.vtu"),
        _representation("96", "95", "Surface", Visibility=1),
    ])
    names = "".join(f'<Item id="{i}" name="{n}"/>' for i, n in
                    (("70", "part.stl"), ("80", "part.vtu"), ("90", "part2.vtu"), ("95", "missing.vtu")))
    path = _state_with_sources(tmp_path, sources, ("71", "81", "91", "96"), names)
    with pytest.warns(UserWarning, match=r"missing.vtu \(XMLUnstructuredGridReader\) shown as 'Surface' is not "
                                         r"drawn: .*its data file 'missing.vtu' is neither there nor beside the state"):
        scene = load_state(path)
    stl, boundary, outline = scene.surfaces
    assert stl.n_triangles == 2 and stl.color == (0.2, 0.4, 0.9)
    assert boundary.n_triangles == 12 * 2 ** 2  # 2 triangles a square, 4 squares a side, 6 sides
    assert np.allclose([outline.points.min(axis=0), outline.points.max(axis=0)], cube.bounds, atol=0.05)


@pytest.mark.gl
def test_a_state_with_a_sphere_renders_against_the_reference(tmp_path):
    """The volume with the sphere and the outline in it: GPU against the CPU reference,
    the same bar as the state alone (max 2/255, no pixel beyond 1/255), and the sphere seen."""
    from tetvr.reference.tets import render_reference
    from tetvr.scene.paraview import load_state

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_state(_state_with_sources(tmp_path), size=(120, 90))
    got = tetvr.render(scene.mesh, camera=scene.camera, tf=scene.tf, size=scene.size, settings=scene.settings,
                       **scene.render_options)
    want = render_reference(scene.mesh, scene.camera, scene.tf, scene.size, **scene.render_options)
    alone = render_reference(scene.mesh, scene.camera, scene.tf, scene.size)
    assert np.sum(np.abs(want - alone).max(axis=-1) > 0.1) > 100  # the surfaces show
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    if err.max() > 2 / 255 or np.any(err > 1 / 255):
        save_failure("pvsm_sources", got, want)
    assert err.max() <= 2 / 255 and not np.any(err > 1 / 255)


def test_saving_a_states_scene_says_which_surfaces_it_leaves_out(tmp_path):
    from tetvr.scene.paraview import load_state

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_state(_state_with_sources(tmp_path))
    with pytest.warns(UserWarning, match=r"3 of the scene's surfaces came from no file .* not in the saved scene"):
        scene.save(tmp_path / "scene.json")
    assert "surfaces" not in (tmp_path / "scene.json").read_text()

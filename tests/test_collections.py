"""ParaView's collections: .pvd time steps with their times, .vtm multiblocks (nested),
.pvtu pieces (each readable alone, or merged into the mesh the solver split)."""

from __future__ import annotations

import os
from pathlib import Path

import meshio
import numpy as np
import pytest

import tetvr
from tetvr.mesh import synthetic
from tetvr.apps.cli import main
from tetvr.io.collections import leaf_files, pieces, read_pvd
from tetvr.io.series import read_step

N_PIECES = 4


def _write_vtu(path: Path, mesh: tetvr.TetMesh, ids: np.ndarray, *, scale: float = 1.0,
               cell_field: bool = False, ghost: np.ndarray | None = None) -> None:
    """Cells ``ids`` of ``mesh`` as a .vtu holding only the points they use (as a solver's piece)."""
    used, tets = np.unique(mesh.tets[ids], return_inverse=True)
    cell_data = {}
    if cell_field:
        cell_data["c"] = [mesh.centroids[ids, 0] * scale]
    if ghost is not None:
        cell_data["vtkGhostType"] = [ghost.astype(np.uint8)]
    meshio.Mesh(mesh.points[used], [("tetra", tets.reshape(-1, 4))], point_data={"f": mesh.scalars[used] * scale},
                cell_data=cell_data).write(path)


def _pieces_of(mesh: tetvr.TetMesh, n: int) -> list[np.ndarray]:
    """Cells split into ``n`` slabs by centroid x."""
    order = np.argsort(mesh.centroids[:, 0], kind="stable")
    return np.array_split(order, n)


def _write_pvtu(folder: Path, mesh: tetvr.TetMesh, n: int = N_PIECES, **kw) -> Path:
    names = []
    for k, ids in enumerate(_pieces_of(mesh, n)):
        names.append(f"part_{k}.vtu")
        _write_vtu(folder / names[-1], mesh, ids, **kw)
    body = "\n".join(f'    <Piece Source="{n}"/>' for n in names)
    path = folder / "grid.pvtu"
    path.write_text('<?xml version="1.0"?>\n<VTKFile type="PUnstructuredGrid" version="0.1">\n'
                    '  <PUnstructuredGrid GhostLevel="0">\n    <PPointData Scalars="f">\n'
                    '      <PDataArray type="Float64" Name="f"/>\n    </PPointData>\n'
                    f'{body}\n  </PUnstructuredGrid>\n</VTKFile>\n')
    return path


def _signature(mesh: tetvr.TetMesh) -> np.ndarray:
    """Each tet as (sorted corner coordinates, corner scalars), rows sorted: equal for two
    meshes that differ only in the numbering of points and cells."""
    p = np.concatenate([mesh.points[mesh.tets], mesh.scalars[mesh.tets][..., None]], axis=2)
    p = p[np.arange(len(p))[:, None], np.lexsort(p.transpose(2, 0, 1)[::-1], axis=1)]
    rows = p.reshape(len(p), -1)
    return rows[np.lexsort(rows.T[::-1])]


@pytest.fixture(scope="module")
def cube() -> tetvr.TetMesh:
    return synthetic.cube(4)


def test_pvtu_pieces_alone_and_merged_equal_the_whole(tmp_path, cube):
    path = _write_pvtu(tmp_path, cube)
    files = pieces(path)
    assert [os.path.basename(f) for f in files] == [f"part_{k}.vtu" for k in range(N_PIECES)]
    alone = [tetvr.read(f) for f in files]
    assert sum(m.n_tets for m in alone) == cube.n_tets
    merged = tetvr.read(path)
    # Shared points are joined: the merged mesh is the whole one, renumbered.
    assert merged.n_points == cube.n_points and merged.n_tets == cube.n_tets
    assert np.array_equal(_signature(merged), _signature(cube))
    assert merged.scalar_name == "f"


def test_pvtu_cell_field_averages_across_piece_seams_like_one_file(tmp_path, cube):
    path = _write_pvtu(tmp_path, cube, cell_field=True)
    _write_vtu(tmp_path / "whole.vtu", cube, np.arange(cube.n_tets), cell_field=True)
    merged, whole = tetvr.read(path, "c"), tetvr.read(tmp_path / "whole.vtu", "c")
    assert merged.report.scalar_source == "cell"
    assert np.allclose(_signature(merged), _signature(whole), rtol=0, atol=1e-12)


def test_pvtu_ghost_cells_are_left_out(tmp_path, cube):
    ids = _pieces_of(cube, 2)
    # Piece 0 also holds piece 1's first 10 cells, marked as duplicates (ghosts).
    extra = np.concatenate([ids[0], ids[1][:10]])
    ghost = np.r_[np.zeros(len(ids[0])), np.ones(10)]
    _write_vtu(tmp_path / "a.vtu", cube, extra, ghost=ghost)
    _write_vtu(tmp_path / "b.vtu", cube, ids[1], ghost=np.zeros(len(ids[1])))
    (tmp_path / "g.pvtu").write_text('<VTKFile type="PUnstructuredGrid"><PUnstructuredGrid GhostLevel="1">'
                                     '<Piece Source="a.vtu"/><Piece Source="b.vtu"/></PUnstructuredGrid></VTKFile>')
    merged = tetvr.read(tmp_path / "g.pvtu")
    assert merged.n_tets == cube.n_tets
    assert np.array_equal(_signature(merged), _signature(cube))


def test_vtm_nested_blocks_merge_into_one_scene(tmp_path, cube):
    a, b, c = _pieces_of(cube, 3)
    (tmp_path / "sub").mkdir()
    _write_vtu(tmp_path / "a.vtu", cube, a)
    _write_vtu(tmp_path / "sub" / "b.vtu", cube, b)
    _write_vtu(tmp_path / "sub" / "c.vtu", cube, c)
    (tmp_path / "sub" / "inner.vtm").write_text(
        '<VTKFile type="vtkMultiBlockDataSet"><vtkMultiBlockDataSet>'
        '<Piece index="0"><DataSet index="0" file="b.vtu"/></Piece><DataSet index="1" file="c.vtu"/>'
        '</vtkMultiBlockDataSet></VTKFile>')
    (tmp_path / "outer.vtm").write_text(
        '<VTKFile type="vtkMultiBlockDataSet" version="1.0"><vtkMultiBlockDataSet>'
        '<Block index="0" name="walls"><DataSet index="0" file="a.vtu"/><DataSet index="1"/></Block>'
        '<Block index="1"><DataSet index="0" file="sub/inner.vtm"/></Block>'
        '</vtkMultiBlockDataSet></VTKFile>')
    assert [os.path.relpath(f, tmp_path) for f in leaf_files(tmp_path / "outer.vtm")] == \
        ["a.vtu", os.path.join("sub", "b.vtu"), os.path.join("sub", "c.vtu")]
    merged = tetvr.read(tmp_path / "outer.vtm")
    assert np.array_equal(_signature(merged), _signature(cube))
    # and through a scene
    (tmp_path / "scene.json").write_text('{"mesh": "outer.vtm", "size": [32, 24]}')
    scene = tetvr.load_scene(tmp_path / "scene.json")
    assert scene.mesh.n_tets == cube.n_tets


def _write_pvd(folder: Path, cube: tetvr.TetMesh, times=(0.0, 0.5, 1.25), parts: int = 1) -> Path:
    rows = []
    for k, t in enumerate(times):
        for p, ids in enumerate(_pieces_of(cube, parts)):
            name = f"step{k}_{p}.vtu"
            _write_vtu(folder / name, cube, ids, scale=k + 1.0)
            rows.append(f'<DataSet timestep="{t}" group="" part="{p}" file="{name}"/>')
    path = folder / "run.pvd"
    # written out of time order: steps come back sorted
    path.write_text('<?xml version="1.0"?><VTKFile type="Collection" version="0.1"><Collection>'
                    + "".join(rows[::-1]) + "</Collection></VTKFile>")
    return path


def test_pvd_steps_with_times_and_parts(tmp_path, cube):
    path = _write_pvd(tmp_path, cube, parts=2)
    coll = read_pvd(path)
    assert coll.times == (0.0, 0.5, 1.25)
    assert [len(s.files) for s in coll.steps] == [2, 2, 2]
    for k in range(3):
        m = read_step(coll, k)
        assert np.array_equal(_signature(m), _signature(cube.with_scalars(cube.scalars * (k + 1.0), "f")))
    with pytest.warns(UserWarning, match=r"holds 3 time steps .*read the first"):
        first = tetvr.read(path)
    assert np.allclose(first.scalar_range, cube.scalar_range)
    with pytest.raises(IndexError, match="3 time steps"):
        read_step(coll, 3)


@pytest.mark.parametrize("text, match", [
    ("not xml", "not valid XML"),
    ('<Other/>', "not a VTK XML file"),
    ('<VTKFile type="Collection"><Collection/></VTKFile>', "no DataSet"),
    ('<VTKFile type="Collection"><Collection><DataSet timestep="x" file="a.vtu"/></Collection></VTKFile>',
     "not a number"),
    ('<VTKFile type="Collection"><Collection><DataSet file="missing.vtu"/></Collection></VTKFile>',
     r"not found: .*missing.vtu.*named by 'bad.pvd'"),
])
def test_bad_collections_say_why(tmp_path, text, match):
    (tmp_path / "bad.pvd").write_text(text)
    with pytest.raises((ValueError, FileNotFoundError), match=match):
        tetvr.read(tmp_path / "bad.pvd")


def test_a_vtm_that_names_itself_is_refused(tmp_path):
    (tmp_path / "loop.vtm").write_text('<VTKFile type="vtkMultiBlockDataSet"><vtkMultiBlockDataSet>'
                                       '<DataSet file="loop.vtm"/></vtkMultiBlockDataSet></VTKFile>')
    with pytest.raises(ValueError, match="nested deeper"):
        tetvr.read(tmp_path / "loop.vtm")


@pytest.mark.gl
def test_cli_renders_one_frame_per_step_named_by_time(tmp_path, cube, capsys):
    path = _write_pvd(tmp_path, cube)
    out = tmp_path / "out"
    out.mkdir()
    assert main(["render", str(path), "-o", str(out / "frame_{time}.png")]) == 0
    assert sorted(os.listdir(out)) == ["frame_0.0.png", "frame_0.5.png", "frame_1.25.png"]
    said = capsys.readouterr()
    assert "t = 1.25" in said.out and "time steps" not in said.err  # no "read the first step" warning
    # one name for three steps: refused before rendering, with one error line
    assert main(["render", str(path), "-o", str(out / "frame.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("tetvr: error:") == 1 and "{time}" in err
    assert not (out / "frame.png").exists()
    # never over an input: a step's name that is one of the collection's files
    assert main(["render", str(path), "-o", str(tmp_path / "step{index}_0.vtu")]) == 2
    assert "refusing to write" in capsys.readouterr().err


def test_cli_never_writes_over_a_piece_of_a_collection(tmp_path, cube, capsys):
    path = _write_pvtu(tmp_path, cube)
    before = (tmp_path / "part_2.vtu").read_bytes()
    assert main(["render", str(path), "-o", str(tmp_path / "part_2.vtu")]) == 2
    assert "refusing to write" in capsys.readouterr().err
    assert (tmp_path / "part_2.vtu").read_bytes() == before


@pytest.mark.gl
def test_a_pvtu_of_4_pieces_renders_as_the_whole_mesh(tmp_path, cube, renderer):
    merged = tetvr.read(_write_pvtu(tmp_path, cube))
    camera = tetvr.Camera.fit(cube, direction=(-1.0, -0.4, -0.7))
    tf = tetvr.TransferFunction.preset("viridis", cube.scalar_range, opacity=0.8, unit_distance=0.3)
    want = renderer.render(cube, camera, tf, size=(48, 40))
    got = renderer.render(merged, camera, tf, size=(48, 40))
    assert want[..., 3].max() > 0.3
    assert np.abs(got - want).max() < 1e-6  # the same cells, numbered otherwise: float32 rounding at most

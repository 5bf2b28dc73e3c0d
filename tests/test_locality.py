"""The walk's mesh numbered along a space-filling curve (tetvr.mesh.locality): the same
cells and picture, whatever order the file's points come in."""

from __future__ import annotations

import numpy as np
import pytest

import tetvr
from tetvr.gl.renderer import Renderer
from tetvr.mesh import synthetic
from tetvr.mesh.locality import MIN_POINTS, numbered_locally, spatially_ordered
from tetvr.mesh.tetmesh import TetMesh

SIZE = (64, 64)


def _shuffled(mesh: TetMesh, seed: int = 0, **kw) -> TetMesh:
    """The same cells with their points in random order (as TetGen or SimVascular may write them)."""
    perm = np.random.default_rng(seed).permutation(mesh.n_points)
    rank = np.argsort(perm)
    return TetMesh.from_arrays(mesh.points[perm], rank[mesh.tets], mesh.scalars[perm], **kw)


@pytest.fixture(scope="module")
def grid() -> TetMesh:
    mesh = synthetic.cube(16)  # 4,913 points, numbered row by row
    assert mesh.n_points >= MIN_POINTS
    return mesh


def _cells(mesh: TetMesh) -> np.ndarray:
    """Each cell as its sorted corner coordinates, the cells sorted: the mesh's cells whatever their numbering."""
    corners = np.sort(mesh.points[mesh.tets].reshape(mesh.n_tets, 12), axis=1)
    return corners[np.lexsort(corners.T[::-1])]


def test_a_grid_numbered_row_by_row_is_walked_as_given(grid):
    assert numbered_locally(grid)
    assert spatially_ordered(grid) is grid


def test_a_mesh_kept_as_it_is_is_checked_once(monkeypatch):
    """Whether a mesh is numbered locally is asked on every view change (the walk check
    starts from spatially_ordered): it is measured once per mesh, not per frame (90 ms on
    1M tets, most of a frame on a GPU)."""
    from tetvr.mesh import locality

    mesh = synthetic.cube(16)
    calls = []
    monkeypatch.setattr(locality, "numbered_locally", lambda m: calls.append(m) or True)
    assert all(spatially_ordered(mesh) is mesh for _ in range(3))
    assert len(calls) == 1
    other = synthetic.cube(16)  # another mesh, the same numbering: measured on its own
    assert spatially_ordered(other) is other and len(calls) == 2


def test_points_in_no_order_are_renumbered_into_the_same_cells(grid):
    mesh = _shuffled(grid)
    assert not numbered_locally(mesh)
    ordered = spatially_ordered(mesh)
    assert ordered is spatially_ordered(mesh)  # cached with the mesh
    assert numbered_locally(ordered)
    np.testing.assert_array_equal(_cells(ordered), _cells(mesh))
    # Canonical as TetMesh.from_arrays makes meshes: positively oriented, rows sorted.
    again = TetMesh.from_arrays(ordered.points, ordered.tets, ordered.scalars)
    np.testing.assert_array_equal(again.tets, ordered.tets)
    assert again.report.inverted_fixed == 0
    # The field moves with its points.
    np.testing.assert_array_equal(np.sort(ordered.scalars[ordered.tets].ravel()), np.sort(mesh.scalars[mesh.tets].ravel()))


@pytest.mark.parametrize("kind", ["point", "cell", "repeated"])
def test_a_shuffled_mesh_renders_as_the_grid_and_the_reference(grid, kind):
    if kind == "cell":
        grid = TetMesh.from_arrays(grid.points, grid.tets, None, cell_scalars=grid.centroids[:, 0])
        mesh = _shuffled(grid, cell_scalars=grid.cell_scalars)
    elif kind == "repeated":  # every cell twice: the copies' counts follow the renumbered cells
        grid = synthetic.merge(grid, grid)
        mesh = synthetic.merge(*([_shuffled(synthetic.cube(16))] * 2))
    else:
        mesh = _shuffled(grid)
    camera = tetvr.Camera.fit(grid)
    tf = tetvr.TransferFunction.preset("viridis", grid.scalar_range, opacity=0.6, mesh=grid)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as renderer:
        given = renderer.render(grid, camera, tf, size=SIZE)
        shuffled = renderer.render(mesh, camera, tf, size=SIZE)
        walked = renderer._march._walked
    assert walked is not mesh and numbered_locally(walked)
    ref = tetvr.render(mesh, method="reference", camera=camera, tf=tf, size=SIZE)
    err = np.abs(shuffled.astype(np.float64) - ref).max()
    assert err <= 1 / 255, err
    assert np.abs(shuffled - given).max() <= 1e-4

"""Cell data rendered exactly: the field constant in each tet, jumping at its faces.

The oracle is the reference renderer, itself checked against closed forms: a slab of
constant opacity ``a`` and thickness ``h`` has alpha ``1 - (1 - a)^(h / u)``, and two such
slabs seen one behind the other composite "over".
"""

from __future__ import annotations

import meshio
import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.core.image import psnr
from tetvr.mesh.tetmesh import TetMesh
from tetvr.io.meshfile import read
from tetvr.reference.tets import render_reference
from tetvr.optics.transfer import field_range

from .conftest import save_failure

# Error bars: what the GPU reached on these scenes (~101 dB, max 5e-4) with margin.
MIN_PSNR = 90.0
MAX_ERROR = 2e-3


def _slabs(values: tuple[float, float]) -> TetMesh:
    """The unit cube cut at z = 0.5 into two slabs, each made of tets holding one value."""
    cube = synthetic.cube(2, rotate=False)  # 2 x 2 x 2 axis-aligned sub-cubes, 6 tets each
    z = cube.centroids[:, 2]
    lo, hi = float(cube.bounds[0, 2]), float(cube.bounds[1, 2])
    return cube.with_cell_scalars(np.where(z < 0.5 * (lo + hi), values[0], values[1]), name="material")


def _check(renderer, name: str, mesh: TetMesh, camera: Camera, tf: TransferFunction, size=(96, 96)) -> None:
    got = renderer.render(mesh, camera, tf, size=size)
    want = render_reference(mesh, camera, tf, size)
    assert np.all(np.isfinite(got)), f"{name}: NaN or Inf in the image"
    assert want[..., 3].max() > 0.2, f"{name}: reference image is nearly empty"
    err = np.abs(got.astype(np.float64) - want)
    value, worst, beyond = psnr(got, want), float(err.max()), int((err > 1 / 255).any(axis=-1).sum())
    if value < MIN_PSNR or worst > MAX_ERROR or beyond:
        where = save_failure(name, got, want)
        pytest.fail(f"{name}: {value:.1f} dB, max error {worst:.2e}, {beyond} pixels beyond 1/255 "
                    f"(images in {where})")


def test_reference_integrates_constant_cells_in_closed_form():
    mesh = _slabs((0.0, 1.0))
    tf = TransferFunction(color=[(0.0, 1.0, 0.0, 0.0), (1.0, 0.0, 0.0, 1.0)],
                          opacity=[(0.0, 0.3), (1.0, 0.6)], unit_distance=0.25)
    lo, hi = mesh.bounds
    camera = Camera(position=(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2] + 1.0),
                    focal_point=tuple(0.5 * (lo + hi)), view_up=(0.0, 1.0, 0.0), parallel_projection=True,
                    parallel_scale=0.25 * float(hi[1] - lo[1]), clipping_range=(0.1, 10.0))
    image = render_reference(mesh, camera, tf, (8, 8))
    h = 0.5 * float(hi[2] - lo[2])
    a_front = 1.0 - 0.4 ** (h / 0.25)  # the eye looks down -z: the slab of value 1 is in front
    a_back = 1.0 - 0.7 ** (h / 0.25)
    want = np.array([0.0, 0.0, a_front, a_front]) + (1.0 - a_front) * np.array([a_back, 0.0, 0.0, a_back])
    np.testing.assert_allclose(image.reshape(-1, 4), np.broadcast_to(want, (64, 4)), atol=1e-9)


@pytest.mark.gl
@pytest.mark.parametrize("view", ["outside", "parallel", "inside"])
def test_gpu_matches_the_cell_constant_reference(renderer, view):
    mesh = synthetic.cube(6)
    rng = np.random.default_rng(7)
    mesh = mesh.with_cell_scalars(rng.uniform(0.0, 1.0, mesh.n_tets) ** 2, name="stress")  # jumps at every face
    tf = TransferFunction.preset("viridis", mesh)
    centre = mesh.bounds.mean(axis=0)
    if view == "inside":
        camera = Camera(position=tuple(centre + (0.05, -0.1, 0.03)), focal_point=tuple(centre + (1.0, 0.3, -0.2)),
                        view_up=(0.0, 0.0, 1.0), view_angle=60.0, clipping_range=(0.01, 10.0))
    else:
        # y up, the view the bars were measured in (z up: projected tetrahedra 2.8e-3 at one pixel, bar 2e-3)
        camera = Camera.fit(mesh, parallel=view == "parallel", view_up=(0, 1, 0))
    _check(renderer, f"cell_data_{view}", mesh, camera, tf)


@pytest.mark.gl
def test_jump_between_two_materials(renderer):
    mesh = _slabs((0.1, 0.9))
    tf = TransferFunction.preset("cool-to-warm", (0.0, 1.0), opacity=[(0.0, 0.0), (0.5, 0.2), (1.0, 0.8)],
                                 unit_distance=0.2)
    _check(renderer, "cell_data_slabs", mesh, Camera.fit(mesh, direction=(-0.3, -1.0, -0.4)), tf)


@pytest.mark.gl
def test_chunked_cell_data_is_identical():
    from tetvr.gl import Renderer

    mesh = synthetic.cube(4)
    mesh = mesh.with_cell_scalars(np.arange(mesh.n_tets) % 7 / 6.0)
    tf = TransferFunction.preset("viridis", mesh)
    camera = Camera.fit(mesh)
    settings = RenderSettings(method="projected")
    with Renderer(settings) as whole, Renderer(settings, chunk_tets=37) as chunked:
        a = whole.render(mesh, camera, tf, size=(64, 64))
        b = chunked.render(mesh, camera, tf, size=(64, 64))
    np.testing.assert_array_equal(a, b)


def test_cell_scalars_follow_their_tets_through_canonicalisation():
    base = synthetic.cube(2)
    values = np.linspace(0.0, 1.0, base.n_tets)
    rng = np.random.default_rng(3)
    perm = rng.permutation(base.n_tets)
    # Shuffled rows and vertex order (orientation flipped for some): the same mesh.
    tets = base.tets[perm][:, [1, 0, 2, 3]]
    shuffled = TetMesh.from_arrays(base.points, tets, None, cell_scalars=values[perm])
    again = base.with_cell_scalars(values)
    np.testing.assert_array_equal(shuffled.tets, again.tets)
    np.testing.assert_array_equal(shuffled.cell_scalars, again.cell_scalars)
    assert shuffled.cell_data and shuffled.scalar_range == (0.0, 1.0)
    np.testing.assert_array_equal(shuffled.corner_scalars, np.repeat(values[:, None], 4, axis=1))
    assert not shuffled.averaged().cell_data


def test_bad_cell_scalars_are_refused():
    m = synthetic.cube(1)
    with pytest.raises(ValueError, match=r"one value per tet \(6\)"):
        TetMesh.from_arrays(m.points, m.tets, None, cell_scalars=[1.0, 2.0])
    with pytest.raises(ValueError, match="NaN or Inf"):
        m.with_cell_scalars([1.0, np.nan, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="give scalars"):
        TetMesh.from_arrays(m.points, m.tets, None)


def _write_cell_file(path, values) -> None:
    m = synthetic.cube(2)
    meshio.Mesh(m.points, [("tetra", m.tets)], cell_data={"stress": [np.asarray(values)]}).write(path)


def test_read_keeps_cell_data_exact_or_averages_on_request(tmp_path):
    path = tmp_path / "cells.vtu"
    values = np.arange(48, dtype=float)
    _write_cell_file(path, values)
    exact = read(path)
    assert exact.cell_data and exact.report.scalar_source == "cell"
    assert sorted(exact.cell_scalars.tolist()) == values.tolist()
    assert exact.scalar_range == (0.0, 47.0)
    averaged = read(path, cell_data="average")
    assert not averaged.cell_data
    assert 0.0 < averaged.scalars.min() and averaged.scalars.max() < 47.0  # averaging narrows the range
    with pytest.raises(ValueError, match=r"cell_data must be one of \('exact', 'average'\), got 'mean'"):
        read(path, cell_data="mean")
    grid = exact.to_pyvista() if _has_pyvista() else None
    if grid is not None:
        np.testing.assert_array_equal(np.asarray(grid.cell_data["stress"]), exact.cell_scalars)


def test_default_range_comes_from_the_cells():
    m = synthetic.cube(4)
    lo, hi = field_range(m.with_cell_scalars(np.r_[np.linspace(0.0, 1.0, m.n_tets - 1), 1000.0]))
    assert 0.0 <= lo < 0.05 and 0.9 < hi <= 1.0  # one cell of 384 does not set the top


def _has_pyvista() -> bool:
    try:
        import pyvista  # noqa: F401
    except ImportError:
        return False
    return True

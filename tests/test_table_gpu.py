"""The pre-integration table's runs built on the GPU (tetvr.gl.tablebuild, shaders/table_runs.comp)
against the CPU's build of the same table: equal to float32 rounding, for the tables the GPU builds,
and the CPU's for the others."""

from __future__ import annotations

import numpy as np
import pytest

from tetvr import RenderSettings, TransferFunction
from tetvr.core.camera import Camera
from tetvr.mesh import synthetic
from tetvr.optics.preintegrate import build_table, cache_clear, table_for
from tests.test_discretized_maps import _paraview_map

SMOOTH = TransferFunction.preset("viridis", (0.0, 1.0), opacity=0.5)
#: An opaque spike between two nodes' worth of scalars: thick bins, transmittance near 0.
SPIKY = TransferFunction(color=((0.0, 0.1, 0.2, 0.9), (0.5, 1.0, 0.9, 0.1), (1.0, 0.9, 0.1, 0.1)),
                         opacity=((0.0, 0.0), (0.48, 0.0), (0.5, 0.999), (0.52, 0.0), (1.0, 0.05)),
                         unit_distance=0.01)


@pytest.fixture(scope="module")
def runs():
    from tests.conftest import gl_object
    from tetvr.gl import Renderer
    from tetvr.gl.tablebuild import TableRuns

    for r in gl_object(Renderer, "no OpenGL 4.3 context"):
        yield TableRuns(r.ctx, lambda ring: r._program("table_runs", RING=ring))


def _assert_same(gpu, cpu):
    assert gpu.data.shape == cpu.data.shape and gpu.data.dtype == cpu.data.dtype == np.float32
    assert np.all(np.isfinite(gpu.data))
    colour = np.abs(gpu.data[..., :3].astype(np.float64) - cpu.data[..., :3])
    extinction = np.abs(gpu.data[..., 3].astype(np.float64) - cpu.data[..., 3])
    # Both are float64 arithmetic rounded to float32 once: they differ by a rounding at most.
    assert colour.max() <= 2e-7, colour.max()
    assert np.all(extinction <= 2e-7 * np.maximum(np.abs(cpu.data[..., 3]), 1e-30)), extinction.max()
    for field in ("scalar_range", "log_base", "encoding", "alpha_scale"):
        assert getattr(gpu, field) == getattr(cpu, field)
    np.testing.assert_array_equal(gpu.thicknesses, cpu.thicknesses)
    assert (gpu.steps is None) == (cpu.steps is None)
    if cpu.steps is not None:
        np.testing.assert_allclose(gpu.steps, cpu.steps, atol=2e-7, rtol=0)


@pytest.mark.parametrize("tf, d_max, n_bins, n_slices, optics", [
    (SMOOTH, 0.3, 256, 8, "exact"),
    (SMOOTH, 0.3, 2, 1, "exact"),  # the fewest nodes: one bin
    (SPIKY, 2.0, 200, 16, "exact"),  # optical depths past 700: transmittance 0
    (SPIKY, 1e-6, 64, 8, "exact"),  # every bin thin: the terms of order one cancel
    (SMOOTH, 0.3, 128, 8, "linear"),
    (SPIKY, 0.5, 513, 4, "exact"),  # 512 bins: runs as long as the ring (table_runs.comp's RING)
    (SPIKY, 0.5, 514, 2, "exact"),  # 513 bins: the next ring
    (SMOOTH, 0.3, 2048, 2, "exact"),  # the most bins RenderSettings allows

    (_paraview_map((0.0, 1.0), bands=32), 0.5, 256, 8, "exact"),  # steps on nodes: bins' ends differ
])
def test_the_gpu_builds_the_cpus_table(runs, tf, d_max, n_bins, n_slices, optics):
    kw = dict(n_bins=n_bins, n_slices=n_slices, log_base=1.7, optics=optics)
    _assert_same(build_table(tf, (0.0, 1.0), d_max, runs=runs, **kw), build_table(tf, (0.0, 1.0), d_max, **kw))


def test_the_ring_holds_every_run():
    from tetvr.gl.tablebuild import ring_size

    for n in (1, 2, 255, 256, 257, 512, 513, 2048, 2060):
        ring = ring_size(n)
        assert ring >= n and ring & (ring - 1) == 0 and ring >= 256
    assert ring_size(512) == 512 and ring_size(513) == 1024


class _Spy:
    """A runs builder that counts its calls and builds nothing."""

    calls = 0

    def __call__(self, *args):
        self.calls += 1
        raise AssertionError("this table is not the GPU's to build")


@pytest.mark.parametrize("kw", [dict(encoding="premultiplied"), dict(dtype="uint8"), dict(optics="vtk"),
                                dict(warp=True)])
def test_tables_the_gpu_does_not_build_are_the_cpus(kw):
    spy = _Spy()
    table = build_table(SPIKY, (0.0, 1.0), 1.0, n_bins=64, n_slices=4, runs=spy, **kw)
    assert spy.calls == 0
    np.testing.assert_array_equal(table.data, build_table(SPIKY, (0.0, 1.0), 1.0, n_bins=64, n_slices=4, **kw).data)


def test_the_builder_refuses_an_output_of_another_shape(runs):
    with pytest.raises(ValueError, match="out must be a C-contiguous float32 array of shape"):
        runs(np.zeros((3, 3)), np.zeros((3, 3)), np.ones(3), np.arange(4.0), np.ones(2), np.zeros((4, 4, 2, 4), np.float32))


def test_the_cache_keeps_one_table_whoever_built_it(runs):
    cache_clear()
    a = table_for(SMOOTH, (0.0, 1.0), 0.3, n_bins=32, n_slices=4, runs=runs)
    assert table_for(SMOOTH, (0.0, 1.0), 0.3, n_bins=32, n_slices=4) is a
    cache_clear()
    assert table_for(SMOOTH, (0.0, 1.0), 0.3, n_bins=32, n_slices=4) is not a


def test_the_renderer_draws_with_the_gpus_table(runs):
    from tetvr.gl import Renderer
    from tetvr.optics.tablesize import resolve

    mesh = synthetic.cube(4)
    tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.5)
    with Renderer(RenderSettings(method="raymarch")) as r:
        table = r.table(mesh, tf)
        size = resolve(r.settings, tf, mesh)
        cache_clear()
        cpu = table_for(tf, mesh.scalar_range, mesh.max_edge, n_bins=size.n_bins, n_slices=size.n_slices,
                        log_base=size.log_base, align_nodes=True)
        assert cpu is not table
        _assert_same(table, cpu)
        # Built in the texture's layout: the table's data is a view of it, uploaded as it is.
        assert not table.data.flags.c_contiguous and np.moveaxis(table.data, 0, 2).flags.c_contiguous
        camera = Camera.fit(mesh)
        image = r.render(mesh, camera, tf, size=(48, 48))
        r._table_cache = (r._table_cache[0], cpu)  # the same frame with the CPU's table in the texture
        assert np.max(np.abs(r.render(mesh, camera, tf, size=(48, 48)) - image)) <= 1e-6

"""bench/vs_vtk.py's first frames: the median of several, each on the mesh loaded again,
with tetvr's table caches emptied, the default and VTK in turn."""

from __future__ import annotations

import types

import pytest

from tetvr.mesh import synthetic
from tetvr.optics import preintegrate

from .test_bench_speed_charts import _load


@pytest.fixture(scope="module")
def vs_vtk():
    pytest.importorskip("matplotlib")
    return _load("vs_vtk")


def test_first_frames_again(vs_vtk, monkeypatch):
    made, loads, cached = [], [], []
    seconds = {"tetvr": iter([0.5, 0.1]), "vtk_pt": iter([0.9, 0.3])}

    class Fake:
        def __init__(self, key):
            self.key = key
            self.renderer = types.SimpleNamespace(first_seconds=float("nan"))

        def frame(self, mesh, cam, tf, size):
            cached.append(len(preintegrate._cache))
            self.renderer.first_seconds = next(seconds[self.key])

        def release(self):
            pass

    def make(key, mesh, tf, size):
        made.append((key, mesh))
        return Fake(key)

    def load():
        loads.append(synthetic.cube(2))
        return loads[-1]

    monkeypatch.setattr(vs_vtk, "_make", make)
    # perf_counter, each first frame's start and end: VTK's, the default's; the default's, VTK's.
    clock = [0.0, 0.0, 0.0, 0.2, 1.0, 1.4, 0.0, 0.0]
    monkeypatch.setattr(vs_vtk, "time", types.SimpleNamespace(perf_counter=iter(clock).__next__))
    preintegrate.table_for(vs_vtk.default_transfer_function(synthetic.cube(2)), (0.0, 1.0), 1.0, n_bins=4, n_slices=2)
    rec = {"first_frame_s": {"tetvr": 0.3, "tetvr_projected": 0.2, "vtk_pt": 0.6}}
    vs_vtk.first_frames_again(rec, load, (8, 8), 2)
    # In turn, VTK first and then the default first; each time on a mesh loaded again.
    assert [k for k, _ in made] == ["vtk_pt", "tetvr", "tetvr", "vtk_pt"]
    assert len(loads) == 2 and made[0][1] is made[1][1] is loads[0] and made[2][1] is loads[1]
    assert cached == [0, 0, 0, 0]  # no table kept from before
    assert rec["first_frame_samples_s"] == {"tetvr": pytest.approx([0.3, 0.2, 0.4]), "vtk_pt": [0.6, 0.9, 0.3]}
    assert rec["first_frame_s"]["tetvr"] == pytest.approx(0.3) and rec["first_frame_s"]["vtk_pt"] == pytest.approx(0.6)
    assert rec["first_frame_s"]["tetvr_projected"] == 0.2  # not timed again: kept
    assert rec["first_frame_vs_vtk_pt"]["tetvr"] == pytest.approx(2.0)

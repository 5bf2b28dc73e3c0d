"""bench/methods.py, the script a session lent a GPU runs there (bench/device_check.sh): one
small mesh through the timing run, then --accuracy against the reference and --fit, so
that a broken script is found here and not in the GPU's minutes."""

from __future__ import annotations

import json
import sys

import pytest

from .test_bench_speed_charts import _load

pytestmark = pytest.mark.gl


def test_a_timing_run_then_its_accuracy_and_model(tmp_path, monkeypatch):
    # The script puts bench/ on sys.path, where bench/distributed.py would shadow Dask's
    # package in every process started later (the cluster tests' workers): put it back.
    monkeypatch.setattr(sys, "path", list(sys.path))
    methods = _load("methods")
    assert methods.main(["--only", "cube(12)", "--sizes", "32", "--image-size", "24", "--step", "5",
                         "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "methods.json").read_text())
    (mesh,) = res["meshes"]
    assert mesh["name"] == "cube(12)" and mesh["n_tets"] == 6 * 12**3
    timed = mesh["sizes"]["32"]
    assert set(timed["median_s"]) == {"raymarch", "projected"} and len(timed["samples_s"]["raymarch"]) >= 5
    assert set(timed["auto_method"]) <= {"raymarch", "projected"}
    assert isinstance(res["filter_in_shader"], bool) and res["linear_filter_error"] >= 0.0
    assert isinstance(res["interpolate_in_shader"], bool) and res["interpolation_error_px"] >= 0.0
    assert sorted(p.name for p in tmp_path.glob("methods_images_*.npz")) == ["methods_images_0.npz"]

    assert methods.main(["--accuracy", str(tmp_path), "--fit"]) == 0
    res = json.loads((tmp_path / "methods.json").read_text())
    acc = res["meshes"][0]["accuracy"]
    for method in ("raymarch", "projected"):  # both exact to well within 1/255 on this grid
        assert acc[method]["pixels_beyond_1_255"] == 0 and acc[method]["max_error"] < 2e-3
    assert res["cost_model"]["fitted_ns"]["march_ns_per_segment"] >= 0.0
    assert (tmp_path / "methods.png").stat().st_size > 0  # the chart

"""bench/gpu_images.py: the GL tests' images kept as a pytest plugin, and two such folders
compared, so that a GPU's failures can be looked at pixel by pixel here."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from .test_bench_speed_charts import _load

ROOT = Path(__file__).resolve().parents[1]


def test_two_folders_compare_image_by_image(tmp_path):
    gpu_images = _load("gpu_images")
    a = np.zeros((4, 5, 4), np.float32)
    b = a.copy()
    b[1, 3, 2] = 0.01  # beyond 1/255 at x 3, y 1
    b[2, 0, 0] = 5e-4  # beyond 1e-4 only
    for name, images in (("gpu", {"t::x#0": a, "t::y#0": a, "t::only#0": a}), ("here", {"t::x#0": b, "t::y#0": a[:2]})):
        (tmp_path / name).mkdir()
        np.savez_compressed(tmp_path / name / "main.npz", **images)
    rows = gpu_images.compare(gpu_images.load(tmp_path / "gpu"), gpu_images.load(tmp_path / "here"))
    assert rows[0] == {"key": "t::x#0", "max": pytest.approx(0.01), "beyond_1_255": 1, "beyond": 2, "first": (3, 1)}
    assert rows[1] == {"key": "t::y#0", "shape": ((4, 5, 4), (2, 5, 4))}
    assert gpu_images.main([str(tmp_path / "gpu"), str(tmp_path / "here")]) == 0


@pytest.mark.gl
def test_the_plugin_keeps_each_test_s_images(tmp_path):
    env = {**os.environ, "TETVR_TEST_IMAGES": str(tmp_path / "kept")}
    test = "tests/test_gl_images.py::test_constant_slab_has_alpha_of_its_opacity"
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "bench.gpu_images",
                           test], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    with np.load(tmp_path / "kept" / "main.npz") as z:
        assert sorted(z.files) == [f"{test}[projected]#0", f"{test}[raymarch]#0"]
        assert z[f"{test}[raymarch]#0"].shape == (64, 64, 4)
        assert np.allclose(z[f"{test}[raymarch]#0"][..., 3], 0.7, atol=1e-4)

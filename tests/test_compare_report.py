"""tetvr compare's checks and report pictures (no VTK needed)."""

from __future__ import annotations

import numpy as np
import pytest

import tetvr
from tetvr.apps import vtkcompare


def test_compare_says_vtk_is_missing_before_rendering_anything(monkeypatch):
    scene = tetvr.load_scene(tetvr.demo_scene_path())
    monkeypatch.setattr(vtkcompare, "vtk_status", lambda: (False, "VTK is not installed (pip install vtk)"))

    def no_render(*args, **kwargs):
        raise AssertionError("rendered before checking for VTK")

    monkeypatch.setattr("tetvr.reference.tets.render_reference", no_render)
    with pytest.raises(vtkcompare.VTKUnavailableError, match="not installed"):
        vtkcompare.compare(scene, mappers=("pt",))


@pytest.mark.gl
def test_report_pictures_use_the_scene_background(tmp_path):
    import dataclasses

    import matplotlib.pyplot as plt

    scene = tetvr.load_scene(tetvr.demo_scene_path())
    scene = dataclasses.replace(scene, background=(0.0, 0.0, 1.0))
    vtkcompare.compare(scene, mappers=(), size=(16, 12), views=1, references=("exact",), outdir=tmp_path)
    png = plt.imread(tmp_path / "reference_exact.png")
    assert np.allclose(png[0, 0, :3], (0, 0, 1), atol=1 / 255)  # a corner the mesh leaves empty
    assert (tmp_path / "side_by_side.png").is_file()

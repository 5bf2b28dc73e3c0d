"""The command line, and a render from a non-editable wheel (the shaders ship inside it)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tetvr.apps.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.gl
def test_cli_demo_and_render(tmp_path, capsys):
    out = tmp_path / "demo.png"
    assert main(["demo", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    scene = tmp_path / "s.json"
    scene.write_text('{"mesh": "%s", "size": [40, 30], "camera": {"fit": {"parallel": true}}}'
                     % (ROOT / "meshes" / "post.vtk"))
    npy = tmp_path / "o.npy"
    assert main(["render", str(scene), "-o", str(tmp_path / "o.png"), "--npy", str(npy)]) == 0
    img = np.load(npy)
    assert img.shape == (30, 40, 4) and img[..., 3].max() > 0.1


def test_cli_errors_are_clear(tmp_path, capsys):
    assert main(["render", str(tmp_path / "missing.json")]) == 2
    assert "missing.json" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert main(["render", str(bad)]) == 2
    assert "not valid JSON" in capsys.readouterr().err


def test_import_needs_no_gl():
    code = "import sys, tetvr, tetvr.reference.tets; assert 'moderngl' not in sys.modules, 'GL imported'"
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.gl
def test_wheel_renders_from_outside_the_source_tree(tmp_path):
    wheel_dir = tmp_path / "wheel"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                    "-w", str(wheel_dir), str(ROOT)], check=True, cwd=tmp_path)
    wheel = next(wheel_dir.glob("tetvr-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    assert "tetvr/shaders/classify.comp" in names and "tetvr/meshes/post.vtk" in names
    site = tmp_path / "site"
    zipfile.ZipFile(wheel).extractall(site)
    code = ("import tetvr, pathlib; assert pathlib.Path(tetvr.__file__).is_relative_to(r'%s'), tetvr.__file__;"
            "from tetvr.gl.shaders import shader_dir; assert shader_dir().is_relative_to(r'%s');"
            "s = tetvr.load_scene(tetvr.demo_scene_path());"
            "img = tetvr.render(s.mesh, camera=s.camera, tf=s.tf, size=(32, 24));"
            "assert img[..., 3].max() > 0.1" % (site, site))
    subprocess.run([sys.executable, "-c", code], check=True, cwd=tmp_path, env={"PYTHONPATH": str(site), "PATH": ""})


@pytest.mark.gl
def test_cli_fusion_demo(tmp_path):
    assert main(["fusion-demo", "-o", str(tmp_path), "--size", "64", "48"]) == 0
    for name in ("fusion_interleave", "fusion_overlay", "fusion_cutaway", "fusion_ray_textures", "fusion_modes"):
        assert (tmp_path / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
    if importlib.util.find_spec("matplotlib") is not None:  # labelled: a title row above each picture
        import matplotlib.image

        grid = matplotlib.image.imread(tmp_path / "fusion_modes.png")
        one = matplotlib.image.imread(tmp_path / "fusion_overlay.png")
        assert one.shape[0] > one.shape[1] * 48 / 64 + 10 and grid.shape[0] > 2 * one.shape[0] - 20


def test_image_cells_to_tets_lines_up_with_the_volume():
    from tetvr.scene.examples import carotid_fusion

    scene = carotid_fusion()
    # Every mesh point is a voxel centre carrying that voxel's value.
    values = scene.volume.sample(scene.mesh.points)
    np.testing.assert_allclose(values, scene.mesh.scalars, rtol=1e-6)
    assert scene.mesh.scalar_range[0] > 175.0

"""Pictures that explain themselves: the annotated PNG (legend, title, triad, outline)
leaves the rendered pixels as they were; tetvr.plot and the CLI's render output carry it;
meshio / pyvista / vtk objects in and out.

Renders here use the CPU reference (method="reference", ``--reference``): no GL needed.
"""

from __future__ import annotations

import io
import subprocess
import sys

import numpy as np
import pytest

import tetvr
from tetvr import Camera
from tetvr.mesh import synthetic
from tetvr.apps.annotate import Picture, annotate, as_mesh, panels, plot, show
from tetvr.apps.cli import EXIT_USAGE, main
from tetvr.core.image import composite_over, to_rgba8
from tetvr.render import default_transfer_function

from .badinput._util import POST_VTK

mpimg = pytest.importorskip("matplotlib.image")

PNG = b"\x89PNG\r\n\x1a\n"


def decode(png: bytes) -> np.ndarray:
    return np.round(mpimg.imread(io.BytesIO(png), format="png") * 255).astype(np.uint8)


@pytest.fixture(scope="module")
def scene():
    mesh = synthetic.cube(3, synthetic.linear_field((1.0, 0.5, 0.2), 0.3))
    cam = Camera.fit(mesh)
    tf = default_transfer_function(mesh)
    image = tetvr.render(mesh, camera=cam, tf=tf, size=(60, 90), method="reference")
    return mesh, cam, tf, image


def test_the_rendered_pixels_are_drawn_as_they_are(scene):
    mesh, cam, tf, image = scene
    for bg in ((1.0, 1.0, 1.0), (0.0, 0.0, 0.1)):
        png = annotate(image, tf, field="T", camera=cam, bounds=mesh.bounds, triad=False, outline=False, background=bg)
        got = decode(png)
        assert got.shape[0] == 90 and got.shape[1] > 60  # the legend is beside the picture, not over it
        np.testing.assert_array_equal(got[:, :60], to_rgba8(composite_over(image, bg)))


def test_the_float_image_is_not_changed(scene):
    mesh, cam, tf, image = scene
    before = image.copy()
    annotate(image, tf, field="T", title="title", camera=cam, bounds=mesh.bounds)
    np.testing.assert_array_equal(image, before)


def test_legend_shows_the_colour_map_and_the_title_sits_above(scene):
    mesh, cam, tf, image = scene
    png = annotate(image, tf, field="Temperature", units="K", title="A title", camera=cam, bounds=mesh.bounds)
    got = decode(png)
    assert got.shape[0] > 90  # the title line
    legend = got[:, 60:, :3].reshape(-1, 3).astype(int)
    for value in tf.domain:  # both ends of the colour map are in the legend
        want = np.round(tf.evaluate([value])[0][0] * 255)
        assert np.abs(legend - want).sum(axis=1).min() <= 40, value


def test_triad_and_outline_draw_over_the_picture(scene):
    mesh, cam, tf, image = scene
    plain = decode(annotate(image, tf, camera=cam, bounds=mesh.bounds, triad=False, outline=False, legend=False))
    drawn = decode(annotate(image, tf, camera=cam, bounds=mesh.bounds, legend=False))
    assert plain.shape == drawn.shape == (90, 60, 4)
    assert np.any(plain != drawn)


def test_annotate_checks_its_arguments(scene):
    mesh, cam, tf, image = scene
    with pytest.raises(ValueError, match=r"image must have shape \(H, W, 4\)"):
        annotate(image[..., :3], tf)
    with pytest.raises(TypeError, match="tf must be a TransferFunction"):
        annotate(image, {"color": []})


def _ink_rows(rgba: np.ndarray, background=(255, 255, 255)) -> np.ndarray:
    """Rows of a decoded picture holding anything but the background."""
    return np.flatnonzero(np.any(rgba[..., :3] != np.asarray(background, dtype=np.uint8), axis=(1, 2)))


def test_panels_put_each_title_above_its_picture(scene):
    _, _, _, image = scene
    solid = np.zeros((40, 60, 4), np.float32)
    solid[..., 0] = solid[..., 3] = 1.0  # opaque red: where the picture is
    titled = decode(panels([solid, image], ["a red square", "the cube"], cols=2))
    plain = decode(panels([solid, image], cols=2))
    assert titled.shape[0] > plain.shape[0]  # the titles take their own rows
    red = np.all(titled[..., :3] == (255, 0, 0), axis=-1)
    top_of_red = np.flatnonzero(red.any(axis=1))[0]
    ink = _ink_rows(titled[:top_of_red])  # the title: dark text above the red square
    assert len(ink) > 3 and (titled[ink][..., :3].min() < 80)
    with pytest.raises(ValueError, match="2 images but 1 titles"):
        panels([solid, image], ["one"])


def test_show_returns_a_picture_jupyter_displays(scene):
    _, _, _, image = scene
    one = show(image, "the cube")
    assert isinstance(one, Picture) and one._repr_png_().startswith(PNG)
    assert one.image is not None and np.array_equal(one.image, image)
    two = show([image, image], ["left", "right"], background=(0, 0, 0))
    assert two.image.shape == (90, 120, 4)
    assert decode(two.png)[0, 0, :3].tolist() == [0, 0, 0]  # the background asked for


def test_plot_renders_annotates_and_saves(tmp_path):
    pic = plot(POST_VTK, cmap="magma", size=(48, 32), title="post", method="reference")
    assert isinstance(pic, Picture) and pic._repr_png_().startswith(PNG)
    assert pic.image.shape == (32, 48, 4) and pic.image.dtype == np.float32
    assert decode(pic.png).shape[1] > 48
    pic.save(tmp_path / "post.png")
    assert (tmp_path / "post.png").read_bytes() == pic.png
    plain = plot(POST_VTK, size=(48, 32), method="reference", annotations=False)
    assert decode(plain.png).shape == (32, 48, 4)


def test_import_tetvr_loads_no_matplotlib_pyvista_or_vtk():
    code = ("import sys, tetvr; bad = {'matplotlib', 'pyvista', 'vtk', 'vtkmodules'} & set(sys.modules); "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True)


# ---- what users hold ----

def test_from_meshio_matches_read():
    import meshio

    m = meshio.read(POST_VTK)
    a, b = tetvr.read(POST_VTK), tetvr.TetMesh.from_meshio(m)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.tets, b.tets)
    assert np.array_equal(a.scalars, b.scalars) and a.scalar_name == b.scalar_name
    assert as_mesh(m).n_tets == a.n_tets
    with pytest.raises(KeyError, match="no field named 'nope'"):
        tetvr.TetMesh.from_meshio(m, "nope")


def test_from_meshio_cell_field_and_hexahedra():
    import meshio

    pts = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=float)
    hexa = [[0, 1, 3, 2, 4, 5, 7, 6]]
    with pytest.warns(UserWarning, match="hexahedron"):
        mesh = tetvr.TetMesh.from_meshio(meshio.Mesh(pts, [("hexahedron", hexa)], cell_data={"p": [[7.0]]}))
    assert mesh.report.scalar_source == "cell" and np.allclose(mesh.scalars, 7.0)
    assert mesh.n_tets >= 5


def test_vtk_grids_in_and_pyvista_out():
    pytest.importorskip("vtkmodules")
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonDataModel import vtkImageData

    img = vtkImageData()
    img.SetDimensions(3, 3, 3)
    arr = numpy_to_vtk(np.arange(27.0), deep=True)
    arr.SetName("v")
    img.GetPointData().AddArray(arr)
    mesh = as_mesh(img)  # a vtk data set, tetrahedralised by VTK
    assert mesh.scalar_name == "v" and mesh.bounds.tolist() == [[0, 0, 0], [2, 2, 2]]
    assert mesh.scalar_range == (0.0, 26.0)
    pv = pytest.importorskip("pyvista")
    grid = tetvr.read(POST_VTK).to_pyvista()
    assert isinstance(grid, pv.UnstructuredGrid) and grid.n_cells == tetvr.read(POST_VTK).n_tets
    again = as_mesh(grid)
    assert np.array_equal(again.tets, tetvr.read(POST_VTK).tets)


def test_as_mesh_refuses_what_it_cannot_use():
    with pytest.raises(TypeError, match="cannot make a tetrahedral mesh from a builtins.dict"):
        as_mesh({"points": []})
    with pytest.raises(ValueError, match="carries the field 'scalars', not 'T'"):
        as_mesh(synthetic.single_tet(), "T")


# ---- the command line ----

def test_cli_renders_a_mesh_file_with_a_legend(tmp_path, capsys):
    out = tmp_path / "o.png"
    argv = ["render", str(POST_VTK), "--scalars", "Pressure", "--cmap", "magma", "--size", "320x240",
            "--background", "white", "-o", str(out), "--reference", "--npy", str(tmp_path / "o")]
    assert main(argv) == 0
    assert "annotated PNG" in capsys.readouterr().out
    got = decode(out.read_bytes())
    assert got.shape[:2] == (240, 320)  # the size asked for, the legend inside it
    image = np.load(tmp_path / "o.npy")  # the exact float image, as rendered: left of the legend
    assert image.shape[0] == 240 and 160 <= image.shape[1] < 320 and image[..., 3].max() > 0.2
    assert main(argv[:-3] + ["--reference", "--no-annotations"]) == 0
    assert decode(out.read_bytes()).shape == (240, 320, 4)


def test_cli_without_matplotlib_writes_the_plain_picture(tmp_path, capsys, monkeypatch):
    def missing():
        raise ImportError("no matplotlib")

    monkeypatch.setattr("tetvr.apps.annotate._matplotlib", missing)
    out = tmp_path / "o.png"
    assert main(["render", str(POST_VTK), "--size", "32x24", "-o", str(out), "--reference"]) == 0
    assert "no legend: matplotlib is not installed" in capsys.readouterr().err
    assert decode(out.read_bytes()).shape == (24, 32, 4)


@pytest.mark.parametrize("argv,words", [
    (["render", str(POST_VTK), "--size", "64"], "expected WIDTHxHEIGHT"),
    (["render", str(POST_VTK), "--background", "1,2,3"], "components in [0, 1]"),
    (["render", str(POST_VTK), "--cmap", "no-such-map", "--reference", "--size", "8x8"], "unknown colour map"),
], ids=["size", "background", "cmap"])
def test_cli_render_options_fail_in_one_line(tmp_path, capsys, argv, words):
    assert main(argv + ["-o", str(tmp_path / "o.png")]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1].startswith("tetvr: error: ") and words in err
    assert not (tmp_path / "o.png").exists()


def test_cli_scene_refuses_mesh_options(tmp_path, capsys):
    scene = tmp_path / "s.json"
    scene.write_text('{"mesh": "%s", "size": [8, 6]}' % POST_VTK)
    assert main(["render", str(scene), "--scalars", "Pressure", "-o", str(tmp_path / "o.png")]) == EXIT_USAGE
    assert "--scalars is for a mesh file" in capsys.readouterr().err


def test_cli_version_and_info(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"tetvr {tetvr.__version__}"
    assert main(["info", str(POST_VTK)]) == 0
    out = capsys.readouterr().out
    assert "'Pressure' (point)" in out and "median" in out and "99%" in out and "tetrahedra" in out


def test_info_percentiles_of_a_field_that_is_mostly_one_value():
    from tetvr.apps.cli.commands import _stats_line

    line = _stats_line(np.r_[np.zeros(90), np.arange(1.0, 11.0)])  # a CT that is mostly air
    assert "1% 0, median 0, 99% 9.5" in line, line  # the median is not widened to the maximum


def test_cli_info_on_a_volume(capsys):
    from tetvr.scene.examples import bundled

    assert main(["info", str(bundled("carotid.vtk"))]) == 0
    out = capsys.readouterr().out
    assert "a volume of" in out and "voxels" in out and "median" in out


@pytest.mark.parametrize("lo,hi,want", [
    (0.0, 1.0, ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"]),
    (0.1, 0.8, ["0.15", "0.30", "0.45", "0.60", "0.75"]),  # the step needs two decimals
    (1e5, 3e5, ["1.2e+05", "1.6e+05", "2.0e+05", "2.4e+05", "2.8e+05"]),
    (-0.5, 0.5, ["-0.4", "-0.2", "0.0", "0.2", "0.4"]),
])
def test_legend_tick_labels_are_in_data_units_and_evenly_spaced(lo, hi, want):
    from tetvr.apps.legend import _tick_labels

    ticks, labels = _tick_labels(lo, hi)
    assert labels == want
    np.testing.assert_allclose([float(v) for v in labels], ticks, rtol=1e-9, atol=1e-12)


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="needs named pipes")
@pytest.mark.parametrize("command,name", [("render", "pipe.vtu"), ("render", "pipe.txt"), ("info", "pipe.vtk")])
def test_cli_never_opens_a_fifo_to_sniff_it(tmp_path, capsys, command, name):
    import os

    from .badinput._util import deadline

    fifo = tmp_path / name
    os.mkfifo(fifo)
    argv = [command, str(fifo)] + (["-o", str(tmp_path / "o.png")] if command == "render" else [])
    with deadline(20, f"tetvr {command} of a FIFO"):
        assert main(argv) == EXIT_USAGE
    assert "FIFO" in capsys.readouterr().err

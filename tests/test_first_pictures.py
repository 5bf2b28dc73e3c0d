"""What a new user sees in the first PNG: the field rendered when none is named (not a
constant one), a warning when the picture is nearly blank, the file at the size asked for,
a legend that says which colours are clipped and what a vector field's colour means, an
outline that stays in the frame, and a camera without a clipping range that sees a mesh
wherever it is.

Renders here use the CPU reference (``method="reference"``, ``--reference``) unless marked
``gl``.
"""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TransferFunction
from tetvr.apps.cli import main
from tetvr.core.camera import reset_clipping_range
from tetvr.mesh import synthetic
from tetvr.render import default_transfer_function

meshio = pytest.importorskip("meshio")
mpimg = pytest.importorskip("matplotlib.image")

WHITE = (255, 255, 255)


def decode(data: bytes) -> np.ndarray:
    return np.round(mpimg.imread(io.BytesIO(data), format="png") * 255).astype(np.uint8)


def cylinder(diameter: float = 0.02, length: float = 0.02, n: int = 6) -> tetvr.TetMesh:
    """A cylinder (a cube's cross-sections mapped onto discs), a field rising across it."""
    c = synthetic.cube(n, rotate=False)
    p = c.points - c.points.mean(axis=0)
    p = p / np.ptp(p, axis=0)  # [-0.5, 0.5]^3
    xy = p[:, :2]
    norm = np.linalg.norm(xy, axis=1)
    scale = np.where(norm > 0, np.abs(xy).max(axis=1) / np.where(norm > 0, norm, 1.0), 0.0)
    p[:, :2] = xy * scale[:, None] * diameter
    p[:, 2] *= length
    return tetvr.TetMesh.from_arrays(p, c.tets, p[:, 0] / diameter + 0.5, scalar_name="T")


def write_fields(path, **fields) -> None:
    mesh = synthetic.cube(3, rotate=False)
    meshio.write(path, meshio.Mesh(mesh.points, [("tetra", mesh.tets)],
                                   point_data={k: f(mesh.points) for k, f in fields.items()}))


def ones(p):
    return np.ones(len(p))


def ramp(p):
    return 1.0 + 3.0 * p[:, 0]


def figure_texts(fig) -> list[str]:
    from matplotlib.text import Text

    return [t.get_text() for t in fig.findobj(Text) if t.get_text()]


# ---- the field rendered when none is named ----

def test_the_default_field_is_the_first_that_varies(tmp_path):
    write_fields(tmp_path / "m.vtu", Ones=ones, T=ramp)
    with pytest.warns(UserWarning, match=r"field 'Ones' \(1.0 everywhere\) is constant; rendering 'T', the first "
                                         r"field that varies"):
        mesh = tetvr.read(tmp_path / "m.vtu")
    assert mesh.scalar_name == "T" and mesh.scalar_range[1] > mesh.scalar_range[0]
    m = meshio.read(tmp_path / "m.vtu")  # a meshio.Mesh in memory takes the same rule
    with pytest.warns(UserWarning, match="rendering 'T'"):
        assert tetvr.TetMesh.from_meshio(m).scalar_name == "T"
    write_fields(tmp_path / "all.vtu", Ones=ones, Twos=lambda p: 2.0 * ones(p))
    with pytest.warns(UserWarning, match=r"every field is constant; rendering the first, 'Ones' \(1.0 everywhere\)"):
        assert tetvr.read(tmp_path / "all.vtu").scalar_name == "Ones"
    write_fields(tmp_path / "fine.vtu", T=ramp, Ones=ones)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the first field varies: chosen without a word
        assert tetvr.read(tmp_path / "fine.vtu").scalar_name == "T"


def test_cli_says_which_field_it_rendered(tmp_path, capsys):
    write_fields(tmp_path / "m.vtu", Ones=ones, T=ramp)
    out = tmp_path / "m.png"
    assert main(["render", str(tmp_path / "m.vtu"), "--reference", "--size", "160x120", "-o", str(out)]) == 0
    said = capsys.readouterr()
    assert "field 'T'" in said.out
    assert "tetvr: warning: m.vtu: field 'Ones' (1.0 everywhere) is constant; rendering 'T'" in said.err


def test_a_constant_field_named_on_purpose_is_warned_about_and_its_legend_says_so(tmp_path):
    from tetvr.apps.annotate import _figure, mesh_labels

    write_fields(tmp_path / "m.vtu", Ones=ones, T=ramp)
    with pytest.warns(UserWarning, match=r"field 'Ones' is constant \(1.0 everywhere\): the picture shows the mesh's "
                                         "shape in one colour"):
        mesh = tetvr.read(tmp_path / "m.vtu", "Ones")
    tf = default_transfer_function(mesh)
    assert tf.domain[1] > tf.domain[0]  # the renderer's range is widened ...
    image = tetvr.render(mesh, tf=tf, size=(40, 30), method="reference")
    fig = _figure(image, tf, units=None, title=None, camera=None, size=None, legend=True, triad=False,
                  outline=False, background=(1, 1, 1), **mesh_labels(mesh))
    texts = figure_texts(fig)
    assert "constant 1.0" in texts  # ... but the legend invents no range
    assert not any(t.startswith("1.00") for t in texts), texts


# ---- a nearly blank picture ----

def test_a_nearly_blank_picture_is_warned_about():
    """A 2 cm cylinder with a unit distance of 1 (a metre): the old rule bounded the
    opacity by the most opaque value across the whole diagonal (0.077 here, above its 0.05)
    and said nothing of a picture whose most opaque pixel is 0.017."""
    mesh = cylinder()
    tf = default_transfer_function(mesh, unit_distance=1.0)
    with pytest.warns(UserWarning, match=r"nearly blank: its most opaque pixel reaches 0.01[5-9] opacity.*unit_distance"):
        image = tetvr.render(mesh, tf=tf, size=(32, 32), method="reference")
    assert image[..., 3].max() < 0.02
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the default unit distance (the mesh's own): no warning
        assert tetvr.render(mesh, size=(32, 32), method="reference")[..., 3].max() > 0.5


# ---- the size asked for is the size of the file ----

@pytest.mark.parametrize("extra", [[], ["--title", "A title", "--units", "Pa"]], ids=["plain", "title"])
def test_cli_size_is_the_size_of_the_file(tmp_path, extra):
    out, npy = tmp_path / "o.png", tmp_path / "o.npy"
    mesh = str(tetvr.demo_scene_path().parent / "post.vtk")
    argv = ["render", mesh, "--reference", "--size", "240x180", "-o", str(out), "--npy", str(npy)] + extra
    assert main(argv) == 0
    picture, image = decode(out.read_bytes()), np.load(npy)
    assert picture.shape[:2] == (180, 240)  # the legend (and title) inside the size asked for
    h, w = image.shape[:2]
    assert w < 240 and (h < 180) == bool(extra)
    assert np.any(picture[:, w:, :3] < 128)  # the legend's dark ink is right of the render
    assert main(argv + ["--no-annotations"]) == 0
    assert decode(out.read_bytes()).shape[:2] == np.load(npy).shape[:2] == (180, 240)


def test_annotate_lays_out_inside_a_size_or_refuses_a_render_that_does_not_fit():
    from tetvr.apps.annotate import annotate, render_area

    mesh = synthetic.cube(2, synthetic.linear_field((1.0, 0.0, 0.0), 0.5))
    tf = default_transfer_function(mesh)
    w, h = render_area((300, 200), tf, field="T", title="t")
    assert w < 300 and h < 200
    image = np.zeros((h, w, 4), np.float32)
    assert decode(annotate(image, tf, field="T", title="t", size=(300, 200))).shape[:2] == (200, 300)
    with pytest.raises(ValueError, match=rf"image is 300x200 pixels, but a 300x200 picture with this legend and "
                                         rf"title holds a {w}x{h} render"):
        annotate(np.zeros((200, 300, 4), np.float32), tf, field="T", title="t", size=(300, 200))
    assert render_area((60, 40), tf, field="T") == (60, 40)  # too small for a legend: none


# ---- the legend says what is clipped, and what a vector's colour is ----

def _legend_colour_count(png: bytes, rgb, x0: int) -> int:
    legend = decode(png)[:, x0:, :3].astype(int)
    return int((np.abs(legend - np.round(np.asarray(rgb) * 255)).sum(axis=-1) <= 6).sum())


def test_legend_marks_the_ends_the_data_runs_past_and_labels_them():
    from tetvr.apps.annotate import _figure, annotate

    mesh = synthetic.cube(2, synthetic.linear_field((1.0, 0.0, 0.0), 0.5))
    tf = TransferFunction.preset("viridis", (0.5412, 2.3317), mesh=mesh)
    image = np.zeros((200, 160, 4), np.float32)
    kw = dict(field="Density", triad=False, outline=False)
    fig = _figure(image, tf, units=None, title=None, camera=None, bounds=None, data_range=(0.19, 4.98), size=None,
                  legend=True, background=(1, 1, 1), **kw)
    texts = figure_texts(fig)
    assert "0.54" in texts and "2.33" in texts  # both ends labelled
    lo_rgb, hi_rgb = (tf.evaluate([v])[0][0] for v in tf.domain)
    counts = {}
    for data_range in [(0.6, 2.2), (0.19, 4.98), (0.6, 4.98), (0.19, 2.2)]:
        png = annotate(image, tf, data_range=data_range, background=(1, 1, 1), **kw)
        counts[data_range] = (_legend_colour_count(png, lo_rgb, 160), _legend_colour_count(png, hi_rgb, 160))
    # A triangle in the end colour adds ~40 pixels of it at that end, and none at the other.
    inside = counts[(0.6, 2.2)]
    assert counts[(0.19, 4.98)][0] > inside[0] + 20 and counts[(0.19, 4.98)][1] > inside[1] + 20  # "both"
    assert counts[(0.6, 4.98)][1] > inside[1] + 20 and counts[(0.6, 4.98)][0] <= inside[0] + 5  # "max"
    assert counts[(0.19, 2.2)][0] > inside[0] + 20 and counts[(0.19, 2.2)][1] <= inside[1] + 5  # "min"


def test_a_vector_fields_legend_says_it_is_the_magnitude(tmp_path):
    from tetvr.apps.annotate import _figure, mesh_labels

    write_fields(tmp_path / "v.vtu", Velocity=lambda p: np.c_[p[:, 0], 2 * p[:, 1], np.ones(len(p))])
    mesh = tetvr.read(tmp_path / "v.vtu")
    assert mesh.report.scalar_of == "magnitude" and mesh_labels(mesh)["field"] == "|Velocity|"
    assert mesh_labels(tetvr.read(tmp_path / "v.vtu", component=1))["field"] == "Velocity[1]"
    assert mesh_labels(mesh.with_scalars(mesh.scalars, "speed"))["field"] == "speed"  # a new field: no bars
    tf = default_transfer_function(mesh)
    fig = _figure(np.zeros((60, 80, 4), np.float32), tf, units="m/s", title=None, camera=None, size=None,
                  legend=True, triad=False, outline=False, background=(1, 1, 1), **mesh_labels(mesh))
    assert "|Velocity| [m/s]" in figure_texts(fig)


# ---- the outline stays in the frame ----

def _corners_px(camera: Camera, bounds, size) -> np.ndarray:
    from tetvr.apps.annotate import _project_px

    lo, hi = np.asarray(bounds)
    corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    return _project_px(camera, corners, size)[0]


@pytest.mark.parametrize("size", [(160, 120), (90, 160)])
def test_framing_keeps_the_outline_in_the_picture(size):
    from tetvr.apps.annotate import frame

    mesh = synthetic.cube(3)  # turned about two axes: its box reaches far past its silhouette
    px = _corners_px(frame(mesh, size), mesh.bounds, size)
    assert px.min() >= 0 and px[:, 0].max() <= size[0] and px[:, 1].max() <= size[1]
    loose = _corners_px(frame(mesh, size, outline=False), mesh.bounds, size)
    assert loose.min() < 0 or loose[:, 0].max() > size[0] or loose[:, 1].max() > size[1]  # the old framing


def _border_is_background(png: bytes, width: int) -> bool:
    rgb = decode(png)[..., :3][:, :width]
    border = np.concatenate([rgb[0], rgb[-1], rgb[:, 0], rgb[:, -1]])
    return bool(np.all(border == WHITE))


def test_cli_pictures_keep_the_outline_in_the_frame(tmp_path):
    """The demo scene (a fitted camera, zoomed) and a mesh file whose box is larger than its
    silhouette: nothing drawn crosses the render's edges."""
    write_fields(tmp_path / "m.vtu", T=ramp)
    turned = synthetic.cube(3)
    meshio.write(tmp_path / "turned.vtu", meshio.Mesh(turned.points, [("tetra", turned.tets)],
                                                      point_data={"T": turned.points[:, 0]}))
    for source in (str(tetvr.demo_scene_path()), str(tmp_path / "turned.vtu")):
        out, npy = tmp_path / "o.png", tmp_path / "o.npy"
        assert main(["render", source, "--reference", "--size", "240x180", "-o", str(out), "--npy", str(npy)]) == 0
        assert _border_is_background(out.read_bytes(), np.load(npy).shape[1]), source


# ---- a camera without a clipping range ----

def test_a_camera_without_a_clipping_range_sees_a_far_mesh():
    from tetvr.core.camera import resolve_clipping_range

    mesh = synthetic.cube(2, synthetic.linear_field((1.0, 0.0, 0.0), 0.5))
    cam = Camera(position=(3000.0, 0.0, 0.0), focal_point=(0.0, 0.0, 0.0), view_up=(0, 0, 1), view_angle=0.05)
    assert cam.clipping_range is None and Camera.from_dict(cam.to_dict()) == cam
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        image = tetvr.render(mesh, camera=cam, size=(16, 16), method="reference")
    assert image[..., 3].max() > 0.5
    want = tetvr.render(mesh, camera=reset_clipping_range(cam, mesh.bounds), size=(16, 16), method="reference")
    np.testing.assert_array_equal(image, want)  # None is VTK's range from the data
    given = Camera(position=(3000.0, 0.0, 0.0), view_up=(0, 0, 1), view_angle=0.05, clipping_range=(0.01, 1000))
    assert resolve_clipping_range(given, mesh.bounds) is given  # an explicit range is kept ...
    with pytest.warns(UserWarning, match=r"clipping_range \(0.01, 1000\) clips all the data away"):
        blank = tetvr.render(mesh, camera=given, size=(16, 16), method="reference")
    assert blank.max() == 0.0  # ... and clips as before


def test_the_readers_of_a_clipping_range_resolve_none():
    from tetvr.mesh.meshing import pixel_footprint
    from tetvr.order.cull import outside_view
    from tetvr.order.precision import check_view_precision, float32_clipping_range

    mesh = synthetic.cube(2)
    cam = Camera(position=(0.0, 0.0, 3000.0), view_angle=0.05)
    resolved = reset_clipping_range(cam, mesh.bounds)
    assert np.array_equal(outside_view(mesh, cam), outside_view(mesh, resolved))
    assert not outside_view(mesh, cam).any()
    check_view_precision(mesh, cam, (64, 64))
    assert float32_clipping_range(mesh, cam).clipping_range == resolved.clipping_range
    assert pixel_footprint(cam, (64, 64), mesh.points) == pixel_footprint(resolved, (64, 64), mesh.points)
    with pytest.raises(ValueError, match="clipping_range is None .* resolve it first"):
        cam.projection_matrix(1.0)


@pytest.mark.gl
def test_gpu_renderer_resolves_a_missing_clipping_range():
    from tetvr.gl.renderer import Renderer

    mesh = synthetic.cube(2, synthetic.linear_field((1.0, 0.0, 0.0), 0.5))
    cam = Camera(position=(3000.0, 0.0, 0.0), view_up=(0, 0, 1), view_angle=0.05)
    tf = default_transfer_function(mesh)
    with Renderer() as r:
        got = r.render(mesh, cam, tf, size=(24, 24))
        want = r.render(mesh, reset_clipping_range(cam, mesh.bounds), tf, size=(24, 24))
    assert got[..., 3].max() > 0.5
    np.testing.assert_array_equal(got, want)


def test_the_triad_takes_the_emptiest_corner():
    from tetvr.apps.annotate import _triad_length, _triad_origin

    size = (200, 150)
    r = 1.35 * _triad_length(size) + 4
    lower_left, lower_right = (r, 150 - r), (200 - r, 150 - r)
    alpha = np.zeros((150, 200), np.float32)
    assert _triad_origin(alpha, [], size) == lower_left  # as ParaView puts it
    alpha[:50] = 0.8  # data along the top ...
    alpha[100:, :60] = 0.8  # ... and in the lower left: the triad moves to the lower right
    assert _triad_origin(alpha, [], size) == lower_right
    edge = np.array([[140.0, 149.0], [199.0, 90.0]])  # an outline's edge across the lower right
    alpha[100:, :60] = 0.005  # a faint haze in the lower left: no corner is clearly emptier
    assert _triad_origin(alpha, [edge], size) == lower_left
    assert _triad_origin(alpha, [], size) == lower_right

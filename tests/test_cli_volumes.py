"""CT/MR volumes by the same defaults as meshes, and the ``render`` command's tuning options.

A small synthetic volume (a blob in a transparent background, anisotropic spacing, off the
origin) is written by SimpleITK as NRRD. ``tetvr render vol.nhdr`` must give the picture
``tetvr.render(volume)`` gives, which must match the CPU reference (the bars of
tests/test_raycast.py: max error 0.01, at most 1 % of the covered pixels beyond 1/255).
Each option must change the picture, and exactly as the Python call it documents does
(the same GPU code on the same inputs: equal to 1e-6). Bad values end in one error line
that names the value, with status 2.
"""

from __future__ import annotations

import dataclasses
import io
import json
import shutil
import types
from pathlib import Path

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TransferFunction
from tetvr.apps.animate import azimuth
from tetvr.apps.cli import EXIT_USAGE, main
from tetvr.core.camera import reset_clipping_range
from tetvr.core.image import png_bytes
from tetvr.mesh import synthetic
from tetvr.optics.transfer import field_range, robust_range
from tetvr.reference.volume import RaycastSettings
from tetvr.render import default_transfer_function

from .conftest import SHARED, save_failure

pytestmark = pytest.mark.gl

ROOT = Path(__file__).resolve().parents[1]
S = 32  # square pictures: the CLI's fit for W/H = 1 is Camera.fit's


def _blob() -> np.ndarray:
    z, y, x = np.meshgrid(np.linspace(-1, 1, 8), np.linspace(-1, 1, 10), np.linspace(-1, 1, 12), indexing="ij")
    return (1000.0 * np.exp(-3.0 * ((x - 0.2) ** 2 + y**2 + 2 * z**2)) + 40.0 * (x + 1)).astype(np.float32)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    sitk = pytest.importorskip("SimpleITK")
    meshio = pytest.importorskip("meshio")
    d = tmp_path_factory.mktemp("volumes")
    img = sitk.GetImageFromArray(_blob())  # (nz, ny, nx), as Volume.data
    img.SetSpacing((1.5, 1.0, 2.0))
    img.SetOrigin((5.0, -3.0, 1.0))
    sitk.WriteImage(img, str(d / "vol.nhdr"))
    vol = tetvr.read_volume(d / "vol.nhdr")
    # A small mesh inside the volume's box, for the fusion.
    cube = synthetic.cube(2, rotate=False)
    lo, hi = vol.bounds
    pts = (lo + hi) / 2 + cube.points * (hi - lo) * 0.4
    meshio.write_points_cells(str(d / "mesh.vtu"), pts, [("tetra", cube.tets)],
                              point_data={"T": pts[:, 0] + 0.5 * pts[:, 2]})
    return types.SimpleNamespace(dir=d, vol=d / "vol.nhdr", mesh=d / "mesh.vtu")


@pytest.fixture(scope="module")
def volume(files):
    return tetvr.read_volume(files.vol)


def _cli(tmp_path: Path, path: Path, *options: str, size: int = S) -> tuple[np.ndarray, np.ndarray]:
    """``tetvr render`` to a plain PNG and the float image: (image, decoded PNG)."""
    png, npy = tmp_path / "out.png", tmp_path / "out.npy"
    argv = ["render", str(path), "-o", str(png), "--npy", str(npy), "--size", f"{size}x{size}", "--no-annotations",
            *options]
    assert main(argv) == 0, argv
    import matplotlib.image as mpimg

    return np.load(npy), np.round(mpimg.imread(png, format="png") * 255).astype(np.int16)


def _decoded(png: bytes) -> np.ndarray:
    import matplotlib.image as mpimg

    return np.round(mpimg.imread(io.BytesIO(png), format="png") * 255).astype(np.int16)


def _same(got: np.ndarray, want: np.ndarray, name: str) -> None:
    if not np.abs(got - want).max() <= 1e-6:
        where = save_failure(f"cli_{name}", got, want)
        pytest.fail(f"{name}: the CLI's picture differs from Python's by {np.abs(got - want).max():.3g}; see {where}")


# ---- the default rule for volumes ----

def test_a_volume_takes_the_meshes_default_rule(volume):
    tf = TransferFunction.preset("viridis", mesh=volume)
    assert tf == TransferFunction.preset("viridis", volume) == default_transfer_function(volume)
    # The range: the 1st..99.5th percentile of the voxels, each weighing the same (the
    # partition-based path agrees with the weighted sort of the meshes' rule).
    assert field_range(volume) == pytest.approx(robust_range(volume.data, np.ones(volume.data.size)), rel=1e-12)
    assert tf.domain == field_range(volume) and tf.domain[1] < volume.scalar_range[1]
    assert tf.opacity[0][1] == 0.0  # the background at the bottom of the range is transparent
    assert tf.unit_distance == pytest.approx(np.linalg.norm(np.subtract(*volume.bounds)) / 20)


def test_render_of_a_volume_matches_the_reference(volume):
    got = tetvr.render(volume, size=(S, S))
    want = tetvr.render(volume, size=(S, S), method="reference",
                        settings=RaycastSettings(termination_tolerance=0.0))
    d = np.abs(got.astype(np.float64) - want).max(axis=-1)
    covered = max(int(np.count_nonzero(want[..., 3] > 1e-3)), 1)
    assert want[..., 3].max() > 0.3 and want[0, 0, 3] < 1e-3  # the blob, in a transparent box
    if d.max() > 0.01 or np.count_nonzero(d > 1 / 255) > 0.01 * covered:
        where = save_failure("render_volume_defaults", got, want)
        pytest.fail(f"max error {d.max():.4f}, {np.count_nonzero(d > 1 / 255)} of {covered} pixels beyond 1/255; "
                    f"see {where}")


def test_render_of_a_volume_refuses_mesh_settings_and_options(volume):
    with pytest.raises(TypeError, match="settings must be a RaycastSettings or None, got RenderSettings"):
        tetvr.render(volume, settings=tetvr.RenderSettings())
    with pytest.raises(TypeError, match="a volume takes no clip"):
        tetvr.render(volume, clip=tetvr.Clip.box((0, 0, 0), (1, 1, 1)))


def test_plot_of_a_volume_is_its_render(volume):
    pic = tetvr.plot(volume, size=(S, S), annotations=False)
    np.testing.assert_array_equal(pic.image, tetvr.render(volume, size=(S, S)))
    with pytest.raises(ValueError, match="not 'density'"):
        tetvr.plot(volume, "density")


# ---- the command line ----

def test_cli_renders_a_volume_file_as_python_does(files, volume, tmp_path):
    image, png = _cli(tmp_path, files.vol)
    want = tetvr.render(volume, size=(S, S))
    _same(image, want, "volume")
    assert png.std() > 5  # not blank
    np.testing.assert_array_equal(png, _decoded(png_bytes(want, background=(1, 1, 1))))
    annotated = tmp_path / "annotated.png"
    assert main(["render", str(files.vol), "-o", str(annotated), "--size", "64x48"]) == 0
    assert annotated.stat().st_size > 1000


def _fit(volume, **kw):
    return Camera.fit(volume, **kw)


def _turned(camera, bounds, az=0.0, el=0.0):
    if az:
        camera = azimuth(camera, az)
    if el:
        camera = azimuth(camera, -el, axis=camera.basis()[0])
    return reset_clipping_range(camera, bounds)


#: option -> (camera, transfer function) it stands for, in Python.
OPTIONS = {
    "--azimuth 90": lambda v: (_turned(_fit(v), v.bounds, az=90), None),
    "--elevation 30": lambda v: (_turned(_fit(v), v.bounds, el=30), None),
    "--azimuth -40 --elevation 25": lambda v: (_turned(_fit(v), v.bounds, az=-40, el=25), None),
    "--view +x": lambda v: (_fit(v, direction=(1, 0, 0)), None),
    "--view -y": lambda v: (_fit(v, direction=(0, -1, 0)), None),
    "--view 1,1,-1": lambda v: (_fit(v, direction=(1, 1, -1)), None),
    "--zoom 2": lambda v: (_fit(v, zoom=2.0), None),
    "--parallel": lambda v: (_fit(v, parallel=True), None),
    "--range 300 900": lambda v: (None, default_transfer_function(v, scalar_range=(300, 900))),
    "--unit-distance 2.5": lambda v: (None, default_transfer_function(v, unit_distance=2.5)),
    "--opacity-scale 3": lambda v: (None, TransferFunction(
        color=default_transfer_function(v).color, unit_distance=default_transfer_function(v).unit_distance,
        opacity=tuple((x, min(1.0, 3 * a)) for x, a in default_transfer_function(v).opacity))),
    "--cmap hot": lambda v: (None, default_transfer_function(v, preset="hot")),
}


@pytest.fixture(scope="module")
def default_image(volume):
    return tetvr.render(volume, size=(S, S))


@pytest.mark.parametrize("option", list(OPTIONS))
def test_each_option_changes_the_picture_as_python_does(files, volume, default_image, tmp_path, option):
    camera, tf = OPTIONS[option](volume)
    want = tetvr.render(volume, camera=camera, tf=tf, size=(S, S))
    got, _ = _cli(tmp_path, files.vol, *option.split())
    _same(got, want, option.replace(" ", "_"))
    assert np.abs(got - default_image).max() > 0.02, f"{option} does not change the picture"


def test_elevation_raises_the_camera_and_opacity_scale_thickens(volume, default_image):
    cam = _fit(volume)
    assert _turned(cam, volume.bounds, el=30).position[2] > cam.position[2] + 1
    thick = tetvr.render(volume, tf=OPTIONS["--opacity-scale 3"](volume)[1], size=(S, S))
    assert thick[..., 3].sum() > 1.5 * default_image[..., 3].sum()


def test_background_fills_the_empty_pixels(files, tmp_path):
    image, png = _cli(tmp_path, files.vol, "--background", "#ff8000")
    assert image[0, 0, 3] < 1e-3 and tuple(png[0, 0, :3]) == (255, 128, 0)


def test_clip_box_cuts_a_volume(files, volume, default_image, tmp_path):
    lo, hi = volume.bounds
    box = (tuple(lo), tuple((lo + hi) / 2))
    got, _ = _cli(tmp_path, files.vol, "--clip-box", *(repr(float(v)) for v in (*box[0], *box[1])))
    _same(got, tetvr.render(volume, size=(S, S), settings=RaycastSettings(clip_box=box)), "clip_box")
    assert got[..., 3].sum() < 0.8 * default_image[..., 3].sum()


def test_zoom_narrows_a_scene_camera(tmp_path):
    shutil.copy(ROOT / "meshes" / "post.vtk", tmp_path / "post.vtk")
    cam = {"position": [8, -9, 8.5], "focal_point": [0, 0, 0.5], "view_up": [0, 0, 1], "view_angle": 30}
    (tmp_path / "s.json").write_text(json.dumps({"mesh": "post.vtk", "camera": cam}))
    scene = tetvr.load_scene(tmp_path / "s.json")
    got, _ = _cli(tmp_path, tmp_path / "s.json", "--zoom", "2")
    narrow = dataclasses.replace(scene.camera, view_angle=float(np.degrees(2 * np.arctan(np.tan(np.radians(15)) / 2))))
    _same(got, tetvr.render(scene.mesh, camera=narrow, tf=scene.tf, size=(S, S)), "scene_zoom")


def test_parity_renders_a_paraview_state_as_load_state_does(tmp_path):
    from tetvr.scene.paraview import load_state

    shutil.copy(ROOT / "tests" / "data" / "post_volume.pvsm", tmp_path / "post_volume.pvsm")
    (tmp_path / "post.vtk").symlink_to(ROOT / "meshes" / "post.vtk")
    state = tmp_path / "post_volume.pvsm"
    got, _ = _cli(tmp_path, state, "--parity")
    plain, _ = _cli(tmp_path, state)
    scene = load_state(state, parity=True)
    _same(got, tetvr.render(scene.mesh, camera=scene.camera, tf=scene.tf, size=(S, S), settings=scene.settings),
          "parity")
    assert np.abs(got - plain).max() > 1e-3  # ParaView's picture is not tetvr's exact one


def test_volume_option_renders_the_fusion_as_fuse_does(files, volume, tmp_path):
    mesh = tetvr.read(files.mesh)
    got, png = _cli(tmp_path, files.mesh, "--volume", str(files.vol))
    pts = np.concatenate([mesh.points, volume.corners])
    both = types.SimpleNamespace(points=pts, bounds=np.stack([pts.min(axis=0), pts.max(axis=0)]))
    want = tetvr.fuse(mesh, volume, Camera.fit(both), default_transfer_function(mesh),
                      default_transfer_function(volume, preset="grayscale"), size=(S, S))
    _same(got, want, "fusion")
    alone = tetvr.render(mesh, camera=Camera.fit(both), size=(S, S))
    assert np.abs(got - alone).max() > 0.02 and png.std() > 5  # the volume is in the picture


@pytest.mark.data
def test_the_ct_head_renders_by_the_defaults(tmp_path):
    head = SHARED / "volumes" / "headsq" / "quarter.nhdr"
    if not head.is_file():
        pytest.skip(f"shared data not available: {head}")
    image, png = _cli(tmp_path, head, size=48)
    a = image[..., 3]
    # Air is transparent (not the opaque box of a constant opacity), the head is not.
    assert a[0, 0] < 1e-3 and a[-1, -1] < 1e-3 and a.max() > 0.9
    assert np.count_nonzero(a > 0.98) < 0.3 * np.count_nonzero(a > 0.01)
    assert png.std() > 10


# ---- bad values ----

BAD = [
    (["--range", "5", "1"], "argument --range: expected LO < HI (finite), got 5 1"),
    (["--range", "0", "inf"], "argument --range: expected a finite number, got 'inf'"),
    (["--range", "low", "1"], "argument --range: expected a number, got 'low'"),
    (["--zoom", "0"], "argument --zoom: expected a number above 0, got '0'"),
    (["--zoom", "-2"], "argument --zoom: expected a number above 0, got '-2'"),
    (["--opacity-scale", "nan"], "argument --opacity-scale: expected a finite number, got 'nan'"),
    (["--unit-distance", "0"], "argument --unit-distance: expected a number above 0, got '0'"),
    (["--unit-distance", "1e-320"], "got 1e-320"),
    (["--azimuth", "ninety"], "argument --azimuth: expected a number, got 'ninety'"),
    (["--elevation", "inf"], "argument --elevation: expected a finite number, got 'inf'"),
    (["--view", "sideways"], "argument --view: expected one of +x, -x, +y, -y, +z, -z or DX,DY,DZ"),
    (["--view", "0,0,0"], "got '0,0,0'"),
    (["--view", "1,2"], "got '1,2'"),
    (["--parity"], "--parity is for a ParaView state (.pvsm)"),
    (["--scalars", "T"], "--scalars is for a mesh"),
    (["--clip-plane", "0", "0", "0", "1", "0", "0"], "--clip-plane is for a mesh"),
    (["--volume", "{vol}"], "--volume fuses a volume with one mesh file"),
]


@pytest.mark.parametrize("options,message", BAD, ids=[" ".join(o) for o, _ in BAD])
def test_bad_values_are_named_in_one_error_line(files, tmp_path, capsys, options, message):
    out = tmp_path / "x.png"
    argv = ["render", str(files.vol), "-o", str(out), *[o.format(vol=files.vol) for o in options]]
    assert main(argv) == EXIT_USAGE
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("tetvr: error: ")]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert message in lines[0], lines[0]
    assert not out.exists()


@pytest.mark.parametrize("options,message", [
    (["--range", "0", "1"], "--range is for a mesh or volume file; a scene sets it in its JSON"),
    (["--volume", "{vol}"], "--volume fuses a volume with one mesh file"),
])
def test_scene_options_are_refused_by_name(files, tmp_path, capsys, options, message):
    shutil.copy(ROOT / "meshes" / "post.vtk", tmp_path / "post.vtk")
    (tmp_path / "s.json").write_text(json.dumps({"mesh": "post.vtk"}))
    argv = ["render", str(tmp_path / "s.json"), "-o", str(tmp_path / "x.png"),
            *[o.format(vol=files.vol) for o in options]]
    assert main(argv) == EXIT_USAGE
    assert message in capsys.readouterr().err


def test_surface_is_refused_with_a_fused_volume(files, tmp_path, capsys):
    argv = ["render", str(files.mesh), "--volume", str(files.vol), "--surface", "s.stl", "-o", str(tmp_path / "x.png")]
    assert main(argv) == EXIT_USAGE
    assert "--surface is not available with --volume" in capsys.readouterr().err

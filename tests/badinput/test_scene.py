"""Bad scene JSON: a ValueError naming the key and the value (KeyError for a missing
field, FileNotFoundError for a missing file), and the command line turns each into
``tetvr: error: ...`` with exit status 2, never a traceback."""

from __future__ import annotations

import json
import shutil

import pytest

from tetvr.apps.cli import main
from tetvr.scene.load import load_scene

from ._util import POST_VTK

BASE = {"mesh": "post.vtk", "size": [8, 8]}

# (id, scene, exception, message regex)
SCENE_BAD = [
    ("unknown-key", {**BASE, "colour": 1}, ValueError, r"unknown scene keys \['colour'\]"),
    ("mesh-key-missing", {"size": [8, 8]}, ValueError, "no 'mesh' key"),
    ("mesh-file-missing", {**BASE, "mesh": "nope.vtk"}, FileNotFoundError, "nope.vtk"),
    ("mesh-null", {**BASE, "mesh": None}, ValueError, "'mesh' must be the path of a mesh file .* got None"),
    ("mesh-number", {**BASE, "mesh": 5}, ValueError, "'mesh' must be the path .* got 5"),
    ("mesh-empty-string", {**BASE, "mesh": ""}, ValueError, "'mesh' must be the path"),
    ("size-word", {**BASE, "size": "big"}, ValueError, r"'size' must be \[width, height\].* got 'big'"),
    ("size-three", {**BASE, "size": [1, 2, 3]}, ValueError, r"'size' .* got \[1, 2, 3\]"),
    ("size-fraction", {**BASE, "size": [8.5, 8]}, ValueError, r"'size' .* got \[8\.5, 8\]"),
    ("size-zero", {**BASE, "size": [0, 8]}, ValueError, r"'size' .* got \[0, 8\]"),
    ("size-negative", {**BASE, "size": [-8, 8]}, ValueError, "'size' .* two positive integers"),
    ("size-number", {**BASE, "size": 8}, ValueError, "'size' .* got 8"),
    ("size-null", {**BASE, "size": None}, ValueError, "'size' .* got None"),
    ("size-bools", {**BASE, "size": [True, True]}, ValueError, r"'size' .* got \[True, True\]"),
    ("size-strings", {**BASE, "size": ["8", "8"]}, ValueError, "'size' .* got \\['8', '8'\\]"),
    ("background-word", {**BASE, "background": "white"}, ValueError, r"'background' must be \[r, g, b\].* got 'white'"),
    ("background-two", {**BASE, "background": [1, 1]}, ValueError, "'background' .* got \\[1, 1\\]"),
    ("background-above-one", {**BASE, "background": [2, 1, 1]}, ValueError, r"'background' .* in \[0, 1\]"),
    ("scalars-missing", {**BASE, "scalars": "Temp"}, KeyError, r"no field named 'Temp'.*point fields: \['Pressure'\]"),
    ("scalars-number", {**BASE, "scalars": 3}, ValueError, "'scalars' must be a field name or null, got 3"),
    ("component-string", {**BASE, "component": "x"}, ValueError, "'component' must be an integer or null, got 'x'"),
    ("component-of-scalar-field", {**BASE, "component": 5}, ValueError, "'Pressure' is a scalar field; component 5"),
    ("tf-string", {**BASE, "transfer_function": "viridis"}, ValueError, "transfer_function must be an object"),
    ("tf-preset-unknown", {**BASE, "transfer_function": {"preset": "no-such-map"}}, ValueError,
     "unknown colour map 'no-such-map'"),
    ("tf-preset-typo", {**BASE, "transfer_function": {"preset": "viridis", "opactiy": 1}}, ValueError,
     r"unknown transfer_function keys \['opactiy'\]"),
    ("tf-range-word", {**BASE, "transfer_function": {"preset": "viridis", "range": "auto"}}, ValueError,
     r"'range' must be \[lo, hi\] or null, got 'auto'"),
    ("tf-range-one-value", {**BASE, "transfer_function": {"preset": "viridis", "range": [1]}}, ValueError,
     r"'range' must be \[lo, hi\]"),
    ("tf-range-inverted", {**BASE, "transfer_function": {"preset": "viridis", "range": [5, 1]}}, ValueError,
     r"lo < hi, got \(5, 1\)"),
    ("tf-opacity-word", {**BASE, "transfer_function": {"preset": "viridis", "opacity": "half"}}, ValueError,
     "opacity must be a number or"),
    ("tf-unit-distance-zero", {**BASE, "transfer_function": {"preset": "viridis", "unit_distance": 0}}, ValueError,
     "unit_distance must be a positive finite number, got 0"),
    ("tf-explicit-missing-opacity", {**BASE, "transfer_function": {"color": [[0, 1, 1, 1]]}}, ValueError,
     r"missing keys \['opacity'\]"),
    ("camera-string", {**BASE, "camera": "front"}, ValueError, "camera must be an object, got 'front'"),
    ("camera-fit-string", {**BASE, "camera": {"fit": "auto"}}, ValueError, "camera 'fit' must be an object"),
    ("camera-fit-unknown", {**BASE, "camera": {"fit": {"dir": [1, 0, 0]}}}, ValueError, r"unknown camera.fit keys \['dir'\]"),
    ("camera-fit-and-position", {**BASE, "camera": {"fit": {}, "position": [0, 0, 1]}}, ValueError, "takes only 'fit'"),
    ("camera-fit-zoom-zero", {**BASE, "camera": {"fit": {"zoom": 0}}}, ValueError, "zoom must be positive"),
    ("camera-unknown-key", {**BASE, "camera": {"eye": [0, 0, 1]}}, ValueError, r"unknown camera keys \['eye'\]"),
    ("camera-parallel-word", {**BASE, "camera": {"position": [0, 0, 1], "parallel_projection": "yes"}}, ValueError,
     "parallel_projection must be true or false, got 'yes'"),
    ("camera-clipping-three", {**BASE, "camera": {"position": [0, 0, 1], "clipping_range": [1, 2, 3]}}, ValueError,
     r"scene camera 'clipping_range' must be a list of 2 numbers .* got \[1, 2, 3\]"),
    ("camera-position-strings", {**BASE, "camera": {"position": ["0", "0", "5"]}}, ValueError,
     r"scene camera 'position' must be a list of 3 numbers such as \[0, 0, 0\], got \['0', '0', '5'\]"),
    ("camera-position-string", {**BASE, "camera": {"position": "0 0 5"}}, ValueError,
     r"scene camera 'position' must be a list of 3 numbers .* got '0 0 5'"),
    ("camera-focal-point-bool", {**BASE, "camera": {"position": [0, 0, 5], "focal_point": [True, 0, 0]}}, ValueError,
     r"scene camera 'focal_point' must be a list of 3 numbers .* got \[True, 0, 0\]"),
    ("camera-view-angle-string", {**BASE, "camera": {"position": [0, 0, 5], "view_angle": "30"}}, ValueError,
     "scene camera 'view_angle' must be a number, got '30'"),
    ("camera-clipping-strings", {**BASE, "camera": {"position": [0, 0, 5], "clipping_range": ["1", "9"]}},
     ValueError, r"scene camera 'clipping_range' must be a list of 2 numbers"),
    ("camera-fit-direction-strings", {**BASE, "camera": {"fit": {"direction": ["1", "0", "0"]}}}, ValueError,
     r"scene camera.fit 'direction' must be a list of 3 numbers .* got \['1', '0', '0'\]"),
    ("camera-fit-zoom-string", {**BASE, "camera": {"fit": {"zoom": "2"}}}, ValueError,
     "scene camera.fit 'zoom' must be a number, got '2'"),
    ("clip-normal-strings", {**BASE, "clip": {"plane": {"origin": [0, 0, 0], "normal": ["1", 0, 0]}}}, ValueError,
     r"clip 'plane' 'normal' must hold numbers, got \['1', 0, 0\]"),
    ("settings-string", {**BASE, "settings": "fast"}, ValueError, "'settings' must be an object of RenderSettings fields"),
    ("settings-unknown", {**BASE, "settings": {"speed": 1}}, ValueError, r"unknown settings keys \['speed'\]"),
    ("settings-bad-value", {**BASE, "settings": {"table_scalar_bins": "many"}}, ValueError, "table_scalar_bins must be"),
    ("not-an-object", [1, 2], ValueError, "a scene must be a JSON object, got list"),
]


@pytest.fixture
def scene_dir(tmp_path):
    shutil.copy(POST_VTK, tmp_path / "post.vtk")
    return tmp_path


@pytest.mark.parametrize("data,exc,match", [c[1:] for c in SCENE_BAD], ids=[c[0] for c in SCENE_BAD])
def test_bad_scene(scene_dir, data, exc, match):
    path = scene_dir / "scene.json"
    path.write_text(json.dumps(data))
    with pytest.raises(exc, match=match):
        load_scene(path)


def test_good_scene_loads(scene_dir):
    path = scene_dir / "scene.json"
    path.write_text(json.dumps(BASE))
    assert load_scene(path).size == (8, 8)
    cam = {"position": [0, 0, 5.5], "focal_point": [0, 0, 0], "view_up": [0, 1, 0], "view_angle": 30}
    path.write_text(json.dumps({**BASE, "camera": cam}))
    assert load_scene(path).camera.position == (0.0, 0.0, 5.5)
    path.write_text(json.dumps({**BASE, "camera": {"fit": {"direction": [1, 0, 0], "view_up": None, "zoom": 2}}}))
    assert load_scene(path).camera.view_angle == 30.0
    path.write_text(json.dumps({**BASE, "clip": {"plane": {"origin": [0, 0, 0], "normal": [1e300, 0, 0]}}}))
    assert load_scene(path).clip.planes == ((1.0, 0.0, 0.0, 0.0),)  # not a zero normal that keeps everything


@pytest.mark.parametrize("text,match", [
    ("{mesh: ", "not valid JSON"),
    ("", "not valid JSON"),
    ('{"mesh": "post.vtk", "size": [NaN, 8]}', r"'size' .* got \[nan, 8\]"),
    ('{"mesh": "post.vtk", "mesh": "other.vtk"}', r"repeated keys \['mesh'\]"),
], ids=["broken", "empty", "nan-size", "repeated-key"])
def test_bad_json_text(scene_dir, text, match):
    path = scene_dir / "scene.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_scene(path)


def test_binary_scene_file(scene_dir):
    path = scene_dir / "scene.json"
    path.write_bytes(b"\xff\xfe\x00\x01garbage")
    with pytest.raises(ValueError, match="not valid JSON .*UTF-8"):
        load_scene(path)


def test_scene_path_is_a_directory(tmp_path):
    with pytest.raises(ValueError, match="is a directory"):
        load_scene(tmp_path)


def test_scene_file_missing(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_scene(tmp_path / "nothere.json")


@pytest.mark.parametrize("argv_kind", ["missing-scene", "directory-scene", "binary-scene", "bad-size",
                                       "info-garbage-mesh", "info-directory", "unwritable-output"])
def test_cli_reports_errors_without_traceback(scene_dir, capsys, argv_kind):
    scene = scene_dir / "scene.json"
    scene.write_text(json.dumps(BASE))
    garbage = scene_dir / "garbage.vtu"
    garbage.write_bytes(b"garbage")
    argv = {
        "missing-scene": ["render", str(scene_dir / "nothere.json"), "-o", str(scene_dir / "o.png"), "--reference"],
        "directory-scene": ["render", str(scene_dir), "-o", str(scene_dir / "o.png"), "--reference"],
        "binary-scene": ["render", str(garbage), "-o", str(scene_dir / "o.png"), "--reference"],
        "bad-size": None,
        "info-garbage-mesh": ["info", str(garbage)],
        "info-directory": ["info", str(scene_dir)],
        "unwritable-output": ["render", str(scene), "-o", str(scene_dir / "no" / "such" / "dir" / "o.png"),
                              "--reference"],
    }[argv_kind]
    if argv is None:
        scene.write_text(json.dumps({**BASE, "size": "big"}))
        argv = ["render", str(scene), "-o", str(scene_dir / "o.png"), "--reference"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("tetvr: error: ") and "Traceback" not in err

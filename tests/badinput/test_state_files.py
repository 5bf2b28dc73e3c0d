"""Hostile numbers in ParaView state files (``.pvsm``) and colour-map presets: each number
is checked once, where it is read, and a bad one is a ValueError naming the file, the
proxy and the property (or the preset and its key), the value and its bound, and saying
to fix it -- never a raw ``int()`` / ``OverflowError`` text, a 7 GiB allocation for
``NumberOfTableValues = 1e9``, or a minute of building for 3e7."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from tetvr.apps.cli import EXIT_USAGE, main
from tetvr.optics.colormaps import from_paraview
from tetvr.scene.paraview import load_state, read_state

from ._util import POST_VTK, REPO, deadline

STATE = REPO / "tests" / "data" / "post_volume.pvsm"
WHOLE = "must be a whole number from"
FINITE = "a state's numbers must be finite: fix or remove that value"


def _state(tmp_path: Path, prop: str, index: int | str, value: str, *, attr: str = "value") -> Path:
    """The test state with one ``<Element>`` of property ``prop`` (its id, "9460.RGBPoints")
    changed: its value, or (``attr="index"``) its index; the data file beside it."""
    text = STATE.read_text()
    start = text.index(f'id="{prop}"')
    pattern = re.compile(rf'<Element index="{index}" value="[^"]*"/>')
    found = pattern.search(text, start)
    assert found is not None, (prop, index)
    new = (f'<Element index="{index}" value="{value}"/>' if attr == "value"
           else f'<Element index="{value}" value="0"/>')
    path = tmp_path / "state.pvsm"
    path.write_text(text[:found.start()] + new + text[found.end():])
    (tmp_path / "post.vtk").symlink_to(POST_VTK)
    return path


LUT = r"state\.pvsm: PVLookupTable \(id 9460\) property"
VIEW = r"state\.pvsm: RenderView \(id 4477\) property"
REP = r"state\.pvsm: UnstructuredGridRepresentation \(id 9471\) property"

# (id, property id, element index, value, message regex)
STATE_BAD = [
    ("table-values-1e9", "9460.NumberOfTableValues", 0, "1e9", rf"{LUT} NumberOfTableValues {WHOLE} 1 to 16384, got '1e9'; fix"),
    ("table-values-3e7", "9460.NumberOfTableValues", 0, "3e7", rf"{LUT} NumberOfTableValues {WHOLE} 1 to 16384, got '3e7'"),
    ("table-values-nan", "9460.NumberOfTableValues", 0, "nan", rf"{LUT} NumberOfTableValues holds 'nan'; {FINITE}"),
    ("table-values-inf", "9460.NumberOfTableValues", 0, "inf", rf"{LUT} NumberOfTableValues holds 'inf'; {FINITE}"),
    ("table-values-fraction", "9460.NumberOfTableValues", 0, "2.5", rf"{LUT} NumberOfTableValues {WHOLE} 1 to 16384, got '2.5'"),
    ("table-values-zero", "9460.NumberOfTableValues", 0, "0", rf"{LUT} NumberOfTableValues {WHOLE} 1 to 16384, got '0'"),
    ("table-values-word", "9460.NumberOfTableValues", 0, "many", rf"{LUT} NumberOfTableValues holds 'many', not a number; fix"),
    ("discretize-two", "9460.Discretize", 0, "2", rf"{LUT} Discretize {WHOLE} 0 to 1, got '2'"),
    ("color-space-huge", "9460.ColorSpace", 0, "1e20", rf"{LUT} ColorSpace {WHOLE} -2147483648 to 2147483647, got '1e20'"),
    ("rgb-position-nan", "9460.RGBPoints", 0, "NaN", rf"{LUT} RGBPoints holds 'NaN'; {FINITE}"),
    ("rgb-position-overflow", "9460.RGBPoints", 0, "1e400", rf"{LUT} RGBPoints holds '1e400'; {FINITE}"),
    ("rgb-position-beyond", "9460.RGBPoints", 0, "-1e305", rf"{LUT} RGBPoints holds '-1e305', outside \[-1e\+300, 1e\+300\]"),
    ("rgb-red-above-one", "9460.RGBPoints", 1, "2", rf"{LUT} RGBPoints: node 0's red is 2\.0, outside \[0, 1\]; fix"),
    ("opacity-negative", "9459.Points", 1, "-0.5", r"state\.pvsm: PiecewiseFunction \(id 9459\) property Points: "
                                                   r"node 0's opacity is -0\.5, outside \[0, 1\]"),
    ("camera-angle-nan", "4477.CameraViewAngle", 0, "nan", rf"{VIEW} CameraViewAngle holds 'nan'; {FINITE}"),
    ("camera-position-inf", "4477.CameraPosition", 0, "-inf", rf"{VIEW} CameraPosition holds '-inf'; {FINITE}"),
    ("view-size-huge", "4477.ViewSize", 0, "1e9", rf"{VIEW} ViewSize {WHOLE} 0 to 65536, got '1e9'"),
    ("view-size-fraction", "4477.ViewSize", 1, "300.5", rf"{VIEW} ViewSize {WHOLE} 0 to 65536, got '300\.5'"),
    ("association-word", "9471.ColorArrayName", 3, "x", rf"{REP} ColorArrayName holds 'x', not a number"),
    ("association-fraction", "9471.ColorArrayName", 3, "0.5", rf"{REP} ColorArrayName {WHOLE} 0 to 8, got '0\.5'"),
    ("unit-distance-subnormal", "9471.ScalarOpacityUnitDistance", 0, "1e-320",
     rf"{REP} ScalarOpacityUnitDistance must be a finite number of at least 1e-300"),
    ("visibility-half", "9471.Visibility", 0, "0.5", rf"{REP} Visibility {WHOLE} 0 to 1, got '0\.5'"),
]


@pytest.mark.parametrize("prop,index,value,match", [c[1:] for c in STATE_BAD], ids=[c[0] for c in STATE_BAD])
def test_bad_number_in_a_state_names_file_proxy_and_property(tmp_path, prop, index, value, match):
    path = _state(tmp_path, prop, index, value)
    with deadline(5.0, "read_state"), pytest.raises(ValueError, match=match):
        read_state(path)


@pytest.mark.parametrize("index", ["x", "-1", "1e9"])
def test_bad_element_index_is_named(tmp_path, index):
    path = _state(tmp_path, "4477.ViewSize", 1, index, attr="index")
    with pytest.raises(ValueError, match=rf"{VIEW} ViewSize has an <Element index='{re.escape(index)}'>; an index "
                                         r"is a whole number from 0 to \d+: is the state damaged\?"):
        read_state(path)


@pytest.mark.parametrize("value", ["1e9", "3e7"])
def test_huge_table_is_refused_at_once_through_the_cli(tmp_path, capsys, value):
    path = _state(tmp_path, "9460.NumberOfTableValues", 0, value)
    with deadline(20.0, "tetvr render"):
        status = main(["render", str(path), "-o", str(tmp_path / "o.png"), "--reference", "--size", "8x6"])
    assert status == EXIT_USAGE
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("tetvr: error: ") and "NumberOfTableValues must be a whole number from 1 to 16384" in err
    assert not (tmp_path / "o.png").exists()


def test_largest_table_is_built_in_time(tmp_path):
    path = _state(tmp_path, "9460.NumberOfTableValues", 0, "16384")
    with deadline(20.0, "the largest discretized map"):
        scene = load_state(path)
    assert len(scene.tf.color) == 2 * 16384


def test_state_without_a_unit_distance_takes_paraviews(tmp_path):
    """The representation's ScalarOpacityUnitDistance left out: ParaView's default (this
    once failed with a NameError: the function was imported for type checking only)."""
    path = _state(tmp_path, "9471.ScalarOpacityUnitDistance", 0, "0")
    assert load_state(path).tf.unit_distance > 0


# ---- colour-map presets (ParaView JSON) ----

RGB = [0, 0, 0, 0, 1, 1, 1, 1]


@pytest.mark.parametrize("preset,match", [
    ({"RGBPoints": [0, "0", 0, 0, 1, 1, 1, 1]}, r"'p' RGBPoints: value 1 is '0', not a number; fix that value"),
    ({"RGBPoints": [0, True, 0, 0, 1, 1, 1, 1]}, r"'p' RGBPoints: value 1 is True, not a number"),
    ({"RGBPoints": [0, None, 0, 0, 1, 1, 1, 1]}, r"'p' RGBPoints: value 1 is None, not a number"),
    ({"RGBPoints": [float("nan"), 0, 0, 0, 1, 1, 1, 1]}, r"'p' RGBPoints: node 0's position is nan, not finite"),
    ({"RGBPoints": [0, 0, 0, 1.5, 1, 1, 1, 1]}, r"'p' RGBPoints: node 0's blue is 1\.5, outside \[0, 1\]"),
    ({"RGBPoints": "0 0 0 0"}, r"'p' RGBPoints must be a list of numbers, got str"),
    ({"RGBPoints": RGB, "Points": [0, 0, 2, 0, 1, 1, 0.5, 0]}, r"'p' Points: node 0's midpoint is 2\.0, outside"),
    ({"RGBPoints": RGB, "Points": [0, 0, 0.5, float("inf"), 1, 1, 0.5, 0]}, r"node 0's sharpness is inf, not finite"),
    ({"RGBPoints": [v for k in range(5000) for v in (k, 0, 0, 0)], "ColorSpace": "Diverging"},
     r"'p' \(5000 colour and 0 opacity nodes, 256 samples a segment\) would make up to 1280000 transfer-function "
     r"rows, more than 1048576; use fewer nodes or fewer samples_per_segment"),
], ids=["string", "bool", "null", "nan-position", "blue-above-one", "not-a-list", "midpoint", "sharpness-inf",
        "too-many-rows"])
def test_bad_preset_number_names_the_preset_and_key(preset, match):
    with deadline(5.0, "from_paraview"), pytest.raises(ValueError, match=match):
        from_paraview({"Name": "p", **preset}, samples_per_segment=256)


def test_bad_preset_file_is_named(tmp_path):
    path = tmp_path / "maps.json"
    path.write_text(json.dumps([{"Name": "warm", "RGBPoints": [0, 0, 0, 0, 1, 1, 1, float("inf")]}]))
    with pytest.raises(ValueError, match=r"maps\.json: ParaView preset 'warm' RGBPoints: node 1's blue is inf, not "
                                         r"finite; fix that value"):
        from_paraview(path)

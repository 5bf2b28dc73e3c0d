"""ParaView preset JSON and matplotlib colormaps -> TransferFunction (pure numpy; no GL)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tetvr import TransferFunction
from tetvr.optics.colormaps import (_lab_to_rgb, _rgb_to_lab, available, colormap, from_matplotlib, from_paraview,
                             read_paraview, to_paraview, write_paraview)

# As ParaView 5.x writes "Save preset" for Cool to Warm with its opacity (the bundled
# preset's nodes; ParaView adds "Creator" and "NanColor").
PARAVIEW_COOL_TO_WARM = [{
    "ColorSpace": "Diverging",
    "Creator": "Pseudo-Moreland",
    "Name": "Cool to Warm",
    "NanColor": [1, 1, 0],
    "Points": [0.355, 0, 0.5, 0, 1.64, 1, 0.5, 0],
    "RGBPoints": [0.355, 0.23137254902, 0.298039215686, 0.752941176471,
                  1.64, 0.705882352941, 0.0156862745098, 0.149019607843],
}]


@pytest.fixture(autouse=True)
def _strict_numpy():
    with np.errstate(all="raise"):
        yield


def test_round_trip_through_paraview_json(tmp_path):
    tf = TransferFunction(color=((0.0, 0.1, 0.2, 0.3), (0.4, 1.0, 0.5, 0.0), (2.0, 0.0, 0.0, 1.0)),
                          opacity=((0.0, 0.0), (1.0, 0.7), (2.0, 0.2)), unit_distance=0.25)
    path = tmp_path / "mine.json"
    write_paraview({"mine": tf, "other": TransferFunction.preset("hot", (0, 1))}, path)
    raw = json.loads(path.read_text())
    assert [p["Name"] for p in raw] == ["mine", "other"]
    assert raw[0]["ColorSpace"] == "RGB" and len(raw[0]["RGBPoints"]) == 12 and len(raw[0]["Points"]) == 12
    back = from_paraview(path, name="mine", unit_distance=0.25)
    assert back == tf  # RGB space and linear opacity: nothing is resampled
    assert list(read_paraview(path)) == ["mine", "other"]
    assert from_paraview(to_paraview(tf), unit_distance=0.25) == tf


def test_paraview_file_with_diverging_space(tmp_path):
    path = tmp_path / "cool_to_warm.json"
    path.write_text(json.dumps(PARAVIEW_COOL_TO_WARM))
    tf = from_paraview(path, unit_distance=0.1)
    assert tf.domain == (0.355, 1.64)
    rgb, alpha = tf.evaluate([0.355, 0.9975, 1.64])
    np.testing.assert_allclose(rgb[0], PARAVIEW_COOL_TO_WARM[0]["RGBPoints"][1:4], atol=1e-9)
    np.testing.assert_allclose(rgb[2], PARAVIEW_COOL_TO_WARM[0]["RGBPoints"][5:8], atol=1e-9)
    # Moreland's diverging map passes through its white point: ParaView's (and tetvr's
    # "cool-to-warm" preset's) middle colour 0.865.
    np.testing.assert_allclose(rgb[1], [0.865003] * 3, atol=2e-3)
    np.testing.assert_allclose(alpha, [0.0, 0.5, 1.0], atol=1e-12)
    # Stretched onto another range, colour and opacity nodes move together.
    tf2 = from_paraview(path, scalar_range=(-1.0, 1.0))
    assert tf2.domain == (-1.0, 1.0)
    np.testing.assert_allclose(tf2.evaluate([0.0])[1], [0.5], atol=1e-12)


def test_lab_conversion_round_trips():
    rgb = np.random.default_rng(0).uniform(0, 1, (200, 3))
    np.testing.assert_allclose(_lab_to_rgb(_rgb_to_lab(rgb)), rgb, atol=1e-9)
    np.testing.assert_allclose(_rgb_to_lab([1.0, 1.0, 1.0]), [100.0, 0.0, 0.0], atol=0.05)


def test_lab_hsv_and_step_spaces():
    base = {"Name": "t", "RGBPoints": [0, 1, 0, 0, 1, 1, 0, 1]}  # red -> magenta
    lab = from_paraview(dict(base, ColorSpace="Lab"), samples_per_segment=8)
    want = _lab_to_rgb(0.5 * (_rgb_to_lab([1, 0, 0]) + _rgb_to_lab([1, 0, 1])))
    np.testing.assert_allclose(lab.evaluate([0.5])[0][0], want, atol=1e-9)  # 0.5 is a node
    hsv = from_paraview(dict(base, ColorSpace="HSV"), samples_per_segment=8)
    # Hue 0 -> 5/6 the short way, through 11/12: (1, 0, 0.5).
    np.testing.assert_allclose(hsv.evaluate([0.5])[0][0], [1.0, 0.0, 0.5], atol=1e-9)
    step = from_paraview(dict(base, ColorSpace="Step"))
    rgb = step.evaluate([0.0, 0.5, 0.999, 1.0])[0]
    np.testing.assert_allclose(rgb[:3], [[1, 0, 0]] * 3)
    np.testing.assert_allclose(rgb[3], [1, 0, 1])


def test_opacity_midpoint_and_sharpness_follow_vtk():
    def tf(mid, sharp):
        return from_paraview({"Name": "o", "ColorSpace": "RGB", "RGBPoints": [0, 0, 0, 0, 1, 1, 1, 1],
                              "Points": [0, 0.0, mid, sharp, 1, 1.0, 0.5, 0.0]}, samples_per_segment=64)

    # Linear (0.5, 0): two nodes only.
    assert tf(0.5, 0.0).opacity == ((0.0, 0.0), (1.0, 1.0))
    # The midpoint is where the value is half-way (vtkPiecewiseFunction's definition).
    np.testing.assert_allclose(tf(0.25, 0.0).evaluate([0.25])[1], [0.5], atol=1e-9)
    np.testing.assert_allclose(tf(0.25, 0.0).evaluate([0.125])[1], [0.25], atol=1e-9)
    # Sharpness 1: a step at the midpoint.
    step = tf(0.3, 1.0)
    np.testing.assert_allclose(step.evaluate([0.1, 0.29, 0.31, 0.9])[1], [0, 0, 1, 1], atol=1e-6)
    # In between: monotone, inside [0, 1], half-way at the midpoint.
    mid = tf(0.5, 0.5)
    a = mid.evaluate(np.linspace(0, 1, 101))[1]
    assert np.all(np.diff(a) >= -1e-12) and a.min() >= 0 and a.max() <= 1
    np.testing.assert_allclose(a[50], 0.5, atol=1e-9)


def test_preset_without_opacity_takes_the_given_one():
    p = {"Name": "c", "ColorSpace": "RGB", "RGBPoints": [-1, 0, 0, 0, 1, 1, 1, 1]}
    assert from_paraview(p).opacity == ((-1.0, 0.5), (1.0, 0.5))
    assert from_paraview(p, scalar_range=(0, 10), opacity=[(0, 0), (1, 0.8)]).opacity == ((0.0, 0.0), (10.0, 0.8))


@pytest.mark.parametrize("preset, match", [
    ({"Name": "cats", "IndexedColors": [1, 0, 0, 0, 1, 0], "Annotations": ["a", "A", "b", "B"]}, "indexed"),
    ({"Name": "x", "ColorSpace": "CMYK", "RGBPoints": [0, 0, 0, 0, 1, 1, 1, 1]}, "ColorSpace"),
    ({"Name": "x", "RGBPoints": [0, 0, 0, 0, 1, 1, 1]}, "groups of 4"),
    ({"Name": "x", "RGBPoints": [1, 0, 0, 0, 0, 1, 1, 1]}, "ascending"),
    ({"Name": "x", "RGBPoints": [0.5, 0, 0, 0]}, "single value"),
])
def test_bad_presets_are_refused_with_the_reason(preset, match):
    with pytest.raises(ValueError, match=match):
        from_paraview(preset)


def test_read_paraview_errors(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        read_paraview(bad)
    one = tmp_path / "one.json"
    one.write_text(json.dumps(PARAVIEW_COOL_TO_WARM[0]))  # a bare object is one preset
    assert list(read_paraview(one)) == ["Cool to Warm"]
    with pytest.raises(KeyError, match="Cool to Warm"):
        from_paraview(one, name="Viridis")


def test_matplotlib_colormaps():
    pytest.importorskip("matplotlib", reason="matplotlib colour maps need matplotlib (pip install tetvr[notebooks] or tetvr[bench])")
    tf = from_matplotlib("viridis", (2.0, 4.0), opacity=0.3, unit_distance=0.5)
    assert len(tf.color) == 256 and tf.domain == (2.0, 4.0) and tf.unit_distance == 0.5
    # The nodes are matplotlib's own entries: its lookup table, at positions k / 255.
    import matplotlib

    lut = matplotlib.colormaps["viridis"](np.arange(256))[:, :3]
    np.testing.assert_allclose(tf.evaluate(2.0 + 2.0 * np.arange(256) / 255)[0], lut, atol=1e-12)
    assert colormap("magma", (0, 1)).color[0][1:] == pytest.approx(from_matplotlib("magma", (0, 1)).color[0][1:])
    names = available()
    assert "magma" in names and names[:4] == ["cool-to-warm", "grayscale", "hot", "viridis"]
    with pytest.raises(ValueError, match="unknown colour map 'no-such-map'"):
        colormap("no-such-map", (0, 1))
    with pytest.raises(ValueError, match="scalar_range"):
        from_matplotlib("viridis", (1.0, 1.0))


def test_colormap_reports_the_real_error_of_a_known_matplotlib_map():
    pytest.importorskip("matplotlib", reason="matplotlib colour maps need matplotlib (pip install tetvr[notebooks] or tetvr[bench])")
    with pytest.raises(ValueError, match="scalar_range") as err:
        colormap("magma", (1, 0))
    assert "unknown colour map" not in str(err.value)


def test_colormap_prefers_tetvr_presets_and_reads_preset_files(tmp_path):
    assert colormap("hot", (0, 2), opacity=0.2) == TransferFunction.preset("hot", (0, 2), opacity=0.2)
    path = tmp_path / "c2w.json"
    path.write_text(json.dumps(PARAVIEW_COOL_TO_WARM))
    assert colormap(str(path), (0, 1)).domain == (0.0, 1.0)

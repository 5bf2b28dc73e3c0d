"""Bad parameter objects: Camera, Camera.fit, TransferFunction and RenderSettings reject
nonsense in ``__post_init__`` with a ValueError naming the field and the value (never a
ZeroDivisionError, an unpacking error or a silent ``bool("no") == True``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.core.clip import Clip
from tetvr.mesh import synthetic

NAN = float("nan")

# ---- Camera -----------------------------------------------------------------------

CAMERA_BAD = [
    ("position-is-focal-point", dict(position=(1, 2, 3), focal_point=(1, 2, 3)), "position equals focal_point"),
    ("view-up-parallel", dict(position=(0, 0, 1), view_up=(0, 0, 5)), "view_up .* is parallel to the view direction"),
    ("view-up-antiparallel", dict(position=(0, 0, 1), view_up=(0, 0, -1)), "parallel to the view direction"),
    ("view-up-zero", dict(view_up=(0, 0, 0)), "view_up must not be the zero vector"),
    ("view-angle-zero", dict(view_angle=0), r"view_angle must be in \(0, 180\) degrees, got 0"),
    ("view-angle-negative", dict(view_angle=-10), r"view_angle must be in \(0, 180\) degrees, got -10"),
    ("view-angle-180", dict(view_angle=180), r"view_angle must be in \(0, 180\) degrees, got 180"),
    ("view-angle-270", dict(view_angle=270.0), r"view_angle must be in \(0, 180\)"),
    ("view-angle-nan", dict(view_angle=NAN), "view_angle must be finite"),
    ("view-angle-string", dict(view_angle="wide"), "view_angle must be a number, got 'wide'"),
    ("near-equals-far", dict(clipping_range=(5, 5)), r"near < far, got \(5, 5\)"),
    ("near-beyond-far", dict(clipping_range=(10, 1)), r"near < far, got \(10, 1\)"),
    ("near-zero-perspective", dict(clipping_range=(0, 1)), "perspective camera needs near > 0"),
    ("near-negative-perspective", dict(clipping_range=(-1, 1)), "perspective camera needs near > 0"),
    ("clipping-three-values", dict(clipping_range=(1, 2, 3)), r"clipping_range must be two finite numbers.*\(1, 2, 3\)"),
    ("clipping-scalar", dict(clipping_range=5), "clipping_range must be two finite numbers"),
    ("clipping-nan", dict(clipping_range=(NAN, 2)), "clipping_range must be two finite numbers"),
    ("clipping-inf", dict(clipping_range=(1, math.inf)), "clipping_range must be two finite numbers"),
    ("position-nan", dict(position=(NAN, 0, 1)), r"position must be 3 finite numbers, got \(nan, 0, 1\)"),
    ("position-inf", dict(position=(0, math.inf, 1)), "position must be 3 finite numbers"),
    ("position-two-values", dict(position=(0, 1)), r"position must be 3 finite numbers, got \(0, 1\)"),
    ("position-string", dict(position="origin"), "position must be 3 finite numbers, got 'origin'"),
    ("focal-point-nan", dict(focal_point=(0, NAN, 0)), "focal_point must be 3 finite numbers"),
    ("position-overflows-distance", dict(position=(1e308, 1e308, 1e308), focal_point=(-1e308, 0, 0)), "too far apart"),
    ("parallel-scale-zero", dict(parallel_projection=True, parallel_scale=0), "parallel_scale must be positive, got 0"),
    ("parallel-scale-negative", dict(parallel_projection=True, parallel_scale=-2), "parallel_scale must be positive"),
    ("parallel-scale-nan", dict(parallel_projection=True, parallel_scale=NAN), "parallel_scale must be finite"),
    ("parallel-flag-string", dict(parallel_projection="false"), "parallel_projection must be true or false, got 'false'"),
    ("parallel-flag-two", dict(parallel_projection=2), "parallel_projection must be true or false, got 2"),
]


@pytest.mark.parametrize("kwargs,match", [c[1:] for c in CAMERA_BAD], ids=[c[0] for c in CAMERA_BAD])
def test_bad_camera(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Camera(**kwargs)


def test_parallel_camera_may_have_near_at_or_behind_zero():
    cam = Camera(position=(0, 0, 1), parallel_projection=True, clipping_range=(-1.0, 1.0))
    assert cam.clipping_range == (-1.0, 1.0)


def test_camera_from_dict_unknown_key():
    with pytest.raises(ValueError, match=r"unknown camera keys \['eye'\]"):
        Camera.from_dict({"eye": [0, 0, 1]})


FIT_BAD = [
    ("zoom-zero", dict(zoom=0), "zoom must be positive, got 0"),
    ("zoom-negative", dict(zoom=-1), "zoom must be positive"),
    ("zoom-nan", dict(zoom=NAN), "zoom must be finite"),
    ("zoom-string", dict(zoom="x"), "zoom must be a number"),
    ("view-angle-zero", dict(view_angle=0), r"view_angle must be in \(0, 180\)"),
    ("view-angle-200", dict(view_angle=200), r"view_angle must be in \(0, 180\)"),
    ("direction-zero", dict(direction=(0, 0, 0)), "direction must not be the zero vector"),
    ("direction-nan", dict(direction=(NAN, 0, 1)), "direction must be 3 finite numbers"),
    ("direction-two-values", dict(direction=(1, 0)), "direction must be 3 finite numbers"),
    ("view-up-zero", dict(view_up=(0, 0, 0)), "view_up must not be the zero vector"),
    ("view-up-nan", dict(view_up=(NAN, 1, 0)), "view_up must be 3 finite numbers"),
]


@pytest.mark.parametrize("kwargs,match", [c[1:] for c in FIT_BAD], ids=[c[0] for c in FIT_BAD])
def test_bad_camera_fit(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Camera.fit(synthetic.single_tet(), **kwargs)


def test_camera_fit_repairs_a_view_up_along_the_direction():
    cam = Camera.fit(synthetic.single_tet(), direction=(0, 1, 0), view_up=(0, 1, 0))
    assert abs(float(np.dot(cam.direction, cam.view_up))) < 0.99


# ---- TransferFunction -------------------------------------------------------------

C2 = ((0.0, 1.0, 0.0, 0.0), (1.0, 0.0, 0.0, 1.0))
O2 = ((0.0, 0.5), (1.0, 0.5))

TF_BAD = [
    ("color-unsorted", dict(color=((1, 1, 0, 0), (0, 0, 1, 0)), opacity=O2), r"color positions must be sorted ascending, got \[1\.0, 0\.0\]"),
    ("opacity-unsorted", dict(color=C2, opacity=((0.5, 0.1), (0.2, 0.3), (1, 0.2))), "opacity positions must be sorted"),
    ("opacity-duplicate", dict(color=C2, opacity=((0, 0.5), (0, 0.6), (1, 0.5))), r"opacity has duplicate positions \[0\.0\]"),
    ("color-duplicate", dict(color=((0, 1, 0, 0), (0, 0, 1, 0)), opacity=O2), "color has duplicate positions"),
    ("opacity-above-one", dict(color=C2, opacity=((0, 1.5), (1, 0.5))), r"opacity values must lie in \[0, 1\], got 0\.5 \.\. 1\.5"),
    ("opacity-negative", dict(color=C2, opacity=((0, -0.1), (1, 0.5))), r"opacity values must lie in \[0, 1\], got -0\.1"),
    ("color-above-one", dict(color=((0, 2, 0, 0), (1, 0, 1, 0)), opacity=O2), r"color values must lie in \[0, 1\]"),
    ("opacity-nan-position", dict(color=C2, opacity=((NAN, 0.5), (1, 0.5))), "opacity contains NaN or Inf"),
    ("color-inf-position", dict(color=((-math.inf, 1, 0, 0), (1, 0, 1, 0)), opacity=O2), "color contains NaN or Inf"),
    ("opacity-nan-value", dict(color=C2, opacity=((0, NAN), (1, 0.5))), "opacity contains NaN or Inf"),
    ("positions-span-overflows", dict(color=((-1e308, 1, 0, 0), (1e308, 0, 1, 0)), opacity=O2), "span more than float64"),
    ("opacity-empty", dict(color=C2, opacity=()), r"opacity must be a sequence of \(x, a\) rows"),
    ("color-empty", dict(color=[], opacity=O2), r"color must be a sequence of \(x, r, g, b\) rows"),
    ("opacity-flat-list", dict(color=C2, opacity=[0.5]), r"opacity must be a sequence of \(x, a\) rows, got an array of shape \(1,\)"),
    ("color-ragged", dict(color=((0, 1, 0), (1, 0, 1, 0)), opacity=O2), "color must be a sequence of .* rows of numbers"),
    ("color-string", dict(color="red", opacity=O2), "color must be a sequence of .* rows, got 'red'"),
    ("color-rows-of-three", dict(color=((0, 1, 0), (1, 0, 1)), opacity=O2), r"got an array of shape \(2, 3\)"),
    ("unit-distance-zero", dict(color=C2, opacity=O2, unit_distance=0), "unit_distance must be a positive finite number, got 0"),
    ("unit-distance-negative", dict(color=C2, opacity=O2, unit_distance=-1.0), "unit_distance must be a positive finite number, got -1.0"),
    ("unit-distance-nan", dict(color=C2, opacity=O2, unit_distance=NAN), "unit_distance must be a positive finite number, got nan"),
    ("unit-distance-inf", dict(color=C2, opacity=O2, unit_distance=math.inf), "unit_distance must be a positive finite number"),
    ("unit-distance-string", dict(color=C2, opacity=O2, unit_distance="1"), "unit_distance must be a positive finite number, got '1'"),
    ("unit-distance-none", dict(color=C2, opacity=O2, unit_distance=None), "unit_distance must be a positive finite number, got None"),
]


@pytest.mark.parametrize("kwargs,match", [c[1:] for c in TF_BAD], ids=[c[0] for c in TF_BAD])
def test_bad_transfer_function(kwargs, match):
    with pytest.raises(ValueError, match=match):
        TransferFunction(**kwargs)


def test_single_control_point_is_a_constant_function():
    tf = TransferFunction(color=((0.5, 1, 0, 0),), opacity=((0.5, 0.25),))
    rgb, a = tf.evaluate([-1e9, 0.5, 1e9])
    assert np.array_equal(a, [0.25] * 3) and np.array_equal(rgb[:, 0], [1.0] * 3)


PRESET_BAD = [
    ("unknown-name", ("jet", (0, 1)), {}, r"unknown preset 'jet'; choose one of \['cool-to-warm'"),
    ("range-empty", ("viridis", (1, 1)), {}, r"scalar_range must be finite with lo < hi, got \(1, 1\)"),
    ("range-inverted", ("viridis", (2, 1)), {}, "lo < hi"),
    ("range-nan", ("viridis", (NAN, 1)), {}, "scalar_range must be finite"),
    ("range-overflows", ("viridis", (-1e308, 1e308)), {}, "scalar_range must be finite"),
    ("range-scalar", ("viridis", 5), {}, "scalar_range must be two numbers"),
    ("opacity-above-one", ("viridis", (0, 1)), dict(opacity=2.0), r"opacity values must lie in \[0, 1\]"),
    ("opacity-nan", ("viridis", (0, 1)), dict(opacity=NAN), "opacity contains NaN"),
    ("opacity-string", ("viridis", (0, 1)), dict(opacity="half"), "opacity must be a number or \\(t, a\\) rows"),
    ("opacity-bad-rows", ("viridis", (0, 1)), dict(opacity=[(0, 0.5, 3)]), "opacity must be a number or"),
    ("unit-distance-zero", ("viridis", (0, 1)), dict(unit_distance=0.0), "unit_distance must be a positive"),
]


@pytest.mark.parametrize("args,kwargs,match", [c[1:] for c in PRESET_BAD], ids=[c[0] for c in PRESET_BAD])
def test_bad_preset(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        TransferFunction.preset(*args, **kwargs)


@pytest.mark.parametrize("data,match", [
    ({"color": [[0, 1, 1, 1]]}, r"missing keys \['opacity'\]"),
    ({"opacity": [[0, 1]]}, r"missing keys \['color'\]"),
    ({"color": [[0, 1, 1, 1]], "opacity": [[0, 1]], "gamma": 2}, r"unknown transfer-function keys \['gamma'\]"),
    ({"color": [[0, 1, 1, 1]], "opacity": [0.5]}, r"opacity must be a sequence of \(x, a\) rows"),
    ({"color": [[0, "r", 1, 1]], "opacity": [[0, 1]]}, "color must be a sequence of .* rows of numbers"),
], ids=["no-opacity", "no-color", "unknown-key", "opacity-numbers", "color-string-entry"])
def test_bad_transfer_function_dict(data, match):
    with pytest.raises(ValueError, match=match):
        TransferFunction.from_dict(data)


# ---- RenderSettings ---------------------------------------------------------------

SETTINGS_BAD = [
    ("sort-unknown", dict(sort="depth"), "sort must be one of .* got 'depth'"),
    ("bins-one", dict(table_scalar_bins=1), r"table_scalar_bins must be \"auto\" or an integer in \[2, 2048\], got 1"),
    ("bins-huge", dict(table_scalar_bins=100000), r"table_scalar_bins must be \"auto\" or an integer"),
    ("bins-fraction", dict(table_scalar_bins=2.5), r"table_scalar_bins must be \"auto\" or an integer.*2.5"),
    ("bins-bool", dict(table_scalar_bins=True), r"table_scalar_bins must be \"auto\" or an integer.*True"),
    ("bins-string", dict(table_scalar_bins="256"), r"table_scalar_bins must be \"auto\" or an integer.*'256'"),
    ("slices-zero", dict(table_thickness_slices=0), r"table_thickness_slices must be \"auto\" or an integer in \[1, 256\], got 0"),
    ("bins-other-word", dict(table_scalar_bins="Auto"), r"table_scalar_bins must be \"auto\" or an integer.*'Auto'"),
    ("tolerance-zero", dict(table_tolerance=0), r"table_tolerance must be a number in \(0, 1\], got 0"),
    ("tolerance-nan", dict(table_tolerance=NAN), "table_tolerance must be a number in"),
    ("tolerance-string", dict(table_tolerance="1e-4"), "table_tolerance must be a number.*'1e-4'"),
    ("log-base-one", dict(table_log_base=1), r"table_log_base must be in \(1, 100\], got 1"),
    ("log-base-nan", dict(table_log_base=NAN), "table_log_base must be in"),
    ("dtype-float16", dict(table_dtype="float16"), "table_dtype must be one of .* got 'float16'"),
    ("encoding-unknown", dict(table_encoding="log"), "table_encoding must be one of .* got 'log'"),
]


@pytest.mark.parametrize("kwargs,match", [c[1:] for c in SETTINGS_BAD], ids=[c[0] for c in SETTINGS_BAD])
def test_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RenderSettings(**kwargs)


def test_settings_from_dict_unknown_key():
    with pytest.raises(ValueError, match=r"unknown settings keys \['speed'\]"):
        RenderSettings.from_dict({"speed": 1})


# ---- Clip -------------------------------------------------------------------------

@pytest.mark.parametrize("normal,unit", [
    ((1e300, 1e300, 1e300), (1 / math.sqrt(3),) * 3),  # its squared norm overflows
    ((1.7e308, -1.7e308, 0), (1 / math.sqrt(2), -1 / math.sqrt(2), 0)),
    ((1e-200, 0, 0), (1.0, 0.0, 0.0)),  # its squared norm underflows to 0
    ((5e-324, 5e-324, 0), (1 / math.sqrt(2), 1 / math.sqrt(2), 0)),  # subnormal
    ((0, 0, 2), (0.0, 0.0, 1.0)),
], ids=["huge", "near-max", "tiny", "subnormal", "plain"])
def test_clip_plane_normalises_any_finite_normal(normal, unit):
    with np.errstate(all="raise"):
        clip = Clip.plane((0.0, 0.0, 0.0), normal)
    nx, ny, nz, w = clip.planes[0]
    assert (nx, ny, nz) == pytest.approx(unit, rel=1e-15, abs=1e-300) and w == 0
    # The plane still cuts: the side the normal points into is kept, the other is not.
    assert clip.contains([unit, tuple(-v for v in unit)]).tolist() == [True, False]


@pytest.mark.parametrize("origin,normal,match", [
    ((0, 0, 0), (0, 0, 0), r"normal must not be the zero vector, got \(0\.0, 0\.0, 0\.0\); give the direction"),
    ((0, 0, 0), (-0.0, 0, 0), "normal must not be the zero vector"),
    ((0, 0, 0), (NAN, 0, 1), r"normal must be finite, got \(nan, 0\.0, 1\.0\)"),
    ((0, 0, 0), (math.inf, 0, 0), "normal must be finite"),
    ((1.5e308, 1.5e308, 1.5e308), (1, 1, 1), "beyond float64's range .* give an origin nearer the data"),
], ids=["zero", "negative-zero", "nan", "inf", "distance-overflows"])
def test_clip_plane_refuses_only_zero_or_non_finite(origin, normal, match):
    with pytest.raises(ValueError, match=match):
        Clip.plane(origin, normal)


def test_clip_rows_are_normalised_safely():
    assert Clip(((1e-200, 0, 0, 2e-200),)).planes == ((1.0, 0.0, 0.0, 2.0),)
    assert Clip(((1e300, 0, 0, -3e300),)).planes == ((1.0, 0.0, 0.0, -3.0),)
    with pytest.raises(ValueError, match="plane 0 has a zero normal.*give a normal that is not"):
        Clip(((0, 0, 0, 1),))
    with pytest.raises(ValueError, match=r"plane 0 .* lies beyond float64's range .* overflows"):
        Clip(((1e-300, 0, 0, 1e300),))


@pytest.mark.parametrize("up,want", [((0, 1e-200, 0), (0.0, 1.0, 0.0)), ((1e300, 1e300, 0), (2**-0.5, 2**-0.5, 0.0)),
                                     ((0, 2, 0), (0.0, 2.0, 0.0))], ids=["tiny", "huge", "plain-kept-as-given"])
def test_camera_view_up_of_any_finite_length_is_kept(up, want):
    """As Clip.plane: a view up whose squared length leaves float64's range is not "the
    zero vector" (tiny) nor lost to an overflow (huge); ordinary ones are kept as given."""
    with np.errstate(all="raise"):
        cam = Camera(position=(0, 0, 5), view_up=up)
        assert cam.view_up == pytest.approx(want, rel=1e-15)
        assert np.all(np.isfinite(cam.view_matrix()))

"""Early ray termination of the volume ray caster as an error bound (issue 37, item 6).

An emission-absorption ray stops once its transmittance ``1 - alpha`` is at most
``RaycastSettings.termination_tolerance``; colours are at most 1, so what the rest of the ray
would have added is at most that tolerance in any premultiplied channel, and never
negative. The GPU (shaders/raycast.frag) and the CPU reference stop by the same rule.

Tolerances, stated and justified:

* the stop alone: ``0 <= full - stopped <= tolerance`` per channel, plus 2e-6 for float32
  (an RGBA32F target accumulating a few hundred pieces near 1);
* the defaults against the fine reference (1/16-voxel pieces, no termination): at most half
  an 8-bit step (1/510 = 1.96e-3), on the small analytic volume and on the CT head alike.
  Measured on llvmpipe at 48x48: 1.57e-3 and 1.41e-3, the same as without termination (what
  is left is the step, the table and float32); the old stop at alpha 0.998 gave 1.99e-3
  and 1.83e-3.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tetvr import Camera, TransferFunction
from tetvr.gl.raycaster import Raycaster
from tetvr.io.volume_file import read_volume
from tetvr.reference.volume import TERMINATION_TOLERANCE, RaycastSettings, render_volume_reference
from tetvr.volume.volume import Volume

from .conftest import gl_object, save_failure, shared_file

HALF_STEP = 0.5 / 255
FLOAT32_SLACK = 2e-6
FULL = RaycastSettings(termination_tolerance=0.0)


@pytest.fixture(scope="module")
def raycaster():
    yield from gl_object(Raycaster, "no OpenGL context")


def _blob() -> tuple[Volume, TransferFunction, Camera]:
    """A Gaussian blob whose core is opaque within a few voxels: most rays through it stop."""
    n = 24
    g = np.linspace(-1.0, 1.0, n)
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    s = np.exp(-((x - 0.1) ** 2 + (y + 0.15) ** 2 + z**2) / 0.3).astype(np.float32)
    vol = Volume.from_array(s, spacing=(2 / (n - 1),) * 3, origin=(-1, -1, -1))
    tf = TransferFunction(color=((0, 0.1, 0.2, 0.9), (0.5, 0.9, 0.6, 0.2), (1, 1, 1, 0.8)),
                          opacity=((0, 0), (0.2, 0.05), (0.6, 0.6), (1, 0.95)), unit_distance=0.1)
    return vol, tf, Camera.fit(vol, direction=(-0.4, -0.3, -1.0))


def _slab(tolerance: float) -> tuple[Volume, TransferFunction, Camera]:
    """A deliberately long box seen end on: 79 voxels of a red medium whose transmittance
    falls to ``tolerance / 2``, then 16 voxels of an opaque green one. A ray that stops
    where the bound allows (about 73 voxels in) composites no green at all; one marched to
    the far end shows about ``tolerance / 4`` of it."""
    front = 79
    data = np.zeros((4, 4, front + 17), np.float32)  # (z, y, x): the box is 95 long in x
    data[..., front + 1:] = 1.0
    vol = Volume.from_array(data)
    tau = math.log(2.0 / tolerance) / front  # per unit length: T = tolerance / 2 at the green
    red = 1.0 - math.exp(-tau)  # opacity per unit_distance 1
    tf = TransferFunction(color=((0, 1, 0, 0), (0.5, 1, 0, 0), (1, 0, 1, 0)),
                          opacity=((0, red), (0.5, red), (1, 0.9)), unit_distance=1.0)
    cam = Camera(position=(-20.0, 1.5, 1.5), focal_point=(0.0, 1.5, 1.5), view_up=(0, 0, 1),
                 parallel_projection=True, parallel_scale=1.0, clipping_range=(1.0, 200.0))
    return vol, tf, cam


# ---------------------------------------------------------------------------------
# The setting
# ---------------------------------------------------------------------------------


def test_the_default_bounds_the_error_below_half_an_8_bit_step_with_margin():
    assert RaycastSettings().termination_tolerance == TERMINATION_TOLERANCE
    assert 0 < TERMINATION_TOLERANCE <= HALF_STEP / 4  # the margin: a quarter of half a step, or less


def test_termination_is_the_compatible_alias_of_the_tolerance():
    assert RaycastSettings(termination=1.0) == RaycastSettings(termination_tolerance=0.0)
    assert RaycastSettings(termination=0.998) == RaycastSettings(termination_tolerance=0.002)
    assert RaycastSettings(termination_tolerance=0.01).termination == pytest.approx(0.99)
    assert dataclasses.replace(FULL, termination=0.9).termination_tolerance == pytest.approx(0.1)
    assert dataclasses.replace(RaycastSettings(termination=0.9), mode="mip").termination_tolerance == pytest.approx(0.1)
    # Saved settings: the tolerance is written; an old file's "termination" still loads.
    s = RaycastSettings(termination_tolerance=1e-3)
    assert "termination" not in s.to_dict() and RaycastSettings.from_dict(s.to_dict()) == s
    assert RaycastSettings.from_dict({"termination": 0.99}).termination_tolerance == pytest.approx(0.01)


@pytest.mark.parametrize("kwargs,match", [
    (dict(termination_tolerance=-1e-3), r"termination_tolerance must be in \[0, 1\)"),
    (dict(termination_tolerance=1.0), r"termination_tolerance must be in \[0, 1\)"),
    (dict(termination_tolerance=float("nan")), "termination_tolerance"),
    (dict(termination=0.0), "termination must be"),
])
def test_bad_tolerances_are_rejected(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RaycastSettings(**kwargs)


# ---------------------------------------------------------------------------------
# The CPU reference stops by the same rule
# ---------------------------------------------------------------------------------


@pytest.mark.parametrize("tolerance", [TERMINATION_TOLERANCE, 0.05])
def test_the_reference_stops_within_the_bound(tolerance):
    vol, tf, cam = _blob()
    full = render_volume_reference(vol, cam, tf, (24, 24), settings=FULL).astype(np.float64)
    cut = render_volume_reference(vol, cam, tf, (24, 24),
                                  settings=RaycastSettings(termination_tolerance=tolerance)).astype(np.float64)
    assert full[..., 3].max() > 1 - tolerance  # some rays get opaque enough to stop
    drop = full - cut
    assert drop.min() >= -FLOAT32_SLACK and drop.max() <= tolerance + FLOAT32_SLACK
    assert drop.max() > tolerance / 100  # it did stop: the drop is not rounding


# ---------------------------------------------------------------------------------
# The GPU: where it stops, and the error against the fine reference
# ---------------------------------------------------------------------------------


@pytest.mark.gl
def test_an_opaque_slab_is_not_marched_to_its_far_end(raycaster):
    tol = TERMINATION_TOLERANCE
    vol, tf, cam = _slab(tol)
    size = (4, 4)
    stopped = raycaster.render(vol, cam, tf, size=size)
    full = raycaster.render(vol, cam, tf, size=size, settings=FULL)
    ref_stopped = render_volume_reference(vol, cam, tf, size)
    ref_full = render_volume_reference(vol, cam, tf, size, settings=FULL)
    # Marched to the end, the green behind shows (transmittance tol/2 in front of it) ...
    assert full[..., 1].min() > tol / 8 and ref_full[..., 1].min() > tol / 8
    np.testing.assert_allclose(full[..., 1], ref_full[..., 1], rtol=0.05)
    # ... stopped by the bound, no ray reached it, on the GPU and in the reference alike,
    assert not stopped[..., 1].any() and not ref_stopped[..., 1].any()
    # and each stopped where the bound allows it, not before.
    assert (1.0 - stopped[..., 3]).max() <= tol and (1.0 - ref_stopped[..., 3]).max() <= tol
    assert np.abs(stopped - full).max() <= tol + FLOAT32_SLACK


@pytest.mark.gl
def test_the_defaults_against_the_fine_reference_on_a_small_volume(raycaster):
    vol, tf, cam = _blob()
    size = (48, 48)
    got = raycaster.render(vol, cam, tf, size=size)
    full = raycaster.render(vol, cam, tf, size=size, settings=FULL)
    want = render_volume_reference(vol, cam, tf, size, settings=FULL, fine_step=float(vol.spacing.min()) / 16)
    assert want[..., 3].max() > 1 - TERMINATION_TOLERANCE  # termination engages on this scene
    drop = full.astype(np.float64) - got
    assert drop.min() >= -FLOAT32_SLACK and drop.max() <= TERMINATION_TOLERANCE + FLOAT32_SLACK
    worst = float(np.abs(got.astype(np.float64) - want).max())
    if worst > HALF_STEP:
        where = save_failure("termination_blob_defaults", got, want)
        pytest.fail(f"max per-pixel error {worst:.5f} against the fine reference (bar {HALF_STEP:.5f}); "
                    f"images in {where}")


def _ct_head() -> tuple[Volume, TransferFunction, Camera]:
    path = shared_file("volumes/headsq/quarter.nhdr")
    try:
        vol = read_volume(path)
    except ImportError as exc:  # NRRD goes through SimpleITK, an optional dependency
        pytest.skip(f"cannot read {path.name}: {exc}")
    tf = TransferFunction(color=((0, 0.2, 0.1, 0.05), (600, 0.9, 0.5, 0.3), (1200, 1, 0.9, 0.8), (3926, 1, 1, 1)),
                          opacity=((0, 0), (500, 0), (700, 0.3), (1000, 0.05), (1150, 0.0), (1300, 0.6), (3926, 0.9)),
                          unit_distance=10.0)
    c, r = vol.center, vol.diagonal / 2  # bench/volume_accuracy.py's view
    d = np.array([-0.3, 1.0, -0.4]) / np.linalg.norm([-0.3, 1.0, -0.4])
    dist = r / math.sin(math.radians(15))
    cam = Camera(position=tuple(c - d * dist), focal_point=tuple(c), view_up=(0, 0, -1), view_angle=30.0,
                 clipping_range=(dist - 1.5 * r, dist + 1.5 * r))
    return vol, tf, cam


@pytest.mark.gl
@pytest.mark.data
def test_the_defaults_against_the_fine_reference_on_the_ct_head(raycaster):
    vol, tf, cam = _ct_head()
    size = (48, 48)
    got = raycaster.render(vol, cam, tf, size=size)
    full = raycaster.render(vol, cam, tf, size=size, settings=FULL)
    want = render_volume_reference(vol, cam, tf, size, settings=FULL, fine_step=float(vol.spacing.min()) / 16)
    assert want[..., 3].max() > 1 - TERMINATION_TOLERANCE
    drop = full.astype(np.float64) - got
    assert drop.min() >= -FLOAT32_SLACK and drop.max() <= TERMINATION_TOLERANCE + FLOAT32_SLACK
    worst = float(np.abs(got.astype(np.float64) - want).max())
    print(f"CT head, defaults: max per-pixel error {worst:.5f} against the fine reference")
    if worst > HALF_STEP:
        where = save_failure("termination_ct_head_defaults", got, want)
        pytest.fail(f"max per-pixel error {worst:.5f} against the fine reference (bar {HALF_STEP:.5f}); "
                    f"images in {where}")

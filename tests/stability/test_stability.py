"""Where projected tetrahedra usually fail: every case renders with the default settings,
finite, and within a stated distance of the exact reference.

Bounds (PSNR on premultiplied RGB):
- 40 dB everywhere by default: the acceptance bar of the image tests.
- ``edge_on``: pixel centres lying exactly on a silhouette edge whose face contains the
  view direction have a finite chord in the reference and no coverage under GL's
  top-left rule (a measure-zero set that the symmetric setup hits); still >= 40 dB.
- ``interlocking_rings``: 70 dB. The default sort for this non-convex mesh is ``xmpvo``,
  whose boundary rays order the two rings wherever they overlap, so what remains is the
  table's error (89 dB measured); centroid order and MPVONC give about 58 dB here.
- ``transparent_tf``: exactly zero. ``opaque_tf``: alpha reaches 1 - 1e-6 per unit distance.
The weaker method variants' errors on the same cases are measured, not asserted, by
``bench/speed_accuracy.py``.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from tetvr.core.image import psnr
from tetvr.order.method import choose
from tetvr.order.walkable import walk_check
from tetvr.reference.tets import render_reference
from tetvr.scene.stability import CASES, case

from ..conftest import save_failure

pytestmark = pytest.mark.gl

SIZE = (96, 96)
MIN_PSNR = {name: 40.0 for name in CASES} | {"interlocking_rings": 70.0}
#: Max per-pixel error and pixels beyond 1/255 allowed, both methods (measured at 96x96;
#: the defaults are 1/255 and none). The exceptions are the documented weak spots
#: (docs/limits.md): a silhouette edge seen exactly end-on (pixel centres on it: 0.41 on 11
#: pixels under projected tetrahedra, on 15 under tet marching, whose float64 ray-triangle
#: test there decides by rounding where the reference perturbs the ray symbolically) and the
#: tangled slivers under projected tetrahedra (0.024 on 445). The opacity
#: spikes and the step meet the default bar with the warped table (spike 9.6e-4, step
#: 6.6e-4, the spike on the graded mesh 7.1e-4).
MAX_ERROR = {"edge_on": (0.45, 16), "slivers": (0.03, 500)}
#: Bars that only projected tetrahedra need (tet marching meets the defaults there): the
#: pixel whose centre an edge along the ray projects onto (0.58 on 1 pixel: the fan's
#: triangles there have zero area), and tets beside the eye, whose part in view is drawn
#: through the exact per-fragment path (0.014 on 332 pixels).
MAX_ERROR_PROJECTED = {"edge_along_ray": (0.6, 1), "beside_the_eye": (0.02, 400)}


@pytest.mark.parametrize("name", sorted(CASES))
def test_case_against_reference(renderer, name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # dropped zero-volume tets are reported, not errors
        c = case(name)
    if renderer.settings.method == "raymarch" and not walk_check(c.mesh).walkable:
        # A tangled mesh (overlapping cells): tet marching refuses it, saying why, and
        # method="auto" renders it by projected tetrahedra (the other parameter of this test).
        with pytest.raises(ValueError, match="folded"):
            renderer.render(c.mesh, c.camera, c.tf, size=SIZE)
        with pytest.warns(UserWarning, match="folded"):
            assert choose(dataclasses.replace(renderer.settings, method="auto"), c.mesh) == "projected"
        return
    got = renderer.render(c.mesh, c.camera, c.tf, size=SIZE)
    assert np.all(np.isfinite(got)), f"{name}: NaN/Inf in the image"
    assert got[..., 3].min() >= 0.0 and got[..., 3].max() <= 1.0 + 1e-6
    want = render_reference(c.mesh, c.camera, c.tf, SIZE)
    if name == "transparent_tf":
        assert np.all(got == 0.0)
        return
    assert want[..., 3].max() > 0.3, f"{name}: the reference image is nearly empty; the case tests nothing"
    value = psnr(got, want)
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    max_error, max_count = MAX_ERROR.get(name, (1 / 255, 0))
    if renderer.settings.method == "projected":
        max_error, max_count = MAX_ERROR_PROJECTED.get(name, (max_error, max_count))
    if value < MIN_PSNR[name] or err.max() > max_error or np.count_nonzero(err > 1 / 255) > max_count:
        where = save_failure(f"stability_{name}", got, want)
        pytest.fail(f"{name} ({c.what}): PSNR {value:.1f} dB (bar {MIN_PSNR[name]}), max error {err.max():.3g} "
                    f"(bar {max_error:.3g}), {np.count_nonzero(err > 1 / 255)} pixels beyond 1/255 (bar {max_count}) "
                    f"(images in {where})")

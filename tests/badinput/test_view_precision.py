"""Views float32 cannot resolve are refused per view, with the reason; views it can are
rendered right (checked against the reference with a max per-pixel error)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import tetvr
from tetvr import Camera, RenderSettings, TetMesh, TransferFunction
from tetvr.mesh import synthetic
from tetvr.order.precision import check_view_precision
from tetvr.reference.tets import render_reference

pytestmark = pytest.mark.gl


def _tf(mesh: TetMesh, unit: float) -> TransferFunction:
    lo, hi = mesh.scalar_range
    return TransferFunction.preset("viridis", (lo, hi if hi > lo else lo + 1), opacity=[(0, 0.5), (1, 0.9)],
                                   unit_distance=unit)


def _small_cube_far_from_centre(offset: float, size: float) -> TetMesh:
    """A cube of edge ``size`` at ``offset`` from the centre of a mesh whose other cube is
    far away: the small cells sit far from the bounding-box centre."""
    small, big = synthetic.cube(2), synthetic.cube(1)
    a = TetMesh(small.points * size, small.tets, small.scalars)
    b = TetMesh(big.points + np.array([2 * offset, 0.0, 0.0]), big.tets, big.scalars)
    return synthetic.merge(a, b)


@pytest.mark.parametrize("method", ["projected", "raymarch"])
@pytest.mark.parametrize("case", ["parallel_scale", "view_angle", "telephoto", "unused_far_point", "small_far_cells"])
def test_unresolvable_views_are_refused_with_the_reason(case, method):
    mesh = synthetic.cube(2)
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0))
    if case == "parallel_scale":
        cam = dataclasses.replace(Camera.fit(mesh, parallel=True), parallel_scale=1e-10)
    elif case == "view_angle":
        cam = dataclasses.replace(cam, view_angle=1e-7)
    elif case == "telephoto":  # 1e7 extents away, the mesh filling the view
        d = 1e7
        cam = Camera(position=(0.0, 0.0, d), focal_point=(0.0, 0.0, 0.0),
                     view_angle=float(np.degrees(2 * np.arctan(0.8 / d))), clipping_range=(d - 2, d + 2))
    elif case == "unused_far_point":
        mesh = TetMesh(np.vstack([mesh.points, [[1e16, 0.0, 0.0]]]), mesh.tets, np.append(mesh.scalars, 0.0))
    else:  # 1e-4 cells 3e4 from the centre, seen close up
        mesh = _small_cube_far_from_centre(3e4, 1e-4)
        cam = Camera(position=(0.0, 0.0, 5e-4), focal_point=(0.0, 0.0, 0.0), view_angle=30,
                     clipping_range=(1e-5, 1e-3))
    with pytest.raises(ValueError, match="float32 on the GPU cannot resolve this view"):
        check_view_precision(mesh, cam, (64, 64))
    with tetvr.Renderer(RenderSettings(method=method)) as r:
        with pytest.raises(ValueError, match="resolved only to"):
            r.render(mesh, cam, _tf(mesh, 0.5), size=(64, 64))
        # The renderer is still usable afterwards.
        ok = synthetic.cube(2)
        assert r.render(ok, Camera.fit(ok), _tf(ok, 0.5), size=(16, 16))[..., 3].max() > 0.1


@pytest.mark.parametrize("method", ["projected", "raymarch"])
def test_small_cells_far_from_centre_within_the_limit_render_right(method):
    """The same layout at an offset float32 still resolves: accepted, and right."""
    mesh = _small_cube_far_from_centre(30.0, 1e-2)
    cam = Camera(position=(0.003, 0.002, 0.05), focal_point=(0.0, 0.0, 0.0), view_angle=30,
                 clipping_range=(1e-3, 0.1))
    check_view_precision(mesh, cam, (64, 64))
    tf = _tf(mesh, 0.01)
    with tetvr.Renderer(RenderSettings(method=method)) as r:
        got = r.render(mesh, cam, tf, size=(64, 64))
    want = render_reference(mesh, cam, tf, (64, 64))
    assert want[..., 3].max() > 0.2
    err = np.abs(got - want).max(axis=-1)
    assert err.max() < 1 / 255, err.max()


def test_subnormal_field_is_refused_by_name():
    """A field in [0, 1e-39] (subnormal in float32) rendered 9-13 dB wrong without an error."""
    mesh = synthetic.cube(2)
    sub = mesh.with_scalars((mesh.scalars - mesh.scalars.min()) / np.ptp(mesh.scalars) * 1e-39)
    tf = TransferFunction.preset("viridis", sub.scalar_range, opacity=[(0, 0.2), (1, 0.9)], unit_distance=0.3)
    with tetvr.Renderer() as r:
        with pytest.raises(ValueError, match="float32 cannot resolve"):
            r.render(sub, Camera.fit(mesh), tf, size=(16, 16))


def test_control_points_closer_than_float_slopes_allow_are_refused():
    """Control points 5e-324 apart gave infinite slopes in the table build: 16-25 dB."""
    with pytest.raises(ValueError, match="5e-324 are 4.94e-324 apart"):
        TransferFunction(color=((-1, 0, 0, 1), (0.0, 0, 0, 1), (5e-324, 1, 0, 0), (1, 1, 0, 0)),
                         opacity=((-1, 0.2), (1, 0.9)), unit_distance=0.3)
    # A steep but representable step is kept.
    TransferFunction(color=((-1, 0, 0, 1), (0.0, 0, 0, 1), (1e-9, 1, 0, 0), (1, 1, 0, 0)),
                     opacity=((-1, 0.2), (1, 0.9)), unit_distance=0.3)

"""Rays that lie exactly in a face's plane or run through an edge: the walk decides them as
the reference does (tetvr.reference.segments: the ray moved by (e, e^2, e^3) along the eye's
x, y and z), so an axis-aligned view of an axis-aligned mesh, the eye on its node lines, is
drawn within 1/255 of the reference at every pixel. Rays in the plane of a boundary face
are in the mesh or out of it exactly where the reference has them; before the rule, whole
columns of such pixels were drawn where the reference has nothing (and the reverse), 1.0 off.
Rays within a rounding of an interior face's plane may leave tets by faces seen edge-on,
whose exits lie behind their entries: the frame's check traces them again (tetvr.gl.selfcheck)."""

from __future__ import annotations

import numpy as np
import pytest

import tetvr
from tetvr.core.camera import Camera
from tetvr.gl.renderer import Renderer
from tetvr.mesh import synthetic

SIZE = (33, 33)  # odd: the centre column and row of pixels lie on the eye's lines


@pytest.fixture(scope="module")
def scene():
    mesh = synthetic.cube(3, rotate=False)  # nodes at -1/2, -1/6, 1/6, 1/2
    tf = tetvr.TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.9, unit_distance=0.2)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as renderer:
        yield mesh, tf, renderer


def _camera(eye_x: float, eye_y: float, axis: int, parallel: bool) -> Camera:
    perm = [(0, 1, 2), (1, 2, 0), (2, 0, 1)][axis]
    pos = np.array([eye_x, eye_y, 2.0])[list(perm)]
    focal = np.array([eye_x, eye_y, 1.0])[list(perm)]
    up = np.array([0.0, 1.0, 0.0])[list(perm)]
    return Camera(position=tuple(pos), focal_point=tuple(focal), view_up=tuple(up), parallel_projection=parallel,
                  parallel_scale=0.8, view_angle=40.0, clipping_range=(0.5, 4.0))


# The eye on the lines of the mesh's boundary planes (x = +-1/2: the rays of a column lie
# in a boundary face's plane, on the side the reference counts in or out) and of its
# interior planes; looking along each axis.
CASES = [(x, y, axis, parallel) for (x, y) in ((0.5, 0.0), (-0.5, 0.0), (0.5, 0.5), (-0.5, -0.5), (-0.5, 0.5),
                                                 (1 / 6, 0.5), (0.5, -1 / 6))
         for axis in (0, 1) for parallel in (True, False)]
# Perspective views whose diagonal pixel rays lie in the cells' diagonal (interior) planes
# to a rounding: the walk leaves tets by faces seen edge-on, whose points' weights are
# rounding (0.006 off on a pixel before the frame's check traced such rays again).
CASES += [(x, y, axis, False) for (x, y) in ((0.0, 0.0), (1 / 6, -1 / 6), (-1 / 6, -1 / 6), (1 / 6, 1 / 6))
          for axis in (0, 2)]


@pytest.mark.parametrize("eye_x, eye_y, axis, parallel", CASES)
def test_rays_in_face_planes_match_the_reference(scene, eye_x, eye_y, axis, parallel):
    mesh, tf, renderer = scene
    camera = _camera(eye_x, eye_y, axis, parallel)
    ref = tetvr.render(mesh, method="reference", camera=camera, tf=tf, size=SIZE)
    image = renderer.render(mesh, camera, tf, size=SIZE)
    err = np.abs(image.astype(np.float64) - ref).max(axis=2)
    assert err.max() <= 1 / 255, (err.max(), np.argwhere(err > 1 / 255)[:8].tolist())

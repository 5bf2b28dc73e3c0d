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


def _torus_view(eye, direction):
    mesh = synthetic.torus()
    lo, hi = mesh.scalar_range
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    tf = tetvr.TransferFunction.preset("viridis", (lo, hi), opacity=[(0, 0.3), (0.6, 0.9), (1, 0.5)],
                                       unit_distance=0.2 * diag)
    eye, direction = np.asarray(eye), np.asarray(direction)
    camera = Camera(position=tuple(eye), focal_point=tuple(eye + direction), view_angle=70.0,
                    clipping_range=(1e-3 * diag, 5 * diag))
    return mesh, camera, tf


@pytest.mark.parametrize("size", [(48, 48), (192, 192)])
def test_an_entry_face_that_misses_its_ray_is_traced_again(scene, size):
    """A brick of a torus cut into 8 k-d bricks holds faces of almost no area in the cut
    plane; seen at a sine of 0.01-0.02, the rasteriser gives two pixels such a face although
    the ray passes beside it, and its plane puts their entry 1.2 ahead of the mesh (0.51 off
    the reference before the frame's check looked at where an entry lies). The check finds
    the entry point outside the tet's other faces and traces the pixel again."""
    from tetvr.cluster.bricks import kd_bricks

    _, _, renderer = scene
    whole, camera, tf = _torus_view((0.8669012146611078, 0.5930797796801389, -0.007751668365155248),
                                    (-0.4867274699297417, -0.8271525614522157, 0.28091815551656807))
    tree = kd_bricks(whole, 8)
    mesh = tree.brick_mesh(next(b for b in tree.bricks() if b.index == 4))
    ref = tetvr.render(mesh, method="reference", camera=camera, tf=tf, size=size)
    image = renderer.render(mesh, camera, tf, size=size)
    err = np.abs(image.astype(np.float64) - ref).max(axis=2)
    assert err.max() <= 1 / 255, (err.max(), np.argwhere(err > 1 / 255)[:8].tolist())


def test_a_ray_a_rounding_outside_a_boundary_face_starts_outside(scene):
    """The eye 4.8e-6 above a torus's flat top, rays running down into it at a few degrees:
    their points on the near plane lie a rounding outside the top faces. Taken as inside
    (the allowance the shared faces get), three pixels started in the mesh 0.01 early and
    were 0.024 off; the boundary faces get no allowance."""
    _, _, renderer = scene
    mesh, camera, tf = _torus_view((1.0965505756209029, 0.2522343023064567, 0.300004827575369),
                                   (0.8883346951822735, 0.13457927370110814, 0.4390329013018265))
    ref = tetvr.render(mesh, method="reference", camera=camera, tf=tf, size=(48, 48))
    image = renderer.render(mesh, camera, tf, size=(48, 48))
    err = np.abs(image.astype(np.float64) - ref).max(axis=2)
    assert err.max() <= 1 / 255, (err.max(), np.argwhere(err > 1 / 255)[:8].tolist())


def test_an_eye_a_rounding_beside_a_brick_enters_it_where_the_reference_does(scene):
    """The eye 1.7e-6 outside a k-d brick of a torus, beside its cut plane: the ray of one
    pixel enters the brick through a face in that plane at a sine of 1e-4, where the face's
    plane gives t only to a few per cent. The entry took the last of the tet's other planes
    instead, the near plane, and drew a chord 3.5x the reference's (0.012 off, and so the
    bricks' composite). The face's points seen across the ray give the entry as the walk
    gives an exit."""
    from tetvr.cluster.bricks import kd_bricks

    _, _, renderer = scene
    whole, camera, tf = _torus_view((1.6664372226354807e-06, -0.7233567527734905, -0.1455893318111497),
                                    (0.5139880544361342, 0.23253389934679008, 0.8256780641094532))
    tree = kd_bricks(whole, 8)
    mesh = tree.brick_mesh(next(b for b in tree.bricks() if b.index == 0))
    assert mesh.bounds[1][0] < camera.position[0] < 2e-6  # just outside the brick
    ref = tetvr.render(mesh, method="reference", camera=camera, tf=tf, size=(48, 48))
    image = renderer.render(mesh, camera, tf, size=(48, 48))
    err = np.abs(image.astype(np.float64) - ref).max(axis=2)
    assert err.max() <= 1 / 255, (err.max(), np.argwhere(err > 1 / 255)[:8].tolist())


def test_ray_limits_are_traced_again_where_the_walk_went_wrong(scene):
    """The ray limits fusion reads come from the same walk, and its check: in the brick
    whose sliver face gives two pixels an entry 1.2 ahead of the mesh, the front limits
    are the reference's at every pixel (they were 0.34 where the reference has 1.51)."""
    from tetvr.cluster.bricks import kd_bricks
    from tetvr.reference.segments import pixel_extents

    _, _, renderer = scene
    whole, camera, _ = _torus_view((0.8669012146611078, 0.5930797796801389, -0.007751668365155248),
                                   (-0.4867274699297417, -0.8271525614522157, 0.28091815551656807))
    tree = kd_bricks(whole, 8)
    mesh = tree.brick_mesh(next(b for b in tree.bricks() if b.index == 4))
    front, back = renderer.depth_extent(mesh, camera, size=(48, 48))
    ref_front, ref_back = pixel_extents(mesh, camera, (48, 48), np.arange(48 * 48))
    for got, want in ((front, ref_front), (back, ref_back)):
        want = want.reshape(48, 48)
        assert np.array_equal(np.isfinite(got), np.isfinite(want))
        seen = np.isfinite(want)
        assert np.abs(got[seen] - want[seen]).max() < 1e-4


def test_a_ray_entering_just_past_the_near_plane_is_not_lost(scene):
    """A parallel view from inside a torus's tube: one pixel's ray enters a boundary face
    9e-6 past the near plane. The GL clipped the face at the near plane, and the clipped edge
    passed 5e-4 px from the pixel's centre, which the rasteriser left out; its point on the
    near plane lies outside every cell, so no cell took it either, and the pixel was empty
    where the reference has alpha 0.98 (bench/grazing.py). The faces are drawn unclipped."""
    _, _, renderer = scene
    mesh = synthetic.torus()
    lo, hi = mesh.scalar_range
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    tf = tetvr.TransferFunction.preset("viridis", (lo, hi), opacity=[(0, 0.3), (0.6, 0.9), (1, 0.5)],
                                       unit_distance=0.1 * diag)
    camera = Camera(position=(0.40080417008121944, 0.486981937567868, -0.022118878475444456),
                    focal_point=(0.86613941799463, 1.3187734134541889, -0.324750746744833), view_up=(0.0, 1.0, 0.0),
                    parallel_projection=True, parallel_scale=0.7451174404078864,
                    clipping_range=(0.003725587202039432, 18.62793601019716))
    ref = tetvr.render(mesh, method="reference", camera=camera, tf=tf, size=(40, 40))
    image = renderer.render(mesh, camera, tf, size=(40, 40))
    err = np.abs(image.astype(np.float64) - ref).max(axis=2)
    assert err.max() <= 1 / 255, (err.max(), np.argwhere(err > 1 / 255)[:8].tolist())

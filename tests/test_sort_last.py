"""Sort-last compositing: bricks of one mesh rendered apart, composited, equal the whole.

The renderer is a pure function of (mesh part, camera, settings) -> premultiplied float
image. Two bricks on either side of a plane, seen from one side, are in the same order
along every ray, so the front brick's image over the back brick's is the whole image,
up to float rounding; a brick that travels (pickled, as to another process) renders the
same bits.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from tetvr import Camera, TransferFunction
from tetvr.mesh import synthetic
from tetvr.order.cull import submesh
from tetvr.reference.tets import render_reference

SIZE = (56, 48)


def over(front: np.ndarray, back: np.ndarray) -> np.ndarray:
    """Premultiplied RGBA ``front`` over ``back``."""
    front = front.astype(np.float64)
    return front + (1.0 - front[..., 3:4]) * back


def _bricks(parallel: bool):
    mesh = synthetic.cube(6, rotate=False)  # a grid: the plane x = 0 runs along its faces
    x = mesh.points[mesh.tets].mean(axis=1)[:, 0]
    near, far = submesh(mesh, np.nonzero(x > 0)[0]), submesh(mesh, np.nonzero(x < 0)[0])
    assert near.n_tets + far.n_tets == mesh.n_tets
    lo, hi = mesh.scalar_range
    tf = TransferFunction.preset("viridis", (lo, hi), opacity=[(0, 0.3), (0.6, 0.9), (1, 0.5)], unit_distance=0.5)
    # The eye is on the x > 0 side: every ray crosses the near brick first.
    camera = Camera.fit(mesh, direction=(-1.0, -0.35, -0.25), zoom=1.3, parallel=parallel)
    assert camera.position[0] > 0.5
    return mesh, near, far, tf, camera


@pytest.mark.parametrize("parallel", [False, True])
def test_reference_bricks_composite_to_the_whole(parallel):
    mesh, near, far, tf, camera = _bricks(parallel)
    whole = render_reference(mesh, camera, tf, SIZE)
    parts = over(render_reference(near, camera, tf, SIZE), render_reference(far, camera, tf, SIZE))
    assert whole[..., 3].max() > 0.8 and render_reference(far, camera, tf, SIZE)[..., 3].max() > 0.3
    assert np.abs(parts - whole).max() < 3e-7  # the reference returns float32: a few ulps


@pytest.mark.gl
@pytest.mark.parametrize("parallel", [False, True])
def test_gpu_bricks_composite_to_the_whole(renderer, parallel):
    mesh, near, far, tf, camera = _bricks(parallel)
    whole = renderer.render(mesh, camera, tf, size=SIZE)
    front = renderer.render(near, camera, tf, size=SIZE)
    back = renderer.render(far, camera, tf, size=SIZE)
    assert back[..., 3].max() > 0.3 and front[..., 3].max() > 0.3
    parts = over(front, back)
    # float32 blending in a different association: rounding only
    assert np.abs(parts - whole).max() < 1e-6
    # and both are as close to the reference as the whole is
    ref = render_reference(mesh, camera, tf, SIZE)
    assert abs(np.abs(parts - ref).max() - np.abs(whole - ref).max()) < 2e-6


@pytest.mark.gl
def test_a_pickled_brick_renders_the_same_bits(renderer):
    _, near, _, tf, camera = _bricks(False)
    moved = pickle.loads(pickle.dumps(near))
    assert moved.max_edge == near.max_edge  # the whole mesh's, which sets the table
    assert np.array_equal(renderer.render(moved, camera, tf, size=SIZE), renderer.render(near, camera, tf, size=SIZE))

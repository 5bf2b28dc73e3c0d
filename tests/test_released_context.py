"""A Raycaster whose borrowed context was released says so (it used to raise
``AttributeError: 'InvalidObject' object has no attribute '__enter__'``), like a
released Renderer does; releasing it then is harmless."""

from __future__ import annotations

import numpy as np
import pytest

from tetvr import Camera, TransferFunction
from tetvr.gl import Raycaster, Renderer
from tetvr.gl.context import create_context
from tetvr.volume.volume import Volume

pytestmark = pytest.mark.gl


def _scene() -> tuple[Volume, Camera, TransferFunction]:
    vol = Volume.from_array(np.linspace(0, 1, 4**3, dtype=np.float32).reshape(4, 4, 4))
    cam = Camera(position=(8.0, 6.0, 5.0), focal_point=(1.5, 1.5, 1.5), view_up=(0.0, 0.0, 1.0),
                 clipping_range=(1.0, 20.0))
    return vol, cam, TransferFunction.preset("viridis", vol.scalar_range, opacity=0.5, unit_distance=1.0)


def test_raycaster_on_a_context_released_by_its_owner():
    vol, cam, tf = _scene()
    r = Renderer()
    rc = Raycaster(ctx=r.ctx)
    rc.render(vol, cam, tf, size=(8, 8))
    r.release()  # the owner goes first: the raycaster's GL objects go with the context
    for use in (lambda: rc.render(vol, cam, tf, size=(8, 8)), lambda: rc._program("mip")):
        with pytest.raises(RuntimeError, match=r"OpenGL context of this Raycaster has been released.*borrowed"):
            use()
    rc.release()  # nothing left to release, and no error
    rc.release()
    with pytest.raises(RuntimeError, match="this Raycaster has been released"):
        rc.render(vol, cam, tf, size=(8, 8))


def test_raycaster_on_a_context_released_by_hand():
    vol, cam, tf = _scene()
    ctx = create_context()
    rc = Raycaster(ctx=ctx)
    ctx.release()
    with pytest.raises(RuntimeError, match="context of this Raycaster has been released"):
        rc.render(vol, cam, tf, size=(8, 8))
    rc.release()


def test_raycaster_refuses_a_released_context():
    ctx = create_context()
    ctx.release()
    with pytest.raises(RuntimeError, match="ctx has been released"):
        Raycaster(ctx=ctx)


def test_renderer_released_twice_and_used_after():
    r = Renderer()
    r.release()
    r.release()
    with pytest.raises(RuntimeError, match="this Renderer has been released"):
        r.depth_extent(None, None, size=(8, 8))  # type: ignore[arg-type]

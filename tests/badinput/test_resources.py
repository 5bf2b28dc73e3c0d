"""Bounded resources: many frames from one Renderer, and many Renderers made and
released, leave host memory flat and the GL error state clean.

RSS is read from /proc/self/statm after a warm-up (shader compilation, first table,
Mesa's own caches). The allowance, 50 MiB, is generous: a leak of one 32x32 RGBA32F
target or one 64x64x9 float table per frame would pass 50 MiB long before 200 frames
(16 KiB and 600 KiB each); what it tolerates is allocator noise.
"""

from __future__ import annotations

import gc
import sys

import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.gl import Renderer
from tetvr.render import default_transfer_function

from ._util import rss_mb

pytestmark = [pytest.mark.gl, pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")]

SLACK_MB = 50.0
SETTINGS = RenderSettings(table_scalar_bins=64, table_thickness_slices=8)


def test_two_hundred_frames_from_one_renderer():
    mesh = synthetic.cube(2)
    tf = default_transfer_function(mesh)
    tfs = [tf, TransferFunction.preset("hot", mesh.scalar_range, opacity=0.7, unit_distance=tf.unit_distance)]
    cams = [Camera.fit(mesh, direction=(np.cos(a), np.sin(a), -0.5)) for a in np.linspace(0, 2 * np.pi, 7)]
    sizes = [(32, 32), (24, 40)]
    with Renderer(SETTINGS) as r:
        for i in range(20):  # warm-up: every program, table and target in use below
            r.render(mesh, cams[i % 7], tfs[i % 2], size=sizes[i % 2])
        gc.collect()
        start = rss_mb()
        for i in range(200):
            img = r.render(mesh, cams[i % 7], tfs[i % 2], size=sizes[i % 2])
            assert r.ctx.error == "GL_NO_ERROR", f"frame {i}"
            if i % 50 == 0:
                assert np.all(np.isfinite(img))
        gc.collect()
        grown = rss_mb() - start
    assert grown < SLACK_MB, f"RSS grew {grown:.1f} MiB over 200 frames"


def test_errors_in_a_loop_do_not_leak():
    mesh = synthetic.single_tet()
    cam, tf = Camera.fit(mesh), default_transfer_function(mesh)
    with Renderer(SETTINGS) as r:
        r.render(mesh, cam, tf, size=(16, 16))
        start = rss_mb()
        for i in range(200):
            with pytest.raises(ValueError):
                r.render(mesh, cam, tf, size=(0, 16) if i % 2 else (16, 10**6))
            assert r.ctx.error == "GL_NO_ERROR"
        r.render(mesh, cam, tf, size=(16, 16))
        assert r.ctx.error == "GL_NO_ERROR"
        grown = rss_mb() - start
    assert grown < SLACK_MB


def test_twenty_renderers_made_and_released():
    mesh = synthetic.single_tet((0.0, 1.0, 2.0, 3.0))
    cam, tf = Camera.fit(mesh), default_transfer_function(mesh)

    def one() -> np.ndarray:
        with Renderer(SETTINGS) as r:
            img = r.render(mesh, cam, tf, size=(16, 16))
            assert r.ctx.error == "GL_NO_ERROR"
            objects = r._gl_objects()
        assert r._released and all(type(o.mglo).__name__ == "InvalidObject" for o in objects)
        return img

    first = one()
    one()
    gc.collect()
    start = rss_mb()
    for _ in range(20):
        assert np.array_equal(one(), first)
    gc.collect()
    grown = rss_mb() - start
    assert grown < SLACK_MB, f"RSS grew {grown:.1f} MiB over 20 renderers"

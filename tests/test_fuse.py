"""Fusion of a tet mesh with a ray-cast volume: each mode against the CPU composite of the
reference images (exact mesh image and depth extents, fine-step volume march).

Tolerance: PSNR >= 40 dB, as for every image test; measured ~78 dB.
"""

from __future__ import annotations

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TetMesh, TransferFunction
from tetvr.mesh import synthetic
from tetvr.fuse import FUSION_MODES, RayTextures, compose, fuse, fuse_reference, over
from tetvr.core.image import psnr
from tetvr.volume.volume import Volume

from .conftest import save_failure

SIZE = (80, 80)


@pytest.fixture(scope="module")
def scene():
    n = 32
    g = np.linspace(-1.0, 1.0, n)
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    vol = Volume.from_array(np.sqrt(x * x + y * y + z * z).astype(np.float32), spacing=(2 / (n - 1),) * 3,
                            origin=(-1, -1, -1))
    base = synthetic.cube(3)
    mesh = TetMesh.from_arrays(base.points * 0.8, base.tets, base.scalars)
    vtf = TransferFunction(color=((0, 1, 0.9, 0.7), (1.8, 0.6, 0.2, 0.1)),
                           opacity=((0, 0.0), (0.6, 0.02), (0.9, 0.3), (1.0, 0.0), (1.8, 0.0)), unit_distance=0.2)
    mtf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.6, unit_distance=0.3)
    cam = Camera.fit(mesh, direction=(-0.4, -0.3, -1), zoom=0.6)
    return mesh, vol, cam, mtf, vtf


@pytest.mark.gl
@pytest.mark.parametrize("mode", FUSION_MODES)
def test_fusion_mode_against_reference(scene, mode):
    mesh, vol, cam, mtf, vtf = scene
    kw = {}
    if mode == "ray_textures":
        end = np.ones(SIZE[::-1])
        end[:, : SIZE[0] // 2] = 0.5
        kw["ray_textures"] = RayTextures(np.zeros(SIZE[::-1]), end)
    got = fuse(mesh, vol, cam, mtf, vtf, size=SIZE, mode=mode, **kw)
    want = fuse_reference(mesh, vol, cam, mtf, vtf, size=SIZE, mode=mode, **kw)
    assert np.all(np.isfinite(got)) and want[..., 3].max() > 0.5
    value = psnr(got, want)
    if value < 40.0:
        where = save_failure(f"fuse_{mode}", got, want)
        pytest.fail(f"{mode}: PSNR {value:.1f} dB < 40 dB (images in {where})")


def test_modes_differ_as_documented():
    """compose() on synthetic images: the rules, independent of any renderer."""
    h, w = 4, 4
    mesh_img = np.zeros((h, w, 4), np.float32)
    mesh_img[1:3, 1:3] = (0.5, 0.0, 0.0, 0.5)
    front = np.full((h, w), np.inf, np.float32)
    back = np.full((h, w), -np.inf, np.float32)
    front[1:3, 1:3], back[1:3, 1:3] = 2.0, 3.0
    calls = []

    def volume(t0, t1, m):
        calls.append((None if t0 is None else np.nan_to_num(t0, nan=-1), None if t1 is None else np.nan_to_num(t1, nan=-1)))
        img = np.zeros((h, w, 4), np.float32)
        img[...] = (0.0, 0.0, 0.3, 0.3)
        return img

    inter = compose("interleave", mesh_img, front, back, volume)
    # Covered pixels: volume before, mesh, volume behind.
    expect = over((0, 0, 0.3, 0.3), over((0.5, 0, 0, 0.5), (0, 0, 0.3, 0.3)))
    np.testing.assert_allclose(inter[1, 1], expect, rtol=1e-6)
    np.testing.assert_allclose(inter[0, 0], (0, 0, 0.3, 0.3))  # no mesh: the whole volume once
    assert calls[0][1][1, 1] == 2.0 and calls[1][0][1, 1] == 3.0  # cut at the mesh's front, then back
    calls.clear()
    ov = compose("overlay", mesh_img, front, back, volume)
    np.testing.assert_allclose(ov[1, 1], over((0.5, 0, 0, 0.5), (0, 0, 0.3, 0.3)), rtol=1e-6)
    calls.clear()
    compose("cutaway", mesh_img, front, back, volume, margin=1)
    t0 = calls[0][0]
    assert t0[0, 0] == 3.0 and t0[1, 1] == 3.0 and t0[3, 3] == 3.0  # the margin reaches the corner pixels
    with pytest.raises(ValueError, match="fusion mode"):
        compose("blend", mesh_img, front, back, volume)
    with pytest.raises(ValueError, match="ray_textures"):
        compose("ray_textures", mesh_img, front, back, volume)


@pytest.mark.parametrize("bad", [dict(start=np.full((2, 2), 1.5)), dict(start=np.zeros((2, 3))),
                                 dict(mode=np.full((2, 2), 3))])
def test_ray_texture_validation(bad):
    kw = dict(start=np.zeros((2, 2)), end=np.ones((2, 2)))
    kw.update(bad)
    with pytest.raises(ValueError):
        RayTextures(**kw)

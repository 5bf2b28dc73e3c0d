"""A tet-marching frame checks its own walk (march.frag) and traces again, on the CPU,
the pixels whose walk went wrong (tetvr.gl.selfcheck): the image is right and says how
many it traced. A clean mesh gives none."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import tetvr
from tetvr.core.clip import Clip
from tetvr.gl import march_layout, raymarch
from tetvr.gl.renderer import Renderer
from tetvr.mesh import synthetic
from tetvr.reference.tets import render_reference, render_reference_pixels

SIZE = (40, 32)


def _scene(mesh):
    tf = tetvr.TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.8, mesh=mesh)
    return tetvr.Camera.fit(mesh), tf


@pytest.mark.parametrize("inside", [False, True])
def test_a_clean_mesh_has_no_walk_gone_wrong(inside):
    mesh = synthetic.cube(6)
    camera, tf = _scene(mesh)
    if inside:
        camera = tetvr.Camera(position=(0.1, 0.05, 0.0), focal_point=(1.0, 0.3, 0.2), view_angle=70.0)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as r:
        r.render(mesh, camera, tf, size=SIZE)
        assert r._march.last_stats.n_suspect == 0


def test_walks_gone_wrong_are_traced_again_exactly(monkeypatch):
    """The check made to fail (no slack: every exit of the walk by points counts as behind its
    entry): the pixels of those rays are listed and traced again, to the reference's values,
    and the others are left as drawn."""
    mesh = synthetic.cube(4)
    camera, tf = _scene(mesh)
    clip = Clip.plane((0.05, 0.0, 0.0), (1.0, 0.2, 0.0))
    ref = render_reference(mesh, camera, tf, SIZE, clip=clip)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as r:
        plain = r.render(mesh, camera, tf, size=SIZE, clip=clip)
        monkeypatch.setattr(raymarch, "_slack", lambda mesh, camera: -1e30)
        checked = r.render(mesh, camera, tf, size=SIZE, clip=clip)
        stats = r._march.last_stats
    width, height = SIZE
    rows, cols = stats.suspect_pixels // width, stats.suspect_pixels % width
    traced = np.zeros((height, width), dtype=bool)
    traced[height - 1 - rows, cols] = True  # the list's rows count from the bottom
    covered = ref[..., 3] > 0
    assert stats.n_suspect > 0 and traced.sum() > covered.sum() // 2
    assert np.abs(checked[traced] - ref[traced]).max() <= 1e-6  # traced: the reference's own values
    np.testing.assert_array_equal(checked[~traced], plain[~traced])  # the others as drawn
    assert np.abs(plain - ref)[traced].max() > 1e-6  # drawn, they were the table's values
    assert np.abs(plain - ref).max() <= 1 / 255


def test_more_walks_gone_wrong_than_listed_are_said(monkeypatch):
    mesh = synthetic.cube(4)
    camera, tf = _scene(mesh)
    monkeypatch.setattr(raymarch, "_slack", lambda mesh, camera: -1e30)
    monkeypatch.setattr(march_layout, "SUSPECT_LENGTH", 16)
    monkeypatch.setattr(raymarch, "SUSPECT_LENGTH", 16)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as r, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r.render(mesh, camera, tf, size=SIZE)
    assert any("walk went wrong" in str(w.message) and "traced again exactly" in str(w.message) for w in caught)


def test_reference_pixels_are_the_reference_images_pixels():
    mesh = synthetic.cube(3)
    camera, tf = _scene(mesh)
    full = render_reference(mesh, camera, tf, SIZE).reshape(-1, 4)
    pixels = np.array([0, 5, 5, 17 * 40 + 20, SIZE[0] * SIZE[1] - 1, 600])
    np.testing.assert_array_equal(render_reference_pixels(mesh, camera, tf, SIZE, pixels), full[pixels])
    with pytest.raises(ValueError, match="pixels must lie in the 40x32 image"):
        render_reference_pixels(mesh, camera, tf, SIZE, [SIZE[0] * SIZE[1]])


@pytest.mark.parametrize("chunk", [1 << 18, 64], ids=["by tiles", "pixel by pixel"])
@pytest.mark.parametrize("view", ["inside", "parallel", "outside"])
def test_reference_pixels_of_a_few_pixels_cull_no_tet_they_need(view, chunk):
    """The pixels' tets are found first by their vertices' boxes (every tet the near plane
    cuts kept), then through the screen tiles the boxes cover (or, where the boxes would
    cover too many tiles for the chunk, pixel by pixel): the values are the full image's,
    bit for bit."""
    mesh = synthetic.torus()
    camera = tetvr.Camera.fit(mesh, direction=(0.3, -0.8, -0.5), parallel=view == "parallel")
    if view == "inside":  # the eye in the tube: the near plane cuts cells
        camera = tetvr.Camera(position=(1.0, 0.0, 0.05), focal_point=(1.0, 1.0, 0.0), view_angle=70.0)
    tf = tetvr.TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.8, mesh=mesh)
    full = render_reference(mesh, camera, tf, SIZE).reshape(-1, 4)
    assert np.count_nonzero(full[:, 3] > 0.01) > 100
    pixels = np.random.default_rng(3).choice(SIZE[0] * SIZE[1], 60, replace=False)
    np.testing.assert_array_equal(render_reference_pixels(mesh, camera, tf, SIZE, pixels, chunk=chunk),
                                  full[pixels])


def test_rays_past_the_last_layer_are_traced_again(monkeypatch):
    """A ray that would enter the mesh again after the march's last layer is not cut off:
    its pixel is traced again exactly (here with 1 layer on a torus, entered twice)."""
    mesh = synthetic.torus()
    camera, tf = tetvr.Camera.fit(mesh, direction=(1.0, 0.05, -0.1)), _scene(mesh)[1]
    ref = render_reference(mesh, camera, tf, SIZE)
    monkeypatch.setattr(raymarch, "MAX_LAYERS", 1)
    with Renderer(tetvr.RenderSettings(method="raymarch")) as r:
        image = r.render(mesh, camera, tf, size=SIZE)
        st = r._marcher.last_stats
    assert st.layers_exhausted and st.n_suspect > 0
    assert np.abs(image - ref).max() <= 1 / 255


def test_a_walk_gone_astray_stops_and_is_traced_again():
    """A Delaunay pipe with a graded wall layer has slivers where a few walks go astray; such
    a walk once circled for the rest of its step bound (the mesh's cell count: 44k steps,
    most of a frame of a 924k-tet pipe). It stops where it goes astray, and the ray is traced
    again exactly."""
    pytest.importorskip("scipy", reason="the Delaunay pipe needs scipy: pip install -e '.[mesh]'")
    from tetvr.scene.imperfect import delaunay_pipe

    mesh = delaunay_pipe(16, 20)
    camera, tf = tetvr.Camera.fit(mesh), tetvr.TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.5,
                                                                          mesh=mesh)
    size = (128, 128)
    with Renderer() as r:
        counts = r.segment_counts(mesh, camera, size=size)
        image = r.render(mesh, camera, tf, size=size)
        n_suspect = r._marcher.last_stats.n_suspect
    assert n_suspect > 0  # the scene has walks that go astray
    assert counts.max() < 1000  # none walks on: the longest ray crosses ~120 cells
    ref = render_reference(mesh, camera, tf, size)
    assert np.abs(image - ref).max() <= 1 / 255

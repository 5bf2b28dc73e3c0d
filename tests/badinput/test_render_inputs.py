"""Bad and borderline inputs at render time, on the GPU and the CPU reference: clear
errors for impossible requests, finite pictures for merely unusual ones, a clean GL error
state after every call (including the ones that raise), and the caller's arrays untouched."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import tetvr
from tetvr import Camera, RenderSettings, TetMesh, TransferFunction
from tetvr.mesh import synthetic
from tetvr.reference.tets import render_reference
from tetvr.render import default_transfer_function
from tetvr.order.precision import GPU_EXTENT_RANGE

from ._util import POINTS, SCALARS, TETS

pytestmark = pytest.mark.gl

SMALL = RenderSettings(table_scalar_bins=32, table_thickness_slices=4)


def _clean(renderer) -> None:
    assert renderer.ctx.error == "GL_NO_ERROR"


def _finite_premultiplied(img: np.ndarray) -> None:
    assert np.all(np.isfinite(img)), "NaN or Inf in the image"
    a = img[..., 3]
    assert a.min() >= 0.0 and a.max() <= 1.0 + 1e-6
    assert img[..., :3].min() >= -1e-6 and np.all(img[..., :3] <= a[..., None] + 1e-5)


@pytest.fixture(scope="module")
def scene():
    mesh = synthetic.single_tet((0.0, 1.0, 2.0, 3.0))
    return mesh, Camera.fit(mesh), default_transfer_function(mesh)


BAD_SIZES = [(0, 10), (10, 0), (-1, 5), (5, -1), (2.5, 3), (3, "4"), (8,), (1, 2, 3), "big", None, (np.nan, 4)]


@pytest.mark.parametrize("size", BAD_SIZES, ids=[repr(s) for s in BAD_SIZES])
def test_bad_size_gpu(renderer, scene, size):
    mesh, cam, tf = scene
    _clean(renderer)
    with pytest.raises(ValueError, match="size"):
        renderer.render(mesh, cam, tf, size=size)
    _clean(renderer)
    with pytest.raises(ValueError, match="size"):
        renderer.depth_extent(mesh, cam, size=size)
    _clean(renderer)


@pytest.mark.parametrize("size", BAD_SIZES, ids=[repr(s) for s in BAD_SIZES])
def test_bad_size_reference(scene, size):
    mesh, cam, tf = scene
    with pytest.raises(ValueError, match="size"):
        render_reference(mesh, cam, tf, size)


@pytest.mark.parametrize("axis", [0, 1])
def test_size_beyond_the_gl_limit(renderer, scene, axis):
    mesh, cam, tf = scene
    limit = int(renderer.ctx.info["GL_MAX_TEXTURE_SIZE"])
    size = [4, 4]
    size[axis] = limit + 1
    with pytest.raises(ValueError, match=rf"outside 1\.\.\d+ pixels per side \(the GL limit here\)"):
        renderer.render(mesh, cam, tf, size=tuple(size))
    _clean(renderer)
    img = renderer.render(mesh, cam, tf, size=(8, 8))  # the renderer still works afterwards
    _clean(renderer)
    assert img[..., 3].max() > 0


def test_one_by_one_image(renderer, scene):
    mesh, cam, tf = scene
    got = renderer.render(mesh, cam, tf, size=(1, 1))
    _clean(renderer)
    want = render_reference(mesh, cam, tf, (1, 1))
    assert got.shape == want.shape == (1, 1, 4)
    _finite_premultiplied(got)
    assert np.abs(got - want).max() < 2e-3


def test_numpy_integer_sizes_are_accepted(renderer, scene):
    mesh, cam, tf = scene
    img = renderer.render(mesh, cam, tf, size=(np.int64(6), np.int32(5)))
    assert img.shape == (5, 6, 4)
    _clean(renderer)


def test_error_paths_leave_gl_clean(renderer, scene):
    mesh, cam, tf = scene
    with pytest.raises(ValueError, match="order must be at most 1 integer cell ids"):
        renderer.render(mesh, cam, tf, size=(8, 8), order=np.arange(3))
    _clean(renderer)
    with pytest.raises(ValueError, match="each at most once"):
        renderer.render(mesh, cam, tf, size=(8, 8), order=np.array([5]))
    _clean(renderer)
    with pytest.raises(ValueError, match="unknown shader"):
        renderer.render(mesh, cam, tf, size=(8, 8), shader="no-such-shader")
    _clean(renderer)
    _finite_premultiplied(renderer.render(mesh, cam, tf, size=(8, 8)))
    _clean(renderer)


def test_released_renderer_refuses_to_render(scene):
    mesh, cam, tf = scene
    r = tetvr.Renderer(SMALL)
    r.release()
    with pytest.raises(RuntimeError, match="released"):
        r.render(mesh, cam, tf, size=(4, 4))


@pytest.mark.parametrize("value", [0.0, 0.5, -7.25, 1e20, -1e-20])
def test_constant_field_renders(value):
    """A zero-range field gets a transfer function over a tiny interval around it."""
    mesh = synthetic.single_tet((value,) * 4)
    assert mesh.scalar_range == (value, value)
    gpu = tetvr.render(mesh, size=(24, 24))
    ref = tetvr.render(mesh, size=(24, 24), method="reference")
    for img in (gpu, ref):
        _finite_premultiplied(img)
        assert img[..., 3].max() > 0.5  # the tet is visible, not blank
    assert tetvr.psnr(gpu, ref) > 40.0


@pytest.mark.parametrize("settings", [RenderSettings(table_scalar_bins=32, table_thickness_slices=4, table_encoding=e,
                                                     table_dtype=d)
                                      for e in ("normalized", "premultiplied") for d in ("float32", "uint8")],
                         ids=lambda s: f"{s.table_encoding}-{s.table_dtype}")
@pytest.mark.parametrize("unit_distance", [1e-300, 1e-40, 1e300])
def test_extreme_unit_distance_gives_a_finite_image(scene, settings, unit_distance):
    """Extinction past float32's range used to be stored as inf: NaN where d * inf met d = 0."""
    mesh, cam, _ = scene
    tf = TransferFunction(color=((0, 1, 0, 0), (3, 0, 0, 1)), opacity=((0, 0.5), (3, 0.5)), unit_distance=unit_distance)
    with tetvr.Renderer(settings) as r:
        got = r.render(mesh, cam, tf, size=(16, 16))
        _clean(r)
    want = render_reference(mesh, cam, tf, (16, 16))
    _finite_premultiplied(got)
    if settings.table_encoding == "normalized":  # alpha exact in the thickness
        assert np.abs(got[..., 3] - want[..., 3]).max() < 1e-3
    else:  # premultiplied interpolates alpha from 0 at d = 0: thin segments fall short
        # (near every edge of the one tet, which Camera.fit makes fill the view: 12 % of
        # alpha on average at an opaque extreme; what this test is about is finiteness)
        assert np.abs(got[..., 3] - want[..., 3]).mean() < 0.15


@pytest.mark.parametrize("kwargs,match", [
    (dict(mesh="mesh.vtu"), "mesh must be a TetMesh"),
    (dict(camera="front"), "camera must be a Camera or None, got str"),
    (dict(tf="viridis"), "tf must be a TransferFunction or None, got str"),
    (dict(settings={"sort": "none"}), "settings must be a RenderSettings or None, got dict"),
], ids=["mesh", "camera", "tf", "settings"])
def test_facade_rejects_wrong_types(scene, kwargs, match):
    mesh = kwargs.pop("mesh", scene[0])
    with pytest.raises(TypeError, match=match):
        tetvr.render(mesh, size=(4, 4), **kwargs)


def test_facade_rejects_unknown_method(scene):
    with pytest.raises(ValueError, match="method must be 'gpu' or 'reference', got 'cuda'"):
        tetvr.render(scene[0], size=(4, 4), method="cuda")


def test_reference_rejects_wrong_types(scene):
    mesh, cam, tf = scene
    with pytest.raises(TypeError, match="tf must be a TransferFunction"):
        render_reference(mesh, cam, None, (4, 4))  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="camera must be a Camera"):
        render_reference(mesh, "cam", tf, (4, 4))  # type: ignore[arg-type]


@pytest.mark.parametrize("scale", [1e-20, 1e25])
def test_gpu_refuses_extents_float32_cannot_resolve(scale):
    """Such meshes used to come back blank (or wrong) from the GPU without a word."""
    base = synthetic.single_tet((0.0, 1.0, 2.0, 3.0))
    mesh = TetMesh.from_arrays(base.points * scale, base.tets, base.scalars)
    with pytest.raises(ValueError, match="extent .* outside .* use method='reference'"):
        tetvr.render(mesh, size=(8, 8))
    ref = tetvr.render(mesh, size=(8, 8), method="reference")  # the exact renderer has no such limit
    _finite_premultiplied(ref)
    assert ref[..., 3].max() > 0.5


@pytest.mark.parametrize("scalars", [(1e39, 2e39, 3e39, 4e39), (0.0, 1e300, -1e300, 5.0)], ids=["1e39", "1e300"])
def test_gpu_refuses_scalars_beyond_float32(scalars):
    """Stored as inf on the GPU, they came back as a wrong picture (PSNR ~20 dB)."""
    mesh = synthetic.single_tet(scalars)
    with pytest.raises(ValueError, match="scalar values up to .* beyond the GPU's float32"):
        tetvr.render(mesh, size=(8, 8))
    _finite_premultiplied(tetvr.render(mesh, size=(8, 8), method="reference"))


def test_gpu_refuses_a_transfer_function_narrower_than_float32_resolves():
    """A field 1 +- 4e-8 under a function spanning just that: float32 scalars cannot tell
    its values apart, and the GPU picture was noise (26 dB against the reference)."""
    mesh = synthetic.single_tet((1 + 4e-8, 1 - 4e-8, 1 - 4e-8, 1 + 4e-8))
    lo, hi = mesh.scalar_range
    tf = TransferFunction.preset("cool-to-warm", (lo, hi), opacity=0.5, unit_distance=0.1)
    with pytest.raises(ValueError, match="too narrow for their magnitude .* subtract an offset"):
        tetvr.render(mesh, tf=tf, size=(8, 8))
    _finite_premultiplied(tetvr.render(mesh, tf=tf, size=(8, 8), method="reference"))
    shifted = mesh.with_scalars(mesh.scalars - 1.0)  # the remedy the message names
    tf0 = TransferFunction.preset("cool-to-warm", shifted.scalar_range, opacity=0.5, unit_distance=0.1)
    got = tetvr.render(shifted, tf=tf0, size=(16, 16))
    assert tetvr.psnr(got, tetvr.render(shifted, tf=tf0, size=(16, 16), method="reference")) > 40.0


def test_default_function_of_a_nearly_constant_field_renders():
    mesh = synthetic.single_tet((1 + 4e-8, 1 - 4e-8, 1 - 4e-8, 1 + 4e-8))
    gpu = tetvr.render(mesh, size=(16, 16))
    ref = tetvr.render(mesh, size=(16, 16), method="reference")
    _finite_premultiplied(gpu)
    assert tetvr.psnr(gpu, ref) > 40.0


@pytest.mark.parametrize("scale", [GPU_EXTENT_RANGE[0] * 10, GPU_EXTENT_RANGE[1] / 10])
def test_gpu_is_exact_inside_its_extent_range(scale):
    base = synthetic.single_tet((0.0, 1.0, 2.0, 3.0))
    mesh = TetMesh.from_arrays(base.points / np.sqrt(2) * scale, base.tets, base.scalars)
    got = tetvr.render(mesh, size=(16, 16))
    want = tetvr.render(mesh, size=(16, 16), method="reference")
    assert tetvr.psnr(got, want) > 40.0


def test_inputs_are_not_modified(renderer):
    points, tets, scalars = POINTS.copy(), TETS[:, [0, 2, 1, 3]].copy(), SCALARS.copy()
    order = np.array([1, 0])
    arrays = (points, tets, scalars, order)
    before = [a.copy() for a in arrays]
    mesh = TetMesh.from_arrays(points, tets, scalars)
    mesh_before = [mesh.points.copy(), mesh.tets.copy(), mesh.scalars.copy()]
    cam, tf = Camera.fit(mesh), default_transfer_function(mesh)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        renderer.render(mesh, cam, tf, size=(16, 16))
        renderer.render(mesh, cam, tf, size=(16, 16), order=order)
        renderer.depth_extent(mesh, cam, size=(16, 16))
        render_reference(mesh, cam, tf, (16, 16))
        tetvr.render(mesh, camera=cam, tf=tf, size=(16, 16))
    _clean(renderer)
    for arr, old in zip(arrays, before):
        assert np.array_equal(arr, old) and arr.flags.writeable
    for arr, old in zip((mesh.points, mesh.tets, mesh.scalars), mesh_before):
        assert np.array_equal(arr, old)

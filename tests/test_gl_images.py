"""GPU images against the exact CPU reference (Mesa llvmpipe is enough).

Tolerance: PSNR >= 40 dB on premultiplied RGB (RMSE <= 0.01), the issue's acceptance
bar. What remains is the table's interpolation (256 scalar nodes, 16 log-thickness
slices; ~1e-4 at nodes, a few 1e-3 between them near transfer-function kinks), float32
geometry, and pixels on silhouettes where rasterisation and the reference's exact ray
may disagree about coverage.
"""

from __future__ import annotations

import dataclasses
import numpy as np
import pytest

import tetvr
from tetvr import Camera, TransferFunction
from tetvr.mesh import synthetic
from tetvr.core.image import psnr
from tetvr.reference.tets import render_reference

from .conftest import save_failure, shared_file

pytestmark = pytest.mark.gl

MIN_PSNR = 40.0


def _tf(mesh: tetvr.TetMesh, *, opacity=((0.0, 0.2), (0.5, 0.6), (1.0, 0.9)), units: float = 4.0) -> TransferFunction:
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    lo, hi = mesh.scalar_range
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    return TransferFunction.preset("viridis", (lo, hi), opacity=list(opacity), unit_distance=diag / units)


def _peaked_tf(mesh: tetvr.TetMesh, units: float = 20.0) -> TransferFunction:
    """A demanding function: a narrow opacity spike at the 30 % quantile (an iso-layer)
    and a ramp above the 60 % quantile, over a diverging colour map."""
    lo, hi = mesh.scalar_range
    q30, q60 = ((q - lo) / (hi - lo) for q in np.quantile(mesh.scalars, [0.3, 0.6]))
    opacity = [(0.0, 0.02), (q30 - 0.03, 0.05), (q30, 0.9), (q30 + 0.03, 0.05), (q60, 0.3), (1.0, 0.9)]
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    return TransferFunction.preset("cool-to-warm", (lo, hi), opacity=opacity, unit_distance=diag / units)


def _compare(renderer, name: str, mesh, camera, tf, size=(128, 128), min_psnr: float = MIN_PSNR) -> float:
    got = renderer.render(mesh, camera, tf, size=size)
    want = render_reference(mesh, camera, tf, size)
    assert np.all(np.isfinite(got))
    assert got[..., 3].min() >= 0.0 and got[..., 3].max() <= 1.0 + 1e-6
    value = psnr(got, want)
    # The scene must not be trivially empty: a blank image would pass any PSNR.
    assert want[..., 3].max() > 0.2, f"{name}: reference image is nearly empty"
    if value < min_psnr:
        where = save_failure(name, got, want)
        pytest.fail(f"{name}: PSNR {value:.2f} dB < {min_psnr} dB against the reference (images in {where})")
    print(f"{name}: PSNR {value:.2f} dB")
    return value


def _ortho(mesh, direction=(0.0, 0.0, -1.0), up=(0.0, 1.0, 0.0)) -> Camera:
    return Camera.fit(mesh, direction=direction, view_up=up, parallel=True)


def _chord_lengths(mesh: tetvr.TetMesh, camera: Camera, size) -> np.ndarray:
    """Chord of each pixel ray through a single convex tet, by slab clipping against its faces."""
    o, d = camera.rays(*size)
    p = mesh.points[mesh.tets[0]]
    t0 = np.full(o.shape[0], -np.inf)
    t1 = np.full(o.shape[0], np.inf)
    for k in range(4):
        a, b, c = (p[(k + i) % 4] for i in (1, 2, 3))
        n = np.cross(b - a, c - a)
        if n @ (p[k] - a) > 0:  # make the normal point away from the opposite vertex
            n = -n
        num = (a - o) @ n
        den = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / den
        entering = den < 0
        t0 = np.where(entering, np.maximum(t0, t), t0)
        t1 = np.where(~entering & (den != 0), np.minimum(t1, t), t1)
        t1 = np.where((den == 0) & (num < 0), -np.inf, t1)
    length = np.clip(t1 - t0, 0, None) * np.linalg.norm(d, axis=1)
    return length.reshape(size[1], size[0])


def test_single_tet_constant_matches_closed_form(renderer):
    mesh = synthetic.single_tet((0.5, 0.5, 0.5, 0.5))
    tf = TransferFunction(color=((0.0, 0.9, 0.4, 0.1), (1.0, 0.9, 0.4, 0.1)), opacity=((0.0, 0.6), (1.0, 0.6)),
                          unit_distance=0.3)
    cam = _ortho(mesh)
    size = (128, 128)
    got = renderer.render(mesh, cam, tf, size=size)
    length = _chord_lengths(mesh, cam, size)
    tau = -np.log(1 - 0.6) / 0.3
    alpha = 1 - np.exp(-tau * length)
    assert alpha.max() > 0.5  # the test scene is not trivially thin
    err = np.abs(got[..., 3] - alpha)
    err_rgb = np.abs(got[..., :3] - alpha[..., None] * np.array([0.9, 0.4, 0.1]))
    # Silhouette pixels whose centre lies within float32 rounding of an edge may differ in
    # coverage; away from edges the closed form holds to 1e-3.
    assert err.max() <= 1e-3, f"max alpha error {err.max():.2e}"
    assert err_rgb.max() <= 1e-3


@pytest.mark.parametrize("scene", ["single_tet", "two_tets", "cube", "cube4"])
def test_analytic_scenes_orthographic(renderer, scene):
    mesh = {"single_tet": lambda: synthetic.single_tet((0.0, 0.3, 0.7, 1.0)),
            "two_tets": synthetic.two_tets,
            "cube": lambda: synthetic.cube(1),
            "cube4": lambda: synthetic.cube(4)}[scene]()
    _compare(renderer, scene, mesh, _ortho(mesh), _tf(mesh))


def test_constant_slab_has_alpha_of_its_opacity(renderer):
    # Thickness exactly u: alpha must equal the transfer function's opacity (the optical model's definition).
    mesh = synthetic.slab(thickness=0.1, width=1.0, value=0.5)
    tf = TransferFunction(color=((0.0, 0.2, 0.5, 1.0), (1.0, 0.2, 0.5, 1.0)), opacity=((0.0, 0.7), (1.0, 0.7)),
                          unit_distance=0.1)
    cam = Camera(position=(0, 0, 2), focal_point=(0, 0, 0), parallel_projection=True, parallel_scale=0.4,
                 clipping_range=(0.5, 4.0))
    got = renderer.render(mesh, cam, tf, size=(64, 64))
    np.testing.assert_allclose(got[..., 3], 0.7, atol=1e-4)
    np.testing.assert_allclose(got[..., 2], 0.7, atol=1e-4)


def test_perspective_cube(renderer):
    mesh = synthetic.cube(3)
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0), zoom=1.2)
    _compare(renderer, "cube_perspective", mesh, cam, _tf(mesh))


@pytest.mark.parametrize("kind", ["smooth", "peaked"])
def test_post_vtk(renderer, kind):
    mesh = tetvr.read(tetvr.demo_scene_path().parent / "post.vtk", "Pressure")
    tf = _tf(mesh, units=8.0) if kind == "smooth" else _peaked_tf(mesh)
    _compare(renderer, f"post_{kind}", mesh, _ortho(mesh, direction=(-1.0, -0.6, -0.8), up=(0, 0, 1)), tf)


@pytest.mark.parametrize("kind", ["smooth", "peaked"])
def test_bluntfin(renderer, kind):
    with pytest.warns(UserWarning, match="dropped 77 zero-volume"):
        mesh = tetvr.read(shared_file("tets/bluntfin_tets.vtu"), "Density")
    tf = _tf(mesh, units=6.0) if kind == "smooth" else _peaked_tf(mesh)
    _compare(renderer, f"bluntfin_{kind}", mesh, _ortho(mesh, direction=(-1.0, -0.5, -0.7)), tf, size=(256, 256))


def test_shuffled_input_renders_identically(renderer):
    mesh = synthetic.cube(3)
    rng = np.random.default_rng(7)
    tets = mesh.tets[rng.permutation(mesh.n_tets)]
    tets = np.take_along_axis(tets, np.argsort(rng.random(tets.shape), axis=1), axis=1)
    shuffled = tetvr.TetMesh.from_arrays(mesh.points, tets, mesh.scalars)
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0))
    tf = _tf(mesh)
    a = renderer.render(mesh, cam, tf, size=(96, 96))
    b = renderer.render(shuffled, cam, tf, size=(96, 96))
    assert np.array_equal(a, b)


def test_same_scene_twice_is_bit_identical(renderer):
    mesh = synthetic.cube(2)
    cam = Camera.fit(mesh)
    tf = _tf(mesh)
    assert np.array_equal(renderer.render(mesh, cam, tf, size=(64, 48)), renderer.render(mesh, cam, tf, size=(64, 48)))


@pytest.mark.parametrize("name,camera", [
    ("inside", Camera(position=(0.1, 0.05, 0.2), focal_point=(-0.3, -0.2, -1), view_angle=70, clipping_range=(0.01, 5))),
    ("near_plane_cuts", Camera(position=(0, 0, 1.0), focal_point=(0, 0, 0), view_angle=40, clipping_range=(0.9, 5))),
    ("eye_on_a_vertex_plane", Camera(position=(0, 0, 0.0), focal_point=(0.2, 0.1, -1), view_angle=60, clipping_range=(0.05, 5))),
])
def test_camera_inside_and_near_plane(renderer, name, camera):
    # Tets crossing the near plane are intersected per fragment, not dropped.
    mesh = synthetic.cube(6)
    _compare(renderer, name, mesh, camera, _tf(mesh))


@pytest.mark.parametrize("parallel", [False, True])
def test_far_plane_cuts_the_mesh(renderer, parallel):
    # The far clip is compiled in only for views that need it (CLIP_RANGE): the segment
    # must end at the far plane, as in the reference, in both projections.
    mesh = synthetic.cube(6)
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0), parallel=parallel)
    near, far = cam.clipping_range
    centre = float(np.asarray(cam.focal_point) @ np.asarray(cam.direction) - np.asarray(cam.position) @ np.asarray(cam.direction))
    cut = dataclasses.replace(cam, clipping_range=(near, centre))
    full = renderer.render(mesh, cam, _tf(mesh), size=(96, 96))
    value = _compare(renderer, f"far_plane_{'parallel' if parallel else 'perspective'}", mesh, cut, _tf(mesh), size=(96, 96))
    assert value >= MIN_PSNR
    # And the cut is visible: half the mesh is gone.
    assert renderer.render(mesh, cut, _tf(mesh), size=(96, 96))[..., 3].sum() < 0.8 * full[..., 3].sum()


@pytest.mark.parametrize("parallel", [False, True])
def test_depth_extent_matches_reference_segments(renderer, parallel):
    from tetvr.reference.segments import ray_segments

    mesh = synthetic.cube(3)
    cam = Camera.fit(mesh, direction=(-0.4, -0.3, -1.0), parallel=parallel, zoom=1.3)
    size = (64, 48)
    front, back = renderer.depth_extent(mesh, cam, size=size)
    seg = ray_segments(mesh, cam, size)
    want_front = np.full(size[0] * size[1], np.inf)
    want_back = np.full(size[0] * size[1], -np.inf)
    np.minimum.at(want_front, seg.pixel, seg.t_in)
    np.maximum.at(want_back, seg.pixel, seg.t_out)
    want_front = want_front.reshape(size[1], size[0])
    want_back = want_back.reshape(size[1], size[0])
    covered = np.isfinite(want_front)
    assert covered.mean() > 0.2
    # Coverage agrees except where a pixel centre grazes the silhouette.
    assert np.mean(np.isfinite(front) == covered) > 0.99
    both = covered & np.isfinite(front)
    scale = cam.clipping_range[1]
    assert np.abs(front[both] - want_front[both]).max() < 1e-4 * scale
    assert np.abs(back[both] - want_back[both]).max() < 1e-4 * scale


def test_chunked_drawing_is_identical():
    """Meshes beyond one storage buffer are drawn in sorted chunks: same image, bit for bit."""
    mesh = synthetic.cube(4)
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0))
    tf = _tf(mesh)
    pt = tetvr.RenderSettings(method="projected")  # chunks are projected tetrahedra's
    with tetvr.Renderer(pt) as whole, tetvr.Renderer(pt, chunk_tets=50) as chunked:
        a = whole.render(mesh, cam, tf, size=(64, 64))
        b = chunked.render(mesh, cam, tf, size=(64, 64))
        fa, ba = whole.depth_extent(mesh, cam, size=(64, 64))
        fb, bb = chunked.depth_extent(mesh, cam, size=(64, 64))
    assert chunked._cells.chunked and not whole._cells.chunked
    assert np.array_equal(a, b)
    assert np.array_equal(fa, fb) and np.array_equal(ba, bb)


def test_draw_batches_and_index_buffer_growth_are_identical(monkeypatch):
    """The indexed fans are drawn in batches (u_first offsets the order); many small batches,
    and an index buffer first sized for a smaller mesh and then grown, give the same image."""
    import tetvr.gl.projected as gl_projected

    mesh = synthetic.cube(4)  # 384 tets
    small = synthetic.cube(1)  # 6 tets
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0))
    tf = _tf(mesh)
    pt = tetvr.RenderSettings(method="projected")  # draw batches are projected tetrahedra's
    with tetvr.Renderer(pt) as r:
        want = r.render(mesh, cam, tf, size=(64, 64))
        want_front, want_back = r.depth_extent(mesh, cam, size=(64, 64))
    monkeypatch.setattr(gl_projected, "_DRAW_BATCH", 37)  # 11 draw calls, the last one partial
    with tetvr.Renderer(pt) as r:
        r.render(small, Camera.fit(small), _tf(small), size=(16, 16))
        assert r._cells.fan_indices.size == small.n_tets * 12 * 4  # sized for the small mesh first
        got = r.render(mesh, cam, tf, size=(64, 64))
        front, back = r.depth_extent(mesh, cam, size=(64, 64))
        assert r._cells.fan_indices.size == 37 * 12 * 4
    assert np.array_equal(got, want)
    assert np.array_equal(front, want_front) and np.array_equal(back, want_back)


def test_mpvonc_is_exact_on_a_convex_mesh_in_perspective():
    """No pixel differs from the per-pixel-sorted reference by more than the table error,
    where centroid order visibly fails (bluntfin, close perspective view)."""
    with pytest.warns(UserWarning, match="zero-volume"):
        mesh = tetvr.read(shared_file("tets/bluntfin_tets.vtu"), "Density")
    from tetvr.render import default_transfer_function

    tf = default_transfer_function(mesh, opacity=0.8)
    cam = Camera.fit(mesh, direction=(-1.0, -0.5, -0.7), zoom=1.5)
    want = render_reference(mesh, cam, tf, (128, 128))
    errors = {}
    for sort in ("centroid", "mpvonc"):
        with tetvr.Renderer(tetvr.RenderSettings(sort=sort, method="projected")) as r:
            got = r.render(mesh, cam, tf, size=(128, 128))
            assert r.last_stats.cycle_breaks == 0
        errors[sort] = (np.abs(got - want).max(), psnr(got, want))
    assert errors["mpvonc"][0] < 2e-3, errors  # the table's own error, measured ~1e-4 at nodes
    assert errors["mpvonc"][1] > 90.0, errors
    assert errors["centroid"][1] < errors["mpvonc"][1] - 20.0, errors  # centroid order is visibly wrong here

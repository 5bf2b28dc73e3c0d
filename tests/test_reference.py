"""The CPU reference renderer (tetvr.reference.tets) on scenes with known answers.

Every expected value here is computed another way than the renderer computes it:
chords by closed form, by barycentric coordinates from a matrix inverse, or by the
slab method on a box; integrals by brute-force marching or by a per-pixel loop over
integrate_pieces. Images are float32, so agreement is asked to 1e-6 (float32 rounding
of values <= 1 is 6e-8, the renderer's own error ~1e-9).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tetvr import Camera, TetMesh, TransferFunction
from tetvr.optics.model import MAX_OPACITY, integrate_pieces
from tetvr.reference.tets import render_reference
from tetvr.reference.integrate import composite, integrate_segments
from tetvr.reference.segments import ray_lengths, ray_segments

ATOL = 1e-6


@pytest.fixture(autouse=True)
def _strict_floats():
    with np.errstate(all="raise"):
        yield


# ---------------------------------------------------------------- scene helpers


def corner_tet(scalars=(0.5, 0.5, 0.5, 0.5)) -> TetMesh:
    return TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]], scalars)


def random_tet(rng) -> np.ndarray:
    while True:
        p = rng.uniform(-1.0, 1.0, (4, 3))
        if abs(np.linalg.det(p[1:] - p[0])) > 0.3:
            return p


def cube_corners(lo=-1.0, hi=1.0) -> np.ndarray:
    """Corner v = i + 2 j + 4 k sits at (x_i, y_j, z_k)."""
    return np.array([[(lo, hi)[i], (lo, hi)[j], (lo, hi)[k]] for k in (0, 1) for j in (0, 1) for i in (0, 1)], float)


#: The cube in 5 tets: a regular central tet and four corner tets.
FIVE_TETS = [[0, 3, 5, 6], [1, 0, 3, 5], [2, 0, 3, 6], [4, 0, 5, 6], [7, 3, 5, 6]]


def kuhn_grid(n: int, lo=-1.0, hi=1.0, jitter=0.0, rng=None) -> tuple[np.ndarray, np.ndarray]:
    """An n^3 grid of cubes, each cut into the 6 Kuhn tets around its main diagonal.

    Interior points move by up to ``jitter`` cells; boundary points stay on the box.
    """
    ax = np.linspace(lo, hi, n + 1)
    pts = np.array([[x, y, z] for z in ax for y in ax for x in ax])
    if jitter:
        interior = np.all((pts > lo) & (pts < hi), axis=1)
        pts[interior] += rng.uniform(-jitter, jitter, (int(interior.sum()), 3)) * (hi - lo) / n

    def vid(i, j, k):
        return i + (n + 1) * (j + (n + 1) * k)

    tets = []
    for i, j, k in itertools.product(range(n), repeat=3):
        for perm in itertools.permutations(range(3)):
            c = [i, j, k]
            chain = [vid(*c)]
            for axis in perm:
                c[axis] += 1
                chain.append(vid(*c))
            tets.append(chain)
    return pts, np.array(tets)


def barycentric_chords(p: np.ndarray, origins: np.ndarray, dirs: np.ndarray, near=-np.inf, far=np.inf):
    """Interval of t where o + t d lies in the tet p (4, 3), by barycentric coordinates.

    lambda(o + t d) = M^-1 [o; 1] + t M^-1 [d; 0]; each lambda >= 0 bounds t.
    """
    minv = np.linalg.inv(np.vstack([p.T, np.ones(4)]))
    l0 = np.c_[origins, np.ones(len(origins))] @ minv.T
    l1 = np.c_[dirs, np.zeros(len(dirs))] @ minv.T
    t0 = np.full(len(origins), float(near))
    t1 = np.full(len(origins), float(far))
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = -l0 / l1
    for i in range(4):
        t0 = np.where(l1[:, i] > 0, np.maximum(t0, bound[:, i]), t0)
        t1 = np.where(l1[:, i] < 0, np.minimum(t1, bound[:, i]), t1)
        t1 = np.where((l1[:, i] == 0) & (l0[:, i] < 0), -np.inf, t1)
    return t0, np.maximum(t1, t0)


def box_chords(lo, hi, origins, dirs, near=-np.inf, far=np.inf):
    """Slab method: interval of t where o + t d is inside the box [lo, hi]."""
    t0 = np.full(len(origins), float(near))
    t1 = np.full(len(origins), float(far))
    for ax in range(3):
        d, o = dirs[:, ax], origins[:, ax]
        moving = d != 0
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (lo[ax] - o) / d, (hi[ax] - o) / d
        t0 = np.where(moving, np.maximum(t0, np.minimum(ta, tb)), t0)
        t1 = np.where(moving, np.minimum(t1, np.maximum(ta, tb)), t1)
        t1 = np.where(~moving & ((o <= lo[ax]) | (o >= hi[ax])), -np.inf, t1)
    return t0, np.maximum(t1, t0)


def chord_rgba(tf: TransferFunction, s0: float, s1: float, length: float) -> np.ndarray:
    """One linear-scalar chord integrated by a plain loop: cut at breakpoints, composite."""
    cuts = [b for b in tf.breakpoints if min(s0, s1) < b < max(s0, s1)]
    cuts = sorted(cuts, reverse=bool(s1 < s0))
    ss = [s0, *cuts, s1]
    rgb, alpha_t = np.zeros(3), 1.0
    for a, b in zip(ss[:-1], ss[1:]):
        frac = (b - a) / (s1 - s0) if s1 != s0 else 1.0
        (ca, cb), (oa, ob) = tf.evaluate([a, b])
        piece_rgb, theta = integrate_pieces(ca[None], cb[None], np.array([oa]), np.array([ob]),
                                            np.array([frac * length]), tf.unit_distance)
        rgb += alpha_t * piece_rgb[0]
        alpha_t *= np.exp(-theta[0])
    return np.r_[rgb, 1.0 - alpha_t]


def march(tf: TransferFunction, scalar_at, t0: float, t1: float, scale: float, n=100_000) -> np.ndarray:
    """Brute force along one ray: the TF sampled at n midpoints, exact exponential steps."""
    t = t0 + (np.arange(n) + 0.5) * (t1 - t0) / n
    c, a = tf.evaluate(scalar_at(t))
    step = -np.log1p(-np.minimum(a, MAX_OPACITY)) / tf.unit_distance * (t1 - t0) / n * scale
    theta = np.cumsum(step)
    w = -np.expm1(-step) * np.exp(-(theta - step))
    return np.r_[(w[:, None] * c).sum(axis=0), -np.expm1(-theta[-1])]


TF_RAMP = TransferFunction.preset(
    "viridis", (0.0, 1.0), opacity=((0.0, 0.1), (0.4, 0.6), (0.7, 0.2), (1.0, 0.8)), unit_distance=0.3
)


def axis_camera(x=0.0, y=0.0, scale=1.0, near=0.5, far=20.0) -> Camera:
    return Camera(position=(x, y, 5.0), focal_point=(x, y, 0.0), view_up=(0, 1, 0),
                  parallel_projection=True, parallel_scale=scale, clipping_range=(near, far))


def oblique_camera(target=(0.0, 0.0, 0.0), distance=4.0, parallel=False) -> Camera:
    d = np.array([-0.55, -0.35, -0.75])
    pos = np.asarray(target) - distance * d / np.linalg.norm(d)
    return Camera(position=tuple(pos), focal_point=target, view_up=(0, 1, 0), view_angle=40.0,
                  parallel_projection=parallel, parallel_scale=distance * np.tan(np.radians(20.0)),
                  clipping_range=(0.1, 50.0))


# ---------------------------------------------------------------- (a) one tet, constant scalar


def test_constant_tet_axis_view_matches_closed_form_chord():
    """Corner tet seen along -z: the chord at (x, y) is 1 - x - y where x, y >= 0."""
    a, u, colour = 0.35, 0.4, (0.2, 0.6, 0.9)
    tf = TransferFunction(color=((0, *colour), (1, *colour)), opacity=((0, a), (1, a)), unit_distance=u)
    cam = axis_camera(0.4, 0.4, scale=0.55)
    size = (24, 20)  # not square: the aspect ratio must be honoured
    img = render_reference(corner_tet(), cam, tf, size)
    origins, _ = cam.rays(*size)
    x, y = origins[:, 0], origins[:, 1]
    chord = np.where((x >= 0) & (y >= 0), np.maximum(0.0, 1.0 - x - y), 0.0).reshape(size[1], size[0])
    assert np.count_nonzero(chord > 0.05) > 100
    tau = -np.log1p(-a) / u
    alpha = 1.0 - np.exp(-tau * chord)
    np.testing.assert_allclose(img[..., 3], alpha, rtol=0, atol=ATOL)
    np.testing.assert_allclose(img[..., :3], alpha[..., None] * np.array(colour), rtol=0, atol=ATOL)


@pytest.mark.parametrize("parallel", [False, True])
def test_constant_random_tet_matches_barycentric_chords(parallel):
    rng = np.random.default_rng(11)
    p = random_tet(rng)
    mesh = TetMesh.from_arrays(p, [[0, 1, 2, 3]], np.full(4, 0.25))
    a, u = 0.6, 0.7
    tf = TransferFunction(color=((0, 1, 0.5, 0), (1, 1, 0.5, 0)), opacity=((0, a), (1, a)), unit_distance=u)
    cam = oblique_camera(target=tuple(p.mean(axis=0)), distance=2.5, parallel=parallel)
    size = (30, 26)
    img = render_reference(mesh, cam, tf, size)
    origins, dirs = cam.rays(*size)
    t0, t1 = barycentric_chords(p, origins, dirs, *cam.clipping_range)
    length = ((t1 - t0) * np.linalg.norm(dirs, axis=1)).reshape(size[1], size[0])
    assert np.count_nonzero(length > 0.05) > 50
    alpha = 1.0 - (1.0 - a) ** (length / u)
    np.testing.assert_allclose(img[..., 3], alpha, rtol=0, atol=ATOL)
    np.testing.assert_allclose(img[..., 0], alpha, rtol=0, atol=ATOL)
    np.testing.assert_allclose(img[..., 1], 0.5 * alpha, rtol=0, atol=ATOL)
    assert np.all(img[..., 2] == 0)

    # The segments themselves: same interval, in eye depth, as the barycentric one.
    seg = ray_segments(mesh, cam, size)
    assert np.unique(seg.pixel).size == seg.pixel.size  # one tet: one segment per ray
    assert set(np.nonzero(t1 - t0 > 1e-9)[0].tolist()) <= set(seg.pixel.tolist())  # no ray lost
    np.testing.assert_allclose(seg.t_in, t0[seg.pixel], rtol=0, atol=1e-12)
    np.testing.assert_allclose(seg.t_out, t1[seg.pixel], rtol=0, atol=1e-12)
    np.testing.assert_allclose(ray_lengths(cam, size), np.linalg.norm(dirs, axis=1), rtol=1e-15)


# ---------------------------------------------------------------- (b) one tet, linear scalar


@pytest.mark.parametrize("parallel", [False, True])
def test_linear_tet_matches_brute_force_marching(parallel):
    rng = np.random.default_rng(5)
    p = random_tet(rng)
    s = np.array([0.05, 0.95, 0.3, 0.6])
    mesh = TetMesh.from_arrays(p, [[0, 1, 2, 3]], s)
    cam = oblique_camera(target=tuple(p.mean(axis=0)), distance=2.5, parallel=parallel)
    size = (20, 20)
    img = render_reference(mesh, cam, TF_RAMP, size).reshape(-1, 4)
    origins, dirs = cam.rays(*size)
    t0, t1 = barycentric_chords(p, origins, dirs)
    minv = np.linalg.inv(np.vstack([p.T, np.ones(4)]))
    order = np.argsort(t1 - t0)
    pixels = list(order[-3:]) + list(rng.choice(np.nonzero(t1 - t0 > 0.05)[0], 3, replace=False))
    for k in pixels:
        def scalar_at(t, k=k):
            x = origins[k] + t[:, None] * dirs[k]
            return (np.c_[x, np.ones(len(t))] @ minv.T) @ s  # barycentric interpolation

        want = march(TF_RAMP, scalar_at, t0[k], t1[k], np.linalg.norm(dirs[k]))
        np.testing.assert_allclose(img[k], want, rtol=0, atol=ATOL, err_msg=f"pixel {k}")
    outside = (t1 - t0) <= 0
    assert np.all(img[outside] == 0)


# ---------------------------------------------------------------- (c) two tets sharing a face

# A convex bipyramid: any ray through both tets crosses the shared face.
BIPYRAMID = np.array([[0.1, 0.0, -1.0], [1.0, 0.0, 0.05], [-0.5, 0.85, 0.0], [-0.5, -0.85, -0.05], [0.0, 0.1, 1.0]])
LINEAR_TF = TransferFunction(color=((0.0, 1, 0, 0), (1.0, 0, 0.2, 1)), opacity=((0.0, 0.1), (1.0, 0.7)),
                             unit_distance=0.5)


def _linear_field(points, g=(0.2, -0.15, 0.3), h=0.5):
    return np.asarray(points) @ np.asarray(g) + h


@pytest.mark.parametrize("parallel", [False, True])
def test_two_tets_sharing_a_face_equal_the_merged_segment(parallel):
    mesh = TetMesh.from_arrays(BIPYRAMID, [[0, 1, 2, 3], [1, 2, 3, 4]], _linear_field(BIPYRAMID))
    s = mesh.scalars
    assert 0 < s.min() and s.max() < 1  # inside the TF domain: one linear piece
    cam = oblique_camera(distance=5.0, parallel=parallel)
    size = (32, 32)
    img = render_reference(mesh, cam, LINEAR_TF, size).reshape(-1, 4)
    seg = ray_segments(mesh, cam, size)
    origins, dirs = cam.rays(*size)

    order = np.lexsort((seg.t_in, seg.pixel))
    pix, t_in, t_out = seg.pixel[order], seg.t_in[order], seg.t_out[order]
    both = np.nonzero(pix[1:] == pix[:-1])[0]
    assert both.size > 30
    assert np.bincount(pix).max() == 2
    # Adjacent tets give adjacent intervals: exactly, not within a tolerance.
    np.testing.assert_array_equal(t_out[both], t_in[both + 1])

    for i in both:
        k = pix[i]
        a, b = t_in[i], t_out[i + 1]
        ends = _linear_field([origins[k] + a * dirs[k], origins[k] + b * dirs[k]])
        (c0, c1), (o0, o1) = LINEAR_TF.evaluate(ends)
        rgb, theta = integrate_pieces(c0[None], c1[None], np.array([o0]), np.array([o1]),
                                      np.array([(b - a) * np.linalg.norm(dirs[k])]), LINEAR_TF.unit_distance)
        np.testing.assert_allclose(img[k], np.r_[rgb[0], -np.expm1(-theta[0])], rtol=0, atol=ATOL)


# ---------------------------------------------------------------- (d) a cube cut into tets


def _check_box_image(img, cam, size, tf, lo, hi, strict_inside=False):
    origins, dirs = cam.rays(*size)
    t0, t1 = box_chords(np.asarray(lo), np.asarray(hi), origins, dirs, *cam.clipping_range)
    img = img.reshape(-1, 4)
    checked = 0
    for k in range(len(origins)):
        if strict_inside and np.any(np.isin(origins[k][:2], [lo[0], hi[0]])):
            continue  # a ray in the box's own face: which side takes it is a convention
        if t1[k] <= t0[k]:
            assert np.all(img[k] == 0), k
            continue
        ends = _linear_field([origins[k] + t0[k] * dirs[k], origins[k] + t1[k] * dirs[k]])
        want = chord_rgba(tf, ends[0], ends[1], (t1[k] - t0[k]) * np.linalg.norm(dirs[k]))
        np.testing.assert_allclose(img[k], want, rtol=0, atol=ATOL, err_msg=f"pixel {k}")
        checked += 1
    return checked


def test_five_tet_cube_matches_box_chords():
    pts = cube_corners()
    mesh = TetMesh.from_arrays(pts, FIVE_TETS, _linear_field(pts))
    cam = oblique_camera(distance=6.0)
    size = (24, 24)
    img = render_reference(mesh, cam, TF_RAMP, size)
    assert _check_box_image(img, cam, size, TF_RAMP, (-1, -1, -1), (1, 1, 1)) > 150


def test_kuhn_cubes_axis_view_rays_in_shared_faces_counted_once():
    """Pixel centres lie exactly on grid planes and cell diagonals, which are faces shared
    by two tets and parallel to the view: each such ray must be taken by one tet."""
    pts, tets = kuhn_grid(2)
    mesh = TetMesh.from_arrays(pts, tets, _linear_field(pts))
    cam = axis_camera(1 / 16, 1 / 16, scale=1.0)  # centres at multiples of 1/8
    size = (16, 16)
    origins, _ = cam.rays(*size)
    x, y = origins[:, 0], origins[:, 1]
    assert np.any(x == 0) and np.any(x == y) and np.any(x == y + 1)  # the case is exercised
    img = render_reference(mesh, cam, TF_RAMP, size)
    assert _check_box_image(img, cam, size, TF_RAMP, (-1, -1, -1), (1, 1, 1), strict_inside=True) > 150
    # And the depth covered is exactly the box, ray by ray.
    seg = ray_segments(mesh, cam, size)
    depth = np.bincount(seg.pixel, weights=seg.t_out - seg.t_in, minlength=size[0] * size[1])
    inside = (np.abs(x) < 1) & (np.abs(y) < 1)
    np.testing.assert_allclose(depth[inside], 2.0, rtol=0, atol=1e-13)
    # Many of these rays pass through vertices, where rounding could carry the end scalars
    # past the vertex values: they must not.
    for s in (seg.scalar_in, seg.scalar_out):
        vertex_s = mesh.scalars[mesh.tets[seg.tet]]
        assert np.all((s >= vertex_s.min(axis=1)) & (s <= vertex_s.max(axis=1)))


def _raw_permuted(mesh: TetMesh, rng) -> TetMesh:
    """The same cells in shuffled order with shuffled vertices, bypassing canonicalisation
    (odd permutations flip the orientation, which the renderer must not care about)."""
    tets = mesh.tets[rng.permutation(mesh.n_tets)]
    perms = np.array(list(itertools.permutations(range(4))))
    tets = np.take_along_axis(tets, perms[rng.integers(0, len(perms), len(tets))], axis=1)
    return TetMesh(points=mesh.points, tets=tets.astype(np.int32), scalars=mesh.scalars)


@pytest.mark.parametrize("permuted", [False, True])
@pytest.mark.parametrize("parallel", [False, True])
def test_jittered_grid_is_watertight(parallel, permuted):
    """Segments of a ray tile the box chord: each starts exactly where the last ended."""
    rng = np.random.default_rng(2)
    pts, tets = kuhn_grid(3, jitter=0.3, rng=rng)
    mesh = TetMesh.from_arrays(pts, tets, _linear_field(pts))
    if permuted:
        mesh = _raw_permuted(mesh, rng)
    cam = oblique_camera(distance=5.0, parallel=parallel)
    size = (40, 40)
    seg = ray_segments(mesh, cam, size)
    origins, dirs = cam.rays(*size)
    t0, t1 = box_chords(np.full(3, -1.0), np.full(3, 1.0), origins, dirs, *cam.clipping_range)
    order = np.lexsort((seg.t_in, seg.pixel))
    pix, t_in, t_out = seg.pixel[order], seg.t_in[order], seg.t_out[order]
    same = pix[1:] == pix[:-1]
    np.testing.assert_array_equal(t_out[:-1][same], t_in[1:][same])
    first = np.r_[True, ~same]
    last = np.r_[~same, True]
    scale = np.abs(t1).max()
    np.testing.assert_allclose(t_in[first], t0[pix[first]], rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(t_out[last], t1[pix[last]], rtol=0, atol=1e-12 * scale)
    hit = np.nonzero(t1 - t0 > 1e-9)[0]
    assert hit.size > 400
    assert set(hit.tolist()) <= set(pix.tolist())

    # End scalars: the linear field there, and never outside the tet's vertex values.
    for t, s in ((seg.t_in, seg.scalar_in), (seg.t_out, seg.scalar_out)):
        x = origins[seg.pixel] + t[:, None] * dirs[seg.pixel]
        np.testing.assert_allclose(s, _linear_field(x), rtol=0, atol=1e-12)
        vertex_s = mesh.scalars[mesh.tets[seg.tet]]
        assert np.all((s >= vertex_s.min(axis=1)) & (s <= vertex_s.max(axis=1)))


@pytest.mark.parametrize("parallel", [False, True])
def test_sliver_tet_end_scalars_stay_in_vertex_range(parallel):
    """A flat tet has a steep gradient, so rounding at a face would push the scalar past
    the vertex values (by ~1e-12 here); the ends must be clamped to them."""
    rng = np.random.default_rng(0)
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 1e-5]]) @ rotation.T + 0.1
    mesh = TetMesh.from_arrays(p, [[0, 1, 2, 3]], [0.2, 0.2, 0.2, 0.7])
    seg = ray_segments(mesh, oblique_camera(target=tuple(p.mean(axis=0)), distance=2.5, parallel=parallel), (64, 64))
    assert seg.pixel.size > 100
    ends = np.r_[seg.scalar_in, seg.scalar_out]
    assert ends.min() >= 0.2 and ends.max() <= 0.7
    assert np.count_nonzero(ends == 0.2) > 20  # the base face is hit, at its value exactly


# ---------------------------------------------------------------- (e) invariance


def test_cell_and_vertex_order_do_not_change_the_image():
    rng = np.random.default_rng(4)
    pts, tets = kuhn_grid(3, jitter=0.25, rng=rng)
    mesh = TetMesh.from_arrays(pts, tets, rng.random(len(pts)))
    cam = oblique_camera(distance=5.0)
    size = (32, 32)
    img = render_reference(mesh, cam, TF_RAMP, size)
    assert img[..., 3].max() > 0.5

    raw = _raw_permuted(mesh, rng)
    img2 = render_reference(raw, cam, TF_RAMP, size)
    np.testing.assert_allclose(img2, img, rtol=0, atol=1e-7)
    # Chunking only bounds memory.
    img3 = render_reference(raw, cam, TF_RAMP, size, chunk=37)
    np.testing.assert_allclose(img3, img, rtol=0, atol=1e-7)


# ---------------------------------------------------------------- (f) near and far planes


@pytest.mark.parametrize("far", [50.0, 0.8])
def test_camera_inside_the_mesh(far):
    pts, tets = kuhn_grid(2)
    mesh = TetMesh.from_arrays(pts, tets, np.full(len(pts), 0.5))
    a, u = 0.5, 0.6
    tf = TransferFunction(color=((0, 0.3, 0.7, 0.1), (1, 0.3, 0.7, 0.1)), opacity=((0, a), (1, a)), unit_distance=u)
    near = 0.05
    cam = Camera(position=(0.3, 0.2, 0.1), focal_point=(-0.4, -0.1, -0.8), view_up=(0, 1, 0), view_angle=70.0,
                 clipping_range=(near, far))
    size = (32, 24)
    img = render_reference(mesh, cam, tf, size)
    assert np.all(np.isfinite(img))
    assert img[..., 3].min() >= 0 and img[..., 3].max() <= 1
    origins, dirs = cam.rays(*size)
    _, t1 = box_chords(np.full(3, -1.0), np.full(3, 1.0), origins, dirs)
    length = ((np.minimum(t1, far) - near) * np.linalg.norm(dirs, axis=1)).reshape(size[1], size[0])
    alpha = 1.0 - (1.0 - a) ** (length / u)
    np.testing.assert_allclose(img[..., 3], alpha, rtol=0, atol=ATOL)
    np.testing.assert_allclose(img[..., :3], alpha[..., None] * np.array([0.3, 0.7, 0.1]), rtol=0, atol=ATOL)


def test_mesh_behind_the_camera_or_outside_the_view_renders_nothing():
    mesh = corner_tet()
    tf = LINEAR_TF
    behind = Camera(position=(0.2, 0.2, -3.0), focal_point=(0.2, 0.2, -6.0), clipping_range=(0.1, 100.0))
    beside = Camera(position=(30.0, 0.2, 5.0), focal_point=(30.0, 0.2, 0.0), clipping_range=(0.1, 100.0))
    for cam in (behind, beside):
        img = render_reference(mesh, cam, tf, (8, 8))
        assert img.shape == (8, 8, 4) and img.dtype == np.float32 and np.all(img == 0)
        assert ray_segments(mesh, cam, (8, 8)).pixel.size == 0


# ---------------------------------------------------------------- building blocks


def test_integrate_segments_is_accurate_where_opacity_ramps_to_one():
    """integrate_pieces alone is 1e-5 off here (see test_optics); the reference cuts the pieces."""
    tf = TransferFunction(color=((0, 0, 0, 1), (1, 1, 0, 0)), opacity=((0, 1.0), (1, 0.0)), unit_distance=1.0)
    for length in (0.03, 0.3, 3.0):
        rgb, theta = integrate_segments(np.array([0.0]), np.array([1.0]), np.array([length]), tf)
        # Fine quadrature on a grid graded towards the opaque end, where 1 - a -> 1e-6.
        x = np.unique(np.r_[np.geomspace(1.0 - MAX_OPACITY, 1.0, 400_001), np.linspace(1.0 - MAX_OPACITY, 1.0, 400_001)])
        f = (x - x[0]) / (1.0 - x[0])  # fraction along the segment where 1 - a = x
        primitive = x - x * np.log(x)
        th = length * (primitive - primitive[0]) / (1.0 - x[0])
        g = -np.log(x) * np.exp(-th) * length
        y = g[:, None] * np.c_[f, np.zeros_like(f), 1.0 - f]
        want = (0.5 * (y[1:] + y[:-1]) * np.diff(f)[:, None]).sum(axis=0)
        np.testing.assert_allclose(rgb[0], want, rtol=0, atol=1e-9)
        assert theta[0] == pytest.approx(th[-1], rel=1e-12)


def test_integrate_segments_splits_in_ray_order():
    """A segment and its reverse: same optical depth, different colour, each as a loop says."""
    rng = np.random.default_rng(9)
    s_in, s_out = rng.random(50), rng.random(50)
    length = rng.uniform(0.01, 2.0, 50)
    rgb, theta = integrate_segments(s_in, s_out, length, TF_RAMP)
    for i in range(50):
        want = chord_rgba(TF_RAMP, s_in[i], s_out[i], length[i])
        np.testing.assert_allclose(rgb[i], want[:3], rtol=0, atol=1e-12)
        assert -np.expm1(-theta[i]) == pytest.approx(want[3], abs=1e-12)
    rgb_r, theta_r = integrate_segments(s_out, s_in, length, TF_RAMP)
    np.testing.assert_allclose(theta_r, theta, rtol=1e-12)
    assert np.abs(rgb_r - rgb).max() > 1e-3


def test_composite_orders_by_depth_within_each_pixel():
    rng = np.random.default_rng(1)
    n, n_pix = 400, 30
    pixel = rng.integers(0, n_pix, n)
    t_in = rng.random(n)
    rgb = rng.random((n, 3)) * 0.2
    theta = rng.random(n) * 0.7
    out = composite(pixel, t_in, rgb, theta, n_pix)
    for p in range(n_pix):
        acc, trans = np.zeros(3), 1.0
        for i in np.nonzero(pixel == p)[0][np.argsort(t_in[pixel == p])]:
            acc += trans * rgb[i]
            trans *= np.exp(-theta[i])
        np.testing.assert_allclose(out[p], np.r_[acc, 1.0 - trans], rtol=1e-12, atol=1e-15)


def test_bad_arguments_are_named():
    mesh, cam, tf = corner_tet(), axis_camera(), LINEAR_TF
    with pytest.raises(ValueError, match="size"):
        render_reference(mesh, cam, tf, (0, 8))
    with pytest.raises(ValueError, match="size"):
        render_reference(mesh, cam, tf, (8.5, 8))
    with pytest.raises(ValueError, match="chunk"):
        render_reference(mesh, cam, tf, (8, 8), chunk=0)
    with pytest.raises(TypeError, match="tf"):
        render_reference(mesh, cam, None, (8, 8))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="same length"):
        integrate_segments(np.zeros(2), np.zeros(3), np.zeros(2), tf)

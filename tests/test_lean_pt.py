"""The lean projected-tetrahedra path: classify.comp runs after the sort and writes each
tet's fan as finished vertices, in drawing order, into a plain vertex buffer; tet.vert
passes them through (issue 17).

What is checked here without the old code: the vertices are the projections of the right
tets in the right order, near-plane and clipped tets get their markers, splitting the
classification into storage-buffer ranges, the draw into batches or the mesh into chunks
gives the same bits, and the image stays within a stated error of the CPU reference.
(The switch itself was checked bit for bit against the old path on 10 scenes at 512x512,
cube(26) and bluntfin, perspective, parallel, eye inside, far plane, floor shader,
explicit order, cull, chunks: all equal.)
"""

from __future__ import annotations

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TransferFunction
from tetvr.mesh import synthetic
from tetvr.reference.tets import render_reference

pytestmark = pytest.mark.gl

PT = tetvr.RenderSettings(method="projected")


def _tf(mesh: tetvr.TetMesh) -> TransferFunction:
    return TransferFunction.preset("viridis", mesh.scalar_range, opacity=[(0.0, 0.2), (0.5, 0.6), (1.0, 0.9)],
                                   unit_distance=0.4)


def _outside() -> Camera:
    # Explicit, not Camera.fit: the test pins the geometry it reasons about.
    return Camera(position=(2.2, 1.4, 2.9), focal_point=(0.0, 0.0, 0.0), view_angle=40.0, clipping_range=(0.5, 8.0))


def _inside() -> Camera:
    return Camera(position=(0.1, -0.05, 0.2), focal_point=(0.8, 0.3, -0.6), view_angle=70.0, clipping_range=(0.05, 6.0))


def _fan_vertices(r: tetvr.Renderer, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ndc (n, 5, 2), exact tet (n, 5), segment (n, 5, 4)) of the last chunk's fans."""
    with r.ctx:
        raw = r._cells.fans.read(size=n * 5 * 32)
    words = np.frombuffer(raw, dtype=np.float32).reshape(n, 5, 8)
    exact = np.frombuffer(raw, dtype=np.int32).reshape(n, 5, 8)[..., 2]
    return words[..., :2], exact, words[..., 4:]


def _project(mesh: tetvr.TetMesh, cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """NDC (x, y) and eye depth of every point, in float64."""
    p = np.c_[mesh.points, np.ones(mesh.n_points)]
    eye = p @ cam.view_matrix().T
    clip = eye @ cam.projection_matrix(1.0).T
    return clip[:, :2] / clip[:, 3:], -eye[:, 2]


def test_fan_vertices_are_the_tets_projections_in_drawing_order():
    mesh = synthetic.cube(3)
    cam = _outside()
    order = np.random.default_rng(7).permutation(mesh.n_tets)  # an explicit order: the fans follow it
    with tetvr.Renderer(PT) as r:
        r.render(mesh, cam, _tf(mesh), size=(64, 64), order=order)
        ndc, exact, seg = _fan_vertices(r, mesh.n_tets)
    p_ndc, _ = _project(mesh, cam)
    assert np.all(exact == -1)  # every point lies inside the clipping range
    for pos, tet in enumerate(order):
        corners = p_ndc[mesh.tets[tet]]
        # Slots 1..4: the silhouette, each a vertex of the tet drawn at this position.
        dist = np.abs(ndc[pos, 1:, None, :] - corners[None]).max(axis=-1).min(axis=-1)
        assert dist.max() < 1e-5, (pos, tet, dist)
        # A 3-vertex silhouette repeats its first vertex; a 4-vertex one uses all four.
        distinct = {tuple(np.round(v, 5)) for v in ndc[pos, 1:]}
        assert len(distinct) in (3, 4)
        if len(distinct) == 3:
            assert np.array_equal(ndc[pos, 4], ndc[pos, 1])
        # Slot 0, the thick vertex, lies within the silhouette's bounding box.
        assert np.all(ndc[pos, 0] >= corners.min(axis=0) - 1e-5) and np.all(ndc[pos, 0] <= corners.max(axis=0) + 1e-5)
    # A silhouette vertex is one point: its front and back are the same.
    assert np.array_equal(seg[:, 1:, 0], seg[:, 1:, 2]) and np.array_equal(seg[:, 1:, 1], seg[:, 1:, 3])
    # The thick vertex's front is nearer than its back (perspective: 1/w is larger).
    assert np.all(seg[:, 0, 0] >= seg[:, 0, 2])


def test_near_plane_and_clipped_tets_get_their_markers():
    mesh = synthetic.cube(3)
    cam = _inside()
    with tetvr.Renderer(PT) as r:
        r.render(mesh, cam, _tf(mesh), size=(64, 64), order=np.arange(mesh.n_tets))
        ndc, exact, seg = _fan_vertices(r, mesh.n_tets)
    p_ndc, depth = _project(mesh, cam)
    d = depth[mesh.tets]
    near, far = cam.clipping_range
    clipped = (d < near).all(axis=1) | (d > far).all(axis=1)
    crossing = (d < near).any(axis=1) & ~clipped
    assert clipped.any() and crossing.any()
    # Wholly outside the clipping range: all five vertices at one point outside the view.
    assert np.all(ndc[clipped] == 2.0) and np.all(exact[clipped] == -1)
    # Crossing the near plane: a screen rectangle inside the viewport whose fragments
    # intersect the tet exactly (every vertex names the tet; no fan segment).
    ids = np.nonzero(crossing)[0]
    assert np.array_equal(exact[ids], np.repeat(ids[:, None], 5, axis=1))
    assert np.all(np.abs(ndc[ids]) <= 1.0) and np.all(seg[ids] == 0.0)
    lo, hi = ndc[ids, 1], ndc[ids, 3]
    assert np.allclose(ndc[ids, 0], (lo + hi) / 2, atol=1e-6)  # fanned from the centre
    # The rest are fans, except tets with a vertex projecting far outside the view (beyond
    # EXACT_NDC = 8 in common.glsl, where the GL's guard band would clip them): exact too.
    reach = np.abs(p_ndc[mesh.tets]).max(axis=(1, 2))
    rest = ~crossing & ~clipped
    assert np.all(exact[rest & (reach < 7.99)] == -1)
    huge = np.nonzero(rest & (reach > 8.01))[0]
    assert huge.size and np.array_equal(exact[huge], np.repeat(huge[:, None], 5, axis=1))


def _parallel() -> Camera:
    return Camera(position=(2.2, 1.4, 2.9), focal_point=(0.0, 0.0, 0.0), parallel_projection=True, parallel_scale=1.2,
                  clipping_range=(0.5, 8.0))


@pytest.mark.parametrize("cam", [_outside(), _inside(), _parallel()], ids=["perspective", "inside", "parallel"])
def test_classify_ranges_draw_batches_and_chunks_give_the_same_bits(monkeypatch, cam):
    """classify.comp writes its vertices through storage-buffer ranges (a chunk's fans may
    exceed one binding), the draw points its attributes at each batch's first tet, chunks
    upload their cells in drawing order: none of it may change a bit."""
    import tetvr.gl.projected as gl_projected

    mesh = synthetic.cube(4)  # 384 tets
    tf = _tf(mesh)
    with tetvr.Renderer(PT) as r:
        want = r.render(mesh, cam, tf, size=(64, 64))
        want_extent = r.depth_extent(mesh, cam, size=(64, 64))
    monkeypatch.setattr(gl_projected, "_DRAW_BATCH", 37)
    for chunk in (None, 50):
        with tetvr.Renderer(PT, chunk_tets=chunk) as r:
            r._cells.max_ssbo = 2 * 64 * 5 * 32  # 128 tets' fans per binding: 3 classify ranges per 384 tets
            got = r.render(mesh, cam, tf, size=(64, 64))
            extent = r.depth_extent(mesh, cam, size=(64, 64))
            with r.ctx:
                assert r.ctx.error == "GL_NO_ERROR"
        assert np.array_equal(got, want), chunk
        assert all(np.array_equal(a, b) for a, b in zip(extent, want_extent)), chunk


def test_against_the_reference():
    """Outside and inside views of a 384-tet cube at 64x64 against the CPU reference.

    Bound: the worst pixel measured 1.2e-4 outside and 5.1e-5 inside, none beyond 1/255;
    1e-3 leaves room for the table and float32 rounding on another GL. A wrong fan (a
    silhouette vertex of another tet, a wrong thick vertex, a lost near-plane rectangle)
    puts 0.05-0.7 on whole tets.
    """
    mesh = synthetic.cube(4)
    tf = _tf(mesh)
    with tetvr.Renderer(PT) as r:
        for cam in (_outside(), _inside()):
            got = r.render(mesh, cam, tf, size=(64, 64))
            want = render_reference(mesh, cam, tf, (64, 64))
            assert want[..., 3].max() > 0.2
            err = np.abs(got - want).max(axis=-1)
            assert err.max() < 1e-3, err.max()
            assert np.count_nonzero(err > 1 / 255) == 0


def test_floor_shader_draws_the_same_triangles():
    """The fill-rate floor passes the same vertices through with a constant colour (its
    fragment shader reads no segment): it covers exactly the pixels the real image covers."""
    mesh = synthetic.cube(3)
    cam = _outside()
    with tetvr.Renderer(PT) as r:
        real = r.render(mesh, cam, _tf(mesh), size=(64, 64))
        floor = r.render(mesh, cam, _tf(mesh), size=(64, 64), shader="floor")
        with r.ctx:
            assert r.ctx.error == "GL_NO_ERROR"
    assert np.array_equal(real[..., 3] > 0, floor[..., 3] > 0)
    assert np.all(floor[..., 0][floor[..., 3] > 0] > 0)


def test_only_the_fans_between_the_first_and_last_exact_take_the_exact_branch(monkeypatch):
    """The fans from the first to the last on the exact path (near-plane tets) are drawn
    with tet.frag's exact branch compiled in, those before and after without, in drawing
    order: the same bits as one draw with the branch, and every exact fan in that range."""
    import tetvr.gl.renderer as gl_renderer

    mesh = synthetic.cube(4)
    tf = _tf(mesh)
    near_corner = Camera(position=(1.6, 1.2, 1.9), focal_point=(0.0, 0.0, 0.0), view_angle=40.0,
                         clipping_range=(2.2, 8.0))  # the near plane cuts the mesh's nearest corner
    draws: list[tuple[int, range]] = []
    runs = gl_renderer.exact_runs
    monkeypatch.setattr(gl_renderer, "exact_runs", lambda exact, n: draws.extend(runs(exact, n)) or runs(exact, n))
    with tetvr.Renderer(PT) as r:
        got = r.render(mesh, near_corner, tf, size=(64, 64))
        _, exact, _ = _fan_vertices(r, mesh.n_tets)
    on_path = np.nonzero(exact[:, 0] >= 0)[0]
    assert on_path.size and [v for v, _ in draws] in ([0, 1], [0, 1, 0])
    assert draws[1][1] == range(on_path[0], on_path[-1] + 1) and draws[0][1] == range(on_path[0])
    monkeypatch.setattr(gl_renderer, "exact_runs", lambda exact, n: [(1, range(n))])
    with tetvr.Renderer(PT) as r:
        want = r.render(mesh, near_corner, tf, size=(64, 64))
    assert want[..., 3].max() > 0.2
    assert np.array_equal(got, want)


def test_the_depth_pass_draws_the_near_plane_tets_by_their_own_program():
    """Fusion's depth extent draws every fan but the exact ones with one program and the
    exact ones (here the tets the near plane cuts) with the other: together, the reference's
    nearest entry and farthest exit, clipped to the clipping range."""
    from tetvr.reference.segments import ray_segments

    mesh = synthetic.cube(4)
    cam = Camera(position=(1.6, 1.2, 1.9), focal_point=(0.0, 0.0, 0.0), view_angle=40.0, clipping_range=(2.2, 8.0))
    size = (64, 48)
    with tetvr.Renderer(PT) as r:
        front, back = r.depth_extent(mesh, cam, size=size)
        _, exact, _ = _fan_vertices(r, mesh.n_tets)
    assert (exact[:, 0] >= 0).any() and (exact[:, 0] < 0).any()
    seg = ray_segments(mesh, cam, size)
    want_front = np.full(size[0] * size[1], np.inf)
    want_back = np.full(size[0] * size[1], -np.inf)
    np.minimum.at(want_front, seg.pixel, seg.t_in)
    np.maximum.at(want_back, seg.pixel, seg.t_out)
    want_front, want_back = want_front.reshape(size[1], size[0]), want_back.reshape(size[1], size[0])
    covered = np.isfinite(want_front)
    assert covered.mean() > 0.2 and np.any(want_front[covered] == 2.2)  # the near plane cuts some rays' entries
    assert np.mean(np.isfinite(front) == covered) > 0.99  # but where a pixel centre grazes the silhouette
    both = covered & np.isfinite(front)
    assert np.abs(front[both] - want_front[both]).max() < 1e-4 * 8.0
    assert np.abs(back[both] - want_back[both]).max() < 1e-4 * 8.0

"""The tet-marching ray caster (RenderSettings(method="raymarch")) against the exact reference.

Tolerance: the same table as projected tetrahedra (its interpolation error is ~1e-4 on
these scenes) and float32 geometry; no visibility-order error, since every ray is
composited in the order it crosses the cells. Every comparison asserts the maximum
per-pixel error -- an 8-bit step: a ray grazing a corner on the silhouette may miss a
sliver the reference sees (2e-3 on one pixel here, as for projected tetrahedra) -- and
PSNR.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import tetvr
from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.core.image import psnr
from tetvr.order.method import choose
from tetvr.reference.tets import render_reference

from .conftest import save_failure
from .test_near_plane_fuzz import _random_cameras

pytestmark = pytest.mark.gl

MAX_ERROR = 1 / 255
MIN_PSNR = 90.0


@pytest.fixture(scope="module")
def marcher():
    with tetvr.Renderer(RenderSettings(method="raymarch")) as r:
        yield r
        with r.ctx:
            assert r.ctx.error == "GL_NO_ERROR"


def _tf(mesh: tetvr.TetMesh, units: float = 4.0) -> TransferFunction:
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    lo, hi = mesh.scalar_range
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    return TransferFunction.preset("viridis", (lo, hi), opacity=[(0.0, 0.2), (0.5, 0.6), (1.0, 0.9)],
                                   unit_distance=diag / units)


def _compare(r, name, mesh, camera, tf, size=(80, 80), max_error=MAX_ERROR):
    got = r.render(mesh, camera, tf, size=size)
    want = render_reference(mesh, camera, tf, size)
    assert want[..., 3].max() > 0.1, f"{name}: the reference image is nearly empty"
    assert np.all(np.isfinite(got))
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    value = psnr(got, want)
    if err.max() > max_error or np.count_nonzero(err > 1 / 255) or value < MIN_PSNR:
        where = save_failure(f"raymarch_{name}", got, want)
        pytest.fail(f"{name}: max error {err.max():.3g}, {np.count_nonzero(err > 1 / 255)} pixels beyond 1/255, "
                    f"{value:.1f} dB (images in {where})")
    return got, want


def _separate_cubes() -> tetvr.TetMesh:
    a, b = synthetic.cube(2), synthetic.cube(2)
    return synthetic.merge(a, tetvr.TetMesh(b.points * 0.5 + np.array([1.6, 0.3, -0.8]), b.tets, b.scalars))


SCENES = {
    "single_tet": lambda: synthetic.single_tet((0.1, 0.4, 0.7, 1.0)),
    "two_tets": synthetic.two_tets,
    "cube": lambda: synthetic.cube(4),
    "slab": synthetic.slab,
    "torus": lambda: synthetic.torus(n_around=16),  # non-convex: rays leave and enter again
    "rings": synthetic.interlocking_rings,  # interlocking parts: up to 4 entries per ray
    "separate_parts": _separate_cubes,
}


@pytest.mark.parametrize("parallel", [False, True], ids=["perspective", "parallel"])
@pytest.mark.parametrize("scene", sorted(SCENES))
def test_scenes_against_the_reference(marcher, scene, parallel):
    mesh = SCENES[scene]()
    cam = Camera.fit(mesh, direction=(-0.3, -0.5, -1.0), parallel=parallel)
    _compare(marcher, f"{scene}_{'parallel' if parallel else 'perspective'}", mesh, cam, _tf(mesh))


def test_convex_mesh_needs_one_layer_and_rings_need_several(marcher):
    cube = synthetic.cube(3)
    marcher.render(cube, Camera.fit(cube, direction=(-0.3, -0.5, -1.0)), _tf(cube), size=(32, 32))
    assert marcher._marcher.last_stats.layers == 1
    rings = synthetic.interlocking_rings()
    marcher.render(rings, Camera.fit(rings, direction=(-0.3, -0.5, -1.0)), _tf(rings), size=(32, 32))
    assert marcher._marcher.last_stats.layers >= 2  # a ray through both rings enters twice or more
    assert not marcher._marcher.last_stats.layers_exhausted


@pytest.mark.parametrize("parallel", [False, True], ids=["perspective", "parallel"])
@pytest.mark.parametrize("scene", ["torus", "rings", "separate_parts"])
def test_layers_from_the_entry_list_and_from_peeling_agree(marcher, scene, parallel, monkeypatch):
    """Each further entry picked by the march from the first entry pass's list is the one a
    peel pass finds: a one-face list overflows wherever a ray meets two front faces, and
    then the frame peels."""
    import tetvr.gl.raymarch as raymarch

    mesh = SCENES[scene]()
    direction = (1.6, 0.3, -0.8) if scene == "separate_parts" else (-0.3, -0.5, -1.0)  # rays through both parts
    cam = Camera.fit(mesh, direction=direction, parallel=parallel)
    listed, _ = _compare(marcher, f"listed_{scene}", mesh, cam, _tf(mesh))
    assert marcher._marcher.last_stats.entry_list and marcher._marcher.last_stats.layers >= 2
    monkeypatch.setattr(raymarch, "LIST_LENGTH", 1)
    with tetvr.Renderer(RenderSettings(method="raymarch")) as r:
        peeled, _ = _compare(r, f"peeled_{scene}", mesh, cam, _tf(mesh))
        assert not r._marcher.last_stats.entry_list
    assert np.abs(listed - peeled).max() <= 1e-6
    monkeypatch.setattr(raymarch, "LIST_LENGTH", 8)
    monkeypatch.setattr(raymarch, "LIST_MAX_BYTES", 80 * 80 * 68 - 1)  # a frame too large for the list peels
    with tetvr.Renderer(RenderSettings(method="raymarch")) as r:
        assert np.array_equal(r.render(mesh, cam, _tf(mesh), size=(80, 80)), peeled)
        assert not r._marcher.last_stats.entry_list


def test_rays_through_more_faces_than_the_list_holds_peel(marcher):
    """Ten cubes one behind the other: the rays through all of them meet ten front faces,
    more than the list holds, and the frame peels them all."""
    from tetvr.gl.raymarch import LIST_LENGTH

    cube = synthetic.cube(2)
    mesh = synthetic.merge(*[tetvr.TetMesh(cube.points * 0.5 + np.array([0.0, 0.0, 0.8 * i]), cube.tets,
                                           cube.scalars + i) for i in range(LIST_LENGTH + 2)])
    cam = Camera.fit(mesh, direction=(0.02, 0.03, -1.0))
    _compare(marcher, "many_layers", mesh, cam, _tf(mesh, units=40.0))
    stats = marcher._marcher.last_stats
    assert not stats.entry_list and stats.layers > LIST_LENGTH and not stats.layers_exhausted


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_cameras_inside_and_around(marcher, seed):
    """Eye inside the mesh, near plane cutting cells, parallel views: every ray that starts
    inside the mesh starts in the cell holding its point on the near plane."""
    mesh = synthetic.cube(3)
    tf = _tf(mesh, units=5.0)
    for i, cam in enumerate(_random_cameras(12, seed)):
        got = marcher.render(mesh, cam, tf, size=(40, 40))
        want = render_reference(mesh, cam, tf, (40, 40))
        err = np.abs(got - want).max(axis=-1)
        assert err.max() < MAX_ERROR, f"camera {i}: max error {err.max():.3g}"


@pytest.mark.parametrize("parallel", [False, True])
def test_far_plane_cuts_the_walk(marcher, parallel):
    mesh = synthetic.cube(5)
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0), parallel=parallel)
    near, far = cam.clipping_range
    centre = float((np.asarray(cam.focal_point) - np.asarray(cam.position)) @ np.asarray(cam.direction))
    cut = dataclasses.replace(cam, clipping_range=(near, centre))
    got, _ = _compare(marcher, "far_plane", mesh, cut, _tf(mesh), size=(64, 64))
    assert got[..., 3].sum() < 0.8 * marcher.render(mesh, cam, _tf(mesh), size=(64, 64))[..., 3].sum()


def test_a_ray_through_many_cells_and_an_opaque_scene(marcher):
    """A fine mesh (3,000 cells along some rays' paths) and an absorbing transfer
    function, where the walk stops early once alpha is 1 to float precision."""
    mesh = synthetic.cube(10)
    tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=[(0.0, 1.0), (1.0, 1.0)], unit_distance=0.01)
    got, want = _compare(marcher, "opaque", mesh, Camera.fit(mesh, direction=(-0.3, -0.5, -1.0)), tf, size=(48, 48))
    assert want[..., 3].max() > 0.999


def test_shuffled_cells_and_reoriented_tets_render_the_same(marcher):
    mesh = synthetic.cube(3)
    rng = np.random.default_rng(3)
    perm = rng.permutation(mesh.n_tets)
    tets = mesh.tets[perm][:, [1, 0, 2, 3]]  # and every tet's orientation flipped
    shuffled = tetvr.TetMesh(mesh.points, tets, mesh.scalars)
    cam = Camera.fit(mesh, direction=(-0.3, -0.5, -1.0))
    a = marcher.render(mesh, cam, _tf(mesh), size=(48, 48))
    b = marcher.render(shuffled, cam, _tf(mesh), size=(48, 48))
    assert np.abs(a - b).max() < 1e-6
    assert np.array_equal(a, marcher.render(mesh, cam, _tf(mesh), size=(48, 48)))  # deterministic


def test_projected_and_raymarch_agree_where_both_are_exact():
    mesh = synthetic.cube(4)
    cam = Camera.fit(mesh, direction=(-0.3, -0.5, -1.0))
    with tetvr.Renderer(RenderSettings(method="projected")) as p, tetvr.Renderer(RenderSettings(method="raymarch")) as r:
        a = p.render(mesh, cam, _tf(mesh), size=(64, 64))
        b = r.render(mesh, cam, _tf(mesh), size=(64, 64))
        assert r._marcher is not None and p._marcher is None  # each took its own path
    diff = np.abs(a - b).max(axis=-1)
    assert diff.max() < 1 / 255  # pixels on the silhouette: coverage by different triangles
    assert np.count_nonzero(diff > 5e-4) <= 4


def test_records_built_beside_the_table_are_taken_or_dropped():
    """A new mesh's records are built in the background while the table is: the ray caster
    takes them; where the choice is projected tetrahedra (here an 8-bit target), they go."""
    mesh = synthetic.cube(3)
    cam = Camera.fit(mesh)
    with tetvr.Renderer(RenderSettings()) as r:
        first = r.render(mesh, cam, _tf(mesh), size=(24, 24))
        assert r._marcher._prefetch is None and r._marcher._records is not None
        again = r.render(mesh, cam, _tf(mesh), size=(24, 24))
        assert np.array_equal(first, again)
    with tetvr.Renderer(RenderSettings(framebuffer="uint8")) as r:
        r.render(mesh, cam, _tf(mesh), size=(24, 24))
        assert r._marcher is not None and r._marcher._prefetch is None and r._marcher._records is None


def test_records_stay_across_views_the_cost_model_sends_to_projected_tetrahedra(monkeypatch):
    """Where "auto" chooses per view (a convex mesh: the cost model decides), a view that
    takes projected tetrahedra keeps the records for the next that marches: they are built
    and put on the GL once, not again every frame."""
    import tetvr.gl.raymarch as gl_raymarch
    from tetvr.order.method import choose

    builds = []
    prefetch = gl_raymarch.Prefetch
    monkeypatch.setattr(gl_raymarch, "Prefetch", lambda m: builds.append(m) or prefetch(m))
    mesh = synthetic.cube(3)
    cam = Camera.fit(mesh)
    big, small = (1024, 1024), (64, 64)  # few cells over many pixels: projected tetrahedra
    assert [choose(RenderSettings(), mesh, cam, s) for s in (big, small)] == ["projected", "raymarch"]
    with tetvr.Renderer(RenderSettings()) as r:
        for size in (big, big, small, big):
            r.render(mesh, cam, _tf(mesh), size=size)
            assert r._marcher._records is not None and r._marcher._prefetch is None
        with tetvr.Renderer(RenderSettings(method="raymarch")) as m:
            want = m.render(mesh, cam, _tf(mesh), size=small)
            assert np.array_equal(r.render(mesh, cam, _tf(mesh), size=small), want)
    assert builds == [mesh, mesh]  # once for each renderer


def test_records_put_on_the_gl_before_the_walk_check_ends_go_if_it_fails(monkeypatch):
    """The records go to the GL while the rest of the walk check runs; where that check then
    finds parts that overlap (so "auto" takes projected tetrahedra), they are released."""
    import warnings

    from tetvr.gl.raymarch import Marcher
    from tetvr.scene.imperfect import embedded_block

    uploads = []
    use_mesh = Marcher._use_mesh
    monkeypatch.setattr(Marcher, "_use_mesh", lambda self, m: uploads.append(m) or use_mesh(self, m))
    mesh = embedded_block()
    with tetvr.Renderer(RenderSettings()) as r:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "parts of the mesh overlap": projected tetrahedra
            r.render(mesh, Camera.fit(mesh), _tf(mesh), size=(24, 24))
        assert r._marcher is not None and r._marcher._records is None and not r._marcher._textures
        assert r._marcher._prefetch is None and r._marcher._unused is None
    assert uploads == [mesh]  # they were put on the GL


def test_records_go_to_the_gl_in_blocks_and_leave_the_host(monkeypatch):
    """The per-tet records are built and written a block of tets at a time (here three
    blocks of 4096, the last part of a row), by the caller from the first block and a helper
    thread from the last (holding many, one or no blocks the caller has not taken): the same image as
    from one block. Once they are on the GL the host keeps none of them (the textures are the
    only copy a view reads, rebuilt from the mesh if needed), nor the face adjacency's planes
    of every face."""
    from tetvr.gl import march_layout
    from tetvr.mesh import adjacency

    mesh = synthetic.cube(12)  # 10,368 tets
    cam = Camera.fit(mesh, direction=(0.4, -0.3, 1.0))
    images = []
    for block, helper in ((march_layout._SHARED_BLOCK, march_layout._HELPER_AHEAD), (4096, 100),
                          (4096, 1), (4096, 0)):
        monkeypatch.setattr(march_layout, "_SHARED_BLOCK", block)
        monkeypatch.setattr(march_layout, "_HELPER_AHEAD", helper)
        with tetvr.Renderer(RenderSettings(method="raymarch")) as r:
            images.append(r.render(mesh, cam, _tf(mesh), size=(64, 64)))
            rec = r._marcher._records
            assert rec.planes is None and rec.scalar is None and rec.links is None and rec.ids is None
            assert rec.boundary_slots.size > 0
    assert len(adjacency.blocks(mesh.n_tets, 4096)) == 3 and images[0][..., 3].max() > 0.1
    for image in images[1:]:
        assert np.array_equal(images[0], image)
    assert "normals" not in vars(adjacency.face_adjacency(mesh))


def test_both_ends_yield_every_block_once_and_raise_a_helpers_error(monkeypatch):
    """The records' blocks from both ends: each block once, whatever the helper's bound (the
    caller takes the helper's blocks after each of its own, out of order), and an error in
    a block the helper built is raised to the caller."""
    import time

    from tetvr.gl import march_layout

    mesh = synthetic.cube(12)
    n_blocks = len(march_layout.adjacency.blocks(mesh.n_tets, 1024))

    def fake(m, rec, rows):
        time.sleep(0.002)
        if rows.start == fail:
            raise RuntimeError("block failed")
        return rows.start, rows.stop

    monkeypatch.setattr(march_layout, "_SHARED_BLOCK", 1024)
    monkeypatch.setattr(march_layout, "cell_records", fake)
    fail = -1
    for ahead in (0, 1, 4):
        monkeypatch.setattr(march_layout, "_HELPER_AHEAD", ahead)
        got = [(rows.start, a, b) for rows, a, b in march_layout._BothEnds(mesh, None)]
        assert sorted(g[0] for g in got) == [i * 1024 for i in range(n_blocks)]
        assert all(a == start for start, a, _ in got)
    monkeypatch.setattr(march_layout, "_HELPER_AHEAD", 4)
    fail = (n_blocks - 1) * 1024  # the helper's first block
    with pytest.raises(RuntimeError, match="block failed"):
        list(march_layout._BothEnds(mesh, None))


def test_method_setting():
    with pytest.raises(ValueError, match="method must be one of"):
        RenderSettings(method="marching")
    assert choose(RenderSettings()) == "raymarch"
    assert choose(RenderSettings(method="projected")) == "projected"
    # Settings only projected tetrahedra implement keep them under "auto".
    assert choose(RenderSettings(optics="vtk")) == "projected"
    assert choose(RenderSettings(framebuffer="uint8")) == "projected"


def test_ray_limits_and_segment_counts_of_a_non_convex_mesh(marcher):
    """The ray caster's entry/exit depths (the ray limits fusion gives the volume ray caster)
    and its segment count per pixel equal the reference's, on a torus whose rays enter twice."""
    from tetvr.reference.segments import ray_segments

    mesh = synthetic.torus(n_around=16)
    # y up, the view these bars were measured in (a pixel grazing the silhouette sets the max)
    cam = Camera.fit(mesh, direction=(-0.3, -0.5, -1.0), view_up=(0, 1, 0))
    size = (48, 40)
    front, back = marcher.depth_extent(mesh, cam, size=size)
    counts = marcher.segment_counts(mesh, cam, size=size)
    seg = ray_segments(mesh, cam, size)
    n = size[0] * size[1]
    want_front = np.full(n, np.inf)
    want_back = np.full(n, -np.inf)
    np.minimum.at(want_front, seg.pixel, seg.t_in)
    np.maximum.at(want_back, seg.pixel, seg.t_out)
    want_counts = np.bincount(seg.pixel, minlength=n).reshape(size[1], size[0])
    covered = np.isfinite(want_front.reshape(size[1], size[0]))
    assert covered.mean() > 0.2
    agree = np.isfinite(front) == covered
    assert agree.mean() > 0.99  # pixel centres grazing the silhouette may differ
    both = covered & np.isfinite(front)
    assert np.abs(front[both] - want_front.reshape(size[1], size[0])[both]).max() < 1e-5 * cam.clipping_range[1]
    assert np.abs(back[both] - want_back.reshape(size[1], size[0])[both]).max() < 1e-5 * cam.clipping_range[1]
    assert np.mean(counts[both] == want_counts[both]) > 0.98  # zero-length grazes may count either way


@pytest.mark.parametrize("parallel", [False, True])
def test_segment_estimate_of_the_auto_choice(marcher, parallel):
    """method="auto" weighs segments per tet (what tet marching pays for) against tets
    (what projected tetrahedra pay for); the estimate from a sample of tets matches the
    segments the ray caster walks (exactly in parallel projection, to a few per cent in
    perspective, where each tet is scaled at its centroid)."""
    from tetvr.order.method import segments_per_tet

    mesh = synthetic.cube(3)
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0), parallel=parallel)
    for size in ((64, 64), (200, 160)):
        walked = marcher.segment_counts(mesh, cam, size=size).sum() / mesh.n_tets
        estimate = segments_per_tet(mesh, cam, size)
        assert abs(estimate / walked - 1.0) < (0.01 if parallel else 0.1), (size, estimate, walked)
    # A few large tets at a large size: each ray's setup outweighs the few triangles, and
    # the convex cube's cell order is exact, so projected tetrahedra; small: tet marching.
    assert segments_per_tet(mesh, cam, (1024, 1024)) > 1000.0
    assert choose(RenderSettings(), mesh, cam, (1024, 1024)) == "projected"
    assert choose(RenderSettings(), mesh, cam, (32, 32)) == "raymarch"

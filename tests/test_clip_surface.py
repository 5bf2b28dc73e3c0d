"""Clip planes and boxes, and opaque surfaces inside the mesh, against the exact reference.

Both GPU methods cut each ray--tet segment to the pixel's window exactly as the reference
does (tetvr.core.clip.ray_window; the surface's hit from tetvr.core.surface.surface_hits), so the
error is the table's interpolation (~1e-4 here) plus float32 geometry. The surfaces' hits
are intersected per pixel on the GPU too, so coverage agrees to rounding: a silhouette
pixel the rasteriser and the reference decided differently would show as an error near 1,
which the max-error bound (1/255) would catch.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tetvr
from tetvr import Camera, Clip, RenderSettings, Surface, TransferFunction
from tetvr.mesh import synthetic
from tetvr.core.clip import MAX_CLIP_PLANES, ray_window
from tetvr.core.image import psnr
from tetvr.reference.tets import render_reference
from tetvr.render import default_transfer_function
from tetvr.core.surface import surface_hits

from .conftest import save_failure, shared_file

SIZE = (72, 72)
MAX_ERROR = 1 / 255
MIN_PSNR = 90.0
METHODS = ("raymarch", "projected")


def _tf(mesh: tetvr.TetMesh) -> TransferFunction:
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    return TransferFunction.preset("viridis", mesh.scalar_range, opacity=[(0.0, 0.2), (0.5, 0.6), (1.0, 0.9)],
                                   unit_distance=diag / 4)


def sphere(centre, radius, n=12, **kwargs) -> Surface:
    """A UV sphere of ``n`` bands (no trimesh needed)."""
    th = np.linspace(0, math.pi, n + 1)[1:-1]
    ph = np.linspace(0, 2 * math.pi, 2 * n, endpoint=False)
    ring = np.stack([np.sin(th)[:, None] * np.cos(ph), np.sin(th)[:, None] * np.sin(ph),
                     np.cos(th)[:, None] * np.ones_like(ph)], axis=-1).reshape(-1, 3)
    pts = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]]) * radius + np.asarray(centre)
    m, top, bottom = 2 * n, 0, len(pts) - 1
    tris = []
    for j in range(m):
        tris.append((top, 1 + j, 1 + (j + 1) % m))
    for i in range(n - 2):
        for j in range(m):
            a, b = 1 + i * m + j, 1 + i * m + (j + 1) % m
            tris += [(a, a + m, b), (b, a + m, b + m)]
    last = 1 + (n - 2) * m
    for j in range(m):
        tris.append((last + j, bottom, last + (j + 1) % m))
    return Surface(pts, np.array(tris), **kwargs)


@pytest.fixture(scope="module")
def renderers():
    rs = {m: tetvr.Renderer(RenderSettings(method=m)) for m in METHODS}
    yield rs
    for r in rs.values():
        with r.ctx:
            assert r.ctx.error == "GL_NO_ERROR"
        r.release()


def _check(name, got, want, min_psnr=MIN_PSNR, max_error=MAX_ERROR, max_beyond=0):
    assert np.all(np.isfinite(got))
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    value = psnr(got, want)
    beyond = int(np.count_nonzero(err > 1 / 255))
    if err.max() > max_error or beyond > max_beyond or value < min_psnr:
        where = save_failure(name, got, want)
        pytest.fail(f"{name}: max error {err.max():.3g}, {beyond} pixels beyond 1/255, {value:.1f} dB ({where})")


# ---- the value objects ----

def test_clip_planes_are_unit_and_keep_the_normal_side():
    c = Clip.plane((0, 0, 2), (0, 0, -3))
    assert c.planes == ((0.0, 0.0, -1.0, 2.0),)
    assert c.contains([[0, 0, 1], [0, 0, 3]]).tolist() == [True, False]
    box = Clip.box((0, 0, 0), (1, 2, 3))
    assert box.contains([[0.5, 1, 1], [1.5, 1, 1], [0.5, -0.1, 1]]).tolist() == [True, False, False]
    assert Clip.from_dict(box.to_dict()) == box
    both = Clip.from_dict({"box": [[0, 0, 0], [1, 2, 3]], "plane": {"origin": [0, 0, 2], "normal": [0, 0, -3]}})
    assert both.planes == c.planes + box.planes


@pytest.mark.parametrize("bad, match", [
    (dict(planes=()), "one or more"),
    (dict(planes=((0, 0, 0, 1),)), "zero normal"),
    (dict(planes=((0, 0, 1, float("nan")),)), "finite"),
    (dict(planes=((0, 0, 1, 0),) * (MAX_CLIP_PLANES + 1)), "at most"),
])
def test_bad_clips_are_refused(bad, match):
    with pytest.raises(ValueError, match=match):
        Clip(**bad)


def test_bad_boxes_and_dicts_are_refused():
    with pytest.raises(ValueError, match="lo < hi"):
        Clip.box((0, 0, 0), (1, 0, 1))
    with pytest.raises(ValueError, match="unknown clip keys"):
        Clip.from_dict({"sphere": 1})
    with pytest.raises(ValueError, match="three numbers"):
        Clip.plane((0, 0), (0, 0, 1))


def test_ray_window_matches_points_along_the_ray():
    """The interval ray_window gives is where the ray's points are kept."""
    rng = np.random.default_rng(3)
    clip = Clip.box((-1, -1, -1), (1, 1, 1)) & Clip.plane((0.2, 0, 0), (1, 0.5, 0.1))
    for parallel in (False, True):
        cam = Camera(position=(0.3, -4, 0.5), focal_point=(0, 0, 0), view_up=(0, 0, 1),
                     parallel_projection=parallel, parallel_scale=1.5, clipping_range=(0.1, 20))
        x, y = rng.uniform(-0.6, 0.6, 200), rng.uniform(-0.6, 0.6, 200)
        lo, hi = ray_window(clip.eye_planes(cam), x, y, parallel=parallel, near=0.1, far=20)
        ts = np.linspace(0.1, 20, 4001)
        scale = np.ones_like(ts) if parallel else ts
        eye = np.stack(np.broadcast_arrays(x[:, None] * scale, y[:, None] * scale, -ts[None, :]), axis=-1)
        inv = np.linalg.inv(cam.view_matrix())
        world = eye @ inv[:3, :3].T + inv[:3, 3]
        kept = clip.contains(world.reshape(-1, 3)).reshape(200, -1)
        inside = (ts >= lo[:, None]) & (ts <= hi[:, None])
        step = ts[1] - ts[0]
        near_end = (np.abs(ts - lo[:, None]) < step) | (np.abs(ts - hi[:, None]) < step)
        assert np.all((kept == inside) | near_end)
        assert kept.any()


def test_bad_surfaces_are_refused():
    with pytest.raises(ValueError, match=r"vertices 0\.\.2, got indices 0\.\.3"):
        Surface([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]])
    with pytest.raises(ValueError, match="NaN"):
        Surface([[0, 0, 0], [1, 0, 0], [0, float("nan"), 0]], [[0, 1, 2]])
    with pytest.raises(ValueError, match="RGB"):
        Surface([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], color=(2, 0, 0))
    with pytest.raises(TypeError, match="surfaces"):
        render_reference(synthetic.cube(2), Camera.fit(synthetic.cube(2)), _tf(synthetic.cube(2)), (4, 4),
                         surfaces=["not a surface"])


def test_a_surface_does_not_change_its_inputs():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float64)
    tri = np.array([[0, 1, 2]])
    s = Surface(pts, tri)
    pts[0, 0] = 5.0
    assert s.points[0, 0] == 0.0 and not s.points.flags.writeable


def test_surface_hits_of_a_sphere_are_where_the_sphere_is():
    """The reference's hit depth against the analytic sphere (a polygon inside it)."""
    s = sphere((0, 0, 0), 1.0, n=24)
    cam = Camera(position=(0, 0, 5), focal_point=(0, 0, 0), view_angle=30, clipping_range=(0.1, 20))
    t, rgb = surface_hits([s], cam, (32, 32))
    hit = np.isfinite(t)
    assert 0.3 < hit.mean() < 0.6
    assert t[hit].min() == pytest.approx(4.0, abs=0.02)  # the nearest point is 1 from the centre
    assert np.all(rgb[~hit] == 0) and rgb[hit].min() > 0


# ---- GPU against the reference ----

@pytest.mark.gl
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("parallel", [False, True])
def test_clipped_cube_matches_the_reference(renderers, method, parallel):
    mesh = synthetic.cube(6)
    tf = _tf(mesh)
    lo, hi = mesh.bounds
    c = 0.5 * (lo + hi)
    clips = {"plane": Clip.plane(c + 0.05, (1, 0.3, 0.2)),
             "box": Clip.box(lo + 0.2 * (hi - lo), hi - 0.3 * (hi - lo)),
             "wedge": Clip.plane(c, (1, 0.3, 0.2)) & Clip.plane(c, (0.2, -1, 0.1))}
    cam = Camera.fit(mesh, parallel=parallel)
    for name, clip in clips.items():
        want = render_reference(mesh, cam, tf, SIZE, clip=clip)
        got = renderers[method].render(mesh, cam, tf, size=SIZE, clip=clip)
        assert want[..., 3].max() > 0.1
        _check(f"clip_{name}_{method}_{parallel}", got, want)


@pytest.mark.gl
@pytest.mark.parametrize("method", METHODS)
def test_clip_from_inside_the_mesh(renderers, method):
    """The eye inside the mesh (near plane cutting tets) and a clip plane through the view.

    Projected tetrahedra get the view's cells beside the eye slightly out of order here
    with or without the clip (without: max 0.009, 42 pixels beyond 1/255; the same pixels
    with it: 0.017, 95; docs/limits.md, "beside the eye"), so their bound is that limit's;
    tet marching has no order to get wrong."""
    mesh = synthetic.cube(6)
    tf = _tf(mesh)
    lo, hi = mesh.bounds
    c = 0.5 * (lo + hi)
    cam = Camera(position=tuple(c + 0.1 * (hi - lo)), focal_point=tuple(c - (hi - lo)), view_up=(0, 0, 1),
                 view_angle=60, clipping_range=(0.01, 10))
    clip = Clip.plane(c, (0.3, 1, 0))
    want = render_reference(mesh, cam, tf, SIZE, clip=clip)
    got = renderers[method].render(mesh, cam, tf, size=SIZE, clip=clip)
    assert want[..., 3].max() > 0.1
    if method == "projected":
        _check(f"clip_inside_{method}", got, want, min_psnr=60.0, max_error=0.02, max_beyond=120)
    else:
        _check(f"clip_inside_{method}", got, want)


@pytest.mark.gl
@pytest.mark.parametrize("method", METHODS)
def test_a_clip_that_keeps_everything_changes_nothing_and_one_that_keeps_nothing_is_empty(renderers, method):
    mesh = synthetic.cube(4)
    tf = _tf(mesh)
    cam = Camera.fit(mesh)
    lo, hi = mesh.bounds
    r = renderers[method]
    plain = r.render(mesh, cam, tf, size=SIZE)
    everything = r.render(mesh, cam, tf, size=SIZE, clip=Clip.box(lo - 1, hi + 1))
    assert np.abs(everything - plain).max() <= 1e-6
    nothing = r.render(mesh, cam, tf, size=SIZE, clip=Clip.plane(hi + 1, (1, 1, 1)))
    assert np.all(nothing == 0)


@pytest.mark.gl
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("smooth", [False, True])
def test_opaque_surface_inside_matches_the_reference(renderers, method, parallel, smooth):
    """A sphere inside the cube, and a second one half out of it: the tets in front are
    composited over the lit surface, nothing behind it shows."""
    mesh = synthetic.cube(6)
    tf = _tf(mesh)
    lo, hi = mesh.bounds
    c = 0.5 * (lo + hi)
    side = float((hi - lo).max())
    surfaces = [sphere(c + 0.05 * side, 0.22 * side, color=(0.9, 0.4, 0.2), smooth=smooth),
                sphere(hi - 0.1 * side, 0.15 * side, n=8, color=(0.2, 0.5, 0.9), ambient=0.4, smooth=smooth)]
    cam = Camera.fit(mesh, parallel=parallel)
    want = render_reference(mesh, cam, tf, SIZE, surfaces=surfaces)
    got = renderers[method].render(mesh, cam, tf, size=SIZE, surfaces=surfaces)
    hit = np.isfinite(surface_hits(surfaces, cam, SIZE)[0])
    assert 0.05 < hit.mean() < 0.6
    assert np.all(want[hit, 3] == pytest.approx(1.0))
    _check(f"surface_{method}_{parallel}_{smooth}", got, want)


@pytest.mark.gl
@pytest.mark.parametrize("method", METHODS)
def test_surface_around_the_eye_and_clip(renderers, method):
    """The eye inside a surface that encloses part of the mesh (its triangles cross the
    near plane and behind the eye), with a clip box as well. Projected tetrahedra's bound is
    their limit beside the eye (this view without surface or clip: max 0.018, 337 pixels
    beyond 1/255; with both: 0.014, 299)."""
    mesh = synthetic.cube(6)
    tf = _tf(mesh)
    lo, hi = mesh.bounds
    c = 0.5 * (lo + hi)
    side = float((hi - lo).max())
    cam = Camera(position=tuple(c + 0.15 * side), focal_point=tuple(lo), view_up=(0, 0, 1), view_angle=70,
                 clipping_range=(0.01, 10))
    surfaces = [sphere(c, 0.45 * side, n=10, smooth=True)]
    clip = Clip.box(lo + 0.1 * side, hi)
    want = render_reference(mesh, cam, tf, SIZE, surfaces=surfaces, clip=clip)
    got = renderers[method].render(mesh, cam, tf, size=SIZE, surfaces=surfaces, clip=clip)
    assert want[..., 3].min() == pytest.approx(1.0)  # the sphere is everywhere behind
    if method == "projected":
        _check(f"surface_eye_inside_{method}", got, want, min_psnr=55.0, max_error=0.025, max_beyond=400)
    else:
        _check(f"surface_eye_inside_{method}", got, want)


@pytest.mark.gl
@pytest.mark.filterwarnings("ignore:dropped .* zero-volume")
def test_clipped_bluntfin_and_a_surface_in_it_match_the_reference(renderers):
    mesh = tetvr.read(shared_file("tets/bluntfin_tets.vtu"))
    tf = default_transfer_function(mesh)
    lo, hi = mesh.bounds
    c = 0.5 * (lo + hi)
    diag = float(np.linalg.norm(hi - lo))
    cam = Camera.fit(mesh)
    clip = Clip.plane(c, (0, 1, 0.3))
    surfaces = [sphere(c, 0.12 * diag, n=16, color=(0.9, 0.5, 0.2), smooth=True)]
    size = (96, 96)
    want = render_reference(mesh, cam, tf, size, clip=clip)
    got = renderers["raymarch"].render(mesh, cam, tf, size=size, clip=clip)
    _check("bluntfin_clip", got, want)
    want = render_reference(mesh, cam, tf, size, clip=clip, surfaces=surfaces)
    got = renderers["raymarch"].render(mesh, cam, tf, size=size, clip=clip, surfaces=surfaces)
    _check("bluntfin_clip_surface", got, want)


@pytest.mark.gl
def test_clip_and_surfaces_are_refused_where_they_do_not_apply():
    mesh = synthetic.cube(2)
    tf, cam = _tf(mesh), Camera.fit(mesh)
    with tetvr.Renderer(RenderSettings(optics="vtk")) as r:
        with pytest.raises(ValueError, match="VTK parity"):  # parity cuts the cells: their ids change
            r.render(mesh, cam, tf, size=(8, 8), clip=Clip.plane((0, 0, 0), (1, 0, 0)), order=np.arange(mesh.n_tets))
        with pytest.raises(TypeError, match="clip must be a tetvr.Clip"):
            r.render(mesh, cam, tf, size=(8, 8), clip=((1, 0, 0, 0),))
        with pytest.raises(ValueError, match="shader='tet'"):
            r.render(mesh, cam, tf, size=(8, 8), shader="floor", clip=Clip.plane((0, 0, 0), (1, 0, 0)))


def test_surface_from_trimesh_and_meshio(tmp_path):
    trimesh = pytest.importorskip("trimesh", reason="trimesh is in the 'mesh' extra")
    box = trimesh.creation.box(extents=(1, 2, 3))
    s = Surface.from_trimesh(box, color=(1, 0, 0))
    assert s.n_triangles == 12
    path = tmp_path / "box.stl"
    box.export(path)
    r = Surface.read(path)
    assert r.n_triangles == 12
    np.testing.assert_allclose(np.sort(r.corners.reshape(-1, 3), axis=0), np.sort(s.corners.reshape(-1, 3), axis=0),
                               atol=1e-6)
    with pytest.raises(FileNotFoundError, match="no surface file"):
        Surface.read(tmp_path / "missing.stl")


def _write_obj(path, surface: Surface) -> None:
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in surface.points]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in surface.triangles]
    path.write_text("\n".join(lines) + "\n")


def _cube_and_ball(folder):
    """cube.vtu and ball.obj (a sphere in its middle) in ``folder``; the cube's bounds."""
    import meshio

    mesh = synthetic.cube(3)
    meshio.write(folder / "cube.vtu", meshio.Mesh(mesh.points, [("tetra", mesh.tets)], point_data={"s": mesh.scalars}))
    lo, hi = mesh.bounds
    _write_obj(folder / "ball.obj", sphere(0.5 * (lo + hi), 0.2 * float((hi - lo).max()), n=6))
    return lo, hi


def test_a_scene_with_clip_and_surfaces_round_trips_and_renders(tmp_path):
    import json

    from tetvr.apps.cli import main
    from tetvr.scene.load import load_scene

    lo, hi = _cube_and_ball(tmp_path)
    c = 0.5 * (lo + hi)
    spec = {"mesh": "cube.vtu", "size": [24, 24], "clip": {"plane": {"origin": c.tolist(), "normal": [1, 0, 0]}},
            "surfaces": [{"path": "ball.obj", "color": [1, 0, 0], "smooth": True}]}
    (tmp_path / "scene.json").write_text(json.dumps(spec))
    scene = load_scene(tmp_path / "scene.json")
    assert scene.clip == Clip.plane(c, (1, 0, 0))
    assert scene.surfaces[0].smooth and scene.surfaces[0].color == (1.0, 0.0, 0.0)
    assert str(tmp_path / "ball.obj") in scene.input_paths()
    scene.save(tmp_path / "again.json")
    again = load_scene(tmp_path / "again.json")
    assert again.clip == scene.clip and again.surfaces[0].n_triangles == scene.surfaces[0].n_triangles
    want = render_reference(scene.mesh, scene.camera, scene.tf, (24, 24), **scene.render_options)
    assert want[..., 3].max() == pytest.approx(1.0)  # the ball shows
    assert main(["render", str(tmp_path / "scene.json"), "-o", str(tmp_path / "out.png"), "--reference",
                 "--npy", str(tmp_path / "out.npy"), "--no-annotations"]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "out.npy"), want)
    with pytest.raises(ValueError, match="unknown keys"):
        tetvr.Scene.from_dict(dict(spec, surfaces=[{"path": "ball.obj", "colour": [1, 0, 0]}]), tmp_path)


def test_cli_clip_and_surface_options(tmp_path):
    from tetvr.apps.cli import main

    lo, hi = _cube_and_ball(tmp_path)
    c = 0.5 * (lo + hi)
    args = ["render", str(tmp_path / "cube.vtu"), "--reference", "--size", "20x20", "--no-annotations"]
    assert main(args + ["-o", str(tmp_path / "a.png"), "--npy", str(tmp_path / "a.npy")]) == 0
    assert main(args + ["-o", str(tmp_path / "b.png"), "--npy", str(tmp_path / "b.npy"),
                        "--clip-box", *map(str, lo), *map(str, c), "--clip-plane", *map(str, c), "1", "1", "0",
                        "--surface", str(tmp_path / "ball.obj")]) == 0
    a, b = np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy")
    assert np.abs(a - b).max() > 0.05

"""The interactive viewer's logic without a browser: camera navigation, the progressive
refinement decisions, transfer-function editing, the model (with a recording renderer),
and the ipywidgets front-end when ipywidgets is installed."""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TransferFunction
from tetvr.mesh import synthetic
from tetvr.apps.viewer.model import (OrbitControl, ProgressiveRefiner, RenderRequest, TransferFunctionEditor, ViewerModel,
                          histogram_image, log_histogram, png_bytes)

ROOT = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------- camera
@pytest.fixture
def control():
    mesh = synthetic.cube(2)
    cam = Camera.fit(mesh, direction=(0, 0, -1), view_up=(0, 1, 0))
    return OrbitControl(cam, bounds=mesh.bounds, degrees_per_pixel=0.5), mesh


def _dist(cam):
    return float(np.linalg.norm(np.subtract(cam.position, cam.focal_point)))


def test_azimuth_and_drag_directions(control):
    c, _ = control
    start = c.camera
    right, up, _ = start.basis()
    d0 = _dist(start)
    moved = c.azimuth(10.0)
    assert np.dot(np.subtract(moved.position, start.position), right) > 0  # camera to its right
    assert _dist(moved) == pytest.approx(d0) and moved.focal_point == start.focal_point
    c.reset()
    # Dragging right turns the object right: the camera goes left, by 0.5 degree a pixel.
    dragged = c.drag(20, 0)
    assert np.dot(np.subtract(dragged.position, start.position), right) < 0
    v0 = np.subtract(start.position, start.focal_point)
    v1 = np.subtract(dragged.position, dragged.focal_point)
    assert np.degrees(np.arccos(np.dot(v0, v1) / d0**2)) == pytest.approx(10.0)
    c.reset()
    # Dragging down tilts the camera up (it looks down on the object).
    assert np.dot(np.subtract(c.drag(0, 20).position, start.position), up) > 0
    assert c.reset() is start


def test_orbit_over_the_pole_never_degenerates(control):
    c, _ = control
    for _ in range(30):  # 450 degrees of elevation: a trackball has no pole
        cam = c.elevation(15.0)
        assert abs(np.dot(cam.direction, cam.view_up)) < 1e-9
        assert _dist(cam) == pytest.approx(_dist(c.home))


def test_zoom_and_clipping_enclose_the_mesh(control):
    c, mesh = control
    d0 = _dist(c.camera)
    cam = c.zoom(2.0)
    assert _dist(cam) == pytest.approx(d0 / 2)
    centre = mesh.bounds.mean(axis=0)
    radius = 0.5 * np.linalg.norm(mesh.bounds[1] - mesh.bounds[0])
    for cam in (c.camera, c.zoom(0.25), c.azimuth(33), c.elevation(-71)):
        near, far = cam.clipping_range
        depth = np.dot(centre - np.asarray(cam.position), cam.direction)
        assert near <= max(depth - radius, 1e-3 * radius) + 1e-12 and far >= depth + radius
    # Dolly inside the mesh: near stays positive for a perspective camera.
    inside = c.zoom(50.0)
    assert 0 < inside.clipping_range[0] < inside.clipping_range[1]
    with pytest.raises(ValueError, match="zoom factor"):
        c.zoom(0.0)
    par = OrbitControl(Camera.fit(mesh, parallel=True), bounds=mesh.bounds)
    s0 = par.camera.parallel_scale
    assert par.zoom(4.0).parallel_scale == pytest.approx(s0 / 4) and par.camera.position == par.home.position


def test_pan_moves_eye_and_focus_together(control):
    c, _ = control
    start = c.camera
    right, up, _ = start.basis()
    cam = c.pan(10, 0, (100, 100))
    shift = np.subtract(cam.focal_point, start.focal_point)
    np.testing.assert_allclose(np.subtract(cam.position, start.position), shift, atol=1e-12)
    assert np.dot(shift, right) < 0 and abs(np.dot(shift, up)) < 1e-12  # the scene follows the pointer


# ---------------------------------------------------------------- progressive refinement
def test_refiner_previews_while_interacting_then_refines_once():
    r = ProgressiveRefiner((400, 300), preview_scale=0.25, settle_s=0.2)
    assert r.state == "idle" and r.preview_size == (100, 75)
    assert r.finish() == RenderRequest((400, 300), sort=True, final=True)  # first frame
    assert r.poll(10.0) is None  # idle: nothing to do
    assert r.change(1.0) == RenderRequest((100, 75), sort=False, final=False)  # previous order reused
    assert r.change(1.1) == RenderRequest((100, 75), sort=False, final=False)
    assert r.poll(1.25) is None  # 0.15 s after the last change: still interacting
    assert r.state == "interacting" and r.seconds_to_refine == 0.2
    assert r.poll(1.3) == RenderRequest((400, 300), sort=True, final=True)  # camera moved: sort
    assert r.poll(1.4) is None and r.state == "idle"
    # A transfer-function edit does not move the camera: the final frame keeps the order.
    r.change(2.0, camera=False)
    assert r.poll(2.5) == RenderRequest((400, 300), sort=False, final=True)
    # New geometry: the next frame must sort, even a preview.
    r.invalidate_order()
    assert r.change(3.0, camera=False).sort is True
    with pytest.raises(ValueError, match="preview_scale"):
        ProgressiveRefiner((10, 10), preview_scale=0.0)


# ---------------------------------------------------------------- transfer-function editing
def test_editor_points_stay_ordered_and_ends_stay_put():
    ed = TransferFunctionEditor((-2.0, 2.0), points=[(0.0, 0.1), (1.0, 0.9)], unit_distance=0.5)
    assert ed.add_point(0.5, 0.4) == 1 and ed.add_point(0.25, 0.2) == 1
    assert ed.points == [(0.0, 0.1), (0.25, 0.2), (0.5, 0.4), (1.0, 0.9)]
    assert ed.add_point(0.5, 0.7) == 2 and len(ed.points) == 4  # same t: set, not insert
    t, a = ed.move_point(1, t=0.9, a=1.5)  # clamped below its right neighbour, a into [0, 1]
    assert t == pytest.approx(0.5 - ed.MIN_GAP) and a == 1.0
    assert ed.move_point(0, t=0.3, a=0.0) == (0.0, 0.0)  # ends move in opacity only
    with pytest.raises(ValueError, match="end points"):
        ed.remove_point(3)
    ed.remove_point(1)
    assert [p[0] for p in ed.points] == [0.0, 0.5, 1.0]
    with pytest.raises(IndexError):
        ed.move_point(7, a=0.1)
    tf = ed.transfer_function()
    assert tf.opacity == ((-2.0, 0.0), (0.0, 0.7), (2.0, 0.9)) and tf.unit_distance == 0.5
    assert tf.domain == (-2.0, 2.0)
    ed.set_range(0.0, 8.0)
    assert ed.transfer_function().opacity[1] == (4.0, 0.7)
    assert ed.nearest_point(0.48, 0.6) == 1


def test_editor_round_trips_a_transfer_function_and_switches_colour_maps():
    tf = TransferFunction(color=((1.0, 0, 0, 0), (2.0, 1, 0.5, 0), (3.0, 1, 1, 1)),
                          opacity=((1.0, 0.0), (2.5, 0.6), (3.0, 0.2)), unit_distance=0.7)
    ed = TransferFunctionEditor.from_transfer_function(tf)
    assert ed.colormap is None
    back = ed.transfer_function()
    assert back.unit_distance == tf.unit_distance
    np.testing.assert_allclose(back.color, tf.color, atol=1e-12)
    np.testing.assert_allclose(back.opacity, tf.opacity, atol=1e-12)
    ed.set_colormap("hot")
    assert ed.transfer_function().color == TransferFunction.preset("hot", (1.0, 3.0)).color
    with pytest.raises(ValueError, match="unknown colour map"):
        ed.set_colormap("no-such-map")
    assert ed.colormap == "hot"
    with pytest.raises(ValueError, match="unit_distance"):
        ed.set_unit_distance(-1.0)


def test_histogram_is_log_scaled_and_drawn():
    values = np.concatenate([np.zeros(999), [1.0]])
    logc, edges = log_histogram(values, (0.0, 1.0), bins=4)
    np.testing.assert_allclose(logc, [3.0, 0.0, 0.0, np.log10(2.0)])
    assert edges[0] == 0.0 and edges[-1] == 1.0
    ed = TransferFunctionEditor((0.0, 1.0), points=[(0, 0), (0.5, 0.5), (1, 1)])
    img = ed.image(values, size=(80, 40), selected=1)
    assert img.shape == (40, 80, 4) and np.all(img[..., 3] == 1.0)
    # The selected point's red square sits at t = 0.5, a = 0.5.
    cy, cx = int(round(0.5 * 37)) + 1, int(round(0.5 * 79))
    np.testing.assert_allclose(img[cy, cx, :3], (1.0, 0.2, 0.2), atol=1e-6)
    # The tall first bar (log10 1000) reaches near the top; the empty middle has none.
    assert not np.allclose(img[5, 0, :3], img[5, 40, :3])
    png = png_bytes(img, None)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert histogram_image(values, ed.transfer_function(), (0, 1), size=(20, 10)).shape == (10, 20, 4)


# ---------------------------------------------------------------- the model
class RecordingRenderer:
    """Stands in for tetvr.gl.Renderer: records what it was asked to draw."""

    def __init__(self):
        self.calls = []

    def render(self, mesh, camera, tf, *, size, order=None):
        self.calls.append(dict(mesh=mesh, camera=camera, tf=tf, size=size, order=order))
        return np.zeros((size[1], size[0], 4), np.float32)

    def fuse(self, mesh, volume, camera, tf, volume_tf, *, size, mode):
        self.calls.append(dict(mesh=mesh, volume=volume, camera=camera, tf=tf, volume_tf=volume_tf, size=size,
                               mode=mode))
        return np.zeros((size[1], size[0], 4), np.float32)

    def release(self):
        pass


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def _scene(tmp_path, size=(80, 60)):
    """A mesh file with two point fields and a cell field, and a scene for it."""
    import meshio

    mesh = synthetic.cube(2)
    meshio.write(tmp_path / "two.vtu", meshio.Mesh(
        mesh.points, [("tetra", mesh.tets)],
        point_data={"temperature": mesh.scalars, "pressure": 10.0 + 5.0 * mesh.points[:, 0]},
        cell_data={"material": [np.arange(mesh.n_tets) % 3 * 1.0]}))
    (tmp_path / "scene.json").write_text(json.dumps({
        "mesh": "two.vtu", "scalars": "temperature", "size": list(size),
        "transfer_function": {"preset": "cool-to-warm", "opacity": [[0, 0.1], [1, 0.8]]}}))
    return tetvr.load_scene(tmp_path / "scene.json")


def test_model_progressive_frames_reuse_the_order(tmp_path, monkeypatch):
    import tetvr.order.sort

    sorts = []
    real = tetvr.order.sort.visibility_order
    monkeypatch.setattr(tetvr.order.sort, "visibility_order", lambda m, c, s: sorts.append(c) or real(m, c, s))
    rec, clock = RecordingRenderer(), Clock()
    model = ViewerModel(_scene(tmp_path), renderer=rec, clock=clock, preview_scale=0.5, settle_s=0.3)
    model.settings = dataclasses.replace(model.settings, method="projected")  # the ray caster needs no order
    model.final()
    assert rec.calls[-1]["size"] == (80, 60) and len(sorts) == 1
    first_order = rec.calls[-1]["order"]
    np.testing.assert_array_equal(first_order, real(model.mesh, model.camera, model.settings.sort))
    # Drag: two previews at half size with the first order, no sort.
    for k in range(2):
        clock.now += 0.05
        model.control.drag(15, 5)
        model.changed()
        assert rec.calls[-1]["size"] == (40, 30) and rec.calls[-1]["order"] is first_order
    assert len(sorts) == 1 and model.last_request.final is False
    clock.now += 0.1
    assert model.poll() is None
    clock.now += 0.3
    model.poll()
    assert rec.calls[-1]["size"] == (80, 60) and len(sorts) == 2 and sorts[-1] is model.camera
    assert not np.array_equal(rec.calls[-1]["order"], first_order)
    # A transfer-function edit re-renders without sorting.
    model.editor.move_point(0, a=0.5)
    model.changed(camera=False)
    clock.now += 1.0
    model.poll()
    assert len(sorts) == 2 and rec.calls[-1]["tf"].opacity[0][1] == 0.5


def test_model_fields_save_and_load(tmp_path):
    rec = RecordingRenderer()
    model = ViewerModel(_scene(tmp_path), renderer=rec)
    assert model.fields == ["temperature", "pressure", "material"]
    model.set_field("pressure")
    assert model.mesh.scalar_name == "pressure"
    assert model.editor.scalar_range == pytest.approx(model.mesh.scalar_range)
    assert model.editor.points[-1][1] == pytest.approx(0.8)  # the opacity points were kept
    model.set_field("material")  # a cell field, averaged onto the points
    with pytest.raises(KeyError, match="no field"):
        model.set_field("nope")
    model.set_colormap("hot")
    model.control.azimuth(40.0)
    (tmp_path / "sub").mkdir()
    saved = model.save(tmp_path / "sub" / "view.json")
    data = json.loads(saved.read_text())
    assert data["mesh"] == "../two.vtu" and data["scalars"] == "material"
    again = tetvr.load_scene(saved)
    assert again.camera == model.camera
    assert again.tf == model.editor.transfer_function()
    other = ViewerModel(again, renderer=rec)
    other.load(tmp_path / "scene.json")
    assert other.field == "temperature" and other.camera == tetvr.load_scene(tmp_path / "scene.json").camera


class CheckingRenderer(RecordingRenderer):
    """A recording renderer that refuses what the GPU renderer refuses (float32 ranges)."""

    def render(self, mesh, camera, tf, *, size, order=None):
        from tetvr.order.precision import check_float32_range

        check_float32_range(mesh, tf)
        return super().render(mesh, camera, tf, size=size, order=order)


def _constant_scene(tmp_path):
    import meshio

    mesh = synthetic.cube(2)
    meshio.write(tmp_path / "const.vtu", meshio.Mesh(
        mesh.points, [("tetra", mesh.tets)],
        point_data={"temperature": mesh.scalars, "five": np.full(mesh.n_points, 5.0)}))
    (tmp_path / "scene.json").write_text(json.dumps({"mesh": "const.vtu", "scalars": "temperature",
                                                     "size": [40, 30]}))
    return tmp_path / "scene.json"


def test_model_renders_a_constant_field(tmp_path):
    """A constant field gets the transfer function range tetvr.render would give it, wide
    enough for the GPU's float32 (it used to be refused as 'too narrow')."""
    from tetvr.render import default_transfer_function

    path = _constant_scene(tmp_path)
    model = ViewerModel(path, renderer=CheckingRenderer())  # a scene path works too
    model.final()
    model.set_field("five")
    model.final()
    model.changed(camera=False)
    assert model.editor.scalar_range == default_transfer_function(model.mesh).domain
    lo, hi = model.editor.scalar_range
    assert lo == 5.0 and hi > lo


def _fake_renderers(monkeypatch) -> list:
    """tetvr.gl.renderer.Renderer replaced by a RecordingRenderer that remembers its
    settings and whether it was released; returns the list of those made."""
    import tetvr.gl.renderer

    made = []

    class FakeRenderer(RecordingRenderer):
        def __init__(self, settings=None):
            super().__init__()
            self.settings, self.released = settings, False
            made.append(self)

        def release(self):
            self.released = True

    monkeypatch.setattr(tetvr.gl.renderer, "Renderer", FakeRenderer)
    return made


def test_model_rebuilds_its_renderer_when_the_settings_change(tmp_path, monkeypatch):
    made = _fake_renderers(monkeypatch)
    scene = _scene(tmp_path)
    model = ViewerModel(scene)
    model.final()
    model.load(scene)  # the same settings: the renderer is kept
    model.final()
    assert len(made) == 1 and not made[0].released
    faster = dataclasses.replace(scene, settings=dataclasses.replace(scene.settings, sort="centroid"))
    assert faster.settings != scene.settings
    model.load(faster)
    model.final()
    assert len(made) == 2 and made[0].released and made[1].settings == faster.settings
    # A renderer the caller gave is the caller's: kept whatever the settings.
    rec = RecordingRenderer()
    other = ViewerModel(scene, renderer=rec)
    other.load(faster)
    other.final()
    assert other.renderer is rec and rec.calls


@pytest.mark.gl
def test_model_refined_frame_is_the_plain_render():
    scene = tetvr.load_scene(tetvr.demo_scene_path())
    scene = dataclasses.replace(scene, size=(96, 72))
    model = ViewerModel(scene)
    try:
        model.control.azimuth(25.0)
        preview = model.changed()
        assert preview.shape == (36, 48, 4)
        final = model.final()
        want = tetvr.render(scene.mesh, camera=model.camera, tf=scene.tf, size=(96, 72))
        assert np.array_equal(final, want)
        # A scene's clip is drawn by the viewer, and saved with its scene.
        lo, hi = scene.mesh.bounds
        clipped = dataclasses.replace(scene, clip=tetvr.Clip.plane(0.5 * (lo + hi), (0, 1, 0)))
        model.load(clipped)
        model.control.azimuth(25.0)
        want = tetvr.render(scene.mesh, camera=model.camera, tf=scene.tf, size=(96, 72), clip=clipped.clip)
        assert np.array_equal(model.final(), want) and model.scene().clip == clipped.clip
        model.load(scene)
        # A transfer-function edit's preview uses the small table; the full frame the full one.
        model.editor.move_point(0, a=0.3)
        tf = model.editor.transfer_function()
        model.draw(model.mesh, model.camera, tf, RenderRequest((48, 36), sort=False, final=False), preview_table=True)
        assert model.renderer.settings == model.preview_settings != model.settings
        assert model.renderer.table(model.mesh, tf).data.shape[1] == 64
        final = model.final()
        assert model.renderer.settings == model.settings
        assert np.array_equal(final, tetvr.render(scene.mesh, camera=model.camera, tf=tf, size=(96, 72)))
    finally:
        model.close()


# ---------------------------------------------------------------- the render loop
class SlowRenderer(RecordingRenderer):
    """A recording renderer that takes ``seconds`` a frame (and can be told to fail)."""

    def __init__(self, seconds=0.05):
        super().__init__()
        self.seconds, self.fail = seconds, None

    def render(self, mesh, camera, tf, *, size, order=None):
        import time

        time.sleep(self.seconds)
        if self.fail:
            raise RuntimeError(self.fail)
        return super().render(mesh, camera, tf, size=size, order=order)


def test_preview_sizer_follows_the_measured_cost():
    from tetvr.apps.viewer.loop import PreviewSizer

    full = (400, 300)
    s = PreviewSizer(budget_s=0.1, min_scale=0.1, max_growth=1.25)
    s.observe(1.6, size=full, full=full)  # 1.6 s for the full frame: 1/16 of the pixels
    assert s.scale == pytest.approx(0.25) and s.size(full) == (100, 75)
    s.observe(0.01, size=(100, 75), full=full)  # a cheap preview: grows, but by 25 % at most
    assert s.scale == pytest.approx(0.3125)
    # Frames of 40 ms + 1 us a pixel: the fit finds both; the budget's 60 ms buy 60k pixels.
    s = PreviewSizer(budget_s=0.1, min_scale=0.05, max_growth=10.0)
    for w, h in [(400, 300), (200, 150), (100, 75), (300, 225)]:
        s.observe(0.04 + 1e-6 * w * h, size=(w, h), full=full)
    assert s.overhead_s == pytest.approx(0.04) and s.per_pixel_s == pytest.approx(1e-6)
    assert s.size(full)[0] * s.size(full)[1] == pytest.approx(60_000, rel=0.01)
    # The overhead alone is over the budget: the pixels get half the budget (25 ms: 25k pixels).
    s = PreviewSizer(budget_s=0.05, min_scale=0.05, max_growth=10.0)
    for w, h in [(400, 300), (200, 150), (100, 75)]:
        s.observe(0.08 + 1e-6 * w * h, size=(w, h), full=full)
    assert s.size(full)[0] * s.size(full)[1] == pytest.approx(25_000, rel=0.02)
    # A loaded machine: a fixed 0.3 s and 4 us a pixel. The pixels get 50 ms (12.5k, under
    # min_scale: 140 px wide), not as much as the fixed cost (75k pixels, a 0.6 s preview).
    s = PreviewSizer(budget_s=0.1, max_growth=10.0)
    for w, h in [(560, 420), (140, 105), (280, 210)]:
        s.observe(0.3 + 4e-6 * w * h, size=(w, h), full=(560, 420))
    assert s.overhead_s == pytest.approx(0.3) and s.size((560, 420)) == (140, 105)
    s.observe(100.0, size=full, full=full)
    assert s.scale >= 0.05  # never below min_scale
    with pytest.raises(ValueError, match="budget_s"):
        PreviewSizer(budget_s=0.0)
    # A cold frame (bluntfin's first: 10 s, the mesh sent and its records built) bounds the
    # cost until a warm frame is measured; it is not a sample, and it never shrinks a warm estimate.
    full = (560, 420)
    s = PreviewSizer(budget_s=0.1)
    s.observe(10.0, size=full, full=full, cold=True)
    assert s.size(full) == (140, 105) and s.samples == []  # a quarter of the width at least
    s.observe(4.3e-6 * 140 * 105, size=(140, 105), full=full)  # warm: 4.3 us a pixel
    assert s.size(full)[0] * s.size(full)[1] == pytest.approx(0.1 / 4.3e-6, rel=0.02)  # ~176 px wide
    s.observe(30.0, size=full, full=full, cold=True)
    assert s.size(full)[0] * s.size(full)[1] == pytest.approx(0.1 / 4.3e-6, rel=0.02)
    s.reset()
    assert s.samples == [] and s.scale == 0.5


class CostedRenderer(RecordingRenderer):
    """Takes no time, but moves a fake clock on by what a frame would cost: ``cold_s`` for
    the first frame of a mesh, ``per_pixel_s`` a pixel after that."""

    def __init__(self, clock, cold_s, per_pixel_s):
        super().__init__()
        self.clock, self.cold_s, self.per_pixel_s = clock, cold_s, per_pixel_s
        self.meshes = set()

    def render(self, mesh, camera, tf, *, size, order=None):
        cold = id(mesh) not in self.meshes
        self.meshes.add(id(mesh))
        self.clock.now += self.cold_s if cold else self.per_pixel_s * size[0] * size[1]
        return super().render(mesh, camera, tf, size=size, order=order)


def test_render_loop_sizes_previews_by_the_warm_cost_of_this_mesh(tmp_path):
    """bluntfin at 560x420: a 10 s first frame, then 4.3 us a pixel (measured through the
    render process). The first frame's cost is no measure of a preview's: previews are a
    quarter of the width before a warm frame is measured, then the ~23k pixels 0.1 s buys."""
    from tetvr.apps.viewer.loop import RenderLoop

    clock = Clock()
    rec = CostedRenderer(clock, cold_s=10.0, per_pixel_s=4.3e-6)
    model = ViewerModel(_scene(tmp_path, size=(560, 420)), renderer=rec)
    loop = RenderLoop(model, lambda f: None, settle_s=0.25, budget_s=0.1, clock=clock)
    try:
        loop.update(final=True)
        assert loop.wait_idle(10) and loop.last_frame.seconds == 10.0
        sizes = []
        for _ in range(3):
            n = loop.frames
            loop.update(lambda m: m.control.azimuth(2.0))
            sizes.append(loop.wait_frame(n, 10).size)
        loop.settle()
        assert loop.wait_idle(10) and loop.last_frame.size == (560, 420)
        assert sizes[0] == (140, 105)
        assert all(w * h == pytest.approx(0.1 / 4.3e-6, rel=0.02) for w, h in sizes[1:]), sizes
        # Another mesh: its first frame is cold again, and the last mesh's costs are forgotten.
        rec.per_pixel_s = 1e-6
        loop.update(lambda m: setattr(m, "mesh", synthetic.cube(3)), final=True)
        assert loop.wait_idle(10) and loop.sizer.samples == []
        n = loop.frames
        loop.update(lambda m: m.control.azimuth(2.0))
        assert loop.wait_frame(n, 10).size == (140, 105)
    finally:
        loop.close()


def test_render_loop_draws_the_latest_state_and_drops_stale_ones(tmp_path):
    from tetvr.apps.viewer.loop import RenderLoop

    rec = SlowRenderer(0.05)
    model = ViewerModel(_scene(tmp_path, size=(80, 60)), renderer=rec)
    frames = []
    loop = RenderLoop(model, frames.append, settle_s=0.15, budget_s=0.01)
    try:
        time.sleep(0.2)
        assert rec.calls == []  # nothing is drawn before something is wanted
        loop.update(final=True)
        assert loop.wait_idle(10)
        assert len(frames) == 1 and frames[-1].final and frames[-1].size == (80, 60)  # drawn once
        n0, start = len(rec.calls), model.camera
        for _ in range(40):  # 40 inputs in ~0.2 s against 50 ms frames
            loop.update(lambda m: m.control.azimuth(1.0))
        assert loop.wait_idle(10)
        drawn = rec.calls[n0:]
        assert 2 <= len(drawn) < 10  # merged into few frames, not 40 queued ones
        assert [f.final for f in frames[-len(drawn):]] == [False] * (len(drawn) - 1) + [True]
        assert all(c["size"][0] < 80 for c in drawn[:-1]) and drawn[-1]["size"] == (80, 60)
        # The full frame shows the latest state: all 40 degrees.
        assert drawn[-1]["camera"] == model.camera != start
        assert frames[-1].revision == loop.revision and frames[-1].wanted_at > 0
        # The end of an input (mouse-up) asks for the full frame at once, not settle_s later.
        loop.settle_s = 30.0
        loop.update(lambda m: m.control.azimuth(1.0))
        assert not loop.wait_idle(0.3)
        loop.settle()
        assert loop.wait_idle(10) and frames[-1].final and rec.calls[-1]["camera"] == model.camera
        # While a button is held, a pause longer than settle_s is not the end of the drag.
        loop.settle_s, loop.hold_settle_s = 0.05, 30.0
        loop.hold()
        loop.update(lambda m: m.control.azimuth(1.0))
        assert not loop.wait_idle(0.4) and not frames[-1].final
        loop.settle()
        assert loop.wait_idle(10) and frames[-1].final
    finally:
        loop.close()
    with pytest.raises(RuntimeError, match="closed"):
        loop.update()


def test_render_loop_previews_transfer_function_edits_with_the_small_table(tmp_path):
    from tetvr.apps.viewer.loop import RenderLoop

    model = ViewerModel(_scene(tmp_path), renderer=SlowRenderer(0.02))
    seen = []
    real = model.draw
    model.draw = lambda *a, preview_table=False, **kw: seen.append((a[3].final, preview_table)) or real(
        *a, preview_table=preview_table, **kw)
    loop = RenderLoop(model, lambda f: None, settle_s=0.1)
    try:
        loop.update(final=True)
        assert loop.wait_idle(10)
        loop.update(lambda m: m.control.azimuth(5.0))  # camera: previews keep the full table
        assert loop.wait_idle(10)
        assert seen[1:] == [(False, False), (True, False)]
        del seen[:]
        loop.update(lambda m: m.editor.move_point(0, a=0.4), camera=False)  # opacity edit
        loop.update(lambda m: m.control.azimuth(5.0))  # and a camera move before the full frame
        assert loop.wait_idle(10)
        assert seen[0] == (False, True) and seen[-1] == (True, False)
    finally:
        loop.close()


def test_render_loop_reports_errors_and_recovers(tmp_path):
    from tetvr.apps.viewer.loop import RenderLoop

    rec = SlowRenderer(0.0)
    frames = []
    loop = RenderLoop(ViewerModel(_scene(tmp_path), renderer=rec), frames.append, settle_s=0.0)
    try:
        rec.fail = "cannot create texture"
        loop.update(final=True)
        assert loop.wait_idle(10)
        assert frames[-1].error == "RuntimeError: cannot create texture" and frames[-1].image is None
        assert "cannot create texture" in loop.last_error
        rec.fail = None
        loop.update(lambda m: m.control.azimuth(5.0), final=True)
        assert loop.wait_idle(10) and frames[-1].error is None and frames[-1].final
    finally:
        loop.close()


# ---------------------------------------------------------------- the Jupyter viewer (no browser)
@pytest.fixture(autouse=True)
def _browser_stub(monkeypatch):
    """What the browser does with the picture's frames: each frame sent is recorded in
    ``canvas.sent`` and acknowledged at once (``canvas.acks = False``: never)."""
    try:
        from tetvr.apps.viewer.jupyter import _Canvas
    except ImportError:  # no jupyter_rfb: the viewer's tests skip
        return
    real = _Canvas._rfb_send_frame

    def send(self, array, is_lossless_redraw=False):
        real(self, array, is_lossless_redraw)
        self.__dict__.setdefault("sent", []).append(array)
        if self.__dict__.get("acks", True):
            self._frame_feedback = {"index": self._rfb_frame_index, "timestamp": 0.0, "localtime": 0.0}

    monkeypatch.setattr(_Canvas, "_rfb_send_frame", send)


def _viewer(tmp_path, renderer=None, **kw):
    pytest.importorskip("jupyter_rfb", reason="the Jupyter viewer needs jupyter_rfb: pip install -e '.[widget]'")
    from tetvr.apps.viewer import Viewer

    v = Viewer(_scene(tmp_path), renderer=renderer or RecordingRenderer(), **kw)
    v.canvas._has_visible_views = True  # the page shows it
    return v


def _drag(target, points, button=1, modifiers=()):
    (x0, y0), rest = points[0], points[1:]
    target({"type": "pointer_down", "x": x0, "y": y0, "button": button, "buttons": (button,), "modifiers": modifiers})
    for x, y in rest:
        target({"type": "pointer_move", "x": x, "y": y, "button": button, "buttons": (button,),
                "modifiers": modifiers})
    target({"type": "pointer_up", "x": rest[-1][0], "y": rest[-1][1], "button": button, "buttons": (),
            "modifiers": modifiers})


def test_viewer_mouse_orbits_pans_zooms_and_ends_on_the_full_frame(tmp_path):
    v = _viewer(tmp_path, SlowRenderer(0.01), settle_s=0.1)
    try:
        assert v.loop.wait_idle(10)
        first = v.canvas.sent[-1]
        assert first.shape == (60, 80, 3) and first.dtype == np.uint8 and "full 80×60" in v.status.value
        home = v.model.camera
        _drag(v._image_event, [(10, 10), (20, 12), (30, 15)])
        assert v.model.camera.position != home.position and v.model.camera.focal_point == home.focal_point
        orbited = v.model.camera
        _drag(v._image_event, [(10, 10), (30, 10)], modifiers=("Shift",))  # pans: the focal point moves
        assert v.model.camera.focal_point != orbited.focal_point
        d0 = _dist(v.model.camera)
        v._image_event({"type": "wheel", "dx": 0, "dy": -100, "x": 5, "y": 5})
        assert _dist(v.model.camera) == pytest.approx(d0 / 1.1)
        assert v.loop.wait_idle(10)
        assert v.canvas.sent[-1].shape == (60, 80, 3) and "full" in v.status.value
        assert v.model.renderer.calls[-1]["camera"] == v.model.camera
    finally:
        v.close()


def test_viewer_shows_render_errors(tmp_path):
    rec = SlowRenderer(0.0)
    rec.fail = "image of NaN"
    v = _viewer(tmp_path, rec)
    try:
        assert v.loop.wait_idle(10)
        assert "error" in v.status.value and "image of NaN" in v.status.value
        v.lo.value = v.hi.value + 1.0  # an impossible range is shown too, not raised
        assert "scalar range" in v.status.value
    finally:
        v.close()


def test_histogram_edits_click_drag_double_click_and_rebuild_little(tmp_path, monkeypatch):
    import tetvr.order.sort
    import tetvr.apps.viewer.model as widget

    from tetvr.apps.viewer.jupyter import HIST_SIZE

    v = _viewer(tmp_path)
    sorts, passes = [], []
    real_sort, real_hist = tetvr.order.sort.visibility_order, widget.log_histogram
    try:
        v.model.settings = dataclasses.replace(v.model.settings, method="projected")
        v.loop.update(final=True)
        assert v.loop.wait_idle(10)
        v._hist_frame()
        monkeypatch.setattr(tetvr.order.sort, "visibility_order", lambda *a: sorts.append(1) or real_sort(*a))
        monkeypatch.setattr(widget, "log_histogram", lambda *a: passes.append(1) or real_hist(*a))
        renderer, n = v.model.renderer, len(v.model.editor.points)
        w_px, h_px = HIST_SIZE
        # Click on empty space: a point there; drag it; the picture follows.
        before = v._hist_frame()
        _drag(v._hist_event, [(w_px * 0.4, h_px * 0.5), (w_px * 0.45, h_px * 0.2)])
        assert len(v.model.editor.points) == n + 1
        t, a = v.model.editor.points[v.picker.selected]
        assert t == pytest.approx(0.45 * w_px / (w_px - 1), abs=0.01) and a == pytest.approx(0.81, abs=0.02)
        assert not np.array_equal(v._hist_frame(), before)
        assert v.loop.wait_idle(10)
        assert renderer.calls[-1]["tf"] == v.model.editor.transfer_function() and renderer.calls[-1]["size"] == (80, 60)
        # Double-click on it: gone. The end points stay.
        x, y = t * (w_px - 1), (1 - a) * (h_px - 3) + 1
        v._hist_event({"type": "double_click", "x": x, "y": y})
        assert len(v.model.editor.points) == n
        v._hist_event({"type": "double_click", "x": 0, "y": (1 - v.model.editor.points[0][1]) * (h_px - 3) + 1})
        assert len(v.model.editor.points) == n
        assert v.loop.wait_idle(10)
        # Opacity edits: no sort, no pass over the field's values, the same renderer.
        assert sorts == [] and passes == [] and v.model.renderer is renderer
    finally:
        v.close()


def test_a_control_echoing_its_value_back_draws_nothing(tmp_path):
    """The browser sends the unit-distance slider's value back through log10 and 10**x, one
    ulp off: a viewer shown and left alone draws its full frame once, not a preview and a
    second full frame. A real change still draws."""
    v = _viewer(tmp_path, SlowRenderer(0.0), settle_s=0.05)
    try:
        assert v.loop.wait_idle(10) and v.loop.frames == 1
        u, (lo, hi) = v.model.editor.unit_distance, v.model.editor.scalar_range
        v.unit.value = float(np.nextafter(u, np.inf))  # the slider's echo
        v.lo.value = float(np.nextafter(lo, -np.inf))  # a text box's, should one round
        time.sleep(0.2)
        assert v.loop.wait_idle(10) and v.loop.frames == 1 and v.loop.revision == 1
        assert v.model.editor.unit_distance == u and v.model.editor.scalar_range == (lo, hi)
        v.unit.value = 2 * u
        assert v.loop.wait_idle(10) and v.loop.frames > 1 and v.model.editor.unit_distance == 2 * u
    finally:
        v.close()


def test_nothing_is_sent_before_the_page_shows_a_view(tmp_path):
    pytest.importorskip("jupyter_rfb", reason="the Jupyter viewer needs jupyter_rfb: pip install -e '.[widget]'")
    from tetvr.apps.viewer import Viewer

    v = Viewer(_scene(tmp_path), renderer=RecordingRenderer())
    try:
        assert v.loop.wait_idle(10) and "sent" not in v.canvas.__dict__  # the page would drop it
        v.canvas._has_visible_views = True
        assert len(v.canvas.sent) == 1 and v.canvas.sent[0].shape == (60, 80, 3)
    finally:
        v.close()


def test_frames_go_out_while_a_cell_keeps_the_kernel_busy(tmp_path):
    """A viewer made in a running event loop (the kernel's), which a cell then blocks: the
    frames and the status still go out, two at a time until the browser acknowledges them."""
    import asyncio

    async def cell():
        v = _viewer(tmp_path, SlowRenderer(0.0), settle_s=0.0)
        v.canvas.acks = False
        try:
            assert v._kernel_loop is asyncio.get_running_loop()
            # (the page reported its view before the cell began: a frame sent earlier is lost)
            # The loop is blocked from here on: this cell neither awaits nor returns.
            assert v.loop.wait_idle(10) and len(v.canvas.__dict__.get("sent", [])) == 1
            assert "full 80×60" in v.status.value
            for k in range(3):
                v._camera(lambda c: c.azimuth(10.0), final=True)
                assert v.loop.wait_idle(10)
            assert len(v.canvas.sent) == 2  # two in flight: the newest waits in the slot ...
            v.canvas._frame_feedback = {"index": 2, "timestamp": 0.0, "localtime": 0.0}
            assert len(v.canvas.sent) == 3  # ... until the browser acknowledges them
            assert v.model.renderer.calls[-1]["camera"] == v.model.camera
        finally:
            v.close()

    asyncio.run(cell())


def test_viewer_resizes_with_the_page_keeping_the_aspect(tmp_path):
    v = _viewer(tmp_path)
    try:
        v._image_event({"type": "resize", "width": 40.0, "height": 60.0, "ratio": 2.0})
        assert v.canvas.css_height == "32px"  # 40 px wide at 4:3 (+ the 1 px border each side)
        assert v.loop.wait_idle(10) and v.model.size == (80, 60)
        v._image_event({"type": "resize", "width": 200.0, "height": 150.0, "ratio": 1.0})
        assert v.loop.wait_idle(10) and v.model.size == (200, 150) and v.canvas.sent[-1].shape == (150, 200, 3)
        # Each frame goes out once (a second send finds nothing new) ...
        n = len(v.canvas.sent)
        v._send()
        assert len(v.canvas.sent) == n
        # ... except to a new view, which reports its size: it gets the last frame again.
        v._image_event({"type": "resize", "width": 200.0, "height": 150.0, "ratio": 1.0})
        assert len(v.canvas.sent) == n + 1 and v.canvas.sent[-1] is v.canvas.sent[-2]
        assert v.canvas.quality == 100  # PNG: no lossless re-send of a preview after it
    finally:
        v.close()


def test_viewer_takes_a_mesh_file_a_mesh_or_a_scene(tmp_path):
    pytest.importorskip("jupyter_rfb", reason="the Jupyter viewer needs jupyter_rfb: pip install -e '.[widget]'")
    from tetvr.apps.viewer.model import DEFAULT_SIZE, scene_of
    from tetvr.apps.viewer import Viewer

    scene = _scene(tmp_path)
    v = Viewer(tmp_path / "two.vtu", renderer=RecordingRenderer())  # a mesh file is not read as JSON
    try:
        assert v.model.size == DEFAULT_SIZE and v.model.fields == ["temperature", "pressure", "material"]
    finally:
        v.close()
    mesh_scene = scene_of(scene.mesh, size=(30, 20))
    assert mesh_scene.size == (30, 20) and mesh_scene.mesh is scene.mesh
    with pytest.raises(ValueError, match="in memory"):
        ViewerModel(mesh_scene, renderer=RecordingRenderer()).save(tmp_path / "x.json")
    with pytest.raises(FileNotFoundError, match="no such scene or mesh file"):
        scene_of(tmp_path / "missing.vtu")
    with pytest.raises(TypeError, match="Scene, a TetMesh or the path"):
        scene_of(42)
    with pytest.raises(ValueError, match="size"):
        scene_of(scene, size=(0, 10))


def test_viewer_save_load_and_pickers(tmp_path):
    v = _viewer(tmp_path)
    try:
        v.colormap.value = "hot"
        assert v.model.editor.colormap == "hot"
        v.field.value = "pressure"
        assert v.model.mesh.scalar_name == "pressure" and v.lo.value == pytest.approx(v.model.editor.scalar_range[0])
        v.path.value = str(tmp_path / "saved.json")
        v._save()
        assert "saved" in v.status.value and (tmp_path / "saved.json").is_file()
        v.field.value = "temperature"
        v._load()
        assert v.model.field == "pressure" and v.field.value == "pressure" and v.colormap.value == "(scene)"
        assert v.picker.editor is v.model.editor
        home = v.model.control.home
        v.model.control.azimuth(30.0)

        def buttons(widget):
            import ipywidgets as w

            if isinstance(widget, w.Button):
                yield widget
            for child in getattr(widget, "children", ()):
                yield from buttons(child)

        next(b for b in buttons(v.widget) if b.description == "⟲").click()
        assert v.model.camera == home
        v.path.value = str(tmp_path / "nope.json")
        v._guard(v._load)
        assert "error" in v.status.value
    finally:
        v.close()


@pytest.mark.gl
def test_closing_the_widget_stops_the_loop_and_frees_gl(tmp_path):
    pytest.importorskip("jupyter_rfb", reason="the Jupyter viewer needs jupyter_rfb: pip install -e '.[widget]'")
    from tetvr.apps.viewer import Viewer

    v = Viewer(tetvr.demo_scene_path(), size=(48, 36))  # the renderer in its own process
    assert v.loop.wait_idle(60)
    assert v.loop.last_frame.error is None, v.loop.last_error
    renderer = v.model.renderer
    assert renderer.gpu_bytes() > 0 and renderer.alive
    v.canvas.close()  # what the front end's close does
    assert v.closed and v.loop.closed and not v.loop._thread.is_alive()
    assert not renderer.alive and v.model._renderer is None
    assert v.canvas.comm is None and v.hist.comm is None


def test_view_without_a_display_says_so(tmp_path, monkeypatch, capsys):
    from tetvr.apps.cli import main

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr("tetvr.apps.viewer.desktop.os.name", "posix")
    monkeypatch.setattr("tetvr.apps.viewer.desktop.os.uname", lambda: type("U", (), {"sysname": "Linux"})())
    _scene(tmp_path)
    assert main(["view", str(tmp_path / "scene.json")]) == 3
    err = capsys.readouterr().err
    assert "no display" in err and "DISPLAY" in err


@pytest.mark.gl
def test_process_renderer_draws_what_the_renderer_draws_and_reports_its_errors():
    from tetvr.gl import Renderer
    from tetvr.apps.viewer.process import ProcessRenderer, RenderProcessError

    scene = tetvr.load_scene(tetvr.demo_scene_path())
    cams = [scene.camera, OrbitControl(scene.camera).azimuth(40.0)]
    with Renderer(scene.settings) as local, ProcessRenderer(scene.settings) as remote:
        for cam in cams:  # the mesh crosses the pipe once, then only the view
            want = local.render(scene.mesh, cam, scene.tf, size=(40, 30))
            got = remote.render(scene.mesh, cam, scene.tf, size=(40, 30))
            assert got.dtype == np.float32 and np.array_equal(got, want)
        # A clip and a surface cross the pipe too (the surface once), and draw the same bits.
        from tests.test_clip_surface import sphere

        lo, hi = scene.mesh.bounds
        clip = tetvr.Clip.plane(0.5 * (lo + hi), (1, 0, 0))
        ball = sphere(0.5 * (lo + hi), 0.2 * float(np.linalg.norm(hi - lo)), n=6)
        for cam in cams:
            want = local.render(scene.mesh, cam, scene.tf, size=(40, 30), clip=clip, surfaces=[ball])
            got = remote.render(scene.mesh, cam, scene.tf, size=(40, 30), clip=clip, surfaces=[ball])
            assert np.array_equal(got, want) and want[..., 3].max() == 1.0
        assert remote.gpu_bytes() > 0
        with pytest.raises(RenderProcessError, match="ValueError: .*size"):
            remote.render(scene.mesh, cams[0], scene.tf, size=(0, 30))
        assert remote.alive  # an error in a frame keeps the process
        proc = remote._proc
    assert proc.poll() is not None and not remote.alive  # released: the process (and its GL) is gone
    with pytest.raises(RenderProcessError, match="released"):
        remote.render(scene.mesh, cams[0], scene.tf, size=(40, 30))
    with pytest.raises(TypeError, match="RenderSettings"):
        ProcessRenderer({"method": "auto"})


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


@pytest.mark.gl
@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="reads process states from /proc (Linux)")
def test_the_render_process_is_outside_its_parents_process_group_and_ends_with_it():
    """Jupyter interrupts and shuts down a kernel by signalling the kernel's process group, and
    ipykernel's shutdown waits for that group's children: in the group, the render process
    died of every interrupt and held each kernel shutdown for 2.5 s. Outside it, it still
    ends with its parent (here one that exits without releasing it)."""
    import subprocess
    import sys

    code = ("import os, tetvr\n"
            "from tetvr.apps.viewer.process import ProcessRenderer\n"
            "scene = tetvr.load_scene(tetvr.demo_scene_path())\n"
            "r = ProcessRenderer(scene.settings)\n"
            "r.render(scene.mesh, scene.camera, scene.tf, size=(16, 12))\n"
            "print(r._proc.pid, os.getpgid(r._proc.pid), os.getpgrp(), flush=True)\n"
            "os._exit(0)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT,
                         stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stderr
    child, child_group, parent_group = map(int, out.stdout.split())
    assert child_group != parent_group
    deadline = time.monotonic() + 60
    while _running(child) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _running(child), f"the render process {child} outlived its parent"


def _volume():
    g = np.linspace(-1.0, 1.0, 12)
    z, y, x = np.meshgrid(g, g, g, indexing="ij")
    return tetvr.Volume.from_array(np.sqrt(x**2 + y**2 + z**2).astype(np.float32), spacing=(2 / 11,) * 3,
                                   origin=(-1.0, -1.0, -1.0))


def test_viewer_fuses_a_volume_with_its_own_editor_and_mode_picker(tmp_path):
    pytest.importorskip("jupyter_rfb", reason="the Jupyter viewer needs jupyter_rfb: pip install -e '.[widget]'")
    from tetvr.apps.viewer.model import FUSION_PICKER
    from tetvr.apps.viewer.jupyter import HIST_SIZE

    vol = _volume()
    rec = RecordingRenderer()
    v = _viewer(tmp_path, rec, volume=vol, fusion="overlay")
    try:
        assert v.loop.wait_idle(10)
        last = rec.calls[-1]
        assert last["volume"] is vol and last["mode"] == "overlay" and last["size"] == (80, 60)
        assert last["volume_tf"].domain == pytest.approx(vol.scalar_range)
        v.fusion.value = "cutaway"
        assert v.loop.wait_idle(10) and rec.calls[-1]["mode"] == "cutaway"
        assert tuple(v.fusion.options) == FUSION_PICKER
        # The volume's editor edits the volume's transfer function only.
        mesh_tf, vol_tf = rec.calls[-1]["tf"], rec.calls[-1]["volume_tf"]
        _drag(v.volume_panel.event, [(HIST_SIZE[0] * 0.5, HIST_SIZE[1] * 0.5), (HIST_SIZE[0] * 0.5, HIST_SIZE[1] * 0.2)])
        assert v.loop.wait_idle(10)
        assert rec.calls[-1]["tf"] == mesh_tf and rec.calls[-1]["volume_tf"] != vol_tf
        assert len(v.model.volume_editor.points) == 3 and v.volume_panel.frame().shape == (HIST_SIZE[1] + 14,
                                                                                          HIST_SIZE[0], 3)
        with pytest.raises(ValueError, match="fusion mode"):
            v.model.set_fusion("ray_textures")  # needs per-pixel images the viewer has no way to take
        with pytest.raises(TypeError, match="tetvr.Volume"):
            v.model.set_volume(np.zeros((4, 4, 4)))
    finally:
        v.close()


@pytest.mark.gl
def test_fused_frames_from_the_render_process_equal_tetvr_fuse():
    from tetvr.fuse import fuse
    from tetvr.apps.viewer.model import ViewerModel
    from tetvr.apps.viewer.process import ProcessRenderer

    mesh = synthetic.cube(2)
    vol = _volume()
    cam = Camera.fit(mesh, zoom=0.6)
    model = ViewerModel(tetvr.apps.viewer.model.scene_of(mesh, size=(32, 24)), renderer="process")
    try:
        model.set_volume(vol, mode="interleave")
        model.control.set(cam)
        got = model.final()
        want = fuse(mesh, vol, cam, model.editor.transfer_function(), model.volume_editor.transfer_function(),
                    size=(32, 24), mode="interleave")
        assert isinstance(model.renderer, ProcessRenderer) and np.array_equal(got, want)
        assert got[..., 3].max() > 0.05  # the volume shows
        inproc = ViewerModel(tetvr.apps.viewer.model.scene_of(mesh, size=(32, 24)))
        try:
            inproc.set_volume(vol, mode="interleave")
            inproc.control.set(cam)
            assert np.array_equal(inproc.final(), want)  # the in-process renderer fuses the same
        finally:
            inproc.close()
    finally:
        model.close()


def test_a_viewer_nobody_sees_frees_its_renderer_until_the_next_frame(tmp_path, monkeypatch):
    made = _fake_renderers(monkeypatch)
    pytest.importorskip("jupyter_rfb", reason="the Jupyter viewer needs jupyter_rfb: pip install -e '.[widget]'")
    from tetvr.apps.viewer import Viewer

    v = Viewer(_scene(tmp_path), renderer=None, idle_release_s=0.05)
    try:
        assert v.loop.wait_idle(10) and len(made) == 1
        v.canvas._has_visible_views = True
        v.canvas._has_visible_views = False  # the cell's output was cleared (or scrolled away)
        deadline = time.monotonic() + 5
        while not made[0].released and time.monotonic() < deadline:
            time.sleep(0.02)
        assert made[0].released and v.model._renderer is None
        v.canvas._has_visible_views = True
        v._image_event({"type": "wheel", "dx": 0, "dy": -100, "x": 5, "y": 5})
        assert v.loop.wait_idle(10) and len(made) == 2 and made[1].calls  # made again for the next frame
        v.canvas._has_visible_views = False
        v.canvas._has_visible_views = True  # back in view before the delay: kept
        time.sleep(0.2)
        assert not made[1].released
    finally:
        v.close()
    assert made[1].released

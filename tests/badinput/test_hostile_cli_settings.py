"""Hostile command lines and settings: outputs never overwrite inputs and are written
atomically; every CLI failure is one ``tetvr: error:`` line and a documented status;
image sizes are checked against the GL's real limits and memory, and a failed frame
leaves the renderer usable; settings are checked against memory and arithmetic limits
up front; settings of the wrong type are refused with a TypeError."""

from __future__ import annotations

import ctypes
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.core import image as image_mod
from tetvr.apps.cli import EXIT_ENVIRONMENT, EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_MEMORY, EXIT_USAGE, main
from tetvr.core.image import write_png
from tetvr.optics.preintegrate import build_table
from tetvr.optics.table import MIN_UNIT_DISTANCE
from tetvr.reference.volume import RaycastSettings, render_volume_reference
from tetvr.reference.tets import render_reference
from tetvr.render import default_transfer_function
from tetvr.optics.tablesize import choose_table_size

from ._util import POST_VTK

IMAGE = np.zeros((3, 4, 4), dtype=np.float32)


def _one_error_line(err: str) -> str:
    """The stderr of a failed command: one ``tetvr: error:`` line, last, and no traceback."""
    lines = err.strip().splitlines()
    assert "Traceback" not in err, err
    assert sum(line.startswith("tetvr: error: ") for line in lines) == 1, err
    assert lines[-1].startswith("tetvr: error: "), err
    return lines[-1]


@pytest.fixture()
def scene_dir(tmp_path: Path) -> Path:
    shutil.copy(POST_VTK, tmp_path / "post.vtk")
    (tmp_path / "scene.json").write_text(json.dumps({"mesh": "post.vtk", "size": [6, 4]}))
    return tmp_path


def _digests(*paths: Path) -> list[bytes]:
    return [p.read_bytes() for p in paths]


# ---- 1. no output over an input; atomic writes ----

@pytest.mark.parametrize("target", ["mesh", "scene", "hard-link-to-mesh", "symlink-to-scene"])
def test_render_never_writes_over_its_inputs(scene_dir, capsys, target):
    mesh, scene = scene_dir / "post.vtk", scene_dir / "scene.json"
    before = _digests(mesh, scene)
    if target == "hard-link-to-mesh":
        os.link(mesh, scene_dir / "alias.vtk")
    if target == "symlink-to-scene":
        os.symlink(scene, scene_dir / "alias.json")
    out = {"mesh": mesh, "scene": scene, "hard-link-to-mesh": scene_dir / "alias.vtk",
           "symlink-to-scene": scene_dir / "alias.json"}[target]
    assert main(["render", str(scene), "-o", str(out), "--reference"]) == EXIT_USAGE
    line = _one_error_line(capsys.readouterr().err)
    assert "refusing to write the PNG" in line and "an input of this command" in line
    assert _digests(mesh, scene) == before


def test_render_npy_never_writes_over_the_scene(scene_dir, capsys):
    scene = scene_dir / "scene.npy"  # a scene file by any name is read as JSON
    scene.write_text((scene_dir / "scene.json").read_text())
    before = scene.read_bytes()
    argv = ["render", str(scene), "-o", str(scene_dir / "o.png"), "--npy", str(scene_dir / "scene"), "--reference"]
    assert main(argv) == EXIT_USAGE  # np.save's name: "scene" + ".npy"
    assert "refusing to write the --npy array" in _one_error_line(capsys.readouterr().err)
    assert scene.read_bytes() == before and not (scene_dir / "o.png").exists()


def test_render_png_and_npy_may_not_be_one_file(scene_dir, capsys):
    out = scene_dir / "o.npy"
    assert main(["render", str(scene_dir / "scene.json"), "-o", str(out), "--npy", str(out), "--reference"]) == 2
    assert "are the same file" in _one_error_line(capsys.readouterr().err)
    assert not out.exists()


def test_animate_frames_never_overwrite_the_scene(scene_dir, capsys):
    frames = scene_dir / "frames"
    frames.mkdir()
    scene = frames / "frame_0000.png"  # a scene file under the name of the first frame
    scene.write_text(json.dumps({"mesh": "../post.vtk", "size": [6, 4]}))
    before = scene.read_bytes()
    assert main(["animate", str(scene), "--orbit", "2", "-o", str(frames), "--no-progress"]) == EXIT_USAGE
    assert "would overwrite the scene file" in _one_error_line(capsys.readouterr().err)
    assert scene.read_bytes() == before


def test_compare_report_never_overwrites_the_scene(scene_dir, capsys):
    scene = scene_dir / "comparison.json"
    scene.write_text((scene_dir / "scene.json").read_text())
    before = scene.read_bytes()
    argv = ["compare", str(scene), "-o", str(scene_dir), "--mappers", "", "--views", "1", "--size", "6", "4"]
    assert main(argv) == EXIT_USAGE
    assert "would overwrite the scene file" in _one_error_line(capsys.readouterr().err)
    assert scene.read_bytes() == before


def test_write_png_is_atomic(tmp_path, monkeypatch):
    path = tmp_path / "out.png"
    path.write_bytes(b"earlier picture")

    def fail(src, dst):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(image_mod.os, "replace", fail)
    with pytest.raises(OSError, match="No space left"):
        write_png(IMAGE, path)
    assert path.read_bytes() == b"earlier picture"  # not truncated, not half-written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.png"]  # no temporary left behind


def test_write_png_replaces_a_hard_link_instead_of_writing_through_it(tmp_path):
    keep = tmp_path / "input.vtk"
    keep.write_bytes(b"mesh bytes")
    os.link(keep, tmp_path / "out.png")
    write_png(IMAGE, tmp_path / "out.png")
    assert keep.read_bytes() == b"mesh bytes"
    assert (tmp_path / "out.png").read_bytes().startswith(b"\x89PNG")


def test_scene_save_refuses_its_own_mesh(scene_dir):
    from tetvr.scene.load import load_scene

    scene = load_scene(scene_dir / "scene.json")
    before = (scene_dir / "post.vtk").read_bytes()
    with pytest.raises(ValueError, match=r"refusing to write the scene '.*post\.vtk' over the mesh file "
                                         r"'.*post\.vtk', an input of the scene; choose another output path"):
        scene.save(scene_dir / "post.vtk")
    assert (scene_dir / "post.vtk").read_bytes() == before
    scene.save(scene_dir / "again.json")
    assert load_scene(scene_dir / "again.json").mesh.n_tets == scene.mesh.n_tets


# ---- 2. every CLI failure: one line, a documented status ----

def _moderngl_error() -> BaseException:
    import moderngl

    return moderngl.Error("the framebuffer is not complete (INCOMPLETE_ATTACHMENT)")


@pytest.mark.parametrize("make_exc,status,words", [
    (lambda: MemoryError("Unable to allocate 74.5 GiB"), EXIT_MEMORY, "out of memory: Unable to allocate 74.5 GiB"),
    (lambda: MemoryError(), EXIT_MEMORY, "out of memory"),
    (lambda: ZeroDivisionError("float division by zero"), EXIT_INTERNAL, "internal error: ZeroDivisionError"),
    (lambda: AttributeError("'dict' object has no attribute 'sort'"), EXIT_INTERNAL, "internal error: AttributeError"),
    (_moderngl_error, EXIT_ENVIRONMENT, "OpenGL: the framebuffer is not complete"),
    (lambda: RuntimeError("OpenGL error after rendering: GL_OUT_OF_MEMORY"), EXIT_MEMORY, "GL_OUT_OF_MEMORY"),
    (lambda: RuntimeError("no display: set DISPLAY"), EXIT_ENVIRONMENT, "no display"),
    (lambda: ImportError("writing .mp4 needs imageio"), EXIT_ENVIRONMENT, "needs imageio"),
    (lambda: ValueError("bad mesh\nsecond line"), EXIT_USAGE, "bad mesh; second line"),
    (lambda: KeyError("no field 'T'"), EXIT_USAGE, "no field 'T'"),
    (lambda: PermissionError(13, "Permission denied", "/x/mesh.vtu"), EXIT_USAGE, "Permission denied"),
    (lambda: RecursionError("maximum recursion depth exceeded"), EXIT_INTERNAL, "internal error: RecursionError"),
    (lambda: SystemExit(1), EXIT_INTERNAL, "tried to exit"),
    (lambda: KeyboardInterrupt(), EXIT_INTERRUPTED, "interrupted"),
], ids=["memory", "memory-bare", "zero-division", "attribute", "moderngl", "gl-oom", "runtime", "import", "value",
        "key", "permission", "recursion", "sys-exit", "ctrl-c"])
def test_every_failure_is_one_line_and_a_documented_status(monkeypatch, capsys, make_exc, status, words):
    def read(*args, **kwargs):
        raise make_exc()

    monkeypatch.setattr("tetvr.io.meshfile.read", read)
    assert main(["info", "mesh.vtu"]) == status
    assert words in _one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("argv", [["render"], ["nonsense"], ["render", "s.json", "--size"], []],
                         ids=["missing-scene", "unknown-command", "unknown-option", "nothing"])
def test_bad_arguments_return_2_with_one_error_line(capsys, argv):
    assert main(argv) == EXIT_USAGE
    err = capsys.readouterr().err
    assert err.startswith("usage: ")
    _one_error_line(err)


def test_help_documents_the_exit_statuses(capsys):
    assert main(["--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    for words in ("0 success", "1 internal error", "2 bad usage or input", "4 out of memory", "130 interrupted"):
        assert words in out


# ---- 3. sizes against the GL's real limits; a failed frame leaves the renderer usable ----

class _FakeContext:
    """What check_size reads of a moderngl context."""

    def __init__(self, renderer: str = "Fake GPU", **limits: object) -> None:
        self.info = {"GL_MAX_TEXTURE_SIZE": 16384, "GL_MAX_RENDERBUFFER_SIZE": 16384,
                     "GL_MAX_VIEWPORT_DIMS": (16384, 16384), "GL_RENDERER": renderer, **limits}
        self.extensions: set[str] = set()


@pytest.mark.parametrize("limit,size", [("GL_MAX_RENDERBUFFER_SIZE", (5000, 8)), ("GL_MAX_VIEWPORT_DIMS", (8, 5000))])
def test_check_size_reads_every_gl_limit(limit, size):
    from tetvr.gl.util import check_size

    ctx = _FakeContext(**{limit: 4096 if limit != "GL_MAX_VIEWPORT_DIMS" else (16384, 4096)})
    with pytest.raises(ValueError, match=rf"outside 1\.\.4096 pixels per side \(the GL limit here\): .*{limit} 4096"):
        check_size(size, ctx)
    assert check_size((4096, 8), ctx) == (4096, 8)


def test_check_size_bounds_llvmpipe_targets(monkeypatch):
    from tetvr.gl.util import check_size

    monkeypatch.setattr(image_mod, "available_memory", lambda: 1 << 40)
    ctx = _FakeContext("llvmpipe (LLVM 15.0.6, 256 bits)")
    with pytest.raises(MemoryError, match=r"a 16384x8192 image \(16 bytes a pixel\) needs a 2 GiB render target; "
                                          r"llvmpipe .* at most 1.5 GiB"):
        check_size((16384, 8192), ctx)
    assert check_size((16384, 6140), ctx) == (16384, 6140)  # measured: the largest llvmpipe makes
    with pytest.raises(MemoryError):
        check_size((16384, 6141), ctx)


def test_check_size_bounds_host_memory(monkeypatch):
    from tetvr.gl.util import check_size

    monkeypatch.setattr(image_mod, "available_memory", lambda: 1 << 20)
    with pytest.raises(MemoryError, match=r"a frame of 1024x1024 pixels .* needs about 64 MiB of host memory .*"
                                          r"more than the 1 MiB this process may take"):
        check_size((1024, 1024), _FakeContext())


@pytest.fixture(scope="module")
def gl_scene():
    mesh = synthetic.single_tet((0.0, 1.0, 2.0, 3.0))
    return mesh, Camera.fit(mesh), default_transfer_function(mesh)


SMALL = RenderSettings(table_scalar_bins=32, table_thickness_slices=4)


@pytest.mark.gl
def test_huge_frame_is_refused_and_the_renderer_still_works(gl_scene, monkeypatch):
    from tetvr.gl import Renderer

    monkeypatch.setattr("tetvr.gl.util.free_video_memory", lambda ctx: 1 << 30)  # a GPU with 1 GiB free
    mesh, cam, tf = gl_scene
    with Renderer(SMALL) as r:
        # llvmpipe refuses the texture (its size limit), a GPU the frame (its free memory).
        with pytest.raises(MemoryError, match=r"16384x8192 (image .* needs a 2 GiB render target|frame needs .* of "
                                              r"render targets; the GPU reports 1 GiB free)"):
            r.render(mesh, cam, tf, size=(16384, 8192))
        img = r.render(mesh, cam, tf, size=(8, 8))
        assert img.shape == (8, 8, 4) and img[..., 3].max() > 0


@pytest.mark.gl
def test_renderer_recovers_from_an_error_a_failed_frame_left(gl_scene):
    from tetvr.gl import Renderer
    from tetvr.gl.util import _gl_get_integerv

    mesh, cam, tf = gl_scene
    with Renderer(SMALL) as r:
        r.render(mesh, cam, tf, size=(8, 8))
        with r.ctx:  # what a frame that failed half-way leaves: an error flag nobody read
            _gl_get_integerv()(0xFFFF, (ctypes.c_int * 4)())  # GL_INVALID_ENUM
        img = r.render(mesh, cam, tf, size=(8, 8))
        assert img[..., 3].max() > 0


@pytest.mark.gl
def test_make_target_leaves_nothing_behind():
    from tetvr.gl.context import create_context
    from tetvr.gl.util import make_target

    ctx = create_context()
    try:
        with ctx:
            too_wide = int(ctx.info["GL_MAX_TEXTURE_SIZE"]) + 1
            with pytest.raises((MemoryError, RuntimeError), match=rf"could not make a {too_wide}x1 render target"):
                make_target(ctx, (too_wide, 1), 4, "f4")
            assert ctx.error == "GL_NO_ERROR"
    finally:
        ctx.release()


# ---- 4. settings against memory and arithmetic limits, up front ----

@pytest.mark.parametrize("kwargs,match", [
    (dict(table_scalar_bins=2048, table_thickness_slices=256),
     r"table_scalar_bins=2048 with table_thickness_slices=256 is a 2048 x 2048 x 257 table .* needs 128 GiB"),
    (dict(table_thickness_slices=256, table_log_base=100),
     r"table_log_base=100.0 with table_thickness_slices=256: .* = 1e510"),
    (dict(table_scalar_bins=64, table_thickness_slices=200, table_log_base=1.6), r"1e41 .* more than 1e\+24"),
], ids=["table-memory", "log-base-overflow", "span-beyond-float32"])
def test_render_settings_refuse_tables_beyond_memory_and_arithmetic(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RenderSettings(**kwargs)


def test_sizes_within_the_limits_are_kept():
    s = RenderSettings(table_scalar_bins=1024, table_thickness_slices=48, table_log_base=1.2)  # the bench's largest
    assert (s.table_scalar_bins, s.table_thickness_slices) == (1024, 48)
    assert RenderSettings(table_scalar_bins=2048).table_thickness_slices == "auto"


def test_raycast_settings_refuse_tables_beyond_memory():
    with pytest.raises(ValueError, match=r"4096 x 4096 x 65 table"):
        RaycastSettings(table_scalar_bins=4096, table_thickness_slices=64)


def test_build_table_checks_its_arithmetic_and_memory(monkeypatch):
    tf = TransferFunction.preset("viridis", (0.0, 1.0), opacity=0.5)
    with pytest.raises(ValueError, match=r"log_base=100 with n_slices=256: .* 1e510"):
        build_table(tf, (0.0, 1.0), 1.0, n_bins=4, n_slices=256, log_base=100)
    with pytest.raises(ValueError, match=r"the thinnest slice, .* = 1e-319, underflows"):
        build_table(tf, (0.0, 1.0), 1e-300, n_bins=4, n_slices=20, log_base=10.0)
    monkeypatch.setattr(image_mod, "available_memory", lambda: 1 << 20)
    with pytest.raises(MemoryError, match=r"building a 256 x 256 x 17 pre-integration table needs about 136 MiB"):
        build_table(tf, (0.0, 1.0), 1.0, n_bins=256, n_slices=16)


@pytest.mark.parametrize("u", [5e-324, 1e-310, 2.2250738585072014e-308, 1e-301])
def test_subnormal_unit_distance_is_refused_by_name(u):
    mesh = synthetic.cube(2)
    tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.5, unit_distance=u)
    match = rf"unit_distance must be a finite number of at least 1e-300 .*got {u!r}"
    with pytest.raises(ValueError, match=match):
        choose_table_size(tf, mesh)  # was: "min() arg is an empty sequence"
    with pytest.raises(ValueError, match=match):
        build_table(tf, mesh.scalar_range, 1.0, n_bins=8, n_slices=2)  # was: a NaN table
    with pytest.raises(ValueError, match=match):
        render_reference(mesh, Camera.fit(mesh), tf, (4, 4))  # was: a NaN image


def test_smallest_unit_distance_renders_finite():
    mesh = synthetic.cube(2)
    tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=[(0, 0), (0.5, 1), (1, 0.3)],
                                 unit_distance=MIN_UNIT_DISTANCE)
    with np.errstate(under="ignore"):
        img = render_reference(mesh, Camera.fit(mesh), tf, (4, 4))
        table = build_table(tf, mesh.scalar_range, mesh.max_edge, n_bins=8, n_slices=2)
    assert np.all(np.isfinite(img)) and np.all(np.isfinite(table.data))


def test_scene_refuses_a_subnormal_unit_distance(scene_dir, capsys):
    scene = scene_dir / "scene.json"
    scene.write_text(json.dumps({"mesh": "post.vtk", "size": [6, 4],
                                 "transfer_function": {"preset": "viridis", "unit_distance": 5e-324}}))
    assert main(["render", str(scene), "-o", str(scene_dir / "o.png"), "--reference"]) == EXIT_USAGE
    assert "transfer_function 'unit_distance' must be" in _one_error_line(capsys.readouterr().err)


def test_reference_bounds_its_memory_by_the_image_size_up_front():
    mesh = synthetic.single_tet((0.0, 1.0, 2.0, 3.0))
    tf = default_transfer_function(mesh)
    with pytest.raises(MemoryError, match=r"a 100000x100000 reference image needs about 596 GiB"):
        render_reference(mesh, Camera.fit(mesh), tf, (100_000, 100_000))


def test_cli_reference_too_big_for_memory_exits_4(scene_dir, capsys):
    scene = scene_dir / "scene.json"
    scene.write_text(json.dumps({"mesh": "post.vtk", "size": [100000, 100000]}))
    assert main(["render", str(scene), "-o", str(scene_dir / "o.png"), "--reference"]) == EXIT_MEMORY
    # The picture's memory is checked before the reference renders (tetvr.gl.framesize).
    assert "a frame of 100000x100000 pixels (its picture" in _one_error_line(capsys.readouterr().err)
    assert not (scene_dir / "o.png").exists()


# ---- 5. settings of the wrong type ----

@pytest.mark.parametrize("settings", [{}, {"table_scalar_bins": 64}, "fast", 3], ids=["empty-dict", "dict", "str", "int"])
def test_renderer_refuses_settings_of_another_type(settings):
    from tetvr.gl import Renderer

    with pytest.raises(TypeError, match=rf"settings must be a RenderSettings or None, got {type(settings).__name__}"):
        Renderer(settings)  # checked before a context is made: needs no GL


def test_renderer_settings_dict_points_to_from_dict():
    from tetvr.gl import Renderer

    with pytest.raises(TypeError, match=r"RenderSettings\.from_dict"):
        Renderer(settings={})


@pytest.mark.parametrize("settings", [{}, "mip"], ids=["dict", "str"])
def test_raycaster_refuses_settings_of_another_type(settings):
    from tetvr.gl import Raycaster

    with pytest.raises(TypeError, match=rf"settings must be a RaycastSettings or None, got {type(settings).__name__}"):
        Raycaster(settings)


def test_volume_reference_refuses_settings_of_another_type():
    from tetvr.volume.volume import Volume

    vol = Volume.from_array(np.zeros((2, 2, 2)))
    tf = TransferFunction.preset("grayscale", (0, 1))
    with pytest.raises(TypeError, match="settings must be a RaycastSettings or None, got dict"):
        render_volume_reference(vol, Camera(position=(5, 0, 0), focal_point=(0, 0, 0)), tf, (2, 2), settings={})


@pytest.mark.parametrize("settings", [{}, "fast"], ids=["dict", "str"])
def test_render_refuses_settings_of_another_type(settings):
    import tetvr

    with pytest.raises(TypeError, match="settings must be a RenderSettings or None"):
        tetvr.render(synthetic.single_tet((0.0, 1.0, 2.0, 3.0)), settings=settings, size=(4, 4))

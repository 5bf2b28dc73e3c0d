"""Hostile outputs, through the API as through the command line (issue 32, "Nothing lost,
nothing hung"):

* every entry point that writes files refuses, before it reads or renders anything, an
  output that is one of its inputs (as files: hard and symbolic links count) -- with a
  ValueError naming the output, the input and whose input it is, and saying to choose
  another path (:mod:`tetvr.core.outputs`);
* an output whose folder cannot be written is refused before the render, by the folder's
  name, not the hidden temporary file's after the work;
* an output that is not a regular file (a FIFO, ``/dev/stdout``) is written through, not
  renamed over, and a symbolic link to a regular file survives, pointing at the written
  file (:func:`tetvr.core.image.atomic_output`: the choice is documented there).
"""

from __future__ import annotations

import contextlib
import importlib
import io
import json
import os
import re
import shutil
import stat
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np
import pytest

from tetvr.apps import animate as animate_mod
from tetvr.apps.animate import animate
from tetvr.apps.cli import EXIT_OK, EXIT_USAGE, main
from tetvr.cluster import timeseries
from tetvr.core.image import atomic_output, write_png
from tetvr.io.video import write_frames
from tetvr.scene.load import load_scene

from ._util import POST_VTK, REPO, deadline

IMAGE = np.zeros((3, 4, 4), dtype=np.float32)
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture()
def scene_dir(tmp_path: Path) -> Path:
    shutil.copy(POST_VTK, tmp_path / "post.vtk")
    (tmp_path / "scene.json").write_text(json.dumps({"mesh": "post.vtk", "size": [6, 4]}))
    return tmp_path


@pytest.fixture()
def no_work(monkeypatch):
    """Any render or cluster started fails the test: the checks must come first."""
    def fail(*args, **kwargs):
        raise AssertionError("the work started before the outputs were checked")

    monkeypatch.setattr(timeseries, "cluster_client", fail)
    monkeypatch.setattr(animate_mod, "render_frames", fail)
    monkeypatch.setattr(importlib.import_module("tetvr.render"), "render", fail)  # tetvr.render is the function


def _pvd(folder: Path, files: list[str]) -> Path:
    rows = "".join(f'<DataSet timestep="{k}" part="0" file="{f}"/>' for k, f in enumerate(files))
    path = folder / "run.pvd"
    path.write_text(f'<?xml version="1.0"?><VTKFile type="Collection"><Collection>{rows}</Collection></VTKFile>')
    return path


# ---- 1. no output over an input, in every entry point ----

@pytest.mark.parametrize("steps_as", ["list", "pvd", "glob"])
def test_render_series_refuses_to_write_frames_over_its_steps(tmp_path, no_work, monkeypatch, steps_as):
    for name in ("s_0.vtu", "s_1.vtu"):
        shutil.copy(POST_VTK, tmp_path / name)
    before = [(tmp_path / n).read_bytes() for n in ("s_0.vtu", "s_1.vtu")]
    monkeypatch.chdir(tmp_path)
    steps = {"list": ["s_0.vtu", "s_1.vtu"], "pvd": str(_pvd(tmp_path, ["s_0.vtu", "s_1.vtu"])),
             "glob": "s_*.vtu"}[steps_as]
    with deadline(30, "render_series"), pytest.raises(
            ValueError, match=r"refusing to write the frame of step 0 's_0\.vtu' over the .*s_0\.vtu', an input of "
                              r"render_series; choose another output path"):
        timeseries.render_series(steps, output="s_{index}.vtu", progress=False)
    assert [(tmp_path / n).read_bytes() for n in ("s_0.vtu", "s_1.vtu")] == before


def test_render_series_refuses_a_link_to_a_step_and_a_bad_pattern(tmp_path, no_work):
    shutil.copy(POST_VTK, tmp_path / "s_0.vtu")
    (tmp_path / "f_0.png").symlink_to(tmp_path / "s_0.vtu")
    with pytest.raises(ValueError, match=r"'.*f_0\.png' over the time-series file '.*s_0\.vtu'"):
        timeseries.render_series([tmp_path / "s_0.vtu"], output=str(tmp_path / "f_{index}.png"), progress=False)
    with pytest.raises(ValueError, match=r"may use only \{index\} and \{time\} fields .*KeyError\('step'\)"):
        timeseries.render_series([tmp_path / "s_0.vtu"], output=str(tmp_path / "f_{step}.png"), progress=False)


def test_animate_series_refuses_a_video_over_a_step(scene_dir, no_work):
    scene = load_scene(scene_dir / "scene.json")
    shutil.copy(POST_VTK, scene_dir / "s_0.vtu")
    (scene_dir / "movie.gif").symlink_to(scene_dir / "s_0.vtu")
    with pytest.raises(ValueError, match=r"refusing to write the video '.*movie\.gif' over the time-series file "
                                         r"'.*s_0\.vtu', an input of animate_series; choose another output path"):
        timeseries.animate_series(scene, [str(scene_dir / "s_0.vtu")], scene_dir / "movie.gif", progress=False)


@pytest.mark.parametrize("target", ["video-link-to-mesh", "frame-link-to-mesh", "frame-is-the-scene"])
def test_animate_refuses_outputs_over_its_inputs(scene_dir, no_work, target):
    mesh, scene = scene_dir / "post.vtk", scene_dir / "scene.json"
    before = [mesh.read_bytes(), scene.read_bytes()]
    frames = scene_dir / "frames"
    frames.mkdir()
    if target == "video-link-to-mesh":
        out = scene_dir / "movie.gif"
        out.symlink_to(mesh)
        match = r"refusing to write the video '.*movie\.gif' over the mesh file '.*post\.vtk', an input of animate"
    elif target == "frame-link-to-mesh":
        out = frames
        (frames / "frame_0001.png").symlink_to(mesh)
        match = (r"refusing to write frames into '.*frames': it would overwrite the mesh file '.*post\.vtk' "
                 r"\(as 'frame_0001\.png' there\), an input of animate; choose another folder")
    else:
        out = scene_dir
        scene = scene_dir / "frame_0000.png"  # a scene file under the name of the first frame
        scene.write_text(json.dumps({"mesh": "post.vtk", "size": [6, 4]}))
        before[1] = scene.read_bytes()
        match = r"would overwrite the scene file '.*frame_0000\.png', an input of animate; choose another folder"
    with pytest.raises(ValueError, match=match):
        animate(str(scene), out, orbit_frames=2, progress=False)
    assert [mesh.read_bytes(), scene.read_bytes()] == before


def test_write_frames_checks_before_it_takes_the_first_frame(tmp_path):
    mesh = tmp_path / "mesh.vtk"
    shutil.copy(POST_VTK, mesh)
    frames = tmp_path / "frames"
    frames.mkdir()
    os.link(mesh, frames / "frame_0000.png")

    def images():
        raise AssertionError("a frame was rendered before the output was checked")
        yield IMAGE  # pragma: no cover

    with pytest.raises(ValueError, match=r"would overwrite the mesh file '.*mesh\.vtk' \(as 'frame_0000\.png' "
                                         r"there\), an input of write_frames"):
        write_frames(images(), frames, inputs=[("mesh file", mesh)])
    assert write_frames([IMAGE], tmp_path / "new") == [tmp_path / "new" / "frame_0000.png"]


@pytest.mark.parametrize("how", ["symlink-to-mesh", "hard-link-to-mesh", "the-mesh-itself"])
def test_scene_save_refuses_its_own_mesh_by_any_name(scene_dir, how):
    scene = load_scene(scene_dir / "scene.json")
    mesh = scene_dir / "post.vtk"
    before = mesh.read_bytes()
    out = {"symlink-to-mesh": scene_dir / "alias.json", "hard-link-to-mesh": scene_dir / "alias.json",
           "the-mesh-itself": mesh}[how]
    if how == "symlink-to-mesh":
        out.symlink_to(mesh)
    elif how == "hard-link-to-mesh":
        os.link(mesh, out)
    with pytest.raises(ValueError, match=r"refusing to write the scene '.*' over the mesh file '.*post\.vtk', "
                                         r"an input of the scene; choose another output path"):
        scene.save(out)
    assert mesh.read_bytes() == before


# ---- 2. a FIFO or /dev/stdout is written through; a link survives ----

def _read_fifo(path: Path, got: list[bytes]) -> threading.Thread:
    def read() -> None:
        with open(path, "rb") as f:  # blocks until the writer opens it
            got.append(f.read())

    t = threading.Thread(target=read, daemon=True)
    t.start()
    return t


@pytest.mark.parametrize("via_link", [False, True], ids=["fifo", "link-to-fifo"])
def test_write_png_writes_through_a_fifo(tmp_path, via_link):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    out = fifo
    if via_link:  # what /dev/stdout is: a link to a pipe
        out = tmp_path / "stdout"
        out.symlink_to(fifo)
    got: list[bytes] = []
    reader = _read_fifo(fifo, got)
    with deadline(20, "writing to a FIFO"):
        write_png(IMAGE, out)
    reader.join(10)
    assert got and got[0].startswith(PNG_SIGNATURE) and got[0].endswith(b"IEND\xaeB`\x82")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode), "the FIFO was replaced by a regular file"
    assert not via_link or os.readlink(out) == str(fifo)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["pipe"] + (["stdout"] if via_link else []))


def test_a_failed_write_sends_nothing_down_a_fifo(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # a reader that does not block
    try:
        with pytest.raises(RuntimeError, match="the render failed"):
            with atomic_output(fifo) as f:
                f.write(b"half a picture")
                raise RuntimeError("the render failed")
        assert os.read(fd, 100) == b""
    finally:
        os.close(fd)


def test_cli_renders_into_a_fifo(scene_dir, capsys):
    fifo = scene_dir / "pipe"
    os.mkfifo(fifo)
    got: list[bytes] = []
    reader = _read_fifo(fifo, got)
    with deadline(60, "tetvr render -o FIFO"):
        status = main(["render", str(scene_dir / "scene.json"), "-o", str(fifo), "--reference", "--no-annotations"])
    reader.join(10)
    assert status == EXIT_OK, capsys.readouterr().err
    assert got and got[0].startswith(PNG_SIGNATURE)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_cli_renders_to_dev_stdout(scene_dir):
    """The reader of the pipe gets the whole PNG and nothing else: the report line goes
    to stderr when the output is stdout."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    argv = [sys.executable, "-m", "tetvr", "render", str(scene_dir / "post.vtk"), "-o", "/dev/stdout", "--reference",
            "--size", "16x12", "--no-annotations"]
    done = subprocess.run(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, timeout=120)
    assert done.returncode == 0, done.stderr.decode()
    assert done.stdout.startswith(PNG_SIGNATURE) and done.stdout.endswith(b"IEND\xaeB`\x82")
    assert b"-> PNG /dev/stdout" in done.stderr


@pytest.mark.parametrize("dangling", [False, True], ids=["link-to-file", "dangling-link"])
def test_a_link_survives_and_points_at_the_written_file(tmp_path, dangling):
    target, link = tmp_path / "real.png", tmp_path / "link.png"
    if not dangling:
        target.write_bytes(b"an earlier picture")
    link.symlink_to(target.name)
    write_png(IMAGE, link)
    assert link.is_symlink() and os.readlink(link) == "real.png"
    assert target.read_bytes().startswith(PNG_SIGNATURE)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.png", "real.png"]


# ---- 10. an output folder that cannot be written: refused first, by its name ----

def _unprivileged(fn):
    """``fn()`` where files cannot be made in a 0o555 folder: here, or (root may write
    anywhere) in a forked child that has dropped to ``nobody``. Returns what it returned,
    or ``(exception type name, message)``. The child imports nothing new: the modules it
    runs are imported by this file first."""
    def call():
        try:
            return ("returned", fn())
        except Exception as exc:  # noqa: BLE001 - reported to the test
            return (type(exc).__name__, str(exc))

    if os.geteuid() != 0:
        return call()
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        try:
            os.close(r)
            os.setgid(65534)
            os.setuid(65534)
            os.write(w, json.dumps(call(), default=str).encode())
        finally:
            os._exit(0)
    os.close(w)
    with os.fdopen(r, "rb") as f:
        data = f.read()
    os.waitpid(pid, 0)
    return tuple(json.loads(data))


@pytest.fixture()
def readonly_dir():
    """A folder anyone may read (the child above runs as nobody), holding the scene and
    a read-only folder ``ro``."""
    top = Path(tempfile.mkdtemp(prefix="tetvr-ro-"))
    try:
        top.chmod(0o755)
        shutil.copy(POST_VTK, top / "post.vtk")
        (top / "scene.json").write_text(json.dumps({"mesh": "post.vtk", "size": [6, 4]}))
        for p in top.iterdir():
            p.chmod(0o644)
        (top / "ro").mkdir(mode=0o555)
        (top / "ro").chmod(0o555)
        yield top
    finally:
        (top / "ro").chmod(0o755)
        shutil.rmtree(top)


UNWRITABLE = r"the folder '.*/ro' is not writable \(permission denied\); choose another folder, or make it writable"


def test_cli_refuses_an_unwritable_output_folder_before_the_render(readonly_dir, no_work):
    def run():
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            status = main(["render", str(readonly_dir / "scene.json"), "-o", str(readonly_dir / "ro" / "o.png"),
                           "--reference"])
        return status, err.getvalue()

    kind, (status, err) = _unprivileged(run)
    assert status == EXIT_USAGE, err
    line = err.strip().splitlines()[-1]
    assert line.startswith("tetvr: error: cannot write the PNG '") and ".tmp" not in line
    assert re.search(UNWRITABLE, line), line


@pytest.mark.parametrize("entry", ["render_series", "animate", "scene.save", "write_png"])
def test_api_refuses_an_unwritable_output_folder_by_its_name(readonly_dir, no_work, entry):
    ro = readonly_dir / "ro"
    scene = load_scene(readonly_dir / "scene.json")
    call = {
        "render_series": lambda: timeseries.render_series([str(readonly_dir / "post.vtk")],
                                                          output=str(ro / "f_{index}.png"), progress=False),
        "animate": lambda: animate(scene, ro / "frames", orbit_frames=2, progress=False),
        "scene.save": lambda: scene.save(ro / "again.json"),
        "write_png": lambda: write_png(IMAGE, ro / "out.png"),  # at the write itself: by the output's name too
    }[entry]
    kind, message = _unprivileged(call)
    assert kind == "PermissionError", message
    assert re.search(r"cannot write .*'.*/ro" + ("/out.png'" if entry == "write_png" else ""),
                                   message), message
    assert "not writable" in message and "choose another folder" in message and ".tmp" not in message
    assert os.listdir(ro) == []


def test_compare_refuses_a_report_over_its_scene(scene_dir, no_work):
    from tetvr.apps.vtkcompare import compare

    scene = scene_dir / "comparison.json"  # the name of write_report's table
    scene.write_text((scene_dir / "scene.json").read_text())
    before = scene.read_bytes()
    with pytest.raises(ValueError, match=r"refusing to write the comparison into '.*': it would overwrite the scene "
                                         r"file '.*comparison\.json', an input of compare; choose another folder"):
        compare(str(scene), mappers=(), views=1, outdir=scene_dir)
    assert scene.read_bytes() == before


def test_a_plot_is_never_saved_over_its_mesh(scene_dir):
    from tetvr.apps.annotate import Picture

    mesh = scene_dir / "post.vtk"
    before = mesh.read_bytes()
    (scene_dir / "alias.png").symlink_to(mesh)
    pic = Picture(image=IMAGE, png=PNG_SIGNATURE, inputs=(str(mesh),))  # as tetvr.plot("post.vtk") makes it
    for out in (mesh, scene_dir / "alias.png"):
        with pytest.raises(ValueError, match=r"refusing to write the picture '.*' over the mesh file '.*post\.vtk', "
                                             r"an input of this picture; choose another output path"):
            pic.save(out)
    assert mesh.read_bytes() == before

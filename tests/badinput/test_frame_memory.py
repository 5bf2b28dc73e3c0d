"""A frame larger than the memory it may take is refused up front, by name.

Before ``tetvr.gl.framesize``, a size the GL's limits accepted could take the host's
memory half-way through a frame: an 8192x8192 picture of a 27-cell cube peaked at 6.3 GB
(tet marching keeps 96 bytes a pixel on llvmpipe); under an address-space limit
(``ulimit -v``) 16384x6000 ended the process with SIGSEGV (projected tetrahedra, in
moderngl's readback) or "the framebuffer is not complete (UNSUPPORTED)" (tet marching).
Each such frame now raises :class:`~tetvr.gl.framesize.FrameMemoryError` (a
``MemoryError``) that names the size, the estimate, what is available and what would fit,
before a renderer or a render target is made.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import tetvr
import tetvr.core.image as image_mod
from tetvr import Camera, RenderSettings
from tetvr.gl import framesize
from tetvr.gl.framesize import FrameMemoryError, frame_estimate, frame_method, picture_estimate
from tetvr.mesh import synthetic
from tetvr.render import default_transfer_function

from ._util import POST_VTK, REPO

RESULTS = REPO / "bench" / "results" / "frame_memory.json"

#: Run under an address-space limit of 3 GiB: the sizes of the failures above, refused;
#: a Renderer asked directly for 8192x8192, refused before it makes a target; sizes that
#: fit, rendered. Prints what happened to each, as JSON.
_CHILD = r"""
import json, resource, sys
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
import tetvr
from tetvr import Camera, RenderSettings
from tetvr.mesh import synthetic
from tetvr.render import default_transfer_function
import tetvr.gl.renderer as renderer_module

made = []
init = renderer_module.Renderer.__init__
def counted(self, *a, **k):
    made.append(1)
    init(self, *a, **k)
renderer_module.Renderer.__init__ = counted

def outcome(call):
    try:
        img = call()
        return {"shape": list(img.shape), "alpha": float(img[..., 3].max())}
    except Exception as exc:
        return {"error": [c.__name__ for c in type(exc).__mro__], "message": str(exc)}

mesh = synthetic.cube(3)
out = {}
for method in ("auto", "projected"):
    out[method] = outcome(lambda: tetvr.render(mesh, size=(16384, 6000), settings=RenderSettings(method=method)))
out["renderers_made"] = len(made)
out["fits"] = outcome(lambda: tetvr.render(mesh, size=(1024, 768)))
with tetvr.Renderer() as r:
    cam, tf = Camera.fit(mesh), default_transfer_function(mesh)
    out["renderer"] = outcome(lambda: r.render(mesh, cam, tf, size=(8192, 8192)))
    out["renderer_targets"] = len(r._targets) + (r._marcher is not None)
    out["renderer_after"] = outcome(lambda: r.render(mesh, cam, tf, size=(256, 256)))
print(json.dumps(out))
"""


@pytest.mark.gl
def test_frames_beyond_an_address_space_limit_are_refused_by_name_not_crashed():
    res = subprocess.run([sys.executable, "-c", _CHILD], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert res.returncode == 0, f"exit {res.returncode} (-11: SIGSEGV)\n{res.stderr[-3000:]}"
    out = json.loads(res.stdout.strip().splitlines()[-1])
    for method, words in (("auto", "tet marching"), ("projected", "projected tetrahedra")):
        got = out[method]
        assert "error" in got, f"{method}: rendered {got}"
        assert got["error"][:2] == ["FrameMemoryError", "MemoryError"], got
        msg = got["message"]
        assert f"a frame of 16384x6000 pixels ({words}) needs about" in msg
        assert "left under the address-space limit of 3 GiB (ulimit -v, RLIMIT_AS" in msg
        assert "render at most" in msg and "raise the address-space limit" in msg
        assert "not complete" not in msg
    assert out["renderers_made"] == 0  # refused before the context was made
    assert out["fits"]["shape"] == [768, 1024, 4] and out["fits"]["alpha"] > 0
    # The renderer itself, its context made: refused before any render target.
    got = out["renderer"]
    assert got.get("error", [None])[0] == "FrameMemoryError", got
    assert "a frame of 8192x8192 pixels (tet marching) needs about" in got["message"]
    assert 'use method="projected"' not in got["message"]  # 48 bytes a pixel do not fit 3 GiB either
    assert out["renderer_targets"] == 0
    assert out["renderer_after"]["alpha"] > 0  # and it still renders


@pytest.fixture
def one_gib(monkeypatch):
    """The host says 1 GiB is available, and no address-space limit is set."""
    monkeypatch.setattr(image_mod, "available_memory", lambda: 1 << 30)
    monkeypatch.setattr(framesize, "_address_space_limit", lambda: None)


def _no_gl(*args, **kwargs):
    raise AssertionError("a GL context was made for a frame that had to be refused first")


def test_the_facade_refuses_before_making_a_renderer(one_gib, monkeypatch):
    import tetvr.gl.raycaster as raycaster_module
    import tetvr.gl.renderer as renderer_module

    monkeypatch.setattr(renderer_module.Renderer, "__init__", _no_gl)
    monkeypatch.setattr(raycaster_module.Raycaster, "__init__", _no_gl)
    mesh = synthetic.cube(2)
    # 32 bytes a pixel of readback whatever the GL: 2 GiB, 32 MiB for the frame, 256 MiB for the renderer.
    with pytest.raises(FrameMemoryError, match=r"a frame of 8192x8192 pixels \(tet marching\) needs about 2.28 GiB "
                                               r"of host memory \(32 bytes a pixel: readback 32; and 32 MiB for the "
                                               r"frame, 256 MiB for the renderer's context, shaders and table\), "
                                               r"more than the 1 GiB this process may take \(1 GiB of memory "
                                               r"available\)\. To render it: render at most 4910x4910 \(the same "
                                               r"aspect; 2835x2835 where the GL keeps its render targets in host "
                                               r"memory, .*\), or free memory\.$") as info:
        tetvr.render(mesh, size=(8192, 8192))
    assert info.value.size == (8192, 8192) and info.value.need > info.value.available == 1 << 30
    volume = tetvr.Volume.from_array(np.zeros((4, 4, 4), np.float32))
    with pytest.raises(FrameMemoryError, match=r"8192x8192 pixels \(the volume ray caster\)"):
        tetvr.render(volume, size=(8192, 8192), tf=tetvr.TransferFunction.preset("viridis", (0.0, 1.0)))


@pytest.mark.gl
def test_the_renderer_refuses_before_making_a_target_and_still_renders(monkeypatch):
    from tetvr.gl.util import is_software

    mesh = synthetic.cube(2)
    cam, tf = Camera.fit(mesh), default_transfer_function(mesh)
    monkeypatch.setattr(framesize, "_address_space_limit", lambda: None)
    # A small table: on a GPU the frame's host need (its readback) is less than a 256-bin
    # table's build, which would be refused first.
    with tetvr.Renderer(RenderSettings(method="raymarch", table_scalar_bins=64, table_thickness_slices=8)) as r:
        need = frame_estimate((2048, 2048), "raymarch", software=is_software(r.ctx)).host
        monkeypatch.setattr(image_mod, "available_memory", lambda: need // 2)
        with pytest.raises(FrameMemoryError, match=r"a frame of 2048x2048 pixels \(tet marching\)"):
            r.render(mesh, cam, tf, size=(2048, 2048))
        assert r._marcher is None and not r._targets  # nothing made for it
        assert r.render(mesh, cam, tf, size=(64, 64))[..., 3].max() > 0


@pytest.mark.gl
def test_render_targets_the_gl_cannot_complete_are_a_memory_error_naming_the_size():
    import moderngl

    from tetvr.gl.context import create_context
    from tetvr.gl.util import cached_targets

    made = []

    def make(size, t):  # what llvmpipe does when it cannot allocate a texture
        t["color"] = ctx.texture(size, 4, dtype="f4")
        made.append(t["color"])
        raise moderngl.Error("the framebuffer is not complete (UNSUPPORTED)")

    ctx = create_context()
    try:
        with ctx:
            targets: dict = {}
            with pytest.raises(MemoryError, match=r"could not make the 32x16 render targets \(the framebuffer is "
                                                  r"not complete \(UNSUPPORTED\)\).*render it smaller"):
                cached_targets(ctx, targets, (32, 16), make)
            assert targets == {} and type(made[0].mglo).__name__ == "InvalidObject"  # released
            assert ctx.error == "GL_NO_ERROR"
    finally:
        ctx.release()


def test_the_cli_checks_the_picture_before_rendering(one_gib, monkeypatch, tmp_path, capsys):
    from tetvr.apps.cli import EXIT_MEMORY, main

    monkeypatch.setattr(sys.modules["tetvr.render"], "render", _no_gl)  # the module, not the function
    out = tmp_path / "o.png"
    assert main(["render", str(POST_VTK), "-o", str(out), "--size", "8000x6000"]) == EXIT_MEMORY
    err = capsys.readouterr().err
    assert "a frame of 8000x6000 pixels (its picture: legend and PNG) needs about" in err
    assert not out.exists()


def test_the_method_a_frame_is_estimated_for():
    many = 10**12  # more tets than any memory holds the records of
    assert frame_method(None, 10) == "raymarch"  # "auto" counts as the larger of the two
    assert frame_method(None, many) == "projected"  # what "auto" takes by size alone
    assert frame_method(RenderSettings(method="projected"), 10) == "projected"
    assert frame_method(RenderSettings(integration="exact"), many) == "raymarch"
    assert frame_method(RenderSettings(optics="vtk"), 10) == "projected"
    assert frame_method(None, 10, order=np.arange(10)) == "projected"


def test_the_estimates_cover_what_the_benchmark_measured():
    """Every size bench/frame_memory.py measured on llvmpipe fits its estimate, which is
    at most 50 % above the measurement at the largest size (the slope that matters)."""
    data = json.loads(RESULTS.read_text())
    for kind, measured in data["per_pixel"].items():
        for row in measured["rows"]:
            if kind in framesize.TARGET_BYTES_PER_PIXEL:
                est = frame_estimate(tuple(row["size"]), kind, software=True).host
            else:  # the picture, beyond the frame's image, which the process already held
                e = picture_estimate(tuple(row["size"]), kind)
                est = e.host - 16 * row["pixels"]
            got = max(row["rss_added"], row["address_space_added"])
            assert got <= est, f"{kind} at {row['size']}: measured {got} bytes, estimated {est}"
        assert est <= 1.5 * got, f"{kind} at {row['size']}: estimated {est} bytes, measured only {got}"
    context = data["context"]
    assert context["rss_added"] <= framesize.CONTEXT_BYTES
    assert context["address_space_added"] <= framesize.CONTEXT_ADDRESS_SPACE

"""GL tests: every shader variant compiles, no GL error, every GL object released."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tetvr import Camera, RenderSettings
from tetvr.mesh import synthetic
from tetvr.gl import Renderer
from tetvr.gl.march_layout import Layout
from tetvr.render import default_transfer_function

pytestmark = pytest.mark.gl


def test_every_shader_variant_compiles():
    with Renderer() as r:
        assert r.ctx.error == "GL_NO_ERROR"
        r._program("classify")
        for pc, norm, near, cubic in itertools.product((0, 1), (0, 1), (0, 1), (0, 1)):
            r._program("tet", PERSPECTIVE_CORRECT=pc, TABLE_NORMALIZED=norm, NEAR_CROSSING=near, TABLE_CUBIC=cubic)
        for kind in ("floor", "depth"):
            r._program(kind, PERSPECTIVE_CORRECT=1)
        for kind in ("classify_vtk", "vtk_pt"):  # VTK parity (optics="vtk")
            r._program(kind)
        # The ray window (clip planes, a surface's ray limit) in both methods, the surfaces,
        # and tet marching without a table.
        for clip, limit, near in itertools.product((0, 3), (0, 1), (0, 1)):
            r._program("tet", PERSPECTIVE_CORRECT=1, TABLE_NORMALIZED=1, NEAR_CROSSING=near, CLIP_RANGE=1,
                       CLIP_PLANES=clip, RAY_LIMIT=limit, PERSPECTIVE=1)
        for clip, limit, exact, extent, persp in itertools.product((0, 6), (0, 1), (0, 1), (0, 1), (0, 1)):
            if exact and extent:
                continue
            r._program("march", PERSPECTIVE=persp, CELL_DATA=0, FIRST=1, TABLE_NORMALIZED=1, EXTENT=extent,
                       INTEGRATION_EXACT=exact, CLIP_PLANES=clip, RAY_LIMIT=limit, **Layout.of(16384).defines)
        # Cell data, repeated cells, a point field that jumps at faces, the entry list.
        for cells, copies, jumps, listed in itertools.product((0, 1), (0, 1), (0, 1), (0, 1)):
            r._program("march", PERSPECTIVE=1, CELL_DATA=cells, MULTIPLICITY=copies, JUMPS=jumps, FIRST=0,
                       LIST=listed, LIST_LENGTH=8, TABLE_NORMALIZED=1, EXTENT=0, **Layout.of(16384).defines)
        for persp in (0, 1):
            r._program("surface", PERSPECTIVE=persp)
        assert r.ctx.error == "GL_NO_ERROR"


@pytest.mark.parametrize("optics", ["exact", "vtk"])
def test_every_gl_object_is_released(optics):
    mesh = synthetic.cube(2)
    r = Renderer(RenderSettings(table_scalar_bins=32, table_thickness_slices=4, optics=optics))
    img = r.render(mesh, Camera.fit(mesh), default_transfer_function(mesh), size=(32, 32))
    assert img.shape == (32, 32, 4)
    objects = r._gl_objects()
    # programs, vao, buffers, table (VTK parity: the vertex colours instead), target
    assert len(objects) >= 8
    if optics == "vtk":
        assert r._parity is not None and r._parity.gl_objects()[0] in objects
    assert r.ctx.error == "GL_NO_ERROR"
    r.release()
    for obj in objects:
        assert type(obj.mglo).__name__ == "InvalidObject", f"{obj!r} was not released"
    r.release()  # twice is harmless
    with pytest.raises(RuntimeError, match="released"):
        r.render(mesh, Camera.fit(mesh), default_transfer_function(mesh), size=(8, 8))


@pytest.mark.parametrize("encoding,dtype", [("normalized", "float32"), ("premultiplied", "float32"),
                                            ("normalized", "uint8"), ("premultiplied", "uint8")])
def test_table_variants_render_finite_images(encoding, dtype):
    mesh = synthetic.cube(2)
    s = RenderSettings(table_encoding=encoding, table_dtype=dtype, table_scalar_bins=64, table_thickness_slices=8)
    with Renderer(s) as r:
        img = r.render(mesh, Camera.fit(mesh), default_transfer_function(mesh, opacity=0.8), size=(48, 48))
        assert r.ctx.error == "GL_NO_ERROR"
    assert np.all(np.isfinite(img)) and img[..., 3].max() > 0.1 and img[..., 3].max() <= 1.0


@pytest.mark.parametrize("size", [(0, 10), (10, -1), (100000, 10)])
def test_bad_image_size_is_rejected(renderer, size):
    mesh = synthetic.single_tet()
    with pytest.raises(ValueError, match="size"):
        renderer.render(mesh, Camera.fit(mesh), default_transfer_function(mesh), size=size)


def test_one_pixel_image(renderer):
    mesh = synthetic.single_tet()
    img = renderer.render(mesh, Camera.fit(mesh, zoom=0.2), default_transfer_function(mesh, opacity=0.9), size=(1, 1))
    assert img.shape == (1, 1, 4) and np.all(np.isfinite(img))


def test_missing_gl_gives_an_install_hint(monkeypatch):
    import moderngl

    from tetvr.gl import GLUnavailableError
    from tetvr.gl.context import create_context

    def broken(**kwargs):
        raise Exception("eglGetDisplay failed")

    monkeypatch.setattr(moderngl, "create_standalone_context", broken)
    with pytest.raises(GLUnavailableError, match=r"OpenGL 4\.3.*EGL: Exception: eglGetDisplay failed.*"
                                                 r"the platform default: .*apt-get install libegl1"):
        create_context()


def test_without_egl_the_platform_default_context_is_used(monkeypatch):
    import moderngl

    from tetvr.gl.context import create_context

    real = moderngl.create_standalone_context
    asked = []

    def no_egl(**kwargs):
        asked.append(kwargs.get("backend"))
        if kwargs.get("backend") == "egl":
            raise Exception("libEGL.so.1: cannot open shared object file")
        return real(backend="egl", require=kwargs["require"])  # this machine's stand-in for GLX/WGL/CGL

    monkeypatch.setattr(moderngl, "create_standalone_context", no_egl)
    with Renderer() as r:  # the context it got from the fallback renders
        mesh = synthetic.cube(2)
        img = r.render(mesh, Camera.fit(mesh), default_transfer_function(mesh), size=(8, 8))
    assert asked == ["egl", None] and img[..., 3].max() > 0.1


def test_gpu_bytes_counts_what_the_renderer_holds():
    mesh = synthetic.cube(2)
    table = 5 * 32 * 32 * 16
    with Renderer(RenderSettings(table_scalar_bins=32, table_thickness_slices=4, method="projected")) as r:
        r.render(mesh, Camera.fit(mesh), default_transfer_function(mesh), size=(16, 8))
        # points, tets + fan vertices (5 x 32 B) + order + fan indices (12 uint32 per tet), table, target
        expected = (mesh.n_points * 16 + mesh.n_tets * (16 + 160 + 4 + 48) + table + 16 * 8 * 16)
        assert r.gpu_bytes() == expected
    with Renderer(RenderSettings(table_scalar_bins=32, table_thickness_slices=4, method="raymarch")) as r:
        r.render(mesh, Camera.fit(mesh), default_transfer_function(mesh), size=(16, 8))
        # records, each one row of a power of two of items: the planes (at most 4096 tets, 5
        # RGBA32F texels each), the links (at most 4096 tets, 4 RGBA32I texels each), the ids
        # (RGBA32I), the points (RGBA32F) and the boundary faces' neighbours (RGBA32I), 8192 a
        # row; boundary faces (3 corners: 3 floats + 1 int), table, targets (entry id + depth,
        # and two sets of colour, state and last entry)
        n_faces = 6 * 4 * 2  # two triangles on each of a 2x2 grid of squares per cube side
        max_tex = r.ctx.info["GL_MAX_TEXTURE_SIZE"]
        tets_per_row = min(1 << ((max_tex // 5).bit_length() - 1), 4096)
        links_per_row = min(1 << ((max_tex // 4).bit_length() - 1), 4096)
        assert tets_per_row & (tets_per_row - 1) == 0 and tets_per_row * 5 <= max_tex
        expected = (tets_per_row * 5 * 16 + links_per_row * 4 * 16 + 3 * 8192 * 16 + n_faces * 3 * 16 + table
                    + 16 * 8 * (4 + 4 + 2 * (16 + 8 + 4)))
        assert r.gpu_bytes() == expected


def test_viewer_blit_shaders_compile():
    from tetvr.gl.shaders import assemble

    with Renderer() as r:
        with r.ctx:
            prog = r.ctx.program(vertex_shader=assemble("blit.vert")[0], fragment_shader=assemble("blit.frag")[0])
            assert r.ctx.error == "GL_NO_ERROR"
            prog.release()


def test_table_follows_the_transfer_function_asked_for():
    # Regression: table() used to remember the key of its last call but return the table of
    # the last frame, so asking twice for tfB after a frame with tfA gave tfA's table.
    from tetvr.optics.preintegrate import table_for

    mesh = synthetic.cube(2)
    s = RenderSettings(table_scalar_bins=32, table_thickness_slices=4)
    tf_a = default_transfer_function(mesh, opacity=0.2)
    tf_b = default_transfer_function(mesh, opacity=0.9)
    with Renderer(s) as r:
        r.render(mesh, Camera.fit(mesh), tf_a, size=(8, 8))
        table_a = r.table(mesh, tf_a)
        want = table_for(tf_b, mesh.scalar_range, mesh.max_edge, n_bins=s.table_scalar_bins,
                         n_slices=s.table_thickness_slices, log_base=s.table_log_base,
                         encoding=s.table_encoding, dtype=s.table_dtype, optics=s.optics,
                         align_nodes=s.table_align_nodes)
        for _ in range(2):
            table_b = r.table(mesh, tf_b)
            assert np.array_equal(table_b.data, want.data)
            assert not np.array_equal(table_b.data, table_a.data)
        assert r.table(mesh, tf_a) is table_a  # and back: the frame's table again


def test_table_follows_settings_replaced_between_frames():
    # Regression: the table cache was keyed on the scene only, so a renderer whose
    # settings were replaced kept returning the table of the old size.
    mesh = synthetic.cube(2)
    tf = default_transfer_function(mesh, opacity=0.5)
    with Renderer(RenderSettings(table_scalar_bins=32, table_thickness_slices=4)) as r:
        assert r.table(mesh, tf).n_bins == 32
        r.settings = RenderSettings(table_scalar_bins=64, table_thickness_slices=4)
        assert r.table(mesh, tf).n_bins == 64

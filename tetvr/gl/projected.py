"""Projected tetrahedra's cells on the GL: the mesh's buffers, chunks, classification, fan draws.

Owned by a :class:`~tetvr.gl.renderer.Renderer` (its context and programs), which sorts the
cells, sets the uniforms and owns the targets. Per mesh (once, :meth:`ProjectedCells.use_mesh`):
points and tets go to shader storage buffers. Per view: the drawing order goes to the order
buffer, or, for a mesh larger than one chunk, each chunk's cells in drawing order go to the
tets buffer (:meth:`~ProjectedCells.chunks`); ``classify.comp`` classifies the cells in
drawing order and writes each one's finished fan vertices into a vertex buffer
(:meth:`~ProjectedCells.classify`); one indexed draw call per batch of fans passes them
through ``tet.vert`` to the fragment shader (:meth:`~ProjectedCells.draw`).
"""

from __future__ import annotations

from typing import Any, Iterator

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh.tetmesh import TetMesh
from tetvr.gl.host import DrawHost, ProgramHost
from tetvr.gl.util import set_uniforms

__all__ = ["ProjectedCells", "exact_runs", "depth_pass"]

#: Bytes per tet that size the largest chunk against one storage-buffer binding: the tets
#: buffer needs 16 (the fan vertices are bound in ranges), with room for the per-tet data a
#: shader may bind whole; on llvmpipe's 128 MiB binding this caps chunks at 2.8M tets.
_CHUNK_BYTES_PER_TET = 48
#: One fan vertex as classify.comp writes it (common.glsl's FanVertex): uvec4(ndc.xy, exact
#: tet, 0), then the segment; 5 per tet. The attributes of tet.vert: (name, class, format, offset).
_FAN_VERTEX_BYTES = 32
_FAN_ATTRIBUTES = (("in_ndc", "f", "2f", 0), ("in_exact", "i", "1i", 8), ("in_chord", "f", "1f", 12),
                   ("in_segment", "f", "4f", 16))
_GROUP = 64  # classify.comp local size
_MAX_GROUPS = 65535
#: Most tets per draw call; the index buffer holds at most this many fan patterns (3 MiB).
_DRAW_BATCH = 65_536
#: tet.vert's fan of one tet: 4 triangles over its 5 vertices (0 the thick vertex).
_FAN_PATTERN = np.array([0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 1], dtype=np.uint32)
#: Tets per chunk: 96 MB of fan vertices (160 B a tet), which keeps host memory bounded for
#: meshes of millions of tets (bench/memory.py) on llvmpipe, whose buffers live there.
_DEFAULT_CHUNK = 600_000


def exact_runs(exact: range, n_tets: int) -> list[tuple[int, range]]:
    """The draws of ``n_tets`` classified fans: (1 with tet.frag's exact branch compiled in,
    0 without; drawing positions), in drawing order; ``exact`` the positions from the first
    to the last fan on the exact path (:meth:`ProjectedCells.classify`). The branch, merely
    present, makes llvmpipe's fragment stage up to three times slower, and near-plane tets,
    the usual exact ones, come last in a back-to-front order.

    Examples
    --------
    >>> exact_runs(range(0), 10)
    [(0, range(0, 10))]
    >>> exact_runs(range(7, 9), 10)
    [(0, range(0, 7)), (1, range(7, 9)), (0, range(9, 10))]
    """
    if not exact:
        return [(0, range(n_tets))]
    runs = [(0, range(exact.start)), (1, exact), (0, range(exact.stop, n_tets))]
    return [(variant, run) for variant, run in runs if run]


def depth_pass(owner: DrawHost, mesh: TetMesh, size: tuple[int, int], uniforms: dict[str, Any], *,
               perspective: int) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Per pixel, the eye depth of ``mesh``'s nearest entry and farthest exit (``inf`` and
    ``-inf`` where no cell is drawn), by ``depth.frag`` through ``owner``'s classification
    and draws, MIN-blended; ``uniforms`` the view's. Any order will do: every fan but the
    exact ones with the program that has no exact branch, then the range of the exact ones
    with the program that draws only them (the branch, merely present, slowed llvmpipe's
    whole pass threefold: cube(26) at 1024x1024, 700 against 200 ms)."""
    import moderngl

    correct = int(owner.settings.perspective_correct)
    progs = [owner._program("depth", PERSPECTIVE_CORRECT=correct, PERSPECTIVE=perspective, NEAR_CROSSING=on)
             for on in (0, 1)]
    for prog in progs:
        set_uniforms(prog, **uniforms)
    fbo = owner._use_target(size, 2)
    fbo.use()
    fbo.clear(3e38, 3e38, 0.0, 0.0)
    for n in owner._chunks(mesh, np.arange(mesh.n_tets, dtype=np.uint32)):
        # The depth pass reads no table coordinates: the table's uniforms do not matter.
        exact = owner._classify(n, uniforms, perspective_correct=correct, count_exact=True)
        for prog, run in ((progs[0], range(n)), (progs[1], exact)):
            if run:
                owner._draw(prog, fbo, run.stop, ((moderngl.ONE, moderngl.ONE), moderngl.MIN), run.start)
    ext = owner._read(fbo, size, 2)
    front = np.where(ext[..., 0] >= 3e38, np.inf, ext[..., 0]).astype(np.float32)
    back = np.where(ext[..., 1] >= 3e38, -np.inf, -ext[..., 1]).astype(np.float32)
    return front, back


class ProjectedCells:
    """GL state of projected tetrahedra for one :class:`~tetvr.gl.renderer.Renderer`: the
    mesh's points and cells, the drawing order, the fan vertices and the fans' index buffer.

    ``chunk_tets`` is the most tets classified and drawn at once (default 600,000), capped
    by the GL's storage-buffer size; larger meshes are drawn in sorted chunks."""

    def __init__(self, owner: ProgramHost, chunk_tets: int | None = None) -> None:
        self.owner = owner
        self.ctx = owner.ctx
        # One storage buffer must hold a chunk's fans (48 B/tet); meshes beyond it are drawn
        # in sorted chunks, each classified and drawn in turn.
        self.max_ssbo = int(self.ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE", 1 << 27))
        limit = self.max_ssbo // _CHUNK_BYTES_PER_TET
        self.chunk_tets = min(chunk_tets or _DEFAULT_CHUNK, limit)
        self.chunked = False
        self.centre = np.zeros(3)  # the buffers hold the points minus it
        self._mesh: TetMesh | None = None
        self._mesh_buffers: list[Any] = []  # points, tets
        self._gpu_tets: NDArray[np.int32] | None = None  # the tets buffer's cells (cell data: unshared points)
        self.fans: Any = None  # classify.comp's fan vertices, read as vertex attributes
        self._order: Any = None
        self._exact_count: Any = None  # classify.comp's count of fans on the exact path, first, last
        self.fan_indices: Any = None  # index buffer of fan patterns (_reserve_fans), made on first draw
        self._vaos: dict[int, Any] = {}

    # ---- ownership ----
    def gl_objects(self) -> list[Any]:
        return [*self._vaos.values(), *self._mesh_buffers,
                *(o for o in (self.fans, self._order, self.fan_indices, self._exact_count) if o is not None)]

    def forget(self) -> None:
        self._vaos.clear()
        self._mesh_buffers = []
        self.fans = self._order = self.fan_indices = self._exact_count = None
        self._mesh = self._gpu_tets = None

    def gpu_bytes(self) -> int:
        """Bytes held in the mesh's buffers, the order, the fan vertices and their indices."""
        return int(sum(b.size for b in [*self._mesh_buffers, self.fans, self._order, self.fan_indices]
                       if b is not None))

    # ---- per mesh ----
    def use_mesh(self, mesh: TetMesh) -> None:
        """Upload the mesh once. Meshes larger than one draw allows keep only their points
        on the GPU; their cells then travel per frame in sorted chunks (:meth:`chunks`)."""
        if mesh is self._mesh:
            return
        for b in [*self._mesh_buffers, self.fans, self._order]:
            if b is not None:
                b.release()
        # Coordinates relative to the mesh centre keep float32 precise far from the origin.
        self.centre = mesh.float32_origin
        if mesh.cell_scalars is None:
            pts = np.empty((mesh.n_points, 4), dtype=np.float32)
            pts[:, :3] = mesh.points - self.centre
            pts[:, 3] = mesh.scalars
            self._gpu_tets = mesh.tets
        else:
            # Cell data: every tet gets its own four points carrying its value, so the
            # shaders, which read a scalar per vertex, see the field constant in each tet.
            pts = np.empty((mesh.n_tets, 4, 4), dtype=np.float32)
            pts[..., :3] = mesh.points[mesh.tets] - self.centre
            pts[..., 3] = mesh.cell_scalars[:, None]
            pts = pts.reshape(-1, 4)
            self._gpu_tets = np.arange(4 * mesh.n_tets, dtype=np.int32).reshape(-1, 4)
        if pts.nbytes > self.max_ssbo:
            raise MemoryError(f"the mesh needs {pts.shape[0]} points on the GPU ({pts.nbytes >> 20} MiB); this GL "
                              f"allows {self.max_ssbo >> 20} MiB in one storage buffer")
        chunk = min(mesh.n_tets, self.chunk_tets)
        self.chunked = chunk < mesh.n_tets
        points = self.ctx.buffer(pts.tobytes())
        if self.chunked:
            tets = self.ctx.buffer(reserve=chunk * 16)
        else:
            tets = self.ctx.buffer(np.ascontiguousarray(self._gpu_tets, dtype=np.int32).tobytes())
        self._mesh_buffers = [points, tets]
        # Written by classify.comp, read as vertex attributes: 5 finished vertices per tet.
        self.fans = self.ctx.buffer(reserve=max(chunk, 1) * 5 * _FAN_VERTEX_BYTES)
        self._order = self.ctx.buffer(reserve=max(chunk, 1) * 4)
        if self.chunked:
            self._order.write(np.arange(chunk, dtype=np.uint32).tobytes())
        self._mesh = mesh

    # ---- per view ----
    def chunks(self, order: NDArray[np.uint32], clock: Any) -> Iterator[int]:
        """Make each chunk of the drawing order current in turn; yields the number of
        cells to classify and draw, which classify.comp finds through the order buffer.

        Unchunked meshes are one chunk: the order buffer holds the order (which may list a
        subset: the cells left after culling, or an explicit order). Chunked meshes get the
        cells of each chunk uploaded in drawing order, with an identity order.
        """
        if not self.chunked:
            self._order.write(np.ascontiguousarray(order, dtype=np.uint32).tobytes())
            clock.lap("order_upload")
            yield int(order.shape[0])
            return
        for first in range(0, int(order.shape[0]), self.chunk_tets):
            ids = order[first:first + self.chunk_tets]
            if first:
                # llvmpipe shades fragments when the scene is flushed, not at the draw, and
                # does not flush for a write to a storage buffer that a fragment shader reads
                # (tet.frag's exact segments read the tets buffer): without this wait the
                # previous chunk's near-plane fragments read this chunk's cells.
                self.ctx.finish()
            assert self._gpu_tets is not None  # set with the mesh's buffers
            self._mesh_buffers[1].write(np.ascontiguousarray(self._gpu_tets[ids], dtype=np.int32).tobytes())
            clock.lap("order_upload")
            yield int(ids.shape[0])

    def classify(self, n_tets: int, uniforms: dict[str, Any], clock: Any, *, perspective_correct: int,
                 count_exact: bool = False, program: Any = None) -> range:
        """Run classify.comp (or ``program``, which writes the same fans) over the first
        ``n_tets`` drawing positions of the order buffer: it writes their fans' vertices in
        drawing order. With ``count_exact``, return the drawing positions from the first to
        the last fan that takes the exact per-fragment path (empty where none; a 12-byte read
        that waits for the classification), else all ``n_tets``. ``uniforms`` holds the
        view's and, for the render, the table's (the vertices carry table coordinates)."""
        classify = program or self.owner._program("classify", PERSPECTIVE_CORRECT=perspective_correct)
        set_uniforms(classify, u_count=n_tets, **uniforms)
        if self._exact_count is None:
            self._exact_count = self.ctx.buffer(reserve=12)
        self._exact_count.write(np.array([0, 0xFFFFFFFF, 0], dtype=np.uint32).tobytes())  # count, first, last
        self._mesh_buffers[0].bind_to_storage_buffer(0)
        self._mesh_buffers[1].bind_to_storage_buffer(1)
        self._order.bind_to_storage_buffer(3)
        self._exact_count.bind_to_storage_buffer(4)
        # A chunk's fan vertices (160 B/tet) may exceed one storage-buffer binding: bind them
        # in ranges. A whole number of groups per range keeps each offset a multiple of
        # 64 * 160 B, which meets any GL's offset alignment.
        per_tet = 5 * _FAN_VERTEX_BYTES
        step = min(_MAX_GROUPS, max(self.max_ssbo // (per_tet * _GROUP), 1)) * _GROUP
        for first in range(0, n_tets, step):
            count = min(step, n_tets - first)
            self.fans.bind_to_storage_buffer(2, offset=first * per_tet, size=count * per_tet)
            set_uniforms(classify, u_offset=first)
            classify.run((count + _GROUP - 1) // _GROUP)
        exact = range(n_tets)
        if count_exact:
            self.ctx.memory_barrier()
            count, first, last = (int(v) for v in np.frombuffer(self._exact_count.read(), dtype=np.uint32))
            exact = range(first, last + 1) if count else range(0)
        clock.lap("classify")
        return exact

    def draw(self, prog: Any, fbo: Any, n_tets: int, blend: tuple[Any, ...], clock: Any, first: int = 0) -> None:
        """Draw the classified fans at drawing positions ``first`` to ``n_tets`` with ``prog``
        into ``fbo`` under ``blend`` ((source, destination factors), equation), in batches
        of indexed fans."""
        import moderngl

        fbo.use()
        # The exact per-fragment path reads the mesh (tet.frag, depth.frag).
        self._mesh_buffers[0].bind_to_storage_buffer(0)
        self._mesh_buffers[1].bind_to_storage_buffer(1)
        self.ctx.memory_barrier()  # classify.comp's vertices -> the vertex fetch
        self.ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func, self.ctx.blend_equation = blend
        self._reserve_fans(min(n_tets - first, _DRAW_BATCH))
        vao = self._vaos.get(id(prog))
        if vao is None:
            vao = self._vaos[id(prog)] = self.ctx.vertex_array(prog, [], index_buffer=self.fan_indices,
                                                               index_element_size=4)
        attributes = [(prog[name].location, cls, fmt, offset) for name, cls, fmt, offset in _FAN_ATTRIBUTES
                      if name in prog]  # the floor shader reads no segment
        for start in range(first, n_tets, _DRAW_BATCH):
            # The index pattern counts from 0: each batch points the attributes at its first tet.
            base = start * 5 * _FAN_VERTEX_BYTES
            for location, cls, fmt, offset in attributes:
                vao.bind(location, cls, self.fans, fmt, offset=base + offset, stride=_FAN_VERTEX_BYTES)
            count = min(_DRAW_BATCH, n_tets - start)
            # fan_varyings.glsl (INTERPOLATE_IN_SHADER) reads the batch's fan vertices here.
            self.fans.bind_to_storage_buffer(2, offset=base, size=count * 5 * _FAN_VERTEX_BYTES)
            vao.render(moderngl.TRIANGLES, vertices=12 * count)
        self.ctx.disable(moderngl.BLEND)
        clock.lap("draw")

    def _reserve_fans(self, n_tets: int) -> None:
        """Make the index buffer hold the fan pattern of at least ``n_tets`` tets (the
        vertex arrays that use it are remade with it)."""
        if self.fan_indices is not None and self.fan_indices.size >= n_tets * _FAN_PATTERN.nbytes:
            return
        for obj in [*self._vaos.values(), *([self.fan_indices] if self.fan_indices is not None else [])]:
            obj.release()
        self._vaos.clear()
        first = np.arange(max(n_tets, 1), dtype=np.uint32)[:, None] * 5
        self.fan_indices = self.ctx.buffer((first + _FAN_PATTERN).tobytes())

"""How the tet-marching ray caster's records sit on the GL: the image units the passes read
them from, the textures' layout (items a row, powers of two), the textures themselves
(:func:`records_textures`), and the GL buffers of one view's rim faces
(:func:`tetvr.mesh.records.rim_faces`). Used by :mod:`tetvr.gl.raymarch`."""

from __future__ import annotations

import dataclasses
import threading
from typing import Any, Iterator

import numpy as np
from numpy.typing import NDArray

from tetvr.mesh import adjacency
from tetvr.mesh.records import RECORD_TEXELS, MarchRecords, cell_records
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["PLANES_IMAGE", "IDS_IMAGE", "LINKS_IMAGE", "POINTS_IMAGE", "COUNT_IMAGE", "LIST_IMAGE", "COPIES_IMAGE", "NEIGHBORS_IMAGE",
           "OVERFLOW_BUFFER", "MORE_BUFFER", "SUSPECT_BUFFER", "SUSPECT_LENGTH", "LIST_LENGTH", "LIST_MAX_BYTES", "NEAREST", "Layout", "Rim",
           "raymarch_capacity", "rect_triangles", "records_textures", "texture"]

#: GL_NEAREST: records and targets are read with texelFetch, never filtered (the value of
#: moderngl.NEAREST, written here so that importing this module imports no moderngl).
NEAREST = 0x2600


#: Image units of the walk's records, read with imageLoad (march_common.glsl): on llvmpipe
#: an imageLoad costs less than a texelFetch (no sampler state, no level), and the walk
#: measured 11-12 % faster on bluntfin at 512x512, images bit-identical. Units 0-3: GL 4.3
#: guarantees 8 image units to a fragment shader.
PLANES_IMAGE, IDS_IMAGE, LINKS_IMAGE, POINTS_IMAGE = 0, 1, 2, 3
#: Image units of the first layer's entry list (march_entry.frag, LIST): each pixel's count
#: of faces, and the faces; storage-buffer bindings of the pixels that overflowed it and of
#: those that go on to another layer (march.frag, LIST).
COUNT_IMAGE, LIST_IMAGE, OVERFLOW_BUFFER, MORE_BUFFER = 4, 5, 0, 1
#: Storage-buffer binding of the frame's check of itself (march.frag: the count of pixels
#: whose walk went wrong, and the first SUSPECT_LENGTH of them, for tetvr.gl.selfcheck).
SUSPECT_BUFFER = 2
SUSPECT_LENGTH = 4096
#: Faces listed per pixel: a pixel whose ray meets more front faces than this (in its
#: clipping range) overflows the list, and that frame peels instead. With the list, the
#: march passes pick each further entry themselves: no peel pass rasterises the boundary
#: again, and none runs to find that no ray enters again.
LIST_LENGTH = 8
#: Most bytes the list may hold (its count and LIST_LENGTH faces a pixel, 68 B): a larger
#: frame (above about 1400x1400) peels instead.
LIST_MAX_BYTES = 128 << 20
#: Image unit of each tet's number of copies (march.frag, MULTIPLICITY: a mesh in which
#: cells repeat, :mod:`tetvr.mesh.copies`).
COPIES_IMAGE = 6
#: Image unit of each boundary face's neighbours on the boundary (march.frag, LIST:
#: :attr:`tetvr.mesh.records.MarchRecords.boundary_neighbors`).
NEIGHBORS_IMAGE = 7


@dataclasses.dataclass(frozen=True)
class Layout:
    """Items per row of each records texture: powers of two, so that the shaders find an
    item's row and column by a shift and a mask (llvmpipe has no vector integer division:
    ``i / n`` with n a uniform costs one scalar division per lane; at 512x512 the walk
    measured 17 % faster on bluntfin, 41 % on combustor)."""

    planes: int  # tets a row of the planes texture (RECORD_TEXELS texels a tet)
    links: int   # tets a row of the links texture (four texels a tet)
    items: int   # tets a row of the ids texture, points a row of the points texture

    @classmethod
    def of(cls, max_texture_size: int) -> "Layout":
        def pow2(n: int) -> int:
            return 1 << max(0, n.bit_length() - 1)

        return cls(min(pow2(max_texture_size // RECORD_TEXELS), 4096), min(pow2(max_texture_size // 4), 4096),
                   min(pow2(max_texture_size), 8192))

    def capacity(self, max_texture_size: int) -> int:
        """The most tets (and points) the textures hold."""
        return min(self.planes, self.links, self.items) * max_texture_size

    @property
    def defines(self) -> dict[str, int]:
        return dict(TETS_ROW_SHIFT=self.planes.bit_length() - 1, LINKS_ROW_SHIFT=self.links.bit_length() - 1,
                    ITEMS_ROW_SHIFT=self.items.bit_length() - 1, PLANES_IMAGE=PLANES_IMAGE, IDS_IMAGE=IDS_IMAGE,
                    LINKS_IMAGE=LINKS_IMAGE, POINTS_IMAGE=POINTS_IMAGE, COUNT_IMAGE=COUNT_IMAGE,
                    LIST_IMAGE=LIST_IMAGE, OVERFLOW_BUFFER=OVERFLOW_BUFFER, MORE_BUFFER=MORE_BUFFER,
                    COPIES_IMAGE=COPIES_IMAGE, NEIGHBORS_IMAGE=NEIGHBORS_IMAGE, SUSPECT_BUFFER=SUSPECT_BUFFER,
                    SUSPECT_LENGTH=SUSPECT_LENGTH)


def rect_triangles(rects: NDArray[np.float64]) -> NDArray[np.float32]:
    """NDC rectangles (x_lo, y_lo, x_hi, y_hi) as two counter-clockwise triangles each:
    (n, 6, 2) corners."""
    return rects[:, [[0, 1], [2, 1], [2, 3], [0, 1], [2, 3], [0, 3]]].astype(np.float32)


def raymarch_capacity(max_texture_size: int) -> int:
    """The most tets whose records fit one texture of a GL with this GL_MAX_TEXTURE_SIZE."""
    return Layout.of(max_texture_size).capacity(max_texture_size)


@dataclasses.dataclass(frozen=True)
class Rim:
    """One view's :func:`~tetvr.mesh.records.rim_faces` on the GL: vertex buffers of the
    rectangles (6 corners a face), of each face's corners in float64 and of its slot, and an
    index buffer of the boundary faces the rasteriser draws (``n_drawn`` indices)."""

    rects: Any
    corners: Any
    slots: Any
    drawn: Any
    n_faces: int
    n_drawn: int

    def release(self) -> None:
        for b in (self.rects, self.corners, self.slots, self.drawn):
            b.release()


def records_textures(ctx: Any, layout: Layout, mesh: TetMesh, rec: MarchRecords,
                     copies: NDArray[np.int32] | None) -> tuple[dict[int, Any], bool]:
    """The records of ``mesh`` on the GL, by image unit (not the points: written per view),
    and whether the field jumps at any face (march.frag, JUMPS). The per-tet planes and
    links are built a block of tets at a time (:func:`~tetvr.mesh.records.cell_records`)
    and each block goes to its textures as it is built, so that the host never holds them
    whole (on a GL that keeps textures in host memory, as llvmpipe does, they would be
    there twice); a second thread builds blocks from the last one back (:class:`_BothEnds`);
    ``copies``: each tet's number of copies, where cells repeat."""
    if _SHARED_BLOCK % max(layout.planes, layout.links):
        raise ValueError(f"blocks of {_SHARED_BLOCK} tets do not fill whole rows of {layout}")
    assert rec.ids is not None
    textures: dict[int, Any] = {}
    try:  # a GL out of memory half-way: what was made is released
        planes = textures[PLANES_IMAGE] = _empty(ctx, mesh.n_tets, layout.planes, RECORD_TEXELS, "f4")
        links = textures[LINKS_IMAGE] = _empty(ctx, mesh.n_tets, layout.links, 4, "i4")
        jumps = False
        for rows, block_planes, block_links in _BothEnds(mesh, rec):
            _write(planes, rows.start, block_planes, layout.planes, RECORD_TEXELS, 0.0)
            _write(links, rows.start, block_links, layout.links, 4, -1)
            jumps |= bool(np.any(block_links[..., 3]))
        textures[IDS_IMAGE] = texture(ctx, rec.ids, layout.items, 1, 0)
        textures[NEIGHBORS_IMAGE] = texture(ctx, rec.boundary_neighbors, layout.items, 1, -1)
        if copies is not None:
            per_tet = np.zeros((mesh.n_tets, 4), dtype=np.int32)
            per_tet[:, 0] = copies
            textures[COPIES_IMAGE] = texture(ctx, per_tet, layout.items, 1, 0)
    except BaseException:
        for tex in textures.values():
            tex.release()
        raise
    return textures, jumps


#: Tets a block of the records is built in by :class:`_BothEnds` (a multiple of every row of
#: :class:`Layout`: at most 4096 tets a row of the planes and links).
_SHARED_BLOCK = 1 << 14
#: The most blocks the helper of :class:`_BothEnds` holds built that the caller has not
#: taken yet (0: no helper). The caller takes them after each of its own, so it rarely waits
#: at this bound; it bounds the host memory of records in flight (~2.4 MB a block).
_HELPER_AHEAD = 4


class _BothEnds:
    """The per-tet records of ``mesh`` (:func:`~tetvr.mesh.records.cell_records`), block by
    block: the caller builds them from the first block on as it iterates, and a helper
    thread from the last block back, until the two meet (numpy lets go of the GIL in its
    loops: on bluntfin's 187k tets, 0.55 s -> 0.35 s on two cores). After each of its own
    blocks the caller yields the helper's built since, so blocks come out of order and few
    wait in memory (:data:`_HELPER_AHEAD` at most; they waited for the caller to reach them
    before: 64 MiB more at the peak of 2M tets' first frame). (Both threads taking the next
    block in turn measured slower on bluntfin, 0.5 s against 0.35 s: the caller waits for
    the helper's blocks between its own.)"""

    def __init__(self, mesh: TetMesh, rec: MarchRecords) -> None:
        self.mesh, self.rec = mesh, rec
        self.rows = adjacency.blocks(mesh.n_tets, _SHARED_BLOCK)
        self.front, self.back = 0, len(self.rows) - 1  # the next block each side takes
        self.stopped = False
        self.built: dict[int, tuple[NDArray[np.float32], NDArray[np.int32]] | BaseException] = {}
        self.cond = threading.Condition()
        if len(self.rows) > 1 and _HELPER_AHEAD > 0:
            threading.Thread(target=self._helper, name="tetvr-records-back", daemon=True).start()

    def _helper(self) -> None:
        while True:
            with self.cond:
                self.cond.wait_for(lambda: self.stopped or len(self.built) < _HELPER_AHEAD)
                if self.stopped or self.back < self.front:
                    return
                i, self.back = self.back, self.back - 1
            try:
                result: Any = cell_records(self.mesh, self.rec, self.rows[i])
            except BaseException as exc:  # raised in the caller, with that block
                result = exc
            with self.cond:
                self.built[i] = result
                self.cond.notify_all()

    def __iter__(self) -> Iterator[tuple[slice, NDArray[np.float32], NDArray[np.int32]]]:
        try:
            yield from self._blocks()
        finally:  # done, or the caller stopped: the helper takes no more blocks
            with self.cond:
                self.stopped = True
                self.built.clear()
                self.cond.notify_all()

    def _blocks(self) -> Iterator[tuple[slice, NDArray[np.float32], NDArray[np.int32]]]:
        left = len(self.rows)
        while left:
            with self.cond:
                mine = self.front if self.front <= self.back else None
                if mine is not None:
                    self.front += 1
                else:  # the rest are the helper's: wait for one
                    self.cond.wait_for(lambda: bool(self.built))
                ready, self.built = self.built, {}
                self.cond.notify_all()
            if mine is not None:
                left -= 1
                yield (self.rows[mine], *cell_records(self.mesh, self.rec, self.rows[mine]))
            for i, result in sorted(ready.items()):
                if isinstance(result, BaseException):
                    raise result
                left -= 1
                yield (self.rows[i], *result)


def texture(ctx: Any, items: NDArray[Any], per_row: int, texels: int, fill: float) -> Any:
    """A texture of ``items``, each ``texels`` texels of four components, ``per_row`` items
    a row (the last row padded with ``fill``)."""
    tex = _empty(ctx, items.shape[0], per_row, texels, items.dtype.str[1:])
    _write(tex, 0, items, per_row, texels, fill)
    return tex


def _empty(ctx: Any, n: int, per_row: int, texels: int, dtype: str) -> Any:
    """A texture for ``n`` items, each ``texels`` texels of four components, ``per_row`` a row."""
    tex = ctx.texture((per_row * texels, -(-n // per_row)), 4, dtype=dtype)
    tex.filter = (NEAREST, NEAREST)
    return tex


def _write(tex: Any, start: int, items: NDArray[Any], per_row: int, texels: int, fill: float) -> None:
    """``items`` into ``tex`` from item ``start`` (the first of a row) on, as :func:`texture`
    lays them out: whole rows straight from the array, the last one padded with ``fill``."""
    whole = items.shape[0] // per_row * per_row
    row = start // per_row
    if whole:
        tex.write(np.ascontiguousarray(items[:whole]), viewport=(0, row, per_row * texels, whole // per_row))
    if whole < items.shape[0]:
        last = np.full((per_row, *items.shape[1:]), fill, dtype=items.dtype)
        last[:items.shape[0] - whole] = items[whole:]
        tex.write(last, viewport=(0, row + whole // per_row, per_row * texels, 1))

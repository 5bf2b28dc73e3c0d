"""Where the pixel rays meet the tetrahedra: the geometry half of the CPU reference.

Steps 1-3 of :mod:`tetvr.reference.tets` (Garrity 1990): each tet's face planes and
linear scalar function in eye space, its candidate pixels (the pixel centres in its
projected bounding box, near-plane crossings clipped first), and the Cyrus–Beck clip of
every candidate ray against its four planes and the clipping range. Vectorised over
(tet, pixel) pairs, a chunk of tets at a time.

Watertightness. A face shared by two tets is computed from its three vertices in
ascending id order in both tets, so the two planes are exact negatives of each other,
bit for bit. A ray that crosses the face therefore leaves one tet at exactly the ``t``
where it enters the other: there are no gaps and no overlaps, and no tolerance is
needed. A ray that lies *in* a shared face (it happens with axis-aligned orthographic
views of axis-aligned meshes) is given to exactly one of the two tets by a symbolic
perturbation of the ray origin along eye ``x``, then ``y``, then ``z`` (the rule that
makes rasteriser fill conventions watertight).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Iterator, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.core.checks import check_instances
from tetvr.core.image import image_size
from tetvr.core.rays import EyeRays
from tetvr.mesh.adjacency import FACE_VERTICES
from tetvr.mesh.tetmesh import TetMesh
from tetvr.reference.boxes import candidates

__all__ = ["DEFAULT_CHUNK", "RaySegments", "pixel_extents", "ray_lengths", "ray_segments"]

#: Candidate (tet, pixel) pairs examined at once: ~200 bytes of temporaries each, so
#: ~50 MB. Larger chunks are no faster (bluntfin at 256x256 on 2 cores: 2.3-3 s for
#: chunks of 2**16 to 2**18, 3.5 s at 2**20): their arrays fall out of cache.
DEFAULT_CHUNK = 1 << 18

# Pixel-centre boxes are widened by this much so that rounding in the projection never
# drops a ray that touches the tet; the exact plane test then decides.
_BOX_MARGIN_PX = 1e-6

# Faces opposite vertex k, as local indices in ascending order. Tet vertices are sorted
# by id first, so a face shared by two tets is built from the same points in the same
# order in both and its plane is bit-identical up to sign.
_FACES = FACE_VERTICES

Float = NDArray[np.float64]
Int = NDArray[np.int64]


class RaySegments(NamedTuple):
    """The intersections of the pixel rays with the tets, one row per (ray, tet).

    ``t`` is eye depth along the ray of pixel ``pixel`` (row-major, row 0 at the top), as
    in :meth:`tetvr.core.camera.Camera.rays`; multiply a length in ``t`` by
    :func:`ray_lengths` ``[pixel]`` to get world units. Only segments of positive length
    are listed, clipped to the camera's clipping range, in no particular order.
    """

    pixel: Int
    t_in: Float
    t_out: Float
    scalar_in: Float
    scalar_out: Float
    tet: Int


@dataclasses.dataclass(frozen=True)
class _TetGeometry:
    """Per-tet data in eye space for the tets that can be seen (``index`` into mesh.tets)."""

    index: Int  # (m,)
    nx: Float  # (m, 4) outward face normals, components
    ny: Float
    nz: Float
    d: Float  # (m, 4) plane offsets: inside is n . x - d <= 0
    perturb_out: NDArray[np.bool_]  # (m, 4) a ray lying in the plane is outside
    p0: Float  # (m, 3) first vertex
    s0: Float  # (m,) its scalar
    grad: Float  # (m, 3) scalar gradient
    s_min: Float  # (m,) scalar range over the vertices
    s_max: Float
    col_lo: Int  # (m,) candidate pixel box, inclusive
    col_hi: Int
    row_lo: Int
    row_hi: Int


def _validate(mesh: TetMesh, camera: Camera, size: tuple[int, int]) -> tuple[int, int]:
    check_instances(mesh=(mesh, TetMesh), camera=(camera, Camera))
    return image_size(size)


def _check_chunk(chunk: int) -> int:
    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
        raise ValueError(f"chunk must be a positive integer, got {chunk!r}")
    return int(chunk)


def _tet_geometry(mesh: TetMesh, camera: Camera, rays: EyeRays, pixels: Int | None = None) -> _TetGeometry:
    """Planes, scalar functions and candidate pixel boxes of the tets (with ``pixels``,
    row * width + column, only of the tets whose box may hold one of them)."""
    view = camera.view_matrix()
    pts = (mesh.points - np.asarray(camera.position)) @ view[:3, :3].T  # eye space
    base = None
    ids = mesh.tets
    if pixels is not None:  # a few pixels of a large mesh: their tets first, cheaply
        held = _held_by(pixels, rays)
        some = candidates(mesh, np.asarray(camera.position, dtype=np.float64), view[:3, :3], rays, _pixel_coords, held,
                          wait=False)
        base = np.flatnonzero(_may_cover(pts, ids if some is None else ids[some], rays, held))
        if some is not None:
            base = some[base]
        ids = ids[base]
    ids = np.sort(ids.astype(np.int64), axis=1)
    p = pts[ids]  # (m, 4, 3)
    depth = -p[:, :, 2]

    # Cull what the clipping range removes whole, and tets of zero volume (they hold no
    # segment of positive length, and their planes are undefined).
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    vol6 = np.einsum("ij,ij->i", np.cross(e1, e2), e3)
    visible = (depth.max(axis=1) >= rays.near) & (depth.min(axis=1) <= rays.far) & (vol6 != 0)
    index = np.nonzero(visible)[0]
    p, depth, ids = p[index], depth[index], ids[index]
    if base is not None:
        index = base[index]  # ids into the mesh's tets

    col_lo, col_hi, row_lo, row_hi = _pixel_boxes(p, depth, rays)
    nonempty = (col_lo <= col_hi) & (row_lo <= row_hi)
    index, p, ids = index[nonempty], p[nonempty], ids[nonempty]
    col_lo, col_hi, row_lo, row_hi = col_lo[nonempty], col_hi[nonempty], row_lo[nonempty], row_hi[nonempty]

    fa, fb, fc = p[:, _FACES[:, 0]], p[:, _FACES[:, 1]], p[:, _FACES[:, 2]]  # (m, 4, 3)
    n = np.cross(fb - fa, fc - fa)
    d = np.einsum("ijk,ijk->ij", n, fa)
    # Orient outward: the opposite vertex must be on the inside (negative) side. Only the
    # sign changes, which is exact, so shared faces stay exact negatives of each other.
    height = np.einsum("ijk,ijk->ij", n, p) - d
    flip = height > 0
    n = np.where(flip[:, :, None], -n, n)
    d = np.where(flip, -d, d)
    height = np.where(flip, -height, height)

    # A ray lying in a plane is inside iff the origin, pushed by (eps, eps^2, eps^3) in eye
    # space, is: the sign of the first non-zero normal component decides. Twin faces have
    # opposite normals, so exactly one of the two tets takes the ray.
    lead = np.where(n[..., 0] != 0, n[..., 0], np.where(n[..., 1] != 0, n[..., 1], n[..., 2]))
    perturb_out = lead > 0

    # Scalar gradient from the barycentric gradients n_k / height_k (lambda_k = f_k / f_k(p_k)).
    s = mesh.scalars[ids] if mesh.cell_scalars is None else mesh.corner_scalars[index]
    grad = np.einsum("ij,ijk->ik", (s[:, 1:] - s[:, :1]) / height[:, 1:], n[:, 1:])

    return _TetGeometry(
        index=index,
        nx=np.ascontiguousarray(n[..., 0]),
        ny=np.ascontiguousarray(n[..., 1]),
        nz=np.ascontiguousarray(n[..., 2]),
        d=d,
        perturb_out=perturb_out,
        p0=p[:, 0].copy(),
        s0=s[:, 0].copy(),
        grad=grad,
        s_min=s.min(axis=1),
        s_max=s.max(axis=1),
        col_lo=col_lo,
        col_hi=col_hi,
        row_lo=row_lo,
        row_hi=row_hi,
    )


def _may_cover(pts: Float, tets: Int, rays: EyeRays, held: Callable[..., NDArray[np.bool_]]) -> NDArray[np.bool_]:
    """Per tet, whether its box (:func:`_pixel_boxes`) may hold one of the pixels ``held``
    counts (:func:`_held_by`): the box of its vertices' projections where all lie in front
    of the near plane (the same box, by the same arithmetic), and every tet that reaches
    the near plane (its box comes from the cut; kept). Per point, then four columns of the
    tets (numpy reduces a short last axis slowly)."""
    depth = -pts[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        col, row = _pixel_coords(pts[:, 0], pts[:, 1], None if rays.parallel else depth, rays)
    loose = ~(np.isfinite(col) & np.isfinite(row))  # a point whose projection bounds nothing
    if not rays.parallel:
        loose |= depth < rays.near
    t = [np.ascontiguousarray(tets[:, k]) for k in range(4)]

    def pick(v: Float, f: Any) -> Float:
        return f(f(v[t[0]], v[t[1]]), f(v[t[2]], v[t[3]]))

    kept = loose[t[0]] | loose[t[1]] | loose[t[2]] | loose[t[3]]
    col, row = np.where(loose, 0.0, col), np.where(loose, 0.0, row)
    return held(pick(col, np.minimum), pick(col, np.maximum), pick(row, np.minimum), pick(row, np.maximum)) | kept


def _held_by(pixels: Int, rays: EyeRays) -> Callable[..., NDArray[np.bool_]]:
    """``held(col_min, col_max, row_min, row_max)``: per box of pixel coordinates, whether
    the pixel centres it holds (:func:`_box`) include one of ``pixels``, from a summed
    table of the pixels."""
    mask = np.zeros((rays.height + 1, rays.width + 1), dtype=np.int64)
    np.add.at(mask, (pixels // rays.width + 1, pixels % rays.width + 1), 1)
    table = mask.cumsum(axis=0).cumsum(axis=1)

    def held(col_min: Float, col_max: Float, row_min: Float, row_max: Float) -> NDArray[np.bool_]:
        c_lo, c_hi, r_lo, r_hi = _box(col_min, col_max, row_min, row_max, rays)
        ok = (c_lo <= c_hi) & (r_lo <= r_hi)
        c_lo, c_hi, r_lo, r_hi = (np.where(ok, a, 0) for a in (c_lo, c_hi, r_lo, r_hi))
        count = table[r_hi + 1, c_hi + 1] - table[r_lo, c_hi + 1] - table[r_hi + 1, c_lo] + table[r_lo, c_lo]
        return ok & (count > 0)

    return held


def _pixel_coords(x: Float, y: Float, depth: Float | None, rays: EyeRays) -> tuple[Float, Float]:
    """Column and row of eye-space ``x``, ``y`` (at ``depth`` in perspective, None in parallel
    projection), pixel centre (row i, col j) at x_ndc = 2 (j + 0.5) / W - 1, y_ndc = 1 - 2 (i + 0.5) / H."""
    x_ndc = x / rays.kx if depth is None else x / (depth * rays.kx)
    y_ndc = y / rays.ky if depth is None else y / (depth * rays.ky)
    return (x_ndc + 1.0) * (0.5 * rays.width) - 0.5, (1.0 - y_ndc) * (0.5 * rays.height) - 0.5


def _box(col_min: Float, col_max: Float, row_min: Float, row_max: Float, rays: EyeRays) -> tuple[Int, Int, Int, Int]:
    """The inclusive pixel ranges of a box of columns and rows, widened by the margin and
    clipped to the image (in float first: boxes far outside must not overflow int64)."""
    col_lo = np.ceil(np.clip(col_min - _BOX_MARGIN_PX, -1, rays.width)).astype(np.int64)
    col_hi = np.floor(np.clip(col_max + _BOX_MARGIN_PX, -1, rays.width)).astype(np.int64)
    row_lo = np.ceil(np.clip(row_min - _BOX_MARGIN_PX, -1, rays.height)).astype(np.int64)
    row_hi = np.floor(np.clip(row_max + _BOX_MARGIN_PX, -1, rays.height)).astype(np.int64)
    return (np.maximum(col_lo, 0), np.minimum(col_hi, rays.width - 1), np.maximum(row_lo, 0),
            np.minimum(row_hi, rays.height - 1))


def _pixel_boxes(p: Float, depth: Float, rays: EyeRays) -> tuple[Int, Int, Int, Int]:
    """Inclusive column and row range of the pixel centres each tet can cover."""
    if rays.parallel:
        # Affine projection: the vertices bound the shadow.
        col, row = _pixel_coords(p[:, :, 0], p[:, :, 1], None, rays)
        valid = np.ones(col.shape, dtype=bool)
    else:
        # Perspective: bound the part of the tet in front of the near plane, the convex
        # hull of the vertices there and the points where edges cross the plane. All
        # of them have depth >= near > 0, so their projections are finite.
        ia, ib = np.triu_indices(4, 1)
        da, db = depth[:, ia], depth[:, ib]
        crosses = (da < rays.near) != (db < rays.near)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(crosses, (rays.near - da) / np.where(crosses, db - da, 1.0), 0.0)
        cut = p[:, ia] + lam[:, :, None] * (p[:, ib] - p[:, ia])
        q = np.concatenate([p, cut], axis=1)  # (m, 10, 3)
        valid = np.concatenate([depth >= rays.near, crosses], axis=1)
        col, row = _pixel_coords(q[:, :, 0], q[:, :, 1], np.where(valid, -q[:, :, 2], 1.0), rays)
    return _box(np.where(valid, col, np.inf).min(axis=1), np.where(valid, col, -np.inf).max(axis=1),
                np.where(valid, row, np.inf).min(axis=1), np.where(valid, row, -np.inf).max(axis=1), rays)


def _iter_segments(geo: _TetGeometry, rays: EyeRays, chunk: int) -> Iterator[RaySegments]:
    """Ray-tet segments, a chunk of tets at a time (each chunk has <= ``chunk`` candidates,
    unless a single tet alone has more)."""
    box_w = geo.col_hi - geo.col_lo + 1
    box_h = geo.row_hi - geo.row_lo + 1
    counts = box_w * box_h
    ends = np.cumsum(counts)
    m = counts.shape[0]
    start = 0
    while start < m:
        base = ends[start - 1] if start else 0
        stop = max(int(np.searchsorted(ends, base + chunk, side="right")), start + 1)
        yield _clip_chunk(geo, rays, np.arange(start, stop), counts[start:stop], box_w)
        start = stop


def _clip_chunk(geo: _TetGeometry, rays: EyeRays, tets: Int, counts: Int, box_w: Int) -> RaySegments:
    """Clip the rays of every candidate pixel of ``tets`` against those tets."""
    total = int(counts.sum())
    tet = np.repeat(tets, counts)
    first = np.cumsum(counts) - counts
    k = np.arange(total, dtype=np.int64) - np.repeat(first, counts)
    w = box_w[tet]
    row = geo.row_lo[tet] + k // w
    col = geo.col_lo[tet] + k % w
    del k, w
    return _clip_pairs(geo, rays, tet, row, col)


#: Screen tiles (pixels a side) through which the rays of a few pixels find their tets.
_TILE = 16


def _pixel_segments(geo: _TetGeometry, rays: EyeRays, pixels: Int, chunk: int) -> Iterator[RaySegments]:
    """Ray-tet segments of the rays through ``pixels`` only (row * width + column, sorted):
    each pixel's candidate tets are those whose box holds it, found through the screen tiles
    the boxes cover, then in the order the whole image takes them (by tet, per pixel)."""
    row, col = pixels // rays.width, pixels % rays.width
    tiles_x = -(-rays.width // _TILE)
    c0, r0 = geo.col_lo // _TILE, geo.row_lo // _TILE
    w = geo.col_hi // _TILE - c0 + 1
    n = w * (geo.row_hi // _TILE - r0 + 1)  # tiles per box
    if int(n.sum()) > 16 * chunk:  # boxes over much of the screen: pixel by pixel, every box
        per = max(1, chunk // max(1, geo.col_lo.shape[0]))
        for start in range(0, pixels.size, per):
            some = slice(start, start + per)
            inside = ((geo.col_lo[None, :] <= col[some, None]) & (col[some, None] <= geo.col_hi[None, :])
                      & (geo.row_lo[None, :] <= row[some, None]) & (row[some, None] <= geo.row_hi[None, :]))
            which, tet = np.nonzero(inside)
            if tet.size:
                yield _clip_pairs(geo, rays, tet, row[some][which], col[some][which])
        return
    tile = (row // _TILE) * tiles_x + col // _TILE
    order = np.argsort(tile, kind="stable")
    first = np.searchsorted(tile[order], np.arange(tiles_x * -(-rays.height // _TILE) + 1))
    held = np.diff(first)  # the pixels in each tile: order[first[k]:first[k + 1]]
    tet = np.repeat(np.arange(n.size), n)
    k = np.arange(tet.size) - np.repeat(np.cumsum(n) - n, n)
    box_tile = (r0[tet] + k // w[tet]) * tiles_x + c0[tet] + k % w[tet]
    keep = held[box_tile] > 0
    tet, box_tile = tet[keep], box_tile[keep]
    m = held[box_tile]
    tet = np.repeat(tet, m)
    px = order[np.repeat(first[box_tile], m) + np.arange(tet.size) - np.repeat(np.cumsum(m) - m, m)]
    inside = ((geo.col_lo[tet] <= col[px]) & (col[px] <= geo.col_hi[tet])
              & (geo.row_lo[tet] <= row[px]) & (row[px] <= geo.row_hi[tet]))
    tet, px = tet[inside], px[inside]
    by = np.lexsort((tet, px))
    tet, px = tet[by], px[by]
    for start in range(0, px.size, chunk):
        some = slice(start, start + chunk)
        yield _clip_pairs(geo, rays, tet[some], row[px[some]], col[px[some]])


def _clip_pairs(geo: _TetGeometry, rays: EyeRays, tet: Int, row: Int, col: Int) -> RaySegments:
    """Clip the ray of pixel (row, col) against tet ``tet``, for each such pair."""
    x = rays.x_col[col][:, None]
    y = rays.y_row[row][:, None]
    nx, ny = geo.nx[tet], geo.ny[tet]

    # Plane function along the ray: f(t) = a + b t, inside where f <= 0. The expressions
    # are linear in n and d, so twin faces give exactly opposite (a, b) and the same t.
    if rays.parallel:
        a = nx * x + ny * y - geo.d[tet]
        b = -geo.nz[tet]
    else:
        a = -geo.d[tet]
        b = nx * x + ny * y - geo.nz[tet]
    del nx, ny, x, y
    in_plane = b == 0
    t = -a / np.where(in_plane, 1.0, b)
    enter = np.where(b < 0, t, -np.inf)
    leave = np.where(b > 0, t, np.inf)
    del t
    outside = in_plane & ((a > 0) | ((a == 0) & geo.perturb_out[tet]))
    del a, b, in_plane
    # Column by column: numpy reduces a short last axis slowly.
    t_in = np.maximum(np.maximum(enter[:, 0], enter[:, 1]), np.maximum(enter[:, 2], rays.near))
    np.maximum(t_in, enter[:, 3], out=t_in)
    t_out = np.minimum(np.minimum(leave[:, 0], leave[:, 1]), np.minimum(leave[:, 2], rays.far))
    np.minimum(t_out, leave[:, 3], out=t_out)
    if rays.lo is not None and rays.hi is not None:
        pixel = row * rays.width + col
        np.maximum(t_in, rays.lo[pixel], out=t_in)
        np.minimum(t_out, rays.hi[pixel], out=t_out)
        del pixel
    keep = (t_out > t_in) & ~(outside[:, 0] | outside[:, 1] | outside[:, 2] | outside[:, 3])
    del enter, leave, outside

    tet, row, col, t_in, t_out = tet[keep], row[keep], col[keep], t_in[keep], t_out[keep]
    x = rays.x_col[col]
    y = rays.y_row[row]
    s_in = _scalar_at(geo, tet, x, y, t_in, rays.parallel)
    s_out = _scalar_at(geo, tet, x, y, t_out, rays.parallel)
    return RaySegments(row * rays.width + col, t_in, t_out, s_in, s_out, geo.index[tet])


def _scalar_at(geo: _TetGeometry, tet: Int, x: Float, y: Float, t: Float, parallel: bool) -> Float:
    """The tet's linear scalar at ray parameter ``t``, clamped to its vertex range.

    The clamp is exact (a linear function on a tet takes its extremes at vertices) and
    stops rounding at a face from extrapolating past the vertex values.
    """
    if parallel:
        px, py = x, y
    else:
        px, py = x * t, y * t
    p0 = geo.p0[tet]
    g = geo.grad[tet]
    s = geo.s0[tet] + g[:, 0] * (px - p0[:, 0]) + g[:, 1] * (py - p0[:, 1]) + g[:, 2] * (-t - p0[:, 2])
    return np.clip(s, geo.s_min[tet], geo.s_max[tet])


def ray_lengths(camera: Camera, size: tuple[int, int]) -> Float:
    """World length of one unit of ``t`` (eye depth) along every pixel ray, row-major.

    ``1`` for a parallel camera; ``|d|`` of :meth:`Camera.rays` for a perspective one.
    """
    width, height = size
    return EyeRays.from_camera(camera, int(width), int(height)).norms()


def ray_segments(
    mesh: TetMesh, camera: Camera, size: tuple[int, int], *, chunk: int = DEFAULT_CHUNK
) -> RaySegments:
    """Every intersection of a pixel ray with a tet.

    Parameters
    ----------
    mesh : the tetrahedra and their scalar field.
    camera : the view; segments are clipped to its ``clipping_range``.
    size : ``(width, height)`` of the image in pixels.
    chunk : candidate (tet, pixel) pairs examined at once; bounds memory.

    Returns
    -------
    RaySegments
        ``pixel`` (row-major index, row 0 at the top), ``t_in`` < ``t_out`` (eye depth),
        ``scalar_in``, ``scalar_out`` (the field at the two ends) and ``tet`` (row of
        ``mesh.tets``), one entry per segment of positive length.

    Examples
    --------
    >>> mesh = TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]], [0, 1, 2, 3])
    >>> cam = Camera(position=(0.2, 0.2, 5), focal_point=(0.2, 0.2, 0), parallel_projection=True,
    ...              parallel_scale=0.1)
    >>> seg = ray_segments(mesh, cam, (1, 1))
    >>> seg.pixel.tolist(), seg.t_in.round(6).tolist(), seg.t_out.round(6).tolist()
    ([0], [4.4], [5.0])
    """
    width, height = _validate(mesh, camera, size)
    chunk = _check_chunk(chunk)
    camera = resolve_clipping_range(camera, mesh.bounds)
    rays = EyeRays.from_camera(camera, width, height)
    geo = _tet_geometry(mesh, camera, rays)
    parts = list(_iter_segments(geo, rays, chunk))
    if not parts:
        e = np.zeros(0)
        return RaySegments(np.zeros(0, np.int64), e, e.copy(), e.copy(), e.copy(), np.zeros(0, np.int64))
    return RaySegments(*(np.concatenate(cols) for cols in zip(*parts)))


def pixel_extents(mesh: TetMesh, camera: Camera, size: tuple[int, int], pixels: ArrayLike, *,
                  chunk: int = DEFAULT_CHUNK) -> tuple[Float, Float]:
    """The eye depth at which the rays of ``pixels`` (row * width + column, row 0 at the top)
    first enter the mesh and last leave it, within the clipping range: ``(front, back)``,
    each (len(pixels),), ``inf`` and ``-inf`` where a ray meets no tet. What a GPU frame of
    ray limits traces again where its walk went wrong (:mod:`tetvr.gl.selfcheck`).

    Examples
    --------
    >>> mesh = TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]], [0, 1, 2, 3])
    >>> cam = Camera(position=(0.2, 0.2, 5), focal_point=(0.2, 0.2, 0), parallel_projection=True,
    ...              parallel_scale=0.1)
    >>> front, back = pixel_extents(mesh, cam, (1, 1), [0])
    >>> front.round(6).tolist(), back.round(6).tolist()
    ([4.4], [5.0])
    """
    width, height = _validate(mesh, camera, size)
    chunk = _check_chunk(chunk)
    pixels = np.asarray(pixels, dtype=np.int64).reshape(-1)
    if pixels.size and (pixels.min() < 0 or pixels.max() >= width * height):
        raise ValueError(f"pixels must lie in the {width}x{height} image, got {int(pixels.min())}..{int(pixels.max())}")
    camera = resolve_clipping_range(camera, mesh.bounds)
    rays = EyeRays.from_camera(camera, width, height)
    unique, back_of = np.unique(pixels, return_inverse=True)
    front, back = np.full(unique.size, np.inf), np.full(unique.size, -np.inf)
    for seg in _pixel_segments(_tet_geometry(mesh, camera, rays, unique), rays, unique, chunk):
        at = np.searchsorted(unique, seg.pixel)
        np.minimum.at(front, at, seg.t_in)
        np.maximum.at(back, at, seg.t_out)
    return front[back_of], back[back_of]

"""The exact CPU reference renderer: every GPU image is measured against it.

About this technique
--------------------
Per-pixel ray casting through every tetrahedron (Garrity 1990, "Raytracing irregular
volume data"), integrated exactly in the manner of Williams, Max & Stein 1998 ("A high
accuracy volume renderer for unstructured data"):

1. Each tet gets its four face planes (outward normals, offsets) and its linear scalar
   function, all in eye space.
2. Each tet is projected to the image; the pixels whose centres fall inside its
   bounding box are its candidate rays. Tets that cross the near plane are first
   clipped to it, so their boxes stay finite.
3. Every (tet, pixel) candidate clips the ray ``o + t d`` against the four planes
   (Cyrus–Beck) and against the clipping range ``near <= t <= far``. ``t`` is eye depth,
   as in :meth:`tetvr.camera.Camera.rays`; the world length of a segment is
   ``(t_out - t_in) * |d|``.
4. The scalar is linear along a segment, so each segment is cut at the transfer
   function's breakpoints; colour and opacity are then linear on every piece, and
   :func:`tetvr.optics.integrate_pieces` integrates each piece exactly (see the error
   bound below).
5. Pieces are composited front to back per pixel: colour
   ``sum_k rgb_k exp(-sum_{j<k} theta_j)``, alpha ``1 - exp(-sum_k theta_k)``.

Everything is vectorised over (tet, pixel) pairs; tets are taken in chunks so that the
memory in use stays bounded whatever the mesh and image size.

Watertightness. A face shared by two tets is computed from its three vertices in
ascending id order in both tets, so the two planes are exact negatives of each other,
bit for bit. A ray that crosses the face therefore leaves one tet at exactly the ``t``
where it enters the other: there are no gaps and no overlaps, and no tolerance is
needed. A ray that lies *in* a shared face (it happens with axis-aligned orthographic
views of axis-aligned meshes) is given to exactly one of the two tets by a symbolic
perturbation of the ray origin along eye ``x``, then ``y``, then ``z`` (the rule that
makes rasteriser fill conventions watertight).

Error bound
-----------
Geometry is exact up to float64 rounding (``t`` to ~1e-15 of the scene size), and so
is the optical depth (closed form). The colour of a piece is a Gauss–Legendre
quadrature in :func:`tetvr.optics.integrate_pieces`, stated there to be within ~1e-7.
That holds while the opacity stays away from 1; where it ramps towards 1 the extinction
``-ln(1 - a)`` turns steep and the quadrature was measured up to 4.5e-5 off, so this
renderer also cuts every piece where ``1 - a`` has changed by a factor of 2. Measured
against graded fine quadrature, a piece is then within 1e-10 for any opacity
(``tests/test_reference.py``). Pieces are weighted by transmittances <= 1, so a pixel
is within ~1e-7 of the exact emission–absorption integral (in practice ~1e-9), before
the final rounding to float32 (relative 6e-8).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable, Iterator, NamedTuple, Sequence

import numpy as np
from numpy.typing import NDArray

from ._checks import check_instances
from .adjacency import FACE_VERTICES
from .camera import Camera
from .clip import Clip, check_clip, ray_window
from .image import check_memory, image_size
from .mesh import TetMesh
from .optics import _SUB_THETA, OPTICS, integrate_linear_pieces, integrate_pieces, piece_optical_depth, vtk_segments
from .preintegrate import check_unit_distance
from .surface import Surface, check_surfaces, surface_hits
from .transfer import TransferFunction

__all__ = [
    "DEFAULT_CHUNK",
    "RaySegments",
    "composite",
    "integrate_segments",
    "ray_lengths",
    "ray_segments",
    "render_reference",
]

#: Bytes per pixel :func:`render_reference` holds whatever the mesh: the rays' lengths
#: (float64), the composited float64 RGBA, one channel's bincount and the float32 result.
_BYTES_PER_PIXEL = 8 + 32 + 8 + 16

#: Candidate (tet, pixel) pairs examined at once: ~200 bytes of temporaries each, so
#: ~50 MB. Larger chunks are no faster (bluntfin at 256x256 on 2 cores: 2.3-3 s for
#: chunks of 2**16 to 2**18, 3.5 s at 2**20): their arrays fall out of cache.
DEFAULT_CHUNK = 1 << 18

# Pixel-centre boxes are widened by this much so that rounding in the projection never
# drops a ray that touches the tet; the exact plane test then decides.
_BOX_MARGIN_PX = 1e-6


# Sub-pieces evaluated per integrate_pieces call: bounds its (n_sub, 6) temporaries.
_SUB_BUDGET = 1 << 20

# Faces opposite vertex k, as local indices in ascending order. Tet vertices are sorted
# by id first, so a face shared by two tets is built from the same points in the same
# order in both and its plane is bit-identical up to sign.
_FACES = FACE_VERTICES

Float = NDArray[np.float64]
Int = NDArray[np.int64]


class RaySegments(NamedTuple):
    """The intersections of the pixel rays with the tets, one row per (ray, tet).

    ``t`` is eye depth along the ray of pixel ``pixel`` (row-major, row 0 at the top), as
    in :meth:`tetvr.camera.Camera.rays`; multiply a length in ``t`` by
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
class _EyeRays:
    """Pixel rays in eye space, mirroring :meth:`Camera.rays`.

    Parallel: origin ``(x[col], y[row], 0)``, direction ``(0, 0, -1)``.
    Perspective: origin ``0``, direction ``(x[col], y[row], -1)``.
    Either way the point at parameter ``t`` has eye depth ``t``.
    """

    parallel: bool
    width: int
    height: int
    x_col: Float  # (W,)
    y_row: Float  # (H,)
    kx: float  # x_eye = x_ndc * kx   (times depth for perspective)
    ky: float
    near: float
    far: float
    # Per pixel (row-major) window of eye depth, or None: the clipping range cut by clip
    # planes and surfaces (tetvr.clip, tetvr.surface).
    lo: Float | None = None
    hi: Float | None = None

    @classmethod
    def from_camera(cls, camera: Camera, width: int, height: int) -> "_EyeRays":
        aspect = width / height
        x_ndc = (2.0 * (np.arange(width) + 0.5) / width) - 1.0
        y_ndc = 1.0 - (2.0 * (np.arange(height) + 0.5) / height)
        if camera.parallel_projection:
            k = camera.parallel_scale
        else:
            k = math.tan(math.radians(camera.view_angle) / 2)
        # Same operation order as Camera.rays, so the rays agree to the last bit or so.
        x_col = x_ndc * k * aspect
        y_row = y_ndc * k
        near, far = camera.clipping_range
        return cls(camera.parallel_projection, width, height, x_col, y_row, k * aspect, k, near, far)

    def norms(self) -> Float:
        """World length of the direction of every pixel ray, row-major."""
        if self.parallel:
            return np.ones(self.width * self.height)
        x2 = self.x_col[None, :] ** 2
        y2 = self.y_row[:, None] ** 2
        return np.sqrt(x2 + y2 + 1.0).reshape(-1)


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


def _tet_geometry(mesh: TetMesh, camera: Camera, rays: _EyeRays) -> _TetGeometry:
    """Planes, scalar functions and candidate pixel boxes of the tets."""
    view = camera.view_matrix()
    pts = (mesh.points - np.asarray(camera.position)) @ view[:3, :3].T  # eye space
    ids = np.sort(mesh.tets.astype(np.int64), axis=1)
    p = pts[ids]  # (m, 4, 3)
    depth = -p[:, :, 2]

    # Cull what the clipping range removes whole, and tets of zero volume (they hold no
    # segment of positive length, and their planes are undefined).
    e1, e2, e3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    vol6 = np.einsum("ij,ij->i", np.cross(e1, e2), e3)
    visible = (depth.max(axis=1) >= rays.near) & (depth.min(axis=1) <= rays.far) & (vol6 != 0)
    index = np.nonzero(visible)[0]
    p, depth, ids = p[index], depth[index], ids[index]

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


def _pixel_boxes(p: Float, depth: Float, rays: _EyeRays) -> tuple[Int, Int, Int, Int]:
    """Inclusive column and row range of the pixel centres each tet can cover."""
    if rays.parallel:
        # Affine projection: the vertices bound the shadow.
        x_ndc = p[:, :, 0] / rays.kx
        y_ndc = p[:, :, 1] / rays.ky
        valid = np.ones(x_ndc.shape, dtype=bool)
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
        q_depth = np.where(valid, -q[:, :, 2], 1.0)
        x_ndc = q[:, :, 0] / (q_depth * rays.kx)
        y_ndc = q[:, :, 1] / (q_depth * rays.ky)
    # Pixel centre (row i, col j) sits at x_ndc = 2 (j + 0.5) / W - 1, y_ndc = 1 - 2 (i + 0.5) / H.
    col = (x_ndc + 1.0) * (0.5 * rays.width) - 0.5
    row = (1.0 - y_ndc) * (0.5 * rays.height) - 0.5
    col_min = np.where(valid, col, np.inf).min(axis=1)
    col_max = np.where(valid, col, -np.inf).max(axis=1)
    row_min = np.where(valid, row, np.inf).min(axis=1)
    row_max = np.where(valid, row, -np.inf).max(axis=1)
    # Clip in float first: boxes far outside the image must not overflow int64.
    col_lo = np.ceil(np.clip(col_min - _BOX_MARGIN_PX, -1, rays.width)).astype(np.int64)
    col_hi = np.floor(np.clip(col_max + _BOX_MARGIN_PX, -1, rays.width)).astype(np.int64)
    row_lo = np.ceil(np.clip(row_min - _BOX_MARGIN_PX, -1, rays.height)).astype(np.int64)
    row_hi = np.floor(np.clip(row_max + _BOX_MARGIN_PX, -1, rays.height)).astype(np.int64)
    return (
        np.maximum(col_lo, 0),
        np.minimum(col_hi, rays.width - 1),
        np.maximum(row_lo, 0),
        np.minimum(row_hi, rays.height - 1),
    )


def _iter_segments(geo: _TetGeometry, rays: _EyeRays, chunk: int) -> Iterator[RaySegments]:
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


def _clip_chunk(geo: _TetGeometry, rays: _EyeRays, tets: Int, counts: Int, box_w: Int) -> RaySegments:
    """Clip the rays of every candidate pixel of ``tets`` against those tets."""
    total = int(counts.sum())
    tet = np.repeat(tets, counts)
    first = np.cumsum(counts) - counts
    k = np.arange(total, dtype=np.int64) - np.repeat(first, counts)
    w = box_w[tet]
    row = geo.row_lo[tet] + k // w
    col = geo.col_lo[tet] + k % w
    del k, w
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
    return _EyeRays.from_camera(camera, int(width), int(height)).norms()


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
    rays = _EyeRays.from_camera(camera, width, height)
    geo = _tet_geometry(mesh, camera, rays)
    parts = list(_iter_segments(geo, rays, chunk))
    if not parts:
        e = np.zeros(0)
        return RaySegments(np.zeros(0, np.int64), e, e.copy(), e.copy(), e.copy(), np.zeros(0, np.int64))
    return RaySegments(*(np.concatenate(cols) for cols in zip(*parts)))


def integrate_segments(
    scalar_in: Float, scalar_out: Float, length_world: Float, tf: TransferFunction, *, optics: str = "exact"
) -> tuple[Float, Float]:
    """Integrate segments along which the scalar runs linearly.

    Each segment is cut where the scalar crosses a transfer-function breakpoint, so that
    colour and opacity are linear on every piece; the pieces are integrated exactly
    (:func:`tetvr.optics.integrate_pieces`) and composited front to back.

    Parameters
    ----------
    scalar_in, scalar_out : (n,) scalar at the front and back of each segment.
    length_world : (n,) length of each segment in world units.
    tf : the transfer function.
    optics : "exact" (``tau = -ln(1 - a)/u``), "linear" (``tau = a/u``, integrated exactly)
        or "vtk" (VTK's projected-tetrahedra segment: mean end colour, not cut at
        breakpoints); see :data:`tetvr.optics.OPTICS` and docs/paraview.md.

    Returns
    -------
    rgb : (n, 3) premultiplied colour of each segment, as seen from its front.
    theta : (n,) optical depth of each segment.

    Examples
    --------
    >>> tf = TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)), opacity=((0, 0.5), (1, 0.5)))
    >>> rgb, theta = integrate_segments(np.array([0.0]), np.array([1.0]), np.array([1.0]), tf)
    >>> float(1 - np.exp(-theta[0]))  # a slab of one unit distance has the TF opacity
    0.5
    """
    s_in = np.asarray(scalar_in, dtype=np.float64).reshape(-1)
    s_out = np.asarray(scalar_out, dtype=np.float64).reshape(-1)
    length = np.asarray(length_world, dtype=np.float64).reshape(-1)
    if not s_in.shape == s_out.shape == length.shape:
        raise ValueError(
            f"scalar_in, scalar_out and length_world must have the same length, got "
            f"{s_in.shape[0]}, {s_out.shape[0]}, {length.shape[0]}"
        )
    n = s_in.shape[0]
    if optics not in OPTICS:
        raise ValueError(f"optics must be one of {OPTICS}, got {optics!r}")
    if optics == "vtk":  # one formula per segment, from its two ends only
        c_in, o_in = tf.evaluate(s_in)
        c_out, o_out = tf.evaluate(s_out)
        return vtk_segments(c_in, c_out, o_in, o_out, length, tf.unit_distance)
    seg, s_a, s_b, piece_len = _split_at_breakpoints(s_in, s_out, length, tf.breakpoints)
    c_a, o_a = tf.evaluate(s_a)
    c_b, o_b = tf.evaluate(s_b)
    rgb, theta = _integrate_batched(c_a, c_b, o_a, o_b, piece_len, tf.unit_distance,
                                    integrate_linear_pieces if optics == "linear" else integrate_pieces)
    # Pieces are in ray order inside each segment, segments contiguous.
    excl = _exclusive_group_cumsum(theta, seg)
    w = np.exp(-excl)
    seg_rgb = np.empty((n, 3))
    for c in range(3):
        seg_rgb[:, c] = np.bincount(seg, weights=rgb[:, c] * w, minlength=n)
    seg_theta = np.bincount(seg, weights=theta, minlength=n).astype(np.float64, copy=False)
    return seg_rgb, seg_theta


def _split_at_breakpoints(
    s_in: Float, s_out: Float, length: Float, bp: Float
) -> tuple[Int, Float, Float, Float]:
    """Cut segments at the breakpoints strictly between their end scalars.

    Returns, per piece in ray order: segment index, scalar at its front and back, and
    world length.
    """
    n = s_in.shape[0]
    lo = np.minimum(s_in, s_out)
    hi = np.maximum(s_in, s_out)
    first = np.searchsorted(bp, lo, side="right")  # first breakpoint > lo
    last = np.searchsorted(bp, hi, side="left")  # first breakpoint >= hi
    n_inner = np.maximum(last - first, 0)
    n_piece = n_inner + 1
    seg = np.repeat(np.arange(n, dtype=np.int64), n_piece)
    k = np.arange(seg.shape[0], dtype=np.int64) - np.repeat(np.cumsum(n_piece) - n_piece, n_piece)
    s0, s1, inner = s_in[seg], s_out[seg], n_inner[seg]
    rising = s1 >= s0

    def breakpoint_(j: Int) -> Float:
        # The j-th breakpoint met along the ray (indices only used where 0 <= j < inner).
        idx = np.where(rising, first[seg] + j, last[seg] - 1 - j)
        return bp[np.clip(idx, 0, bp.shape[0] - 1)]

    head, tail = k == 0, k == inner
    s_a = np.where(head, s0, breakpoint_(k - 1))
    s_b = np.where(tail, s1, breakpoint_(k))
    # Fractions along the segment; a segment that is not cut keeps its exact length.
    ds = np.where(s1 == s0, 1.0, s1 - s0)
    f_a = np.where(head, 0.0, np.clip((s_a - s0) / ds, 0.0, 1.0))
    f_b = np.where(tail, 1.0, np.clip((s_b - s0) / ds, 0.0, 1.0))
    return seg, s_a, s_b, (f_b - f_a) * length[seg]


def _integrate_batched(
    c0: Float, c1: Float, a0: Float, a1: Float, length: Float, u: float,
    integrate: Callable[..., tuple[Float, Float]] = integrate_pieces,
) -> tuple[Float, Float]:
    """integrate_pieces in batches that bound its sub-piece temporaries.

    Thin pieces (one sub-piece) go in batches of their own: integrate_pieces then skips
    its bisection search, which is the costly part. Results are per piece, unaffected
    by the batching.
    """
    n = length.shape[0]
    rgb = np.zeros((n, 3))
    theta = np.zeros(n)
    est = piece_optical_depth(a0, a1, length, u)
    # As integrate_pieces counts them (past optical depth 40 it drops the rest).
    n_sub = np.clip(np.ceil(np.minimum(est, 40.0) / _SUB_THETA), 1, None)
    for group in (np.nonzero(est <= _SUB_THETA)[0], np.nonzero(est > _SUB_THETA)[0]):
        ends = np.cumsum(n_sub[group])
        start = 0
        while start < group.shape[0]:
            base = ends[start - 1] if start else 0.0
            stop = max(int(np.searchsorted(ends, base + _SUB_BUDGET, side="right")), start + 1)
            idx = group[start:stop]
            rgb[idx], theta[idx] = integrate(c0[idx], c1[idx], a0[idx], a1[idx], length[idx], u)
            start = stop
    return rgb, theta


def _exclusive_group_cumsum(values: Float, group: Int) -> Float:
    """Sum of the earlier values of the same group, for sorted (contiguous) groups.

    The running sum is reset at each group start rather than taken globally and
    differenced, so its rounding error scales with one group's total, not the image's;
    what rounding leaves at a group start is then removed, so each group starts at 0.
    """
    x = values.copy()
    if x.shape[0] == 0:
        return x
    is_start = np.r_[True, group[1:] != group[:-1]]
    starts = np.nonzero(is_start)[0]
    totals = np.add.reduceat(values, starts)
    x[starts[1:]] -= totals[:-1]
    run = np.cumsum(x) - values
    return run - run[starts][np.cumsum(is_start) - 1]


def composite(pixel: Int, t_in: Float, rgb: Float, theta: Float, n_pixels: int) -> Float:
    """Composite segments front to back into pixels.

    Parameters
    ----------
    pixel : (n,) pixel of each segment.
    t_in : (n,) depth of its front; segments of a pixel are composited in this order.
    rgb : (n, 3) premultiplied colour of each segment, as seen from its front.
    theta : (n,) optical depth of each segment.
    n_pixels : number of pixels.

    Returns
    -------
    (n_pixels, 4) float64 premultiplied RGBA; pixels without segments are 0.

    Examples
    --------
    >>> composite(np.array([0, 0]), np.array([2.0, 1.0]), np.array([[0.0, 0, 0], [0.5, 0, 0]]),
    ...           np.array([0.0, np.log(2)]), 1).round(6).tolist()
    [[0.5, 0.0, 0.0, 0.5]]
    """
    pixel = np.asarray(pixel, dtype=np.int64)
    order = np.lexsort((t_in, pixel))
    pixel, rgb, theta = pixel[order], rgb[order], theta[order]
    w = np.exp(-_exclusive_group_cumsum(theta, pixel))
    out = np.empty((n_pixels, 4))
    for c in range(3):
        out[:, c] = np.bincount(pixel, weights=rgb[:, c] * w, minlength=n_pixels)
    out[:, 3] = -np.expm1(-np.bincount(pixel, weights=theta, minlength=n_pixels))
    return out


def _check_chunk(chunk: int) -> int:
    if isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1:
        raise ValueError(f"chunk must be a positive integer, got {chunk!r}")
    return int(chunk)


def render_reference(
    mesh: TetMesh,
    camera: Camera,
    tf: TransferFunction,
    size: tuple[int, int],
    *,
    chunk: int = DEFAULT_CHUNK,
    progress: bool = False,
    optics: str = "exact",
    clip: Clip | None = None,
    surfaces: Surface | Sequence[Surface] = (),
) -> NDArray[np.float32]:
    """Render the mesh exactly on the CPU.

    Parameters
    ----------
    mesh : the tetrahedra and their scalar field.
    camera : the view; the volume is clipped to its ``clipping_range``.
    tf : transfer function mapping the scalar to colour and opacity.
    size : ``(width, height)`` of the image in pixels.
    chunk : candidate (tet, pixel) pairs processed at once; their temporaries take
        ~200 bytes each (~50 MB at the default). Each segment found also keeps ~50 bytes
        until compositing (bluntfin, 187k tets at 256x256: 1.6M segments, 80 MB).
    progress : show a progress bar over the chunks (needs tqdm).
    optics : the opacity convention, as ``RenderSettings.optics``: "exact" (default),
        "linear" (``tau = a/u``) or "vtk" (VTK's projected-tetrahedra segment formula,
        on exact geometry); see :func:`integrate_segments`.
    clip : keep only this part of the mesh (:class:`tetvr.Clip`): every segment is cut to
        the part of its ray the clip keeps.
    surfaces : opaque surfaces (:class:`tetvr.Surface`): every ray ends at its nearest
        hit (:func:`tetvr.surface.surface_hits`), whose shaded colour is composited behind.

    Returns
    -------
    (height, width, 4) float32 premultiplied RGBA, row 0 at the top: ``rgb`` is the
    emitted colour reaching the eye and ``a = 1 - transmittance``. Pixel ``(i, j)``
    samples the ray through its centre.

    Examples
    --------
    >>> mesh = TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]], [0, 0, 0, 0])
    >>> tf = TransferFunction(color=((0, 1, 0, 0), (1, 1, 0, 0)), opacity=((0, 0.5), (1, 0.5)), unit_distance=0.6)
    >>> cam = Camera(position=(0.2, 0.2, 5), focal_point=(0.2, 0.2, 0), parallel_projection=True,
    ...              parallel_scale=0.1)
    >>> render_reference(mesh, cam, tf, (1, 1))[0, 0].round(6).tolist()  # chord 0.6 = u
    [0.5, 0.0, 0.0, 0.5]
    """
    width, height = _validate(mesh, camera, size)
    chunk = _check_chunk(chunk)
    if not isinstance(tf, TransferFunction):
        raise TypeError(f"tf must be a TransferFunction, got {type(tf).__name__}")
    if optics not in OPTICS:
        raise ValueError(f"optics must be one of {OPTICS}, got {optics!r}")
    check_unit_distance(tf.unit_distance, "the transfer function's unit_distance")
    # Up front, not at the first allocation: a 100000 x 100000 image needs 600 GiB.
    check_memory(width * height * _BYTES_PER_PIXEL, f"a {width}x{height} reference image")
    clip, surfaces = check_clip(clip), check_surfaces(surfaces)
    rays = _EyeRays.from_camera(camera, width, height)
    hit_t = hit_rgb = None
    if clip is not None or surfaces:
        if clip is not None:
            lo, hi = ray_window(clip.eye_planes(camera), rays.x_col[None, :], rays.y_row[:, None],
                                parallel=rays.parallel, near=rays.near, far=rays.far)
        else:
            lo, hi = np.full((height, width), rays.near), np.full((height, width), rays.far)
        if surfaces:
            hit_t, hit_rgb = surface_hits(surfaces, camera, (width, height))
            hi = np.minimum(hi, hit_t)
        rays = dataclasses.replace(rays, lo=lo.reshape(-1), hi=hi.reshape(-1))
    norms = rays.norms()
    geo = _tet_geometry(mesh, camera, rays)

    chunks: Iterator[RaySegments] = _iter_segments(geo, rays, chunk)
    if progress:
        from tqdm import tqdm  # deferred: only needed for interactive use

        n_pairs = int(((geo.col_hi - geo.col_lo + 1) * (geo.row_hi - geo.row_lo + 1)).sum())
        chunks = tqdm(chunks, total=max(1, -(-n_pairs // chunk)), desc="reference", unit="chunk")

    # Integrate per chunk and keep one row per segment: the pieces never all live at once.
    pixels, fronts, colours, depths = [], [], [], []
    for seg in chunks:
        length = (seg.t_out - seg.t_in) * norms[seg.pixel]
        rgb, theta = integrate_segments(seg.scalar_in, seg.scalar_out, length, tf, optics=optics)
        pixels.append(seg.pixel)
        fronts.append(seg.t_in)
        colours.append(rgb)
        depths.append(theta)
    n_pixels = width * height
    if not pixels:
        image = np.zeros((height, width, 4))
    else:
        image = composite(np.concatenate(pixels), np.concatenate(fronts), np.concatenate(colours),
                          np.concatenate(depths), n_pixels).reshape(height, width, 4)
    if hit_t is not None and hit_rgb is not None:
        hit = np.isfinite(hit_t)
        behind = np.concatenate([hit_rgb, hit[..., None].astype(np.float64)], axis=-1)
        image = image + (1.0 - image[..., 3:4]) * behind  # the tets over the surfaces
    return image.astype(np.float32)

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
   as in :meth:`tetvr.core.camera.Camera.rays`; the world length of a segment is
   ``(t_out - t_in) * |d|``.
4. The scalar is linear along a segment, so each segment is cut at the transfer
   function's breakpoints; colour and opacity are then linear on every piece, and
   :func:`tetvr.optics.model.integrate_pieces` integrates each piece exactly (see the error
   bound below).
5. Pieces are composited front to back per pixel: colour
   ``sum_k rgb_k exp(-sum_{j<k} theta_j)``, alpha ``1 - exp(-sum_k theta_k)``.

Steps 1-3 are :mod:`tetvr.reference.segments` (where it also says why the geometry is
watertight without a tolerance), steps 4-5 :mod:`tetvr.reference.integrate`; this module
runs them. Everything is vectorised over (tet, pixel) pairs; tets are taken in chunks so
that the memory in use stays bounded whatever the mesh and image size.

Error bound
-----------
Geometry is exact up to float64 rounding (``t`` to ~1e-15 of the scene size), and so
is the optical depth (closed form). The colour of a piece is a Gauss–Legendre
quadrature in :func:`tetvr.optics.model.integrate_pieces`, stated there to be within ~1e-7.
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
from typing import Iterator, Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera, resolve_clipping_range, union_bounds
from tetvr.core.clip import Clip, check_clip, ray_window
from tetvr.core.image import check_memory
from tetvr.core.rays import EyeRays
from tetvr.core.surface import Surface, check_surfaces, surface_hits
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.model import OPTICS
from tetvr.optics.table import check_unit_distance
from tetvr.optics.transfer import TransferFunction
from tetvr.reference.integrate import composite, integrate_segments
from tetvr.reference.segments import (DEFAULT_CHUNK, RaySegments, _check_chunk, _iter_segments, _pixel_segments,
                                      _tet_geometry, _TetGeometry, _validate)

__all__ = ["render_reference", "render_reference_pixels"]

#: Bytes per pixel :func:`render_reference` holds whatever the mesh: the rays' lengths
#: (float64), the composited float64 RGBA, one channel's bincount and the float32 result.
_BYTES_PER_PIXEL = 8 + 32 + 8 + 16

Float = NDArray[np.float64]


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
        hit (:func:`tetvr.core.surface.surface_hits`), whose shaded colour is composited behind.

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
    # No clipping range given: the one VTK would compute from everything this frame draws.
    camera = resolve_clipping_range(camera, union_bounds(mesh.bounds, *(s.points for s in surfaces)))
    rays, hit_t, hit_rgb = _window(EyeRays.from_camera(camera, width, height), camera, clip, surfaces)
    image = _integrated_image(_tet_geometry(mesh, camera, rays), rays, tf, chunk=chunk, progress=progress,
                              optics=optics)
    if hit_t is not None and hit_rgb is not None:
        hit = np.isfinite(hit_t)
        behind = np.concatenate([hit_rgb, hit[..., None].astype(np.float64)], axis=-1)
        image = image + (1.0 - image[..., 3:4]) * behind  # the tets over the surfaces
    return image.astype(np.float32)


def render_reference_pixels(
    mesh: TetMesh,
    camera: Camera,
    tf: TransferFunction,
    size: tuple[int, int],
    pixels: NDArray[np.integer],
    *,
    chunk: int = DEFAULT_CHUNK,
    optics: str = "exact",
    clip: Clip | None = None,
    surfaces: Surface | Sequence[Surface] = (),
) -> NDArray[np.float32]:
    """The pixels ``pixels`` (row * width + column, row 0 at the top) of
    :func:`render_reference`'s image, exactly as it renders them: (len(pixels), 4)
    float32 premultiplied RGBA. What a GPU frame that checks itself traces again where its
    walk went wrong (:mod:`tetvr.gl.selfcheck`); its cost is one pass over the tets to find
    those whose boxes may hold the pixels, then one over theirs per pixel.

    Examples
    --------
    >>> mesh = TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]], [0, 0, 0, 0])
    >>> tf = TransferFunction(color=((0, 1, 0, 0), (1, 1, 0, 0)), opacity=((0, 0.5), (1, 0.5)), unit_distance=0.6)
    >>> cam = Camera(position=(0.2, 0.2, 5), focal_point=(0.2, 0.2, 0), parallel_projection=True, parallel_scale=0.5)
    >>> full = render_reference(mesh, cam, tf, (8, 8))
    >>> some = render_reference_pixels(mesh, cam, tf, (8, 8), [0, 27, 36])
    >>> bool(np.array_equal(some, full.reshape(-1, 4)[[0, 27, 36]]))
    True
    """
    width, height = _validate(mesh, camera, size)
    chunk = _check_chunk(chunk)
    pixels = np.asarray(pixels, dtype=np.int64).reshape(-1)
    if pixels.size and (pixels.min() < 0 or pixels.max() >= width * height):
        raise ValueError(f"pixels must lie in the {width}x{height} image, got {int(pixels.min())}..{int(pixels.max())}")
    clip, surfaces = check_clip(clip), check_surfaces(surfaces)
    camera = resolve_clipping_range(camera, union_bounds(mesh.bounds, *(s.points for s in surfaces)))
    rays, hit_t, hit_rgb = _window(EyeRays.from_camera(camera, width, height), camera, clip, surfaces)
    unique, back = np.unique(pixels, return_inverse=True)
    norms = rays.norms()
    parts = []
    for seg in _pixel_segments(_tet_geometry(mesh, camera, rays, unique), rays, unique, chunk):
        rgb, theta = integrate_segments(seg.scalar_in, seg.scalar_out, (seg.t_out - seg.t_in) * norms[seg.pixel], tf,
                                        optics=optics)
        parts.append((np.searchsorted(unique, seg.pixel), seg.t_in, rgb, theta))
    out = np.zeros((unique.size, 4))
    if parts:
        out = composite(*(np.concatenate(cols) for cols in zip(*parts)), unique.size).reshape(-1, 4)
    if hit_t is not None and hit_rgb is not None:
        hit = np.isfinite(hit_t.reshape(-1)[unique])
        behind = np.concatenate([hit_rgb.reshape(-1, 3)[unique], hit[:, None].astype(np.float64)], axis=-1)
        out = out + (1.0 - out[:, 3:4]) * behind
    return out[back].astype(np.float32)


def _window(rays: EyeRays, camera: Camera, clip: Clip | None,
            surfaces: tuple[Surface, ...]) -> tuple[EyeRays, Float | None, Float | None]:
    """``rays`` cut to the part of each ray ``clip`` keeps and ended at its nearest surface
    hit, with the hits' depth and shaded colour, (height, width) and (height, width, 3)
    (None without surfaces)."""
    width, height = rays.width, rays.height
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
    return rays, hit_t, hit_rgb


def _integrated_image(geo: _TetGeometry, rays: EyeRays, tf: TransferFunction, *, chunk: int, progress: bool,
                      optics: str) -> Float:
    """The (height, width, 4) float64 composite of every segment of the rays through the tets."""
    width, height = rays.width, rays.height
    norms = rays.norms()
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
        return np.zeros((height, width, 4))
    return composite(np.concatenate(pixels), np.concatenate(fronts), np.concatenate(colours),
                     np.concatenate(depths), n_pixels).reshape(height, width, 4)

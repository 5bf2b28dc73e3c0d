"""Fusion of a tetrahedral mesh with a ray-cast image volume through per-pixel ray limits.

About this technique
--------------------
The mesh pass yields, per pixel, its premultiplied image and the eye depths of its
nearest entry and farthest exit (:meth:`tetvr.gl.Renderer.depth_extent`). The volume's
rays are then cut at those depths (the Holeček thesis's "depth-buffer ray limits"; Ligas
2009's ray textures generalise them), and the pieces are composited with "over", front
to back. Both use one optical model (:mod:`tetvr.optics.model`), so where they meet, the result
is what one ray through both media would give.

Modes (``FUSION_MODES``):

``interleave`` (default)
    volume from the near plane to the mesh's front, then the mesh, then the volume from
    the mesh's back to the far end. Physically ordered where the mesh is convex along each
    ray. *Where the two overlap* (inside the mesh's depth span) only the mesh is shown:
    the simulation result replaces the image data it was computed from. Gaps inside a
    non-convex mesh's span (between its entry and exit) show no volume either.
``overlay``
    the mesh is never hidden: the volume only behind the mesh's far surface, full volume
    where there is no mesh (the Holeček thesis's style).
``cutaway``
    the volume is removed in front of the mesh's far surface within a screen-space margin
    around the mesh, as if cut away to show it, and kept elsewhere.
``ray_textures``
    user images: per pixel a start and an end fraction of the ray's path through the
    volume box, and a volume render mode (Ligas 2009); the mesh is composited by depth as
    in ``interleave``.

Everything here is numpy on images: the same code composites the GPU images
(:func:`fuse`) and the CPU reference images (:func:`fuse_reference`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.camera import Camera, resolve_clipping_range, union_bounds
from tetvr.mesh.tetmesh import TetMesh
from tetvr.reference.volume import RaycastSettings, render_volume_reference, volume_ray_intervals
from tetvr.optics.transfer import TransferFunction

__all__ = ["FUSION_MODES", "fuse", "fuse_reference", "over", "RayTextures"]

FUSION_MODES = ("interleave", "overlay", "cutaway", "ray_textures")

Image = NDArray[np.float32]
# (t_start, t_end, mode or None) -> premultiplied volume image; None limits = unlimited.
VolumeRender = Callable[[NDArray[np.float32] | None, NDArray[np.float32] | None, "str | None"], Image]


def over(front: ArrayLike, back: ArrayLike) -> Image:
    """Premultiplied "over": ``front + (1 - front.alpha) * back``."""
    f = np.asarray(front, dtype=np.float32)
    b = np.asarray(back, dtype=np.float32)
    return (f + (1.0 - f[..., 3:4]) * b).astype(np.float32)


class RayTextures:
    """Per-pixel ray limits and modes for the ``ray_textures`` fusion mode (Ligas 2009).

    Parameters
    ----------
    start, end : (H, W) fractions in [0, 1] of each ray's path through the volume's box
        (0 = where it enters, 1 = where it leaves); the volume is integrated in between.
    mode : optional (H, W) integer image indexing ``modes``: the volume render mode of
        each pixel (e.g. emission–absorption in one region, MIP in another).
    modes : the mode names ``mode`` indexes (see :mod:`tetvr.reference.volume`).
    """

    def __init__(self, start: ArrayLike, end: ArrayLike, mode: ArrayLike | None = None,
                 modes: tuple[str, ...] = ("emission_absorption",)) -> None:
        self.start = np.array(start, dtype=np.float64)
        self.end = np.array(end, dtype=np.float64)
        if self.start.shape != self.end.shape or self.start.ndim != 2:
            raise ValueError(f"start and end must be (H, W) images of one shape, got {self.start.shape} and {self.end.shape}")
        for name, v in (("start", self.start), ("end", self.end)):
            if not np.all(np.isfinite(v)) or v.min() < 0 or v.max() > 1:
                raise ValueError(f"ray texture {name} must hold fractions in [0, 1], got {np.nanmin(v)} .. {np.nanmax(v)}")
        self.mode = None if mode is None else np.asarray(mode)
        if self.mode is not None:
            if self.mode.shape != self.start.shape or self.mode.dtype.kind not in "iu":
                raise ValueError(f"mode must be an integer (H, W) image like start, got {self.mode.shape} {self.mode.dtype}")
            if self.mode.min() < 0 or self.mode.max() >= len(modes):
                raise ValueError(f"mode indexes {len(modes)} modes {modes}, got values {self.mode.min()} .. {self.mode.max()}")
        self.modes = tuple(modes)

    @property
    def size(self) -> tuple[int, int]:
        return int(self.start.shape[1]), int(self.start.shape[0])


def _dilate_max(a: NDArray[np.float64], radius: int) -> NDArray[np.float64]:
    """Maximum over a (2r+1)^2 square neighbourhood (separable; -inf outside the image).

    Each axis takes a sliding-window maximum by doubling (van Herk's idea without the
    blocks): O(log r) passes, and a radius beyond the image is the same as one across it,
    so ``margin=10**6`` costs what ``margin=max(h, w)`` does (it once took minutes).
    """
    out = a
    for axis in (0, 1):
        out = _window_max(out, radius, axis)
    return out if out is not a else a.copy()


def _window_max(a: NDArray[np.float64], radius: int, axis: int) -> NDArray[np.float64]:
    n = a.shape[axis]
    r = min(radius, n - 1)
    if r <= 0:
        return a
    m = np.moveaxis(a, axis, 0)
    pad = np.full((r,) + m.shape[1:], -np.inf)
    m = np.concatenate([pad, m, pad])
    width, span = 2 * r + 1, 1
    while 2 * span <= width:  # m[i] = max over [i, i + 2 span)
        m = np.maximum(m[:-span], m[span:])
        span *= 2
    # Two windows of length span cover [i, i + width) exactly (span <= width < 2 span).
    out = np.maximum(m[:n], m[width - span:width - span + n])
    return np.moveaxis(out, 0, axis)


def compose(
    mode: str,
    mesh_image: Image,
    front: NDArray[np.float32],
    back: NDArray[np.float32],
    render_volume: VolumeRender,
    *,
    margin: int = 8,
    ray_textures: RayTextures | None = None,
    volume_path: Callable[[], tuple[NDArray[np.float64], NDArray[np.float64]]] | None = None,
) -> Image:
    """Fuse one mesh image with volume renders cut at its depths (backend independent).

    ``front``/``back`` are the mesh's per-pixel depth extents (+inf/-inf where it is
    absent); ``render_volume(t_start, t_end, mode)`` renders the volume within those
    per-pixel eye-depth limits; ``volume_path()`` gives each pixel's entry and exit depth
    through the volume's box (needed by ``ray_textures`` only).
    """
    if mode not in FUSION_MODES:
        raise ValueError(f"fusion mode must be one of {FUSION_MODES}, got {mode!r}")
    has_mesh = np.isfinite(front)
    nan = np.float32(np.nan)
    if mode == "interleave":
        before = render_volume(None, np.where(has_mesh, front, nan).astype(np.float32), None)
        behind = render_volume(np.where(has_mesh, back, nan).astype(np.float32), None, None)
        behind[~has_mesh] = 0.0  # there the first render already covers the whole ray
        return over(before, over(mesh_image, behind))
    if mode == "overlay":
        behind = render_volume(np.where(has_mesh, back, nan).astype(np.float32), None, None)
        return over(mesh_image, behind)
    if mode == "cutaway":
        if not (isinstance(margin, int) and margin >= 0):
            raise ValueError(f"margin must be a non-negative number of pixels, got {margin!r}")
        cut = _dilate_max(np.where(has_mesh, back, -np.inf).astype(np.float64), margin)
        behind = render_volume(np.where(np.isfinite(cut), cut, np.nan).astype(np.float32), None, None)
        return over(mesh_image, behind)
    # ray_textures
    if ray_textures is None or volume_path is None:
        raise ValueError("the ray_textures mode needs ray_textures=RayTextures(start, end[, mode])")
    entry, exit_ = volume_path()
    span = np.where(np.isfinite(entry) & np.isfinite(exit_), exit_ - entry, 0.0)
    t0 = np.where(np.isfinite(entry), entry + ray_textures.start * span, np.nan)
    t1 = np.where(np.isfinite(entry), entry + ray_textures.end * span, np.nan)
    # The limits do not depend on the mode: cast once.
    a = np.where(has_mesh, np.minimum(t1, front), t1).astype(np.float32)
    b = np.where(has_mesh, np.maximum(t0, back), np.inf).astype(np.float32)
    t0_32, t1_32 = t0.astype(np.float32), t1.astype(np.float32)
    out = np.zeros(mesh_image.shape, dtype=np.float32)
    modes = [None] if ray_textures.mode is None else list(range(len(ray_textures.modes)))
    for m in modes:
        name = None if m is None else ray_textures.modes[m]
        where = np.ones(front.shape, bool) if m is None else ray_textures.mode == m
        if not np.any(where):
            continue
        before = render_volume(t0_32, a, name)
        behind = render_volume(b, t1_32, name)
        behind[~has_mesh] = 0.0
        # Where the window ends before the mesh starts, nothing of the volume lies behind it.
        behind[has_mesh & (t1 <= back)] = 0.0
        fused = over(before, over(mesh_image, behind))
        out[where] = fused[where]
    return out


def fuse(
    mesh: TetMesh,
    volume: Any,
    camera: Camera,
    mesh_tf: TransferFunction,
    volume_tf: TransferFunction,
    *,
    size: tuple[int, int] = (512, 512),
    mode: str = "interleave",
    margin: int = 8,
    ray_textures: RayTextures | None = None,
    renderer: Any = None,
    raycaster: Any = None,
    volume_settings: Any = None,
) -> Image:
    """Render a mesh inside an image volume on the GPU, fused by ``mode``.

    Parameters
    ----------
    mesh, mesh_tf : the tetrahedral mesh and its transfer function.
    volume, volume_tf : a :class:`tetvr.volume.volume.Volume` and its transfer function.
    camera, size : the shared view.
    mode : one of :data:`FUSION_MODES`.
    margin : the cut-away margin in pixels (``cutaway``).
    ray_textures : per-pixel limits and modes (``ray_textures``).
    renderer, raycaster : a :class:`tetvr.gl.Renderer` and a
        :class:`tetvr.gl.raycaster.Raycaster` to reuse (the raycaster should share the
        renderer's context); made and released here if not given.
    volume_settings : :class:`tetvr.reference.volume.RaycastSettings` for the volume.

    Returns
    -------
    (height, width, 4) float32 premultiplied RGBA.
    """
    from tetvr.gl.raycaster import Raycaster
    from tetvr.gl.renderer import Renderer

    _check_ray_textures(ray_textures, size)
    camera = resolve_clipping_range(camera, union_bounds(mesh.bounds, volume.bounds))  # one range for both
    own_r = renderer is None
    r = renderer or Renderer()
    own_c = raycaster is None
    c = raycaster or Raycaster(volume_settings, ctx=r.ctx)
    base = volume_settings or c.settings or RaycastSettings()
    try:
        image = r.render(mesh, camera, mesh_tf, size=size)
        front, back = r.depth_extent(mesh, camera, size=size)

        def render(t0: Any, t1: Any, s: RaycastSettings) -> Image:
            return c.render(volume, camera, volume_tf, size=size, t_start=t0, t_end=t1, settings=s)

        return _compose_with_volume(mode, image, front, back, render, base, volume, camera, size, margin=margin,
                                    ray_textures=ray_textures)
    finally:
        if own_c:
            c.release()
        if own_r:
            r.release()


def fuse_reference(
    mesh: TetMesh,
    volume: Any,
    camera: Camera,
    mesh_tf: TransferFunction,
    volume_tf: TransferFunction,
    *,
    size: tuple[int, int] = (512, 512),
    mode: str = "interleave",
    margin: int = 8,
    ray_textures: RayTextures | None = None,
    volume_settings: Any = None,
    mesh_extent: tuple[NDArray[np.float32], NDArray[np.float32]] | None = None,
) -> Image:
    """The CPU reference of :func:`fuse`: the exact mesh image and the fine-step volume
    march, composited by the same rules. ``mesh_extent`` defaults to the exact depth
    extents from :func:`tetvr.reference.segments.ray_segments`."""
    from tetvr.reference.tets import render_reference
    from tetvr.reference.segments import ray_segments

    _check_ray_textures(ray_textures, size)
    camera = resolve_clipping_range(camera, union_bounds(mesh.bounds, volume.bounds))  # one range for both
    image = render_reference(mesh, camera, mesh_tf, size)
    if mesh_extent is None:
        seg = ray_segments(mesh, camera, size)
        front = np.full(size[0] * size[1], np.inf)
        back = np.full(size[0] * size[1], -np.inf)
        np.minimum.at(front, seg.pixel, seg.t_in)
        np.maximum.at(back, seg.pixel, seg.t_out)
        mesh_extent = (front.reshape(size[1], size[0]).astype(np.float32),
                       back.reshape(size[1], size[0]).astype(np.float32))

    def render(t0: Any, t1: Any, s: RaycastSettings) -> Image:
        return render_volume_reference(volume, camera, volume_tf, size, settings=s, t_start=t0, t_end=t1)

    return _compose_with_volume(mode, image, mesh_extent[0], mesh_extent[1], render,
                                volume_settings or RaycastSettings(), volume, camera, size, margin=margin,
                                ray_textures=ray_textures)


def _check_ray_textures(ray_textures: RayTextures | None, size: tuple[int, int]) -> None:
    if ray_textures is not None and ray_textures.size != tuple(size):
        raise ValueError(f"ray textures are {ray_textures.size} pixels but the image is {tuple(size)}")


def _compose_with_volume(
    mode: str,
    image: Image,
    front: NDArray[np.float32],
    back: NDArray[np.float32],
    render: Callable[[Any, Any, RaycastSettings], Image],
    base: RaycastSettings,
    volume: Any,
    camera: Camera,
    size: tuple[int, int],
    *,
    margin: int,
    ray_textures: RayTextures | None,
) -> Image:
    """:func:`compose` with a backend's volume renderer ``render(t_start, t_end, settings)``:
    a ray-texture mode replaces the mode of the base ``settings``."""

    def render_volume(t0: Any, t1: Any, m: str | None) -> Image:
        # RaycastSettings checks the mode name.
        return render(t0, t1, base if m is None else dataclasses.replace(base, mode=m))  # type: ignore[arg-type]

    def path() -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        return _path_images(volume_ray_intervals(volume, camera, size), size)

    return compose(mode, image, front, back, render_volume, margin=margin, ray_textures=ray_textures,
                   volume_path=path)


def _path_images(iv: Any, size: tuple[int, int]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Entry and exit eye depth of every pixel's ray through the volume box (NaN: missed)."""
    t0 = np.asarray(iv.t0, dtype=np.float64)
    t1 = np.asarray(iv.t1, dtype=np.float64)
    hit = t1 > t0
    return (np.where(hit, t0, np.nan).reshape(size[1], size[0]), np.where(hit, t1, np.nan).reshape(size[1], size[0]))

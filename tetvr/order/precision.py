"""Whether float32 on the GPU can resolve a view: decided per frame from the precision the
view needs, not from the mesh's extent alone.

Both GPU methods hold coordinates relative to the mesh's bounding-box centre and work in
float32 in the view's frame: a coordinate of magnitude ``M`` (the farthest point from the
centre, or the eye's distance from it, whichever is larger) is resolved to ``M * 2**-23``.
The view needs its geometry resolved well below a pixel's footprint at the nearest part of
the mesh (the width one pixel covers there). Where float32 cannot do that -- a small cell
far from the centre seen up close, a telephoto view from far away, a parallel scale of
1e-10 -- the picture would come out wrong without any error (6-38 dB against the
reference), so :func:`check_view_precision` refuses it and says what to change.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.transfer import TransferFunction

__all__ = ["check_view_precision", "check_float32_range", "float32_clipping_range", "FLOAT32_CLIP_LIMIT", "MIN_FOOTPRINT_ULPS", "GPU_EXTENT_RANGE",
           "GPU_SCALAR_LIMIT", "GPU_MIN_RELATIVE_RANGE", "GPU_MIN_SPAN"]

#: The pixel footprint must span at least this many float32 steps of the coordinates:
#: 8 keeps every vertex within 1/16 px of where it belongs.
MIN_FOOTPRINT_ULPS = 8.0
_EPS32 = 2.0**-23


def check_view_precision(mesh: TetMesh, camera: Camera, size: tuple[int, int]) -> None:
    """Raise ``ValueError`` if float32 cannot place this mesh's points finer than 1/8 of a
    pixel in this view (see the module docstring).

    Examples
    --------
    >>> from tetvr import Camera
    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.cube(2)
    >>> check_view_precision(mesh, Camera.fit(mesh), (256, 256))   # fine: returns None
    >>> import dataclasses
    >>> tiny = dataclasses.replace(Camera.fit(mesh, parallel=True), parallel_scale=1e-9)
    >>> check_view_precision(mesh, tiny, (256, 256))
    Traceback (most recent call last):
    ...
    ValueError: float32 on the GPU cannot resolve this view: ...
    """
    centre = mesh.bounds.mean(axis=0)
    radius = float(np.abs(mesh.bounds - centre).max())
    eye = np.asarray(camera.position, dtype=np.float64)
    magnitude = max(radius, float(np.abs(eye - centre).max()))
    near, far = resolve_clipping_range(camera, mesh.bounds).near_far()
    ulp = magnitude * _EPS32
    if camera.parallel_projection:
        footprint = 2.0 * camera.parallel_scale / size[1]
    else:
        per_depth = 2.0 * np.tan(np.radians(camera.view_angle) / 2.0) / size[1]
        # The nearest depth at which the mesh can be: its bounding sphere, not before near;
        # only where that bound is too coarse, the nearest point in view.
        direction = np.asarray(camera.direction)
        depth = float((centre - eye) @ direction) - float(np.linalg.norm(mesh.bounds[1] - centre))
        footprint = min(max(depth, near), far) * per_depth
        if footprint < MIN_FOOTPRINT_ULPS * ulp:
            # The nearest point in (twice) the view's frustum; none there: the near plane.
            view = camera.view_matrix()
            p_eye = mesh.points @ view[:3, :3].T + view[:3, 3]
            depth_pts = -p_eye[:, 2]
            half = np.tan(np.radians(camera.view_angle) / 2.0) * 2.0
            inside = ((depth_pts > near) & (np.abs(p_eye[:, 1]) <= half * depth_pts)
                      & (np.abs(p_eye[:, 0]) <= half * depth_pts * size[0] / size[1]))
            nearest = float(depth_pts[inside].min()) if inside.any() else near
            footprint = min(max(nearest, near), far) * per_depth
    if footprint < MIN_FOOTPRINT_ULPS * ulp:
        raise ValueError(
            f"float32 on the GPU cannot resolve this view: a pixel covers {footprint:.3g} at the mesh, but "
            f"coordinates of magnitude {magnitude:.3g} (the farthest of the mesh's points and the eye from the "
            f"mesh's centre) are resolved only to {ulp:.3g}; zoom out, move the eye closer, drop points far "
            "from the cells you look at (tetvr.order.cull.submesh), or use method='reference'")


# The GPU computes in float32 (points relative to the mesh centre, squared lengths in the
# classification). Measured on one tet: exact for extents 1e-15 .. 1e19, blank or wrong
# outside; these bounds keep a margin.
GPU_EXTENT_RANGE = (1e-13, 1e18)
# Scalars (of the field and the transfer function) go to the GPU as float32 too: their
# magnitude must fit, and the table's scalar range must span many float32 steps of it
# (at 1e-5 of the magnitude, one rounding step is ~1 % of the range).
GPU_SCALAR_LIMIT = 1e37
GPU_MIN_RELATIVE_RANGE = 1e-5
#: The least span of scalars and transfer function the GPU resolves: float32's smallest
#: normal number is 1.2e-38, and the table's scalar scale (bins / span) must stay finite.
GPU_MIN_SPAN = 1e-30


def check_float32_range(mesh: TetMesh, tf: TransferFunction) -> None:
    """Refuse scenes the GPU's float32 cannot resolve, rather than return a wrong picture
    (called by :meth:`tetvr.gl.Renderer.render` for every frame)."""
    extent = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    if not GPU_EXTENT_RANGE[0] <= extent <= GPU_EXTENT_RANGE[1]:
        raise ValueError(
            f"the mesh's extent ({extent:.3g}, its bounding-box diagonal) is outside "
            f"{GPU_EXTENT_RANGE[0]:g} .. {GPU_EXTENT_RANGE[1]:g}, where the GPU's float32 arithmetic is exact; "
            "rescale the mesh (with the camera and unit_distance) or use method='reference'"
        )
    biggest = max(abs(v) for v in (*mesh.scalar_range, *tf.domain))
    if biggest > GPU_SCALAR_LIMIT:
        raise ValueError(
            f"scalar values up to {biggest:.3g} (field or transfer function) are beyond the GPU's float32 "
            f"(limit {GPU_SCALAR_LIMIT:g}); rescale the field and transfer function or use method='reference'"
        )
    lo, hi = min(mesh.scalar_range[0], tf.domain[0]), max(mesh.scalar_range[1], tf.domain[1])
    if lo < hi and hi - lo < GPU_MIN_SPAN:
        raise ValueError(
            f"the scalars and transfer function span {lo!r} .. {hi!r} ({hi - lo:.3g}), below {GPU_MIN_SPAN:g}, "
            "which the GPU's float32 cannot resolve (its numbers go subnormal near 1e-38); scale the field and "
            "the transfer function (mesh.with_scalars) or use method='reference'")
    if lo < hi and hi - lo < GPU_MIN_RELATIVE_RANGE * max(abs(lo), abs(hi)):
        raise ValueError(
            f"the scalars and transfer function span {lo!r} .. {hi!r}, too narrow for their magnitude in the "
            f"GPU's float32 (below {GPU_MIN_RELATIVE_RANGE:g} of it); subtract an offset from the field and "
            "the transfer function (mesh.with_scalars) or use method='reference'"
        )


#: A clipping plane at a depth beyond this (either sign) is moved to the mesh before the GPU
#: sees it: float32 holds up to 3.4e38, and the projection multiplies depths together.
FLOAT32_CLIP_LIMIT = 1e30


def float32_clipping_range(mesh: TetMesh, camera: Camera) -> Camera:
    """``camera``, with its clipping range cut to the mesh's depth range (and a margin of a
    thousandth of it) where an end of it is beyond :data:`FLOAT32_CLIP_LIMIT`; the cut keeps
    every part of the mesh that was in the range, so no pixel changes. (A parallel camera
    with a range of (-1e308, 1.7e308) otherwise reaches the GPU as infinities.)

    Examples
    --------
    >>> import dataclasses
    >>> from tetvr.mesh import synthetic
    >>> cam = Camera(position=(0, 0, 5), focal_point=(0, 0, 0), parallel_projection=True,
    ...              clipping_range=(-1e308, 1.7e308))
    >>> [round(v, 3) for v in float32_clipping_range(synthetic.cube(2, rotate=False), cam).clipping_range]
    [4.499, 5.501]
    """
    camera = resolve_clipping_range(camera, mesh.bounds)
    near, far = camera.near_far()
    if max(abs(near), abs(far)) <= FLOAT32_CLIP_LIMIT:
        return camera
    view = camera.view_matrix()
    depth = -(mesh.points @ view[2, :3] + view[2, 3])
    lo, hi = float(depth.min()), float(depth.max())
    pad = 1e-3 * (hi - lo) + 1e-300
    new_near = max(near, lo - pad)
    new_far = min(far, hi + pad)
    if not new_near < new_far:
        return camera  # nothing of the mesh in the range: what the range says is drawn (nothing)
    return dataclasses.replace(camera, clipping_range=(new_near, new_far))

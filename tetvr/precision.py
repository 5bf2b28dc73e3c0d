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

import numpy as np

from .camera import Camera
from .mesh import TetMesh

__all__ = ["check_view_precision", "MIN_FOOTPRINT_ULPS"]

#: The pixel footprint must span at least this many float32 steps of the coordinates:
#: 8 keeps every vertex within 1/16 px of where it belongs.
MIN_FOOTPRINT_ULPS = 8.0
_EPS32 = 2.0**-23


def check_view_precision(mesh: TetMesh, camera: Camera, size: tuple[int, int]) -> None:
    """Raise ``ValueError`` if float32 cannot place this mesh's points finer than 1/8 of a
    pixel in this view (see the module docstring).

    Examples
    --------
    >>> from tetvr import Camera, synthetic
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
    near, far = camera.clipping_range
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
            "from the cells you look at (tetvr.cull.submesh), or use method='reference'")

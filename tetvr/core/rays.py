"""Every pixel's ray in eye space, the one definition the CPU renderers and the surface
intersection share (and that mirrors :meth:`tetvr.core.camera.Camera.rays`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera

__all__ = ["EyeRays"]

Float = NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class EyeRays:
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
    # planes and surfaces (tetvr.core.clip, tetvr.core.surface).
    lo: Float | None = None
    hi: Float | None = None

    @classmethod
    def from_camera(cls, camera: Camera, width: int, height: int) -> "EyeRays":
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
        near, far = camera.near_far()
        return cls(camera.parallel_projection, width, height, x_col, y_row, k * aspect, k, near, far)

    def norms(self) -> Float:
        """World length of the direction of every pixel ray, row-major."""
        if self.parallel:
            return np.ones(self.width * self.height)
        x2 = self.x_col[None, :] ** 2
        y2 = self.y_row[:, None] ** 2
        return np.sqrt(x2 + y2 + 1.0).reshape(-1)

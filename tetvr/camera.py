"""The camera, with VTK/ParaView semantics.

``position``, ``focal_point``, ``view_up``; a perspective ``view_angle`` (vertical, in
degrees) or a parallel projection with ``parallel_scale`` (half the image height in world
units); ``clipping_range`` is ``(near, far)`` measured along the view direction.
Pixel ``(i, j)`` (row ``i`` from the top) samples the ray through its centre.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from .mesh import TetMesh

__all__ = ["Camera"]

Vec3 = tuple[float, float, float]


def _vec3(value: Any, name: str) -> Vec3:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _real(value: Any, name: str) -> float:
    """A finite float; booleans and strings are not numbers here."""
    if isinstance(value, (bool, np.bool_, str, bytes)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return out


def _flag(value: Any, name: str) -> bool:
    # bool("false") is True: only real booleans (and 0 / 1) are accepted.
    if isinstance(value, (bool, np.bool_)) or (isinstance(value, (int, np.integer)) and value in (0, 1)):
        return bool(value)
    raise ValueError(f"{name} must be true or false, got {value!r}")


def bounding_sphere(bounds: Any) -> tuple[NDArray[np.float64], float]:
    """``(centre, radius)`` of the sphere around a ``(2, 3)`` box ``(lo, hi)`` (radius at
    least 1e-30, so a point-sized box still has one).

    >>> bounding_sphere([(0, 0, 0), (2, 0, 0)])
    (array([1., 0., 0.]), 1.0)
    """
    lo, hi = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    return 0.5 * (lo + hi), max(0.5 * float(np.linalg.norm(hi - lo)), 1e-30)


@dataclasses.dataclass(frozen=True)
class Camera:
    """A pinhole or parallel camera.

    Examples
    --------
    >>> cam = Camera(position=(0, 0, 5), focal_point=(0, 0, 0), view_up=(0, 1, 0))
    >>> cam.direction
    (0.0, 0.0, -1.0)
    """

    position: Vec3 = (0.0, 0.0, 1.0)
    focal_point: Vec3 = (0.0, 0.0, 0.0)
    view_up: Vec3 = (0.0, 1.0, 0.0)
    view_angle: float = 30.0
    parallel_projection: bool = False
    parallel_scale: float = 1.0
    clipping_range: tuple[float, float] = (0.01, 1000.0)

    def __post_init__(self) -> None:
        pos = _vec3(self.position, "position")
        foc = _vec3(self.focal_point, "focal_point")
        up = _vec3(self.view_up, "view_up")
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "focal_point", foc)
        object.__setattr__(self, "view_up", up)
        with np.errstate(over="ignore", invalid="ignore"):
            d = np.subtract(foc, pos)
            dist = float(np.linalg.norm(d))
        if not dist > 0:
            raise ValueError(f"camera position equals focal_point {foc}: no view direction")
        if not math.isfinite(dist):
            raise ValueError(f"camera position {pos} and focal_point {foc} are too far apart (distance overflows)")
        u = np.asarray(up)
        if not np.linalg.norm(u) > 0:
            raise ValueError("view_up must not be the zero vector")
        sin = np.linalg.norm(np.cross(d / dist, u / np.linalg.norm(u)))
        if sin < 1e-6:
            raise ValueError(f"view_up {up} is parallel to the view direction "
                             f"{tuple(float(v) for v in (d / dist).round(6))}")
        angle = _real(self.view_angle, "view_angle")
        if not (0.0 < angle < 180.0):
            raise ValueError(f"view_angle must be in (0, 180) degrees, got {self.view_angle!r}")
        object.__setattr__(self, "view_angle", angle)
        object.__setattr__(self, "parallel_projection", _flag(self.parallel_projection, "parallel_projection"))
        scale = _real(self.parallel_scale, "parallel_scale")
        if not scale > 0:
            raise ValueError(f"parallel_scale must be positive, got {self.parallel_scale!r}")
        object.__setattr__(self, "parallel_scale", scale)
        try:
            near, far = (_real(v, "clipping_range") for v in self.clipping_range)
        except (TypeError, ValueError):
            raise ValueError(f"clipping_range must be two finite numbers (near, far), got {self.clipping_range!r}") from None
        if not near < far:
            raise ValueError(f"clipping_range must be (near, far) with near < far, got {self.clipping_range!r}")
        if not self.parallel_projection and near <= 0:
            raise ValueError(f"a perspective camera needs near > 0, got clipping_range {self.clipping_range!r}")
        object.__setattr__(self, "clipping_range", (near, far))

    # ---- construction ----
    @classmethod
    def fit(
        cls,
        mesh: "TetMesh",
        *,
        direction: Any = (-1.0, -0.6, -1.2),
        view_up: Any = (0.0, 1.0, 0.0),
        view_angle: float = 30.0,
        parallel: bool = False,
        zoom: float = 1.0,
    ) -> "Camera":
        """A camera looking along ``direction`` at the mesh, which fills the view.

        The bounding sphere of the mesh touches the view's shorter side (divided by ``zoom``).
        """
        centre, radius = bounding_sphere(mesh.bounds)
        d = np.asarray(_vec3(direction, "direction"))
        if not np.linalg.norm(d) > 0:
            raise ValueError("direction must not be the zero vector")
        d = d / np.linalg.norm(d)
        up = np.asarray(_vec3(view_up, "view_up"))
        if not np.linalg.norm(up) > 0:
            raise ValueError("view_up must not be the zero vector")
        view_angle = _real(view_angle, "view_angle")
        if not 0.0 < view_angle < 180.0:
            raise ValueError(f"view_angle must be in (0, 180) degrees, got {view_angle!r}")
        zoom = _real(zoom, "zoom")
        if not zoom > 0:
            raise ValueError(f"zoom must be positive, got {zoom!r}")
        if np.linalg.norm(np.cross(d, up)) < 1e-6 * np.linalg.norm(up):
            up = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
        half = math.radians(view_angle) / 2
        dist = radius / math.sin(half) / zoom
        pos = centre - d * dist
        near = max(dist - radius * 1.05, dist * 1e-3)
        far = dist + radius * 1.05
        return cls(
            position=tuple(pos),  # type: ignore[arg-type]
            focal_point=tuple(centre),  # type: ignore[arg-type]
            view_up=tuple(up),  # type: ignore[arg-type]
            view_angle=view_angle,
            parallel_projection=parallel,
            parallel_scale=radius / zoom,
            clipping_range=(near, far),
        )

    def to_dict(self) -> dict[str, Any]:
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "Camera":
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - names
        if unknown:
            raise ValueError(f"unknown camera keys {sorted(unknown)}; expected some of {sorted(names)}")
        kw = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
        return cls(**kw)  # type: ignore[arg-type]  # validated in __post_init__

    # ---- the frame ----
    @property
    def direction(self) -> Vec3:
        d = np.subtract(self.focal_point, self.position)
        return tuple(float(v) for v in d / np.linalg.norm(d))  # type: ignore[return-value]

    def basis(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Orthonormal (right, up, back) axes of eye space, in world coordinates."""
        d = np.asarray(self.direction)
        right = np.cross(d, self.view_up)
        right /= np.linalg.norm(right)
        up = np.cross(right, d)
        return right, up, -d

    def view_matrix(self) -> NDArray[np.float64]:
        """World -> eye (camera at the origin looking down -z), 4x4, column vectors."""
        r, u, b = self.basis()
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = r, u, b
        m[:3, 3] = -m[:3, :3] @ np.asarray(self.position)
        return m

    def projection_matrix(self, aspect: float) -> NDArray[np.float64]:
        """Eye -> clip, OpenGL convention, for an image of width/height ``aspect``."""
        n, f = self.clipping_range
        m = np.zeros((4, 4))
        if self.parallel_projection:
            h = self.parallel_scale
            m[0, 0] = 1.0 / (h * aspect)
            m[1, 1] = 1.0 / h
            m[2, 2] = -2.0 / (f - n)
            m[2, 3] = -(f + n) / (f - n)
            m[3, 3] = 1.0
        else:
            t = 1.0 / math.tan(math.radians(self.view_angle) / 2)
            m[0, 0] = t / aspect
            m[1, 1] = t
            m[2, 2] = -(f + n) / (f - n)
            m[2, 3] = -2.0 * f * n / (f - n)
            m[3, 2] = -1.0
        return m

    def rays(self, width: int, height: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """World-space ray origins and directions through every pixel centre.

        Returns ``(origins, directions)``, each ``(height*width, 3)`` in row-major pixel
        order (row 0 at the top). Directions are scaled so that the ray parameter equals
        eye-space depth: ``depth(o + t d) = depth(o) + t``, with ``depth(o) = 0``.
        """
        aspect = width / height
        x_ndc = (2.0 * (np.arange(width) + 0.5) / width) - 1.0
        y_ndc = 1.0 - (2.0 * (np.arange(height) + 0.5) / height)
        xx, yy = np.meshgrid(x_ndc, y_ndc)
        r, u, b = self.basis()
        pos = np.asarray(self.position)
        if self.parallel_projection:
            h = self.parallel_scale
            origins = pos + (xx.reshape(-1, 1) * h * aspect) * r + (yy.reshape(-1, 1) * h) * u
            dirs = np.broadcast_to(-b, origins.shape).copy()
        else:
            t = math.tan(math.radians(self.view_angle) / 2)
            dirs = (xx.reshape(-1, 1) * t * aspect) * r + (yy.reshape(-1, 1) * t) * u - b
            origins = np.broadcast_to(pos, dirs.shape).copy()
        return origins, dirs

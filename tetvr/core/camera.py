"""The camera, with VTK/ParaView semantics.

``position``, ``focal_point``, ``view_up``; a perspective ``view_angle`` (vertical, in
degrees) or a parallel projection with ``parallel_scale`` (half the image height in world
units); ``clipping_range`` is ``(near, far)`` measured along the view direction, or ``None``
(the default): computed from the data when it is rendered, as VTK's
``vtkRenderer::ResetCameraClippingRange`` does (:func:`resolve_clipping_range`).
Pixel ``(i, j)`` (row ``i`` from the top) samples the ray through its centre.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

__all__ = ["Bounded", "Camera", "resolve_clipping_range", "union_bounds"]

Vec3 = tuple[float, float, float]


class Bounded(Protocol):
    """What framing needs of a scene object (a :class:`~tetvr.mesh.tetmesh.TetMesh`, a
    :class:`~tetvr.volume.volume.Volume`): its axis-aligned bounds, ``(2, 3)`` as ``(lo, hi)``.
    An object that also has ``points`` is framed by them (its silhouette), not by its box."""

    @property
    def bounds(self) -> Any: ...


def _vec3(value: Any, name: str) -> Vec3:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _safe_length(v: Vec3) -> Vec3:
    """``v`` itself, or, where its squared length leaves float64's range (components
    beyond ~1e150 or below ~1e-150, which a norm overflows to inf or underflows to 0),
    the same direction at unit length; the zero vector stays zero."""
    with np.errstate(over="ignore", under="ignore"):
        length = float(np.linalg.norm(v))
    big = max(abs(c) for c in v)
    if 1e-150 < length < 1e150 or big == 0.0:
        return v
    u = np.asarray(v) / big
    u = u / np.linalg.norm(u)
    return (float(u[0]), float(u[1]), float(u[2]))


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

    Without a ``clipping_range`` the range comes from the data it renders (the mesh's or
    the volume's bounds), resolved by :func:`resolve_clipping_range`:

    >>> cam.clipping_range is None
    True
    >>> resolve_clipping_range(cam, [(-1, -1, -1), (1, 1, 1)]).clipping_range
    (2.96, 7.58)
    """

    position: Vec3 = (0.0, 0.0, 1.0)
    focal_point: Vec3 = (0.0, 0.0, 0.0)
    view_up: Vec3 = (0.0, 1.0, 0.0)
    view_angle: float = 30.0
    parallel_projection: bool = False
    parallel_scale: float = 1.0
    clipping_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        pos = _vec3(self.position, "position")
        foc = _vec3(self.focal_point, "focal_point")
        up = _safe_length(_vec3(self.view_up, "view_up"))
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
        if self.clipping_range is None:
            return  # from the data, when it is rendered (resolve_clipping_range)
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
        mesh: Bounded,
        *,
        direction: Any = (-1.0, -0.6, -1.2),
        view_up: Any = None,
        view_angle: float = 30.0,
        parallel: bool = False,
        zoom: float = 1.0,
    ) -> "Camera":
        """A camera looking along ``direction`` at the mesh, which fills the view.

        ``view_up`` defaults to :data:`DEFAULT_VIEW_UP`, +z (the up axis of most FEM and
        CFD models, and the superior direction of LPS/RAS patient coordinates), or +y
        when ``direction`` runs (nearly) along z. The mesh formats tetvr reads carry no
        up axis; a scene file (``"camera": {"fit": {"view_up": ...}}``) or a ParaView
        state (its ``CameraViewUp``) says which way is up when it knows.

        The mesh's projected extent (its points as this camera sees them, perspective
        included) fills the view's height, or its width in a square view, whichever is
        tighter, less a 4 % margin; ``zoom`` magnifies about the centre of that extent.
        The focal point is the centre of the extent (on the plane through the centre of
        the bounding box), so the mesh sits in the middle of the picture.

        Examples
        --------
        >>> from tetvr.mesh import synthetic
        >>> cam = Camera.fit(synthetic.cube(2, rotate=False), direction=(0, 0, -1), parallel=True)
        >>> round(cam.parallel_scale, 3)  # half the cube's side, plus the margin
        0.521
        """
        return _fit(mesh, direction=direction, view_up=view_up, view_angle=view_angle, parallel=parallel,
                    zoom=zoom, aspect=1.0)

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

    def near_far(self) -> tuple[float, float]:
        """``clipping_range``; a ``ValueError`` when it is still ``None`` (from the data):
        what needs the planes resolves it first, :func:`resolve_clipping_range`."""
        if self.clipping_range is None:
            raise ValueError("this camera's clipping_range is None (computed from the data when it is rendered): "
                             "resolve it first with tetvr.core.camera.resolve_clipping_range(camera, bounds)")
        return self.clipping_range

    def projection_matrix(self, aspect: float) -> NDArray[np.float64]:
        """Eye -> clip, OpenGL convention, for an image of width/height ``aspect``."""
        n, f = self.near_far()
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


#: Fraction of the view's half-height between the mesh's projected extent and the edge.
_FIT_MARGIN = 0.04


#: The up direction :meth:`Camera.fit` uses when none is given: +z.
DEFAULT_VIEW_UP = (0.0, 0.0, 1.0)


def default_view_up(direction: Any) -> tuple[float, float, float]:
    """:data:`DEFAULT_VIEW_UP`, or +y when ``direction`` runs within ~25 degrees of the z axis
    (z would be nearly parallel to the view direction there).

    >>> default_view_up((-1, -0.6, -1.2)), default_view_up((0, 0, -1))
    ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0))
    """
    d = np.asarray(_vec3(direction, "direction"))
    n = float(np.linalg.norm(d))
    return (0.0, 1.0, 0.0) if n > 0 and abs(d[2]) > 0.9 * n else DEFAULT_VIEW_UP


def _fit(mesh: Any, *, direction: Any = (-1.0, -0.6, -1.2), view_up: Any = None,
         view_angle: float = 30.0, parallel: bool = False, zoom: float = 1.0, aspect: float = 1.0) -> Camera:
    """:meth:`Camera.fit` for an image of width/height ``aspect`` (``fit`` assumes a
    square one, which frames the mesh in any landscape image too)."""
    centre, radius = bounding_sphere(mesh.bounds)
    d = np.asarray(_vec3(direction, "direction"))
    if not np.linalg.norm(d) > 0:
        raise ValueError("direction must not be the zero vector")
    d = d / np.linalg.norm(d)
    up = np.asarray(_vec3(default_view_up(d) if view_up is None else view_up, "view_up"))
    if not np.linalg.norm(up) > 0:
        raise ValueError("view_up must not be the zero vector")
    view_angle = _real(view_angle, "view_angle")
    if not 0.0 < view_angle < 180.0:
        raise ValueError(f"view_angle must be in (0, 180) degrees, got {view_angle!r}")
    zoom = _real(zoom, "zoom")
    if not zoom > 0:
        raise ValueError(f"zoom must be positive, got {zoom!r}")
    aspect = _real(aspect, "aspect")
    if not aspect > 0:
        raise ValueError(f"aspect must be positive, got {aspect!r}")
    if np.linalg.norm(np.cross(d, up)) < 1e-6 * np.linalg.norm(up):
        up = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    right = np.cross(d, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, d)
    # The points the extent is measured on: the mesh's own (the silhouette of a cylinder is
    # not its box's), else the corners of its bounding box.
    pts = getattr(mesh, "points", None)
    if pts is None or len(pts) == 0:
        lo, hi = np.asarray(mesh.bounds, dtype=np.float64).reshape(2, 3)
        pts = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    rel = np.asarray(pts, dtype=np.float64) - centre
    x, y, z = rel @ right, rel @ true_up, rel @ -d  # z towards the camera
    # Centre the extent: shift the focal point within the plane through the box's centre.
    sx, sy = 0.5 * (x.max() + x.min()), 0.5 * (y.max() + y.min())
    fill = (1.0 - _FIT_MARGIN) * zoom
    if parallel:
        x, y = x - sx, y - sy
        scale = max(float(np.abs(y).max()), float(np.abs(x).max()) / aspect, 1e-30 * radius) / fill
        dist = 2.0 * radius + scale  # any distance: outside the bounding sphere
    else:
        # Each point p must lie in the view's frustum: |x_p| <= (D - z_p) tan(half_w),
        # |y_p| <= (D - z_p) tan(half_h); the nearest camera that keeps them all is D.
        tan_h = math.tan(math.radians(view_angle) / 2) * fill
        tan_w = tan_h * aspect

        def nearest(xs: NDArray[np.float64], ys: NDArray[np.float64]) -> float:
            d_fit = float(np.max(np.maximum(np.abs(xs) / tan_w, np.abs(ys) / tan_h) + z))
            return max(d_fit, float(z.max()) + 0.1 * radius / zoom)  # never inside (a needle seen end-on)

        # Perspective enlarges the near end: centre the projected extent, not the parallel one.
        for _ in range(8):
            dist = nearest(x - sx, y - sy)
            u, v = (x - sx) / (dist - z), (y - sy) / (dist - z)
            cu, cv = 0.5 * (u.max() + u.min()), 0.5 * (v.max() + v.min())
            if max(abs(cu) / tan_w, abs(cv) / tan_h) < 1e-3:
                break
            depth = dist - 0.5 * (z.max() + z.min())
            sx, sy = sx + cu * depth, sy + cv * depth
        x, y = x - sx, y - sy
        dist = nearest(x, y)
        scale = radius / zoom
    focal = centre + sx * right + sy * true_up
    pos = focal - d * dist
    near = max(dist - float(z.max()) - 0.05 * radius, dist * 1e-3, 1e-300)
    far = dist - float(z.min()) + 0.05 * radius
    return Camera(
        position=tuple(pos),  # type: ignore[arg-type]
        focal_point=tuple(focal),  # type: ignore[arg-type]
        view_up=tuple(up),  # type: ignore[arg-type]
        view_angle=view_angle,
        parallel_projection=parallel,
        parallel_scale=scale,
        clipping_range=(near, far),
    )


# ---- the clipping range from the data (ParaView recomputes it every frame; a state stores none) ----
#: VTK's ``vtkRenderer::ClippingRangeExpansion``: the range is widened by half its depth.
CLIPPING_RANGE_EXPANSION = 0.5
#: VTK's near-plane tolerance for a 24-bit depth buffer (``NearClippingPlaneTolerance``):
#: near is at least this fraction of far.
NEAR_PLANE_TOLERANCE = 0.001


def depth_extent(camera: Camera, points: Any) -> tuple[float, float]:
    """Nearest and farthest depth of ``points`` (an ``(n, 3)`` array, or the ``(2, 3)``
    corners of a box) along the camera's view direction, measured from its position: the
    quantity ``clipping_range`` is compared with.

    >>> depth_extent(Camera(position=(0, 0, 5)), [(0, 0, -1), (0, 0, 1)])
    (4.0, 6.0)
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    d = (p - np.asarray(camera.position)) @ np.asarray(camera.direction)
    return float(d.min()), float(d.max())


def reset_clipping_range(camera: Camera, bounds: Any) -> Camera:
    """The camera with the clipping range ParaView would give it for data in ``bounds``
    (a ``(2, 3)`` box ``(lo, hi)``), as ``vtkRenderer::ResetCameraClippingRange`` computes it.

    The depth range of the box's eight corners along the view direction, no nearer than
    the camera; widened to at least a tenth of the view's height (a flat box seen
    edge-on); then padded: ``near = 0.99 near - 0.5 (far - near)``, then
    ``far = 1.01 far + 0.5 (far - near)`` with that near; near at least ``far / 1000``.

    Examples
    --------
    >>> cam = reset_clipping_range(Camera(position=(0, 0, 1000)), [(-1, -1, -1), (1, 1, 1)])
    >>> [round(v, 3) for v in cam.clipping_range]
    [936.625, 1082.188]
    """
    lo, hi = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    near, far = depth_extent(camera, corners)
    far = max(far, 1e-18)
    if camera.parallel_projection:
        min_gap = 0.1 * camera.parallel_scale
    else:
        min_gap = 0.2 * math.tan(math.radians(camera.view_angle) / 2.0) * far
    if far - near < min_gap:
        grow = min_gap - far + near
        far += grow / 2.0
        near -= grow / 2.0
    near = max(near, 0.0)  # data behind the camera does not move the near plane
    # In sequence, as VTK does: far's padding is measured from the padded near.
    near = 0.99 * near - (far - near) * CLIPPING_RANGE_EXPANSION
    far = 1.01 * far + (far - near) * CLIPPING_RANGE_EXPANSION
    if near >= far:
        near = 0.01 * far
    near = max(near, NEAR_PLANE_TOLERANCE * far)
    return dataclasses.replace(camera, clipping_range=(near, far))


def resolve_clipping_range(camera: Camera, bounds: Any) -> Camera:
    """``camera`` itself when it has a clipping range; else the camera with the range from
    the data in ``bounds`` (a ``(2, 3)`` box ``(lo, hi)`` around everything the frame draws,
    or ``(n, 3)`` points), as :func:`reset_clipping_range` computes it. Every renderer calls this on the
    camera it is given, so ``clipping_range=None`` means "from the data".

    >>> cam = Camera(position=(0, 0, 3000))
    >>> resolve_clipping_range(cam, [(-1, -1, -1), (1, 1, 1)]).clipping_range[1] > 3001
    True
    >>> resolve_clipping_range(Camera(clipping_range=(1, 2)), [(-1, -1, -1), (1, 1, 1)]).clipping_range
    (1.0, 2.0)
    """
    if camera.clipping_range is not None:
        return camera
    return reset_clipping_range(camera, union_bounds(bounds))


def union_bounds(*parts: Any) -> NDArray[np.float64]:
    """The ``(2, 3)`` box ``(lo, hi)`` around every part given: ``(2, 3)`` boxes or
    ``(n, 3)`` points (a box's two corners are two of its points).

    >>> union_bounds([(0, 0, 0), (1, 1, 1)], [(-1, 0, 0), (0, 2, 0)]).tolist()
    [[-1.0, 0.0, 0.0], [1.0, 2.0, 1.0]]
    """
    p = np.concatenate([np.asarray(x, dtype=np.float64).reshape(-1, 3) for x in parts])
    return np.array([p.min(axis=0), p.max(axis=0)])


def check_clipping_range(camera: Camera, points: Any) -> bool:
    """Warn (``UserWarning``) when the camera's clipping range leaves none of ``points``
    between its near and far planes, so the picture would be blank; returns whether it
    does. A camera whose range is ``None`` (from the data) always sees the data.
    :func:`reset_clipping_range` gives a range from the data."""
    if camera.clipping_range is None:
        return False
    near, far = camera.clipping_range
    dmin, dmax = depth_extent(camera, points)
    if dmax >= near and dmin <= far:
        return False
    from tetvr.core.checks import warn

    where = "in front of the near plane" if dmax < near else "beyond the far plane"
    warn(f"the camera's clipping_range ({near:.6g}, {far:.6g}) clips all the data away: the data's depth "
         f"extent along the view is {dmin:.6g} .. {dmax:.6g}, all of it {where}, so the picture is blank; "
         "leave clipping_range out (None) to compute it from the data, or use "
         "tetvr.core.camera.reset_clipping_range(camera, mesh.bounds)")
    return True

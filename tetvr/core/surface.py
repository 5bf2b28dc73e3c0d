"""Opaque triangle surfaces inside the volume: a vessel wall, a CAD part, an implant.

About this technique
--------------------
A surface is opaque, so it ends every ray that meets it: per pixel, the eye depth of the
nearest hit becomes the far end of the ray's window (:mod:`tetvr.core.clip`'s window, the
same cut the clipping range makes), the tets are integrated up to it, and the surface's
shaded colour is composited behind them with "over". That is exact for any mix of
surfaces and tets, in any order along the ray -- the composite ray tracers' answer
(Bunyk et al. 1997 stop rays at opaque geometry the same way), where depth-sorting whole
objects gives "one behind the other".

Each pixel's hit is found exactly: the GPU rasterises a screen rectangle around each
triangle and intersects the pixel's ray with it per fragment (``shaders/surface.*``), the
reference (:func:`surface_hits`) does the same in float64, so coverage and depth agree to
rounding instead of differing at every silhouette pixel the rasteriser's sampling rules
would decide.

Shading is a headlight (the light at the eye, the viewer's usual choice for inspecting
geometry): ``colour * (ambient + (1 - ambient) |n . v|)`` with ``v`` the direction to the
eye, two-sided; ``n`` is the face normal (``smooth=False``) or the vertex normals
(area-weighted) interpolated at the hit.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.camera import Camera, resolve_clipping_range, union_bounds
from tetvr.core.rays import EyeRays

__all__ = ["Surface", "surface_hits", "check_surfaces"]

Float = NDArray[np.float64]


@dataclasses.dataclass(frozen=True, eq=False)
class Surface:
    """An opaque, lit triangle surface in world coordinates.

    Parameters
    ----------
    points : (n, 3) vertex positions.
    triangles : (m, 3) vertex indices.
    color : RGB in [0, 1].
    ambient : the share of the colour shown where the surface is seen edge-on.
    smooth : interpolate vertex normals (True) or shade each triangle flat (False).

    Examples
    --------
    >>> s = Surface([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], color=(1, 0, 0))
    >>> s.n_triangles, s.face_normals.tolist()
    (1, [[0.0, 0.0, 1.0]])
    """

    points: NDArray[np.float64]
    triangles: NDArray[np.int32]
    color: tuple[float, float, float] = (0.85, 0.85, 0.85)
    ambient: float = 0.25
    smooth: bool = False

    def __post_init__(self) -> None:
        try:
            pts = np.array(self.points, dtype=np.float64)
            tri = np.asarray(self.triangles)
        except (TypeError, ValueError):
            raise ValueError("points must be (n, 3) numbers and triangles (m, 3) integers") from None
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 3:
            raise ValueError(f"points must be (n, 3) with n >= 3, got shape {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise ValueError(f"points contain {int(np.sum(~np.isfinite(pts)))} NaN or Inf values")
        if tri.ndim != 2 or tri.shape[1] != 3 or tri.shape[0] == 0:
            raise ValueError(f"triangles must be (m, 3) with m >= 1, got shape {tri.shape}")
        if tri.dtype.kind not in "iu":
            if tri.dtype.kind != "f" or not np.all(tri == np.round(tri)):
                raise ValueError(f"triangles must be integer vertex indices, got dtype {tri.dtype}")
        tri = tri.astype(np.int64)
        if tri.min() < 0 or tri.max() >= pts.shape[0]:
            raise ValueError(f"triangles index vertices 0..{pts.shape[0] - 1}, got indices {int(tri.min())}.."
                             f"{int(tri.max())}")
        if tri.shape[0] >= 2**24:
            raise ValueError(f"at most {2**24 - 1} triangles per surface, got {tri.shape[0]}")
        col = np.asarray(self.color, dtype=np.float64).reshape(-1)
        if col.shape != (3,) or not np.all((col >= 0) & (col <= 1)):
            raise ValueError(f"color must be RGB in [0, 1], got {self.color!r}")
        amb = float(self.ambient)
        if not 0.0 <= amb <= 1.0:
            raise ValueError(f"ambient must be in [0, 1], got {self.ambient!r}")
        pts.setflags(write=False)
        tri = tri.astype(np.int32)
        tri.setflags(write=False)
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "triangles", tri)
        object.__setattr__(self, "color", tuple(float(c) for c in col))
        object.__setattr__(self, "ambient", amb)
        object.__setattr__(self, "smooth", bool(self.smooth))

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])

    @property
    def corners(self) -> Float:
        """(m, 3, 3): each triangle's vertex positions."""
        return self.points[self.triangles]

    @property
    def face_normals(self) -> Float:
        """(m, 3) unit normals, by the right-hand rule (zero for a degenerate triangle)."""
        c = self.corners
        n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return np.divide(n, length, out=np.zeros_like(n), where=length > 0)  # type: ignore[no-any-return]

    @property
    def vertex_normals(self) -> Float:
        """(n, 3) area-weighted mean of the adjacent face normals, unit length."""
        c = self.corners
        n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])  # length = 2 * area
        acc = np.zeros_like(self.points)
        for k in range(3):
            np.add.at(acc, self.triangles[:, k], n)
        length = np.linalg.norm(acc, axis=1, keepdims=True)
        return np.divide(acc, length, out=np.zeros_like(acc), where=length > 0)  # type: ignore[no-any-return]

    def shading_normals(self) -> Float:
        """(m, 3, 3): the normal at each triangle's corners (flat: the face normal thrice)."""
        if self.smooth:
            return self.vertex_normals[self.triangles]  # type: ignore[no-any-return]
        return np.repeat(self.face_normals[:, None, :], 3, axis=1)

    # ---- construction ----
    @classmethod
    def from_trimesh(cls, mesh: Any, **kwargs: Any) -> "Surface":
        """From a ``trimesh.Trimesh``."""
        return cls(np.asarray(mesh.vertices), np.asarray(mesh.faces), **kwargs)

    @classmethod
    def from_meshio(cls, mesh: Any, **kwargs: Any) -> "Surface":
        """From a ``meshio.Mesh``: its triangle cells (quads are split in two)."""
        tris = []
        for block in mesh.cells:
            if block.type == "triangle":
                tris.append(np.asarray(block.data))
            elif block.type == "quad":
                q = np.asarray(block.data)
                tris += [q[:, [0, 1, 2]], q[:, [0, 2, 3]]]
        if not tris:
            kinds = sorted({b.type for b in mesh.cells})
            raise ValueError(f"the mesh has no triangles or quads to make a surface of (cell types: {kinds})")
        return cls(np.asarray(mesh.points)[:, :3], np.concatenate(tris), **kwargs)

    @classmethod
    def read(cls, path: str | os.PathLike[str], **kwargs: Any) -> "Surface":
        """Read a surface file (STL, OBJ, PLY, OFF, VTK/VTU, ... -- anything meshio reads)."""
        import meshio

        path = os.fspath(path)
        if not os.path.isfile(path):
            raise FileNotFoundError(f"no surface file {path!r}")
        if not path.lower().endswith(".stl"):
            return cls.from_meshio(meshio.read(path), **kwargs)
        _check_binary_stl(path)
        with np.errstate(over="ignore"):  # meshio's size test, 84 + 50 n in uint32, wraps on ASCII files
            return cls.from_meshio(meshio.read(path), **kwargs)


def _check_binary_stl(path: str) -> None:
    """``ValueError`` for a binary STL whose triangle count disagrees with its size.

    A binary STL is an 80-byte header, a little-endian uint32 count ``n``, and ``n``
    50-byte triangles. meshio takes a file whose size is not ``84 + 50 n`` for ASCII (and
    computes ``50 n`` in uint32, which wraps for ``n`` >= 2^32 / 50), so a damaged
    binary file came back as "no triangles". A file that starts with ``solid`` and is
    text is ASCII STL and left to meshio.
    """
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        head = f.read(84)
        sample = head + f.read(512)
    if size < 84 or (head.lstrip()[:5].lower() == b"solid" and _is_text(sample)):
        return
    n = int.from_bytes(head[80:84], "little")
    if 84 + 50 * n != size:
        have = max(size - 84, 0) // 50
        raise ValueError(f"surface file {path!r} is a binary STL that declares {n} triangles ({84 + 50 * n} bytes) "
                         f"but is {size} bytes long ({have} whole triangles): it is truncated or damaged; "
                         "export it again")


def _is_text(data: bytes) -> bool:
    return not any(b < 9 or 13 < b < 32 or b > 126 for b in data)


def check_surfaces(surfaces: Any) -> tuple[Surface, ...]:
    """The surfaces as a tuple, each checked to be a :class:`Surface`."""
    if surfaces is None:
        return ()
    if isinstance(surfaces, Surface):
        return (surfaces,)
    try:
        out = tuple(surfaces)
    except TypeError:
        raise TypeError(f"surfaces must be a Surface or a sequence of them, got {type(surfaces).__name__}") from None
    for i, s in enumerate(out):
        if not isinstance(s, Surface):
            raise TypeError(f"surfaces[{i}] must be a tetvr.Surface, got {type(s).__name__}")
    return out


def shade(color: ArrayLike, ambient: float, normal_dot_view: ArrayLike) -> Float:
    """The headlight's colour for ``|n . v|`` values (unit vectors)."""
    c = np.asarray(color, dtype=np.float64)
    k = ambient + (1.0 - ambient) * np.abs(np.asarray(normal_dot_view, dtype=np.float64))
    return k[..., None] * c  # type: ignore[no-any-return]


def surface_hits(surfaces: Sequence[Surface], camera: Camera, size: tuple[int, int]
                 ) -> tuple[Float, Float]:
    """Per pixel, the eye depth of the nearest surface hit and its shaded colour, exactly.

    Returns ``(t, rgb)``: ``t`` (height, width), ``+inf`` where no surface is hit within the
    clipping range; ``rgb`` (height, width, 3), zero there. Row 0 at the top; each pixel's
    ray through its centre, as :func:`tetvr.reference.tets.render_reference`.
    """
    width, height = int(size[0]), int(size[1])
    camera = resolve_clipping_range(camera, union_bounds(*(s.points for s in surfaces)) if surfaces else [[0.0] * 3] * 2)
    rays = EyeRays.from_camera(camera, width, height)
    near, far = camera.near_far()
    best = np.full((height, width), np.inf)
    rgb = np.zeros((height, width, 3))
    # Every pixel's eye-space ray and unit direction to the eye, once for all triangles.
    x, y = np.broadcast_arrays(rays.x_col[None, :], rays.y_row[:, None])
    if rays.parallel:
        o = np.stack([x, y, np.zeros_like(x)], axis=-1)
        d = np.broadcast_to(np.array([0.0, 0.0, -1.0]), o.shape)
    else:
        d = np.stack([x, y, -np.ones_like(x)], axis=-1)
        o = np.zeros_like(d)
    to_eye = -d / np.linalg.norm(d, axis=-1, keepdims=True)
    view = camera.view_matrix()
    for surf in check_surfaces(surfaces):
        corners = surf.corners @ view[:3, :3].T + view[:3, 3]  # (m, 3, 3) eye space
        normals = surf.shading_normals() @ view[:3, :3].T
        for i in range(surf.n_triangles):
            _hit_triangle(corners[i], normals[i], surf, rays, (o, d, to_eye), near, far, best, rgb)
    return best, rgb


def _pixel_range(coords: Float, lo_edge: float, step: float, n: int) -> tuple[int, int]:
    """Pixels whose centre coordinate may lie within [min, max] of ``coords``."""
    a = (coords.min() - lo_edge) / step - 0.5
    b = (coords.max() - lo_edge) / step - 0.5
    return max(0, int(math.floor(a)) - 1), min(n - 1, int(math.ceil(b)) + 1)


def _hit_triangle(p: Float, nrm: Float, surf: Surface, rays: Any, pixel_rays: tuple[Float, Float, Float],
                  near: float, far: float, best: Float, rgb: Float) -> None:
    depth = -p[:, 2]
    if depth.max() < near or depth.min() > far:
        return
    width, height = rays.width, rays.height
    if rays.parallel:
        xy = p[:, :2]
        full = False
    else:
        full = depth.min() < near  # the projection is unbounded: test every pixel
        xy = p[:, :2] / np.where(depth > 0, depth, 1.0)[:, None]
    if full:
        c0, c1, r0, r1 = 0, width - 1, 0, height - 1
    else:
        dx = rays.x_col[1] - rays.x_col[0] if width > 1 else 2 * rays.kx
        dy = rays.y_row[0] - rays.y_row[1] if height > 1 else 2 * rays.ky
        c0, c1 = _pixel_range(xy[:, 0], rays.x_col[0] - 0.5 * dx, dx, width)
        # y_row runs downwards from the top row.
        ys = -xy[:, 1]
        r0, r1 = _pixel_range(ys, -rays.y_row[0] - 0.5 * dy, dy, height)
        if c0 > c1 or r0 > r1:
            return
    box = (slice(r0, r1 + 1), slice(c0, c1 + 1))
    o, d, to_eye = (a[box] for a in pixel_rays)
    t, b1, b2 = moller_trumbore(p, o, d)
    b0 = 1.0 - b1 - b2
    hit = (b1 >= 0) & (b2 >= 0) & (b0 >= 0) & (t >= near) & (t <= far)
    win = best[r0:r1 + 1, c0:c1 + 1]
    closer = hit & (t < win)
    if not closer.any():
        return
    n = b0[..., None] * nrm[0] + b1[..., None] * nrm[1] + b2[..., None] * nrm[2]
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    ndv = np.nan_to_num(np.sum(n * to_eye, axis=-1))
    col = shade(surf.color, surf.ambient, ndv)
    win[closer] = t[closer]
    rgb[r0:r1 + 1, c0:c1 + 1][closer] = col[closer]


def moller_trumbore(p: Float, o: Float, d: Float) -> tuple[Float, Float, Float]:
    """Ray ``o + t d`` against triangle ``p`` (3, 3): ``(t, b1, b2)`` with the hit at
    ``p0 + b1 (p1 - p0) + b2 (p2 - p0)``; NaN where the ray is parallel to the triangle.
    Same formula as ``shaders/surface.frag``."""
    e1, e2 = p[1] - p[0], p[2] - p[0]
    q = np.cross(d, e2)
    det = q @ e1
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(det != 0, 1.0 / det, np.nan)
        s = o - p[0]
        b1 = np.sum(s * q, axis=-1) * inv
        r = np.cross(s, e1)
        b2 = np.sum(r * d, axis=-1) * inv
        t = (r @ e2) * inv
    return t, b1, b2

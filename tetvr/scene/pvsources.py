"""What a ParaView state shows besides its volume: spheres, boxes, surface files and
outlines, as tetvr's opaque geometry (:class:`tetvr.Surface`).

A state often shows more than the volume: a probe drawn as a sphere, a part read from an
STL file, the outline of the data. :func:`shown_sources` lists every visible
representation of the view other than the volume's (:class:`ShownSource`, read from the
state alone); :func:`state_surfaces` makes the geometry of each one tetvr can draw and
says, naming the source, why it leaves out the others.

What tetvr draws, and how:

* **Surface** (and "Surface With Edges", without its edges) of a ``SphereSource``
  (tessellated as ``vtkSphereSource`` does, point for point), a ``CubeSource`` (ParaView's
  Box), a reader of a surface file (STL, PLY, OBJ, OFF) or of a volume mesh (its boundary
  faces): a :class:`~tetvr.Surface` in the representation's solid colour
  (``DiffuseColor``), opaque, lit by tetvr's headlight.
* **Outline** of any of these: its bounding box's 12 edges as
  ribbons ``LineWidth`` pixels wide facing the eye, in ``AmbientColor``, unlit. The width
  is set for the state's camera and view size.

Not drawn (each warned about, naming the source): other representations (Wireframe,
Points, a second Volume, Slice, glyphs), other sources (a cone, a text, a filter's output),
and colouring by an array (drawn in the solid colour instead, with a warning), opacity
below 1 (drawn opaque, with a warning).
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any, Callable

import numpy as np

from tetvr.core.camera import Camera
from tetvr.core.surface import Surface
from tetvr.scene.pvsm import StateProxy

__all__ = ["ShownSource", "shown_sources", "sphere_source", "state_surfaces"]

#: Most points of a sphere tetvr makes (ThetaResolution x PhiResolution): 4M points, 8M
#: triangles. VTK 9 clamps neither from above.
_MAX_SPHERE_POINTS = 1 << 22
#: Surface files tetvr reads as triangles; any other file is read as a volume mesh.
_SURFACE_SUFFIXES = (".stl", ".ply", ".obj", ".off")
#: Representations drawn as a surface, and those drawn as an outline.
_SURFACES = ("Surface", "Surface With Edges")
_OUTLINE = "Outline"


@dataclasses.dataclass(frozen=True)
class ShownSource:
    """One visible representation of a state besides its volume, as the state describes it.

    ``name`` is the source's name in ParaView's pipeline browser (else its proxy type and
    id); ``chain`` the proxy types from the representation's input up to its source (one
    entry unless filters come between); ``numbers`` the source's properties tetvr uses
    (a sphere's centre, radius, resolutions and angles; a box's centre and lengths).
    """

    name: str
    chain: tuple[str, ...]
    representation: str
    color: tuple[float, float, float]
    outline_color: tuple[float, float, float]
    opacity: float
    array: str | None
    line_width: float
    files: tuple[str, ...] = ()
    numbers: tuple[tuple[str, tuple[float, ...]], ...] = ()

    @property
    def source(self) -> str:
        return self.chain[-1]

    def number(self, name: str) -> tuple[float, ...]:
        return dict(self.numbers)[name]


def shown_sources(proxies: dict[str, StateProxy], volume: StateProxy, view: StateProxy) -> tuple[ShownSource, ...]:
    """Every visible representation in ``view`` with an input, but ``volume`` (the one
    rendered as the volume), in the order the view lists them."""
    listed = view.refs("Representations")
    reps = [proxies[i] for i in listed if i in proxies] if listed else list(proxies.values())
    out = []
    for rep in reps:
        if rep.group != "representations" or rep is volume or not rep.refs("Input") or not rep.flag("Visibility", True):
            continue
        chain, up = [], proxies.get(rep.refs("Input")[0])
        while up is not None and len(chain) < 64:
            chain.append(up)
            if up.group == "sources" or not up.refs("Input"):
                break
            up = proxies.get(up.refs("Input")[0])
        if not chain:
            continue
        out.append(_shown(rep, chain))
    return tuple(out)


def _shown(rep: StateProxy, chain: list[StateProxy]) -> ShownSource:
    src = chain[-1]
    names = rep.values("ColorArrayName")
    diffuse = tuple(rep.floats("DiffuseColor", 3, lo=0.0, hi=1.0) or (1.0, 1.0, 1.0))
    numbers: list[tuple[str, tuple[float, ...]]] = []
    if len(chain) == 1 and src.type == "SphereSource":
        numbers = [("Center", tuple(src.floats("Center", 3) or (0.0, 0.0, 0.0))),
                   ("Radius", (src.number("Radius", 0.5, lo=0.0),)),  # type: ignore[arg-type]
                   ("Resolution", (src.integer("ThetaResolution", 8, -(1 << 31), 1 << 31),
                                   src.integer("PhiResolution", 8, -(1 << 31), 1 << 31))),
                   ("Theta", (src.number("StartTheta", 0.0), src.number("EndTheta", 360.0))),  # type: ignore[arg-type]
                   ("Phi", (src.number("StartPhi", 0.0), src.number("EndPhi", 180.0)))]  # type: ignore[arg-type]
    elif len(chain) == 1 and src.type == "CubeSource":
        numbers = [("Center", tuple(src.floats("Center", 3) or (0.0, 0.0, 0.0))),
                   ("Lengths", tuple(src.number(k, 1.0, lo=0.0) for k in ("XLength", "YLength", "ZLength")))]  # type: ignore[misc]
    return ShownSource(
        name=src.name or f"{src.type} (id {src.id})", chain=tuple(p.type for p in chain),
        representation=rep.text("Representation", "Surface") or "Surface",
        color=diffuse, outline_color=tuple(rep.floats("AmbientColor", 3, lo=0.0, hi=1.0) or diffuse),  # type: ignore[arg-type]
        opacity=rep.number("Opacity", 1.0, lo=0.0, hi=1.0),  # type: ignore[arg-type]
        array=names[4] if len(names) >= 5 and names[4] else None,
        line_width=rep.number("LineWidth", 1.0, lo=0.0, hi=1e4),  # type: ignore[arg-type]
        files=tuple(f for f in (src.values("FileNames") or src.values("FileName")) if f) if len(chain) == 1 else (),
        numbers=tuple(numbers))


# ---------------------------------------------------------------- geometry
def sphere_source(center: Any = (0.0, 0.0, 0.0), radius: float = 0.5, theta_resolution: int = 8,
                  phi_resolution: int = 8, theta: tuple[float, float] = (0.0, 360.0),
                  phi: tuple[float, float] = (0.0, 180.0)) -> tuple[np.ndarray, np.ndarray]:
    """The points and triangles of ``vtkSphereSource`` with these settings (one piece,
    triangles, float32 points as VTK makes them): ParaView's Sphere, point for point.

    Resolutions and angles are clamped as VTK 9 clamps them (resolutions at least 3,
    angles 0..360); more than 4M points is a ``ValueError``.

    Examples
    --------
    >>> points, triangles = sphere_source()
    >>> points.shape, triangles.shape
    ((50, 3), (96, 3))
    """
    tres, pres = max(int(theta_resolution), 3), max(int(phi_resolution), 3)
    if tres * pres > _MAX_SPHERE_POINTS:
        raise ValueError(f"a sphere of ThetaResolution {tres} x PhiResolution {pres} has more than the "
                         f"{_MAX_SPHERE_POINTS} points tetvr makes")
    t0, t1 = (min(max(float(a), 0.0), 360.0) for a in theta)
    p0, p1 = (min(max(float(a), 0.0), 360.0) for a in phi)
    c, r = np.asarray(center, dtype=np.float64), float(radius)
    while t1 < t0:
        t1 += 360.0
    points, poles = [], 0
    if p0 <= 0.0:
        points.append(c + (0.0, 0.0, r))
        poles += 1
    if p1 >= 180.0:
        points.append(c - (0.0, 0.0, r))
        poles += 1
    start_phi, end_phi = math.radians(min(p0, p1)), math.radians(max(p0, p1))
    ring = pres - poles
    d_phi = (end_phi - start_phi) / (pres - 1)
    n_theta = tres + (1 if abs(t0 - t1) < 360.0 else 0)
    d_theta = (math.radians(max(t0, t1)) - math.radians(min(t0, t1))) / tres
    j = np.arange(1 if p0 <= 0.0 else 0, pres - 1 if p1 >= 180.0 else pres)
    for i in range(n_theta):
        th = math.radians(t0) + i * d_theta
        ph = start_phi + j * d_phi
        rr = r * np.sin(ph)
        points += list(np.stack([rr * math.cos(th), rr * math.sin(th), r * np.cos(ph)], axis=1) + c)
    base = ring * n_theta
    n_cells = n_theta - (1 if abs(t0 - t1) < 360.0 else 0)
    tris = []
    if p0 <= 0.0:
        tris += [(ring * i + poles, (ring * (i + 1)) % base + poles, 0) for i in range(n_cells)]
    if p1 >= 180.0:
        off = ring - 1 + poles
        tris += [(ring * i + off, poles - 1, (ring * (i + 1)) % base + off) for i in range(n_cells)]
    for i in range(n_cells):
        for k in range(ring - 1):
            a = ring * i + k + poles
            b = (ring * (i + 1) + k) % base + poles + 1
            tris += [(a, a + 1, b), (a, b, b - 1)]
    pts = np.asarray(points, dtype=np.float32).astype(np.float64)
    return pts, np.asarray(tris, dtype=np.int64).reshape(-1, 3)


def _box(center: Any, lengths: Any) -> tuple[np.ndarray, np.ndarray]:
    """``vtkCubeSource``'s box: 8 corners, 12 triangles."""
    c, h = np.asarray(center, dtype=np.float64), 0.5 * np.asarray(lengths, dtype=np.float64)
    corners = c + h * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return corners, np.array([t for a, b, cc, d in quads for t in ((a, b, cc), (a, cc, d))], dtype=np.int64)


def _boundary(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The faces of ``tets`` that no other tet shares: a volume mesh's surface."""
    faces = np.concatenate([tets[:, [1, 2, 3]], tets[:, [0, 3, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 1]]])
    _, first, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
    return faces[first[counts == 1]]


def outline_ribbons(bounds: Any, camera: Camera, size: tuple[int, int], width_px: float,
                    color: tuple[float, float, float]) -> Surface:
    """A box's 12 edges as ribbons ``width_px`` pixels wide at ``camera`` and ``size``
    (the picture's height sets a pixel's size), each facing the eye: lines drawn as
    opaque geometry, so the volume in front of them covers them as ParaView's does."""
    lo, hi = np.asarray(bounds, dtype=np.float64)
    corner = np.array([[(lo, hi)[x][0], (lo, hi)[y][1], (lo, hi)[z][2]] for x in (0, 1) for y in (0, 1)
                       for z in (0, 1)])
    edges = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
    eye = np.asarray(camera.position, dtype=np.float64)
    forward = np.asarray(camera.focal_point, dtype=np.float64) - eye
    forward /= np.linalg.norm(forward)
    h = max(int(size[1]), 1)

    def pixel(p: np.ndarray) -> float:  # a pixel's height in world units at p's depth
        if camera.parallel_projection:
            return 2.0 * float(camera.parallel_scale) / h
        return 2.0 * max(float(np.dot(p - eye, forward)), 0.0) * math.tan(math.radians(camera.view_angle) / 2) / h

    points, tris = [], []
    for a, b in edges:
        pa, pb = corner[a], corner[b]
        along = pb - pa
        if not np.any(along):
            continue
        view = 0.5 * (pa + pb) - eye if not camera.parallel_projection else forward
        side = np.cross(along, view)
        if np.linalg.norm(side) <= 1e-12 * np.linalg.norm(along) * np.linalg.norm(view):
            continue  # seen end-on: a point
        side /= np.linalg.norm(side)
        k = len(points)
        for p in (pa, pb):
            w = 0.5 * width_px * pixel(p)
            points += [p - w * side, p + w * side]
        tris += [(k, k + 1, k + 3), (k, k + 3, k + 2)]
    return Surface(np.array(points), np.array(tris), color=color, ambient=1.0)


def state_surfaces(shown: tuple[ShownSource, ...], *, camera: Camera, size: tuple[int, int],
                   find: Callable[[str], str],
                   read_cells: Callable[[str], Any]) -> tuple[list[Surface], list[str]]:
    """The surfaces of the sources tetvr can draw, and one sentence for each it leaves
    out or draws otherwise than ParaView (naming the source and why).

    ``find`` locates a data file a state names; ``read_cells`` reads a volume mesh
    (:func:`tetvr.io.meshfile.read_cells`).
    """
    surfaces: list[Surface] = []
    said: list[str] = []
    for s in shown:
        what = f"{s.name} ({' <- '.join(s.chain)}) shown as {s.representation!r}"
        if s.representation not in _SURFACES + (_OUTLINE,):
            said.append(f"{what} is not drawn: tetvr draws a state's volume, and its other sources as surfaces "
                        "or outlines only")
            continue
        try:
            geometry = _geometry(s, find, read_cells)
        except (OSError, ValueError) as exc:
            said.append(f"{what} is not drawn: {exc}")
            continue
        if geometry is None:
            said.append(f"{what} is not drawn: tetvr draws spheres, boxes, and surface files and volume meshes read "
                        "directly (no filters)")
            continue
        points, triangles, smooth = geometry
        if s.representation == _OUTLINE:
            surfaces.append(outline_ribbons(np.array([points.min(axis=0), points.max(axis=0)]), camera, size,
                                            s.line_width, s.outline_color))
            continue
        surfaces.append(Surface(points, triangles, color=s.color, smooth=smooth))
        notes = ([f"coloured by the array {s.array!r} in ParaView, drawn in its solid colour"] if s.array else []) \
            + ([f"opacity {s.opacity:g} in ParaView, drawn opaque"] if s.opacity < 1.0 else []) \
            + (["drawn without its edges"] if s.representation != "Surface" else [])
        if notes:
            said.append(f"{what}: " + "; ".join(notes))
    return surfaces, said


def _geometry(s: ShownSource, find: Callable[[str], str],
              read_cells: Callable[[str], Any]) -> tuple[np.ndarray, np.ndarray, bool] | None:
    """A source's points and triangles (and whether VTK shades it smooth); None for a
    source tetvr does not make."""
    if len(s.chain) != 1:
        return None
    if s.source == "SphereSource":
        res, th, ph = s.number("Resolution"), s.number("Theta"), s.number("Phi")
        pts, tris = sphere_source(s.number("Center"), s.number("Radius")[0], int(res[0]), int(res[1]),
                                  (th[0], th[1]), (ph[0], ph[1]))
        return pts, tris, True  # vtkSphereSource makes point normals
    if s.source == "CubeSource":
        pts, tris = _box(s.number("Center"), s.number("Lengths"))
        return pts, tris, False
    if not s.files:
        return None
    path = find(s.files[0])
    if os.path.splitext(path)[1].lower() in _SURFACE_SUFFIXES:
        surface = Surface.read(path)
        return surface.points, surface.triangles.astype(np.int64), False
    cells = read_cells(path)
    return cells.points, _boundary(cells.points, cells.tets), False

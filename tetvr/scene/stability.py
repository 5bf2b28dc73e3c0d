"""Scenes where projected tetrahedra usually fail: the stability suite's generators.

Each case is a (mesh, camera, transfer function) triple; ``tests/stability`` renders them
with the default method and compares with the reference, and ``bench/speed_accuracy.py``
records every method variant's error on them.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from tetvr.mesh import synthetic
from tetvr.core.camera import Camera
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.transfer import TransferFunction

__all__ = ["Case", "CASES", "case"]


@dataclasses.dataclass(frozen=True, eq=False)
class Case:
    name: str
    mesh: TetMesh
    camera: Camera
    tf: TransferFunction
    what: str


def _tf(mesh: TetMesh, opacity=((0.0, 0.3), (1.0, 0.8)), units: float = 4.0, preset: str = "viridis") -> TransferFunction:
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    lo, hi = mesh.scalar_range
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    return TransferFunction.preset(preset, (lo, hi), opacity=list(opacity), unit_distance=diag / units)


def _slivers() -> Case:
    # A cube whose interior points are pushed almost onto grid planes: many tets with
    # relative volume ~1e-6 next to normal ones.
    m = synthetic.cube(4, rotate=False)
    pts = m.points.copy()
    inner = np.all(np.abs(pts) < 0.49, axis=1)
    rng = np.random.default_rng(3)
    pts[inner] += rng.normal(0.0, 1.0, (int(inner.sum()), 3)) * 0.12
    mesh = TetMesh.from_arrays(pts, m.tets, m.scalars)
    return Case("slivers", mesh, Camera.fit(mesh, direction=(-0.3, -0.5, -1.0)), _tf(mesh), "jittered cube with near-flat tets")


def _needles() -> Case:
    # Cells 100x longer than wide: a cube squashed to 1e-2 in x and y, seen from the side
    # through a window as wide as the needles are long... divided by 10.
    m = synthetic.cube(3, rotate=False)
    mesh = TetMesh.from_arrays(m.points * np.array([1e-2, 1e-2, 1.0]), m.tets, m.scalars)
    cam = Camera(position=(-1.0, -0.3, 0.1), focal_point=(0.0, 0.0, 0.1), view_up=(0, 0, 1), parallel_projection=True,
                 parallel_scale=0.02, clipping_range=(0.5, 2.0))
    return Case("needles", mesh, cam, _tf(mesh, units=40.0), "needle-shaped tets (aspect 100) seen side-on")


def _graded() -> Case:
    # Layers whose thickness runs from 1e-6 to 0.5: six orders of magnitude in one view.
    z = np.concatenate([[0.0], np.geomspace(1e-6, 1.0, 14)])
    g = np.linspace(0.0, 1.0, 4)
    x, y, zz = np.meshgrid(g, g, z, indexing="ij")
    pts = np.stack([x.ravel(), y.ravel(), zz.ravel()], axis=1)
    idx = np.arange(pts.shape[0]).reshape(4, 4, z.size)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(3), np.arange(3), np.arange(z.size - 1), indexing="ij"))
    corners = np.stack([idx[i + (c & 1), j + (c >> 1 & 1), k + (c >> 2 & 1)] for c in range(8)], axis=1)
    tets = corners[:, synthetic._KUHN].reshape(-1, 4)
    mesh = TetMesh.from_arrays(pts, tets, pts @ np.array([0.3, 0.2, 0.5]))
    cam = Camera.fit(mesh, direction=(-0.2, -0.3, -1.0))
    return Case("graded_1e-6", mesh, cam, _tf(mesh), "tet thickness spanning 6 orders of magnitude")


def _thin_perspective() -> Case:
    mesh = synthetic.slab(thickness=1e-3, width=1.0, value=0.5, n=6)
    mesh = mesh.with_scalars(mesh.points @ np.array([0.5, 0.5, 0.0]) + 0.5)
    cam = Camera(position=(0.3, -1.2, 0.25), focal_point=(0, 0, 0), view_up=(0, 0, 1), view_angle=50,
                 clipping_range=(0.1, 5.0))
    return Case("thin_perspective", mesh, cam, _tf(mesh, units=300.0), "1e-3 thick slab at a grazing angle")


def _edge_on() -> Case:
    # A tet with the edge (0,1) along the view axis: two vertices project to one point.
    pts = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, -0.5], [0.6, -0.2, 0.1], [-0.3, 0.5, -0.1]])
    mesh = TetMesh.from_arrays(pts, [[0, 1, 2, 3]], [0.0, 1.0, 0.3, 0.7])
    cam = Camera(position=(0, 0, 3), focal_point=(0, 0, 0), parallel_projection=True, parallel_scale=0.7,
                 clipping_range=(0.5, 6))
    return Case("edge_on", mesh, cam, _tf(mesh, units=1.0), "an edge seen end-on (coincident projected vertices)")


def _face_on() -> Case:
    # The face (1,2,3) seen exactly edge-on: its projection is a segment.
    pts = np.array([[0.0, 0.6, 0.0], [-0.5, -0.3, 0.4], [0.5, -0.3, 0.4], [0.0, -0.3, -0.5]])
    mesh = TetMesh.from_arrays(pts, [[0, 1, 2, 3]], [1.0, 0.0, 0.5, 0.2])
    cam = Camera(position=(0, -3, 0), focal_point=(0, 0, 0), view_up=(0, 0, 1), parallel_projection=True,
                 parallel_scale=0.7, clipping_range=(0.5, 6))
    return Case("face_edge_on", mesh, cam, _tf(mesh, units=1.0), "a face seen edge-on (class boundary)")


def _scaled(name: str, scale: float, offset: float) -> Case:
    m = synthetic.cube(3)
    mesh = TetMesh.from_arrays(m.points * scale + offset, m.tets, m.scalars)
    return Case(name, mesh, Camera.fit(mesh, direction=(-0.4, -0.3, -1.0)), _tf(mesh), f"coordinates ~{scale:g} at offset {offset:g}")


def _rings() -> Case:
    mesh = synthetic.interlocking_rings(16, 1)
    cam = Camera.fit(mesh, direction=(-0.5, -1.0, -0.6), view_up=(0, 0, 1))
    return Case("interlocking_rings", mesh, cam, _tf(mesh, opacity=((0, 0.9), (1, 0.9)), units=6.0),
                "two linked rings: non-convex, disconnected, cyclic overlaps")


def _inside() -> Case:
    mesh = synthetic.cube(6)
    cam = Camera(position=(0.1, 0.05, 0.2), focal_point=(-0.3, -0.2, -1), view_angle=70, clipping_range=(0.01, 5))
    return Case("camera_inside", mesh, cam, _tf(mesh), "camera inside the mesh")


def _on_face() -> Case:
    mesh = synthetic.cube(4, rotate=False)
    cam = Camera(position=(0.0, 0.0, 0.25), focal_point=(0.1, 0.2, -1.0), view_angle=60, clipping_range=(0.01, 5))
    return Case("camera_on_face", mesh, cam, _tf(mesh), "eye exactly on an interior grid plane")


def _near_plane() -> Case:
    mesh = synthetic.cube(8)
    cam = Camera(position=(0, 0, 1.2), focal_point=(0, 0, 0), view_angle=45, clipping_range=(1.2, 5))
    return Case("near_plane_cut", mesh, cam, _tf(mesh), "the near plane cuts through many tets")


def _face_through_eye() -> Case:
    # Integer vertices; the face (0, 1, 2) lies in the plane x + y - z = -16, which holds
    # the eye: the face projects to a line, and its fan triangles have zero area.
    pts = np.array([[0.0, 0.0, 16.0], [10.0, 0.0, 26.0], [0.0, 10.0, 26.0], [5.0, 5.0, 10.0]])
    mesh = TetMesh.from_arrays(pts, [[0, 1, 2, 3]], [0.0, 1.0, 0.5, 0.2])
    cam = Camera(position=(31.0, -22.0, 25.0), focal_point=tuple(mesh.centroids[0]), view_up=(0, 0, 1),
                 view_angle=30.0, clipping_range=(1.0, 200.0))
    return Case("face_through_eye", mesh, cam, _tf(mesh, opacity=((0.0, 0.5), (1.0, 0.9)), units=8.0),
                "a face whose plane holds the eye (fan triangles of zero area)")


def _edge_along_ray() -> Case:
    # Two vertices on the ray through the centre of pixel (40, 52) of a 96 x 96 view: the
    # edge between them projects onto that pixel centre.
    cam = Camera(position=(0.0, 0.0, 4.0), focal_point=(0.0, 0.0, 0.0), view_up=(0, 1, 0), view_angle=30.0,
                 clipping_range=(0.5, 10.0))
    o, d = cam.rays(96, 96)
    ray = d.reshape(96, 96, 3)[52, 40]
    ray = ray / np.linalg.norm(ray)
    a, b = o.reshape(-1, 3)[0] + 3.4 * ray, o.reshape(-1, 3)[0] + 4.6 * ray
    pts = np.array([a, b, a + (0.7, -0.2, -0.5), a + (-0.3, 0.6, -0.6)])
    mesh = TetMesh.from_arrays(pts, [[0, 1, 2, 3]], [0.0, 1.0, 0.4, 0.8])
    return Case("edge_along_ray", mesh, cam, _tf(mesh, units=1.5), "an edge along a pixel's ray")


def _beside_eye() -> Case:
    # The eye just outside a face of the cube, the near plane closer still: the tets at
    # that face project to hundreds of viewport widths.
    mesh = synthetic.cube(6, rotate=False)
    cam = Camera(position=(0.03, -0.02, 0.505), focal_point=(0.2, 0.1, -0.5), view_up=(0, 1, 0), view_angle=60.0,
                 clipping_range=(0.001, 5.0))
    return Case("beside_the_eye", mesh, cam, _tf(mesh), "tets just past the near plane, far outside the viewport")


def _spike_graded() -> Case:
    c = _graded()
    spike = ((0.0, 0.0), (0.29, 0.0), (0.3, 1.0), (0.31, 0.0), (0.7, 0.0), (0.72, 0.6), (1.0, 0.6))
    return Case("spike_tf_graded", c.mesh, c.camera, _tf(c.mesh, opacity=spike), "iso-layer opacity spike on a graded mesh")


def _cell_jumps() -> Case:
    mesh = synthetic.cube(5)
    values = np.random.default_rng(11).choice([0.0, 0.1, 1.0], mesh.n_tets)  # jumps of 10x at faces
    mesh = mesh.with_cell_scalars(values, name="material")
    return Case("cell_data_jumps", mesh, Camera.fit(mesh, direction=(-0.4, -0.3, -1.0)), _tf(mesh),
                "cell data with large jumps between neighbours")


def _tf_case(name: str, opacity, what: str, units: float = 4.0) -> Callable[[], Case]:
    def make() -> Case:
        mesh = synthetic.cube(4)
        return Case(name, mesh, Camera.fit(mesh, direction=(-0.4, -0.3, -1.0)), _tf(mesh, opacity=opacity, units=units), what)
    return make


CASES: dict[str, Callable[[], Case]] = {
    "slivers": _slivers,
    "needles": _needles,
    "graded_1e-6": _graded,
    "thin_perspective": _thin_perspective,
    "edge_on": _edge_on,
    "face_edge_on": _face_on,
    "tiny_coordinates": lambda: _scaled("tiny_coordinates", 1e-4, 0.0),
    "huge_coordinates": lambda: _scaled("huge_coordinates", 1.0, 1e5),
    "interlocking_rings": _rings,
    "camera_inside": _inside,
    "camera_on_face": _on_face,
    "near_plane_cut": _near_plane,
    "face_through_eye": _face_through_eye,
    "edge_along_ray": _edge_along_ray,
    "beside_the_eye": _beside_eye,
    "spike_tf_graded": _spike_graded,
    "cell_data_jumps": _cell_jumps,
    "step_tf": _tf_case("step_tf", ((0.0, 0.0), (0.499, 0.0), (0.501, 0.9), (1.0, 0.9)), "opacity step"),
    "spike_tf": _tf_case("spike_tf", ((0.0, 0.0), (0.49, 0.0), (0.5, 1.0), (0.51, 0.0), (1.0, 0.0)), "opacity spike (iso-layer)"),
    "opaque_tf": _tf_case("opaque_tf", ((0.0, 1.0), (1.0, 1.0)), "fully opaque transfer function"),
    "transparent_tf": _tf_case("transparent_tf", ((0.0, 0.0), (1.0, 0.0)), "fully transparent transfer function"),
    "thick_translucent": _tf_case("thick_translucent", ((0.0, 0.02), (1.0, 0.05)), "thick, faint volume (8-bit storage fails)", units=50.0),
}


def case(name: str) -> Case:
    """Build one stability case by name (see :data:`CASES`)."""
    try:
        return CASES[name]()
    except KeyError:
        raise ValueError(f"unknown stability case {name!r}; choose from {sorted(CASES)}") from None

"""Tetrahedral meshes from surfaces, as fine as the view needs, and fields carried onto them.

About this technique
--------------------
Meshing is fTetWild (Hu, Schneider, Wang, Zorin & Panozzo 2020, "Fast Tetrahedral
Meshing in the Wild", ACM TOG 39(4)) through the ``pytetwild`` wrapper: it takes any
triangle soup, keeps the boundary within an envelope ``epsilon`` (relative to the bounding
box diagonal) of the input surface, and aims at a target edge length.

The target comes from the scene. A projected-tetrahedra frame costs about linearly in
the number of cells, but a cell much smaller than a pixel adds no lateral detail: the
footprint of one pixel at the object, ``2 z tan(fov / 2) / H`` at eye depth ``z``
(``2 * parallel_scale / H`` for a parallel camera), bounds the useful resolution. With
``detail="screen"`` the edge length is ``pixels_per_cell`` footprints, the footprint taken
at the surface's nearest point (where it is smallest). Whether a
given field needs that much is what ``bench/meshing_study.py`` measures: the image error
against a much finer mesh, per cell and per millisecond.

fTetWild only refines while it optimises (``optimize=True``), and it never goes coarser
than the input surface's triangles unless ``coarsen=True``; the cells produced are
reported, with the time taken, in :class:`MeshingResult`.

Fields are carried onto the new points by :func:`interpolate`: from scattered points
(nearest neighbour or inverse distance weighting over the ``k`` nearest), from another
:class:`~tetvr.mesh.tetmesh.TetMesh` (the enclosing tet's barycentric interpolation, found
through a uniform grid of tet bounding boxes, all vectorised), from a
:class:`~tetvr.volume.volume.Volume` (its trilinear :meth:`~tetvr.volume.volume.Volume.sample`) or from
a function of the points. New boundary points may lie just outside a source mesh (the
envelope); ``outside="nearest"`` gives them the nearest source value.

Optional dependencies: ``pip install tetvr[mesh]`` (pytetwild, trimesh; scipy's KD-tree
is used when present). pytetwild 0.4 imports pyvista (and so VTK, 140 MB) in its
``__init__`` without declaring it; when that import fails, only its compiled wrapper
``PyfTetWildWrapper`` is loaded, which needs nothing but numpy.
"""

from __future__ import annotations

import dataclasses
import importlib.machinery
import importlib.util
import math
import os
import tempfile
import time
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.mesh.tetmesh import TetMesh

__all__ = ["DETAILS", "MeshingResult", "interpolate", "locate", "pixel_footprint", "tetrahedralize"]

#: How :func:`tetrahedralize` picks the target edge length when none is given.
DETAILS = ("screen", "surface")

# Volume of a regular tetrahedron of edge 1: estimates the cell count of a target.
_REGULAR_TET_VOLUME = 1.0 / (6.0 * math.sqrt(2.0))

Float = NDArray[np.float64]


@dataclasses.dataclass(frozen=True, eq=False)
class MeshingResult:
    """A mesh made by :func:`tetrahedralize` and how it was made.

    Attributes
    ----------
    mesh : the tetrahedral mesh, with the interpolated field.
    edge_length : target edge length handed to fTetWild (world units).
    pixel_footprint : world size of a pixel at the object (``None`` without a camera).
    detail : ``"screen"``, ``"surface"`` or ``"explicit"`` (``edge_length`` given).
    estimated_cells : cells a regular mesh of that edge length would have.
    limited : whether ``max_cells`` made the edge longer than asked.
    seconds_meshing, seconds_field : time in fTetWild and in :func:`interpolate`.
    """

    mesh: TetMesh
    edge_length: float
    pixel_footprint: float | None
    detail: str
    estimated_cells: int
    limited: bool
    seconds_meshing: float
    seconds_field: float

    @property
    def n_cells(self) -> int:
        return self.mesh.n_tets

    @property
    def n_points(self) -> int:
        return self.mesh.n_points

    def summary(self) -> str:
        foot = f", {self.edge_length / self.pixel_footprint:.2g} px" if self.pixel_footprint else ""
        return (f"{self.n_cells} tets, {self.n_points} points (target edge {self.edge_length:.4g}{foot}, "
                f"{self.detail}{', limited by max_cells' if self.limited else ''}); "
                f"fTetWild {self.seconds_meshing:.2f} s, field {self.seconds_field:.2f} s")


def pixel_footprint(camera: Camera, size: tuple[int, int], points: ArrayLike) -> float:
    """World size of one pixel at the nearest of ``points`` (n, 3) — the vertices of a
    surface, or the 8 corners of its box — clamped to the near plane. Eye depth is linear,
    so over a polyhedron it is smallest at a vertex.

    Examples
    --------
    >>> cam = Camera(position=(0, 0, 10), parallel_projection=True, parallel_scale=2.0)
    >>> pixel_footprint(cam, (100, 100), [[-1, -1, -1], [1, 1, 1]])
    0.04
    """
    width, height = (int(v) for v in size)
    if width < 1 or height < 1:
        raise ValueError(f"size must be two positive integers (width, height), got {size!r}")
    if camera.parallel_projection:
        return 2.0 * camera.parallel_scale / height
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    depth = float(((p - np.asarray(camera.position)) @ np.asarray(camera.direction)).min())
    depth = max(depth, resolve_clipping_range(camera, p).near_far()[0])
    return 2.0 * depth * math.tan(math.radians(camera.view_angle) / 2) / height


def tetrahedralize(
    surface: Any,
    *,
    camera: Camera | None = None,
    size: tuple[int, int] | None = None,
    detail: str = "screen",
    pixels_per_cell: float = 2.0,
    edge_length: float | None = None,
    field: Any = None,
    scalar_name: str = "scalars",
    epsilon: float = 1e-3,
    optimize: bool = True,
    coarsen: bool = False,
    max_cells: int = 2_000_000,
    threads: int = 0,
    **interp: Any,
) -> MeshingResult:
    """Fill a closed triangle surface with tetrahedra sized for the view.

    Parameters
    ----------
    surface : a ``trimesh.Trimesh`` or a ``(vertices (n, 3), faces (k, 3))`` pair.
    camera, size : the view and the image ``(width, height)``; needed for ``detail="screen"``.
    detail : ``"screen"``: target edge ``pixels_per_cell`` pixel footprints at the object;
        ``"surface"``: the mean edge length of the input surface.
    pixels_per_cell : target edge length in pixels (``detail="screen"``).
    edge_length : an explicit target edge length in world units; overrides ``detail``.
    field : the scalar for the new mesh, anything :func:`interpolate` takes (a TetMesh, a
        Volume, ``(points, values)``, a function of the points); ``None`` gives zeros.
    scalar_name : name of that scalar.
    epsilon : fTetWild's envelope: how far (relative to the bounding box diagonal) the
        boundary may stray from the input surface.
    optimize : let fTetWild refine and improve quality; without it the edge length is
        ignored and the mesh only conforms to the input surface.
    coarsen : let fTetWild go coarser than the input surface's triangles.
    max_cells : refuse to aim at more cells than this (estimated from the enclosed volume
        and a regular tet of the target edge): the edge is lengthened to fit, and
        ``MeshingResult.limited`` says so.
    threads : fTetWild's threads (0: all cores).
    **interp : passed to :func:`interpolate` (``method``, ``k``, ``power``, ``outside``).

    Returns
    -------
    MeshingResult
        ``.mesh`` and the counts and times.

    Examples
    --------
    >>> import trimesh                                            # doctest: +SKIP
    >>> sphere = trimesh.creation.icosphere(subdivisions=3)       # doctest: +SKIP
    >>> cam = Camera.fit(TetMesh.from_arrays(...))                # doctest: +SKIP
    >>> res = tetrahedralize(sphere, camera=cam, size=(256, 256), field=lambda p: p[:, 2])  # doctest: +SKIP
    >>> res.summary()                                             # doctest: +SKIP
    '51234 tets, ...'
    """
    vertices, faces = _surface_arrays(surface)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    diag = float(np.linalg.norm(hi - lo))
    if not diag > 0:
        raise ValueError("the surface has no extent")
    footprint = None
    if camera is not None and size is not None:
        footprint = pixel_footprint(camera, size, vertices)
    target, how = _target_edge(vertices, faces, footprint, detail, pixels_per_cell, edge_length)
    target = min(target, diag)
    target, estimate, limited = _limit_cells(vertices, faces, target, max_cells)
    pts, tets, seconds_mesh = _run_tetwild(vertices, faces, target, diag, epsilon, optimize, coarsen, threads)

    start = time.perf_counter()
    values = np.zeros(pts.shape[0]) if field is None else interpolate(pts, field, **interp)
    seconds_field = time.perf_counter() - start
    mesh = TetMesh.from_arrays(pts, tets, values, scalar_name=scalar_name)
    return MeshingResult(mesh=mesh, edge_length=target, pixel_footprint=footprint, detail=how,
                         estimated_cells=round(estimate), limited=limited, seconds_meshing=seconds_mesh,
                         seconds_field=seconds_field)


def _target_edge(vertices: Float, faces: NDArray[np.int64], footprint: float | None, detail: str,
                 pixels_per_cell: float, edge_length: float | None) -> tuple[float, str]:
    """The target edge length before any limit, and how it was chosen (see :func:`tetrahedralize`)."""
    if edge_length is not None:
        target = float(edge_length)
        if not (math.isfinite(target) and target > 0):
            raise ValueError(f"edge_length must be a positive number, got {edge_length!r}")
        how = "explicit"
    elif detail == "screen":
        if footprint is None:
            raise ValueError('detail="screen" needs camera= and size= (or give edge_length=)')
        ppc = float(pixels_per_cell)
        if not (math.isfinite(ppc) and ppc > 0):
            raise ValueError(f"pixels_per_cell must be a positive number, got {pixels_per_cell!r}")
        target = ppc * footprint
        how = "screen"
    elif detail == "surface":
        e = vertices[faces]
        target = float(np.mean(np.linalg.norm(e - np.roll(e, 1, axis=1), axis=2)))
        how = "surface"
    else:
        raise ValueError(f"detail must be one of {DETAILS}, got {detail!r}")
    return target, how


def _limit_cells(vertices: Float, faces: NDArray[np.int64], target: float,
                 max_cells: int | None) -> tuple[float, float, bool]:
    """The target lengthened where needed so that the cells estimated (from the enclosed volume
    and a regular tet of that edge) are at most ``max_cells``; that estimate; whether it was."""
    volume = abs(_enclosed_volume(vertices, faces))
    estimate = volume / (_REGULAR_TET_VOLUME * target**3)
    limited = False
    if max_cells is not None and estimate > max_cells:
        target *= (estimate / max_cells) ** (1.0 / 3.0)
        estimate = volume / (_REGULAR_TET_VOLUME * target**3)
        limited = True
    return target, estimate, limited


def _run_tetwild(vertices: Float, faces: NDArray[np.int64], target: float, diag: float, epsilon: float,
                 optimize: bool, coarsen: bool, threads: int) -> tuple[Float, NDArray[np.int64], float]:
    """fTetWild's points and tets for the surface at edge length ``target`` (run in a scratch
    directory), and the seconds it took."""
    wrapper = _tetwild()
    start = time.perf_counter()
    empty = (np.empty((0, 3)), np.empty((0, 4), np.int32), np.empty(0))
    # fTetWild writes __tracked_surface.stl into the working directory: keep it out of the
    # user's (not thread-safe: the process's working directory changes for the call).
    here = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="tetvr-tetwild-") as scratch:
        os.chdir(scratch)
        try:
            pts, tets = wrapper.tetrahedralize_mesh(
                vertices, faces.astype(np.uint32), bool(optimize), False, target / diag, target, float(epsilon),
                10.0, bool(coarsen), int(threads), 80, 6, True, False, False, *empty)
        finally:
            os.chdir(here)
    seconds = time.perf_counter() - start
    pts = np.asarray(pts, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    if tets.shape[0] == 0:
        raise ValueError("fTetWild produced no tetrahedra (is the surface closed?)")
    return pts, tets, seconds


def _surface_arrays(surface: Any) -> tuple[Float, NDArray[np.int64]]:
    if hasattr(surface, "vertices") and hasattr(surface, "faces"):
        v, f = surface.vertices, surface.faces
    elif isinstance(surface, (tuple, list)) and len(surface) == 2:
        v, f = surface
    else:
        raise TypeError(f"surface must be a trimesh.Trimesh or a (vertices, faces) pair, got {type(surface).__name__}")
    v = np.ascontiguousarray(v, dtype=np.float64)
    f = np.asarray(f)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 4:
        raise ValueError(f"surface vertices must have shape (n >= 4, 3), got {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] < 4 or f.dtype.kind not in "iu":
        raise ValueError(f"surface faces must be an integer array of shape (k >= 4, 3), got {f.dtype} {f.shape}")
    if f.min() < 0 or f.max() >= v.shape[0]:
        raise ValueError(f"surface faces index vertices outside 0..{v.shape[0] - 1}")
    if not np.all(np.isfinite(v)):
        raise ValueError("surface vertices contain NaN or Inf")
    return v, np.ascontiguousarray(f, dtype=np.int64)


def _enclosed_volume(v: Float, f: NDArray[np.int64]) -> float:
    """Signed volume enclosed by a closed triangle surface (divergence theorem)."""
    p = v[f]
    return float(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() / 6.0)


def _tetwild() -> Any:
    """pytetwild's compiled wrapper. Its package ``__init__`` imports pyvista, which it does
    not declare; without pyvista the extension module is loaded on its own."""
    try:
        from pytetwild import PyfTetWildWrapper

        return PyfTetWildWrapper
    except ImportError as exc:
        if isinstance(exc, ModuleNotFoundError) and exc.name == "pytetwild":
            raise ModuleNotFoundError("tetrahedralize needs pytetwild: pip install tetvr[mesh]") from exc
        spec = importlib.util.find_spec("pytetwild")  # found: the failure was one of its imports
    locations = list(spec.submodule_search_locations or []) if spec else []
    for folder in locations:
        for name in sorted(os.listdir(folder)):
            if name.startswith("PyfTetWildWrapper") and name.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)):
                path = os.path.join(folder, name)
                loader = importlib.machinery.ExtensionFileLoader("pytetwild.PyfTetWildWrapper", path)
                mod_spec = importlib.util.spec_from_file_location("pytetwild.PyfTetWildWrapper", path, loader=loader)
                assert mod_spec is not None
                module = importlib.util.module_from_spec(mod_spec)
                loader.exec_module(module)
                return module
    raise ModuleNotFoundError("pytetwild is installed but its compiled PyfTetWildWrapper module was not found")


# ---------------------------------------------------------------------------------
# Fields onto new points
# ---------------------------------------------------------------------------------


def interpolate(points: ArrayLike, source: Any, *, method: str = "linear", k: int = 8, power: float = 2.0,
                outside: str | float = "nearest") -> Float:
    """A field at ``points`` (n, 3) from ``source``.

    Parameters
    ----------
    points : where to evaluate.
    source : a :class:`~tetvr.mesh.tetmesh.TetMesh` (barycentric in the enclosing tet), a
        :class:`~tetvr.volume.volume.Volume` (trilinear), a ``(points, values)`` pair of scattered
        samples, or a function ``f(points) -> values``.
    method : for scattered samples: ``"idw"`` (inverse distance weighting over the ``k``
        nearest, weights ``d**-power``) or ``"nearest"``; ``"linear"`` (the default) means
        ``"idw"`` there. Ignored by the other sources.
    outside : for meshes and volumes, the value where a point lies outside the source:
        ``"nearest"`` (the nearest source point's value; for a volume, the value at the
        nearest point of its box) or a number.

    Examples
    --------
    >>> interpolate([[0.5, 0, 0]], ([[0, 0, 0], [1, 0, 0]], [0.0, 2.0]), method="idw").tolist()
    [1.0]
    """
    q = np.asarray(points, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {q.shape}")
    if not (outside == "nearest" or isinstance(outside, (int, float))):
        raise ValueError(f'outside must be "nearest" or a number, got {outside!r}')
    from tetvr.volume.volume import Volume

    if isinstance(source, TetMesh):
        return _from_mesh(q, source, outside)
    if isinstance(source, Volume):
        if outside == "nearest":
            m = source.world_to_index
            return source.sample_index(q @ m[:3, :3].T + m[:3, 3])  # positions clamp to the box
        return source.sample(q, outside=float(outside))
    if callable(source):
        out = np.asarray(source(q), dtype=np.float64)
        if out.shape != (q.shape[0],):
            raise ValueError(f"the field function returned shape {out.shape}, expected ({q.shape[0]},)")
        return out
    if isinstance(source, (tuple, list)) and len(source) == 2:
        sp = np.asarray(source[0], dtype=np.float64)
        sv = np.asarray(source[1], dtype=np.float64)
        if sp.ndim != 2 or sp.shape[1] != 3 or sv.shape != (sp.shape[0],) or sp.shape[0] == 0:
            raise ValueError(f"scattered samples must be (points (n, 3), values (n,)), got {sp.shape}, {sv.shape}")
        if method == "nearest":
            return sv[_nearest(sp, q, 1)[1][:, 0]]
        if method not in ("idw", "linear"):
            raise ValueError(f'method must be "idw", "nearest" or "linear", got {method!r}')
        kk = max(1, min(int(k), sp.shape[0]))
        dist, idx = _nearest(sp, q, kk)
        with np.errstate(divide="ignore"):
            w = 1.0 / dist**power
        exact = dist[:, 0] == 0
        w[exact] = 0.0
        w[exact, 0] = 1.0
        return (w * sv[idx]).sum(axis=1) / w.sum(axis=1)
    raise TypeError(f"source must be a TetMesh, a Volume, (points, values) or a function, got {type(source).__name__}")


def _nearest(src: Float, q: Float, k: int) -> tuple[Float, NDArray[np.int64]]:
    """Distances and indices of the k nearest source points, ascending."""
    try:
        from scipy.spatial import cKDTree
    except ImportError:  # brute force in chunks that bound memory to ~64 MB
        dist = np.empty((q.shape[0], k))
        idx = np.empty((q.shape[0], k), dtype=np.int64)
        step = max(1, (1 << 23) // max(src.shape[0], 1))
        for a in range(0, q.shape[0], step):
            d2 = ((q[a:a + step, None, :] - src[None, :, :]) ** 2).sum(axis=2)
            part = np.argpartition(d2, k - 1, axis=1)[:, :k] if k < src.shape[0] else np.tile(
                np.arange(src.shape[0]), (d2.shape[0], 1))
            dd = np.take_along_axis(d2, part, axis=1)
            order = np.argsort(dd, axis=1)
            idx[a:a + step] = np.take_along_axis(part, order, axis=1)
            dist[a:a + step] = np.sqrt(np.take_along_axis(dd, order, axis=1))
        return dist, idx
    d, i = cKDTree(src).query(q, k=k)
    return np.asarray(d, dtype=np.float64).reshape(q.shape[0], k), np.asarray(i, dtype=np.int64).reshape(q.shape[0], k)


def _from_mesh(q: Float, mesh: TetMesh, outside: str | float) -> Float:
    tet, bary = locate(mesh, q)
    found = tet >= 0
    out = np.empty(q.shape[0])
    out[found] = np.einsum("ij,ij->i", bary[found], mesh.scalars[mesh.tets[tet[found]]])
    if not np.all(found):
        if outside == "nearest":
            out[~found] = mesh.scalars[_nearest(mesh.points, q[~found], 1)[1][:, 0]]
        else:
            out[~found] = float(outside)
    return out


def locate(mesh: TetMesh, points: ArrayLike, *, tolerance: float = 1e-10,
           chunk: int = 1 << 22) -> tuple[NDArray[np.int64], Float]:
    """The tet enclosing each point and the point's barycentric coordinates in it.

    Tets are binned by bounding box into a uniform grid of about one tet per cell; each
    point is tested against the tets of its grid cell, all at once. A point on a shared
    face or edge gets one of the tets around it (the one it is deepest in).

    Returns
    -------
    tet : (n,) int64 row of ``mesh.tets``, ``-1`` outside (beyond ``tolerance`` in
        barycentric terms).
    bary : (n, 4) barycentric coordinates in that tet (0 outside), in ``mesh.tets`` order.

    Examples
    --------
    >>> m = TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]], [0, 1, 2, 3])
    >>> tet, bary = locate(m, [[0.25, 0.25, 0.25], [2, 2, 2]])
    >>> tet.tolist(), bary[0].round(3).tolist()
    ([0, -1], [0.25, 0.25, 0.25, 0.25])
    """
    q = np.asarray(points, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {q.shape}")
    grid = _tet_grid(mesh)
    n = q.shape[0]
    best_tet = np.full(n, -1, dtype=np.int64)
    best_bary = np.zeros((n, 4))
    cell = grid.cell_of(q)
    inside_box = cell >= 0
    counts = np.where(inside_box, grid.starts[np.maximum(cell, 0) + 1] - grid.starts[np.maximum(cell, 0)], 0)
    ends = np.cumsum(counts)
    first = 0
    while first < n:
        base = ends[first - 1] if first else 0
        last = max(int(np.searchsorted(ends, base + chunk, side="right")), first + 1)
        sel = np.arange(first, min(last, n))
        c = counts[sel]
        qi = np.repeat(sel, c)
        if qi.size:
            offset = np.arange(qi.size) - np.repeat(np.cumsum(c) - c, c)
            tet = grid.tet_ids[grid.starts[np.repeat(cell[sel], c)] + offset]
            lam = np.einsum("ijk,ik->ij", grid.inv[tet], q[qi] - grid.p0[tet])
            bary = np.column_stack([1.0 - lam.sum(axis=1), lam])
            depth = bary.min(axis=1)
            # The deepest candidate per point (candidates come grouped by point).
            group = np.cumsum(c[c > 0]) - c[c > 0]
            deepest = np.maximum.reduceat(depth, group)
            hit = np.nonzero(depth == np.repeat(deepest, c[c > 0]))[0]
            head = hit[np.r_[True, qi[hit][1:] != qi[hit][:-1]]]
            ok = depth[head] >= -tolerance
            best_tet[qi[head[ok]]] = tet[head[ok]]
            best_bary[qi[head[ok]]] = bary[head[ok]]
        first = int(sel[-1]) + 1
    return best_tet, best_bary


@dataclasses.dataclass(frozen=True, eq=False)
class _TetGrid:
    lo: Float
    step: Float
    dims: NDArray[np.int64]
    starts: NDArray[np.int64]  # CSR over grid cells
    tet_ids: NDArray[np.int64]
    p0: Float
    inv: Float  # (m, 3, 3): barycentric (l1, l2, l3) = inv @ (x - p0)

    def cell_of(self, q: Float) -> NDArray[np.int64]:
        ijk = np.floor((q - self.lo) / self.step).astype(np.int64)
        ok = np.all((ijk >= 0) & (ijk < self.dims), axis=1)
        ijk = np.clip(ijk, 0, self.dims - 1)
        flat = (ijk[:, 0] * self.dims[1] + ijk[:, 1]) * self.dims[2] + ijk[:, 2]
        return np.where(ok, flat, -1)


def _tet_grid(mesh: TetMesh) -> _TetGrid:
    p = mesh.points[mesh.tets]  # (m, 4, 3)
    t_lo, t_hi = p.min(axis=1), p.max(axis=1)
    lo, hi = mesh.bounds
    extent = np.maximum(hi - lo, 1e-300)
    # Cells half the size of a typical tet (a point then meets few tets' boxes), but never
    # more than ~4 per tet overall.
    size = 0.5 * float(np.median((t_hi - t_lo).max(axis=1)))
    size = max(size, float(np.prod(extent) / (4.0 * mesh.n_tets)) ** (1.0 / 3.0))
    dims = np.maximum(np.ceil(extent / size).astype(np.int64), 1)
    step = extent / dims * (1 + 1e-12)
    a = np.clip(np.floor((t_lo - lo) / step).astype(np.int64), 0, dims - 1)
    b = np.clip(np.floor((t_hi - lo) / step).astype(np.int64), 0, dims - 1)
    span = b - a + 1
    count = span.prod(axis=1)
    tet = np.repeat(np.arange(mesh.n_tets, dtype=np.int64), count)
    k = np.arange(tet.shape[0]) - np.repeat(np.cumsum(count) - count, count)
    sy, sz = span[tet, 1], span[tet, 2]
    i = a[tet, 0] + k // (sy * sz)
    j = a[tet, 1] + (k // sz) % sy
    kk = a[tet, 2] + k % sz
    flat = (i * dims[1] + j) * dims[2] + kk
    order = np.argsort(flat, kind="stable")
    starts = np.searchsorted(flat[order], np.arange(int(dims.prod()) + 1))
    edges = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)  # columns
    return _TetGrid(lo=lo, step=step, dims=dims, starts=starts, tet_ids=tet[order], p0=p[:, 0].copy(),
                    inv=np.linalg.inv(edges).astype(np.float64))

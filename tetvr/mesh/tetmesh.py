"""Tetrahedral meshes: the scene's geometry and its scalar field.

A :class:`TetMesh` is immutable and canonical: every tetrahedron is stored with positive
orientation, its vertex ids ascending apart from the last two (swapped where needed for
orientation), and the rows sorted. Two meshes that differ only in the order of their
cells, or in the order and orientation of the vertices inside a cell, are therefore
identical objects, and render identically.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.checks import warn
from tetvr.mesh.fields import _check_named_field, _field_to_scalar, _scalar_of, choose_field

__all__ = ["TetMesh", "MeshReport"]

# A tet whose volume is below this fraction of (longest edge)^3 / 6 is treated as flat.
_FLAT_RELATIVE_VOLUME = 1e-10


@dataclasses.dataclass(frozen=True)
class MeshReport:
    """What was done to the input while building a mesh (for logs and render stats)."""

    input_cells: int = 0
    dropped_degenerate: int = 0
    inverted_fixed: int = 0
    ignored_cells: tuple[tuple[str, int], ...] = ()
    scalar_source: str = "point"
    split_cells: tuple[tuple[str, int], ...] = ()  # non-tet volume cells split into tets (tetvr.mesh.cells)
    steiner_points: int = 0  # cell centroids added where a cell could not be split otherwise
    fields: tuple[str, ...] = ()  # the file's point fields, then its cell fields (by :func:`read`)
    #: How the rendered scalar comes from a field with several components: ``"magnitude"``,
    #: ``"component 1"``; empty for a scalar field (or arrays given as they are).
    scalar_of: str = ""


@dataclasses.dataclass(frozen=True, eq=False)
class TetMesh:
    """A tetrahedral mesh with one scalar per point, or one per cell.

    Build it with :meth:`TetMesh.from_arrays` or :func:`read`; the constructor expects
    arrays that are already canonical.

    Attributes
    ----------
    points : (n, 3) float64, world coordinates.
    tets : (m, 4) int32, vertex ids, positively oriented, canonical order.
    scalars : (n,) float64, the field at the points. For cell data, the cells' volume-weighted
        average around each point (what histograms and default ranges read).
    scalar_name : name of the field.
    report : what was changed from the input.
    cell_scalars : (m,) float64 or None. Cell data: the field is constant in each tet and
        these values are what is rendered, exactly (``scalars`` is then only their
        average at the points); None for point data (linear in each tet).
    """

    points: NDArray[np.float64]
    tets: NDArray[np.int32]
    scalars: NDArray[np.float64]
    scalar_name: str = "scalars"
    report: MeshReport = MeshReport()
    cell_scalars: NDArray[np.float64] | None = None

    @classmethod
    def from_arrays(
        cls,
        points: ArrayLike,
        tets: ArrayLike,
        scalars: ArrayLike,
        *,
        scalar_name: str = "scalars",
        drop_degenerate: bool = True,
        cell_scalars: ArrayLike | None = None,
    ) -> "TetMesh":
        """Validate, copy and canonicalise arrays into a mesh. The inputs are not modified.

        ``scalars`` holds one value per point. With ``cell_scalars`` (one value per tet, in
        the order of ``tets``) the mesh carries cell data, rendered constant in each tet;
        ``scalars`` may then be None (the cells' volume-weighted average is used at the
        points).

        Examples
        --------
        >>> m = TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 2, 1, 3]], [0, 1, 2, 3])
        >>> m.tets.tolist(), m.report.inverted_fixed
        ([[0, 1, 2, 3]], 1)
        """
        pts = _valid_points(points)
        t = _valid_tets(tets, pts.shape[0])
        s, c = _valid_scalars(pts, t, scalars, cell_scalars)

        t.sort(axis=1)  # t is _valid_tets's own copy
        if np.any(t[:, :-1] == t[:, 1:]):
            bad = int(np.nonzero(np.any(t[:, :-1] == t[:, 1:], axis=1))[0][0])
            raise ValueError(f"tet {bad} repeats a vertex: {np.asarray(tets)[bad].tolist()}")
        with np.errstate(over="ignore", invalid="ignore"):
            vol6 = _signed_volume6(pts, t)
            edge = _max_edge(pts, t)
        if not (np.all(np.isfinite(vol6)) and np.all(np.isfinite(edge))):
            raise ValueError(
                f"points are too large for float64 geometry (largest |coordinate| {float(np.abs(pts).max()):.3g}): "
                "tetrahedron volumes overflow; rescale the mesh"
            )
        flat = np.abs(vol6) <= _FLAT_RELATIVE_VOLUME * edge**3
        dropped = int(flat.sum())
        if dropped:
            if not drop_degenerate:
                raise ValueError(f"{dropped} tetrahedra have zero volume (first: {int(np.argmax(flat))})")
            if dropped == t.shape[0]:
                raise ValueError(f"all {dropped} tetrahedra have zero volume")
            warn(f"dropped {dropped} zero-volume tetrahedra")
        keep = ~flat
        neg = vol6 < 0
        t[neg] = t[neg][:, [0, 1, 3, 2]]
        t = t[keep].astype(np.int32)  # as the mesh holds them
        order = np.lexsort(t.T[::-1])
        t = t[order]
        if c is not None:
            c = c[keep][order]
            c.setflags(write=False)
        # Count what was actually inverted in the input, not what sorting the ids flipped.
        raw = np.asarray(tets)
        inverted = sum(int(np.sum(_signed_volume6(pts, raw[rows][keep[rows]].astype(np.int64)) < 0))
                       for rows in _blocks(raw.shape[0]))
        report = MeshReport(input_cells=int(np.asarray(tets).shape[0]), dropped_degenerate=dropped,
                            inverted_fixed=inverted)
        for arr in (pts, t, s):
            arr.setflags(write=False)
        return cls(points=pts, tets=t, scalars=s, scalar_name=scalar_name, report=report, cell_scalars=c)

    # ---- derived geometry (computed once, used by every view) ----
    @property
    def n_tets(self) -> int:
        return int(self.tets.shape[0])

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @cached_property
    def centroids(self) -> NDArray[np.float64]:
        """(m, 3) tet centroids."""
        return self.points[self.tets].mean(axis=1)

    @cached_property
    def max_edge(self) -> float:
        """Longest edge: the longest chord of any tet, so the thickest possible segment."""
        return float(_max_edge(self.points, self.tets).max())

    @cached_property
    def bounds(self) -> NDArray[np.float64]:
        """(2, 3) min and max corner of the bounding box."""
        return np.stack([self.points.min(axis=0), self.points.max(axis=0)])

    @cached_property
    def float32_origin(self) -> NDArray[np.float64]:
        """(3,) the point the GPU takes coordinates relative to, so that float32 keeps them
        precise far from the world's origin: the centre of the bounding box, unless
        :meth:`with_float32_origin` gave another."""
        origin = self.bounds.mean(axis=0)
        origin.setflags(write=False)
        return origin

    def with_float32_origin(self, origin: ArrayLike) -> "TetMesh":
        """This mesh with another :attr:`float32_origin` (same arrays, no copy).

        Parts of one mesh rendered apart (:mod:`tetvr.cluster.distributed`'s bricks) take their
        whole's origin: their points then round to the same float32 coordinates as in the
        whole, and their images composite to the whole's image. Derived meshes
        (:meth:`with_scalars`, ``dataclasses.replace``) go back to their own centre.

        Examples
        --------
        >>> from tetvr.mesh import synthetic
        >>> mesh = synthetic.cube(2)
        >>> mesh.with_float32_origin((1.0, 0.0, 0.0)).float32_origin.tolist()
        [1.0, 0.0, 0.0]
        """
        o = _as_float_array(origin, "origin")
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise ValueError(f"origin must be 3 finite numbers, got {np.asarray(origin).tolist()!r}")
        o.setflags(write=False)
        out = dataclasses.replace(self)
        out.__dict__.update(self.__dict__)  # what is cached does not depend on the origin
        out.__dict__["float32_origin"] = o  # a cached_property: seeded in the instance
        return out

    @cached_property
    def scalar_range(self) -> tuple[float, float]:
        """Smallest and largest value rendered (of the cells, for cell data)."""
        s = self.scalars if self.cell_scalars is None else self.cell_scalars
        return float(s.min()), float(s.max())

    @property
    def cell_data(self) -> bool:
        """Whether the field is cell data, rendered constant in each tet."""
        return self.cell_scalars is not None

    @cached_property
    def corner_scalars(self) -> NDArray[np.float64]:
        """(m, 4) the field at each tet's four vertices as that tet sees it: the point
        values, or the cell's value four times for cell data. What every renderer reads."""
        if self.cell_scalars is None:
            out = self.scalars[self.tets]
        else:
            out = np.repeat(self.cell_scalars[:, None], 4, axis=1)
        out.setflags(write=False)
        return out

    # ---- what users of the field hold: meshio, pyvista, vtk ----
    @classmethod
    def from_meshio(cls, mesh: Any, scalars: str | None = None, *, component: int | None = None,
                    cell_data: str = "exact") -> "TetMesh":
        """A mesh from a ``meshio.Mesh``, as :func:`read` makes one from a file (volume
        cells split into tets; ``cell_data`` as in :func:`read`).

        Examples
        --------
        >>> import meshio
        >>> m = meshio.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [("tetra", [[0, 1, 2, 3]])],
        ...                 point_data={"T": [0.0, 1.0, 2.0, 3.0]})
        >>> TetMesh.from_meshio(m).scalar_name
        'T'
        """
        blocks = [(c.type, c.data) for c in mesh.cells]
        point_data = {k: np.asarray(v) for k, v in mesh.point_data.items()}
        cell_blocks = {k: [np.asarray(b) for b in v] for k, v in mesh.cell_data.items()}
        return _from_blocks(mesh.points, blocks, point_data, cell_blocks, scalars, component, "the meshio.Mesh",
                            cell_data)

    @classmethod
    def from_pyvista(cls, grid: Any, scalars: str | None = None, *, component: int | None = None,
                     cell_data: str = "exact") -> "TetMesh":
        """A mesh from a ``pyvista`` data set or any ``vtk`` data set (``vtkUnstructuredGrid``,
        ``vtkImageData``, ...); pyvista is not needed, vtk is (it is what the object is made of).

        Unstructured grids go through tetvr's own conforming split of their volume cells;
        other data sets through VTK's ``vtkDataSetTriangleFilter``.
        """
        from vtkmodules.util.numpy_support import vtk_to_numpy

        if not hasattr(grid, "GetNumberOfCells"):
            raise TypeError(f"expected a pyvista or vtk data set, got {type(grid).__name__}")
        if not grid.IsA("vtkUnstructuredGrid"):
            from vtkmodules.vtkFiltersGeneral import vtkDataSetTriangleFilter

            tri = vtkDataSetTriangleFilter()
            tri.SetInputData(grid)
            tri.Update()
            grid = tri.GetOutput()
        if grid.GetNumberOfPoints() == 0 or grid.GetNumberOfCells() == 0:
            raise ValueError("the vtk data set has no points or no cells")
        points = vtk_to_numpy(grid.GetPoints().GetData()).astype(np.float64)
        from vtkmodules.vtkCommonCore import vtkVersion

        # GetCellTypes() returns the array from VTK 9.6 on; GetCellTypesArray() before (deprecated since).
        new_api = (vtkVersion.GetVTKMajorVersion(), vtkVersion.GetVTKMinorVersion()) >= (9, 6)
        types = vtk_to_numpy(grid.GetCellTypes() if new_api else grid.GetCellTypesArray())
        offsets = vtk_to_numpy(grid.GetCells().GetOffsetsArray()).astype(np.int64)
        conn = vtk_to_numpy(grid.GetCells().GetConnectivityArray()).astype(np.int64)
        blocks: list[tuple[str, Any]] = []
        cell_order: list[Any] = []
        for t in np.unique(types):
            name = _VTK_CELL_TYPES.get(int(t), f"vtk cell type {int(t)}")
            ids = np.nonzero(types == t)[0]
            n = offsets[ids + 1] - offsets[ids]
            if np.all(n == n[0]):  # fixed-size cells (all volume cells tetvr splits are)
                data = conn[offsets[ids][:, None] + np.arange(n[0])]
            else:
                data = np.zeros((len(ids), 0), dtype=np.int64)
            blocks.append((name, data))
            cell_order.append(ids)

        def arrays(attrs: Any) -> dict[str, NDArray[Any]]:
            out = {}
            for i in range(attrs.GetNumberOfArrays()):
                arr = attrs.GetArray(i)
                if arr is not None and arr.GetName():
                    out[arr.GetName()] = vtk_to_numpy(arr)
            return out

        point_data = arrays(grid.GetPointData())
        cell_blocks = {k: [v[ids] for ids in cell_order] for k, v in arrays(grid.GetCellData()).items()}
        return _from_blocks(points, blocks, point_data, cell_blocks, scalars, component, "the vtk data set",
                            cell_data)

    def to_pyvista(self) -> Any:
        """The mesh as a ``pyvista.UnstructuredGrid`` of tets, with its field as point data,
        or cell data for a cell field (needs pyvista: ``pip install pyvista``)."""
        try:
            import pyvista
        except ImportError:
            raise ImportError("TetMesh.to_pyvista needs pyvista: pip install pyvista") from None
        grid = pyvista.UnstructuredGrid({pyvista.CellType.TETRA: np.asarray(self.tets, dtype=np.int64)},
                                        np.asarray(self.points))
        if self.cell_scalars is None:
            grid.point_data[self.scalar_name] = np.asarray(self.scalars)
        else:
            grid.cell_data[self.scalar_name] = np.asarray(self.cell_scalars)
        grid.set_active_scalars(self.scalar_name)
        return grid

    def with_scalars(self, scalars: ArrayLike, name: str = "scalars") -> "TetMesh":
        """The same geometry with another point field."""
        s = _as_float_array(scalars, "scalars")
        if s.shape != self.scalars.shape:
            raise ValueError(f"scalars must have one value per point ({self.scalars.shape[0]}), got shape {s.shape}")
        if not np.all(np.isfinite(s)):
            raise ValueError(f"scalars contain {int(np.sum(~np.isfinite(s)))} NaN or Inf values")
        s.setflags(write=False)
        return dataclasses.replace(self, scalars=s, scalar_name=name, cell_scalars=None,
                                   report=self._report_for(name))

    def with_cell_scalars(self, cell_scalars: ArrayLike, name: str = "scalars") -> "TetMesh":
        """The same geometry with a cell field (one value per tet, in this mesh's tet
        order), rendered constant in each tet."""
        c = _as_float_array(cell_scalars, "cell_scalars")
        if c.shape != (self.n_tets,):
            raise ValueError(f"cell_scalars must have one value per tet ({self.n_tets}), got shape {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError(f"cell_scalars contain {int(np.sum(~np.isfinite(c)))} NaN or Inf values")
        s = _cell_to_point(self.points, self.tets.astype(np.int64), c)
        c.setflags(write=False)
        s.setflags(write=False)
        return dataclasses.replace(self, scalars=s, scalar_name=name, cell_scalars=c,
                                   report=self._report_for(name))

    def _report_for(self, name: str) -> MeshReport:
        """The report of this mesh with the field ``name``: the same field (a time step's
        values) keeps how it was made a scalar (``scalar_of``), another field has none."""
        return self.report if name == self.scalar_name else dataclasses.replace(self.report, scalar_of="")

    def averaged(self) -> "TetMesh":
        """Cell data made point data by volume-weighted averaging around each point (the
        field ParaView's Cell Data to Point Data filter makes); point data unchanged."""
        if self.cell_scalars is None:
            return self
        return dataclasses.replace(self, cell_scalars=None,
                                   report=dataclasses.replace(self.report, scalar_source="cell, averaged to points"))


def _valid_points(points: ArrayLike) -> NDArray[np.float64]:
    """``points`` as a new (n >= 4, 3) float64 array of finite coordinates, else an error saying what is wrong."""
    pts = _as_float_array(points, "points")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {pts.shape}")
    if pts.shape[0] < 4:
        raise ValueError(f"a tetrahedral mesh needs at least 4 points, got {pts.shape[0]}")
    if not np.all(np.isfinite(pts)):
        bad = np.argwhere(~np.isfinite(pts))[0]
        raise ValueError(f"points contain NaN or Inf (first at point {bad[0]}: {pts[bad[0]].tolist()})")
    return pts


def _valid_tets(tets: ArrayLike, n_points: int) -> NDArray[np.int64]:
    """``tets`` as an (m >= 1, 4) int64 array of ids in ``0..n_points-1`` (integral floats are
    accepted), else an error saying what is wrong."""
    try:
        t = np.asarray(tets)
    except ValueError as exc:  # ragged nested sequences
        raise ValueError(f"tets must be a rectangular integer array: {exc}") from None
    if t.dtype.kind not in "iu":
        if not (t.dtype.kind == "f" and t.size):
            raise TypeError(f"tets must be an integer array, got dtype {t.dtype}")
        # Checked before any cast: inf or 1e20 cast to int64 become -2**63, a bogus id.
        with np.errstate(invalid="ignore"):
            wrong = ~np.isfinite(t) | (t != np.round(t))
        if np.any(wrong):
            at = tuple(np.argwhere(wrong)[0])
            raise TypeError(f"tets must be an integer array, got dtype {t.dtype} holding {t[at]} "
                            f"(tet {at[0] if at else 0}: {np.atleast_1d(t[at[:1]]).tolist()})")
    if t.ndim != 2 or t.shape[1] != 4:
        raise ValueError(f"tets must have shape (m, 4), got {t.shape}")
    if t.shape[0] == 0:
        raise ValueError("the mesh has no tetrahedra")
    if t.min() < 0 or t.max() >= n_points:
        bad = t.min() if t.min() < 0 else t.max()
        shown = f"{bad:g}" if t.dtype.kind == "f" and abs(bad) >= 2**53 else int(bad)
        raise ValueError(f"tets index point {shown}, outside 0..{n_points - 1}")
    return t.astype(np.int64)


def _valid_scalars(pts: NDArray[np.float64], t: NDArray[np.int64], scalars: ArrayLike | None,
                   cell_scalars: ArrayLike | None) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """The point scalars (the cells' volume-weighted average where only ``cell_scalars`` are
    given) and the cell scalars or None, as new finite float64 arrays of the right lengths."""
    c = None
    if cell_scalars is not None:
        c = _as_float_array(cell_scalars, "cell_scalars")
        if c.ndim != 1 or c.shape[0] != t.shape[0]:
            raise ValueError(f"cell_scalars must have one value per tet ({t.shape[0]}), got shape {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValueError(f"cell_scalars contain {int(np.sum(~np.isfinite(c)))} NaN or Inf values")
        if scalars is None:
            scalars = _cell_to_point(pts, t, c)
    elif scalars is None:
        raise ValueError("give scalars (one per point) or cell_scalars (one per tet)")
    s = _as_float_array(scalars, "scalars")
    if s.ndim != 1 or s.shape[0] != pts.shape[0]:
        raise ValueError(f"scalars must have one value per point ({pts.shape[0]}), got shape {s.shape}")
    if not np.all(np.isfinite(s)):
        raise ValueError(f"scalars contain {int(np.sum(~np.isfinite(s)))} NaN or Inf values")
    return s, c


def _as_float_array(value: ArrayLike, name: str) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value)
    except ValueError as exc:  # ragged nested sequences
        raise ValueError(f"{name} must be a rectangular numeric array: {exc}") from None
    if arr.dtype.kind == "c":
        raise TypeError(f"{name} must be real, got complex dtype {arr.dtype}")
    if arr.dtype.kind not in "fiub":
        raise TypeError(f"{name} must be numeric, got dtype {arr.dtype}")
    return np.array(arr, dtype=np.float64, copy=True)


#: Tets a block of per-tet geometry is computed in: its (n, 4, 3) corners take 25 MB, not
#: 96 bytes a tet of the whole mesh at once.
_BLOCK_TETS = 1 << 18


def _blocks(n: int) -> list[slice]:
    return [slice(start, min(start + _BLOCK_TETS, n)) for start in range(0, n, _BLOCK_TETS)]


def _signed_volume6(points: NDArray[np.float64], tets: NDArray[np.integer[Any]]) -> NDArray[np.float64]:
    """(m,) six times each tet's signed volume, computed a block of tets at a time."""
    out = np.empty(tets.shape[0])
    for rows in _blocks(tets.shape[0]):
        p = points[tets[rows]]
        out[rows] = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    return out


def _max_edge(points: NDArray[np.float64], tets: NDArray[np.integer[Any]]) -> NDArray[np.float64]:
    """(m,) each tet's longest edge, computed a block of tets at a time."""
    out = np.empty(tets.shape[0])
    pairs = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
    for rows in _blocks(tets.shape[0]):
        p = [points[tets[rows, k]] for k in range(4)]
        squares = [np.einsum("ij,ij->i", p[i] - p[j], p[i] - p[j]) for i, j in pairs]
        out[rows] = np.maximum(np.maximum(np.maximum(squares[0], squares[1]), np.maximum(squares[2], squares[3])),
                               np.maximum(squares[4], squares[5]))
    return np.sqrt(out, out=out)  # one root a tet, of its longest edge's square


def _cell_column(blocks: list[NDArray[Any]]) -> NDArray[Any]:
    """A cell field held as one array per cell block, as one array (a column for a scalar)."""
    flat = np.concatenate([np.asarray(b).reshape(len(b), -1) for b in blocks])
    return flat[:, 0] if flat.shape[1] == 1 else flat


# VTK cell type ids -> meshio's cell names (the volume cells tetvr splits, and what is left out).
_VTK_CELL_TYPES = {1: "vertex", 3: "line", 5: "triangle", 7: "polygon", 9: "quad", 10: "tetra", 11: "voxel",
                   12: "hexahedron", 13: "wedge", 14: "pyramid", 24: "tetra10", 25: "hexahedron20",
                   26: "wedge15", 27: "pyramid13", 29: "hexahedron27"}


def _from_blocks(points: ArrayLike, blocks: list[tuple[str, Any]], point_data: dict[str, NDArray[Any]],
                 cell_blocks: dict[str, list[NDArray[Any]]], scalars: str | None, component: int | None,
                 where: str, cell_data: str = "exact") -> TetMesh:
    """A mesh from cell blocks and fields held in memory, as :func:`read` makes one from a file."""
    from tetvr.mesh.cells import split_cells

    exact_cells = _check_cell_data(cell_data)
    if scalars is not None and not isinstance(scalars, str):
        raise TypeError(f"scalars must be a field name (str) or None, got {scalars!r}")
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 2 and pts.shape[1] == 2:
        pts = np.c_[pts, np.zeros(pts.shape[0])]
    if "voxel" in dict(blocks):  # VTK's voxel orders its corners as a grid, a hexahedron as a loop
        blocks = [(k, np.asarray(d)[:, [0, 1, 3, 2, 4, 5, 7, 6]] if k == "voxel" else d) for k, d in blocks]
        blocks = [("hexahedron" if k == "voxel" else k, d) for k, d in blocks]
    split = split_cells(pts, blocks)
    if split.tets.shape[0] == 0:
        found = ", ".join(f"{k}: {v}" for k, v in split.ignored) or "no cells"
        raise ValueError(f"{where} contains no tetrahedra or other volume cells ({found})")
    if split.split or split.ignored:
        warn(f"{where}: {split.summary()}")
    names = list(point_data) + [n for n in cell_blocks if n not in point_data]
    named = scalars is not None
    if scalars is None:
        scalars = choose_field([(n, point_data[n] if n in point_data else _cell_column(cell_blocks[n])) for n in names],
                               component, where)
    used = np.zeros(split.points.shape[0], dtype=bool)
    used[split.tets.ravel()] = True
    if scalars in point_data:
        v = np.asarray(point_data[scalars])
        if v.shape[:1] != (pts.shape[0],):
            raise ValueError(f"{where}: point field {scalars!r} has {v.shape[0] if v.ndim else 0} values, "
                             f"but the mesh has {pts.shape[0]} points")
        values = _field_to_scalar(split.extend(v), scalars, component)
        scalar_of = _scalar_of(v, component)
        source = "point"
    elif scalars in cell_blocks:
        flat = np.concatenate([np.asarray(b).reshape(len(b), -1) for b in cell_blocks[scalars]])
        if flat.shape[0] != sum(len(d) for _, d in blocks):
            raise ValueError(f"{where}: cell field {scalars!r} has {flat.shape[0]} values, but the mesh has "
                             f"{sum(len(d) for _, d in blocks)} cells")
        col = flat[split.parent]
        cell_values = _field_to_scalar(col[:, 0] if col.shape[1] == 1 else col, scalars, component)
        cell_values = cell_values.astype(np.float64)
        scalar_of = _scalar_of(col, component)
        values = _cell_to_point(split.points, split.tets.astype(np.int64), cell_values)
        source = "cell"
    else:
        raise KeyError(f"no field named {scalars!r} in {where}; point fields: {list(point_data)}, "
                       f"cell fields: {list(cell_blocks)}")
    if named:
        _check_named_field(cell_values if source == "cell" else values, scalars, where)
    if not np.all(used):
        values = values[used]
        split = split.compacted(used)
    mesh = TetMesh.from_arrays(split.points, split.tets, values, scalar_name=scalars,
                               cell_scalars=cell_values if source == "cell" and exact_cells else None)
    report = dataclasses.replace(mesh.report, ignored_cells=split.ignored, scalar_source=source,
                                 split_cells=split.split, steiner_points=split.steiner_points, fields=tuple(names),
                                 scalar_of=scalar_of)
    return dataclasses.replace(mesh, report=report)


#: How a cell field is rendered (``read(..., cell_data=...)``).
CELL_DATA = ("exact", "average")


def _check_cell_data(cell_data: str) -> bool:
    """Whether cell fields stay cell data; refuses an unknown mode."""
    if cell_data not in CELL_DATA:
        raise ValueError(f"cell_data must be one of {CELL_DATA}, got {cell_data!r}")
    return cell_data == "exact"


def _cell_to_point(points: NDArray[np.float64], tets: NDArray[np.int64], values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Volume-weighted average of the cells around each point."""
    vol = np.abs(_signed_volume6(points, tets)) / 6.0
    num = np.bincount(tets.ravel(), weights=np.repeat(vol * values, 4), minlength=points.shape[0])
    den = np.bincount(tets.ravel(), weights=np.repeat(vol, 4), minlength=points.shape[0])
    out = np.zeros(points.shape[0])
    used = den > 0
    out[used] = num[used] / den[used]
    # Points no cell uses get the plain mean of the field; they are never rendered.
    out[~used] = values.mean() if values.size else 0.0
    return out

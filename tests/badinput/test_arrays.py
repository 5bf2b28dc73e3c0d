"""Bad arrays into ``TetMesh.from_arrays``: a specific exception naming the argument and
the offending value, or a documented repair (inverted cells flipped, zero-volume cells
dropped with a warning). The caller's arrays are never modified.

Decisions recorded here:
- coincident points are allowed; a tet that uses two coincident points has zero volume
  and is dropped with a warning; if every tet is degenerate it is a ValueError;
- integer, boolean and float16 data are converted to float64; complex data is a TypeError;
- integral float tet ids are accepted; fractional or NaN ids are a TypeError.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from tetvr import TetMesh

from ._util import POINTS, SCALARS, TETS


def _pts(**change):
    p = POINTS.copy()
    for (i, j), v in change.get("at", {}).items():
        p[i, j] = v
    return p


# (id, points, tets, scalars, exception, message regex)
BAD = [
    ("points-2d", POINTS[:, :2], TETS, SCALARS, ValueError, r"points must have shape \(n, 3\), got \(5, 2\)"),
    ("points-flat-list", POINTS.ravel(), TETS, SCALARS, ValueError, r"points must have shape \(n, 3\)"),
    ("three-points", POINTS[:3], [[0, 1, 2, 0]], SCALARS[:3], ValueError, "at least 4 points, got 3"),
    ("points-ragged", [[0, 0, 0], [1, 0]], TETS, SCALARS, ValueError, "points must be a rectangular numeric array"),
    ("points-none", None, TETS, SCALARS, TypeError, "points must be numeric, got dtype object"),
    ("points-strings", np.full((5, 3), "a"), TETS, SCALARS, TypeError, "points must be numeric"),
    ("points-complex", POINTS + 1j, TETS, SCALARS, TypeError, "points must be real, got complex"),
    ("points-nan", _pts(at={(2, 1): np.nan}), TETS, SCALARS, ValueError, r"points contain NaN or Inf \(first at point 2"),
    ("points-inf", _pts(at={(4, 0): np.inf}), TETS, SCALARS, ValueError, r"NaN or Inf \(first at point 4: \[inf"),
    ("points-overflow", POINTS * 1e300, TETS, SCALARS, ValueError, "too large.*overflow"),
    ("points-underflow", POINTS * 1e-300, TETS, SCALARS, ValueError, "all 2 tetrahedra have zero volume"),
    ("tets-3-columns", POINTS, [[0, 1, 2]], SCALARS, ValueError, r"tets must have shape \(m, 4\), got \(1, 3\)"),
    ("tets-empty", POINTS, np.zeros((0, 4), int), SCALARS, ValueError, "no tetrahedra"),
    ("tets-out-of-range", POINTS, [[0, 1, 2, 5]], SCALARS, ValueError, r"tets index point 5, outside 0\.\.4"),
    ("tets-negative", POINTS, [[0, 1, 2, -1]], SCALARS, ValueError, r"tets index point -1, outside 0\.\.4"),
    ("tets-huge-uint64", POINTS, np.array([[0, 1, 2, 2**63]], np.uint64), SCALARS, ValueError,
     r"index point 9223372036854775808"),
    ("tets-fractional", POINTS, TETS + 0.5, SCALARS, TypeError, "tets must be an integer array, got dtype float64"),
    ("tets-nan", POINTS, np.full((1, 4), np.nan), SCALARS, TypeError, "tets must be an integer array"),
    ("tets-complex", POINTS, TETS + 0j, SCALARS, TypeError, "tets must be an integer array, got dtype complex128"),
    ("tets-ragged", POINTS, [[0, 1, 2, 3], [1, 2]], SCALARS, ValueError, "tets must be a rectangular integer array"),
    ("tets-repeated-vertex", POINTS, [[0, 1, 1, 3]], SCALARS, ValueError, r"tet 0 repeats a vertex: \[0, 1, 1, 3\]"),
    ("scalars-short", POINTS, TETS, SCALARS[:3], ValueError, r"one value per point \(5\), got shape \(3,\)"),
    ("scalars-long", POINTS, TETS, np.arange(6.0), ValueError, r"one value per point \(5\), got shape \(6,\)"),
    ("scalars-2d", POINTS, TETS, np.zeros((5, 2)), ValueError, r"one value per point \(5\), got shape \(5, 2\)"),
    ("scalars-nan", POINTS, TETS, [0, 1, np.nan, 3, 4], ValueError, "scalars contain 1 NaN or Inf"),
    ("scalars-inf", POINTS, TETS, [0, -np.inf, np.inf, 3, 4], ValueError, "scalars contain 2 NaN or Inf"),
    ("scalars-complex", POINTS, TETS, SCALARS + 1j, TypeError, "scalars must be real, got complex dtype complex128"),
    ("scalars-strings", POINTS, TETS, ["a"] * 5, TypeError, "scalars must be numeric, got dtype <U1"),
    ("scalars-objects", POINTS, TETS, np.array([1, None, 2, 3, 4], dtype=object), TypeError,
     "scalars must be numeric, got dtype object"),
]


@pytest.mark.parametrize("points,tets,scalars,exc,match", [case[1:] for case in BAD], ids=[c[0] for c in BAD])
def test_bad_arrays(points, tets, scalars, exc, match):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a rejected mesh must not also spray warnings
        with pytest.raises(exc, match=match):
            TetMesh.from_arrays(points, tets, scalars)


def test_coincident_points_make_a_zero_volume_tet_that_is_dropped():
    pts = POINTS.copy()
    pts[4] = pts[3]  # point 4 coincides with point 3: tet (1, 2, 3, 4) is flat
    with pytest.warns(UserWarning, match="dropped 1 zero-volume tetrahedra"):
        mesh = TetMesh.from_arrays(pts, TETS, SCALARS)
    assert mesh.n_tets == 1 and mesh.report.dropped_degenerate == 1


def test_coincident_points_that_no_tet_joins_are_harmless():
    pts = np.vstack([POINTS, POINTS[:1]])  # a duplicate of point 0, used by nobody
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mesh = TetMesh.from_arrays(pts, TETS, np.arange(6.0))
    assert mesh.n_tets == 2 and mesh.report.dropped_degenerate == 0


def test_all_points_coincident():
    with pytest.raises(ValueError, match="all 1 tetrahedra have zero volume"):
        TetMesh.from_arrays(np.zeros((4, 3)), [[0, 1, 2, 3]], [0, 1, 2, 3])


def test_coplanar_tet_is_zero_volume():
    with pytest.raises(ValueError, match="all 1 tetrahedra have zero volume"):
        TetMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2, 3]], [0, 1, 2, 3])


def test_zero_volume_refused_when_dropping_is_off():
    pts = POINTS.copy()
    pts[4] = pts[3]
    with pytest.raises(ValueError, match=r"1 tetrahedra have zero volume \(first: 1\)"):
        TetMesh.from_arrays(pts, TETS, SCALARS, drop_degenerate=False)


def test_inverted_cells_are_flipped_and_counted():
    inverted = TETS[:, [0, 2, 1, 3]]  # both cells negatively oriented
    mesh = TetMesh.from_arrays(POINTS, inverted, SCALARS)
    assert mesh.report.inverted_fixed == 2
    assert np.array_equal(mesh.tets, TetMesh.from_arrays(POINTS, TETS, SCALARS).tets)
    p = mesh.points[mesh.tets]
    vol6 = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])
    assert np.all(vol6 > 0)


@pytest.mark.parametrize("dtype", [np.int8, np.int32, np.int64, np.uint16, np.float16, np.float32, np.bool_])
def test_integer_float16_and_bool_scalars_are_converted(dtype):
    values = (np.arange(5) % 2).astype(dtype)
    mesh = TetMesh.from_arrays(POINTS, TETS, values)
    assert mesh.scalars.dtype == np.float64
    assert np.array_equal(mesh.scalars, values.astype(np.float64))


@pytest.mark.parametrize("dtype", [np.int32, np.float16, np.float32])
def test_integer_and_float16_points_are_converted(dtype):
    mesh = TetMesh.from_arrays(POINTS.astype(dtype), TETS, SCALARS)
    assert mesh.points.dtype == np.float64 and mesh.n_tets == 2


@pytest.mark.parametrize("dtype", [np.int8, np.uint32, np.int64, np.float64])
def test_tet_index_dtypes(dtype):
    mesh = TetMesh.from_arrays(POINTS, TETS.astype(dtype), SCALARS)
    assert mesh.tets.dtype == np.int32 and mesh.n_tets == 2


def test_inputs_are_not_modified_and_stay_writeable():
    points = POINTS.copy()
    tets = TETS[:, [0, 2, 1, 3]].copy()  # inverted: the mesh reorders its copy
    scalars = SCALARS.copy()
    before = [a.copy() for a in (points, tets, scalars)]
    mesh = TetMesh.from_arrays(points, tets, scalars)
    for arr, old in zip((points, tets, scalars), before):
        assert np.array_equal(arr, old) and arr.flags.writeable
    for mine, theirs in ((mesh.points, points), (mesh.tets, tets), (mesh.scalars, scalars)):
        assert not np.shares_memory(mine, theirs)
        assert not mine.flags.writeable
    points[0, 0] = 99.0  # the caller keeps using its arrays
    assert mesh.points[0, 0] == 0.0


def test_with_scalars_validates():
    mesh = TetMesh.from_arrays(POINTS, TETS, SCALARS)
    with pytest.raises(ValueError, match=r"one value per point \(5\), got shape \(4,\)"):
        mesh.with_scalars(SCALARS[:4])
    with pytest.raises(ValueError, match="scalars contain 1 NaN or Inf"):
        mesh.with_scalars([0, 1, 2, np.nan, 4])
    with pytest.raises(TypeError, match="complex"):
        mesh.with_scalars(SCALARS + 1j)

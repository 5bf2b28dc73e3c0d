"""Unreadable mesh files: every one is a ValueError (or FileNotFoundError / KeyError /
TypeError) whose message names the file and the problem, within seconds.

Before these tests, meshio's ``sys.exit(1)`` on a rejected file ended the whole Python
process, and truncated TetGen, Tecplot, Kratos, PLY and ANSYS files made ``read`` spin
forever; every case runs under a deadline so that a regression fails instead of hanging.
"""

from __future__ import annotations

import contextlib
import io
import warnings
from pathlib import Path

import meshio
import numpy as np
import pytest

from tetvr import read

from ._util import POINTS, POST_VTK, deadline

DEADLINE_S = 20.0

# (extension, meshio write options) for the truncated copies of post.vtk.
WRITERS = {
    "vtu-binary": (".vtu", {"binary": True}),
    "vtu-ascii": (".vtu", {"binary": False}),
    "vtk-binary": (".vtk", {"binary": True}),
    "vtk-ascii": (".vtk", {"binary": False}),
    "gmsh22-ascii": (".msh", {"file_format": "gmsh22", "binary": False}),
    "gmsh41-binary": (".msh", {"file_format": "gmsh", "binary": True}),
    "ansys": (".msh", {"file_format": "ansys", "binary": False}),
    "tecplot": (".dat", {}),
    "kratos": (".mdpa", {}),
    "tetgen": (".node", {}),
    "medit": (".mesh", {}),
    "su2": (".su2", {}),
    "abaqus": (".inp", {}),
    "ply": (".ply", {"binary": False}),
}
FRACTIONS = (0.1, 0.5, 0.9)


def _read_checked(path: Path, exc: type[BaseException] = ValueError, match: str | None = None,
                  **kwargs: object) -> BaseException:
    """read(path) must raise ``exc`` naming the file, quickly, without exiting."""
    with deadline(DEADLINE_S, f"read({path.name!r})"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(exc, match=match) as info:
            read(path, **kwargs)  # type: ignore[arg-type]
    assert not isinstance(info.value, SystemExit)
    return info.value


@pytest.fixture(scope="module")
def post_small():
    """post.vtk cut to 60 tets, float64 points: small enough to write in every format."""
    m = meshio.read(POST_VTK)
    return meshio.Mesh(
        np.asarray(m.points, dtype=np.float64),
        [("tetra", m.cells_dict["tetra"][:60].astype(np.int64))],
        point_data={"Pressure": np.asarray(m.point_data["Pressure"], dtype=np.float64)},
    )


@pytest.fixture(scope="module")
def written(post_small, tmp_path_factory):
    """The small mesh written once in each format: {writer: (path, bytes)}."""
    folder = tmp_path_factory.mktemp("formats")
    out = {}
    for name, (ext, options) in WRITERS.items():
        path = folder / f"{name}{ext}"
        with contextlib.redirect_stderr(io.StringIO()):  # meshio's own warnings
            meshio.write(path, post_small, **options)
        out[name] = (path, path.read_bytes())
    return out


@pytest.mark.parametrize("fraction", FRACTIONS)
@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_truncated_file_is_a_value_error(written, tmp_path, writer, fraction):
    src, data = written[writer]
    path = tmp_path / f"cut{src.suffix}"
    path.write_bytes(data[: int(len(data) * fraction)])
    if writer == "tetgen":  # the .ele file travels with the .node file
        path.with_suffix(".ele").write_bytes(src.with_suffix(".ele").read_bytes())
    err = _read_checked(path)
    assert path.name in str(err)


@pytest.mark.parametrize("writer", ["vtu-binary", "vtu-ascii", "vtk-binary", "vtk-ascii", "gmsh41-binary",
                                    "tecplot", "tetgen", "su2"])
def test_intact_copy_reads(written, writer):
    """The files that are cut above are readable whole (so the cut is what fails)."""
    path, _ = written[writer]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mesh = read(path)  # the first field: TetGen keeps no field names
    assert mesh.n_tets == 60 and np.all(np.isfinite(mesh.scalars))


CONTENTS = {
    "garbage": b"hello, this is not a mesh 1 2 3\n" * 8,
    "binary-noise": bytes(np.random.default_rng(7).integers(0, 256, 512, dtype=np.uint8)),
    "blank-lines": b"\n   \n\t\n\n",
    "comments-only": b"# a comment\n# another\n",
}
EXTENSIONS = [".vtu", ".vtk", ".msh", ".xdmf", ".xml", ".node", ".dat", ".mdpa", ".ply", ".off",
              ".mesh", ".inp", ".su2", ".stl", ".obj", ".exo"]


@pytest.mark.parametrize("content", sorted(CONTENTS))
@pytest.mark.parametrize("ext", EXTENSIONS)
def test_file_that_is_not_a_mesh(tmp_path, ext, content):
    path = tmp_path / f"bad{ext}"
    path.write_bytes(CONTENTS[content])
    err = _read_checked(path)
    assert path.name in str(err)


@pytest.mark.parametrize("ext", [".vtu", ".vtk", ".msh", ".node", ".dat", ".xdmf"])
def test_empty_file(tmp_path, ext):
    path = tmp_path / f"empty{ext}"
    path.write_bytes(b"")
    _read_checked(path, match="empty")


def test_missing_file(tmp_path):
    _read_checked(tmp_path / "nothere.vtu", FileNotFoundError, match="nothere.vtu")


@pytest.mark.parametrize("name", ["plain_dir", "looks_like.vtu"])
def test_directory_instead_of_file(tmp_path, name):
    (tmp_path / name).mkdir()
    _read_checked(tmp_path / name, match="directory")


@pytest.mark.parametrize("name,match", [("mesh.foo", r"unknown format.*'\.foo'"),
                                        ("mesh", "no file extension")])
def test_unknown_extension(tmp_path, name, match, written):
    path = tmp_path / name
    path.write_bytes(written["vtu-binary"][1])  # a good mesh, under a name meshio cannot place
    err = _read_checked(path, match=match)
    assert ".vtu" in str(err)  # lists what can be read


def _write(tmp_path: Path, mesh: meshio.Mesh, name: str = "m.vtu") -> Path:
    path = tmp_path / name
    meshio.write(path, mesh)
    return path


def test_only_triangles(tmp_path):
    path = _write(tmp_path, meshio.Mesh(POINTS, [("triangle", np.array([[0, 1, 2], [1, 2, 3]]))],
                                        point_data={"s": np.arange(5.0)}))
    _read_checked(path, match=r"no tetrahedra.*triangle: 2")


def test_no_cells_at_all(tmp_path):
    path = _write(tmp_path, meshio.Mesh(POINTS, [], point_data={"s": np.arange(5.0)}), "m.vtk")
    err = _read_checked(path, match="no tetrahedra|cannot read mesh file")
    assert path.name in str(err)


@pytest.mark.parametrize("bad", [9, -1])
def test_tets_index_points_out_of_range(tmp_path, bad):
    path = _write(tmp_path, meshio.Mesh(POINTS, [("tetra", np.array([[0, 1, 2, bad]]))],
                                        point_data={"s": np.arange(5.0)}))
    _read_checked(path, match=rf"point {bad}\b.*0\.\.4")


def test_nan_coordinates_in_file(tmp_path):
    pts = POINTS.copy()
    pts[1, 1] = np.nan
    path = _write(tmp_path, meshio.Mesh(pts, [("tetra", np.array([[0, 1, 2, 3]]))], point_data={"s": np.arange(5.0)}))
    _read_checked(path, match=r"NaN or Inf.*point 1")


@pytest.mark.parametrize("where", ["point", "cell"])
def test_nan_scalars_in_file(tmp_path, where):
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    if where == "point":
        mesh = meshio.Mesh(POINTS, [("tetra", tets)], point_data={"s": np.array([0, 1, np.nan, 3, 4.0])})
    else:
        mesh = meshio.Mesh(POINTS, [("tetra", tets)], cell_data={"s": [np.array([1.0, np.inf])]})
    _read_checked(_write(tmp_path, mesh), match="NaN or Inf")


def test_no_fields_in_file(tmp_path):
    path = _write(tmp_path, meshio.Mesh(POINTS, [("tetra", np.array([[0, 1, 2, 3]]))]))
    _read_checked(path, match="no point or cell data")


def test_missing_scalar_name_lists_the_fields():
    err = _read_checked(POST_VTK, KeyError, match="Temperature", scalars="Temperature")
    assert "Pressure" in str(err)  # the fields that do exist


def test_scalar_name_of_wrong_type():
    with pytest.raises(TypeError, match="scalars must be a field name"):
        read(POST_VTK, 3)  # type: ignore[arg-type]


@pytest.mark.parametrize("component,exc,match", [(5, ValueError, "scalar field; component 5"),
                                                 ("x", TypeError, "component must be an integer"),
                                                 (True, TypeError, "component must be an integer")])
def test_bad_component(component, exc, match):
    with pytest.raises(exc, match=match):
        read(POST_VTK, component=component)


def test_vector_component_out_of_range(tmp_path):
    mesh = meshio.Mesh(POINTS, [("tetra", np.array([[0, 1, 2, 3]]))], point_data={"v": np.ones((5, 3))})
    with pytest.raises(ValueError, match="3 components; component 3"):
        read(_write(tmp_path, mesh), component=3)


def test_all_tets_flat_in_file(tmp_path):
    flat = POINTS * [1.0, 1.0, 0.0]
    path = _write(tmp_path, meshio.Mesh(flat, [("tetra", np.array([[0, 1, 2, 4]]))], point_data={"s": np.arange(5.0)}))
    _read_checked(path, match="all 1 tetrahedra have zero volume")


def test_integer_point_data_is_converted(tmp_path):
    mesh = meshio.Mesh(POINTS, [("tetra", np.array([[0, 1, 2, 3]]))], point_data={"s": np.arange(5, dtype=np.int32)})
    got = read(_write(tmp_path, mesh))
    assert got.scalars.dtype == np.float64 and got.scalar_range == (0.0, 3.0)

"""Mixed cells split into conforming tetrahedra (tetvr.mesh.cells), and reading them (tetvr.read).

Conformity is checked two ways that share no code with tetvr.mesh.cells: combinatorially (every
interior triangle belongs to exactly two tets, the tet volumes add up to the box) and
optically (the exact reference renderer, looking through a box of hexes whose interior
quads are not planar, must give the closed-form image; a crack or an overlap changes the
chord length some ray sees). The optical test is shown to fail on a split that does not
conform.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import tetvr
from tetvr import Camera, TetMesh, TransferFunction
from tetvr.mesh.cells import _REFERENCE, VOLUME_CELLS, cell_triangulation, split_cells
from tetvr.io.legacy_vtk import read_legacy_vtk
from tetvr.io.meshfile import read_cells
from tetvr.reference.tets import render_reference

from .conftest import shared_file

HEX_NODES = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])


@pytest.fixture(autouse=True)
def _raise_on_float_errors():
    with np.errstate(all="raise"):
        yield


# ---------------------------------------------------------------- helpers (independent of tetvr.mesh.cells)


def volume6(points, tets):
    p = points[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0])


def face_counts(tets):
    """How many tets hold each triangle (keyed by sorted vertex ids)."""
    counts: dict[tuple[int, ...], int] = {}
    for t in np.sort(np.asarray(tets), axis=1).tolist():
        for f in itertools.combinations(t, 3):
            counts[f] = counts.get(f, 0) + 1
    return counts


def assert_conforming(points, tets, box_lo, box_hi):
    """Interior triangles are shared by exactly two tets; boundary ones lie on the box and
    belong to one; the volumes tile the box exactly."""
    counts = face_counts(tets)
    assert max(counts.values()) <= 2, "a triangle is shared by three or more tets"
    for face, n in counts.items():
        if n == 1:
            p = points[list(face)]
            on_box = np.any(np.all(np.isclose(p, box_lo), axis=0) | np.all(np.isclose(p, box_hi), axis=0))
            assert on_box, f"triangle {face} is held by one tet but is not on the box: a crack"
    vol = np.abs(volume6(points, tets)).sum() / 6
    assert vol == pytest.approx(float(np.prod(np.subtract(box_hi, box_lo))), rel=1e-12)


def hex_grid(n, *, rng, jitter=0.0, shuffle=True):
    """(points, hexes) of an n^3 grid of hexes over [0, 1]^3 in VTK order; interior points
    jittered (so interior quads are not planar), ids randomly renumbered."""
    g = np.linspace(0.0, 1.0, n + 1)
    x, y, z = np.meshgrid(g, g, g, indexing="ij")
    pts = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    interior = np.all((pts > 0) & (pts < 1), axis=1)
    pts[interior] += rng.uniform(-jitter, jitter, (int(interior.sum()), 3)) / n
    idx = np.arange(pts.shape[0]).reshape(n + 1, n + 1, n + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij"))
    hexes = np.stack([idx[i + dx, j + dy, k + dz] for dx, dy, dz in HEX_NODES], axis=1)
    if shuffle:
        perm = rng.permutation(pts.shape[0])  # new id of each point
        inv = np.argsort(perm)
        pts, hexes = pts[inv], perm[hexes]
    return pts, hexes


# ---------------------------------------------------------------- the tables


@pytest.mark.parametrize("shape", ["tetra", "pyramid", "wedge", "hexahedron"])
def test_every_table_entry_tiles_its_reference_cell_face_to_face(shape):
    corners, quads, _ = _REFERENCE[shape]
    tables, centroid = cell_triangulation(shape)
    assert len(tables) == 1 << len(quads)
    pts = np.vstack([corners, corners.mean(axis=0)])
    hull = {"tetra": 1 / 6, "pyramid": 1 / 3, "wedge": 1 / 2, "hexahedron": 1.0}[shape]
    for config, local in enumerate(tables):
        assert centroid[config] == bool(np.any(local == len(corners)))
        v = volume6(pts, local)
        assert np.all(np.abs(v) > 1e-12)
        assert np.abs(v).sum() / 6 == pytest.approx(hull, rel=1e-12)
        counts = face_counts(local)
        assert max(counts.values()) <= 2
        # The quads are cut along the configured diagonal, and nowhere else.
        edges = {frozenset(e) for t in local.tolist() for e in itertools.combinations(t, 2)}
        for f, (a, b, c, d) in enumerate(quads):
            want, other = ((b, d), (a, c)) if config >> f & 1 else ((a, c), (b, d))
            assert frozenset(want) in edges and frozenset(other) not in edges


def test_the_cube_has_74_triangulations_and_the_min_id_rule_never_needs_a_centroid():
    from tetvr.mesh.cells import _face_to_face, _search_triangulations, _volume6

    corners, quads, tris = _REFERENCE["hexahedron"]
    sols = [s for s in _search_triangulations(corners, _volume6(corners, quads, tris)) if _face_to_face(s, quads, tris)]
    assert len(sols) == 74  # De Loera, Rambau & Santos, "Triangulations", the 3-cube
    assert sorted({len(s) for s in sols}) == [5, 6]
    for shape in ("hexahedron", "wedge"):
        _, quads, _ = _REFERENCE[shape]
        _, centroid = cell_triangulation(shape)
        n = len(_REFERENCE[shape][0])
        ids = np.array(list(itertools.permutations(range(n))))  # every order of the corner ids
        q = np.array(quads)
        a, b, c, d = (ids[:, q[:, m]] for m in range(4))
        config = ((np.minimum(b, d) < np.minimum(a, c)) << np.arange(len(quads))).sum(axis=1)
        assert not centroid[config].any(), shape


# ---------------------------------------------------------------- conformity


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_hex_grid_with_random_numbering_splits_conformingly(seed):
    rng = np.random.default_rng(seed)
    pts, hexes = hex_grid(4, rng=rng, jitter=0.15)
    s = split_cells(pts, [("hexahedron", hexes)])
    assert s.split == (("hexahedron", 64),) and s.steiner_points == 0 and s.conflicts == 0
    assert s.tets.shape[0] in range(5 * 64, 6 * 64 + 1)
    assert np.all(np.bincount(s.parent, minlength=64) >= 5)
    assert_conforming(s.points, s.tets, (0, 0, 0), (1, 1, 1))
    # (|volumes| add up to the box: no tet of a jittered hex is inverted.)
    mesh = TetMesh.from_arrays(s.points, s.tets, s.points[:, 0])
    assert mesh.n_tets == s.tets.shape[0]


def _mixed_box(rng):
    """A 3x3x3 box of cells of every kind: hexes, hexes cut into 2 wedges, into 6 pyramids
    (around an added centre point), into 6 Kuhn tets, and one quadratic hex; ids shuffled."""
    pts, hexes = hex_grid(3, rng=rng, jitter=0.0, shuffle=False)
    pts = list(map(tuple, pts))
    blocks: dict[str, list] = {"hexahedron": [], "wedge": [], "pyramid": [], "tetra": [], "hexahedron20": []}
    kinds = rng.permutation(np.arange(27) % 5)
    hex_faces = ((0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))
    for h, kind in zip(hexes, kinds):
        if kind == 0:
            blocks["hexahedron"].append(h)
        elif kind == 1:
            blocks["wedge"] += [h[[0, 1, 2, 4, 5, 6]], h[[0, 2, 3, 4, 6, 7]]]
        elif kind == 2:
            pts.append(tuple(np.mean([pts[i] for i in h], axis=0)))
            apex = len(pts) - 1
            blocks["pyramid"] += [list(h[list(f)]) + [apex] for f in hex_faces]
        elif kind == 3:
            kuhn = [[0, 1, 2, 6], [0, 2, 3, 6], [0, 1, 5, 6], [0, 5, 4, 6], [0, 3, 7, 6], [0, 7, 4, 6]]
            blocks["tetra"] += [h[k] for k in kuhn]
        else:  # a serendipity hex: 12 mid-edge nodes after the corners
            mids = []
            for a, b in ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)):
                pts.append(tuple((np.add(pts[h[a]], pts[h[b]])) / 2))
                mids.append(len(pts) - 1)
            blocks["hexahedron20"].append(list(h) + mids)
    pts = np.array(pts)
    perm = rng.permutation(pts.shape[0])
    out = [(k, perm[np.array(v)]) for k, v in blocks.items() if v]
    return pts[np.argsort(perm)], out


@pytest.mark.parametrize("seed", [3, 4, 5, 6])
def test_mixed_box_of_every_cell_kind_conforms(seed):
    rng = np.random.default_rng(seed)
    pts, blocks = _mixed_box(rng)
    s = split_cells(pts, blocks + [("triangle", np.zeros((2, 3), int)), ("line", np.zeros((1, 2), int))])
    assert dict(s.ignored) == {"triangle": 2, "line": 1}
    assert dict(s.split) == {k: len(v) for k, v in blocks if k != "tetra"}
    used = np.unique(s.tets)
    assert_conforming(s.points, s.tets, (0, 0, 0), (1, 1, 1))
    # Mid-edge nodes are not used; added centroids are.
    assert used.shape[0] <= s.points.shape[0]
    # Neighbouring Kuhn tets and wedge triangles claim hex quads; some hexes then need a centroid.
    print(f"seed {seed}: {s.steiner_points} centroids, {s.tets.shape[0]} tets, {s.conflicts} conflicts")
    assert s.conflicts == 0


def test_claimed_diagonals_that_no_triangulation_has_get_a_centroid_with_the_mean_scalar():
    # One hex, and a cap tet on each face holding the face's a-c half: configuration 0,
    # which no triangulation of the cube induces.
    corners, quads, _ = _REFERENCE["hexahedron"]
    pts = [tuple(p) for p in corners]
    caps = []
    for a, b, c, d in quads:
        centre = corners[[a, b, c, d]].mean(axis=0)
        outward = centre - 0.5
        pts.append(tuple(centre + 0.5 * outward))
        caps.append([a, b, c, len(pts) - 1])
    pts = np.array(pts)
    s = split_cells(pts, [("hexahedron", [list(range(8))]), ("tetra", caps)])
    assert s.steiner_points == 1 and s.conflicts == 0
    assert np.allclose(s.points[-1], 0.5)
    assert s.tets.shape[0] == 12 + 6
    counts = face_counts(s.tets)
    for cap in caps:
        assert counts[tuple(sorted(cap[:3]))] == 2  # each cap's base is shared with the hex's tets
    assert np.abs(volume6(s.points, s.tets[s.parent == 0])).sum() / 6 == pytest.approx(1.0)
    values = np.arange(pts.shape[0], dtype=float) ** 2
    assert s.extend(values)[-1] == pytest.approx(values[:8].mean())
    vec = np.c_[values, -values]
    assert np.allclose(s.extend(vec)[-1], [values[:8].mean(), -values[:8].mean()])


def test_twisted_wedge_gets_a_centroid():
    corners, quads, _ = _REFERENCE["wedge"]
    pts = [tuple(p) for p in corners]
    caps = []
    for a, b, c, d in quads:  # claim a-c on every quad: the twisted configuration 0
        centre = corners[[a, b, c, d]].mean(axis=0)
        pts.append(tuple(centre + 0.5 * (centre - corners.mean(axis=0))))
        caps.append([a, b, c, len(pts) - 1])
    s = split_cells(np.array(pts), [("wedge", [list(range(6))]), ("tetra", caps)])
    assert s.steiner_points == 1 and np.sum(s.parent == 0) == 8


def test_collapsed_hex_drops_the_tets_with_a_repeated_node():
    # A hex whose top face collapses onto an edge: a wedge written as a hex (common in FEM files).
    pts = HEX_NODES.astype(float)
    s = split_cells(pts, [("hexahedron", [[0, 1, 2, 3, 4, 5, 5, 4]])])
    assert s.dropped_repeated > 0
    assert np.abs(volume6(pts, s.tets)).sum() / 6 == pytest.approx(0.5)


def test_bad_input_is_rejected_with_the_block_named():
    with pytest.raises(ValueError, match="block 0 \\(hexahedron\\)"):
        split_cells(HEX_NODES, [("hexahedron", [[0, 1, 2]])])
    with pytest.raises(ValueError, match="outside 0..7"):
        split_cells(HEX_NODES, [("hexahedron", [[0, 1, 2, 3, 4, 5, 6, 99]])])
    assert set(VOLUME_CELLS) >= {"tetra10", "hexahedron20", "hexahedron27", "wedge15", "pyramid13"}


# ---------------------------------------------------------------- the crack test (optics)


def _box_chords(camera, size):
    o, d = camera.rays(*size)
    t0 = np.full(len(o), -np.inf)
    t1 = np.full(len(o), np.inf)
    for ax in range(3):
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (0.0 - o[:, ax]) / d[:, ax], (1.0 - o[:, ax]) / d[:, ax]
        t0 = np.maximum(t0, np.minimum(ta, tb))
        t1 = np.minimum(t1, np.maximum(ta, tb))
    return o, d, t0, np.maximum(t1, t0)


def _analytic_image(camera, size, tf_lo, tf_hi, tau, grad):
    """Closed form for a box of scalar grad . x, grayscale colour over [tf_lo, tf_hi]
    (linear in the scalar), constant extinction tau: alpha = 1 - exp(-tau L) and
    rgb = c0 (1 - e^{-tau L}) + c1 (1 - e^{-tau L} (1 + tau L)) / tau with c = c0 + c1 t."""
    o, d, t0, t1 = _box_chords(camera, size)
    length = (t1 - t0) * np.linalg.norm(d, axis=1)
    s0 = (o + t0[:, None] * d) @ grad
    ds_dl = (d / np.linalg.norm(d, axis=1)[:, None]) @ grad
    c0 = (s0 - tf_lo) / (tf_hi - tf_lo)
    c1 = ds_dl / (tf_hi - tf_lo)
    e = np.exp(-tau * length)
    rgb = c0 * (1 - e) + c1 * (1 - e * (1 + tau * length)) / tau
    img = np.zeros((len(o), 4))
    img[:, :3] = rgb[:, None]
    img[:, 3] = 1 - e
    return img.reshape(size[1], size[0], 4)


def test_rays_through_split_hexes_see_no_crack():
    rng = np.random.default_rng(11)
    pts, hexes = hex_grid(3, rng=rng, jitter=0.15)
    grad = np.array([0.7, -0.4, 0.25])
    s = split_cells(pts, [("hexahedron", hexes)])
    mesh = TetMesh.from_arrays(s.points, s.tets, s.points @ grad)
    lo, hi = -1.0, 1.5  # the colour map's range covers the field's, so colour is linear in it
    a, u = 0.6, 0.5
    tf = TransferFunction(color=((lo, 0, 0, 0), (hi, 1, 1, 1)), opacity=((lo, a), (hi, a)), unit_distance=u)
    tau = -np.log(1 - a) / u
    size = (40, 40)
    camera = Camera(position=(0.5 + 3 * 0.31, 0.5 + 3 * 0.23, 0.5 + 3), focal_point=(0.5, 0.5, 0.5),
                    view_up=(0, 1, 0), parallel_projection=True, parallel_scale=0.95, clipping_range=(0.1, 10))
    want = _analytic_image(camera, size, lo, hi, tau, grad)
    got = render_reference(mesh, camera, tf, size)
    assert want[..., 3].max() > 0.5 and (want[..., 3] == 0).any()  # the box, and empty space around it
    err = np.abs(got - want).max()
    # float32 output (relative 6e-8) and the reference's ~1e-7 bound; a crack costs ~1e-2.
    assert err < 1e-6, f"max error {err:.2e}: light leaks through (or doubles up at) a split face"

    # The test can fail: hexes split 5-ways with random parity disagree on every shared quad.
    five = [np.array([[0, 1, 2, 5], [0, 2, 3, 7], [0, 5, 7, 4], [2, 7, 5, 6], [0, 2, 7, 5]]),
            np.array([[1, 2, 3, 6], [1, 3, 0, 4], [1, 6, 4, 5], [3, 4, 6, 7], [1, 3, 4, 6]])]
    bad_tets = np.concatenate([h[five[rng.integers(2)]] for h in hexes])
    bad = TetMesh.from_arrays(pts, bad_tets, pts @ grad)
    bad_err = np.abs(render_reference(bad, camera, tf, size) - want).max()
    assert bad_err > 1e-3, f"a non-conforming split went unnoticed (error {bad_err:.2e})"


# ---------------------------------------------------------------- reading files


def _read_quietly(path, scalars=None, component=None):
    with pytest.warns(UserWarning, match="split into tetrahedra"):
        return tetvr.read(path, scalars, component=component)


def _write_vtu(path, points, cells, point_data=None, cell_data=None):
    import meshio

    meshio.write(path, meshio.Mesh(points, cells, point_data=point_data or {}, cell_data=cell_data or {}))
    return path


def test_read_splits_hexes_and_carries_point_cell_and_vector_fields(tmp_path):
    rng = np.random.default_rng(7)
    pts, hexes = hex_grid(2, rng=rng, jitter=0.0)
    top = next(h for h in hexes if pts[h[4], 2] == 1.0 and pts[h[4], 0] == 0.0 and pts[h[4], 1] == 0.0)
    tets = np.array([[top[4], top[5], top[7], len(pts)]])
    pts = np.vstack([pts, [0.25, 0.1, 1.3]])  # a tet standing on half of the hex's top face
    vel = np.c_[pts[:, 0], 2 * pts[:, 1], -pts[:, 2]]
    temp = pts @ [1.0, 2.0, 3.0]
    press = [np.arange(8.0), np.array([100.0])]
    path = _write_vtu(tmp_path / "mixed.vtu", pts, [("hexahedron", hexes), ("tetra", tets)],
                      point_data={"T": temp, "U": vel}, cell_data={"p": press, "g": [np.ones((8, 3)), np.zeros((1, 3))]})
    with pytest.warns(UserWarning, match="split into tetrahedra: 8 hexahedron"):
        mesh = tetvr.read(path, "T")
    assert mesh.report.split_cells == (("hexahedron", 8),) and mesh.report.steiner_points == 0
    assert mesh.report.scalar_source == "point"
    assert np.allclose(mesh.scalars, mesh.points @ [1.0, 2.0, 3.0])
    counts = face_counts(mesh.tets)
    assert max(counts.values()) == 2
    mag, comp, cell = (_read_quietly(path, name, component=c) for name, c in (("U", None), ("U", 1), ("p", None)))
    p = mag.points
    assert np.allclose(mag.scalars, np.linalg.norm(np.c_[p[:, 0], 2 * p[:, 1], -p[:, 2]], axis=1))
    assert np.allclose(comp.scalars, 2 * comp.points[:, 1])
    assert cell.report.scalar_source == "cell"
    # The apex of the tet is touched only by it: it takes the tet's cell value.
    apex = np.nonzero(np.all(np.isclose(cell.points, [0.25, 0.1, 1.3]), axis=1))[0][0]
    assert cell.scalars[apex] == 100.0
    assert cell.scalar_range[0] >= 0.0 and cell.scalar_range[1] == 100.0
    with pytest.raises(ValueError, match="component 3 is out of range"), pytest.warns(UserWarning):
        tetvr.read(path, "U", component=3)


def test_quadratic_cells_render_through_their_corners(tmp_path):
    corners, _, _ = _REFERENCE["hexahedron"]
    edges = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7))
    mids = np.array([(corners[a] + corners[b]) / 2 for a, b in edges])
    pts = np.vstack([corners, mids])
    path = _write_vtu(tmp_path / "q.vtu", pts, [("hexahedron20", [list(range(20))])], point_data={"s": pts[:, 2]})
    with pytest.warns(UserWarning, match="1 hexahedron20"):
        mesh = tetvr.read(path)
    assert mesh.n_points == 8  # the mid-edge nodes are left out with the rest of the unused points
    assert np.abs(volume6(mesh.points, mesh.tets)).sum() / 6 == pytest.approx(1.0)


def test_surface_only_file_is_refused(tmp_path):
    path = _write_vtu(tmp_path / "s.vtu", np.eye(3), [("triangle", [[0, 1, 2]])], point_data={"s": np.ones(3)})
    with pytest.raises(ValueError, match="no tetrahedra or other volume cells \\(triangle: 1\\)"):
        tetvr.read(path)


@pytest.mark.parametrize("binary", [False, True])
@pytest.mark.parametrize("version", ["4.2", "5.1"])
def test_legacy_vtk_reader_matches_meshio(tmp_path, binary, version):
    import meshio

    rng = np.random.default_rng(5)
    pts, blocks = _mixed_box(rng)
    blocks = [(k, v) for k, v in blocks if k != "hexahedron20"]
    n_cells = [len(v) for _, v in blocks]
    cdata = {"c": [rng.random(n) for n in n_cells], "cv": [rng.random((n, 3)) for n in n_cells]}
    m = meshio.Mesh(pts, blocks, point_data={"s": pts[:, 0], "v": pts * 2}, cell_data=cdata)
    path = tmp_path / "m.vtk"
    meshio.write(path, m, file_format="vtk" + version.replace(".", ""), binary=binary)
    points, got_blocks, pdata, cell_data = read_legacy_vtk(path)
    ref = meshio.read(path)
    assert np.allclose(points, ref.points)
    assert [k for k, _ in got_blocks] == [c.type for c in ref.cells]
    for (kind, conn), c in zip(got_blocks, ref.cells):
        # meshio numbers a wedge as its mirror image (VTK's 1 <-> 2, 4 <-> 5): the same
        # faces, so the same split.
        assert np.array_equal(conn[:, [0, 2, 1, 3, 5, 4]] if kind == "wedge" else conn, c.data)
    for k in ("s", "v"):
        assert np.allclose(pdata[k], ref.point_data[k])
    for k in ("c", "cv"):
        for a, b in zip(cell_data[k], ref.cell_data[k]):
            assert np.allclose(np.asarray(a).reshape(len(a), -1), np.asarray(b).reshape(len(b), -1))


def test_legacy_vtk_with_triangle_strips_that_meshio_refuses(tmp_path):
    text = """# vtk DataFile Version 3.0
strips
ASCII
DATASET UNSTRUCTURED_GRID
POINTS 9 float
0 0 0 1 0 0 1 1 0 0 1 0 0 0 1 1 0 1 1 1 1 0 1 1 2 0 0
CELLS 3 17
8 0 1 2 3 4 5 6 7
4 1 2 8 5
2 0 8
CELL_TYPES 3
12
6
3
CELL_DATA 3
SCALARS c double 1
LOOKUP_TABLE default
1.5 2.5 3.5
POINT_DATA 9
FIELD FieldData 1
temp 1 9 float
0 1 2 3 4 5 6 7 8
"""
    path = tmp_path / "strips.vtk"
    path.write_text(text)
    with pytest.warns(UserWarning, match="1 triangle_strip, 1 line"):
        mesh = tetvr.read(path, "temp")
    assert mesh.n_points == 8 and mesh.n_tets in (5, 6)
    cells = read_cells(path)
    assert cells.reader == "legacy-vtk"
    assert np.all(cells.cell_data["c"] == 1.5)


def test_uGridEx_mixed_cells():
    path = shared_file("tets/uGridEx.vtk")
    with pytest.warns(UserWarning, match="2 hexahedron"):
        mesh = tetvr.read(path)
    assert mesh.report.split_cells == (("hexahedron", 2),)
    assert dict(mesh.report.ignored_cells) == {"polygon": 1, "triangle_strip": 1, "quad": 1, "triangle": 2,
                                               "line": 2, "vertex": 1}
    assert mesh.n_tets == 14 and mesh.report.steiner_points == 0  # 2 hexes in 6 tets each, and the 2 tets
    # The two tets stand on the hexes' top faces: the hexes take their diagonals, so the
    # tets' bottom triangles are shared, not overlapped.
    counts = face_counts(mesh.tets)
    assert max(counts.values()) == 2
    # 6 inside each 6-tet hex, 2 on the quad between them, 1 under each tet.
    assert sum(n == 2 for n in counts.values()) == 2 * 6 + 2 + 2
    assert np.abs(volume6(mesh.points, mesh.tets)).sum() / 6 == pytest.approx(2 + 2 / 6)
    assert mesh.bounds[1].tolist() == [2.0, 1.0, 2.0]  # points only surface cells use are left out
    vec = _read_quietly(path, "vectors")
    comp = _read_quietly(path, "vectors", component=1)
    assert vec.scalar_range == pytest.approx((1.0, 2.0))
    assert comp.scalar_range == (0.0, 2.0)


def test_binary_legacy_vtk_that_meshio_refuses():
    path = shared_file("tets/CylinderLinear.vtk")
    mesh = tetvr.read(path, "vel_norm")
    assert mesh.n_tets == 1522 and mesh.scalar_range[1] == pytest.approx(1.0044, abs=1e-4)
    assert read_cells(path).reader == "legacy-vtk"


@pytest.mark.gl
def test_inverted_tets_render_bit_identically_to_fixed_ones(renderer):
    import meshio

    path = shared_file("tets/pipe_flow_init_flow.vtu")
    mesh = tetvr.read(path, "Pressure")
    raw = meshio.read(path).cells_dict["tetra"]
    assert mesh.report.inverted_fixed == raw.shape[0]  # every tet in the file is inverted
    fixed = TetMesh.from_arrays(mesh.points, raw[:, [0, 1, 3, 2]], mesh.scalars)
    assert fixed.report.inverted_fixed == 0
    assert np.array_equal(fixed.tets, mesh.tets)
    lo, hi = mesh.bounds
    tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.3,
                                 unit_distance=float(np.linalg.norm(hi - lo)) / 10)
    camera = Camera.fit(mesh, direction=(-1, -0.5, -0.8))
    a = renderer.render(mesh, camera, tf, size=(64, 64))
    b = renderer.render(fixed, camera, tf, size=(64, 64))
    assert a[..., 3].max() > 0.3
    assert np.array_equal(a, b)
    # Even bypassing canonicalisation (the raw, inverted rows), classification does not
    # depend on orientation: only float rounding and sort ties differ.
    raw_mesh = TetMesh(points=mesh.points, tets=raw.astype(np.int32), scalars=mesh.scalars)
    c = renderer.render(raw_mesh, camera, tf, size=(64, 64))
    assert np.abs(a - c).max() < 1e-4

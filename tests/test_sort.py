"""Visibility orderings: every face constraint holds, checked against a brute-force oracle.

The oracle below rebuilds the face adjacency with a Python dict and decides each face from
the raw point coordinates, sharing no code with :mod:`tetvr.mesh.adjacency` or the sorters.
"""

from __future__ import annotations

import numpy as np
import pytest

from tetvr import Camera, RenderSettings, TetMesh
from tetvr.mesh import synthetic
from tetvr.mesh import adjacency as adjacency_mod
from tetvr.order import sort as sort_mod
from tetvr.settings import SORT_METHODS
from tetvr.order.sort import SORTERS, centroid_order, mpvo_order, mpvonc_order, sort_with_stats, visibility_order, xmpvo_order

GRAPH_SORTS = [mpvo_order, mpvonc_order, xmpvo_order]


@pytest.fixture(autouse=True)
def _raise_on_float_errors():
    with np.errstate(all="raise"):
        yield


# ---------------------------------------------------------------- the oracle


def face_constraints(mesh: TetMesh, camera: Camera) -> np.ndarray:
    """(k, 2) pairs (behind, in_front) for every interior face not seen edge-on."""
    faces: dict[tuple[int, ...], list[tuple[int, int]]] = {}
    for t, tet in enumerate(mesh.tets.tolist()):
        for k in range(4):
            faces.setdefault(tuple(sorted(tet[:k] + tet[k + 1:])), []).append((t, tet[k]))
    pts = mesh.points
    eye = np.asarray(camera.position)
    pairs = []
    for f, cells in faces.items():
        if len(cells) != 2:
            continue
        (ta, apex_a), (tb, _) = cells
        a, b, c = pts[list(f)]
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        # Parallel: the eye is the point at infinity against the view direction.
        s = n @ -np.asarray(camera.direction) if camera.parallel_projection else n @ (eye - a)
        if abs(s) < 1e-9:
            continue  # edge-on: the two cells do not overlap on screen
        a_in_front = s * (n @ (pts[apex_a] - a)) > 0
        pairs.append((tb, ta) if a_in_front else (ta, tb))
    return np.array(pairs, dtype=np.int64).reshape(-1, 2)


def n_violations(order: np.ndarray, pairs: np.ndarray) -> int:
    """Faces whose front cell is drawn before the cell behind it."""
    rank = np.empty(order.size, dtype=np.int64)
    rank[order] = np.arange(order.size)
    return int(np.count_nonzero(rank[pairs[:, 0]] > rank[pairs[:, 1]]))


def assert_permutation(order: np.ndarray, n: int) -> None:
    assert order.dtype == np.uint32
    assert order.shape == (n,)
    assert np.array_equal(np.sort(order), np.arange(n))


# ---------------------------------------------------------------- meshes and views


def jittered_cube(n: int, seed: int, amount: float = 0.1) -> TetMesh:
    """cube(n) with its interior points moved randomly by up to ``amount`` cells per axis.

    The boundary stays planar, so the mesh stays convex.
    """
    base = synthetic.cube(n, rotate=False)
    rng = np.random.default_rng(seed)
    pts = base.points.copy()
    inner = np.all(np.abs(pts) < 0.5 - 1e-9, axis=1)
    pts[inner] += rng.uniform(-amount, amount, (int(inner.sum()), 3)) / n
    mesh = TetMesh.from_arrays(pts, base.tets, base.scalars)
    assert mesh.report.inverted_fixed == 0 and mesh.n_tets == base.n_tets  # still a valid mesh
    return mesh


def random_views(mesh: TetMesh, seed: int, count: int, *, parallel: bool = False) -> list[Camera]:
    rng = np.random.default_rng(seed)
    cams = [Camera.fit(mesh, parallel=parallel)]
    for _ in range(count):
        d = rng.normal(size=3)
        cams.append(Camera.fit(mesh, direction=d, zoom=float(rng.uniform(0.5, 4.0)), parallel=parallel))
    return cams


def two_cubes(offset: tuple[float, float, float]) -> TetMesh:
    """Two disjoint copies of cube(3), the second moved by ``offset``."""
    a = synthetic.cube(3)
    pts = np.concatenate([a.points, a.points + np.asarray(offset)])
    tets = np.concatenate([a.tets, a.tets + a.n_points])
    return TetMesh.from_arrays(pts, tets, np.concatenate([a.scalars, a.scalars]))


def sliver_pair() -> tuple[TetMesh, Camera, list[int]]:
    """Two tets on the face z = 0, where centroid distance gets the order wrong.

    The eye is above the face, so the upper tet is in front and must be drawn last; but
    the upper tet's apex lies far to the side, which puts its centroid farther from the
    eye than the centroid of the lower one. Returns the mesh, that camera, and the cell
    ids [lower, upper] (the canonical mesh decides which id each gets).
    """
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, -0.05], [5, 5, 0.05]]
    mesh = TetMesh.from_arrays(pts, [[0, 1, 2, 3], [0, 1, 2, 4]], [0, 1, 2, 3, 4])
    cam = Camera(position=(0.3, 0.3, 2.0), focal_point=(0.3, 0.3, 0.0))
    lower_upper = np.argsort(mesh.centroids[:, 2]).tolist()
    return mesh, cam, lower_upper


# ---------------------------------------------------------------- (1) convex meshes


@pytest.mark.parametrize("sorter", GRAPH_SORTS)
@pytest.mark.parametrize("mesh_name", ["cube4", "jittered"])
def test_convex_perspective_order_satisfies_every_face(sorter, mesh_name):
    mesh = synthetic.cube(4) if mesh_name == "cube4" else jittered_cube(5, seed=7)
    cams = random_views(mesh, seed=11, count=6)
    # The eye inside the mesh: still exact, because the test uses the eye point.
    cams.append(Camera(position=(0.05, -0.1, 0.07), focal_point=(1.0, 0.3, -0.2)))
    for cam in cams:
        pairs = face_constraints(mesh, cam)
        assert len(pairs) > 0
        order, stats = sorter(mesh, cam)
        assert_permutation(order, mesh.n_tets)
        assert n_violations(order, pairs) == 0, cam
        assert stats.n_cycle_breaks == 0
        assert stats.n_constraints + stats.n_edge_on == adjacency_mod.face_adjacency(mesh).n_interior_faces


def test_adjacency_matches_brute_force():
    mesh = jittered_cube(3, seed=3)
    adj = adjacency_mod.face_adjacency(mesh)
    assert adj is adjacency_mod.face_adjacency(mesh)  # built once
    for t, tet in enumerate(mesh.tets.tolist()):
        for k in range(4):
            face = set(tet) - {tet[k]}
            others = [u for u, other in enumerate(mesh.tets.tolist()) if u != t and face <= set(other)]
            assert adj.neighbors[t, k] == (others[0] if others else -1)
    # Outward unit normals: the tet's own centroid is on the negative side of each face.
    rel = mesh.centroids - adj.origin
    side = np.einsum("tkj,tj->tk", adj.normals, rel) - adj.offsets
    assert np.all(side < 0)
    np.testing.assert_allclose(np.linalg.norm(adj.normals, axis=2), 1.0, rtol=1e-12)
    assert adj.n_boundary_faces == 6 * 9 * 2  # two triangles per square of the six sides
    assert adj.n_interior_faces == (4 * mesh.n_tets - adj.n_boundary_faces) // 2
    assert adj.n_nonmanifold_faces == 0


def test_nonmanifold_face_is_left_unpaired():
    # Three tets on one face (two of them overlap): no neighbour is guessed.
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 0.5], [0.2, 0.2, -0.5], [0.3, 0.3, 0.9]]
    mesh = TetMesh.from_arrays(pts, [[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 2, 5]], np.zeros(6))
    adj = adjacency_mod.face_adjacency(mesh)
    assert adj.n_nonmanifold_faces == 1 and adj.n_interior_faces == 0
    assert np.all(adj.neighbors == -1) and np.all(adj.mates == -1)
    order, stats = mpvonc_order(mesh, Camera.fit(mesh))
    assert_permutation(order, 3)
    assert stats.n_constraints == 0


# ---------------------------------------------------------------- (2) where centroid fails


def test_centroid_order_breaks_a_face_that_mpvonc_keeps():
    mesh, cam, lower_upper = sliver_pair()
    pairs = face_constraints(mesh, cam)
    assert pairs.tolist() == [lower_upper]  # the lower tet is behind
    assert centroid_order(mesh, cam).tolist() == lower_upper[::-1]
    assert n_violations(centroid_order(mesh, cam), pairs) == 1
    for sorter in GRAPH_SORTS:
        order, stats = sorter(mesh, cam)
        assert order.tolist() == lower_upper
        assert stats.n_cycle_breaks == 0


def test_centroid_order_fails_on_some_views_of_a_jittered_mesh():
    mesh = jittered_cube(4, seed=5, amount=0.2)
    bad_centroid = 0
    for cam in random_views(mesh, seed=2, count=8):
        pairs = face_constraints(mesh, cam)
        bad_centroid += n_violations(centroid_order(mesh, cam), pairs)
        assert n_violations(mpvonc_order(mesh, cam)[0], pairs) == 0
    assert bad_centroid > 0


# ---------------------------------------------------------------- (3) disconnected meshes


@pytest.mark.parametrize("sorter", GRAPH_SORTS)
def test_disconnected_mesh_keeps_faces_of_each_component(sorter):
    mesh = two_cubes((1.7, 0.4, -0.3))
    for cam in random_views(mesh, seed=4, count=5):
        order, stats = sorter(mesh, cam)
        assert_permutation(order, mesh.n_tets)
        assert n_violations(order, face_constraints(mesh, cam)) == 0
        assert stats.n_cycle_breaks == 0


def test_mpvonc_draws_a_hidden_component_first():
    # Second cube straight behind the first along the view direction, with a gap: every
    # one of its cells must be drawn before any cell of the front cube.
    view = np.array([0.3, -0.2, -1.0])
    view /= np.linalg.norm(view)
    mesh = two_cubes(tuple(2.5 * view))
    front_cells = mesh.n_tets // 2
    # Which half is which: from_arrays sorts the tets, so look at the centroids.
    is_back = mesh.centroids @ view > 1.25
    assert is_back.sum() == front_cells
    cam = Camera.fit(mesh, direction=view, zoom=1.5)
    order, _ = mpvonc_order(mesh, cam)
    assert np.all(is_back[order[: front_cells]])
    # MPVO has no depth between components: it interleaves them, the reason for MPVONC.
    order_mpvo, _ = mpvo_order(mesh, cam)
    assert not np.all(is_back[order_mpvo[: front_cells]])


# ---------------------------------------------------------------- (4) determinism, invariance


@pytest.mark.parametrize("method", ["mpvo", "mpvonc", "xmpvo"])
def test_deterministic_and_invariant_to_input_listing(method):
    mesh = jittered_cube(4, seed=9)
    cam = Camera.fit(mesh, direction=(0.4, -1.0, 0.2))
    first = visibility_order(mesh, cam, method)
    assert_permutation(first, mesh.n_tets)
    assert np.array_equal(first, visibility_order(mesh, cam, method))
    # The same cells listed in another order, with their vertices rotated: the canonical
    # mesh, and so the order, is the same. A fresh mesh object also rebuilds the adjacency.
    rng = np.random.default_rng(1)
    tets = mesh.tets[rng.permutation(mesh.n_tets)][:, [1, 2, 0, 3]]
    again = TetMesh.from_arrays(mesh.points, tets, mesh.scalars)
    assert np.array_equal(again.tets, mesh.tets)
    assert np.array_equal(first, visibility_order(again, cam, method))


def test_registered_everywhere():
    for method in ("mpvo", "mpvonc", "xmpvo"):
        assert method in SORTERS and method in SORT_METHODS
        assert RenderSettings(sort=method).sort == method
    mesh = synthetic.cube(2)
    cam = Camera.fit(mesh)
    ids, stats = sort_with_stats(mesh, cam, "mpvonc")
    assert np.array_equal(ids, visibility_order(mesh, cam, "mpvonc"))
    assert stats.method == "mpvonc" and stats.n_cells == mesh.n_tets and stats.n_steps > 1
    ids, stats = sort_with_stats(mesh, cam, "centroid")
    assert np.array_equal(ids, centroid_order(mesh, cam)) and stats.n_cycle_breaks == 0
    with pytest.raises(ValueError, match="unknown sort method"):
        sort_with_stats(mesh, cam, "bogus")
    with pytest.raises(ValueError, match="depth_window"):
        mpvonc_order(mesh, cam, depth_window=-1.0)


# ---------------------------------------------------------------- (5) parallel projection


def test_parallel_projection_uses_the_view_direction():
    # The eye point is above the face (z = 1) but looks up, away from it: in perspective
    # the upper tet is in front; with a parallel projection the viewer is at z = -inf.
    mesh, _, lower_upper = sliver_pair()
    persp = Camera(position=(0.3, 0.3, 1.0), focal_point=(0.3, 0.3, 2.0), clipping_range=(0.01, 10.0))
    para = Camera(position=(0.3, 0.3, 1.0), focal_point=(0.3, 0.3, 2.0), parallel_projection=True)
    for sorter in GRAPH_SORTS:
        assert sorter(mesh, persp)[0].tolist() == lower_upper
        assert sorter(mesh, para)[0].tolist() == lower_upper[::-1]


@pytest.mark.parametrize("sorter", GRAPH_SORTS)
def test_parallel_views_satisfy_every_face(sorter):
    mesh = jittered_cube(4, seed=13)
    for cam in random_views(mesh, seed=6, count=5, parallel=True):
        order, stats = sorter(mesh, cam)
        assert n_violations(order, face_constraints(mesh, cam)) == 0
        assert stats.n_cycle_breaks == 0


def test_axis_aligned_parallel_view_drops_edge_on_faces():
    # Looking straight down z at an unrotated grid, every vertical face is edge-on.
    mesh = synthetic.cube(3, rotate=False)
    cam = Camera(position=(0.0, 0.0, 3.0), view_up=(0.0, 1.0, 0.0), parallel_projection=True)
    order, stats = mpvonc_order(mesh, cam)
    assert stats.n_edge_on > 0 and stats.n_cycle_breaks == 0
    assert n_violations(order, face_constraints(mesh, cam)) == 0


# ---------------------------------------------------------------- cycles


def test_cycle_is_broken_once_and_counted(monkeypatch):
    # Real meshes seen from outside rarely have cycles (Delaunay meshes never do), so the
    # face graph is replaced. The six tets of the centre hex of cube(3) form a ring around
    # its diagonal, each sharing a face with the next: the ring is oriented into a cycle,
    # and each cell outside it that touches the ring waits for its ring neighbour.
    mesh = synthetic.cube(3, rotate=False)
    adj = adjacency_mod.face_adjacency(mesh)
    centre = np.flatnonzero(np.all(np.abs(mesh.centroids) < 1 / 6, axis=1))
    assert centre.size == 6
    ring = [int(centre[0])]
    while len(ring) < 6:
        ring.append(next(int(u) for u in adj.neighbors[ring[-1]] if u in centre and u not in ring))
    assert ring[0] in adj.neighbors[ring[-1]]
    cycle = list(zip(ring, ring[1:] + ring[:1]))  # (behind, in front)
    outer = [(r, int(u)) for r in ring for u in adj.neighbors[r] if u >= 0 and u not in ring]
    assert len(outer) == 12

    def cyclic_graph(adj, camera):
        front = np.full((mesh.n_tets, 4), -1, dtype=np.int32)
        clear = np.ones((mesh.n_tets, 4), dtype=bool)
        for back, ahead in cycle + outer:
            k = int(np.flatnonzero(adj.neighbors[back] == ahead)[0])
            front[back, k] = adj.mates[back, k]
            clear.reshape(-1)[adj.mates[back, k]] = False
        return front, clear

    monkeypatch.setattr(sort_mod, "_face_graph", cyclic_graph)
    cam = Camera.fit(mesh)
    for sorter in GRAPH_SORTS:
        order, stats = sorter(mesh, cam)
        assert_permutation(order, mesh.n_tets)
        assert stats.n_cycle_breaks == 1
        # The cell drawn early is on the cycle: exactly one cycle edge is broken, and no
        # cell that merely waits for the cycle is drawn before it.
        assert n_violations(order, np.array(cycle)) == 1
        assert n_violations(order, np.array(outer)) == 0
        assert np.array_equal(order, sorter(mesh, cam)[0])

"""bench/tile_coherence.py: which tiles' corner rays cross the same cells, and what a pass
that fills such tiles would skip."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from tetvr import Camera, TetMesh

from .test_bench_speed_charts import _load


@pytest.fixture(scope="module")
def tc():
    module = _load("tile_coherence")
    assert not any(Path(p).resolve() == Path(module.__file__).parent for p in sys.path if p)
    return module


def test_uniform_tiles_agree_and_skip_all_but_their_corners(tc):
    count, hashes = np.ones((5, 5), np.int64), np.full((5, 5), 7, np.uint64)
    out = tc.coherence(count, hashes, (2,))
    t = out["tiles"]["2"]
    # Four whole 2x2 tiles (the last row and column are the far corners), 3 pixels each skipped.
    assert t["tiles_covered"] == 4 and t["tiles_agreeing"] == 1.0
    assert t["pixels_skipped"] == pytest.approx(12 / 25) and t["segments_skipped"] == pytest.approx(12 / 25)
    assert out["adjacent"] == 1.0 and out["segments_per_ray"] == 1.0


def test_a_differing_corner_spoils_every_tile_it_is_a_corner_of(tc):
    count, hashes = np.ones((5, 5), np.int64), np.full((5, 5), 7, np.uint64)
    hashes[2, 2] = 8  # the corner the four tiles share
    assert tc.coherence(count, hashes, (2,))["tiles"]["2"]["tiles_agreeing"] == 0.0
    hashes[2, 2], count[0, 4] = 7, 2  # same hash, another count: a corner of one tile only
    t = tc.coherence(count, hashes, (2,))["tiles"]["2"]
    assert t["tiles_agreeing"] == 0.75 and t["pixels_skipped"] == pytest.approx(9 / 25)
    assert t["segments_skipped"] == pytest.approx(9 / 26)


def test_cell_sets_from_the_reference(tc):
    # Two tets sharing the face x + y + z = 1 (points 1, 2, 3), seen along -z: a ray through
    # the shared triangle crosses both, one beside it only the first.
    pts = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]]
    mesh = TetMesh.from_arrays(pts, [[0, 1, 2, 3], [1, 2, 3, 4]], [0.0, 1.0, 2.0, 3.0, 4.0])
    cam = Camera(position=(0.5, 0.5, 5), focal_point=(0.5, 0.5, 0), parallel_projection=True, parallel_scale=0.6)
    count, hashes = tc.cell_sets(mesh, cam, (32, 32))
    assert set(np.unique(count)) == {0, 1, 2}
    for n in (1, 2):  # equal counts here mean equal sets
        assert np.unique(hashes[count == n]).size == 1
    assert np.all(hashes[count == 0] == 0) and hashes[count == 1][0] != hashes[count == 2][0]
    out = tc.coherence(count, hashes, (2, 4))
    assert 0.0 < out["tiles"]["4"]["segments_skipped"] < out["tiles"]["2"]["segments_skipped"] < 1.0

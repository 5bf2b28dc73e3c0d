"""Flat slivers at a mesh's hull: tet marching walks them as the reference does.

Three pieces of the ~1M-tet fTetWild torus of ``bench/corpus.py`` (``tests/data/
torus_hull_pieces.npz``): the cells round the rays that went wrong in
``bench/vs_vtk.py``'s fitted view, and two tiny cells at the corners of that mesh's
bounding box, so that the records' origin, hence every float32 rounding, is the whole
mesh's. The camera is that view's (:data:`tests.test_rim_faces.NEEDLE_CAMERA`).

- *walk* (87 cells, 512x512): pixel (423, 333)'s ray enters a sliver (volume 5e-13, three
  hull faces) beside an edge and leaves it by a hull face 4e-13 later, entering the mesh
  again 0.004 further on. The walk by face planes took the nearest of the sliver's nearly
  coinciding planes, the face into the next cell, and crossed that cell from outside it:
  alpha 0.51 against 0.34.
- *fold* (428 cells round one ray, 1024x1024): pixel (853, 656)'s ray crosses slivers,
  whose scalar gradient is the scalar's change over a tiny height; the walk by planes
  took the scalar where it left one from that gradient in float32, off by enough
  to shift the colour of every cell after it (0.0096 off in the whole mesh, alpha right;
  in this piece 0.0075 once the walk leaves slivers by the face that holds the ray).
  Pixel (851, 647)'s ray leaves the mesh beside an edge and enters again at once through
  the face beside it, which the rasteriser left out for that pixel; with more than
  ``LIST_LENGTH`` entries a pixel here, the next entry came from a peel pass, which
  missed it (alpha 0.69 against 0.78).
- *cycle* (32 cells, 1024x1024): round pixel (851, 669)'s ray five hull faces of flat
  slivers lie within 4e-9 of one another along it, entries and exits; rays left by one
  and entered by the next in turn, a march pass each, until the 64-layer bound (64
  full-screen passes a frame). Such a ray is now traced again.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tetvr import TetMesh, TransferFunction
from tetvr.reference.tets import render_reference

from .test_rim_faces import NEEDLE_CAMERA, marcher  # noqa: F401 - marcher: the fixture

PIECES = np.load(Path(__file__).parent / "data" / "torus_hull_pieces.npz")
# The pieces' transfer functions: the walk's over its own made-up field; the fold's is the
# whole torus's default (bench/vs_vtk.py's), over the torus's field.
WALK_TF = TransferFunction.preset("viridis", (-1.78, -1.66), opacity=[(0.0, 0.6), (1.0, 0.9)], unit_distance=0.01)
FOLD_TF = TransferFunction.preset("viridis", (-1.5937574834869113, 1.655738514683475), opacity=0.5,
                                  unit_distance=0.19404975560487758)


def _piece(name: str) -> TetMesh:
    return TetMesh.from_arrays(PIECES[f"{name}_points"], PIECES[f"{name}_tets"], PIECES[f"{name}_values"])


@pytest.mark.gl
@pytest.mark.parametrize("name, tf, size, pixels", [
    ("walk", WALK_TF, 512, [(423, 333)]),
    ("fold", FOLD_TF, 1024, [(853, 656), (851, 647)]),
])
def test_tet_marching_walks_slivers_at_the_hull(marcher, name, tf, size, pixels):
    mesh = _piece(name)
    want = render_reference(mesh, NEEDLE_CAMERA, tf, (size, size))
    got = marcher.render(mesh, NEEDLE_CAMERA, tf, size=(size, size))
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    for row, col in pixels:
        assert want[row, col, 3] > 0.3  # the rays cross the pieces
        assert err[row, col] < 1e-3, ((row, col), err[row, col], got[row, col], want[row, col])
    assert err.max() < 1e-3 and np.count_nonzero(err > 1 / 255) == 0, (err.max(), np.unravel_index(err.argmax(), err.shape))
    if name == "fold":
        assert not marcher._march.last_stats.entry_list  # the peel passes' path


@pytest.mark.gl
def test_a_ray_entering_coinciding_hull_faces_in_turn_is_traced_again(marcher):
    mesh = _piece("cycle")
    size = (1024, 1024)
    got = marcher.render(mesh, NEEDLE_CAMERA, FOLD_TF, size=size)
    stats = marcher._march.last_stats
    assert stats.entry_list and stats.n_suspect > 0
    assert not stats.layers_exhausted and stats.layers <= 4, stats  # before: 64 layers
    want = render_reference(mesh, NEEDLE_CAMERA, FOLD_TF, size)
    err = np.abs(got.astype(np.float64) - want).max(axis=-1)
    assert err.max() < 1e-3 and np.count_nonzero(err > 1 / 255) == 0, err.max()

"""``method="auto"``'s cost model (tetvr.order.method): its inputs against what the ray
caster walks, its coefficients against the fit bench/cost_model.py writes, and the
choices it makes where the methods' costs and accuracy differ."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import tetvr
from tetvr import Camera, RenderSettings
from tetvr.mesh import synthetic
from tetvr.order.method import (AUTO_MARGIN, LLVMPIPE, CostModel, choose, entering_rays, order_exact,
                                predicted_seconds)
from tetvr.render import default_transfer_function

FIT = Path(__file__).resolve().parents[1] / "bench" / "results" / "cost_model.json"


@pytest.fixture(scope="module")
def marcher():
    with tetvr.Renderer(RenderSettings(method="raymarch")) as r:
        yield r


def test_the_coefficients_are_the_fitted_ones():
    """LLVMPIPE holds what bench/cost_model.py fitted on the corpus (rerun it after
    vs_vtk.py and copy its coefficients): the docs quote the fit's JSON."""
    fit = json.loads(FIT.read_text())
    assert CostModel(**fit["fitted_ns"]) == LLVMPIPE
    assert fit["llvmpipe_ns"] == fit["fitted_ns"] and fit["auto_margin"] == AUTO_MARGIN


@pytest.mark.parametrize("parallel", [True, False])
def test_entering_rays_count_the_pixels_a_convex_mesh_covers(marcher, parallel):
    mesh = synthetic.cube(4)
    cam = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0), parallel=parallel)
    for size in ((64, 64), (200, 160)):
        covered = np.count_nonzero(marcher.segment_counts(mesh, cam, size=size))
        estimate = entering_rays(mesh, cam, size)
        # Perspective scales each face at its centroid: a few per cent.
        assert abs(estimate / covered - 1.0) < (0.03 if parallel else 0.1), (size, estimate, covered)


def test_shapes_off_the_image_count_nothing():
    """A view from close by that crops the mesh: what lies beside the image is not paid
    for (the estimate falls with the field of view, as the pixels the mesh covers do)."""
    mesh = synthetic.cube(8)
    wide = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0))
    close = Camera.fit(mesh, direction=(-0.3, -0.2, -1.0), zoom=4.0)
    size = (256, 256)
    assert entering_rays(mesh, close, size) <= size[0] * size[1] * 1.05
    assert entering_rays(mesh, close, size) > entering_rays(mesh, wide, size)


def test_auto_takes_projected_tetrahedra_only_where_exact_and_clearly_faster():
    cube = synthetic.cube(3)
    cam = Camera.fit(cube)
    # A few large cells at a large size: each ray's setup outweighs the few triangles.
    cost = predicted_seconds(cube, cam, (1024, 1024))
    assert AUTO_MARGIN * cost["projected"] < cost["raymarch"]
    assert choose(RenderSettings(), cube, cam, (1024, 1024)) == "projected"
    assert choose(RenderSettings(), cube, cam, (256, 256)) == "raymarch"
    # Not where the cell order would not be exact: a centroid sort, a non-convex mesh.
    assert not order_exact(RenderSettings(sort="centroid"), cube)
    assert choose(RenderSettings(sort="centroid"), cube, cam, (1024, 1024)) == "raymarch"
    rings = synthetic.interlocking_rings(6, 1)
    cam_rings = Camera.fit(rings)
    cost = predicted_seconds(rings, cam_rings, (2048, 2048))
    assert AUTO_MARGIN * cost["projected"] < cost["raymarch"]  # predicted faster, and yet
    assert choose(RenderSettings(), rings, cam_rings, (2048, 2048)) == "raymarch"
    # Nor from inside, nor close to the mesh.
    inside = Camera(position=(0.05, 0.0, 0.0), focal_point=(1.0, 0.2, 0.1), view_up=(0, 0, 1), view_angle=60.0)
    assert choose(RenderSettings(), cube, inside, (1024, 1024)) == "raymarch"


def test_a_near_tie_keeps_tet_marching():
    """The held-out scene nearest a tie (bench/results/cost_model.json: cell data at
    1024x1024, projected tetrahedra measured 0.97 of tet marching's time, predicted 1.01):
    within the margin, "auto" keeps the more accurate method."""
    mesh = synthetic.cube(16)
    x = mesh.centroids
    levels = np.floor(4.0 * (0.5 + 0.5 * np.sin(5.0 * x[:, 0]) * np.cos(4.0 * x[:, 1] + 2.0 * x[:, 2]))) / 4.0
    mesh = mesh.with_cell_scalars(levels, name="level")
    cam = Camera.fit(mesh, direction=(-0.6, -0.4, -1.0))
    cost = predicted_seconds(mesh, cam, (1024, 1024))
    assert cost["projected"] < AUTO_MARGIN * cost["raymarch"] and cost["raymarch"] < AUTO_MARGIN * cost["projected"]
    assert order_exact(RenderSettings(), mesh)
    assert choose(RenderSettings(), mesh, cam, (1024, 1024)) == "raymarch"


def test_auto_s_projected_frame_is_the_reference_s_picture():
    """Where "auto" takes projected tetrahedra for speed, the picture is as right as tet
    marching's (a convex mesh in MPVO's exact order)."""
    mesh = synthetic.cube(1)
    cam = Camera.fit(mesh, direction=(-0.4, -0.25, -1.0))
    size = (896, 896)  # few cells, many pixels: the model predicts projected tetrahedra 1.9x faster
    assert choose(RenderSettings(), mesh, cam, size) == "projected"
    from tetvr.reference.tets import render_reference_pixels

    tf = default_transfer_function(mesh, opacity=0.6)
    image = tetvr.render(mesh, camera=cam, tf=tf, size=size).reshape(-1, 4)
    pixels = np.arange(0, size[0] * size[1], 37)  # every 37th pixel: rows and columns all sampled
    ref = render_reference_pixels(mesh, cam, tf, size, pixels)
    diff = np.abs(image[pixels].astype(np.float64) - ref).max(axis=-1)
    assert ref[:, 3].max() > 0.3 and diff.max() < 1e-3 and np.count_nonzero(diff > 1 / 255) == 0

"""The VTK-parity optics (RenderSettings.optics): closed forms, table, reference and GPU.

``"linear"`` is tau = a/u integrated exactly; ``"vtk"`` is the fragment formula of VTK's
projected tetrahedra (mean end colour, alpha = 1 - exp(-L (a0 + a1) / 2u)). Neither needs
VTK: they are checked against closed forms, brute-force quadrature and tetvr's own CPU
reference. Against VTK itself: tests/test_vtkcompare.py.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import tetvr
from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.core.image import psnr
from tetvr.optics.model import OPTICS, integrate_linear_pieces, vtk_segments
from tetvr.optics.preintegrate import build_table
from tetvr.reference.tets import render_reference
from tetvr.reference.integrate import integrate_segments
from tetvr.settings import PARITY_SETTINGS

from .conftest import save_failure


def march_linear(c0, c1, a0, a1, length, u, n=100_000):
    """Brute force for tau = a/u: exact exponential per step, midpoint colour and tau
    (second order; converged to ~1e-10 at this n, checked by doubling it)."""
    f = (np.arange(n) + 0.5) / n
    tau = (a0 + (a1 - a0) * f) / u
    step = tau * length / n
    theta = np.cumsum(step)
    weight = -np.expm1(-step) * np.exp(-(theta - step))
    return (weight[:, None] * (c0 + (c1 - c0) * f[:, None])).sum(axis=0), theta[-1]


def test_linear_pieces_match_fine_quadrature():
    rng = np.random.default_rng(7)
    n = 40
    c0, c1 = rng.random((n, 3)), rng.random((n, 3))
    a0, a1 = rng.random(n), rng.random(n)
    a0[:5] = 0.0  # transparent front
    a1[5:10] = 1.0
    length = rng.random(n) * np.array([0.01, 1.0, 10.0, 100.0])[rng.integers(0, 4, n)]
    with np.errstate(all="raise", under="ignore"):
        rgb, theta = integrate_linear_pieces(c0, c1, a0, a1, length, 0.3)
    for i in range(n):
        want_rgb, want_theta = march_linear(c0[i], c1[i], a0[i], a1[i], length[i], 0.3)
        assert theta[i] == pytest.approx(want_theta, rel=1e-12, abs=1e-15)
        np.testing.assert_allclose(rgb[i], want_rgb, atol=2e-8, err_msg=f"piece {i}")


def test_vtk_segment_is_the_mean_colour_times_alpha():
    c0, c1 = np.array([[1.0, 0.0, 0.2]]), np.array([[0.0, 1.0, 0.2]])
    rgb, theta = vtk_segments(c0, c1, np.array([0.2]), np.array([0.8]), np.array([2.0]), 4.0)
    assert theta[0] == pytest.approx(2.0 * 0.5 / 4.0)
    np.testing.assert_allclose(rgb[0], np.array([0.5, 0.5, 0.2]) * -np.expm1(-0.25), rtol=1e-14)
    # At constant opacity the exact integral weights the front colour more (it is seen
    # through less material): VTK's formula ignores the attenuation inside the segment.
    half = np.array([0.5])
    exact, theta_e = integrate_linear_pieces(c0, c1, half, half, np.array([8.0]), 4.0)
    vtk, theta_v = vtk_segments(c0, c1, half, half, np.array([8.0]), 4.0)
    assert theta_e[0] == pytest.approx(theta_v[0])
    assert exact[0, 0] > vtk[0, 0] + 0.02 and exact[0, 1] < vtk[0, 1] - 0.02


@pytest.mark.parametrize("a", [0.1, 0.5, 0.9])
def test_slab_alpha_in_each_convention(a):
    """A slab 0.3 thick, viewed through its normal: exact is 1-(1-a)^(L/u); VTK's is 1-exp(-aL/u)."""
    mesh = synthetic.slab(thickness=0.3, width=1.0, value=0.5, n=2)
    tf = TransferFunction(color=((0, 1.0, 0.5, 0.0), (1, 1.0, 0.5, 0.0)), opacity=((0, a), (1, a)), unit_distance=0.2)
    cam = Camera(position=(0.01, 0.02, 3.0), focal_point=(0.01, 0.02, 0.0), parallel_projection=True,
                 parallel_scale=0.01, clipping_range=(1.0, 5.0))
    want = {"exact": 1.0 - (1.0 - a) ** (0.3 / 0.2), "linear": -np.expm1(-a * 0.3 / 0.2),
            "vtk": -np.expm1(-a * 0.3 / 0.2)}
    for optics in OPTICS:
        px = render_reference(mesh, cam, tf, (1, 1), optics=optics)[0, 0]
        assert px[3] == pytest.approx(want[optics], abs=1e-6), optics
        np.testing.assert_allclose(px[:3], np.array([1.0, 0.5, 0.0]) * px[3], atol=1e-6)


@pytest.mark.parametrize("optics", ["linear", "vtk"])
def test_table_matches_segment_integrals(optics):
    """The table's trilinear lookup against the reference's segment integrator, at random
    (front, back, thickness) between the nodes and slices. Bound 6e-3, as for the default
    optics (measured at N = 128: 5.0e-3 "exact", 3.4e-3 "linear", 2.7e-3 "vtk"): the
    colour between log-thickness slices and the transfer function's kinks between nodes."""
    tf = TransferFunction.preset("viridis", (0.0, 1.0), opacity=[(0, 0.05), (0.4, 0.9), (0.6, 0.2), (1, 0.6)],
                                 unit_distance=0.2)
    table = build_table(tf, (0.0, 1.0), 1.0, n_bins=128, n_slices=16, optics=optics)
    rng = np.random.default_rng(3)
    sf, sb = rng.random(400), rng.random(400)
    d = np.exp(rng.uniform(np.log(1e-3), 0.0, 400))
    got = table.lookup(sf, sb, d)
    rgb, theta = integrate_segments(sf, sb, d, tf, optics=optics)
    np.testing.assert_allclose(got[:, 3], -np.expm1(-theta), atol=6e-3)
    np.testing.assert_allclose(got[:, :3], rgb, atol=6e-3)


def test_unknown_optics_is_rejected():
    tf = TransferFunction.preset("grayscale", (0.0, 1.0))
    with pytest.raises(ValueError, match="optics"):
        RenderSettings(optics="paraview")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="optics"):
        build_table(tf, (0.0, 1.0), 1.0, n_bins=8, n_slices=2, optics="paraview")
    mesh = synthetic.single_tet()
    with pytest.raises(ValueError, match="optics"):
        render_reference(mesh, Camera.fit(mesh), tf, (4, 4), optics="paraview")
    settings = RenderSettings.from_dict(PARITY_SETTINGS.to_dict())  # the scene JSON round trip
    assert settings == PARITY_SETTINGS and settings.optics == "vtk"


def _scene(parallel: bool):
    mesh = synthetic.cube(6)
    lo, hi = mesh.scalar_range
    tf = TransferFunction(color=((lo, 0.1, 0.2, 0.9), (0.5 * (lo + hi), 0.2, 0.9, 0.3), (hi, 1.0, 0.8, 0.1)),
                          opacity=((lo, 0.2), (hi, 0.9)), unit_distance=0.3)
    return mesh, tf, Camera.fit(mesh, parallel=parallel)


@pytest.mark.gl
@pytest.mark.parametrize("parallel", [True, False])
def test_gpu_parity_follows_the_vtk_formula(parallel):
    """PARITY_SETTINGS on the GPU take VTK's steps (tetvr.gl.vtkpt; against VTK itself:
    tests/test_vtkcompare.py), so they follow VTK's formula, the reference in VTK's
    convention, as VTK does: with a transfer function linear between the vertices only
    VTK's 8-bit truncation of the vertex colours and opacities and, in perspective, its
    square-root table (thicknesses rounded down) remain, both biased dark. Measured on
    cube(6) at 96x96: 59.9 / 57.2 dB (parallel / perspective), max 2.4 / 4.5 steps of 1/255,
    11 / 83 pixels beyond 2/255, mean alpha error -0.24 / -0.40 steps. Bars: 55 dB, max
    6/255, at most 200 pixels beyond 2/255, mean alpha error in (-1/255, 0)."""
    mesh, _, cam = _scene(parallel)
    lo, hi = mesh.scalar_range
    tf = TransferFunction(color=((lo, 0.1, 0.2, 0.9), (hi, 1.0, 0.8, 0.1)), opacity=((lo, 0.2), (hi, 0.9)),
                          unit_distance=0.3)
    want = render_reference(mesh, cam, tf, (96, 96), optics="vtk")
    with tetvr.Renderer(PARITY_SETTINGS) as r:
        got = r.render(mesh, cam, tf, size=(96, 96))
    err = np.abs(got.astype(np.float64) - want).max(axis=-1) * 255
    covered = want[..., 3] > 0.01
    bias = float((got[..., 3] - want[..., 3])[covered].mean()) * 255
    value, beyond = psnr(got, want), int((err > 2.0).sum())
    if value < 55.0 or err.max() > 6.0 or beyond > 200 or not -1.0 < bias < 0.0:
        pytest.fail(f"{value:.1f} dB, max {err.max():.1f}/255, {beyond} pixels beyond 2/255, alpha bias "
                    f"{bias:.2f}/255 (images in {save_failure(f'parity_{parallel}', got, want)})")


@pytest.mark.gl
def test_parity_thickness_table_zeroes_thin_cells():
    """VTK's perspective thickness comes from a 2,048-entry square-root table over
    [0, max_edge^2], indexed by truncation: a tet thinner than max_edge / 45 (here 0.15
    against 14.1 / 45 = 0.31) has thickness 0 in perspective, and is invisible in parity
    as in VTK; in a parallel view (exact thickness) and in the default optics it shows."""
    big = [[20, 0, 0], [30, 0, 0], [20, 10, 0], [20, 0, 10]]  # out of view; only sets max_edge
    small = [[0, 0, 0], [0.15, 0, 0], [0, 0.15, 0], [0, 0, 0.15]]
    mesh = tetvr.TetMesh.from_arrays(np.array(big + small, float), [[0, 1, 2, 3], [4, 5, 6, 7]], np.full(8, 0.5))
    view = tetvr.TetMesh.from_arrays(np.array(small, float), [[0, 1, 2, 3]], np.full(4, 0.5))
    tf = TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)), opacity=((0, 1.0), (1, 1.0)), unit_distance=0.05)
    with tetvr.Renderer(PARITY_SETTINGS) as r, tetvr.Renderer(RenderSettings(method="projected")) as exact:
        for parallel in (True, False):
            cam = Camera.fit(view, direction=(0.3, 0.2, -1.0), parallel=parallel)
            alpha = r.render(mesh, cam, tf, size=(32, 32))[..., 3].max()
            assert alpha > 0.5 if parallel else alpha == 0.0
            assert exact.render(mesh, cam, tf, size=(32, 32))[..., 3].max() > 0.5


@pytest.mark.gl
def test_gpu_linear_optics_matches_linear_reference():
    """tau = a/u, pre-integrated exactly, perspective-correct: as accurate as the default
    optics (bar 70 dB; measured 102 dB on cube(6))."""
    mesh, tf, cam = _scene(False)
    want = render_reference(mesh, cam, tf, (96, 96), optics="linear")
    with tetvr.Renderer(RenderSettings(optics="linear")) as r:
        got = r.render(mesh, cam, tf, size=(96, 96))
    assert psnr(got, want) > 70.0


@pytest.mark.gl
def test_exact_and_parity_differ_measurably():
    """What VTK's convention changes: the same transfer function renders more transparent
    (tau = a/u <= -ln(1 - a)/u), here by ~30 dB of PSNR, far above both renderers' error."""
    mesh, tf, cam = _scene(False)
    exact = render_reference(mesh, cam, tf, (96, 96), optics="exact")
    parity = render_reference(mesh, cam, tf, (96, 96), optics="vtk")
    covered = exact[..., 3] > 0.05
    assert psnr(exact, parity) < 35.0
    assert np.all(parity[..., 3][covered] < exact[..., 3][covered])
    assert parity[..., 3][covered].mean() < 0.9 * exact[..., 3][covered].mean()
    with tetvr.Renderer(dataclasses.replace(PARITY_SETTINGS, optics="exact")) as r:
        gpu_exact = r.render(mesh, cam, tf, size=(96, 96))
    assert psnr(gpu_exact, exact) > 60.0 > psnr(gpu_exact, parity)

"""The one-call facade: ``tetvr.render(mesh, camera=..., tf=..., size=...)``."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.core.checks import warn
from tetvr.core.camera import Camera, check_clipping_range
from tetvr.mesh.tetmesh import TetMesh
from tetvr.order.precision import GPU_MIN_RELATIVE_RANGE
from tetvr.settings import RenderSettings
from tetvr.optics.transfer import (DEFAULT_OPACITY_RAMP, TransferFunction, default_unit_distance, field_range,
                                   paraview_unit_distance)

__all__ = ["render", "default_transfer_function"]

def _tf_range(lo: float, hi: float) -> tuple[float, float]:
    """A field's range ``(lo, hi)`` as a transfer function's range the GPU can resolve.

    A constant field, or one whose variation float32 cannot resolve, gets a small interval
    above ``lo``, wide enough that the GPU's float32 scalars (~6e-8 relative rounding) stay
    near its start (1e-6 would be only ~15 float32 steps); other ranges are kept.

    >>> _tf_range(5.0, 5.0), _tf_range(0.0, 0.0), _tf_range(1.0, 2.0)
    ((5.0, 5.005), (0.0, 0.001), (1.0, 2.0))
    """
    if hi - lo <= GPU_MIN_RELATIVE_RANGE * max(abs(lo), abs(hi)):
        hi = lo + max(abs(lo), 1.0) * 1e-3
    return lo, hi


def default_transfer_function(
    mesh: TetMesh,
    *,
    preset: str = "viridis",
    opacity: float | Sequence[tuple[float, float]] | None = None,
    scalar_range: tuple[float, float] | None = None,
    unit_distance: float | None = None,
) -> TransferFunction:
    """The default transfer function of a mesh: the one rule of :mod:`tetvr.optics.transfer`.

    The range spans the 1st..99.5th percentile of the field weighted by volume
    (:func:`~tetvr.optics.transfer.robust_range`), the opacity ramps up quadratically across it
    (:data:`~tetvr.optics.transfer.DEFAULT_OPACITY_RAMP`) so that high values stand out, and the
    unit distance is 1/20 of the mesh's diagonal (:func:`~tetvr.optics.transfer.default_unit_distance`).
    Each can be given instead; ``preset`` is any name :func:`tetvr.optics.colormaps.colormap`
    takes (tetvr's presets, matplotlib's colormaps).

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> tf = default_transfer_function(synthetic.cube(2), preset="hot")
    >>> tf.opacity[0][1], tf.opacity[-1][1]  # transparent at the bottom of the range, 0.9 at the top
    (0.0, 0.9)
    """
    from tetvr.optics.colormaps import colormap

    # robust_range widens a constant field's range as _tf_range does; a given range is the caller's.
    rng = field_range(mesh) if scalar_range is None else scalar_range
    u = default_unit_distance(mesh.bounds) if unit_distance is None else unit_distance
    op = DEFAULT_OPACITY_RAMP if opacity is None else opacity
    if opacity is None and scalar_range is None and mesh.scalar_range[0] == mesh.scalar_range[1]:
        # A constant field sits at the bottom of its widened range, where the ramp is
        # transparent: show it at the ramp's top opacity instead of hiding it.
        op = DEFAULT_OPACITY_RAMP[-1][1]
    return colormap(preset, rng, opacity=op, unit_distance=u)  # type: ignore[arg-type]


def _paraview_unit(mesh: TetMesh) -> float:
    return paraview_unit_distance(mesh.bounds, mesh.n_tets)


def _warn_if_invisible(mesh: TetMesh, tf: TransferFunction) -> None:
    """Warn when the most opaque value would still be nearly transparent across the whole
    mesh: a unit distance in other units than the mesh's (1.0 on a 2 cm mesh, say)."""
    a_max = max(a for _, a in tf.opacity)
    if a_max <= 0.0 or a_max >= 1.0:
        return  # transparent on purpose, or opaque at any thickness
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    alpha = -np.expm1(diag / tf.unit_distance * np.log1p(-a_max))
    if alpha < 0.05:
        warn(
            f"the picture will be nearly blank: at most {alpha:.2g} opacity across the whole mesh (its diagonal is "
            f"{diag:.3g}, the transfer function's unit_distance {tf.unit_distance:.3g}); give a unit_distance in the "
            f"mesh's units, e.g. TransferFunction.preset(..., mesh=mesh) or unit_distance={diag / 20:.3g}")


def render(
    mesh: TetMesh,
    *,
    camera: Camera | None = None,
    tf: TransferFunction | None = None,
    size: tuple[int, int] = (512, 512),
    settings: RenderSettings | None = None,
    method: str = "gpu",
    **kwargs: Any,
) -> NDArray[np.float32]:
    """Render a mesh to a premultiplied float RGBA image of shape (height, width, 4).

    Parameters
    ----------
    mesh : the tetrahedral mesh (see :func:`tetvr.read`).
    camera : defaults to :meth:`Camera.fit`; a camera whose clipping range leaves none of
        the mesh visible is warned about (:func:`tetvr.core.camera.check_clipping_range`).
    tf : defaults to :func:`default_transfer_function` (the data-driven default); a
        function that would leave the picture nearly blank is warned about. With
        ``settings.optics == "vtk"`` (VTK parity) its unit distance is ParaView's default.
    size : (width, height).
    settings : GPU method settings.
    method : ``"gpu"`` (OpenGL; ``settings.method`` picks projected tetrahedra or tet
        marching) or ``"reference"`` (the exact CPU ray caster,
        :func:`tetvr.reference.tets.render_reference`).
    **kwargs : passed on to :meth:`tetvr.Renderer.render` or
        :func:`tetvr.reference.tets.render_reference`; both take ``clip`` (a :class:`tetvr.Clip`:
        keep part of the mesh, cut exactly) and ``surfaces`` (a sequence of
        :class:`tetvr.Surface`: opaque geometry that ends the rays it meets).

    Examples
    --------
    >>> import tetvr                                           # doctest: +SKIP
    >>> image = tetvr.render(tetvr.read("mesh.vtu"), size=(256, 256))  # doctest: +SKIP
    """
    if not isinstance(mesh, TetMesh):
        raise TypeError(f"mesh must be a TetMesh (see tetvr.read), got {type(mesh).__name__}")
    for name, value, cls in (("camera", camera, Camera), ("tf", tf, TransferFunction),
                             ("settings", settings, RenderSettings)):
        if value is not None and not isinstance(value, cls):
            raise TypeError(f"{name} must be a {cls.__name__} or None, got {type(value).__name__}")
    if camera is None:
        camera = Camera.fit(mesh)
    else:
        check_clipping_range(camera, mesh.points)  # a blank picture is said, not silent
    if tf is None:
        parity = settings is not None and settings.optics == "vtk"
        # VTK parity: ParaView's default unit distance (diagonal / cube root of the cells).
        tf = default_transfer_function(mesh, unit_distance=_paraview_unit(mesh) if parity else None)
    else:
        _warn_if_invisible(mesh, tf)
    if method == "reference":
        from tetvr.reference.tets import render_reference

        if settings is not None:
            kwargs.setdefault("optics", settings.optics)
        return render_reference(mesh, camera, tf, size, **kwargs)
    if method != "gpu":
        raise ValueError(f"method must be 'gpu' or 'reference', got {method!r}")
    from tetvr.gl.renderer import Renderer

    with Renderer(settings) as renderer:
        return renderer.render(mesh, camera, tf, size=size, **kwargs)

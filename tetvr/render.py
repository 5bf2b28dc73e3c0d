"""The one-call facade: ``tetvr.render(mesh, camera=..., tf=..., size=...)``, for a
tetrahedral mesh or a CT/MR volume, with the same defaults for both."""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.core.checks import warn
from tetvr.core.camera import Camera, check_clipping_range
from tetvr.mesh.tetmesh import TetMesh
from tetvr.order.precision import GPU_MIN_RELATIVE_RANGE
from tetvr.reference.volume import RaycastSettings
from tetvr.volume.volume import Volume
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
    mesh: TetMesh | Volume,
    *,
    preset: str = "viridis",
    opacity: float | Sequence[tuple[float, float]] | None = None,
    scalar_range: tuple[float, float] | None = None,
    unit_distance: float | None = None,
) -> TransferFunction:
    """The default transfer function of a mesh or a volume: the one rule of
    :mod:`tetvr.optics.transfer`.

    The range spans the 1st..99.5th percentile of the field weighted by volume
    (:func:`~tetvr.optics.transfer.field_range`; a volume's voxels weigh the same), the
    opacity ramps up quadratically across it (:data:`~tetvr.optics.transfer.DEFAULT_OPACITY_RAMP`)
    so that high values stand out (and the air around a CT is transparent), and the unit
    distance is 1/20 of the bounding box's diagonal (:func:`~tetvr.optics.transfer.default_unit_distance`).
    Each can be given instead; ``preset`` is any name :func:`tetvr.optics.colormaps.colormap`
    takes (tetvr's presets, matplotlib's colormaps).

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> tf = default_transfer_function(synthetic.cube(2), preset="hot")
    >>> tf.opacity[0][1], tf.opacity[-1][1]  # transparent at the bottom of the range, 0.9 at the top
    (0.0, 0.9)
    >>> default_transfer_function(Volume.from_array(np.arange(1000.0).reshape(10, 10, 10))).domain
    (9.5, 994.5)
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


#: A picture whose most opaque pixel stays below this opacity is warned about as nearly
#: blank: no pixel moves more than a tenth of the way from the background to its colour
#: (at most 25 of 255 levels, for the colour farthest from the background), which reads as
#: an empty frame. The default transfer function reaches 0.97 to 1.0 on every mesh in the
#: shared data, ten times this.
BLANK_ALPHA = 0.1


def _warn_if_blank(image: NDArray[np.float32], data: TetMesh | Volume, tf: TransferFunction) -> NDArray[np.float32]:
    """``image``, with a warning when it is nearly blank (:data:`BLANK_ALPHA`), measured on
    the picture itself: a bound such as "the most opaque value across the whole diagonal"
    misses a mesh whose most opaque values fill only a thin part of it (a 2 cm cylinder
    with a unit distance of 1: bound 0.077, picture 0.018). Where the unit distance is the
    likely cause (a slab of the most opaque value as thick as the diagonal stays below 0.9),
    the warning says which unit distance the data's size asks for."""
    reached = float(np.max(image[..., 3]))
    a_max = max(a for _, a in tf.opacity)
    if reached >= BLANK_ALPHA or a_max <= 0.0:
        return image  # visible, or transparent on purpose
    diag = float(np.linalg.norm(data.bounds[1] - data.bounds[0]))
    slab = 1.0 if a_max >= 1.0 else float(-np.expm1(diag / tf.unit_distance * np.log1p(-a_max)))
    if slab < 0.9:
        hint = (f"the data's diagonal is {diag:.3g}, the transfer function's unit_distance {tf.unit_distance:.3g}: "
                f"give a unit_distance in the data's units, e.g. TransferFunction.preset(..., mesh=mesh) or "
                f"unit_distance={diag / 20:.3g}")
    else:
        hint = ("is the data in the camera's view, and is the transfer function opaque over the values it holds "
                f"(its range {tf.domain[0]:.4g} .. {tf.domain[1]:.4g})?")
    warn(f"the picture is nearly blank: its most opaque pixel reaches {reached:.2g} opacity; {hint}")
    return image


def render(
    mesh: TetMesh | Volume,
    *,
    camera: Camera | None = None,
    tf: TransferFunction | None = None,
    size: tuple[int, int] = (512, 512),
    settings: RenderSettings | RaycastSettings | None = None,
    method: str = "gpu",
    **kwargs: Any,
) -> NDArray[np.float32]:
    """Render a mesh or a volume to a premultiplied float RGBA image of shape (height, width, 4).

    Parameters
    ----------
    mesh : the tetrahedral mesh (see :func:`tetvr.read`), or a CT/MR
        :class:`~tetvr.Volume` (see :func:`tetvr.read_volume`), ray cast by
        :class:`tetvr.Raycaster` (or, with ``method="reference"``,
        :func:`tetvr.reference.volume.render_volume_reference`).
    camera : defaults to :meth:`Camera.fit`; a camera whose clipping range leaves none of
        the data visible is warned about (:func:`tetvr.core.camera.check_clipping_range`).
    tf : defaults to :func:`default_transfer_function` (the data-driven default, the same
        rule for meshes and volumes); a picture that comes out nearly blank (its most
        opaque pixel below :data:`BLANK_ALPHA`) is warned about. With ``settings.optics == "vtk"`` (VTK parity) its unit distance
        is ParaView's default.
    size : (width, height).
    settings : GPU method settings: a :class:`RenderSettings` for a mesh, a
        :class:`~tetvr.RaycastSettings` for a volume.
    method : ``"gpu"`` (OpenGL; ``settings.method`` picks projected tetrahedra or tet
        marching) or ``"reference"`` (the exact CPU ray caster,
        :func:`tetvr.reference.tets.render_reference`).
    **kwargs : passed on to :meth:`tetvr.Renderer.render` or
        :func:`tetvr.reference.tets.render_reference`; both take ``clip`` (a :class:`tetvr.Clip`:
        keep part of the mesh, cut exactly) and ``surfaces`` (a sequence of
        :class:`tetvr.Surface`: opaque geometry that ends the rays it meets). A volume takes
        ``t_start`` and ``t_end`` (per-pixel eye-depth limits, :meth:`tetvr.Raycaster.render`).

    Examples
    --------
    >>> import tetvr                                           # doctest: +SKIP
    >>> image = tetvr.render(tetvr.read("mesh.vtu"), size=(256, 256))  # doctest: +SKIP
    >>> image = tetvr.render(tetvr.read_volume("head.nhdr"))  # doctest: +SKIP
    """
    if isinstance(mesh, Volume):
        return _render_volume(mesh, camera=camera, tf=tf, size=size, settings=settings, method=method, **kwargs)
    if not isinstance(mesh, TetMesh):
        raise TypeError(f"mesh must be a TetMesh (see tetvr.read) or a Volume (see tetvr.read_volume), "
                        f"got {type(mesh).__name__}")
    _check_types(camera, tf, settings, RenderSettings, "a mesh")
    if camera is None:
        camera = Camera.fit(mesh)
    else:
        check_clipping_range(camera, mesh.points)  # a blank picture is said, not silent
    if tf is None:
        parity = settings is not None and settings.optics == "vtk"  # type: ignore[union-attr]
        # VTK parity: ParaView's default unit distance (diagonal / cube root of the cells).
        tf = default_transfer_function(mesh, unit_distance=_paraview_unit(mesh) if parity else None)
    if method == "reference":
        from tetvr.reference.tets import render_reference

        if settings is not None:
            kwargs.setdefault("optics", settings.optics)  # type: ignore[union-attr]
        return _warn_if_blank(render_reference(mesh, camera, tf, size, **kwargs), mesh, tf)
    _check_method(method)
    from tetvr.gl.framesize import check_frame, frame_method
    from tetvr.gl.renderer import Renderer

    # What any GL needs of the host, before the context is made; the renderer checks the rest.
    check_frame(size, frame_method(settings, mesh.n_tets, order=kwargs.get("order"),  # type: ignore[arg-type]
                                   shader=kwargs.get("shader", "tet")),
                software=None, surfaces=bool(kwargs.get("surfaces")), context_made=False)
    with Renderer(settings) as renderer:  # type: ignore[arg-type]
        return _warn_if_blank(renderer.render(mesh, camera, tf, size=size, **kwargs), mesh, tf)


def _check_types(camera: Any, tf: Any, settings: Any, settings_cls: type, what: str) -> None:
    for name, value, cls in (("camera", camera, Camera), ("tf", tf, TransferFunction),
                             ("settings", settings, settings_cls)):
        if value is not None and not isinstance(value, cls):
            hint = f" ({what} takes {cls.__name__})" if name == "settings" else ""
            raise TypeError(f"{name} must be a {cls.__name__} or None, got {type(value).__name__}{hint}")


def _check_method(method: str) -> None:
    if method != "gpu":
        raise ValueError(f"method must be 'gpu' or 'reference', got {method!r}")


def _render_volume(volume: Volume, *, camera: Camera | None, tf: TransferFunction | None, size: tuple[int, int],
                   settings: Any, method: str, **kwargs: Any) -> NDArray[np.float32]:
    """:func:`render` for a volume: the same defaults, the volume ray caster."""
    _check_types(camera, tf, settings, RaycastSettings, "a volume")
    other = sorted(set(kwargs) - {"t_start", "t_end"})
    if other:
        raise TypeError(f"a volume takes no {', '.join(other)} (only t_start and t_end; a clip box is "
                        "RaycastSettings(clip_box=...))")
    if camera is None:
        camera = Camera.fit(volume)
    else:
        check_clipping_range(camera, volume.corners)
    if tf is None:
        tf = default_transfer_function(volume)
    if method == "reference":
        from tetvr.reference.volume import render_volume_reference

        return _warn_if_blank(render_volume_reference(volume, camera, tf, size, settings=settings, **kwargs), volume, tf)
    _check_method(method)
    from tetvr.gl.framesize import check_frame
    from tetvr.gl.raycaster import Raycaster

    check_frame(size, "raycast", software=None, context_made=False)  # before the context, as for a mesh

    with Raycaster(settings) as raycaster:
        return _warn_if_blank(raycaster.render(volume, camera, tf, size=size, **kwargs), volume, tf)

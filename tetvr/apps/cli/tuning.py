"""The ``render`` command's tuning options: each value checked as it is parsed, and what
each does to the default transfer function and the camera.

Transfer function (a mesh or volume file; a scene sets its own in its JSON):
``--cmap``, ``--range LO HI`` (the colour and opacity range instead of the 1st..99.5th
percentile), ``--unit-distance U`` (world units), ``--opacity-scale S`` (every opacity
control point times ``S``, at most 1): each replaces one part of
:func:`tetvr.render.default_transfer_function`, the same rule for meshes and volumes.

Camera (any input): ``--view``, ``--parallel`` and ``--zoom`` are :meth:`tetvr.Camera.fit`'s
``direction``, ``parallel`` and ``zoom`` (``--view``/``--parallel`` refit a scene's camera;
``--zoom`` alone magnifies a scene's own camera about its focal point, narrowing its view
angle or its parallel scale, as VTK's ``Zoom``); then ``--azimuth A``
turns the camera ``A`` degrees about its view up through the focal point
(:func:`tetvr.apps.animate.azimuth`, VTK's ``Azimuth``) and ``--elevation E`` ``E`` degrees
up about its right axis (VTK's ``Elevation``), with the clipping range reset from the data
(:func:`tetvr.core.camera.reset_clipping_range`).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.apps.animate import azimuth
from tetvr.core.camera import Camera, _fit, reset_clipping_range
from tetvr.optics.table import check_unit_distance
from tetvr.optics.transfer import TransferFunction

#: Nothing public: the ``render`` command uses these.
__all__: list[str] = []

#: ``--view`` names: the direction the camera looks along (ParaView's "Set view direction to +X").
VIEWS = {f"{sign}{axis}": tuple(float(sign + "1") if a == axis else 0.0 for a in "xyz")
         for axis in "xyz" for sign in "+-"}


def finite_arg(text: str) -> float:
    """A finite number (degrees, say)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def positive_arg(text: str) -> float:
    """A finite number above 0 (a zoom, a scale)."""
    value = finite_arg(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a number above 0, got {text!r}")
    return value


def unit_distance_arg(text: str) -> float:
    """A unit distance the optics can use (:func:`tetvr.optics.table.check_unit_distance`)."""
    value = positive_arg(text)
    try:
        return check_unit_distance(value, "the unit distance")
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def view_arg(text: str) -> tuple[float, float, float]:
    """``+x``, ``-x``, ``+y``, ``-y``, ``+z``, ``-z`` (``x`` is ``+x``) or ``DX,DY,DZ``: the
    direction the camera looks along."""
    t = text.strip().lower()
    t = "+" + t if t in ("x", "y", "z") else t
    if t in VIEWS:
        return VIEWS[t]  # type: ignore[return-value]
    try:
        d = tuple(float(v) for v in t.split(","))
    except ValueError:
        d = ()
    if len(d) != 3 or not all(math.isfinite(v) for v in d) or not any(d):
        raise argparse.ArgumentTypeError(f"expected one of {', '.join(VIEWS)} or DX,DY,DZ (not all 0), got {text!r}")
    return d  # type: ignore[return-value]


class RangeAction(argparse.Action):
    """``--range LO HI``: two finite numbers with ``LO < HI``."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        lo, hi = values
        with np.errstate(over="ignore"):
            ok = math.isfinite(hi - lo)
        if not (lo < hi and ok):
            raise argparse.ArgumentError(self, f"expected LO < HI (finite), got {lo:g} {hi:g}")
        setattr(namespace, self.dest, (lo, hi))


# ---- which options an input takes ----

#: Options of the default transfer function, by their argparse names.
_TF_OPTIONS = {"cmap": "--cmap", "range": "--range", "opacity_scale": "--opacity-scale",
               "unit_distance": "--unit-distance"}
_CAMERA_FIT = ("view", "parallel", "zoom")


def check_options(args: argparse.Namespace, kind: str) -> None:
    """``ValueError`` for an option the input does not take; ``kind`` is ``"mesh"``,
    ``"volume"``, ``"scene"`` (a scene JSON) or ``"state"`` (a ParaView state)."""
    given = {name for name in ("scalars", "component", "volume", "clip_box", "clip_plane", "surface", *_TF_OPTIONS)
             if getattr(args, name, None) not in (None, [], False)}
    flag = {"clip_box": "--clip-box", "clip_plane": "--clip-plane", **_TF_OPTIONS}
    if kind in ("scene", "state"):
        for name in sorted(given & {"scalars", "component", *_TF_OPTIONS}):
            files = "a mesh file" if name in ("scalars", "component") else "a mesh or volume file"
            raise ValueError(f"{flag.get(name, '--' + name)} is for {files}; a scene sets it in its JSON "
                             f"({args.scene!r})")
    if args.parity and kind != "state":
        raise ValueError(f"--parity is for a ParaView state (.pvsm), not {args.scene!r}; a scene JSON asks for VTK "
                         "parity with \"settings\": {\"optics\": \"vtk\"}")
    if "volume" in given:
        if kind != "mesh" or args.scene.lower().endswith(".pvd"):
            raise ValueError(f"--volume fuses a volume with one mesh file; {args.scene!r} is not one")
        for name in sorted(given & {"clip_box", "clip_plane", "surface"}):
            raise ValueError(f"{flag.get(name, '--' + name)} is not available with --volume (tetvr.fuse takes none)")
    if kind == "volume":
        for name in sorted(given & {"scalars", "component", "clip_plane", "surface"}):
            raise ValueError(f"{flag.get(name, '--' + name)} is for a mesh; {args.scene!r} is a volume "
                             "(one field; --clip-box cuts it)")


# ---- the transfer function ----

def scaled_opacity(tf: TransferFunction, scale: float | None) -> TransferFunction:
    """``tf`` with every opacity control point times ``scale`` (capped at 1).

    >>> tf = TransferFunction(color=((0, 0, 0, 0), (1, 1, 1, 1)), opacity=((0, 0.2), (1, 0.8)))
    >>> scaled_opacity(tf, 2.0).opacity
    ((0.0, 0.4), (1.0, 1.0))
    """
    if scale is None or scale == 1.0:
        return tf
    return dataclasses.replace(tf, opacity=tuple((x, min(1.0, a * scale)) for x, a in tf.opacity))


def data_tf(data: Any, args: argparse.Namespace, preset: str = "viridis") -> TransferFunction:
    """The default transfer function of a mesh or a volume with the options' parts in place."""
    from tetvr.render import default_transfer_function

    tf = default_transfer_function(data, preset=args.cmap or preset, scalar_range=args.range,
                                   unit_distance=args.unit_distance)
    return scaled_opacity(tf, args.opacity_scale)


# ---- the camera ----

@dataclasses.dataclass(frozen=True)
class Together:
    """What a camera frames of several meshes and volumes: their points (a volume's box
    corners) and their common bounds (:class:`tetvr.core.camera.Bounded`)."""

    points: NDArray[np.float64]
    bounds: NDArray[np.float64]

    @classmethod
    def of(cls, items: Sequence[Any]) -> "Together":
        pts = np.concatenate([np.asarray(it.points if hasattr(it, "points") else it.corners, dtype=np.float64)
                              for it in items])
        return cls(points=pts, bounds=np.stack([pts.min(axis=0), pts.max(axis=0)]))


def turned(camera: Camera, args: argparse.Namespace, bounds: Any) -> Camera:
    """``--azimuth`` then ``--elevation`` (see the module notes)."""
    az, el = args.azimuth or 0.0, args.elevation or 0.0
    if az == 0.0 and el == 0.0:
        return camera
    if az:
        camera = azimuth(camera, az)
    if el:
        camera = azimuth(camera, -el, axis=camera.basis()[0])
    return reset_clipping_range(camera, bounds)


def data_camera(data: Any, args: argparse.Namespace, size: tuple[int, int]) -> Camera:
    """The fitted camera of a mesh, a volume or :class:`Together`, with the camera options."""
    fit: dict[str, Any] = {"parallel": bool(args.parallel), "zoom": args.zoom or 1.0}
    if args.view is not None:
        fit["direction"] = args.view
    return turned(_fit(data, aspect=size[0] / size[1], **fit), args, data.bounds)


def scene_camera(camera: Camera, data: Any, args: argparse.Namespace, size: tuple[int, int]) -> Camera:
    """A scene's camera with the camera options: ``--view``/``--parallel`` refit it,
    ``--zoom`` alone magnifies it by narrowing its view (``tan(view_angle / 2)`` or
    ``parallel_scale`` divided by the zoom), then the turns."""
    if args.view is not None or args.parallel:
        return data_camera(data, args, size)
    if args.zoom:
        camera = dataclasses.replace(camera, parallel_scale=camera.parallel_scale / args.zoom) \
            if camera.parallel_projection else \
            dataclasses.replace(camera, view_angle=math.degrees(2 * math.atan(
                math.tan(math.radians(camera.view_angle) / 2) / args.zoom)))
    return turned(camera, args, data.bounds)

"""Transfer functions: scalar -> (RGB colour, opacity), piecewise linear.

Colour and opacity have separate control points (as in ParaView's colour map and
opacity map). Scalars below the first or above the last control point take the end
values (VTK's clamping). Positions are in the scalar's own units.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["TransferFunction", "PRESETS"]

# Colour presets sampled on [0, 1]: (position, r, g, b).
PRESETS: dict[str, tuple[tuple[float, float, float, float], ...]] = {
    "viridis": (  # matplotlib's viridis at k/8
        (0.0, 0.267004, 0.004874, 0.329415),
        (0.125, 0.278826, 0.175490, 0.483397),
        (0.25, 0.229739, 0.322361, 0.545706),
        (0.375, 0.172719, 0.448791, 0.557885),
        (0.5, 0.127568, 0.566949, 0.550556),
        (0.625, 0.157851, 0.683765, 0.501686),
        (0.75, 0.369214, 0.788888, 0.382914),
        (0.875, 0.678489, 0.863742, 0.189503),
        (1.0, 0.993248, 0.906157, 0.143936),
    ),
    "cool-to-warm": (
        (0.0, 0.231373, 0.298039, 0.752941),
        (0.5, 0.865003, 0.865003, 0.865003),
        (1.0, 0.705882, 0.015686, 0.149020),
    ),
    "grayscale": ((0.0, 0.0, 0.0, 0.0), (1.0, 1.0, 1.0, 1.0)),
    "hot": (
        (0.0, 0.0416, 0.0, 0.0),
        (0.365, 1.0, 0.0, 0.0),
        (0.746, 1.0, 1.0, 0.0),
        (1.0, 1.0, 1.0, 1.0),
    ),
}


def _points(value: ArrayLike, width: int, name: str) -> tuple[tuple[float, ...], ...]:
    rows = "(x, r, g, b)" if width == 4 else "(x, a)"
    if isinstance(value, (str, bytes)):
        raise ValueError(f"{name} must be a sequence of {rows} rows, got {value!r}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:  # ragged rows, non-numbers
        raise ValueError(f"{name} must be a sequence of {rows} rows of numbers, got {value!r} ({exc})") from None
    if arr.ndim != 2 or arr.shape[1] != width or arr.shape[0] < 1:
        raise ValueError(f"{name} must be a sequence of {rows} rows, got an array of shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or Inf: {arr.tolist()}")
    x = arr[:, 0]
    with np.errstate(over="ignore"):  # an overflowing difference is still positive
        dx = np.diff(x)
        span = x[-1] - x[0]
    if np.any(dx < 0):
        raise ValueError(f"{name} positions must be sorted ascending, got {x.tolist()}")
    if np.any(dx == 0):
        raise ValueError(f"{name} has duplicate positions {x[np.nonzero(dx == 0)[0]].tolist()}")
    if not np.isfinite(span):
        raise ValueError(f"{name} positions span more than float64 can hold: {x[0]} .. {x[-1]}")
    vals = arr[:, 1:]
    if np.any(vals < 0) or np.any(vals > 1):
        raise ValueError(f"{name} values must lie in [0, 1], got {vals.min()} .. {vals.max()}")
    return tuple(tuple(float(v) for v in row) for row in arr)


@dataclasses.dataclass(frozen=True)
class TransferFunction:
    """Piecewise-linear colour and opacity over a scalar.

    Parameters
    ----------
    color : rows of ``(x, r, g, b)``, ``x`` ascending, components in [0, 1].
    opacity : rows of ``(x, a)``, ``x`` ascending, ``a`` in [0, 1]: the opacity of a slab
        of thickness ``unit_distance`` (see :mod:`tetvr.optics`).
    unit_distance : world-space length ``u`` over which opacity ``a`` is reached.

    Examples
    --------
    >>> tf = TransferFunction.preset("viridis", (0.0, 1.0), opacity=0.5, unit_distance=0.1)
    >>> tf.evaluate([0.0, 1.0])[1].tolist()
    [0.5, 0.5]
    """

    color: tuple[tuple[float, float, float, float], ...]
    opacity: tuple[tuple[float, float], ...]
    unit_distance: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "color", _points(self.color, 4, "color"))
        object.__setattr__(self, "opacity", _points(self.opacity, 2, "opacity"))
        try:
            u = float(self.unit_distance)
        except (TypeError, ValueError):
            raise ValueError(f"unit_distance must be a positive finite number, got {self.unit_distance!r}") from None
        if isinstance(self.unit_distance, (bool, np.bool_, str, bytes)) or not np.isfinite(u) or u <= 0:
            raise ValueError(f"unit_distance must be a positive finite number, got {self.unit_distance!r}")
        object.__setattr__(self, "unit_distance", u)

    @classmethod
    def preset(
        cls,
        name: str,
        scalar_range: tuple[float, float],
        *,
        opacity: float | Sequence[tuple[float, float]] = 0.5,
        unit_distance: float = 1.0,
    ) -> "TransferFunction":
        """A named colour map stretched over ``scalar_range``.

        ``opacity`` is a constant, or ``(t, a)`` rows with ``t`` in [0, 1] across the range.
        """
        if name not in PRESETS:
            raise ValueError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}")
        try:
            lo, hi = (float(v) for v in scalar_range)
        except (TypeError, ValueError):
            raise ValueError(f"scalar_range must be two numbers (lo, hi), got {scalar_range!r}") from None
        with np.errstate(over="ignore"):
            finite = bool(np.isfinite(lo) and np.isfinite(hi) and np.isfinite(np.float64(hi) - lo))
        if not finite or hi <= lo:
            raise ValueError(f"scalar_range must be finite with lo < hi, got {scalar_range!r}")
        color = tuple((lo + (hi - lo) * p, r, g, b) for p, r, g, b in PRESETS[name])
        try:
            if np.isscalar(opacity):
                op: tuple[tuple[float, float], ...] = ((lo, float(opacity)), (hi, float(opacity)))  # type: ignore[arg-type]
            else:
                op = tuple((lo + (hi - lo) * float(t), float(a)) for t, a in opacity)  # type: ignore[union-attr]
        except (TypeError, ValueError):
            raise ValueError(f"opacity must be a number or (t, a) rows with t in [0, 1], got {opacity!r}") from None
        return cls(color=color, opacity=op, unit_distance=unit_distance)

    @property
    def domain(self) -> tuple[float, float]:
        """Smallest and largest control-point position over colour and opacity."""
        xs = self.breakpoints
        return float(xs[0]), float(xs[-1])

    @property
    def breakpoints(self) -> NDArray[np.float64]:
        """Sorted union of all control-point positions: between two, both maps are linear."""
        xs = [p[0] for p in self.color] + [p[0] for p in self.opacity]
        return np.unique(np.asarray(xs, dtype=np.float64))

    def evaluate(self, scalars: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Colour ``(n, 3)`` and opacity ``(n,)`` at the given scalars (clamped at the ends)."""
        s = np.asarray(scalars, dtype=np.float64)
        c = np.asarray(self.color)
        o = np.asarray(self.opacity)
        rgb = np.stack([np.interp(s, c[:, 0], c[:, k]) for k in (1, 2, 3)], axis=-1)
        return rgb, np.interp(s, o[:, 0], o[:, 1])

    def to_dict(self) -> dict[str, Any]:
        return {
            "color": [list(p) for p in self.color],
            "opacity": [list(p) for p in self.opacity],
            "unit_distance": self.unit_distance,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "TransferFunction":
        known = {"color", "opacity", "unit_distance"}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown transfer-function keys {sorted(unknown)}; expected {sorted(known)}")
        missing = {"color", "opacity"} - set(data)
        if missing:
            raise ValueError(f"transfer function is missing keys {sorted(missing)}")
        # __post_init__ checks the shapes and turns the rows into tuples.
        return cls(color=data["color"], opacity=data["opacity"], unit_distance=data.get("unit_distance", 1.0))

    def digest(self) -> str:
        """A stable hash of the function, used to cache pre-integration tables."""
        return hashlib.sha1(json.dumps(self.to_dict(), sort_keys=True).encode()).hexdigest()[:16]

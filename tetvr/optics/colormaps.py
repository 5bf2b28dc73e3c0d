"""Colour maps in and out: ParaView preset JSON and matplotlib colormaps -> TransferFunction.

ParaView's "Save preset" (and its bundled presets) writes a JSON list of objects::

    [{"Name": "Cool to Warm", "ColorSpace": "Diverging", "NanColor": [1, 1, 0],
      "RGBPoints": [x0, r0, g0, b0, x1, r1, g1, b1, ...],
      "Points":    [x0, a0, 0.5, 0.0, x1, a1, 0.5, 0.0, ...]}]      # optional: opacity

``RGBPoints`` are colour nodes, ``Points`` opacity nodes as ``(x, opacity, midpoint,
sharpness)``. A :class:`~tetvr.optics.transfer.TransferFunction` is piecewise linear in RGB,
so nodes that ParaView interpolates otherwise (colour spaces ``Lab``, ``Diverging``,
``HSV``, ``Step``; opacity nodes with a midpoint other than 0.5 or a sharpness above 0)
are resampled: each such segment becomes ``samples_per_segment`` linear pieces that
follow VTK's curve (``vtkColorTransferFunction``, ``vtkPiecewiseFunction``). Indexed
(categorical) presets have no ``RGBPoints`` and are refused.

ParaView keeps the opacity's unit distance on the representation, not in the preset,
so :func:`from_paraview` takes ``unit_distance`` and :func:`to_paraview` drops it.

Examples
--------
>>> tf = from_paraview({"Name": "bw", "ColorSpace": "RGB", "RGBPoints": [0, 0, 0, 0, 1, 1, 1, 1]},
...                    scalar_range=(10.0, 20.0), opacity=0.3)
>>> tf.color[-1], tf.opacity
((20.0, 1.0, 1.0, 1.0), ((10.0, 0.3), (20.0, 0.3)))
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.optics.transfer import PRESETS, TransferFunction

__all__ = [
    "COLOR_SPACES",
    "available",
    "colormap",
    "from_matplotlib",
    "from_paraview",
    "read_paraview",
    "to_paraview",
    "write_paraview",
]

#: ParaView colour spaces understood on import ("Lab/CIEDE2000" is read as "Lab").
COLOR_SPACES = ("RGB", "HSV", "Lab", "Lab/CIEDE2000", "Diverging", "Step")

Opacity = float | Sequence[tuple[float, float]]


# ---------------------------------------------------------------- ParaView JSON
def read_paraview(path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """The presets of a ParaView colour-map JSON file, by ``Name`` (file order kept).

    A file may hold one preset object or a list of them. Entries without a name are
    called ``"preset 0"``, ``"preset 1"``, ...
    """
    try:
        with open(path) as f:
            data = json.load(f)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from exc
    items = data if isinstance(data, list) else [data]
    out: dict[str, dict[str, Any]] = {}
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise ValueError(f"{path}: preset {i} is not a JSON object but {type(item).__name__}")
        out[str(item.get("Name", f"preset {i}"))] = item
    if not out:
        raise ValueError(f"{path}: holds no presets")
    return out


def from_paraview(
    preset: Mapping[str, Any] | str | os.PathLike[str],
    *,
    name: str | None = None,
    scalar_range: tuple[float, float] | None = None,
    opacity: Opacity | None = None,
    unit_distance: float = 1.0,
    samples_per_segment: int = 16,
) -> TransferFunction:
    """A transfer function from one ParaView preset.

    Parameters
    ----------
    preset : a preset object (as parsed from the JSON), or the path of a preset file.
    name : which preset of a file holding several (default: the first).
    scalar_range : stretch the preset's nodes (colour and opacity alike) linearly onto
        ``(lo, hi)``, as ParaView does when a preset is applied to a data range; ``None``
        keeps the preset's own positions.
    opacity : used when the preset has no ``Points`` (or to override them): a constant,
        or ``(t, a)`` rows with ``t`` in [0, 1] across the range. Default 0.5 when the
        preset has none.
    unit_distance : world length over which the opacity is reached (not in the preset).
    samples_per_segment : linear pieces per node interval where ParaView's curve is not
        linear in RGB.
    """
    source = f"{os.fspath(preset)}: " if isinstance(preset, (str, os.PathLike)) else ""
    preset = _pick_preset(preset, name)
    label = preset.get("Name", "<unnamed>")
    if "RGBPoints" not in preset:
        kind = "an indexed (categorical) preset" if "IndexedColors" in preset else "a preset without RGBPoints"
        raise ValueError(f"{source}ParaView preset {label!r} is {kind}; only continuous colour maps convert")
    if isinstance(samples_per_segment, bool) or not isinstance(samples_per_segment, int) or samples_per_segment < 1:
        raise ValueError(f"samples_per_segment must be a positive integer, got {samples_per_segment!r}")
    rgb = _rows(preset["RGBPoints"], _RGB_COLUMNS, f"{source}ParaView preset {label!r} RGBPoints")
    space = str(preset.get("ColorSpace", "RGB"))
    if space not in COLOR_SPACES:
        raise ValueError(f"{source}ParaView preset {label!r} has ColorSpace {space!r}; supported: {COLOR_SPACES}")
    op_nodes = (_rows(preset["Points"], _OPACITY_COLUMNS, f"{source}ParaView preset {label!r} Points")
                if preset.get("Points") else None)
    _check_rows(len(rgb), 0 if op_nodes is None else len(op_nodes), space, samples_per_segment,
                f"{source}ParaView preset {label!r}")

    # The preset's own span (colour and opacity nodes together) maps onto scalar_range.
    xs = rgb[:, 0] if op_nodes is None else np.concatenate([rgb[:, 0], op_nodes[:, 0]])
    src_lo, src_hi = float(xs.min()), float(xs.max())
    if scalar_range is not None:
        lo, hi = (float(v) for v in scalar_range)
        if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
            raise ValueError(f"scalar_range must be finite with lo < hi, got {scalar_range!r}")
    else:
        lo, hi = src_lo, src_hi
        if hi <= lo:
            raise ValueError(f"ParaView preset {label!r} spans a single value {lo}; pass scalar_range")

    def remap(x: NDArray[np.float64]) -> NDArray[np.float64]:
        if scalar_range is None:
            return x
        if src_hi <= src_lo:  # one node: it covers the whole range
            return np.full_like(x, lo)
        return lo + (x - src_lo) * ((hi - lo) / (src_hi - src_lo))

    rgb = rgb.copy()
    rgb[:, 0] = remap(rgb[:, 0])
    color = _resample_color(rgb, "Lab" if space == "Lab/CIEDE2000" else space, samples_per_segment, (lo, hi))

    if opacity is not None or op_nodes is None:
        op_spec: Opacity = 0.5 if opacity is None else opacity
        if np.isscalar(op_spec):
            op = np.array([[lo, float(op_spec)], [hi, float(op_spec)]])  # type: ignore[arg-type]
        else:
            op = np.array([[lo + (hi - lo) * float(t), float(a)] for t, a in op_spec])  # type: ignore[union-attr]
    else:
        nodes = op_nodes.copy()
        nodes[:, 0] = remap(nodes[:, 0])
        op = _resample_opacity(nodes, samples_per_segment)
    return TransferFunction(color=_dedupe(color), opacity=_dedupe(op), unit_distance=unit_distance)  # type: ignore[arg-type]


def _pick_preset(preset: Mapping[str, Any] | str | os.PathLike[str], name: str | None) -> Mapping[str, Any]:
    """``preset`` itself, or the preset ``name`` (default: the first) of the file it names."""
    if isinstance(preset, (str, os.PathLike)):
        presets = read_paraview(preset)
        if name is None:
            preset = next(iter(presets.values()))
        elif name in presets:
            preset = presets[name]
        else:
            raise KeyError(f"no preset named {name!r} in {preset}; it holds {list(presets)}")
    if not isinstance(preset, Mapping):
        raise TypeError(f"preset must be a dict or a file path, got {type(preset).__name__}")
    return preset


def to_paraview(tf: TransferFunction, name: str = "tetvr") -> dict[str, Any]:
    """One ParaView preset object (RGB colour space; opacity as linear ``Points``)."""
    return {
        "Name": str(name),
        "Creator": "tetvr",
        "ColorSpace": "RGB",
        "NanColor": [1.0, 1.0, 0.0],
        "RGBPoints": [float(v) for row in tf.color for v in row],
        "Points": [v for x, a in tf.opacity for v in (float(x), float(a), 0.5, 0.0)],
    }


def write_paraview(presets: TransferFunction | Mapping[str, TransferFunction], path: str | os.PathLike[str]) -> None:
    """Write transfer functions as a ParaView preset file (a JSON list), importable by
    ParaView's "Import preset" and by :func:`read_paraview`."""
    if isinstance(presets, TransferFunction):
        presets = {Path(path).stem: presets}
    with open(path, "w") as f:
        json.dump([to_paraview(tf, name) for name, tf in presets.items()], f, indent=1)


# ---------------------------------------------------------------- matplotlib
def from_matplotlib(
    name: str,
    scalar_range: tuple[float, float],
    *,
    opacity: Opacity = 0.5,
    unit_distance: float = 1.0,
    samples: int | None = None,
) -> TransferFunction:
    """A matplotlib colormap (by name, e.g. ``"magma"``, ``"RdBu_r"``) stretched over
    ``scalar_range``; ``samples`` colour nodes (default: the map's own count, at most 256).

    Needs matplotlib (``pip install matplotlib``).
    """
    try:
        import matplotlib
    except ImportError:  # pragma: no cover - depends on the environment
        raise ImportError("matplotlib colormaps need matplotlib: pip install matplotlib") from None
    try:
        cmap = matplotlib.colormaps[name]
    except KeyError:
        raise ValueError(f"matplotlib has no colormap {name!r}") from None
    n = samples if samples is not None else min(int(getattr(cmap, "N", 256)), 256)
    if not isinstance(n, int) or n < 2:
        raise ValueError(f"samples must be an integer >= 2, got {samples!r}")
    lo, hi = (float(v) for v in scalar_range)
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        raise ValueError(f"scalar_range must be finite with lo < hi, got {scalar_range!r}")
    t = np.linspace(0.0, 1.0, n)
    rgba = np.asarray(cmap(t), dtype=np.float64)
    color = np.column_stack([lo + (hi - lo) * t, np.clip(rgba[:, :3], 0.0, 1.0)])
    op: tuple[tuple[float, float], ...]
    if np.isscalar(opacity):
        op = ((lo, float(opacity)), (hi, float(opacity)))  # type: ignore[arg-type]
    else:
        op = tuple((lo + (hi - lo) * float(tt), float(a)) for tt, a in opacity)  # type: ignore[union-attr]
    return TransferFunction(color=tuple(map(tuple, color)), opacity=op, unit_distance=unit_distance)  # type: ignore[arg-type]


def available() -> list[str]:
    """Names :func:`colormap` accepts: tetvr's presets, then matplotlib's (if installed)."""
    names = sorted(PRESETS)
    try:
        import matplotlib

        names += sorted(n for n in matplotlib.colormaps if n not in PRESETS)
    except ImportError:  # pragma: no cover - depends on the environment
        pass
    return names


def colormap(
    name: str,
    scalar_range: tuple[float, float],
    *,
    opacity: Opacity = 0.5,
    unit_distance: float = 1.0,
) -> TransferFunction:
    """A transfer function from a colour-map name: a tetvr preset (:data:`~tetvr.PRESETS`),
    else a matplotlib colormap, else a ParaView preset file path.

    Examples
    --------
    >>> colormap("hot", (0.0, 1.0)).color[0][0]
    0.0
    """
    if name in PRESETS:
        return TransferFunction.preset(name, scalar_range, opacity=opacity, unit_distance=unit_distance)
    if name.endswith(".json") and Path(name).is_file():
        return from_paraview(name, scalar_range=scalar_range, opacity=opacity, unit_distance=unit_distance)
    try:
        import matplotlib
    except ImportError:
        raise ValueError(f"unknown colour map {name!r}: not a tetvr preset {sorted(PRESETS)}, and matplotlib "
                         "(for its colormaps) is not installed") from None
    if name not in matplotlib.colormaps:
        raise ValueError(f"unknown colour map {name!r}: not a tetvr preset {sorted(PRESETS)}, a matplotlib "
                         "colormap, nor a ParaView preset .json file")
    # Errors in the other arguments (e.g. the scalar range) surface as they are.
    return from_matplotlib(name, scalar_range, opacity=opacity, unit_distance=unit_distance)


# ---------------------------------------------------------------- internals
#: Largest magnitude of a node's position: beyond it a map's span overflows float64.
_MAX_POSITION = 1e300
#: The columns of colour nodes (RGBPoints) and opacity nodes (Points), with their ranges.
_RGB_COLUMNS = (("position", -_MAX_POSITION, _MAX_POSITION), ("red", 0.0, 1.0), ("green", 0.0, 1.0),
                ("blue", 0.0, 1.0))
_OPACITY_COLUMNS = (("position", -_MAX_POSITION, _MAX_POSITION), ("opacity", 0.0, 1.0), ("midpoint", 0.0, 1.0),
                    ("sharpness", 0.0, 1.0))
#: Most rows a preset may become (colour and opacity together, after resampling).
_MAX_ROWS = 1 << 20


def _rows(flat: Any, columns: tuple[tuple[str, float, float], ...], what: str) -> NDArray[np.float64]:
    """Nodes: a flat list of groups of ``len(columns)`` numbers (JSON numbers: no strings,
    no booleans), each finite and in its column's range, positions ascending."""
    width = len(columns)
    if not isinstance(flat, (list, tuple, np.ndarray)):
        raise ValueError(f"{what} must be a list of numbers, got {type(flat).__name__} {flat!r:.60}")
    values = np.asarray(flat, dtype=object).reshape(-1) if len(flat) else np.zeros(0)
    for k, v in enumerate(values):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise ValueError(f"{what}: value {k} is {v!r}, not a number; fix that value")
    arr = values.astype(np.float64) if values.size else np.zeros(0)
    if arr.size == 0 or arr.size % width:
        raise ValueError(f"{what} must hold groups of {width} numbers ({', '.join(c[0] for c in columns)}), "
                         f"got {arr.size} numbers")
    rows = arr.reshape(-1, width)
    for j, (label, lo, hi) in enumerate(columns):
        bad = ~((rows[:, j] >= lo) & (rows[:, j] <= hi))  # NaN is bad too
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(f"{what}: node {k}'s {label} is {float(rows[k, j])!r}, "
                             f"{'not finite' if not np.isfinite(rows[k, j]) else f'outside [{lo:g}, {hi:g}]'}; "
                             "fix that value")
    if np.any(np.diff(rows[:, 0]) < 0):
        raise ValueError(f"{what}: positions must be ascending, got {rows[:, 0].tolist()}")
    return rows


def _check_rows(n_colour: int, n_opacity: int, space: str, per: int, what: str) -> None:
    """``ValueError`` if the nodes, resampled ``per`` pieces a segment, would make more
    than :data:`_MAX_ROWS` rows (a state's 256 pieces of 1e5 Diverging nodes: 2.6e7)."""
    rows = n_colour * (2 if space == "Step" else 1 if space == "RGB" else per) + n_opacity * per
    if rows > _MAX_ROWS:
        raise ValueError(f"{what} ({n_colour} colour and {n_opacity} opacity nodes, {per} samples a segment) would "
                         f"make up to {rows} transfer-function rows, more than {_MAX_ROWS}; use fewer nodes or "
                         "fewer samples_per_segment")


def _dedupe(rows: NDArray[np.float64]) -> tuple[tuple[float, ...], ...]:
    """Rows with strictly ascending x (a later duplicate replaces an earlier one, as a
    jump); values clipped to [0, 1] against rounding."""
    rows = np.asarray(rows, dtype=np.float64)
    keep = np.ones(len(rows), bool)
    keep[:-1] = np.diff(rows[:, 0]) > 0
    rows = rows[keep].copy()
    rows[:, 1:] = np.clip(rows[:, 1:], 0.0, 1.0)
    return tuple(tuple(float(v) for v in r) for r in rows)


def _resample_color(rgb: NDArray[np.float64], space: str, per: int, span: tuple[float, float]) -> NDArray[np.float64]:
    if len(rgb) == 1:
        return np.array([[span[0], *rgb[0, 1:]], [span[1], *rgb[0, 1:]]])
    if space == "RGB":
        return rgb
    if space == "Step":
        # Each node's colour holds until the next node: a jump just before it.
        eps = 1e-9 * max(abs(span[1] - span[0]), 1e-300)
        out = [rgb[0]]
        for a, b in zip(rgb[:-1], rgb[1:]):
            if b[0] - a[0] > 2 * eps:
                out.append(np.array([b[0] - eps, *a[1:]]))
            out.append(b)
        return np.array(out)
    out = [rgb[:1]]
    for a, b in zip(rgb[:-1], rgb[1:]):
        if b[0] <= a[0]:
            out.append(b[None])
            continue
        t = np.linspace(0.0, 1.0, per + 1)[1:]
        cols = _interp_space(a[1:], b[1:], t, space)
        cols[-1] = b[1:]  # the node itself, exactly
        out.append(np.column_stack([a[0] + (b[0] - a[0]) * t, cols]))
    return np.concatenate(out)


def _resample_opacity(nodes: NDArray[np.float64], per: int) -> NDArray[np.float64]:
    """vtkPiecewiseFunction's curve between nodes (midpoint, sharpness), as linear pieces."""
    if len(nodes) == 1:
        return np.array([[nodes[0, 0], nodes[0, 1]]])
    out = [nodes[:1, :2]]
    for a, b in zip(nodes[:-1], nodes[1:]):
        mid, sharp = float(a[2]), float(a[3])
        if b[0] <= a[0] or (abs(mid - 0.5) < 1e-12 and sharp < 1e-12):
            out.append(b[None, :2])
            continue
        t = np.linspace(0.0, 1.0, per + 1)[1:]
        if sharp > 0.99:  # a step at the midpoint: put its two sides in exactly
            t = np.unique(np.concatenate([t, [mid * (1 - 1e-9), mid]]))
        out.append(np.column_stack([a[0] + (b[0] - a[0]) * t, _vtk_piecewise(a[1], b[1], t, mid, sharp)]))
    return np.concatenate(out)


def _vtk_piecewise(y1: float, y2: float, x: NDArray[np.float64], midpoint: float, sharpness: float) -> NDArray[np.float64]:
    """vtkPiecewiseFunction between two nodes at normalised positions ``x`` in [0, 1]."""
    m = min(max(midpoint, 1e-5), 1.0 - 1e-5)
    x = np.where(x < m, 0.5 * x / m, 0.5 + 0.5 * (x - m) / (1.0 - m))
    if sharpness > 0.99:
        return np.where(x < 0.5, y1, y2)
    if sharpness < 0.01:
        return (1.0 - x) * y1 + x * y2
    p = 1.0 + 10.0 * sharpness
    x = np.where(x < 0.5, 0.5 * np.power(2.0 * x, p), np.where(x > 0.5, 1.0 - 0.5 * np.power(2.0 * (1.0 - x), p), x))
    ss, sss = x * x, x * x * x
    h1, h2 = 2 * sss - 3 * ss + 1, -2 * sss + 3 * ss
    h3, h4 = sss - 2 * ss + x, sss - ss
    slope = (1.0 - sharpness) * (y2 - y1)
    val = h1 * y1 + h2 * y2 + h3 * slope + h4 * slope
    return np.clip(val, min(y1, y2), max(y1, y2))


def _interp_space(c1: NDArray[np.float64], c2: NDArray[np.float64], t: NDArray[np.float64], space: str) -> NDArray[np.float64]:
    t = t[:, None]
    if space == "Lab":
        return _lab_to_rgb((1 - t) * _rgb_to_lab(c1) + t * _rgb_to_lab(c2))
    if space == "HSV":
        h1, h2 = _rgb_to_hsv(c1), _rgb_to_hsv(c2)
        # VTK takes the short way round the hue circle (HSVWrap on).
        if h2[0] - h1[0] > 0.5:
            h1 = h1 + np.array([1.0, 0, 0])
        elif h1[0] - h2[0] > 0.5:
            h2 = h2 + np.array([1.0, 0, 0])
        hsv = (1 - t) * h1 + t * h2
        hsv[:, 0] %= 1.0
        return _hsv_to_rgb(hsv)
    if space == "Diverging":
        ends = _lab_to_msh(_rgb_to_lab(c1)), _lab_to_msh(_rgb_to_lab(c2))  # once a segment, not once a sample
        return np.array([_diverging(c1, c2, float(s), ends) for s in t[:, 0]])
    raise ValueError(f"colour space {space!r}")  # pragma: no cover - checked by the caller


# Colour conversions as VTK does them (sRGB, D65 white; vtkMath::RGBToLab).
_WHITE = np.array([0.9505, 1.0, 1.089])
_RGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
# The exact inverse (not VTK's rounded one), so that nodes survive the round trip.
_XYZ_TO_RGB = np.linalg.inv(_RGB_TO_XYZ)


def _rgb_to_lab(rgb: Any) -> NDArray[np.float64]:
    c = np.asarray(rgb, dtype=np.float64)
    lin = np.where(c > 0.04045, ((c + 0.055) / 1.055) ** 2.4, c / 12.92)
    xyz = (lin @ _RGB_TO_XYZ.T) / _WHITE
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16.0 / 116.0)
    return np.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]), 200.0 * (f[..., 1] - f[..., 2])], -1)


def _lab_to_rgb(lab: Any) -> NDArray[np.float64]:
    lab = np.asarray(lab, dtype=np.float64)
    fy = (lab[..., 0] + 16.0) / 116.0
    f = np.stack([lab[..., 1] / 500.0 + fy, fy, fy - lab[..., 2] / 200.0], -1)
    xyz = np.where(f**3 > 0.008856, f**3, (f - 16.0 / 116.0) / 7.787) * _WHITE
    lin = xyz @ _XYZ_TO_RGB.T
    rgb = np.where(lin > 0.0031308, 1.055 * np.power(np.maximum(lin, 0.0), 1 / 2.4) - 0.055, 12.92 * lin)
    return np.clip(rgb, 0.0, 1.0)


def _rgb_to_hsv(rgb: NDArray[np.float64]) -> NDArray[np.float64]:
    import colorsys

    return np.array(colorsys.rgb_to_hsv(*(float(v) for v in rgb)))


def _hsv_to_rgb(hsv: NDArray[np.float64]) -> NDArray[np.float64]:
    import colorsys

    return np.array([colorsys.hsv_to_rgb(*(float(v) for v in row)) for row in hsv])


def _lab_to_msh(lab: NDArray[np.float64]) -> NDArray[np.float64]:
    m = float(np.linalg.norm(lab))
    s = math.acos(lab[0] / m) if m > 0 else 0.0
    h = math.atan2(lab[2], lab[1]) if s > 0 else 0.0
    return np.array([m, s, h])


def _msh_to_lab(msh: NDArray[np.float64]) -> NDArray[np.float64]:
    m, s, h = msh
    return np.array([m * math.cos(s), m * math.sin(s) * math.cos(h), m * math.sin(s) * math.sin(h)])


def _adjust_hue(msh: NDArray[np.float64], unsat_m: float) -> float:
    m, s, h = msh
    if m >= unsat_m - 0.1:
        return float(h)
    spin = s * math.sqrt(unsat_m**2 - m**2) / (m * math.sin(s))
    return float(h + spin) if h > -math.pi / 3 else float(h - spin)


def _diverging(c1: NDArray[np.float64], c2: NDArray[np.float64], s: float,
               ends: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None) -> NDArray[np.float64]:
    """Moreland's diverging interpolation (2009), as vtkColorTransferFunction's Diverging.
    ``ends``: the two colours in Msh, if the caller has them."""
    if ends is None:
        ends = _lab_to_msh(_rgb_to_lab(c1)), _lab_to_msh(_rgb_to_lab(c2))
    m1, m2 = ends[0].copy(), ends[1].copy()
    dh = abs(m1[2] - m2[2])
    dh = min(dh, 2 * math.pi - dh)
    if m1[1] > 0.05 and m2[1] > 0.05 and dh > math.pi / 3:
        mid = max(m1[0], m2[0], 88.0)
        if s < 0.5:
            m2, s = np.array([mid, 0.0, 0.0]), 2 * s
        else:
            m1, s = np.array([mid, 0.0, 0.0]), 2 * s - 1
    if m1[1] < 0.05 and m2[1] > 0.05:
        m1[2] = _adjust_hue(m2, m1[0])
    elif m2[1] < 0.05 and m1[1] > 0.05:
        m2[2] = _adjust_hue(m1, m2[0])
    return _lab_to_rgb(_msh_to_lab((1 - s) * m1 + s * m2))


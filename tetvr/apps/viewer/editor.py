"""The transfer-function editor: opacity control points over a colour map, drawn on a
log-scaled histogram of the field with a colour legend and value ticks.

:class:`TransferFunctionEditor` is the state (points in [0, 1] of the range, the colour
map, the unit distance) and its edits; :func:`histogram_image` and :func:`legend_image`
draw it; :class:`HistogramPicker` maps pointer positions on that picture to edits (click
to add, drag to move, double-click to remove), which the Jupyter viewer forwards from
the browser.

Examples
--------
>>> ed = TransferFunctionEditor((0.0, 10.0), points=[(0, 0), (1, 1)])
>>> nice_ticks(0.0, 10.0)
[0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.optics.transfer import TransferFunction

__all__ = ["TransferFunctionEditor", "HistogramPicker", "histogram_image", "legend_image", "log_histogram",
           "nice_ticks"]

def log_histogram(values: ArrayLike, scalar_range: tuple[float, float], bins: int = 64
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(log10(1 + count), edges)`` of the values in ``scalar_range``."""
    counts, edges = np.histogram(np.asarray(values, dtype=np.float64), bins=bins, range=scalar_range)
    return np.log10(1.0 + counts), edges


def histogram_image(values: ArrayLike | None, tf: TransferFunction, scalar_range: tuple[float, float], *,
                    size: tuple[int, int] = (360, 120), bins: int = 72,
                    points: Sequence[tuple[float, float]] = (), selected: int | None = None,
                    log_counts: NDArray[np.float64] | None = None) -> NDArray[np.float32]:
    """The transfer-function editor's picture: a log-scaled histogram of ``values`` with
    bars in the transfer function's colour, the opacity curve over it (white line, dark
    rim) and the control ``points`` (``(t, a)``, ``t`` in [0, 1] of the range) as squares,
    the ``selected`` one red. Premultiplied RGBA, opaque, row 0 at the top.

    ``log_counts`` (from :func:`log_histogram` over ``scalar_range`` with ``bins``) skips
    the pass over ``values``: an opacity edit redraws the picture without it."""
    w, h = int(size[0]), int(size[1])
    lo, hi = (float(v) for v in scalar_range)
    img = np.zeros((h, w, 4), np.float32)
    img[...] = (0.12, 0.12, 0.14, 1.0)
    if log_counts is None:
        if values is None:
            raise ValueError("histogram_image needs the values or their log_counts")
        log_counts, _ = log_histogram(values, (lo, hi), bins)
    logc = np.asarray(log_counts, dtype=np.float64)
    bins = logc.shape[0]
    top = max(float(logc.max()), 1e-12)
    xs = lo + (hi - lo) * (np.arange(w) + 0.5) / w
    rgb, alpha = tf.evaluate(xs)
    bar_h = np.round(logc[np.minimum((np.arange(w) * bins) // w, bins - 1)] / top * (h - 4)).astype(int)
    rows = np.arange(h)[:, None]
    bars = rows >= (h - bar_h)[None, :]
    img[..., :3] = np.where(bars[..., None], (0.35 + 0.65 * rgb[None, :, :]).astype(np.float32), img[..., :3])
    # Opacity curve: y = a, 2 px thick with a dark rim so it reads over any bar colour.
    y = np.clip(np.round((1.0 - alpha) * (h - 3)).astype(int) + 1, 1, h - 2)
    for col in range(w):  # each column: from the previous column's height to its own
        y0 = y[col] if col == 0 else y[col - 1]
        a, b = sorted((int(y0), int(y[col])))
        img[max(a - 1, 0):b + 2, col, :3] = 0.0
        img[a:b + 1, col, :3] = 1.0
    for i, (pt, pa) in enumerate(points):
        cx = int(round(float(pt) * (w - 1)))
        cy = int(round((1.0 - float(pa)) * (h - 3))) + 1
        colour = (1.0, 0.2, 0.2) if i == selected else (1.0, 1.0, 1.0)
        img[max(cy - 3, 0):cy + 4, max(cx - 3, 0):cx + 4, :3] = 0.0
        img[max(cy - 2, 0):cy + 3, max(cx - 2, 0):cx + 3, :3] = colour
    return img


def nice_ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    """About ``n`` round values (1, 2, 2.5 or 5 times a power of ten apart) in [lo, hi]."""
    lo, hi = float(lo), float(hi)
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        raise ValueError(f"tick range must be finite with lo < hi, got {(lo, hi)!r}")
    raw = (hi - lo) / max(int(n), 1)
    power = 10.0 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1.0, 2.0, 2.5, 5.0, 10.0) if m * power >= raw * (1 - 1e-9))
    first = math.ceil(lo / step - 1e-9)
    ticks = [k * step for k in range(first, int(math.floor(hi / step + 1e-9)) + 1)]
    return [0.0 if abs(t) < 1e-12 * step else round(t, 12) for t in ticks]


def legend_image(tf: TransferFunction, scalar_range: tuple[float, float], *, size: tuple[int, int] = (360, 18),
                 ticks: Sequence[float] = ()) -> NDArray[np.float32]:
    """The colour legend under the histogram: the transfer function's colour across
    ``scalar_range`` (opaque, no opacity), with a dark tick mark at each of ``ticks``."""
    w, h = int(size[0]), int(size[1])
    lo, hi = (float(v) for v in scalar_range)
    rgb, _ = tf.evaluate(lo + (hi - lo) * (np.arange(w) + 0.5) / w)
    img = np.ones((h, w, 4), np.float32)
    img[..., :3] = rgb[None, :, :]
    for t in ticks:
        col = int(round((float(t) - lo) / (hi - lo) * (w - 1)))
        if 0 <= col < w:
            img[: h // 3, max(col - 1, 0):col + 1, :3] = 0.0
    return img


class HistogramPicker:
    """Pointer events on the editor's picture -> edits of a :class:`TransferFunctionEditor`.

    A press near a point (within ``radius_px``) selects it and starts dragging it; a press
    elsewhere adds a point there and drags that one; a double click on an interior point
    removes it. Pixel coordinates are those of :func:`histogram_image` of ``size``.
    Each method returns True when the transfer function changed.

    Examples
    --------
    >>> ed = TransferFunctionEditor((0.0, 1.0), points=[(0, 0), (1, 1)])
    >>> pick = HistogramPicker(ed, size=(101, 53))
    >>> pick.press(50, 26), len(ed.points), pick.selected
    (True, 3, 1)
    >>> pick.double_click(50, 26), len(ed.points)
    (True, 2)
    """

    def __init__(self, editor: "TransferFunctionEditor", *, size: tuple[int, int] = (360, 120),
                 radius_px: float = 7.0) -> None:
        self.editor = editor
        self.size = (int(size[0]), int(size[1]))
        self.radius_px = float(radius_px)
        self.selected = 0
        self.dragging = False

    def to_point(self, x: float, y: float) -> tuple[float, float]:
        """Picture pixel -> ``(t, a)`` (the inverse of where :func:`histogram_image` draws)."""
        w, h = self.size
        return float(np.clip(x / (w - 1), 0, 1)), float(np.clip(1.0 - (y - 1) / (h - 3), 0, 1))

    def _hit(self, x: float, y: float) -> int | None:
        w, h = self.size
        d = [math.hypot(t * (w - 1) - x, (1.0 - a) * (h - 3) + 1 - y) for t, a in self.editor.points]
        i = int(np.argmin(d))
        return i if d[i] <= self.radius_px else None

    def press(self, x: float, y: float) -> bool:
        hit = self._hit(x, y)
        self.dragging = True
        if hit is not None:
            self.selected = hit
            return False
        t, a = self.to_point(x, y)
        self.selected = self.editor.add_point(t, a)
        return True

    def move(self, x: float, y: float) -> bool:
        if not self.dragging:
            return False
        t, a = self.to_point(x, y)
        before = self.editor.points[self.selected]
        return self.editor.move_point(self.selected, t=t, a=a) != before

    def release(self) -> None:
        self.dragging = False

    def double_click(self, x: float, y: float) -> bool:
        hit = self._hit(x, y)
        self.dragging = False
        if hit is None or hit in (0, len(self.editor.points) - 1):
            return False
        self.editor.remove_point(hit)
        self.selected = max(hit - 1, 0)
        return True


class TransferFunctionEditor:
    """Editable opacity control points over a colour map.

    Points are ``(t, a)``: ``t`` in [0, 1] across ``scalar_range``, ``a`` the opacity per
    ``unit_distance``. The two end points stay at ``t = 0`` and ``t = 1``; interior points
    keep their order (a move is clamped between the neighbours).

    Parameters
    ----------
    scalar_range : (lo, hi) the colour map and the points stretch over.
    colormap : a name for :func:`tetvr.optics.colormaps.colormap` (tetvr preset or matplotlib),
        or ``None`` to keep ``color`` (explicit ``(t, r, g, b)`` rows).
    points : the opacity control points.
    unit_distance : world length over which opacity ``a`` is reached.

    Examples
    --------
    >>> ed = TransferFunctionEditor((0.0, 10.0), points=[(0, 0), (1, 1)], unit_distance=0.5)
    >>> ed.add_point(0.5, 0.2)
    1
    >>> ed.transfer_function().opacity
    ((0.0, 0.0), (5.0, 0.2), (10.0, 1.0))
    """

    MIN_GAP = 1e-4

    def __init__(self, scalar_range: tuple[float, float], *, colormap: str | None = "viridis",
                 points: Sequence[tuple[float, float]] = ((0.0, 0.0), (1.0, 0.5)), unit_distance: float = 1.0,
                 color: Sequence[tuple[float, float, float, float]] | None = None) -> None:
        self.scalar_range = _range(scalar_range)
        if colormap is None and color is None:
            raise ValueError("give a colormap name or explicit color rows")
        self.colormap = colormap
        self.color = None if color is None else tuple(tuple(float(v) for v in row) for row in color)
        pts = sorted((float(t), float(a)) for t, a in points)
        if len(pts) < 2:
            raise ValueError(f"need at least 2 opacity points, got {len(pts)}")
        pts[0] = (0.0, pts[0][1])
        pts[-1] = (1.0, pts[-1][1])
        self.points: list[tuple[float, float]] = [(t, float(np.clip(a, 0, 1))) for t, a in pts]
        self.unit_distance = float(unit_distance)
        self.transfer_function()  # validates everything

    @classmethod
    def from_transfer_function(cls, tf: TransferFunction, *, colormap: str | None = None) -> "TransferFunctionEditor":
        """An editor holding ``tf`` (its colour kept explicitly unless ``colormap`` is given)."""
        lo, hi = tf.domain
        if hi <= lo:
            hi = lo + 1.0
        span = hi - lo
        color = [((x - lo) / span, r, g, b) for x, r, g, b in tf.color]
        pts = [((x - lo) / span, a) for x, a in tf.opacity]
        if pts[0][0] > 0:
            pts.insert(0, (0.0, pts[0][1]))
        if pts[-1][0] < 1:
            pts.append((1.0, pts[-1][1]))
        return cls((lo, hi), colormap=colormap, color=None if colormap else color, points=pts,
                   unit_distance=tf.unit_distance)

    # ---- edits ----
    def add_point(self, t: float, a: float) -> int:
        """Insert a point (or set the opacity of the one at ``t``); returns its index."""
        t = float(np.clip(t, 0.0, 1.0))
        a = float(np.clip(a, 0.0, 1.0))
        for i, (ti, _) in enumerate(self.points):
            if abs(ti - t) < self.MIN_GAP:
                self.points[i] = (ti, a)
                return i
        i = int(np.searchsorted([p[0] for p in self.points], t))
        self.points.insert(i, (t, a))
        return i

    def move_point(self, index: int, t: float | None = None, a: float | None = None) -> tuple[float, float]:
        """Move point ``index``; end points move in opacity only. Returns where it went."""
        self._check_index(index)
        ti, ai = self.points[index]
        if t is not None and 0 < index < len(self.points) - 1:
            lo = self.points[index - 1][0] + self.MIN_GAP
            hi = self.points[index + 1][0] - self.MIN_GAP
            ti = float(np.clip(t, lo, hi))
        if a is not None:
            ai = float(np.clip(a, 0.0, 1.0))
        self.points[index] = (ti, ai)
        return self.points[index]

    def remove_point(self, index: int) -> None:
        """Remove an interior point (the two ends stay)."""
        self._check_index(index)
        if index in (0, len(self.points) - 1):
            raise ValueError("the end points at t = 0 and t = 1 cannot be removed")
        del self.points[index]

    def nearest_point(self, t: float, a: float, *, aspect: float = 3.0) -> int:
        """Index of the point closest to ``(t, a)`` (``t`` weighted by ``aspect``, the
        width/height ratio of the picture the user clicks in)."""
        d = [(aspect * (ti - t)) ** 2 + (ai - a) ** 2 for ti, ai in self.points]
        return int(np.argmin(d))

    def set_range(self, lo: float, hi: float) -> None:
        self.scalar_range = _range((lo, hi))

    def set_colormap(self, name: str) -> None:
        from tetvr.optics.colormaps import colormap

        colormap(name, self.scalar_range)  # fails here, not at the next render
        self.colormap = name
        self.color = None

    def set_unit_distance(self, u: float) -> None:
        u = float(u)
        if not (math.isfinite(u) and u > 0):
            raise ValueError(f"unit_distance must be positive, got {u!r}")
        self.unit_distance = u

    def _check_index(self, index: int) -> None:
        if not (isinstance(index, (int, np.integer)) and 0 <= index < len(self.points)):
            raise IndexError(f"point index {index!r} outside 0..{len(self.points) - 1}")

    # ---- results ----
    def transfer_function(self) -> TransferFunction:
        from tetvr.optics.colormaps import colormap

        lo, hi = self.scalar_range
        opacity = [(t, a) for t, a in self.points]
        if self.colormap is not None:
            return colormap(self.colormap, (lo, hi), opacity=opacity, unit_distance=self.unit_distance)
        assert self.color is not None
        color = tuple((lo + (hi - lo) * t, r, g, b) for t, r, g, b in self.color)
        op = tuple((lo + (hi - lo) * t, a) for t, a in opacity)
        return TransferFunction(color=color, opacity=op, unit_distance=self.unit_distance)

    def image(self, values: ArrayLike | None, *, size: tuple[int, int] = (360, 120), selected: int | None = None,
              log_counts: NDArray[np.float64] | None = None) -> NDArray[np.float32]:
        """The editor's picture over ``values`` (see :func:`histogram_image`)."""
        return histogram_image(values, self.transfer_function(), self.scalar_range, size=size,
                               points=self.points, selected=selected, log_counts=log_counts)


def _range(r: Sequence[float]) -> tuple[float, float]:
    lo, hi = (float(v) for v in r)
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        raise ValueError(f"scalar range must be finite with lo < hi, got {tuple(r)!r}")
    return lo, hi



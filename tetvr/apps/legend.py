"""The colour legend of an annotated picture, and the picture's layout.

The legend is a colour bar over the transfer function's range, its ticks in the field's
units with both ends labelled, and beside it the opacity curve (opacity per unit distance,
the value a slab ``unit_distance`` thick reaches). Where the field's values run past the
range, the bar ends in a triangle on that side, as matplotlib's colorbar ``extend``
(``"min"``, ``"max"``, ``"both"``): those values are drawn in the end colour, clipped. A
constant field gets no bar (a range around one value would be invented): one swatch and
``constant 1.0``.

:func:`plan` lays a picture out: the render, the legend to its right and the title above,
either around an image of a given size or inside a picture of a given size (what the
command line's ``--size`` asks for). matplotlib is imported only when a legend is drawn or
measured.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.optics.transfer import TransferFunction

__all__ = ["MIN_RENDER_SHARE", "Plan", "draw_legend", "extend_of", "field_label", "legend_ticks", "legend_width", "plan", "plain"]

#: Dots per inch of the annotated figure: one matplotlib point is 100/72 pixels.
DPI = 100.0

#: The least share of the picture's width (height) the render keeps: a legend (title) that
#: would leave it less is left out, on pictures too small for one.
MIN_RENDER_SHARE = 0.5


@dataclasses.dataclass(frozen=True)
class Plan:
    """Where each part of an annotated picture goes, in pixels.

    Attributes
    ----------
    picture : (width, height) of the whole PNG.
    area : (width, height) of the render, at the picture's lower left (under the title,
        left of the legend).
    font : the legend's type size in points.
    legend_w : the legend's width (0: no legend).
    title_h : the title's height (0: no title).
    """

    picture: tuple[int, int]
    area: tuple[int, int]
    font: float
    legend_w: int
    title_h: int


def _font(height: int) -> float:
    """Type scaled to the picture, within what stays readable: 11 pt on a 512-pixel-high picture."""
    return float(np.clip(height / 512.0 * 11.0, 7.0, 16.0))


def plan(tf: TransferFunction, label: str, *, image: tuple[int, int] | None = None,
         size: tuple[int, int] | None = None, title: str | None = None, legend: bool = True) -> Plan:
    """The layout of an annotated picture: around a render of ``image`` (width, height) --
    the picture is then wider and taller -- or inside a picture of ``size``, the render
    taking what the legend and the title leave. Inside ``size``, a legend (title) that would
    leave the render less than :data:`MIN_RENDER_SHARE` of the width (height) is left out.

    >>> from tetvr.optics.transfer import TransferFunction
    >>> tf = TransferFunction.preset("viridis", (0.0, 1.0))
    >>> p = plan(tf, "T", size=(800, 600), title="a title")
    >>> p.picture, p.area[0] + p.legend_w, p.area[1] + p.title_h
    ((800, 600), 800, 600)
    """
    if (image is None) == (size is None):
        raise ValueError("plan needs the render's size (image=) or the picture's (size=), one of them")
    w, h = image if image is not None else size  # type: ignore[misc]
    font = _font(h)
    legend_w = legend_width(tf, label, font) if legend else 0
    title_h = int(round(font * 2.2 * DPI / 72.0)) if title else 0
    if image is not None:
        return Plan((w + legend_w, h + title_h), (w, h), font, legend_w, title_h)
    if legend_w > (1.0 - MIN_RENDER_SHARE) * w:
        legend_w = 0
    if title_h > (1.0 - MIN_RENDER_SHARE) * h:
        title_h = 0
    return Plan((w, h), (w - legend_w, h - title_h), font, legend_w, title_h)


def field_label(name: str | None, units: str | None = None, scalar_of: str = "") -> str:
    """The legend's title: the field's name, ``|name|`` for a vector field's magnitude,
    ``name[k]`` for its component k, and the units in brackets.

    >>> field_label("Velocity", "m/s", "magnitude"), field_label("Velocity", None, "component 2")
    ('|Velocity| [m/s]', 'Velocity[2]')
    """
    text = name or "scalars"
    if scalar_of == "magnitude":
        text = f"|{text}|"
    elif scalar_of.startswith("component "):
        text = f"{text}[{scalar_of.split()[1]}]"
    return text + (f" [{units}]" if units else "")


def extend_of(domain: tuple[float, float], data_range: tuple[float, float] | None) -> str:
    """Which ends of the colour bar the field's values run past, in matplotlib's words:
    ``"neither"``, ``"min"``, ``"max"`` or ``"both"``.

    >>> extend_of((0.54, 2.33), (0.19, 4.98)), extend_of((0.0, 1.0), (0.0, 0.5))
    ('both', 'neither')
    """
    if data_range is None:
        return "neither"
    below, above = data_range[0] < domain[0], data_range[1] > domain[1]
    return {(False, False): "neither", (True, False): "min", (False, True): "max", (True, True): "both"}[(below, above)]


def _is_constant(data_range: tuple[float, float] | None) -> bool:
    return data_range is not None and data_range[0] == data_range[1]


def plain(value: float) -> str:
    """A value as a reader writes it: ``1.0``, ``0.25``, ``1e+20``.

    >>> plain(1.0), plain(0.25), plain(1e20)
    ('1.0', '0.25', '1e+20')
    """
    text = f"{value:.6g}"
    return text if any(c in text for c in ".ein") else text + ".0"


# ---- ticks ----

def _ticks(lo: float, hi: float) -> NDArray[np.float64]:
    from matplotlib.ticker import MaxNLocator

    t = np.asarray(MaxNLocator(nbins=6).tick_values(lo, hi))
    span = hi - lo
    return t[(t >= lo - 1e-9 * span) & (t <= hi + 1e-9 * span)]


def _tick_labels(lo: float, hi: float) -> tuple[NDArray[np.float64], list[str]]:
    """Ticks across ``lo .. hi`` and their labels, with as many digits as the step needs
    (scientific notation outside 1e-3 .. 1e5).

    >>> _tick_labels(0.0, 1.0)[1], _tick_labels(0.1, 0.8)[1]
    (['0.0', '0.2', '0.4', '0.6', '0.8', '1.0'], ['0.15', '0.30', '0.45', '0.60', '0.75'])
    """
    ticks = _ticks(lo, hi)
    if len(ticks) < 2:
        return ticks, [f"{t:.4g}" for t in ticks]
    kind, digits = _notation(ticks)
    return ticks, [_write(t, kind, digits) for t in ticks]


def _notation(ticks: NDArray[np.float64]) -> tuple[str, int]:
    """``("f", decimals)`` or ``("e", digits)``: what writes every tick exactly."""
    step = float(np.min(np.diff(ticks)))
    big = float(np.abs(ticks).max())
    if 1e-3 <= big < 1e5 or big == 0.0:
        decimals = max(0, int(-np.floor(np.log10(step) + 1e-9)))
        while decimals < 12 and any(abs(float(f"{t:.{decimals}f}") - t) > 1e-6 * step for t in ticks):
            decimals += 1  # a step of 0.15 needs two decimals
        return "f", decimals
    digits = max(0, int(np.floor(np.log10(big) + 1e-9) - np.floor(np.log10(step) + 1e-9)))
    while digits < 12 and any(abs(float(f"{t:.{digits}e}") - t) > 1e-6 * step for t in ticks):
        digits += 1
    return "e", digits


def _write(value: float, kind: str, digits: int) -> str:
    text = f"{value:.{digits}{kind}}"
    return "0" if float(text) == 0.0 and text.startswith("-") else text


def legend_ticks(lo: float, hi: float) -> tuple[NDArray[np.float64], list[str], NDArray[np.bool_]]:
    """The legend's ticks: the round ticks of :func:`_tick_labels` and both ends of the
    range, an end that is no round tick written with one digit more than the ticks (the
    colour bar of a range 0.5412 .. 2.3317 reads 0.54, 0.9, ..., 2.1, 2.33: the drawing
    leaves out a round tick too close to an end to be read). Returns the values, their
    labels and which are ends.

    >>> legend_ticks(0.5412, 2.3317)[1]
    ['0.54', '0.6', '0.9', '1.2', '1.5', '1.8', '2.1', '2.33']
    >>> legend_ticks(0.0, 1.0)[1]
    ['0.0', '0.2', '0.4', '0.6', '0.8', '1.0']
    """
    ticks, labels = _tick_labels(lo, hi)
    kind, digits = _notation(ticks) if len(ticks) > 1 else ("g", 3)
    span = hi - lo
    values, texts, ends = list(ticks), list(labels), [False] * len(ticks)
    for end, where in ((lo, 0), (hi, None)):
        near = [i for i, t in enumerate(values) if abs(t - end) <= 1e-9 * span]
        if near:
            ends[near[0]] = True
            continue
        at = len(values) if where is None else where
        values.insert(at, end)
        texts.insert(at, _write(end, kind, digits + 1))
        ends.insert(at, True)
    return np.asarray(values), texts, np.asarray(ends)


# ---- measuring and drawing ----

def _text_width(text: str, size: float, bold: bool = False) -> float:
    """Width in pixels of ``text`` as matplotlib draws it."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextToPath

    prop = FontProperties(size=size, weight="bold" if bold else "normal")
    width, _, _ = TextToPath().get_text_width_height_descent(text, prop, ismath=False)
    return width * DPI / 72.0


def _parts(font: float) -> tuple[float, float, float]:
    """Pixel widths of the gap, the colour bar and the opacity curve."""
    pt = DPI / 72.0
    return 0.5 * font * pt, 1.6 * font * pt, 2.6 * font * pt


def legend_width(tf: TransferFunction, label: str, font: float) -> int:
    """The legend's width: its label, or tick labels + bar + opacity curve, whichever is
    wider. It does not depend on the data (a constant field's swatch and value fit in it),
    so every time step of a series is laid out alike."""
    gap, bar_w, curve_w = _parts(font)
    _, labels, _ = legend_ticks(*tf.domain)
    ticks_w = max((_text_width(t, font * 0.85) for t in labels), default=0.0) + 6
    body = ticks_w + bar_w + gap + curve_w + _text_width("0", font * 0.7)
    longest = max(labels, key=len, default="0")
    constant = bar_w + gap + _text_width(f"constant {longest}00", font * 0.85)
    return int(np.ceil(2 * gap + max(body, constant, _text_width(label, font, bold=True))))


def draw_legend(fig: Any, tf: TransferFunction, layout: Plan, ink: str, label: str,
                data_range: tuple[float, float] | None = None) -> None:
    """The legend in the strip right of the render: the label on top, then a colour bar
    over the transfer function's range (triangles at the ends the data runs past) with the
    opacity curve beside it, or, for a constant field, its one colour and value."""
    (fw, fh), (w, h), font = layout.picture, layout.area, layout.font
    gap, bar_w, curve_w = _parts(font)
    top, bottom = max(0.14 * h, 2.2 * font * DPI / 72.0), max(0.12 * h, 2.2 * font * DPI / 72.0)
    hh = max(h - top - bottom, 1.0)
    x0 = w + gap
    fig.text(x0 / fw, (h - 0.5 * top) / fh, label, ha="left", va="center", color=ink, fontsize=font,
             fontweight="bold")
    if _is_constant(data_range):
        _draw_constant(fig, tf, layout, ink, data_range[0], (x0, h - top))  # type: ignore[index]
        return
    lo, hi = tf.domain
    values, labels, ends = legend_ticks(lo, hi)
    x_bar = x0 + max((_text_width(t, font * 0.85) for t in labels), default=0.0) + 6
    cax = fig.add_axes((x_bar / fw, bottom / fh, bar_w / fw, hh / fh))
    bar = _colour_bar(fig, cax, tf, extend_of((lo, hi), data_range))
    # Labels closer than a line of type to an end's label are left out; the ends stay.
    pos = bar.ax.get_position()
    px_per_unit = pos.height * fh / (hi - lo)
    line = 2.0 * font * 0.85 * DPI / 72.0
    keep = ends | np.array([min(abs(v - lo), abs(hi - v)) * px_per_unit >= line for v in values])
    bar.set_ticks(values[keep], labels=[t for t, k in zip(labels, keep) if k])
    bar.ax.yaxis.set_ticks_position("left")
    bar.ax.tick_params(axis="y", colors=ink, labelsize=font * 0.85, length=3)
    bar.outline.set_edgecolor(ink)
    bar.outline.set_linewidth(0.6)
    s = np.linspace(lo, hi, 256)
    alpha = tf.evaluate(s)[1]
    oax = fig.add_axes(((x_bar + bar_w + 0.6 * gap) / fw, pos.y0, curve_w / fw, pos.height))  # the bar's own span
    oax.fill_betweenx(s, 0, alpha, color=ink, alpha=0.12, linewidth=0)
    oax.plot(alpha, s, color=ink, linewidth=1.2)
    oax.set_ylim(lo, hi)
    oax.set_xlim(0, 1.02)
    oax.set_yticks([])
    oax.set_xticks([0, 1])
    oax.tick_params(axis="x", colors=ink, labelsize=font * 0.7, length=2)
    oax.set_xlabel("opacity", color=ink, fontsize=font * 0.75, labelpad=1)
    oax.patch.set_alpha(0.0)
    for side, spine in oax.spines.items():
        spine.set_visible(side in ("bottom", "left"))
        spine.set_color(ink)
        spine.set_linewidth(0.6)


def _colour_bar(fig: Any, cax: Any, tf: TransferFunction, extend: str) -> Any:
    """matplotlib's colorbar of the transfer function's colours; values beyond the range
    take the end colours, as the renderer draws them."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import ListedColormap, Normalize

    lo, hi = tf.domain
    rgb = tf.evaluate(np.linspace(lo, hi, 256))[0]
    cmap = ListedColormap(np.clip(rgb, 0.0, 1.0))
    cmap = cmap.with_extremes(under=cmap(0), over=cmap(255))
    return fig.colorbar(ScalarMappable(Normalize(lo, hi), cmap), cax=cax, extend=extend, extendfrac=0.06)


def _draw_constant(fig: Any, tf: TransferFunction, layout: Plan, ink: str, value: float,
                   corner: tuple[float, float]) -> None:
    """A constant field's legend: a swatch of its colour and ``constant 1.0``."""
    (fw, fh), font = layout.picture, layout.font
    gap, bar_w, _ = _parts(font)
    x0, y_top = corner
    rgb = np.clip(tf.evaluate([value])[0][0], 0.0, 1.0)
    sax = fig.add_axes((x0 / fw, (y_top - bar_w) / fh, bar_w / fw, bar_w / fh))
    sax.set_facecolor(tuple(float(c) for c in rgb))
    sax.set_xticks([])
    sax.set_yticks([])
    for spine in sax.spines.values():
        spine.set_color(ink)
        spine.set_linewidth(0.6)
    fig.text((x0 + bar_w + gap) / fw, (y_top - 0.5 * bar_w) / fh, f"constant {plain(value)}", ha="left",
             va="center", color=ink, fontsize=font * 0.85)

"""Pictures that explain themselves: a colour legend, title, orientation triad and
bounding-box outline composited over a rendered image with matplotlib.

The rendered float image is never changed: :func:`annotate` draws it pixel for pixel
(no resampling) into a matplotlib figure and adds the labels around and over it; the
annotated PNG is a separate product. :func:`plot` is the one-liner that reads, renders
and annotates, returning a :class:`Picture` that displays itself in Jupyter.

The legend shows the colour map over the transfer function's range with ticks in the
field's units, and beside it the opacity curve (opacity per unit distance, the value a
slab ``unit_distance`` thick reaches), so a reader can tell which values are see-through.

matplotlib is an optional dependency (``pip install tetvr[plot]``); nothing here imports
it until a picture is annotated.
"""

from __future__ import annotations

import dataclasses
import io
import os
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tetvr.core.camera import Camera
from tetvr.core.image import DEFAULT_BACKGROUND, atomic_output, composite_over, to_rgba8
from tetvr.core.outputs import check_outputs, check_writable
from tetvr.optics.transfer import TransferFunction

__all__ = ["Picture", "annotate", "panels", "plot", "show", "as_mesh"]

_AXIS_COLOURS = ("#d62728", "#2ca02c", "#1f77b4")  # x, y, z: red, green, blue as ParaView and VTK draw them


def _matplotlib() -> Any:
    try:
        import matplotlib
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise ImportError("annotated pictures need matplotlib: pip install 'tetvr[plot]' (or matplotlib); "
                          "without it, write the plain image with tetvr.write_png") from None
    return matplotlib, Figure, FigureCanvasAgg


@dataclasses.dataclass(frozen=True, eq=False)
class Picture:
    """A rendered image and its annotated PNG.

    Attributes
    ----------
    image : the premultiplied float RGBA image exactly as rendered, (H, W, 4).
    png : the annotated picture as PNG bytes (the legend makes it wider than ``image``).

    In Jupyter a ``Picture`` displays itself (``_repr_png_``).

    Examples
    --------
    >>> pic = tetvr.plot("mesh.vtu", scalars="T")  # doctest: +SKIP
    >>> pic.save("mesh.png")                        # doctest: +SKIP
    """

    image: NDArray[np.float32]
    png: bytes
    #: The files the picture was made from (:func:`plot` of a path): never written over.
    inputs: tuple[str, ...] = ()

    def _repr_png_(self) -> bytes:
        return self.png

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the annotated PNG (atomically; never over the file it was made from)."""
        check_outputs([("picture", path)], [("mesh file", p) for p in self.inputs], by="this picture")
        check_writable(path, "picture")
        with atomic_output(path) as f:
            f.write(self.png)

    def to_array(self) -> NDArray[np.uint8]:
        """The annotated picture as 8-bit RGBA, (H', W', 4)."""
        _matplotlib()
        import matplotlib.image

        return (matplotlib.image.imread(io.BytesIO(self.png), format="png") * 255).round().astype(np.uint8)


def _text_colour(background: Sequence[float] | None) -> str:
    if background is None:
        return "black"
    r, g, b = (float(v) for v in background)
    return "black" if 0.2126 * r + 0.7152 * g + 0.0722 * b > 0.5 else "white"


def _project_px(camera: Camera, points: ArrayLike, size: tuple[int, int]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Pixel coordinates (x right, y down, pixel centres at +0.5) of world points, and
    whether each lies in front of the camera."""
    w, h = size
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    p = np.c_[pts, np.ones(len(pts))]
    clip = p @ (camera.projection_matrix(w / h) @ camera.view_matrix()).T
    front = clip[:, 3] > 1e-12 * np.abs(clip).max()
    ndc = clip[:, :2] / np.where(front, clip[:, 3], 1.0)[:, None]
    return np.c_[(ndc[:, 0] + 1) * 0.5 * w, (1 - ndc[:, 1]) * 0.5 * h], front


def _ticks(lo: float, hi: float) -> NDArray[np.float64]:
    _matplotlib()
    from matplotlib.ticker import MaxNLocator

    t = np.asarray(MaxNLocator(nbins=6).tick_values(lo, hi))
    span = hi - lo
    return t[(t >= lo - 1e-9 * span) & (t <= hi + 1e-9 * span)]


def annotate(
    image: ArrayLike,
    tf: TransferFunction,
    *,
    field: str | None = None,
    units: str | None = None,
    title: str | None = None,
    camera: Camera | None = None,
    bounds: ArrayLike | None = None,
    legend: bool = True,
    triad: bool = True,
    outline: bool = True,
    background: Sequence[float] | None = DEFAULT_BACKGROUND,
) -> bytes:
    """The annotated PNG of a rendered image, as bytes.

    Parameters
    ----------
    image : premultiplied float RGBA, (H, W, 4), as :func:`tetvr.render` returns it;
        drawn pixel for pixel.
    tf : the transfer function it was rendered with (the legend's colours, opacity, range).
    field, units : the legend's label: ``"Density [kg/m^3]"``.
    title : a line above the picture.
    camera : the camera it was rendered with; needed for the triad and the outline.
    bounds : the ``(2, 3)`` box to outline (the mesh's bounds).
    legend, triad, outline : which annotations to draw.
    background : composited under the image (``None``: keep it translucent).

    Examples
    --------
    >>> png = annotate(tetvr.render(mesh), tf, field="T", camera=cam, bounds=mesh.bounds)  # doctest: +SKIP
    """
    _, Figure, FigureCanvasAgg = _matplotlib()
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 4:
        raise ValueError(f"image must have shape (H, W, 4), got {img.shape}")
    if not isinstance(tf, TransferFunction):
        raise TypeError(f"tf must be a TransferFunction, got {type(tf).__name__}")
    h, w = img.shape[:2]
    size = (w, h)
    rgba = to_rgba8(composite_over(img, background))
    ink = _text_colour(background)
    face = "none" if background is None else tuple(float(v) for v in background)
    dpi = 100.0
    # Type scaled to the picture, within what stays readable: 11 pt on a 512-pixel-high picture.
    font = float(np.clip(h / 512.0 * 11.0, 7.0, 16.0))
    label = _legend_label(field, units)
    legend_w = _legend_width(tf, label, font, dpi) if legend else 0
    title_h = int(round(font * 2.2 * dpi / 72.0)) if title else 0
    fw, fh = w + legend_w, h + title_h
    fig = Figure(figsize=(fw / dpi, fh / dpi), dpi=dpi, facecolor=face)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, w / fw, h / fh))
    ax.imshow(rgba, interpolation="none", extent=(0, w, h, 0), resample=False)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_axis_off()
    if title:
        fig.text(0.5 * w / fw, 1.0 - 0.5 * title_h / fh, title, ha="center", va="center", color=ink,
                 fontsize=font * 1.2, fontweight="bold")
    if outline and camera is not None and bounds is not None:
        _draw_outline(ax, camera, bounds, size, ink)
    if triad and camera is not None:
        _draw_triad(ax, camera, size, font, ink)
    if legend:
        _draw_legend(fig, tf, (w, fw, h, fh), font, ink, label)
    out = io.BytesIO()
    fig.savefig(out, format="png", dpi=dpi, facecolor=face, transparent=background is None)
    return out.getvalue()


def _draw_outline(ax: Any, camera: Camera, bounds: ArrayLike, size: tuple[int, int], ink: str) -> None:
    lo, hi = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    px, front = _project_px(camera, corners, size)
    for i in range(8):
        for k in range(3):
            j = i | (1 << k)
            if j != i and front[i] and front[j]:
                ax.plot(px[[i, j], 0], px[[i, j], 1], color=ink, alpha=0.35, linewidth=0.8, solid_capstyle="round")


def _draw_triad(ax: Any, camera: Camera, size: tuple[int, int], font: float, ink: str) -> None:
    """World x, y, z as seen by the camera, in the lower-left corner (directions only)."""
    w, h = size
    right, up, back = camera.basis()
    length = 0.07 * min(w, h) + 8
    ox, oy = 1.35 * length + 4, h - 1.35 * length - 4  # room for an axis and its label on every side
    # The axes pointing away from the viewer are drawn first, so nearer ones are on top.
    for k in np.argsort([back[k] for k in range(3)]):
        dx, dy = right[k] * length, -up[k] * length
        ax.annotate("", xy=(ox + dx, oy + dy), xytext=(ox, oy),
                    arrowprops=dict(arrowstyle="-|>", color=_AXIS_COLOURS[k], lw=1.6, shrinkA=0, shrinkB=0,
                                    mutation_scale=font * 0.9))
        n = np.hypot(dx, dy)
        lx, ly = (ox + dx * (1 + 0.22 * length / max(n, 1e-9)), oy + dy * (1 + 0.22 * length / max(n, 1e-9)))
        ax.text(lx, ly, "xyz"[k], color=_AXIS_COLOURS[k], fontsize=font * 0.9, ha="center", va="center",
                fontweight="bold")


def _legend_label(field: str | None, units: str | None) -> str:
    return (field or "scalars") + (f" [{units}]" if units else "")


def _tick_labels(lo: float, hi: float) -> tuple[NDArray[np.float64], list[str]]:
    """Ticks across ``lo .. hi`` and their labels, with as many digits as the step needs
    (scientific notation outside 1e-3 .. 1e5).

    >>> _tick_labels(0.0, 1.0)[1], _tick_labels(0.1, 0.8)[1]
    (['0.0', '0.2', '0.4', '0.6', '0.8', '1.0'], ['0.15', '0.30', '0.45', '0.60', '0.75'])
    """
    ticks = _ticks(lo, hi)
    if len(ticks) < 2:
        return ticks, [f"{t:.4g}" for t in ticks]
    step = float(np.min(np.diff(ticks)))
    big = float(np.abs(ticks).max())
    if 1e-3 <= big < 1e5 or big == 0.0:
        decimals = max(0, int(-np.floor(np.log10(step) + 1e-9)))
        while decimals < 12 and any(abs(float(f"{t:.{decimals}f}") - t) > 1e-6 * step for t in ticks):
            decimals += 1  # a step of 0.15 needs two decimals
        labels = [f"{t:.{decimals}f}" for t in ticks]
    else:
        digits = max(0, int(np.floor(np.log10(big) + 1e-9) - np.floor(np.log10(step) + 1e-9)))
        while digits < 12 and any(abs(float(f"{t:.{digits}e}") - t) > 1e-6 * step for t in ticks):
            digits += 1
        labels = [f"{t:.{digits}e}" for t in ticks]
    return ticks, [("0" if float(lab) == 0.0 and lab.startswith("-") else lab) for lab in labels]


def _text_width(text: str, size: float, dpi: float, bold: bool = False) -> float:
    """Width in pixels of ``text`` as matplotlib draws it."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextToPath

    prop = FontProperties(size=size, weight="bold" if bold else "normal")
    width, _, _ = TextToPath().get_text_width_height_descent(text, prop, ismath=False)
    return width * dpi / 72.0


def _legend_parts(font: float, dpi: float) -> tuple[float, float, float]:
    """Pixel widths of the gap, the colour bar and the opacity curve."""
    pt = dpi / 72.0
    return 0.5 * font * pt, 1.6 * font * pt, 2.6 * font * pt


def _legend_width(tf: TransferFunction, label: str, font: float, dpi: float) -> int:
    """The legend's width: its label, or tick labels + bar + opacity curve, whichever is wider."""
    gap, bar_w, curve_w = _legend_parts(font, dpi)
    _, labels = _tick_labels(*tf.domain)
    ticks_w = max((_text_width(t, font * 0.85, dpi) for t in labels), default=0.0) + 6
    body = ticks_w + bar_w + gap + curve_w + _text_width("0", font * 0.7, dpi)
    return int(np.ceil(2 * gap + max(body, _text_width(label, font, dpi, bold=True))))


def _draw_legend(fig: Any, tf: TransferFunction, layout: tuple[int, int, int, int], font: float, ink: str,
                 label: str) -> None:
    """A colour bar over the transfer function's range with ticks in the field's units,
    and the opacity curve beside it."""
    w, fw, h, fh = layout
    dpi = fig.dpi
    lo, hi = tf.domain
    gap, bar_w, curve_w = _legend_parts(font, dpi)
    top, bottom = max(0.14 * h, 2.2 * font * dpi / 72.0), max(0.12 * h, 2.2 * font * dpi / 72.0)
    hh = max(h - top - bottom, 1.0)
    x0 = w + gap
    fig.text(x0 / fw, (h - 0.5 * top) / fh, label, ha="left", va="center", color=ink, fontsize=font,
             fontweight="bold")
    ticks, labels = _tick_labels(lo, hi)
    x_bar = x0 + max((_text_width(t, font * 0.85, dpi) for t in labels), default=0.0) + 6
    s = np.linspace(lo, hi, 256)
    rgb, alpha = tf.evaluate(s)
    cax = fig.add_axes((x_bar / fw, bottom / fh, bar_w / fw, hh / fh))
    cax.imshow(rgb[::-1, None, :], aspect="auto", extent=(0, 1, lo, hi), interpolation="nearest")
    cax.set_xticks([])
    cax.set_yticks(ticks, labels)
    cax.yaxis.tick_left()
    cax.tick_params(axis="y", colors=ink, labelsize=font * 0.85, length=3)
    cax.set_ylim(lo, hi)
    for spine in cax.spines.values():
        spine.set_color(ink)
        spine.set_linewidth(0.6)
    oax = fig.add_axes(((x_bar + bar_w + 0.6 * gap) / fw, bottom / fh, curve_w / fw, hh / fh))
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


# ---- labelled panels: several pictures side by side, each with its title ----

def panels(
    images: Sequence[ArrayLike],
    titles: Sequence[str] | None = None,
    *,
    background: Sequence[float] | None = DEFAULT_BACKGROUND,
    cols: int | None = None,
    suptitle: str | None = None,
    width_in: float = 2.2,
    dpi: float = 110.0,
) -> bytes:
    """Rendered images in a grid, each under its title, as one PNG (bytes).

    Parameters
    ----------
    images : premultiplied float RGBA images, (H, W, 4) each (sizes may differ).
    titles : one line per image (what it shows; a number such as PSNR where it has one).
    background : composited under every image.
    cols : images per row (default: all in one row).
    suptitle : a line above the grid.
    width_in, dpi : the width of one panel in inches, and the resolution.

    Examples
    --------
    >>> png = panels([img_a, img_b], ["projected tetrahedra", "reference"])  # doctest: +SKIP
    """
    _, Figure, FigureCanvasAgg = _matplotlib()
    imgs = [np.asarray(im) for im in images]
    if not imgs:
        raise ValueError("panels needs at least one image")
    for i, im in enumerate(imgs):
        if im.ndim != 3 or im.shape[2] != 4:
            raise ValueError(f"image {i} must have shape (H, W, 4), got {im.shape}")
    names = list(titles) if titles is not None else [""] * len(imgs)
    if len(names) != len(imgs):
        raise ValueError(f"{len(imgs)} images but {len(names)} titles")
    n = len(imgs)
    cols = max(1, min(int(cols or n), n))
    rows = -(-n // cols)
    aspect = max(im.shape[0] / im.shape[1] for im in imgs)
    title_in = 0.3 if any(names) else 0.05
    face = "none" if background is None else tuple(float(v) for v in background)
    ink = _text_colour(background)
    height_in = rows * (width_in * aspect + title_in) + (0.35 if suptitle else 0.0)
    fig = Figure(figsize=(width_in * cols, height_in), dpi=dpi, facecolor=face)
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, im, name in zip(axes.ravel(), imgs, names):
        ax.imshow(to_rgba8(composite_over(im, background)), interpolation="nearest")
        ax.set_title(name, fontsize=8, color=ink)
    if suptitle:
        fig.suptitle(suptitle, fontsize=10, color=ink, y=1.0 - 0.05 / height_in, va="top")
    fig.tight_layout(pad=0.3, rect=(0.0, 0.0, 1.0, 1.0 - (0.35 / height_in if suptitle else 0.0)))
    out = io.BytesIO()
    fig.savefig(out, format="png", dpi=dpi, facecolor=face, transparent=background is None)
    return out.getvalue()


def show(images: ArrayLike | Sequence[ArrayLike], titles: str | Sequence[str] | None = None, **kwargs: Any) -> Picture:
    """One image or several, labelled, as a :class:`Picture` (Jupyter displays it).

    ``images`` is one (H, W, 4) image or a list of them; ``titles`` one line per image;
    further keywords go to :func:`panels`.

    Examples
    --------
    >>> tetvr.show([tetvr.render(mesh), tetvr.render(mesh, method="reference")],
    ...            ["GPU", "CPU reference"])  # doctest: +SKIP
    """
    one = isinstance(images, np.ndarray) and images.ndim == 3
    imgs = [np.asarray(images)] if one else [np.asarray(im) for im in images]  # type: ignore[union-attr]
    names = [titles] if isinstance(titles, str) else titles
    png = panels(imgs, names, **kwargs)
    return Picture(image=imgs[0] if len(imgs) == 1 else _tiled(imgs), png=png)


def _tiled(images: list[NDArray[Any]]) -> NDArray[np.float32]:
    """Images side by side on one transparent canvas (tops aligned)."""
    h = max(im.shape[0] for im in images)
    out = np.zeros((h, sum(im.shape[1] for im in images), 4), dtype=np.float32)
    x = 0
    for im in images:
        out[:im.shape[0], x:x + im.shape[1]] = im
        x += im.shape[1]
    return out


# ---- the one-liner ----

def as_mesh(obj: Any, scalars: str | None = None, *, component: int | None = None) -> Any:
    """A :class:`~tetvr.TetMesh` from what a user holds: a path, a TetMesh, a
    ``meshio.Mesh``, a ``pyvista`` dataset or a ``vtk`` data set (neither imported unless given)."""
    from tetvr.mesh.tetmesh import TetMesh
    from tetvr.io.meshfile import read

    if isinstance(obj, (str, os.PathLike)):
        return read(obj, scalars, component=component)
    if isinstance(obj, TetMesh):
        if scalars is not None and scalars != obj.scalar_name:
            raise ValueError(f"the TetMesh carries the field {obj.scalar_name!r}, not {scalars!r}; "
                             "use mesh.with_scalars(values, name) or read the file with scalars=")
        return obj
    module = type(obj).__module__.split(".")[0]
    if module == "meshio" or type(obj).__name__ == "Mesh" and hasattr(obj, "cells") and hasattr(obj, "points"):
        return TetMesh.from_meshio(obj, scalars, component=component)
    if module in ("pyvista", "vtk", "vtkmodules") or hasattr(obj, "GetNumberOfCells"):
        return TetMesh.from_pyvista(obj, scalars, component=component)
    raise TypeError(f"cannot make a tetrahedral mesh from a {type(obj).__module__}.{type(obj).__name__}: give a "
                    "file path, a TetMesh, a meshio.Mesh, a pyvista or a vtk data set")


def plot(
    mesh: Any,
    scalars: str | None = None,
    *,
    cmap: str = "viridis",
    size: tuple[int, int] = (800, 600),
    background: Sequence[float] = DEFAULT_BACKGROUND,
    title: str | None = None,
    units: str | None = None,
    camera: Camera | None = None,
    tf: TransferFunction | None = None,
    settings: Any = None,
    method: str = "gpu",
    annotations: bool = True,
) -> Picture:
    """Render a mesh and label the picture: the one-liner.

    Parameters
    ----------
    mesh : a mesh file path, a :class:`~tetvr.TetMesh`, a ``meshio.Mesh``, a ``pyvista``
        or ``vtk`` data set.
    scalars : the field to render (default: the file's first).
    cmap : a tetvr preset or any matplotlib colormap name (ignored when ``tf`` is given).
    size : (width, height) of the rendered image; the legend is added to its right.
    background : RGB in [0, 1].
    title, units : the title line and the field's units in the legend.
    camera, tf, settings, method : as :func:`tetvr.render`; by default the camera frames
        the mesh in this image's shape and ``tf`` is the data-driven default
        (:func:`tetvr.render.default_transfer_function`).
    annotations : ``False`` for the plain picture (no legend, triad or outline).

    Returns
    -------
    Picture : ``.image`` is the exact float image, ``.png`` the annotated picture;
        ``.save(path)`` writes it; Jupyter displays it.

    Examples
    --------
    >>> tetvr.plot("bluntfin.vtu", "Density", cmap="magma").save("bluntfin.png")  # doctest: +SKIP
    """
    from tetvr.core.camera import _fit
    from tetvr.core.image import image_size, png_bytes
    from tetvr.render import default_transfer_function, render

    m = as_mesh(mesh, scalars)
    w, h = image_size(size)
    if camera is None:
        camera = _fit(m, aspect=w / h)
    if tf is None:
        tf = default_transfer_function(m, preset=cmap)
    image = render(m, camera=camera, tf=tf, size=(w, h), settings=settings, method=method)
    if annotations:
        png = annotate(image, tf, field=m.scalar_name, units=units, title=title, camera=camera, bounds=m.bounds,
                       background=background)
    else:
        png = png_bytes(image, background=background)
    return Picture(image=image, png=png, inputs=(os.fspath(mesh),) if isinstance(mesh, (str, os.PathLike)) else ())

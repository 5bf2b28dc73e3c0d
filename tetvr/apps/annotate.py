"""Pictures that explain themselves: a colour legend, title, orientation triad and
bounding-box outline composited over a rendered image with matplotlib.

The rendered float image is never changed: :func:`annotate` draws it pixel for pixel
(no resampling) into a matplotlib figure and adds the labels around and over it; the
annotated PNG is a separate product. :func:`plot` is the one-liner that reads, renders
and annotates, returning a :class:`Picture` that displays itself in Jupyter.

The legend (:mod:`tetvr.apps.legend`) shows the colour map over the transfer function's
range with ticks in the field's units and both ends labelled, triangles at the ends the
data runs past (clipped), and beside it the opacity curve (opacity per unit distance, the
value a slab ``unit_distance`` thick reaches), so a reader can tell which values are
see-through. A constant field's legend says so. The picture is laid out around the render,
or inside a given size (:func:`render_area`); :func:`frame` fits a camera that keeps the
outline in view.

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

from tetvr.apps.legend import DPI, draw_legend, field_label, plan
from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.core.image import DEFAULT_BACKGROUND, atomic_output, composite_over, image_size, to_rgba8
from tetvr.core.outputs import check_outputs, check_writable
from tetvr.optics.transfer import TransferFunction

__all__ = ["Framed", "Picture", "annotate", "frame", "mesh_labels", "panels", "plot", "render_area", "show", "as_mesh"]

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
    camera = resolve_clipping_range(camera, pts)  # x and y do not depend on it; the matrix needs one
    p = np.c_[pts, np.ones(len(pts))]
    clip = p @ (camera.projection_matrix(w / h) @ camera.view_matrix()).T
    front = clip[:, 3] > 1e-12 * np.abs(clip).max()
    ndc = clip[:, :2] / np.where(front, clip[:, 3], 1.0)[:, None]
    return np.c_[(ndc[:, 0] + 1) * 0.5 * w, (1 - ndc[:, 1]) * 0.5 * h], front


def _outline(camera: Camera, bounds: ArrayLike, size: tuple[int, int]) -> list[NDArray[np.float64]]:
    """The box's edges in the picture: (2, 2) pixel end points each (the edges in front of the camera)."""
    lo, hi = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
    px, front = _project_px(camera, corners, size)
    return [px[[i, i | (1 << k)]] for i in range(8) for k in range(3)
            if i | (1 << k) != i and front[i] and front[i | (1 << k)]]


def _triad_length(size: tuple[int, int]) -> float:
    return 0.07 * min(size) + 8


def _triad_origin(alpha: NDArray[Any], edges: list[NDArray[np.float64]], size: tuple[int, int]) -> tuple[float, float]:
    """Where the triad goes: the lower-left corner (ParaView's), unless another corner is
    clearly emptier (less than half the ink: the data's opacity and the outline's edges in
    the square the triad takes)."""
    w, h = size
    length = _triad_length(size)
    r = 1.35 * length + 4  # room for an axis and its label on every side
    t = np.linspace(0.0, 1.0, 64)[:, None]
    samples = np.concatenate([e[0] + t * (e[1] - e[0]) for e in edges] + [np.empty((0, 2))])
    # An edge is a line a pixel wide drawn at opacity 0.35: each sample stands for 1/64 of it.
    weight = np.concatenate([np.full(64, 0.35 * float(np.linalg.norm(e[1] - e[0])) / 64) for e in edges] + [[]])
    best, origin = np.inf, (r, h - r)
    for ox, oy in ((r, h - r), (w - r, h - r), (r, r), (w - r, r)):
        x0, x1, y0, y1 = (max(int(v), 0) for v in (ox - r, ox + r, oy - r, oy + r))
        inside = (np.abs(samples[:, 0] - ox) < r) & (np.abs(samples[:, 1] - oy) < r)
        ink = float(alpha[y0:y1, x0:x1].sum()) + float(weight[inside].sum())
        if ink < 0.5 * best:
            best, origin = ink, (ox, oy)
    return origin


def _draw_triad(ax: Any, camera: Camera, size: tuple[int, int], font: float, origin: tuple[float, float]) -> None:
    """World x, y, z as seen by the camera, about ``origin`` (directions only)."""
    right, up, back = camera.basis()
    length = _triad_length(size)
    ox, oy = origin
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


def annotate(
    image: ArrayLike,
    tf: TransferFunction,
    *,
    field: str | None = None,
    units: str | None = None,
    title: str | None = None,
    camera: Camera | None = None,
    bounds: ArrayLike | None = None,
    data_range: tuple[float, float] | None = None,
    size: tuple[int, int] | None = None,
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
    field, units : the legend's label: ``"Density [kg/m^3]"`` (:func:`mesh_labels` gives
        a mesh's, ``"|Velocity|"`` for a vector field's magnitude).
    title : a line above the picture.
    camera : the camera it was rendered with; needed for the triad and the outline.
    bounds : the ``(2, 3)`` box to outline (the mesh's bounds).
    data_range : the field's own ``(min, max)``: the colour bar marks the ends the data
        runs past (drawn in the end colours), and a constant field's legend says
        ``constant 1.0`` instead of inventing a range.
    size : the whole picture's (width, height); ``image`` must then be the render area
        :func:`render_area` gives for it. Default: the picture is ``image`` with the
        legend to its right and the title above.
    legend, triad, outline : which annotations to draw.
    background : composited under the image (``None``: keep it translucent).

    Examples
    --------
    >>> png = annotate(tetvr.render(mesh), tf, camera=cam, **mesh_labels(mesh))  # doctest: +SKIP
    """
    fig = _figure(image, tf, field=field, units=units, title=title, camera=camera, bounds=bounds,
                  data_range=data_range, size=size, legend=legend, triad=triad, outline=outline,
                  background=background)
    out = io.BytesIO()
    fig.savefig(out, format="png", dpi=fig.dpi, facecolor=fig.get_facecolor(), transparent=background is None)
    return out.getvalue()


def _figure(image: ArrayLike, tf: TransferFunction, *, field: str | None, units: str | None, title: str | None,
            camera: Camera | None, bounds: ArrayLike | None, data_range: tuple[float, float] | None,
            size: tuple[int, int] | None, legend: bool, triad: bool, outline: bool,
            background: Sequence[float] | None) -> Any:
    """:func:`annotate`'s matplotlib figure."""
    _, Figure, FigureCanvasAgg = _matplotlib()
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 4:
        raise ValueError(f"image must have shape (H, W, 4), got {img.shape}")
    if not isinstance(tf, TransferFunction):
        raise TypeError(f"tf must be a TransferFunction, got {type(tf).__name__}")
    h, w = img.shape[:2]
    label = field_label(field, units)
    layout = plan(tf, label, title=title, legend=legend,
                  **({"image": (w, h)} if size is None else {"size": image_size(size)}))
    if layout.area != (w, h):
        raise ValueError(f"image is {w}x{h} pixels, but a {layout.picture[0]}x{layout.picture[1]} picture with "
                         f"this legend and title holds a {layout.area[0]}x{layout.area[1]} render "
                         "(render_area gives it)")
    ink = _text_colour(background)
    face = "none" if background is None else tuple(float(v) for v in background)
    fw, fh = layout.picture
    fig = Figure(figsize=(fw / DPI, fh / DPI), dpi=DPI, facecolor=face)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, w / fw, h / fh))
    ax.imshow(to_rgba8(composite_over(img, background)), interpolation="none", extent=(0, w, h, 0), resample=False)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_axis_off()
    if title and layout.title_h:
        fig.text(0.5 * w / fw, 1.0 - 0.5 * layout.title_h / fh, title, ha="center", va="center", color=ink,
                 fontsize=layout.font * 1.2, fontweight="bold")
    edges = _outline(camera, bounds, (w, h)) if outline and camera is not None and bounds is not None else []
    for e in edges:
        ax.plot(e[:, 0], e[:, 1], color=ink, alpha=0.35, linewidth=0.8, solid_capstyle="round")
    if triad and camera is not None:
        _draw_triad(ax, camera, (w, h), layout.font, _triad_origin(img[..., 3], edges, (w, h)))
    if layout.legend_w:
        draw_legend(fig, tf, layout, ink, label, data_range)
    return fig


def mesh_labels(mesh: Any) -> dict[str, Any]:
    """What :func:`annotate` reads off a mesh: the legend's ``field`` (``"|Velocity|"`` for
    a vector field's magnitude, ``"Velocity[1]"`` for a component), the ``bounds`` to
    outline and the field's ``data_range``.

    >>> from tetvr.mesh import synthetic
    >>> sorted(mesh_labels(synthetic.cube(1)))
    ['bounds', 'data_range', 'field']
    """
    scalar_of = getattr(getattr(mesh, "report", None), "scalar_of", "")
    name = field_label(mesh.scalar_name, None, scalar_of) if scalar_of else mesh.scalar_name
    return {"field": name, "bounds": mesh.bounds, "data_range": mesh.scalar_range}


def render_area(size: tuple[int, int], tf: TransferFunction, *, field: str | None = None, units: str | None = None,
                title: str | None = None, legend: bool = True) -> tuple[int, int]:
    """The (width, height) of the render inside an annotated picture of ``size``: what the
    legend (to its right) and the title (above) leave. A legend or title that would take
    more than half the picture is left out (:data:`tetvr.apps.legend.MIN_RENDER_SHARE`);
    :func:`annotate` with the same arguments and ``size`` lays the picture out the same.

    >>> from tetvr.optics.transfer import TransferFunction
    >>> w, h = render_area((800, 600), TransferFunction.preset("viridis", (0.0, 1.0)), field="T")
    >>> w < 800 and h == 600
    True
    """
    _matplotlib()  # the legend is measured as matplotlib draws it
    return plan(tf, field_label(field, units), size=image_size(size), title=title, legend=legend).area


def frame(mesh: Any, size: tuple[int, int], *, outline: bool = True, **fit: Any) -> Camera:
    """A camera that frames ``mesh`` in a render of ``size`` (width, height), as
    :meth:`Camera.fit` with the options ``fit``; with ``outline`` it frames the mesh's
    bounding box too, so the outline :func:`annotate` draws stays in the picture.

    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.cube(2)  # turned: its box is larger than its silhouette
    >>> frame(mesh, (64, 48), parallel=True).parallel_scale > frame(mesh, (64, 48), outline=False,
    ...                                                             parallel=True).parallel_scale
    True
    """
    from tetvr.core.camera import _fit

    w, h = image_size(size)
    return _fit(Framed(mesh, outline), aspect=w / h, **fit)


class Framed:
    """What a picture frames (:class:`tetvr.core.camera.Bounded`): a mesh's points, a
    volume's box, and with ``outline`` the corners of the box the outline draws."""

    def __init__(self, mesh: Any, outline: bool = True) -> None:
        self.bounds = np.asarray(mesh.bounds, dtype=np.float64).reshape(2, 3)
        lo, hi = self.bounds
        corners = np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)])
        pts = getattr(mesh, "points", None)
        if pts is None or len(pts) == 0:
            self.points = corners
        else:
            self.points = np.concatenate([np.asarray(pts, dtype=np.float64), corners]) if outline else pts


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
    from tetvr.volume.volume import Volume

    if isinstance(obj, Volume):  # rendered as it is, by the same defaults (tetvr.render)
        if scalars is not None and scalars != obj.scalar_name:
            raise ValueError(f"the Volume carries one field, {obj.scalar_name!r}, not {scalars!r}")
        return obj
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
    scalars : the field to render (default: the file's first that varies, :func:`tetvr.read`).
    cmap : a tetvr preset or any matplotlib colormap name (ignored when ``tf`` is given).
    size : (width, height) of the rendered image; the legend is added to its right.
    background : RGB in [0, 1].
    title, units : the title line and the field's units in the legend.
    camera, tf, settings, method : as :func:`tetvr.render`; by default the camera frames
        the mesh in this image's shape, its bounding box too where the outline is drawn
        (:func:`frame`), and ``tf`` is the data-driven default
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
    from tetvr.core.image import png_bytes
    from tetvr.render import default_transfer_function, render

    m = as_mesh(mesh, scalars)
    w, h = image_size(size)
    if camera is None:
        camera = frame(m, (w, h), outline=annotations)  # the outline drawn stays in the picture
    if tf is None:
        tf = default_transfer_function(m, preset=cmap)
    image = render(m, camera=camera, tf=tf, size=(w, h), settings=settings, method=method)
    if annotations:
        png = annotate(image, tf, units=units, title=title, camera=camera, background=background, **mesh_labels(m))
    else:
        png = png_bytes(image, background=background)
    return Picture(image=image, png=png, inputs=(os.fspath(mesh),) if isinstance(mesh, (str, os.PathLike)) else ())

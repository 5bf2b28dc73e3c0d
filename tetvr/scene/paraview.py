"""ParaView state files (``.pvsm``) in: the view, the colour and opacity maps, the data.

About this format
-----------------
ParaView's "Save State" writes its server-manager state as XML::

    <ParaView><ServerManagerState version="5.11.0">
      <Proxy group="sources" type="LegacyVTKReader" id="..">        FileNames
      <Proxy group="representations" type="UnstructuredGridRepresentation" id="..">
          Input, Representation ("Volume"), ColorArrayName, LookupTable,
          ScalarOpacityFunction, ScalarOpacityUnitDistance, SelectMapper, Visibility
      <Proxy group="representations" type="GeometryRepresentation" id="..">
          Input (a SphereSource, ...), Representation ("Surface", "Outline"), DiffuseColor, ...
      <Proxy group="lookup_tables" type="PVLookupTable" id="..">    RGBPoints, ColorSpace,
          Discretize, NumberOfTableValues, UseLogScale, NanColor, Above/BelowRangeColor
      <Proxy group="piecewise_functions" type="PiecewiseFunction">  Points (x, a, midpoint, sharpness)
      <Proxy group="views" type="RenderView" id="..">               CameraPosition, CameraFocalPoint,
          CameraViewUp, CameraViewAngle, CameraParallelProjection, CameraParallelScale,
          ViewSize, Background, Representations
    </ServerManagerState></ParaView>

Every ``<Property>`` holds ``<Element index=".." value=".."/>`` values or ``<Proxy
value="id"/>`` references. :func:`read_state` pulls out what a volume rendering needs;
:func:`load_state` turns it into a :class:`~tetvr.scene.scene.Scene` (also what
``tetvr.load_scene("x.pvsm")`` and ``tetvr render x.pvsm`` do).

How each part maps (docs/paraview.md has the user's view of it):

* **Camera** -- 1:1 (VTK's fields are tetvr's). A state stores no clipping range (ParaView
  recomputes it every frame): it is computed from the data as ParaView does
  (:func:`tetvr.core.camera.reset_clipping_range`).
* **Colour map** -- ``RGBPoints`` in any ParaView colour space (through
  :func:`tetvr.optics.colormaps.from_paraview`); ``UseLogScale`` interpolates in log10 of the
  scalar (:meth:`~tetvr.optics.transfer.TransferFunction.log_scaled`); ``Discretize`` becomes
  ``NumberOfTableValues`` constant bands of 8-bit colours, as VTK's lookup table holds
  them; ``UseAboveRangeColor`` / ``UseBelowRangeColor`` become a jump to that colour
  just past the map's ends.
* **Opacity map** -- ``Points`` with their midpoint and sharpness (non-linear pieces are
  followed by linear ones), in log scale when the function says so; the representation's
  ``ScalarOpacityUnitDistance`` is the unit distance.
* **Other sources** in the view (a sphere, a box, a surface file, outlines) -- drawn as
  opaque :class:`~tetvr.Surface` s beside the volume (:mod:`tetvr.scene.pvsources`); each
  one tetvr cannot draw is warned about by name.
* **Not carried over**: filters between the reader and the volume's representation (the
  state is refused, naming them), ``NanColor`` (tetvr refuses NaN scalars when it reads a
  mesh, so there is nothing to colour), ``HSVWrap``, gradient backgrounds (the first colour
  is used), lights, scalar bars and annotations; one representation (the visible volume,
  else the first visible one) is rendered as the volume.

Examples
--------
>>> scene = load_state("post.pvsm")              # doctest: +SKIP
>>> scene.camera.view_angle, scene.tf.unit_distance  # doctest: +SKIP
(30.0, 0.197)
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from tetvr.core.checks import check_input_file, warn
from tetvr.core.camera import Camera, reset_clipping_range, union_bounds
from tetvr.optics.table import check_unit_distance
from tetvr.optics.transfer import paraview_unit_distance
from tetvr.scene.pvsm import (MAX_COMPONENT, MAX_TABLE_VALUES, MAX_VIEW_SIZE, OPACITY_COLUMNS, RGB_COLUMNS, StateProxy,
                              node_rows, parse_state)
from tetvr.scene.pvsources import ShownSource, shown_sources, state_surfaces

if TYPE_CHECKING:
    from tetvr.core.surface import Surface
    from tetvr.mesh.tetmesh import TetMesh
    from tetvr.scene.scene import Scene
    from tetvr.optics.transfer import TransferFunction

__all__ = ["ParaViewState", "load_state", "read_state", "state_transfer_function"]

#: ParaView's ``ColorSpace`` enumeration (5.11), used where a state omits the names.
_COLOR_SPACES = {0: "RGB", 1: "HSV", 2: "Lab", 3: "Diverging", 4: "Lab/CIEDE2000", 5: "Step"}
#: vtkDataObject field associations of ``ColorArrayName``'s fourth element.
_ASSOCIATIONS = {0: "POINTS", 1: "CELLS"}
#: Linear pieces per node interval where ParaView's curve is not linear (colour spaces other
#: than RGB, opacity midpoints and sharpness): 256 keep a Diverging map within ~3e-5 of VTK's.
_SAMPLES_PER_SEGMENT = 256


@dataclasses.dataclass(frozen=True)
class ParaViewState:
    """What a ``.pvsm`` says about one volume rendering (:func:`read_state`).

    Positions are in the data's units. ``camera`` holds the view's camera with a
    placeholder clipping range (a state has none: :func:`load_state` computes it from the
    data). ``opacity_points`` rows are ``(x, a, midpoint, sharpness)``.
    """

    path: str
    version: str
    data_file: str
    reader: str
    array: str | None
    association: str
    component: int | None
    representation: str
    mapper: str | None
    camera: Camera
    view_size: tuple[int, int] | None
    background: tuple[float, float, float]
    color_space: str
    rgb_points: tuple[tuple[float, float, float, float], ...]
    opacity_points: tuple[tuple[float, float, float, float], ...]
    unit_distance: float | None
    discretize: bool = False
    n_table_values: int = 256
    log_scale: bool = False
    opacity_log_scale: bool = False
    nan_color: tuple[float, float, float] = (1.0, 1.0, 0.0)
    above_range_color: tuple[float, float, float] | None = None
    below_range_color: tuple[float, float, float] | None = None
    view_time: float | None = None
    #: The view's other visible representations (:func:`tetvr.scene.pvsources.shown_sources`).
    others: tuple[ShownSource, ...] = ()


def read_state(path: str | os.PathLike[str]) -> ParaViewState:
    """Parse a ParaView state file (``.pvsm``).

    The rendered representation is the visible one shown as ``"Volume"`` (else the first
    visible one coloured by an array), the view is the render view that shows it.

    Raises
    ------
    ValueError : not a state file, no such representation, or a filter between the
        representation and its reader (tetvr reads the data file; it does not run filters).
    """
    path = check_input_file(path, "ParaView state file")
    version, proxies = parse_state(path)
    rep, src, files = _rendered(proxies, path)
    view = _render_view(proxies, rep, path)
    others = shown_sources(proxies, rep, view)
    view_time = view.number("ViewTime")
    times = src.floats("TimestepValues") or []  # every number is checked as it is read (StateProxy)
    data_file = files[0]
    if len(files) > 1 and len(times) == len(files) and view_time is not None:
        data_file = files[int(np.argmin(np.abs(np.asarray(times) - view_time)))]

    camera = _camera(view, path)
    size = view.integers("ViewSize", 2, 0, MAX_VIEW_SIZE)
    background = _background(view, proxies)

    # The colour map, its opacity function, the array.
    name_vals = rep.values("ColorArrayName")
    array = name_vals[4] if len(name_vals) >= 5 and name_vals[4] else None
    assoc = (_ASSOCIATIONS.get(rep.whole("ColorArrayName", name_vals[3], 0, 8), "POINTS")
             if len(name_vals) >= 5 and name_vals[3] else "POINTS")
    lut_ids = rep.refs("LookupTable")
    lut = proxies.get(lut_ids[0]) if lut_ids else None
    if lut is None or array is None:
        raise ValueError(f"{path}: the representation colours by no array (solid colour); a volume rendering "
                         "needs an array and its colour map")
    pwf_ids = rep.refs("ScalarOpacityFunction") or lut.refs("ScalarOpacityFunction")
    pwf = proxies.get(pwf_ids[0]) if pwf_ids else None
    rgb = node_rows(lut, "RGBPoints", RGB_COLUMNS)
    if pwf is not None and pwf.values("Points"):
        op = node_rows(pwf, "Points", OPACITY_COLUMNS)
    else:  # ParaView's default opacity function: a ramp over the colour map's range
        op = ((rgb[0][0], 0.0, 0.5, 0.0), (rgb[-1][0], 1.0, 0.5, 0.0))
    component = None
    if lut.enum_text("VectorMode", {0: "Magnitude", 1: "Component"}) == "Component":
        component = lut.integer("VectorComponent", 0, 0, MAX_COMPONENT)

    def colour(name: str, use: str) -> tuple[float, float, float] | None:
        c = lut.floats(name, 3, lo=0.0, hi=1.0)
        return tuple(c) if c is not None and lut.flag(use) else None  # type: ignore[return-value]

    unit = rep.number("ScalarOpacityUnitDistance")
    if unit is not None and unit > 0:
        check_unit_distance(unit, rep.where("ScalarOpacityUnitDistance"))
    return ParaViewState(
        path=os.fspath(path), version=version, data_file=data_file, reader=src.type, array=array,
        association=assoc, component=component, representation=rep.text("Representation", "") or "",
        mapper=rep.text("SelectMapper"), camera=camera,
        view_size=(size[0], size[1]) if size and size[0] >= 1 and size[1] >= 1 else None,
        background=background, color_space=lut.enum_text("ColorSpace", _COLOR_SPACES) or "RGB",
        rgb_points=rgb, opacity_points=op,  # type: ignore[arg-type]
        unit_distance=unit if unit is not None and unit > 0 else None,
        discretize=lut.flag("Discretize") and not lut.flag("IndexedLookup"),
        n_table_values=lut.integer("NumberOfTableValues", 256, 1, MAX_TABLE_VALUES),
        log_scale=lut.flag("UseLogScale"),
        opacity_log_scale=pwf.flag("UseLogScale") if pwf is not None else False,
        nan_color=tuple(lut.floats("NanColor", 3, lo=0.0, hi=1.0) or (1.0, 1.0, 0.0)),  # type: ignore[arg-type]
        above_range_color=colour("AboveRangeColor", "UseAboveRangeColor"),
        below_range_color=colour("BelowRangeColor", "UseBelowRangeColor"),
        view_time=view_time, others=others,
    )


def _rendered(proxies: dict[str, StateProxy], path: str) -> tuple[StateProxy, StateProxy, list[str]]:
    """The representation rendered (the visible volume, else the first visible one coloured by
    an array), the reader it shows directly (a filter between them is an error) and its files."""
    reps = [p for p in proxies.values() if p.group == "representations" and p.refs("Input")
            and p.flag("Visibility", True) and p.props.get("ColorArrayName") is not None]
    if not reps:
        raise ValueError(f"{path}: the state shows no dataset (no visible representation with an input)")
    # Stable: a volume first, then one coloured by an array.
    reps.sort(key=lambda r: (r.text("Representation", "") != "Volume",
                             len(r.values("ColorArrayName")) < 5 or not r.values("ColorArrayName")[4]))
    rep = reps[0]
    ids = rep.refs("Input")
    src = proxies.get(ids[0]) if ids else None
    if src is None:
        raise ValueError(f"{path}: representation {rep.id} reads proxy {rep.refs('Input')[0]}, which the state lacks")
    if src.group != "sources":
        chain = [src.type]
        up = src
        while up.group != "sources" and up.refs("Input") and up.refs("Input")[0] in proxies:
            up = proxies[up.refs("Input")[0]]
            chain.append(up.type)
        raise ValueError(f"{path}: the rendered data comes through ParaView filter(s) {' <- '.join(chain)}; "
                         "tetvr reads "
                         "data files, not pipelines: save the filter's output (File > Save Data) and open that")
    files = src.values("FileNames") or src.values("FileName")
    if not files or not files[0]:
        raise ValueError(f"{path}: the source {src.type} (id {src.id}) names no data file; tetvr reads files only")
    return rep, src, files


def _render_view(proxies: dict[str, StateProxy], rep: StateProxy, path: str) -> StateProxy:
    """The render view that shows ``rep`` (else the first render view)."""
    views = [p for p in proxies.values() if p.group == "views" and rep.id in p.refs("Representations")]
    if not views:
        views = [p for p in proxies.values() if p.group == "views" and p.type.endswith("RenderView")]
    if not views:
        raise ValueError(f"{path}: the state has no render view")
    return views[0]


def _camera(view: StateProxy, path: str) -> Camera:
    pos = view.floats("CameraPosition", 3)
    foc = view.floats("CameraFocalPoint", 3)
    if pos is None or foc is None:
        raise ValueError(f"{path}: the render view stores no camera (CameraPosition, CameraFocalPoint)")
    fields = dict(view_up=tuple(view.floats("CameraViewUp", 3) or (0.0, 1.0, 0.0)),
                  view_angle=view.number("CameraViewAngle", 30.0),
                  parallel_projection=view.flag("CameraParallelProjection"),
                  parallel_scale=view.number("CameraParallelScale", 1.0))
    try:
        return Camera(position=tuple(pos), focal_point=tuple(foc), **fields)  # type: ignore[arg-type]
    except ValueError as exc:
        raise ValueError(f"{path}: the render view's camera is not usable: {exc}") from None


def _background(view: StateProxy, proxies: dict[str, StateProxy]) -> tuple[float, float, float]:
    colour = view.floats("Background", 3)
    if view.flag("UseColorPaletteForBackground"):
        palette = [p for p in proxies.values() if p.type == "ColorPalette"]
        if palette and palette[0].floats("BackgroundColor", 3):
            colour = palette[0].floats("BackgroundColor", 3)
    if colour is None:
        colour = [0.32, 0.34, 0.43]  # ParaView's default palette
    return tuple(min(max(float(c), 0.0), 1.0) for c in colour)  # type: ignore[return-value]


# ---------------------------------------------------------------- the transfer function
def state_transfer_function(state: ParaViewState, *, unit_distance: float | None = None) -> "TransferFunction":
    """The state's colour and opacity maps as a :class:`~tetvr.TransferFunction`.

    ``unit_distance`` defaults to the state's ``ScalarOpacityUnitDistance`` (then 1.0).
    See the module notes for what each ParaView option becomes. A map tetvr cannot use
    is a ``ValueError`` that names the state file.
    """
    try:
        return _transfer_function(state, unit_distance)
    except ValueError as exc:
        if Path(state.path).name in str(exc):
            raise
        raise ValueError(f"{state.path}: its colour and opacity maps make no usable transfer function: {exc}") from None


def _transfer_function(state: ParaViewState, unit_distance: float | None) -> "TransferFunction":
    from tetvr.optics.colormaps import from_paraview
    from tetvr.optics.transfer import TransferFunction

    u = unit_distance if unit_distance is not None else (state.unit_distance or 1.0)
    rgb = np.array(state.rgb_points, dtype=np.float64)
    op = np.array(state.opacity_points, dtype=np.float64)
    for on, rows, what in ((state.log_scale, rgb, "colour map"), (state.opacity_log_scale, op, "opacity function")):
        if on:
            if np.any(rows[:, 0] <= 0):
                raise ValueError(f"{state.path}: the {what} uses a log scale over positions reaching "
                                 f"{rows[:, 0].min():g} (<= 0), which a log scale cannot map")
            rows[:, 0] = np.log10(rows[:, 0])
    # Colour spaces and midpoint/sharpness are resampled on the (log) axis the state interpolates on.
    base = from_paraview({"Name": Path(state.path).name, "ColorSpace": state.color_space,
                          "RGBPoints": rgb.ravel().tolist(), "Points": op.ravel().tolist()}, unit_distance=u,
                         samples_per_segment=_SAMPLES_PER_SEGMENT)
    color = np.array(base.color)
    opacity = np.array(base.opacity)
    if state.log_scale:
        color[:, 0] = 10.0 ** color[:, 0]
    if state.opacity_log_scale:
        opacity[:, 0] = 10.0 ** opacity[:, 0]
    tf = TransferFunction(color=_ascending(color), opacity=_ascending(opacity),  # type: ignore[arg-type]
                          unit_distance=u)
    tf = tf.log_scaled(color=state.log_scale, opacity=state.opacity_log_scale)
    lo, hi = state.rgb_points[0][0], state.rgb_points[-1][0]
    color_rows: list[tuple[float, ...]] = list(tf.color)
    if state.discretize and hi > lo:
        color_rows = _discretized(state, lo, hi)
    eps = 1e-9 * max(abs(hi - lo), abs(hi), abs(lo), 1e-300)
    if state.below_range_color is not None:
        color_rows.insert(0, (color_rows[0][0] - eps, *_eight_bit(state.below_range_color, state.discretize)))
    if state.above_range_color is not None:
        color_rows.append((color_rows[-1][0] + eps, *_eight_bit(state.above_range_color, state.discretize)))
    return dataclasses.replace(tf, color=tuple(color_rows))  # type: ignore[arg-type]  # rows of 4, built above


def _ascending(rows: Any) -> tuple[tuple[float, ...], ...]:
    """Rows whose positions ascend strictly (10**x may merge two that were apart in x)."""
    rows = np.asarray(rows)
    keep = np.concatenate([[True], np.diff(rows[:, 0]) > 0])
    return tuple(tuple(float(v) for v in r) for r in rows[keep])


def _eight_bit(rgb: Any, on: bool) -> tuple[float, ...]:
    # A discretized map's colours live in vtkLookupTable's 8-bit table: (uchar)(255 c + 0.5).
    c = np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0)
    return tuple(float(v) for v in (np.floor(255.0 * c + 0.5) / 255.0 if on else c))


def _discretized(state: ParaViewState, lo: float, hi: float) -> list[tuple[float, ...]]:
    """``n`` constant bands over ``[lo, hi]`` (equal in log10 with a log scale), band ``i``
    taking the colour at ``lo + i (hi - lo) / (n - 1)``: what
    ``vtkDiscretizableColorTransferFunction`` samples into its 8-bit lookup table, which
    then maps ``v`` to band ``floor((v - lo) n / (hi - lo))`` (the top value to the last)."""
    n, log = state.n_table_values, state.log_scale
    if not 1 <= n <= MAX_TABLE_VALUES:  # read_state checks it; a state made by hand is checked here
        raise ValueError(f"{state.path}: NumberOfTableValues must be a whole number from 1 to {MAX_TABLE_VALUES}, "
                         f"got {n!r}")
    a, b = (math.log10(lo), math.log10(hi)) if log else (lo, hi)
    samples = a + (b - a) * (np.arange(n) / (n - 1) if n > 1 else np.array([0.5]))
    edges = a + (b - a) * np.arange(n + 1) / n
    if log:
        edges = 10.0 ** edges
    # The curve itself at the samples (not its linear pieces): a band's 8-bit colour is
    # rounded from it, and a piece's small error would move some across a rounding step.
    colours = np.floor(255.0 * np.clip(_colour_curve(state, samples, log), 0.0, 1.0) + 0.5) / 255.0
    eps = 1e-9 * max(abs(hi - lo), 1e-300)
    rows: list[tuple[float, ...]] = [(float(lo), *colours[0])]
    for i in range(1, n):
        rows.append((float(edges[i]) - eps, *colours[i - 1]))
        rows.append((float(edges[i]), *colours[i]))
    rows.append((float(hi), *colours[-1]))
    return [tuple(float(v) for v in r) for r in rows]


def _colour_curve(state: ParaViewState, x: Any, log: bool) -> Any:
    """vtkColorTransferFunction's colour at positions ``x`` (log10 positions with a log
    scale), in the state's colour space, between its RGBPoints."""
    from tetvr.optics.colormaps import _interp_space

    nodes = np.array(state.rgb_points, dtype=np.float64)
    xs = np.log10(nodes[:, 0]) if log else nodes[:, 0]
    x = np.clip(np.asarray(x, dtype=np.float64), xs[0], xs[-1])
    seg = np.clip(np.searchsorted(xs, x, side="right") - 1, 0, len(xs) - 2)
    out = np.empty((len(x), 3))
    space = "Lab" if state.color_space == "Lab/CIEDE2000" else state.color_space
    for k in np.unique(seg):
        pick = seg == k
        width = xs[k + 1] - xs[k]
        t = (x[pick] - xs[k]) / width if width > 0 else np.ones(int(pick.sum()))
        c1, c2 = nodes[k, 1:], nodes[k + 1, 1:]
        if space == "RGB":
            out[pick] = c1 + t[:, None] * (c2 - c1)
        elif space == "Step":
            out[pick] = np.where((t >= 1.0)[:, None], c2, c1)
        else:
            out[pick] = _interp_space(c1, c2, t, space)
    return out


# ---------------------------------------------------------------- the scene
def _find_data(name: str, state_path: str, data_directory: str | os.PathLike[str] | None) -> str:
    """The data file a state names: as written (ParaView writes absolute paths), else
    beside the state, else in ``data_directory`` (ParaView's "Search files under
    specified directory")."""
    folder = Path(state_path).resolve().parent
    tries = [Path(name), folder / name, folder / Path(name).name]
    if data_directory is not None:
        tries += [Path(data_directory) / name, Path(data_directory) / Path(name).name]
    for p in tries:
        if p.is_file():
            return str(p)
    raise FileNotFoundError(f"{state_path}: its data file {name!r} is neither there nor beside the state"
                            + (f" nor in {os.fspath(data_directory)!r}" if data_directory is not None else "")
                            + "; put it beside the state file, or pass data_directory= (the folder that holds it) "
                            "to tetvr.scene.paraview.load_state")


def load_state(
    path: str | os.PathLike[str],
    *,
    data_directory: str | os.PathLike[str] | None = None,
    parity: bool = False,
    size: tuple[int, int] | None = None,
) -> "Scene":
    """A :class:`~tetvr.scene.scene.Scene` from a ParaView state file (``.pvsm``).

    Parameters
    ----------
    path : the state file.
    data_directory : where to look for the data file when the path the state names does
        not exist here (ParaView writes absolute paths); the state's own folder is tried first.
    parity : render with :data:`tetvr.settings.PARITY_SETTINGS` (ParaView's "Projected
        tetra" picture) instead of tetvr's exact default. The state's other sources are
        drawn either way; in parity the volume is depth-tested against them as VTK does
        (:mod:`tetvr.gl.vtkpt`).
    size : (width, height); default the state's view size.

    Examples
    --------
    >>> scene = load_state("post.pvsm", parity=True)   # doctest: +SKIP
    >>> image = tetvr.render(scene.mesh, camera=scene.camera, tf=scene.tf, size=scene.size,
    ...                      settings=scene.settings)  # doctest: +SKIP
    """
    from tetvr.core.image import image_size
    from tetvr.io.meshfile import read
    from tetvr.scene.scene import Scene
    from tetvr.settings import RenderSettings

    state = read_state(path)
    if state.representation and state.representation != "Volume":
        warn(f"{state.path}: the dataset is shown as {state.representation!r} in ParaView; tetvr renders "
             "it as a volume with the state's colour and opacity maps", UserWarning)
    mesh_path = _find_data(state.data_file, state.path, data_directory)
    mesh = _read_mesh(mesh_path, state, read)
    if state.association == "CELLS" and mesh.report.scalar_source != "cell":
        warn(f"{state.path}: ParaView colours by the cell array {state.array!r}, tetvr found a point array "
             "of that name and renders it", UserWarning)
    tf = state_transfer_function(state)
    if state.unit_distance is None:
        tf = dataclasses.replace(tf, unit_distance=paraview_unit_distance(mesh.bounds, mesh.n_tets))
    if parity:
        from tetvr.settings import PARITY_SETTINGS

        settings = PARITY_SETTINGS
    else:
        settings = RenderSettings()
    out_size = image_size(size) if size is not None else (state.view_size or (512, 512))
    surfaces = _other_sources(state, out_size, data_directory)
    # ParaView's range holds every visible prop.
    camera = reset_clipping_range(state.camera, union_bounds(mesh.bounds, *(s.points for s in surfaces)))
    return Scene(mesh_path=mesh_path, mesh=mesh, tf=tf, camera=camera, size=out_size, background=state.background,
                 settings=settings, scalars=mesh.scalar_name, component=state.component, surfaces=surfaces)


def _other_sources(state: ParaViewState, size: tuple[int, int],
                   data_directory: str | os.PathLike[str] | None) -> tuple["Surface", ...]:
    """The surfaces of the state's other sources; each one not drawn is warned about.
    ParaView draws them as opaque geometry whatever the volume's mapper: parity draws them too."""
    from tetvr.io.meshfile import read_cells

    if not state.others:
        return ()
    surfaces, said = state_surfaces(state.others, camera=state.camera, size=size,
                                    find=lambda name: _find_data(name, state.path, data_directory),
                                    read_cells=read_cells)
    for sentence in said:
        warn(f"{state.path}: {sentence}", UserWarning)
    return tuple(surfaces)


def _read_mesh(mesh_path: str, state: ParaViewState, read: Any) -> "TetMesh":
    # A .pvd shown at a time: that step (tetvr.read would take the first).
    if Path(mesh_path).suffix.lower() == ".pvd" and state.view_time is not None:
        try:
            from tetvr.io.collections import read_pvd
            from tetvr.io.series import read_step
        except ImportError:  # pragma: no cover - collections are optional here
            return read(mesh_path, state.array, component=state.component)
        coll = read_pvd(mesh_path)
        step = int(np.argmin(np.abs(np.asarray(coll.times, dtype=np.float64) - state.view_time)))
        return read_step(coll, step, state.array, component=state.component)
    return read(mesh_path, state.array, component=state.component)

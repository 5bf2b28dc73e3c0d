"""The command line's commands: ``render``, ``demo``, ``fusion-demo``, ``compare``, ``info``,
``view`` and ``animate``, each a function of the parsed arguments that returns the exit
status (:data:`_COMMANDS` maps the names to them). Heavy and optional packages are
imported by the command that needs them, so ``tetvr --help`` stays quick."""

from __future__ import annotations

import argparse
import dataclasses
import os
import re
import sys
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from tetvr.apps.cli.errors import EXIT_OK
from tetvr.apps.cli.outputs import _npy_path, _report_stream, _scene_inputs, _series_inputs, _step_name
from tetvr.core.outputs import check_outputs, check_outputs_in, check_writable, check_writable_folder

#: Nothing public: :func:`tetvr.apps.cli.main` runs these.
__all__: list[str] = []


def _is_scene(path: str) -> bool:
    """A scene JSON file (by its name, or a JSON object by any name) or a ParaView state
    (``.pvsm``, read by :func:`tetvr.scene.paraview.load_state`), else a mesh file."""
    if path.lower().endswith((".json", ".pvsm")):
        return True
    if not os.path.isfile(path):  # never open a FIFO (it would block) or a device: the reader says what it is
        return False
    try:
        with open(path, "rb") as f:
            head = f.read(256).lstrip()
    except OSError:
        return False  # the mesh reader says what is wrong with it
    return head[:1] == b"{"


def _write_picture(image: Any, out: str, *, tf: Any, mesh: Any, camera: Any, background: Any,
                   annotate: bool, title: str | None, units: str | None, size: tuple[int, int] | None = None) -> str:
    """The PNG: annotated (legend, triad, outline) unless asked not to or matplotlib is
    missing (then the plain image, with a note); returns what was written. ``mesh`` is
    what the legend and the outline describe: a mesh or a volume (its field and bounds).
    ``size``: the picture's, the image being the render area :func:`_render_area` gives."""
    from tetvr.core.image import atomic_output, png_bytes

    data = None
    if annotate:
        try:
            from tetvr.apps.annotate import annotate as annotate_png, mesh_labels

            data = annotate_png(image, tf, units=units, title=title, camera=camera, background=background,
                                size=size,
                                **mesh_labels(mesh))
        except ImportError:
            print("tetvr: note: the picture has no legend: matplotlib is not installed (pip install 'tetvr[plot]')",
                  file=sys.stderr)
    what = "annotated PNG" if data is not None else "PNG"
    if data is None:
        data = png_bytes(image, background=background)
    with atomic_output(out) as f:
        f.write(data)
    return what


#: The ``render`` options other commands leave out (``demo`` renders through ``_render``).
_RENDER_DEFAULTS: dict[str, Any] = dict(
    npy=None, reference=False, scalars=None, component=None, cmap=None, size=None, background=None, title=None,
    units=None, no_annotations=False, range=None, opacity_scale=None, unit_distance=None, volume=None, view=None,
    azimuth=None, elevation=None, zoom=None, parallel=False, parity=False)


def _render_area(args: argparse.Namespace, tf: Any, data: Any, size: tuple[int, int]) -> tuple[int, int]:
    """The render's size inside a picture of ``size`` (``--size``: the size of the file):
    what the legend and the title leave, all of it for a plain picture."""
    if args.no_annotations:
        return size
    try:
        from tetvr.apps.annotate import mesh_labels, render_area

        return render_area(size, tf, field=mesh_labels(data)["field"], units=args.units, title=args.title)
    except ImportError:
        return size  # no matplotlib: the plain picture (_write_picture says so)


def _framed(data: Any, args: argparse.Namespace) -> Any:
    """What the camera frames: the data and the outline drawn around it."""
    from tetvr.apps.annotate import Framed

    return Framed(data, outline=not args.no_annotations)


def _input_kind(path: str) -> str:
    """``"state"`` (a ParaView state), ``"scene"`` (a scene JSON), ``"volume"`` or ``"mesh"``."""
    if _is_scene(path):
        return "state" if path.lower().endswith(".pvsm") else "scene"
    return "volume" if _is_volume(path) else "mesh"


def _render(args: argparse.Namespace) -> int:
    """A mesh file (default scene: fitted camera, the data-driven transfer function), a
    volume (the same defaults), a mesh fused with a volume (``--volume``), or a scene JSON
    or ParaView state; a ``.pvd`` (named by either) renders every time step, one file each."""
    from tetvr.apps.cli.tuning import check_options

    args = argparse.Namespace(**{**_RENDER_DEFAULTS, **vars(args)})
    kind = _input_kind(args.scene)
    check_options(args, kind)
    if kind == "volume" or args.volume:
        return _render_one(args, kind)
    return _render_scene(args, kind)


def _load_scene(args: argparse.Namespace, kind: str) -> tuple[Any, list[tuple[str, str]]]:
    """The scene to render and the command's inputs so far: a scene file with the camera
    options applied, or a mesh file's default scene with the tuning options."""
    from tetvr.apps.cli.tuning import data_camera, data_tf, scene_camera
    from tetvr.io.collections import is_collection
    from tetvr.scene.scene import Scene

    if kind in ("scene", "state"):
        from tetvr.scene.load import load_scene
        from tetvr.scene.paraview import load_state

        for path, label in [(args.output, "PNG")] + ([(args.npy, "--npy array")] if args.npy else []):
            if "{" not in path:
                check_writable(path, label)
        scene = load_state(args.scene, parity=True) if args.parity else load_scene(args.scene)
        area = _render_area(args, scene.tf, scene.mesh, args.size or scene.size)
        if scene.camera_fit is not None:  # fitted again to the render's shape, the outline in view
            from tetvr.apps.annotate import frame

            scene = dataclasses.replace(scene, camera=frame(scene.mesh, area, outline=not args.no_annotations,
                                                            **scene.camera_fit))
        camera = scene_camera(scene.camera, _framed(scene.mesh, args), args, area)
        return dataclasses.replace(scene, camera=camera), _scene_inputs(args.scene, scene)
    from tetvr.io.meshfile import read

    inputs = [("mesh file", args.scene)]
    if "{" not in args.output and not is_collection(args.scene):
        check_writable(args.output, "PNG")
        check_outputs([("PNG", args.output)], inputs)
    mesh = read(args.scene, args.scalars, component=args.component)
    size = args.size or (800, 600)
    tf = data_tf(mesh, args)
    camera = data_camera(_framed(mesh, args), args, _render_area(args, tf, mesh, size))
    scene = Scene(mesh_path=args.scene, mesh=mesh, tf=tf, camera=camera,
                  size=size, scalars=mesh.scalar_name, component=args.component)
    return scene, inputs


def _render_scene(args: argparse.Namespace, kind: str) -> int:
    """A mesh file or a scene, every time step of a ``.pvd``."""
    from tetvr.io.collections import is_collection, leaf_files, quiet_first_step, read_pvd
    from tetvr.io.series import read_step
    from tetvr.render import render

    method = "reference" if args.reference else "gpu"
    t0 = time.perf_counter()
    with quiet_first_step():  # a .pvd's steps are all rendered here
        scene, inputs = _load_scene(args, kind)
    size = args.size or scene.size
    _check_picture_memory(args, size)
    background = args.background or scene.background
    options = _clip_and_surfaces(args, scene)
    inputs += [("surface file", p) for p in getattr(args, "surface", None) or ()]
    coll = read_pvd(scene.mesh_path) if Path(scene.mesh_path).suffix.lower() == ".pvd" else None
    if coll is not None:
        inputs += [("collection file", p) for p in coll.input_paths()]
    elif is_collection(scene.mesh_path):
        inputs += [("collection file", p) for p in leaf_files(scene.mesh_path)]
    steps = list(enumerate(coll.times)) if coll is not None else [(0, None)]
    n = len(steps)
    jobs = []
    for i, t in steps:
        png = _step_name(args.output, "PNG", i, t, n) if t is not None else args.output
        npy = (_npy_path(_step_name(args.npy, "--npy array", i, t, n) if t is not None else args.npy)
               if args.npy else None)
        jobs.append((i, t, png, npy))
    _check_outputs_of(jobs, inputs)
    t1 = time.perf_counter()
    for i, t, png, npy in jobs:
        ts = time.perf_counter()
        mesh = scene.mesh if i == 0 or coll is None else read_step(coll, i, scene.scalars, component=scene.component)
        image = render(mesh, camera=scene.camera, tf=scene.tf, size=_render_area(args, scene.tf, mesh, size),
                       settings=scene.settings, method=method, **options)
        t2 = time.perf_counter()
        step = f"step {i} (t = {t:g}): " if t is not None else ""
        _finish(image, args, png, npy, tf=scene.tf, data=mesh, camera=scene.camera, background=background, size=size,
                title=args.title if t is None or not args.title else f"{args.title} (t = {t:g})",
                report=f"{step}{mesh.n_tets} tets, field {mesh.scalar_name!r}, {size[0]}x{size[1]} px, {method}: "
                       f"read {(t1 - t0) if i == 0 else (ts - t1):.2f} s, render {t2 - ts:.2f} s")
        t1 = time.perf_counter()
    return EXIT_OK


def _check_picture_memory(args: argparse.Namespace, size: tuple[int, int]) -> None:
    """The picture's memory (the legend's canvas, the PNG) checked before any frame is rendered."""
    from tetvr.gl.framesize import check_picture

    check_picture(size, "png" if args.no_annotations else "annotate")


def _check_outputs_of(jobs: list[tuple[Any, Any, str, str | None]], inputs: list[tuple[str, str]]) -> None:
    outputs = [("PNG", png) for _, _, png, _ in jobs] + [("--npy array", npy) for _, _, _, npy in jobs if npy]
    for label, path in outputs:
        check_writable(path, label)
    check_outputs(outputs, inputs)


def _finish(image: Any, args: argparse.Namespace, png: str, npy: str | None, *, tf: Any, data: Any, camera: Any,
            background: Any, title: str | None, report: str, size: tuple[int, int] | None = None) -> None:
    """Write the picture (and the float array) and the report line."""
    from tetvr.core.image import atomic_output

    what = _write_picture(image, png, tf=tf, mesh=data, camera=camera, background=background,
                          annotate=not args.no_annotations, units=args.units, title=title, size=size)
    if npy:
        with atomic_output(npy) as f:
            np.save(f, image)
    print(f"{report} -> {what} {png}" + (f" and {npy}" if npy else ""), file=_report_stream(png, npy))


def _render_one(args: argparse.Namespace, kind: str) -> int:
    """A volume file, or a mesh file fused with ``--volume``: one picture, the defaults of
    both (a fused volume in grayscale), framed together."""
    from tetvr.apps.cli.tuning import Together, data_camera, data_tf
    from tetvr.core.image import DEFAULT_BACKGROUND
    from tetvr.io.volume_file import read_volume
    from tetvr.render import default_transfer_function, render

    method = "reference" if args.reference else "gpu"
    inputs = [("volume file", args.scene)] if kind == "volume" else [("mesh file", args.scene),
                                                                      ("volume file", args.volume)]
    npy = _npy_path(args.npy) if args.npy else None
    _check_outputs_of([(0, None, args.output, npy)], inputs)
    t0 = time.perf_counter()
    size = args.size or (800, 600)
    _check_picture_memory(args, size)
    if kind == "volume":
        data = volume = read_volume(args.scene)
        framed: Any = volume
    else:
        from tetvr.io.meshfile import read

        data = read(args.scene, args.scalars, component=args.component)
        volume = read_volume(args.volume)
        framed = Together.of([data, volume])
    tf = data_tf(data, args)
    area = _render_area(args, tf, data, size)
    camera = data_camera(_framed(framed, args), args, area)
    t1 = time.perf_counter()
    if kind == "volume":
        from tetvr.reference.volume import RaycastSettings

        box = args.clip_box
        settings = RaycastSettings(clip_box=(tuple(box[:3]), tuple(box[3:]))) if box else None
        image = render(volume, camera=camera, tf=tf, size=area, settings=settings, method=method)
        what = f"a {'x'.join(map(str, volume.dims))} volume"
    else:
        from tetvr.fuse import fuse, fuse_reference

        volume_tf = default_transfer_function(volume, preset="grayscale")
        image = (fuse_reference if args.reference else fuse)(data, volume, camera, tf, volume_tf, size=area)
        what = f"{data.n_tets} tets in a {'x'.join(map(str, volume.dims))} volume"
    t2 = time.perf_counter()
    _finish(image, args, args.output, npy, tf=tf, data=data, camera=camera, size=size,
            background=args.background or DEFAULT_BACKGROUND,
            title=args.title, report=f"{what}, field {data.scalar_name!r}, {size[0]}x{size[1]} px, {method}: "
                                     f"read {t1 - t0:.2f} s, render {t2 - t1:.2f} s")
    return EXIT_OK


def _clip_and_surfaces(args: argparse.Namespace, scene: Any) -> dict[str, Any]:
    """The scene's clip and surfaces, with --clip-box, --clip-plane and --surface added."""
    from tetvr.core.clip import Clip
    from tetvr.core.surface import Surface

    clip = scene.clip
    box_values = getattr(args, "clip_box", None)  # commands that render a scene without these options
    if box_values:
        box = Clip.box(box_values[:3], box_values[3:])
        clip = box if clip is None else clip & box
    for values in getattr(args, "clip_plane", None) or ():
        plane = Clip.plane(values[:3], values[3:])
        clip = plane if clip is None else clip & plane
    surfaces = tuple(scene.surfaces) + tuple(Surface.read(p, smooth=True) for p in getattr(args, "surface", None) or ())
    return {**({"clip": clip} if clip is not None else {}), **({"surfaces": surfaces} if surfaces else {})}


def _write_labelled(images: list[Any], titles: list[str], path: Path, *, cols: int | None = None,
                    suptitle: str | None = None, background: Any = None) -> None:
    """Pictures with their titles (matplotlib), or, without matplotlib, the plain images
    side by side and a note saying why they are unlabelled."""
    from tetvr.core.image import atomic_output, png_bytes

    try:
        from tetvr.apps.annotate import panels

        bg = {} if background is None else {"background": background}
        data = panels(images, titles, cols=cols, suptitle=suptitle, width_in=max(2.2, images[0].shape[1] / 110), **bg)
    except ImportError:
        print(f"tetvr: note: {path.name} is unlabelled: matplotlib is not installed (pip install 'tetvr[plot]')",
              file=sys.stderr)
        from tetvr.apps.annotate import _tiled

        data = png_bytes(_tiled(images), **({} if background is None else {"background": background}))
    with atomic_output(path) as f:
        f.write(data)


def _fusion_demo(out: Path, size: tuple[int, int]) -> int:
    from tetvr import FUSION_MODES
    from tetvr.scene.examples import bundled, carotid_fusion
    from tetvr.fuse import RayTextures, fuse
    from tetvr.gl.raycaster import Raycaster
    from tetvr.gl.renderer import Renderer
    from tetvr.core.image import image_size

    size = image_size(size)
    names = {f"fusion_{mode}.png" for mode in FUSION_MODES} | {"mesh_only.png", "volume_only.png", "fusion_modes.png"}
    if out.is_dir():
        check_outputs_in(out, names.__contains__, "the fusion pictures", [("volume file", bundled("carotid.vtk"))])
    check_writable_folder(out, "the fusion pictures")
    out.mkdir(parents=True, exist_ok=True)
    scene = carotid_fusion()
    w, h = size
    # Ray textures: the left half shows the volume's front half only, the right half all of it.
    end = np.ones((h, w))
    end[:, : w // 2] = 0.5
    textures = RayTextures(np.zeros((h, w)), end)
    field, vol_name = "speed", "speed"  # carotid.vtk's 'scalars' are the flow speed
    titles = {"interleave": "interleave: volume, mesh, volume", "overlay": "overlay: mesh over volume",
              "cutaway": "cutaway: no volume before mesh", "ray_textures": "ray textures: left half cut"}
    bg = scene.background
    panels = []
    with Renderer() as r, Raycaster(ctx=r.ctx) as rc:
        for mode in FUSION_MODES:
            img = fuse(scene.mesh, scene.volume, scene.camera, scene.mesh_tf, scene.volume_tf, size=size, mode=mode,
                       renderer=r, raycaster=rc, ray_textures=textures if mode == "ray_textures" else None)
            _write_labelled([img], [titles.get(mode, mode)], out / f"fusion_{mode}.png", background=bg)
            panels.append(img)
        _write_labelled([r.render(scene.mesh, scene.camera, scene.mesh_tf, size=size)],
                        [f"mesh only: lumen, {field}"], out / "mesh_only.png", background=bg)
        _write_labelled([rc.render(scene.volume, scene.camera, scene.volume_tf, size=size)],
                        [f"volume only: {vol_name}"], out / "volume_only.png", background=bg)
    _write_labelled(panels, [titles.get(m, m) for m in FUSION_MODES], out / "fusion_modes.png", cols=2, background=bg,
                    suptitle=f"carotid {field}: {scene.mesh.n_tets} tets in a {'x'.join(map(str, scene.volume.dims))} volume")
    print(f"{scene.mesh.n_tets} tets in a {scene.volume.dims} volume: wrote {', '.join(FUSION_MODES)} "
          f"(fusion_modes.png: {FUSION_MODES[0]}, {FUSION_MODES[1]} / {FUSION_MODES[2]}, {FUSION_MODES[3]}) to {out}")
    return EXIT_OK


def _compare(args: argparse.Namespace) -> int:
    from tetvr.scene.load import load_scene
    from tetvr.apps.vtkcompare import compare

    scene = load_scene(args.scene)
    if os.path.isdir(args.output):
        # write_report's files: comparison.json / .md and a PNG per picture.
        check_outputs_in(args.output, lambda name: name.startswith("comparison.") or name.endswith(".png"),
                         "the comparison", _scene_inputs(args.scene, scene))
    check_writable_folder(args.output, "the comparison")
    mappers = [m for m in args.mappers.split(",") if m]
    compare(scene, mappers=mappers, views=args.views, size=tuple(args.size) if args.size else None,
            outdir=args.output, log=print)
    print(f"-> {Path(args.output) / 'comparison.md'}")
    return EXIT_OK


def _animate(args: argparse.Namespace) -> int:
    from tetvr.apps.animate import animate
    from tetvr.io.video import check_frames_output
    from tetvr.scene.load import load_scene

    scene = load_scene(args.scene)
    series = _expand_series(args.time_series)
    inputs = _scene_inputs(args.scene, scene) + _series_inputs(series)
    check_frames_output(args.output, inputs)
    scheduler = args.scheduler or os.environ.get("TETVR_SCHEDULER") or None
    files = animate(scene, args.output, orbit_frames=args.orbit, degrees=args.degrees,
                    time_series=series, fps=args.fps, progress=not args.no_progress, scheduler=scheduler)
    print(f"wrote {len(files)} file(s): {files[0]}{' ...' if len(files) > 1 else ''}")
    return EXIT_OK


def _expand_series(series: Sequence[str] | None) -> Any:
    """The --time-series arguments: one file (an XDMF time series, a .pvd collection, a
    single step), or mesh files, with glob patterns the shell left unexpanded
    (``"run/step_*.vtu"``) expanded in natural order (``s2`` before ``s10``)."""
    if not series:
        return None
    import glob

    files: list[str] = []
    for name in series:
        if any(ch in name for ch in "*?[") and not os.path.exists(name):
            found = sorted(glob.glob(name), key=lambda f: [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", f)])
            if not found:
                raise FileNotFoundError(f"no file matches {name!r}")
            files += found
        else:
            files.append(name)
    return files[0] if len(files) == 1 else files


def _stats_line(values: Any, weights: Any = None) -> str:
    """min, percentiles (weighted by volume where given) and max of a field, as text."""
    from tetvr.optics.transfer import weighted_percentiles

    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 2:
        v = np.linalg.norm(v, axis=1)
    finite = np.isfinite(v)
    if not finite.any():
        return "no finite values"
    w = None if weights is None else np.asarray(weights)[finite]
    p1, median, p99 = weighted_percentiles(v[finite], w, (1.0, 50.0, 99.0))
    bad = f", {int((~finite).sum())} NaN/Inf" if not finite.all() else ""
    return (f"range {v[finite].min():.4g} .. {v[finite].max():.4g}; 1% {p1:.4g}, median {median:.4g}, "
            f"99% {p99:.4g}{bad}")


def _is_volume(path: str) -> bool:
    from tetvr.io.volume_file import VOLUME_SUFFIXES

    name = path.lower()
    if os.path.isdir(path):
        return True
    if name.endswith(".vtk"):  # legacy VTK: structured points are a volume, anything else a mesh
        if not os.path.isfile(path):
            return False
        try:
            with open(path, "rb") as f:
                return b"STRUCTURED_POINTS" in f.read(1024).upper()
        except OSError:
            return False
    return name.endswith(tuple(s for s in VOLUME_SUFFIXES if s != ".vtk"))


def _info(args: argparse.Namespace) -> int:
    if _is_volume(args.mesh):
        from tetvr.io.volume_file import read_volume

        try:
            vol = read_volume(args.mesh)
        except ValueError as exc:
            if not os.path.isdir(args.mesh):
                raise
            raise ValueError(f"{exc}. tetvr info describes a mesh file (VTU, VTK, Gmsh, Exodus, ...), a volume file "
                             "(NRRD, MetaImage, VTI, NIfTI, DICOM) or a folder of DICOM slices") from None
        lo, hi = vol.bounds
        print(f"{args.mesh}: a volume of {vol.dims[0]} x {vol.dims[1]} x {vol.dims[2]} voxels ({vol.dtype}), "
              f"spacing {' x '.join(f'{v:.4g}' for v in vol.spacing)}"
              + (f", frame {vol.space}" if vol.space else ""))
        print(f"  bounds  {' '.join(f'{v:.4g}' for v in lo)} .. {' '.join(f'{v:.4g}' for v in hi)}")
        print(f"  field   {vol.scalar_name!r}: {_stats_line(vol.data.reshape(-1))}")
        print(f"  default colour range {' .. '.join(f'{v:.4g}' for v in _default_range(vol))}")
        return EXIT_OK
    from tetvr.io import meshfile
    from tetvr.io.meshfile import read_cells
    from tetvr.mesh.tetmesh import _signed_volume6
    from tetvr.optics.transfer import point_weights

    mesh = meshfile.read(args.mesh, args.scalars)  # through the module: the checked reader
    rep = mesh.report
    lo, hi = mesh.bounds
    print(f"{args.mesh}: {mesh.n_points} points, {mesh.n_tets} tetrahedra")
    print(f"  bounds  {' '.join(f'{v:.4g}' for v in lo)} .. {' '.join(f'{v:.4g}' for v in hi)}  "
          f"(size {' x '.join(f'{v:.4g}' for v in hi - lo)})")
    if rep.split_cells:
        print("  cells   " + ", ".join(f"{n} {k}" for k, n in rep.split_cells) + " split into tetrahedra"
              + (f" ({rep.steiner_points} centroid points added)" if rep.steiner_points else ""))
    if rep.ignored_cells:
        print("  left out (not volume cells): " + ", ".join(f"{n} {k}" for k, n in rep.ignored_cells))
    if rep.dropped_degenerate:
        print(f"  {rep.dropped_degenerate} zero-volume tetrahedra (flat: their corners lie in a plane) are left out; "
              "they add nothing to the picture")
    if rep.inverted_fixed:
        print(f"  {rep.inverted_fixed} tetrahedra had their corners in inverted (left-handed) order; "
              "they are turned round, which changes nothing in the picture")
    cells = read_cells(args.mesh, meshio_read=meshfile._read_any)  # as read() does: collections merged
    weights = point_weights(cells.points, cells.tets)
    print("  fields")
    for name, values in cells.point_data.items():
        comp = f", {values.shape[1]} components (magnitude)" if values.ndim == 2 and values.shape[1] > 1 else ""
        mark = "*" if name == mesh.scalar_name else " "
        print(f"   {mark} {name!r} (point{comp}): {_stats_line(values, weights)}")
    cell_volume = np.abs(_signed_volume6(cells.points, np.asarray(cells.tets, dtype=np.int64))) / 6.0
    for name, values in cells.cell_data.items():
        if name in cells.point_data:
            continue
        comp = f", {values.shape[1]} components (magnitude)" if values.ndim == 2 and values.shape[1] > 1 else ""
        mark = "*" if name == mesh.scalar_name else " "
        print(f"   {mark} {name!r} (cell{comp}): {_stats_line(values, cell_volume)}")
    print(f"  * rendered by default; percentiles weighted by volume. Default colour range "
          f"{' .. '.join(f'{v:.4g}' for v in _default_range(mesh))}")
    return EXIT_OK


def _default_range(mesh: Any) -> tuple[float, float]:
    from tetvr.render import default_transfer_function

    return default_transfer_function(mesh).domain


def _view(args: argparse.Namespace) -> int:
    from tetvr.apps.viewer.desktop import run_desktop

    run_desktop(args.scene)
    return EXIT_OK


def _demo(args: argparse.Namespace) -> int:
    from tetvr.scene.scene import demo_scene_path

    return _render(argparse.Namespace(**{**_RENDER_DEFAULTS, "scene": str(demo_scene_path()), "output": args.output}))


_COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "render": _render,
    "demo": _demo,
    "fusion-demo": lambda a: _fusion_demo(Path(a.output), tuple(a.size)),
    "compare": _compare,
    "info": _info,
    "view": _view,
    "animate": _animate,
}

"""Command line: ``tetvr render mesh.vtu --scalars T -o out.png`` (or a scene JSON), ``tetvr demo``,
``tetvr info mesh``, ``tetvr --version``,
``tetvr animate scene.json --orbit 36 -o frames/``, ``tetvr view scene.json``.

Every failure ends in one line ``tetvr: error: ...`` on stderr (bad arguments get
argparse's usage line before it) and one of these exit statuses:

====  =====================================================================================
0     success
1     internal error: an exception tetvr did not expect (a bug; the line names it, and
      ``TETVR_TRACEBACK=1`` prints the traceback too)
2     bad usage or bad input: arguments, a scene, mesh or volume file, a file that cannot
      be read or written, an output that would overwrite one of the command's inputs
3     the environment cannot do it: no OpenGL 4.3 context, an OpenGL or shader error,
      no display, a missing optional package
4     out of memory (host or GPU), including sizes refused up front as too big
130   interrupted (Ctrl-C)
====  =====================================================================================

Outputs are never written over an input of the same command (the scene, the mesh it
names, time-series files; compared as files, so links and other spellings count), and
every file is written atomically: a failed command leaves an earlier file as it was.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

__all__ = ["main", "EXIT_OK", "EXIT_INTERNAL", "EXIT_USAGE", "EXIT_ENVIRONMENT", "EXIT_MEMORY", "EXIT_INTERRUPTED"]

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_ENVIRONMENT = 3
EXIT_MEMORY = 4
EXIT_INTERRUPTED = 130

_EPILOG = """exit status: 0 success; 1 internal error (a bug: please report it; TETVR_TRACEBACK=1 shows
the traceback); 2 bad usage or input (arguments, scene/mesh/volume files, unreadable input,
unwritable output, an output that would overwrite an input); 3 the environment cannot do it
(no OpenGL 4.3, a GL or shader error, no display, a missing optional package); 4 out of
memory (host or GPU); 130 interrupted. Failures print one line 'tetvr: error: ...' on stderr."""


class _UsageError(Exception):
    """Bad command-line arguments (argparse's complaint)."""


class _Parser(argparse.ArgumentParser):
    """argparse that reports through :func:`main`'s one error line instead of exiting."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.print_usage(sys.stderr)
        sub = self.prog.split(" ", 1)[1] if " " in self.prog else ""
        raise _UsageError(f"{sub}: {message}" if sub else message)


# ---- inputs and outputs ----

def _same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # either one missing (a new output is no input), or a bad name
        return False


def _refuse_overwrite(outputs: Sequence[tuple[str, str | os.PathLike[str]]],
                      inputs: Iterable[tuple[str, str | os.PathLike[str]]]) -> None:
    """``ValueError`` if an output file is one of the inputs, or two outputs are one file."""
    inputs = list(inputs)
    for label, out in outputs:
        for in_label, src in inputs:
            if _same_file(out, src):
                raise ValueError(f"refusing to write the {label} {os.fspath(out)!r} over the {in_label} "
                                 f"{os.fspath(src)!r}, an input of this command; choose another output path")
    for i, (label_a, a) in enumerate(outputs):
        for label_b, b in outputs[i + 1:]:
            if os.path.realpath(a) == os.path.realpath(b) or _same_file(a, b):
                raise ValueError(f"the {label_a} and the {label_b} are the same file {os.fspath(a)!r}")


def _refuse_overwrite_in(folder: str | os.PathLike[str], written: Callable[[str], bool], label: str,
                         inputs: Iterable[tuple[str, str | os.PathLike[str]]]) -> None:
    """``ValueError`` if an input lies in ``folder`` under a name the command writes there."""
    for in_label, src in inputs:
        parent = os.path.dirname(os.path.abspath(src))
        if written(os.path.basename(src)) and _same_file(parent, folder):
            raise ValueError(f"refusing to write {label} into {os.fspath(folder)!r}: it would overwrite the "
                             f"{in_label} {os.fspath(src)!r}, an input of this command; choose another folder")


def _check_writable(path: str | os.PathLike[str], label: str) -> None:
    """Fail before the work, not after it: the output's folder must exist and the name
    must not be a folder."""
    if os.path.isdir(path):
        raise IsADirectoryError(f"the {label} {os.fspath(path)!r} is a directory; give a file name")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"cannot write the {label} {os.fspath(path)!r}: the folder {folder!r} does not exist")


def _scene_inputs(scene_path: str | os.PathLike[str], scene: Any) -> list[tuple[str, str]]:
    return [("scene file", os.fspath(scene_path))] + [("mesh file", p) for p in scene.input_paths()]


def _series_inputs(series: Sequence[str] | None) -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    for name in series or ():
        out.append(("time-series file", name))
        if Path(name).suffix.lower() in (".xdmf", ".xmf"):
            out += [("time-series data file", p) for p in _xdmf_data_files(name)]
    return out


def _xdmf_data_files(path: str) -> list[str]:
    """The HDF5 files an XDMF file's data items name (``file.h5:/dataset``), best effort:
    an unreadable XDMF file is the reader's to report."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError, ValueError):
        return []
    folder = os.path.dirname(os.path.abspath(path))
    files = set()
    for item in root.iter():
        if item.tag.rsplit("}", 1)[-1] == "DataItem" and item.get("Format", "").upper() == "HDF" and item.text:
            files.add(os.path.join(folder, item.text.strip().split(":", 1)[0]))
    return sorted(files)


def _npy_path(npy: str) -> str:
    return npy if npy.endswith(".npy") else npy + ".npy"  # where np.save(name) would write


# ---- commands ----

def _step_name(pattern: str, label: str, index: int, t: float, n_steps: int) -> str:
    """``pattern`` with ``{time}`` and ``{index}`` filled in; one name per step required."""
    if n_steps > 1 and not any(k in pattern for k in ("{time", "{index")):
        raise ValueError(f"the scene's .pvd has {n_steps} time steps: put {{time}} or {{index}} in the {label} "
                         f"name (e.g. frame_{{time}}.png) to write one file per step, got {pattern!r}")
    try:
        return pattern.format(time=t, index=index)
    except (KeyError, IndexError, ValueError) as exc:
        raise ValueError(f"the {label} name {pattern!r} may use only {{time}} and {{index}} fields: {exc}") from None


def _is_scene(path: str) -> bool:
    """A scene JSON file (by its name, or a JSON object by any name) or a ParaView state
    (``.pvsm``, read by :func:`tetvr.paraview.load_state`), else a mesh file."""
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


def _size_arg(text: str) -> tuple[int, int]:
    """``WxH`` (or ``W,H``) as two positive integers."""
    parts = re.split(r"[x,X ]", text.strip())
    try:
        w, h = (int(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 1024x768, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"expected two positive integers WIDTHxHEIGHT, got {text!r}")
    return w, h


_COLOUR_NAMES = {"white": (1.0, 1.0, 1.0), "black": (0.0, 0.0, 0.0), "gray": (0.5, 0.5, 0.5),
                 "grey": (0.5, 0.5, 0.5), "paraview": (0.32, 0.34, 0.43)}


def _colour_arg(text: str) -> tuple[float, float, float]:
    """A background: a name (``white``, or any matplotlib colour), ``#rrggbb`` or ``r,g,b`` in [0, 1]."""
    t = text.strip().lower()
    if t in _COLOUR_NAMES:
        return _COLOUR_NAMES[t]
    if re.fullmatch(r"#[0-9a-f]{6}", t):
        return tuple(int(t[i:i + 2], 16) / 255.0 for i in (1, 3, 5))  # type: ignore[return-value]
    if "," in t:
        try:
            rgb = tuple(float(v) for v in t.split(","))
        except ValueError:
            rgb = ()
        if len(rgb) == 3 and all(0.0 <= v <= 1.0 for v in rgb):
            return rgb  # type: ignore[return-value]
        raise argparse.ArgumentTypeError(f"expected r,g,b with components in [0, 1], got {text!r}")
    try:
        from matplotlib.colors import to_rgb

        return tuple(float(v) for v in to_rgb(t))  # type: ignore[return-value]
    except (ImportError, ValueError):
        raise argparse.ArgumentTypeError(f"unknown colour {text!r}: use white, black, #rrggbb, r,g,b in [0, 1] or a "
                                         "matplotlib colour name") from None


def _write_picture(image: Any, out: str, *, tf: Any, mesh: Any, camera: Any, background: Any,
                   annotate: bool, title: str | None, units: str | None) -> str:
    """The PNG: annotated (legend, triad, outline) unless asked not to or matplotlib is
    missing (then the plain image, with a note); returns what was written."""
    from .image import atomic_output, png_bytes

    data = None
    if annotate:
        try:
            from .annotate import annotate as annotate_png

            data = annotate_png(image, tf, field=mesh.scalar_name, units=units, title=title, camera=camera,
                                bounds=mesh.bounds, background=background)
        except ImportError:
            print("tetvr: note: the picture has no legend: matplotlib is not installed (pip install 'tetvr[plot]')",
                  file=sys.stderr)
    what = "annotated PNG" if data is not None else "PNG"
    if data is None:
        data = png_bytes(image, background=background)
    with atomic_output(out) as f:
        f.write(data)
    return what


def _render(args: argparse.Namespace) -> int:
    """A mesh file (default scene: fitted camera, the data-driven transfer function) or a
    scene JSON; a ``.pvd`` (named by either) renders every time step, one file each."""
    from .camera import _fit
    from .collections import is_collection, leaf_files, quiet_first_step, read_pvd, read_step
    from .image import atomic_output
    from .render import default_transfer_function, render
    from .scene import Scene, load_scene

    method = "reference" if args.reference else "gpu"
    t0 = time.perf_counter()
    with quiet_first_step():  # a .pvd's steps are all rendered here
        if _is_scene(args.scene):
            for flag, value in (("--scalars", args.scalars), ("--cmap", args.cmap), ("--component", args.component)):
                if value is not None:
                    raise ValueError(f"{flag} is for a mesh file; a scene sets it in its JSON ({args.scene!r})")
            for path, label in [(args.output, "PNG")] + ([(args.npy, "--npy array")] if args.npy else []):
                if "{" not in path:
                    _check_writable(path, label)
            scene = load_scene(args.scene)
            inputs = _scene_inputs(args.scene, scene)
        else:
            from .mesh import read

            inputs = [("mesh file", args.scene)]
            if "{" not in args.output and not is_collection(args.scene):
                _check_writable(args.output, "PNG")
                _refuse_overwrite([("PNG", args.output)], inputs)
            mesh = read(args.scene, args.scalars, component=args.component)
            size = args.size or (800, 600)
            scene = Scene(mesh_path=args.scene, mesh=mesh, tf=default_transfer_function(mesh, preset=args.cmap or "viridis"),
                          camera=_fit(mesh, aspect=size[0] / size[1]), size=size,
                          scalars=mesh.scalar_name, component=args.component)
    size = args.size or scene.size
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
    outputs = [("PNG", png) for _, _, png, _ in jobs] + [("--npy array", npy) for _, _, _, npy in jobs if npy]
    for label, path in outputs:
        _check_writable(path, label)
    _refuse_overwrite(outputs, inputs)
    t1 = time.perf_counter()
    for i, t, png, npy in jobs:
        ts = time.perf_counter()
        mesh = scene.mesh if i == 0 or coll is None else read_step(coll, i, scene.scalars, component=scene.component)
        image = render(mesh, camera=scene.camera, tf=scene.tf, size=size, settings=scene.settings, method=method,
                       **options)
        t2 = time.perf_counter()
        what = _write_picture(image, png, tf=scene.tf, mesh=mesh, camera=scene.camera, background=background,
                              annotate=not args.no_annotations, units=args.units,
                              title=args.title if t is None or not args.title else f"{args.title} (t = {t:g})")
        if npy:
            with atomic_output(npy) as f:
                np.save(f, image)
        step = f"step {i} (t = {t:g}): " if t is not None else ""
        print(f"{step}{mesh.n_tets} tets, field {mesh.scalar_name!r}, {size[0]}x{size[1]} px, {method}: "
              f"read {(t1 - t0) if i == 0 else (ts - t1):.2f} s, render {t2 - ts:.2f} s -> {what} {png}"
              + (f" and {npy}" if npy else ""))
        t1 = time.perf_counter()
    return EXIT_OK


def _clip_and_surfaces(args: argparse.Namespace, scene: Any) -> dict[str, Any]:
    """The scene's clip and surfaces, with --clip-box, --clip-plane and --surface added."""
    from .clip import Clip
    from .surface import Surface

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
    from .image import atomic_output, png_bytes

    try:
        from .annotate import panels

        bg = {} if background is None else {"background": background}
        data = panels(images, titles, cols=cols, suptitle=suptitle, width_in=max(2.2, images[0].shape[1] / 110), **bg)
    except ImportError:
        print(f"tetvr: note: {path.name} is unlabelled: matplotlib is not installed (pip install 'tetvr[plot]')",
              file=sys.stderr)
        from .annotate import _tiled

        data = png_bytes(_tiled(images), **({} if background is None else {"background": background}))
    with atomic_output(path) as f:
        f.write(data)


def _fusion_demo(out: Path, size: tuple[int, int]) -> int:
    from . import FUSION_MODES
    from .examples import bundled, carotid_fusion
    from .fuse import RayTextures, fuse
    from .gl.raycaster import Raycaster
    from .gl.renderer import Renderer
    from .image import image_size

    size = image_size(size)
    names = {f"fusion_{mode}.png" for mode in FUSION_MODES} | {"mesh_only.png", "volume_only.png", "fusion_modes.png"}
    if out.is_dir():
        _refuse_overwrite_in(out, names.__contains__, "the fusion pictures", [("volume file", bundled("carotid.vtk"))])
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
    from .scene import load_scene
    from .vtkcompare import compare

    scene = load_scene(args.scene)
    if os.path.isdir(args.output):
        # write_report's files: comparison.json / .md and a PNG per picture.
        _refuse_overwrite_in(args.output, lambda name: name.startswith("comparison.") or name.endswith(".png"),
                             "the comparison", _scene_inputs(args.scene, scene))
    mappers = [m for m in args.mappers.split(",") if m]
    compare(scene, mappers=mappers, views=args.views, size=tuple(args.size) if args.size else None,
            outdir=args.output, log=print)
    print(f"-> {Path(args.output) / 'comparison.md'}")
    return EXIT_OK


def _animate(args: argparse.Namespace) -> int:
    from .animate import VIDEO_SUFFIXES, animate
    from .scene import load_scene

    scene = load_scene(args.scene)
    inputs = _scene_inputs(args.scene, scene) + _series_inputs(args.time_series)
    if Path(args.output).suffix.lower() in VIDEO_SUFFIXES:  # its folder is made if missing
        if os.path.isdir(args.output):
            raise IsADirectoryError(f"the video {args.output!r} is a directory; give a file name")
        _refuse_overwrite([("video", args.output)], inputs)
    elif os.path.isdir(args.output):
        _refuse_overwrite_in(args.output, re.compile(r"frame_\d{4,}\.png").fullmatch, "frames",  # type: ignore[arg-type]
                             inputs)
    series = _expand_series(args.time_series)
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
    from .transfer import weighted_percentiles

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
    from .volume_io import VOLUME_SUFFIXES

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
        from .volume import read_volume

        vol = read_volume(args.mesh)
        lo, hi = vol.bounds
        print(f"{args.mesh}: a volume of {vol.dims[0]} x {vol.dims[1]} x {vol.dims[2]} voxels ({vol.dtype}), "
              f"spacing {' x '.join(f'{v:.4g}' for v in vol.spacing)}"
              + (f", frame {vol.space}" if vol.space else ""))
        print(f"  bounds  {' '.join(f'{v:.4g}' for v in lo)} .. {' '.join(f'{v:.4g}' for v in hi)}")
        print(f"  field   {vol.scalar_name!r}: {_stats_line(vol.data.reshape(-1))}")
        return EXIT_OK
    from . import mesh as mesh_mod
    from .cells import read_cells
    from .transfer import point_weights

    mesh = mesh_mod.read(args.mesh, args.scalars)  # through the module: the checked reader
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
    cells = read_cells(args.mesh, meshio_read=mesh_mod._read_any)  # as read() does: collections merged
    weights = point_weights(cells.points, cells.tets)
    print("  fields")
    for name, values in cells.point_data.items():
        comp = f", {values.shape[1]} components (magnitude)" if values.ndim == 2 and values.shape[1] > 1 else ""
        mark = "*" if name == mesh.scalar_name else " "
        print(f"   {mark} {name!r} (point{comp}): {_stats_line(values, weights)}")
    cell_volume = np.abs(mesh_mod._signed_volume6(cells.points, np.asarray(cells.tets, dtype=np.int64))) / 6.0
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
    from .render import default_transfer_function

    return default_transfer_function(mesh).domain


def _view(args: argparse.Namespace) -> int:
    from .widget import run_desktop

    run_desktop(args.scene)
    return EXIT_OK


def _demo(args: argparse.Namespace) -> int:
    from .scene import demo_scene_path

    return _render(argparse.Namespace(scene=str(demo_scene_path()), output=args.output, npy=None, reference=False,
                                      scalars=None, component=None, cmap=None, size=None, background=None,
                                      title=None, units=None, no_annotations=False))


_COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "render": _render,
    "demo": _demo,
    "fusion-demo": lambda a: _fusion_demo(Path(a.output), tuple(a.size)),
    "compare": _compare,
    "info": _info,
    "view": _view,
    "animate": _animate,
}


# ---- errors ----

def _one_line(text: str) -> str:
    return "; ".join(line.strip() for line in text.splitlines() if line.strip())


def _classify(exc: BaseException) -> tuple[int, str]:
    """The exit status and message of a failure (see the module notes)."""
    text = _one_line(str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc))
    if isinstance(exc, _UsageError):
        return EXIT_USAGE, text
    if isinstance(exc, MemoryError):
        return EXIT_MEMORY, f"out of memory: {text}" if text else "out of memory"
    gl = sys.modules.get("moderngl")  # only if the GL package imported it: it is not ours to import
    if gl is not None and isinstance(exc, gl.Error):
        status = EXIT_MEMORY if "OUT_OF_MEMORY" in text else EXIT_ENVIRONMENT
        return status, f"OpenGL: {text}"
    if isinstance(exc, OSError):  # unreadable input, unwritable output
        if exc.filename is not None and exc.strerror and str(exc.filename) not in text:
            text = f"{exc.strerror}: {exc.filename!r}"
        return EXIT_USAGE, text
    if isinstance(exc, ImportError):  # an optional dependency (imageio, moderngl-window, vtk)
        return EXIT_ENVIRONMENT, text
    if isinstance(exc, (ValueError, KeyError, TypeError)):
        return EXIT_USAGE, text
    if isinstance(exc, RuntimeError) and not isinstance(exc, (RecursionError, NotImplementedError)):
        # GLUnavailableError, ShaderCompileError, GL errors after a frame, no display, no VTK
        return (EXIT_MEMORY if "OUT_OF_MEMORY" in text else EXIT_ENVIRONMENT), text
    if isinstance(exc, SystemExit):
        return EXIT_INTERNAL, f"internal error: a library tried to exit the program (status {exc.code!r})"
    return EXIT_INTERNAL, (f"internal error: {type(exc).__name__}: {text} (a bug in tetvr: please report it; "
                           "TETVR_TRACEBACK=1 shows the traceback)")


def _fail(status: int, message: str) -> int:
    if os.environ.get("TETVR_TRACEBACK") and sys.exc_info()[0] is not None:
        import traceback

        traceback.print_exc(file=sys.stderr)
    print(f"tetvr: error: {message}", file=sys.stderr)
    return status


def _parser() -> argparse.ArgumentParser:
    from . import __version__

    parser = _Parser(prog="tetvr", description="Volume rendering of tetrahedral meshes.", epilog=_EPILOG)
    parser.add_argument("--version", action="version", version=f"tetvr {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    p_render = sub.add_parser("render", help="render a mesh file (or .pvd, .vtm, .pvtu) or a scene JSON to a PNG "
                              "with a legend", epilog=_EPILOG)
    p_render.add_argument("scene", metavar="mesh_or_scene",
                          help="a mesh file (VTU, VTK, Gmsh, Exodus, ...), a ParaView collection, or a scene JSON "
                          "(see the README)")
    p_render.add_argument("-o", "--output", default="out.png", help="PNG to write (default: out.png); for a .pvd "
                          "of several time steps a pattern with {time} or {index}, e.g. frame_{time}.png")
    p_render.add_argument("--scalars", help="the field to render (a mesh file; default: its first field)")
    p_render.add_argument("--component", type=int, help="a vector field's component (default: its magnitude)")
    p_render.add_argument("--cmap", help="colour map: viridis, cool-to-warm, grayscale, hot, or any matplotlib "
                          "colormap name such as magma (a mesh file; default: viridis)")
    p_render.add_argument("--size", type=_size_arg, metavar="WxH", help="image size (default: 800x600, or the scene's)")
    p_render.add_argument("--background", type=_colour_arg, metavar="COLOUR",
                          help="white (default), black, #rrggbb, r,g,b in [0, 1] or a matplotlib colour name")
    p_render.add_argument("--title", help="a title above the picture")
    p_render.add_argument("--units", help="the field's units, for the legend")
    p_render.add_argument("--no-annotations", action="store_true",
                          help="the plain image: no legend, axes triad or box outline")
    p_render.add_argument("--npy", help="also save the premultiplied float32 RGBA array here (.npy is added "
                          "if missing)")
    p_render.add_argument("--reference", action="store_true", help="use the exact CPU reference renderer")
    p_render.add_argument("--clip-box", type=float, nargs=6, metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
                          help="keep only the part of the mesh inside this box (world units)")
    p_render.add_argument("--clip-plane", type=float, nargs=6, action="append",
                          metavar=("OX", "OY", "OZ", "NX", "NY", "NZ"),
                          help="keep only the side of the plane through O that N points into (repeatable)")
    p_render.add_argument("--surface", action="append", metavar="FILE",
                          help="an opaque surface (STL, OBJ, PLY, VTK, ...) drawn inside the volume (repeatable)")
    p_demo = sub.add_parser("demo", help="render the bundled demo scene", epilog=_EPILOG)
    p_demo.add_argument("-o", "--output", default="demo.png", help="PNG to write (default: ./demo.png)")
    p_fusion = sub.add_parser("fusion-demo", help="render the bundled vessel-flow fusion demo in every mode",
                              epilog=_EPILOG)
    p_fusion.add_argument("-o", "--output", default="fusion", help="folder for the PNGs (default: ./fusion)")
    p_fusion.add_argument("--size", type=int, nargs=2, default=(480, 360), metavar=("W", "H"))
    p_cmp = sub.add_parser("compare", help="render a scene with tetvr and VTK's unstructured mappers; "
                           "time them and measure their error (needs tetvr[compare])", epilog=_EPILOG)
    p_cmp.add_argument("scene", help="scene JSON")
    p_cmp.add_argument("-o", "--output", default="compare", help="folder for the pictures and tables")
    p_cmp.add_argument("--mappers", default="pt,bunyk,zsweep", help="VTK mappers, comma-separated ('' for none)")
    p_cmp.add_argument("--views", type=int, default=5, help="view changes to time (default 5)")
    p_cmp.add_argument("--size", type=int, nargs=2, metavar=("W", "H"), help="image size (default: the scene's)")
    p_info = sub.add_parser("info", help="describe a mesh or volume file: fields, ranges, percentiles, cells",
                            epilog=_EPILOG)
    p_info.add_argument("mesh", help="a mesh file, or a volume file (NRRD, MetaImage, VTI, NIfTI, DICOM folder)")
    p_info.add_argument("--scalars", help="the field marked as rendered (default: the first)")
    p_view = sub.add_parser("view", help="open a scene in a desktop window (needs moderngl-window and a display)",
                            epilog=_EPILOG)
    p_view.add_argument("scene", help="scene JSON")
    p_anim = sub.add_parser("animate", help="render a camera orbit or time steps to PNG frames or a video",
                            epilog=_EPILOG)
    p_anim.add_argument("scene", help="scene JSON (camera, transfer function, size)")
    p_anim.add_argument("--orbit", type=int, metavar="N", help="N frames of an orbit about the view up")
    p_anim.add_argument("--degrees", type=float, default=360.0, help="orbit sweep in degrees (default 360)")
    p_anim.add_argument("--time-series", nargs="+", metavar="FILE",
                        help="one mesh file per time step (or a quoted glob pattern: 'run/step_*.vtu'), "
                             "one .pvd collection, or one XDMF time series")
    p_anim.add_argument("--scheduler", metavar="ADDRESS",
                        help="render the time steps on a Dask cluster: a scheduler address (tcp://host:8786), "
                             "or 'local' for a LocalCluster on this machine's cores (default: $TETVR_SCHEDULER if "
                             "set, else here, one frame after another); needs pip install \"tetvr[dask]\"")
    p_anim.add_argument("--fps", type=float, default=12.0, help="frames per second of a video (default 12)")
    p_anim.add_argument("--no-progress", action="store_true", help="no progress bar")
    p_anim.add_argument("-o", "--output", default="frames",
                        help="a folder for PNG frames, or a .mp4/.webm/.gif file (default: frames/)")
    return parser


def _show_warning(message: Any, category: Any, filename: str, lineno: int, file: Any = None, line: Any = None) -> None:
    # What happened, in the user's terms: no source file and line of tetvr's.
    print(f"tetvr: warning: {_one_line(str(message))}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (see the module notes)."""
    import warnings

    with warnings.catch_warnings():
        warnings.showwarning = _show_warning
        return _main(argv)


def _main(argv: list[str] | None) -> int:
    try:
        parser = _parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # --help
            return exc.code if isinstance(exc.code, int) else EXIT_OK
        return _COMMANDS[args.command](args)
    except KeyboardInterrupt:
        return _fail(EXIT_INTERRUPTED, "interrupted")
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - every failure ends in one line and a status
        return _fail(*_classify(exc))


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())

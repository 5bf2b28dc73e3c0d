"""Command line: ``tetvr render scene.json -o out.png``, ``tetvr demo``, ``tetvr info mesh``,
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

def _render_scene(scene_path: str, out: str, npy: str | None, method: str) -> int:
    from .image import atomic_output, write_png
    from .render import render
    from .scene import load_scene

    npy_out = _npy_path(npy) if npy else None
    outputs: list[tuple[str, str]] = [("PNG", out)] + ([("--npy array", npy_out)] if npy_out else [])
    for label, path in outputs:
        _check_writable(path, label)
    t0 = time.perf_counter()
    scene = load_scene(scene_path)
    _refuse_overwrite(outputs, _scene_inputs(scene_path, scene))
    t1 = time.perf_counter()
    image = render(scene.mesh, camera=scene.camera, tf=scene.tf, size=scene.size, settings=scene.settings,
                   method=method)
    t2 = time.perf_counter()
    write_png(image, out, background=scene.background)
    if npy_out:
        with atomic_output(npy_out) as f:
            np.save(f, image)
    print(f"{scene.mesh.n_tets} tets, field {scene.mesh.scalar_name!r}, {scene.size[0]}x{scene.size[1]} px, "
          f"{method}: read {t1 - t0:.2f} s, render {t2 - t1:.2f} s -> {out}" + (f" and {npy_out}" if npy_out else ""))
    return EXIT_OK


def _fusion_demo(out: Path, size: tuple[int, int]) -> int:
    from . import FUSION_MODES
    from .examples import bundled, carotid_fusion
    from .fuse import RayTextures, fuse
    from .gl.raycaster import Raycaster
    from .gl.renderer import Renderer
    from .image import image_size, write_png

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
    panels = []
    with Renderer() as r, Raycaster(ctx=r.ctx) as rc:
        for mode in FUSION_MODES:
            img = fuse(scene.mesh, scene.volume, scene.camera, scene.mesh_tf, scene.volume_tf, size=size, mode=mode,
                       renderer=r, raycaster=rc, ray_textures=textures if mode == "ray_textures" else None)
            write_png(img, out / f"fusion_{mode}.png", background=(0, 0, 0))
            panels.append(img)
        write_png(r.render(scene.mesh, scene.camera, scene.mesh_tf, size=size), out / "mesh_only.png", background=(0, 0, 0))
        write_png(rc.render(scene.volume, scene.camera, scene.volume_tf, size=size), out / "volume_only.png",
                  background=(0, 0, 0))
    grid = np.concatenate([np.concatenate(panels[:2], axis=1), np.concatenate(panels[2:], axis=1)], axis=0)
    write_png(grid, out / "fusion_modes.png", background=(0, 0, 0))
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
    series = args.time_series
    if series is not None and len(series) == 1:
        series = series[0]  # one file: an XDMF time series (or a single step)
    files = animate(scene, args.output, orbit_frames=args.orbit, degrees=args.degrees,
                    time_series=series, fps=args.fps, progress=not args.no_progress)
    print(f"wrote {len(files)} file(s): {files[0]}{' ...' if len(files) > 1 else ''}")
    return EXIT_OK


def _info(args: argparse.Namespace) -> int:
    from .mesh import read

    mesh = read(args.mesh)
    lo, hi = mesh.bounds
    print(f"{args.mesh}: {mesh.n_points} points, {mesh.n_tets} tets; field {mesh.scalar_name!r} "
          f"range {mesh.scalar_range}; bounds {lo.tolist()} .. {hi.tolist()}; report {mesh.report}")
    return EXIT_OK


def _view(args: argparse.Namespace) -> int:
    from .widget import run_desktop

    run_desktop(args.scene)
    return EXIT_OK


def _demo(args: argparse.Namespace) -> int:
    from .scene import demo_scene_path

    return _render_scene(str(demo_scene_path()), args.output, None, "gpu")


_COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "render": lambda a: _render_scene(a.scene, a.output, a.npy, "reference" if a.reference else "gpu"),
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
    parser = _Parser(prog="tetvr", description="Volume rendering of tetrahedral meshes.", epilog=_EPILOG)
    sub = parser.add_subparsers(dest="command", required=True)
    p_render = sub.add_parser("render", help="render a scene JSON file to a PNG", epilog=_EPILOG)
    p_render.add_argument("scene", help="scene JSON (see the README for its schema)")
    p_render.add_argument("-o", "--output", default="out.png", help="PNG to write (default: out.png)")
    p_render.add_argument("--npy", help="also save the premultiplied float32 RGBA array here (.npy is added "
                          "if missing)")
    p_render.add_argument("--reference", action="store_true", help="use the exact CPU reference renderer")
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
    p_info = sub.add_parser("info", help="describe a mesh file (points, tets, field, range, bounds)", epilog=_EPILOG)
    p_info.add_argument("mesh")
    p_view = sub.add_parser("view", help="open a scene in a desktop window (needs moderngl-window and a display)",
                            epilog=_EPILOG)
    p_view.add_argument("scene", help="scene JSON")
    p_anim = sub.add_parser("animate", help="render a camera orbit or time steps to PNG frames or a video",
                            epilog=_EPILOG)
    p_anim.add_argument("scene", help="scene JSON (camera, transfer function, size)")
    p_anim.add_argument("--orbit", type=int, metavar="N", help="N frames of an orbit about the view up")
    p_anim.add_argument("--degrees", type=float, default=360.0, help="orbit sweep in degrees (default 360)")
    p_anim.add_argument("--time-series", nargs="+", metavar="FILE",
                        help="one mesh file per time step, or one XDMF time series")
    p_anim.add_argument("--fps", type=float, default=12.0, help="frames per second of a video (default 12)")
    p_anim.add_argument("--no-progress", action="store_true", help="no progress bar")
    p_anim.add_argument("-o", "--output", default="frames",
                        help="a folder for PNG frames, or a .mp4/.webm/.gif file (default: frames/)")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status (see the module notes)."""
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

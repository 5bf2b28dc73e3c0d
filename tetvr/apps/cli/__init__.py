"""Command line: ``tetvr render mesh.vtu --scalars T -o out.png`` (or a CT/MR volume, a scene
JSON, ``mesh.vtu --volume ct.nhdr``; tuning options: :mod:`tetvr.apps.cli.tuning`), ``tetvr demo``,
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
names, time-series files; compared as files, so links and other spellings count), an
output's folder must be writable (both checked before the work, :mod:`tetvr.core.outputs`),
and every file is written atomically: a failed command leaves an earlier file as it was.
An output that is a symbolic link keeps it: the file it points to is replaced. An output
that is not a regular file -- a FIFO, ``-o /dev/stdout`` -- is written through (the report
line then goes to stderr, so the pipe carries the picture alone).

This module parses the arguments and runs :func:`main`; the commands are in
:mod:`tetvr.apps.cli.commands`, the checks that keep outputs off inputs in
:mod:`tetvr.apps.cli.outputs`, and how a failure becomes a status and a line in
:mod:`tetvr.apps.cli.errors`.
"""

from __future__ import annotations

import argparse
import re
import sys
from typing import Any

from tetvr.apps.cli.commands import _COMMANDS
from tetvr.apps.cli.tuning import RangeAction, finite_arg, positive_arg, unit_distance_arg, view_arg
from tetvr.apps.cli.errors import (EXIT_ENVIRONMENT, EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_MEMORY, EXIT_OK, EXIT_USAGE,
                                   _classify, _fail, _show_warning, _UsageError)

__all__ = ["main", "EXIT_OK", "EXIT_INTERNAL", "EXIT_USAGE", "EXIT_ENVIRONMENT", "EXIT_MEMORY", "EXIT_INTERRUPTED"]

_EPILOG = """exit status: 0 success; 1 internal error (a bug: please report it; TETVR_TRACEBACK=1 shows
the traceback); 2 bad usage or input (arguments, scene/mesh/volume files, unreadable input,
unwritable output, an output that would overwrite an input); 3 the environment cannot do it
(no OpenGL 4.3, a GL or shader error, no display, a missing optional package); 4 out of
memory (host or GPU); 130 interrupted. Failures print one line 'tetvr: error: ...' on stderr."""


class _Parser(argparse.ArgumentParser):
    """argparse that reports through :func:`main`'s one error line instead of exiting."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.print_usage(sys.stderr)
        sub = self.prog.split(" ", 1)[1] if " " in self.prog else ""
        raise _UsageError(f"{sub}: {message}" if sub else message)


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


def _add_render(sub: Any) -> None:
    """The ``render`` command's arguments (the tuning options: :mod:`tetvr.apps.cli.tuning`)."""
    p_render = sub.add_parser("render", help="render a mesh file (or .pvd, .vtm, .pvtu), a CT/MR volume or a scene "
                              "JSON to a PNG with a legend", epilog=_EPILOG)
    p_render.add_argument("scene", metavar="input",
                          help="a mesh file (VTU, VTK, Gmsh, Exodus, ...), a ParaView collection, a volume (NRRD, "
                          "MetaImage, VTI, NIfTI, DICOM folder), a scene JSON (see the README) or a ParaView state")
    p_render.add_argument("-o", "--output", default="out.png", help="PNG to write (default: out.png); for a .pvd "
                          "of several time steps a pattern with {time} or {index}, e.g. frame_{time}.png")
    p_render.add_argument("--scalars", help="the field to render (a mesh file; default: its first field that varies)")
    p_render.add_argument("--component", type=int, help="a vector field's component (default: its magnitude)")
    p_render.add_argument("--cmap", help="colour map: viridis, cool-to-warm, grayscale, hot, or any matplotlib "
                          "colormap name such as magma (a mesh or volume file; default: viridis)")
    p_render.add_argument("--range", type=finite_arg, nargs=2, action=RangeAction, metavar=("LO", "HI"),
                          help="colour and opacity range (default: the field's 1st..99.5th percentile)")
    p_render.add_argument("--opacity-scale", type=positive_arg, metavar="S",
                          help="multiply every opacity by S (capped at 1)")
    p_render.add_argument("--unit-distance", type=unit_distance_arg, metavar="U",
                          help="length (world units) over which the opacity is reached (default: diagonal / 20)")
    p_render.add_argument("--volume", metavar="FILE", help="a CT/MR volume to fuse with the mesh (tetvr.fuse; "
                          "the volume in grayscale by the default rule)")
    p_render.add_argument("--view", type=view_arg, metavar="DIR",
                          help="look along +x, -x, +y, -y, +z, -z or DX,DY,DZ (refits the camera)")
    p_render.add_argument("--azimuth", type=finite_arg, metavar="DEG", help="turn the camera about its view up")
    p_render.add_argument("--elevation", type=finite_arg, metavar="DEG", help="then turn it up about its right axis")
    p_render.add_argument("--zoom", type=positive_arg, metavar="Z", help="magnify by Z")
    p_render.add_argument("--parallel", action="store_true", help="parallel projection (refits the camera)")
    p_render.add_argument("--parity", action="store_true",
                          help="a ParaView state: ParaView's 'Projected tetra' picture (load_state(parity=True))")
    p_render.add_argument("--size", type=_size_arg, metavar="WxH", help="the PNG's size, legend and title included (default: 800x600, or the scene's)")
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
                          help="keep only the part of the mesh or volume inside this box (world units)")
    p_render.add_argument("--clip-plane", type=float, nargs=6, action="append",
                          metavar=("OX", "OY", "OZ", "NX", "NY", "NZ"),
                          help="keep only the side of the plane through O that N points into (repeatable)")
    p_render.add_argument("--surface", action="append", metavar="FILE",
                          help="an opaque surface (STL, OBJ, PLY, VTK, ...) drawn inside the volume (repeatable)")


def _parser() -> argparse.ArgumentParser:
    from tetvr import __version__

    parser = _Parser(prog="tetvr", description="Volume rendering of tetrahedral meshes.", epilog=_EPILOG)
    parser.add_argument("--version", action="version", version=f"tetvr {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_render(sub)
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


def _joined_views(argv: list[str]) -> list[str]:
    """``--view -x`` as ``--view=-x``: argparse would take ``-x`` for an option.

    >>> _joined_views(["render", "m.vtu", "--view", "-x", "--view", "+y"])
    ['render', 'm.vtu', '--view=-x', '--view', '+y']
    """
    out: list[str] = []
    for arg in argv:
        if out and out[-1] == "--view" and re.fullmatch(r"-([xyzXYZ]|[\d.].*)", arg):
            out[-1] = f"--view={arg}"
        else:
            out.append(arg)
    return out


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
            args = parser.parse_args(_joined_views(sys.argv[1:] if argv is None else list(argv)))
        except SystemExit as exc:  # --help
            return exc.code if isinstance(exc.code, int) else EXIT_OK
        return _COMMANDS[args.command](args)
    except KeyboardInterrupt:
        return _fail(EXIT_INTERRUPTED, "interrupted")
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - every failure ends in one line and a status
        return _fail(*_classify(exc))


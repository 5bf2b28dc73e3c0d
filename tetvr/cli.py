"""Command line: ``tetvr render scene.json -o out.png``, ``tetvr demo``, ``tetvr info mesh``,
``tetvr animate scene.json --orbit 36 -o frames/``, ``tetvr view scene.json``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["main"]


def _render_scene(scene_path: str, out: str, npy: str | None, method: str) -> int:
    from .image import write_png
    from .render import render
    from .scene import load_scene

    t0 = time.perf_counter()
    scene = load_scene(scene_path)
    t1 = time.perf_counter()
    image = render(scene.mesh, camera=scene.camera, tf=scene.tf, size=scene.size, settings=scene.settings,
                   method=method)
    t2 = time.perf_counter()
    write_png(image, out, background=scene.background)
    if npy:
        np.save(npy, image)
    print(f"{scene.mesh.n_tets} tets, field {scene.mesh.scalar_name!r}, {scene.size[0]}x{scene.size[1]} px, "
          f"{method}: read {t1 - t0:.2f} s, render {t2 - t1:.2f} s -> {out}" + (f" and {npy}" if npy else ""))
    return 0


def _fusion_demo(out: Path, size: tuple[int, int]) -> int:
    from . import FUSION_MODES
    from .examples import carotid_fusion
    from .fuse import RayTextures, fuse
    from .gl.raycaster import Raycaster
    from .gl.renderer import Renderer
    from .image import write_png

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
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="tetvr", description="Volume rendering of tetrahedral meshes.")
    sub = parser.add_subparsers(dest="command", required=True)
    p_render = sub.add_parser("render", help="render a scene JSON file to a PNG")
    p_render.add_argument("scene", help="scene JSON (see the README for its schema)")
    p_render.add_argument("-o", "--output", default="out.png", help="PNG to write (default: out.png)")
    p_render.add_argument("--npy", help="also save the premultiplied float32 RGBA array here")
    p_render.add_argument("--reference", action="store_true", help="use the exact CPU reference renderer")
    p_demo = sub.add_parser("demo", help="render the bundled demo scene")
    p_demo.add_argument("-o", "--output", default="demo.png", help="PNG to write (default: ./demo.png)")
    p_fusion = sub.add_parser("fusion-demo", help="render the bundled vessel-flow fusion demo in every mode")
    p_fusion.add_argument("-o", "--output", default="fusion", help="folder for the PNGs (default: ./fusion)")
    p_fusion.add_argument("--size", type=int, nargs=2, default=(480, 360), metavar=("W", "H"))
    p_cmp = sub.add_parser("compare", help="render a scene with tetvr and VTK's unstructured mappers; "
                           "time them and measure their error (needs tetvr[compare])")
    p_cmp.add_argument("scene", help="scene JSON")
    p_cmp.add_argument("-o", "--output", default="compare", help="folder for the pictures and tables")
    p_cmp.add_argument("--mappers", default="pt,bunyk,zsweep", help="VTK mappers, comma-separated ('' for none)")
    p_cmp.add_argument("--views", type=int, default=5, help="view changes to time (default 5)")
    p_cmp.add_argument("--size", type=int, nargs=2, metavar=("W", "H"), help="image size (default: the scene's)")
    p_info = sub.add_parser("info", help="describe a mesh file (points, tets, field, range, bounds)")
    p_info.add_argument("mesh")
    p_view = sub.add_parser("view", help="open a scene in a desktop window (needs moderngl-window and a display)")
    p_view.add_argument("scene", help="scene JSON")
    p_anim = sub.add_parser("animate", help="render a camera orbit or time steps to PNG frames or a video")
    p_anim.add_argument("scene", help="scene JSON (camera, transfer function, size)")
    p_anim.add_argument("--orbit", type=int, metavar="N", help="N frames of an orbit about the view up")
    p_anim.add_argument("--degrees", type=float, default=360.0, help="orbit sweep in degrees (default 360)")
    p_anim.add_argument("--time-series", nargs="+", metavar="FILE",
                        help="one mesh file per time step, or one XDMF time series")
    p_anim.add_argument("--fps", type=float, default=12.0, help="frames per second of a video (default 12)")
    p_anim.add_argument("--no-progress", action="store_true", help="no progress bar")
    p_anim.add_argument("-o", "--output", default="frames",
                        help="a folder for PNG frames, or a .mp4/.webm/.gif file (default: frames/)")
    args = parser.parse_args(argv)

    try:
        if args.command == "render":
            return _render_scene(args.scene, args.output, args.npy, "reference" if args.reference else "gpu")
        if args.command == "compare":
            from .vtkcompare import compare

            mappers = [m for m in args.mappers.split(",") if m]
            compare(args.scene, mappers=mappers, views=args.views, size=tuple(args.size) if args.size else None,
                    outdir=args.output, log=print)
            print(f"-> {Path(args.output) / 'comparison.md'}")
            return 0
        if args.command == "demo":
            from .scene import demo_scene_path

            return _render_scene(str(demo_scene_path()), args.output, None, "gpu")
        if args.command == "fusion-demo":
            return _fusion_demo(Path(args.output), tuple(args.size))
        if args.command == "info":
            from .mesh import read

            mesh = read(args.mesh)
            lo, hi = mesh.bounds
            print(f"{args.mesh}: {mesh.n_points} points, {mesh.n_tets} tets; field {mesh.scalar_name!r} "
                  f"range {mesh.scalar_range}; bounds {lo.tolist()} .. {hi.tolist()}; report {mesh.report}")
            return 0
        if args.command == "view":
            from .widget import run_desktop

            run_desktop(args.scene)
            return 0
        if args.command == "animate":
            from .animate import animate

            series = args.time_series
            if series is not None and len(series) == 1:
                series = series[0]  # one file: an XDMF time series (or a single step)
            files = animate(args.scene, args.output, orbit_frames=args.orbit, degrees=args.degrees,
                            time_series=series, fps=args.fps, progress=not args.no_progress)
            print(f"wrote {len(files)} file(s): {files[0]}{' ...' if len(files) > 1 else ''}")
            return 0
    except ImportError as exc:  # an optional dependency (imageio, moderngl-window)
        print(f"tetvr: error: {exc}", file=sys.stderr)
        return 2
    except (ValueError, KeyError, OSError, TypeError) as exc:  # OSError: unreadable input, unwritable output
        print(f"tetvr: error: {exc.args[0] if isinstance(exc, KeyError) and exc.args else exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # GLUnavailableError, shader errors
        print(f"tetvr: error: {exc}", file=sys.stderr)
        return 3
    return 1


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())

"""Side by side with VTK's (ParaView's) unstructured-grid volume mappers.

About this comparison
---------------------
ParaView renders a tetrahedral mesh as a volume with one of three VTK mappers,
``"pt"`` ("Projected tetra": Shirley & Tuchman's projected tetrahedra), ``"bunyk"``
("Bunyk ray cast") and ``"zsweep"`` ("Z sweep"); :mod:`tetvr.apps.vtkrender` runs them
offscreen, in a child process, and says what each one implements. :func:`compare`
measures all of them, and tetvr's GPU renderer, against tetvr's exact CPU reference and
writes the pictures and a table (:func:`write_report`; see docs/paraview.md for what was
measured and why the images differ).

VTK is optional (``pip install "tetvr[compare]"``):
:func:`~tetvr.apps.vtkrender.vtk_status` says whether it can render here.
:data:`PARITY_SETTINGS` render what "Projected tetra" renders (VTK parity).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.apps.animate import azimuth
from tetvr.apps.vtkrender import MAPPERS, VTKProcess, VTKUnavailableError, vtk_status
from tetvr.core.camera import Camera
from tetvr.core.image import atomic_output, psnr, rmse, write_png
from tetvr.core.outputs import check_outputs_in, check_writable_folder
from tetvr.settings import PARITY_SETTINGS

__all__ = [
    "compare",
    "orbit",
    "quantize8",
    "tile_images",
    "write_report",
]


# ---------------------------------------------------------------------------- helpers
def orbit(camera: Camera, degrees: float) -> Camera:
    """The camera turned about its view-up axis through the focal point (vtkCamera.Azimuth);
    :func:`tetvr.apps.animate.azimuth`."""
    return azimuth(camera, degrees)


def quantize8(image: NDArray[np.floating[Any]]) -> NDArray[np.float32]:
    """An image as an RGBA8 window stores it (rounded to 1/255), back as float."""
    return (np.round(np.clip(image, 0.0, 1.0) * 255.0) / 255.0).astype(np.float32)


# ---------------------------------------------------------------------------- compare
@dataclasses.dataclass
class _Method:
    key: str
    label: str
    kind: str  # "reference", "tetvr" or "vtk"
    image: NDArray[np.float32] | None = None
    first_frame_s: float | None = None
    view_change_s: list[float] = dataclasses.field(default_factory=list)
    info: dict[str, Any] = dataclasses.field(default_factory=dict)


def compare(
    scene: Any,
    *,
    mappers: Sequence[str] = ("pt", "bunyk", "zsweep"),
    size: tuple[int, int] | None = None,
    views: int = 5,
    azimuth_step: float = 5.0,
    references: Sequence[str] = ("exact", "linear", "vtk"),
    outdir: str | os.PathLike[str] | None = None,
    log: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Render a scene with tetvr and VTK's mappers; time them and measure their error.

    Parameters
    ----------
    scene : a :class:`tetvr.scene.scene.Scene` (or the path of a scene JSON file).
    mappers : keys of :data:`MAPPERS` to run (VTK must be available; see :func:`vtk_status`).
    size : (width, height); default the scene's.
    views : view changes timed after the first frame; each turns the camera by
        ``azimuth_step`` degrees about its view-up axis (vtkCamera.Azimuth).
    references : conventions of the CPU reference to measure against (``"exact"``
        first; ``"linear"`` and ``"vtk"`` show which convention each renderer follows).
    outdir : if given, :func:`write_report` writes the pictures and tables there.

    A scene that leaves the transfer function's unit distance to the default
    (``"unit_distance": null``, :attr:`Scene.unit_distance_default`) is compared with
    ParaView's default unit distance (:func:`tetvr.optics.transfer.paraview_unit_distance`), the
    one a ParaView user gets, for every renderer alike.
    log : called with a line of progress per method (e.g. ``print``).

    Returns
    -------
    dict
        ``scene`` (mesh, tets, size), ``machine``, ``vtk`` (version, window, GL renderer),
        and ``methods``: per renderer its first-frame time, the median view-change time
        (and every sample), and RMSE/PSNR of premultiplied RGB against each reference at
        the first view. Times include reading the image back.

    Examples
    --------
    >>> from tetvr.scene.scene import load_scene                       # doctest: +SKIP
    >>> table = compare(load_scene("scene.json"), outdir="out")  # doctest: +SKIP
    >>> [(m["label"], m["psnr"]["exact"]) for m in table["methods"]]  # doctest: +SKIP
    """
    scene_file = [("scene file", os.fspath(scene))] if isinstance(scene, (str, os.PathLike)) else []
    scene = _checked_scene(scene, mappers, references, views)
    if outdir is not None:  # before anything is rendered: write_report's files over no input
        check_outputs_in(outdir, lambda name: name.startswith("comparison.") or name.endswith(".png"),
                         "the comparison", scene_file + [("mesh file", p) for p in scene.input_paths()], by="compare")
        check_writable_folder(outdir, "the comparison")
    say = log or (lambda line: None)
    vtk_info: dict[str, Any] = {}
    if mappers:
        # Before anything is rendered: the reference alone takes seconds to minutes.
        ok, why = vtk_status()
        if not ok:
            raise VTKUnavailableError(why)
        vtk_info["status"] = why
    width, height = (int(v) for v in (size or scene.size))
    size = (width, height)
    scene, unit_from = _with_paraview_unit_distance(scene, say)
    cams = [orbit(scene.camera, azimuth_step * (i + 1)) for i in range(views)]

    refs, methods = _reference_methods(scene, size, references, say)
    methods += _tetvr_methods(scene, size, cams, say)
    methods += _vtk_methods(scene, size, cams, mappers, vtk_info, say)

    result = _table(scene, size, views, azimuth_step, methods, refs, vtk_info)
    result["scene"]["unit_distance_from"] = unit_from
    if outdir is not None:
        write_report(result, outdir, images={m.key: m.image for m in methods if m.image is not None},
                     background=scene.background)
    return result


def _checked_scene(scene: Any, mappers: Sequence[str], references: Sequence[str], views: int) -> Any:
    """:func:`compare`'s scene (read if it is a path) once its arguments are checked."""
    from tetvr.scene.scene import Scene
    from tetvr.scene.load import load_scene

    if isinstance(scene, (str, os.PathLike)):
        scene = load_scene(scene)
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a tetvr Scene or a path, got {type(scene).__name__}")
    for m in mappers:
        if m not in MAPPERS:
            raise ValueError(f"mappers must be keys of {sorted(MAPPERS)}, got {m!r}")
    if not references or references[0] != "exact":
        raise ValueError(f"references must start with 'exact', got {references!r}")
    if not (isinstance(views, int) and views >= 1):
        raise ValueError(f"views must be a positive integer, got {views!r}")
    return scene


def _with_paraview_unit_distance(scene: Any, say: Callable[[str], None]) -> tuple[Any, str]:
    """The scene as compared, and where its unit distance comes from."""
    if not getattr(scene, "unit_distance_default", False):
        return scene, "the scene"
    # The scene left the unit distance to tetvr's default (diagonal / 20): compare what a
    # ParaView user sees, ParaView's default (diagonal / cube root of the cells), everywhere.
    from tetvr.optics.transfer import paraview_unit_distance

    u = paraview_unit_distance(scene.mesh.bounds, scene.mesh.n_tets)
    scene = dataclasses.replace(scene, tf=dataclasses.replace(scene.tf, unit_distance=u),
                                unit_distance_default=False)
    unit_from = "ParaView's default (bounding-box diagonal / cube root of the cell count)"
    say(f"unit distance: {u:.6g}, {unit_from}; the scene left it to the default")
    return scene, unit_from


def _reference_methods(scene: Any, size: tuple[int, int], references: Sequence[str],
                       say: Callable[[str], None]) -> tuple[dict[str, NDArray[np.float32]], list[_Method]]:
    """The CPU reference in each convention (by name), timed, and as rows of the table."""
    from tetvr.reference.tets import render_reference

    mesh, tf, camera = scene.mesh, scene.tf, scene.camera
    refs: dict[str, NDArray[np.float32]] = {}
    ref_times: dict[str, float] = {}
    for optics in references:
        t0 = time.perf_counter()
        refs[optics] = render_reference(mesh, camera, tf, size, optics=optics)
        ref_times[optics] = time.perf_counter() - t0
        say(f"reference ({optics}): {ref_times[optics]:.2f} s")
    methods: list[_Method] = [_Method(f"reference_{o}", f"tetvr CPU reference ({o})", "reference", refs[o],
                                      first_frame_s=ref_times[o]) for o in references]
    return refs, methods


def _tetvr_methods(scene: Any, size: tuple[int, int], cams: list[Camera],
                   say: Callable[[str], None]) -> list[_Method]:
    """tetvr's GPU renderer with the scene's settings, then with VTK parity, timed: first
    frame (context + upload + table) and each view change in ``cams``."""
    from tetvr.gl.renderer import Renderer

    mesh, tf, camera = scene.mesh, scene.tf, scene.camera
    methods: list[_Method] = []
    for key, label, settings, parity in (("tetvr", "tetvr GPU", scene.settings, False),
                                         ("tetvr_parity", "tetvr GPU, VTK parity", PARITY_SETTINGS, True)):
        meth = _Method(key, label, "tetvr", info={"settings": settings.to_dict()})
        t0 = time.perf_counter()
        with Renderer(settings) as r:
            image = r.render(mesh, camera, tf, size=size)
            meth.first_frame_s = time.perf_counter() - t0
            for cam in cams:
                t0 = time.perf_counter()
                r.render(mesh, cam, tf, size=size)
                meth.view_change_s.append(time.perf_counter() - t0)
            meth.info["gl_renderer"] = r.gl_info.get("GL_RENDERER", "")
        meth.image = quantize8(image) if parity else image
        methods.append(meth)
        say(f"{label}: first {meth.first_frame_s:.3f} s, view change {statistics.median(meth.view_change_s):.3f} s")
    return methods


def _vtk_methods(scene: Any, size: tuple[int, int], cams: list[Camera], mappers: Sequence[str],
                 vtk_info: dict[str, Any], say: Callable[[str], None]) -> list[_Method]:
    """VTK's ``mappers``, each in its own process, timed as :func:`_tetvr_methods` times
    tetvr; ``vtk_info`` gets VTK's version, window and GL renderer."""
    mesh, tf, camera = scene.mesh, scene.tf, scene.camera
    methods: list[_Method] = []
    for key in mappers:
        cls, pv_name = MAPPERS[key]
        meth = _Method(f"vtk_{key}", f'VTK {cls} (ParaView "{pv_name}")', "vtk")
        # Timed inside the VTK process (VTKProcess): without starting it and moving images.
        with VTKProcess(mesh, tf, mapper=key, size=size) as r:
            image = r.render(camera)
            meth.first_frame_s = r.first_seconds
            for cam in cams:
                r.render(cam)
                meth.view_change_s.append(r.last_seconds)
            meth.info.update(r.info)
            vtk_info.update(version=r.info["version"], window=r.info["window"], gl_renderer=r.info["gl_renderer"])
        meth.image = image
        methods.append(meth)
        say(f"{meth.label}: first {meth.first_frame_s:.3f} s, view change {statistics.median(meth.view_change_s):.3f} s")
    return methods


def _table(scene: Any, size: tuple[int, int], views: int, step: float, methods: list[_Method],
           refs: dict[str, NDArray[np.float32]], vtk_info: dict[str, Any]) -> dict[str, Any]:
    rows = []
    exact = refs["exact"]
    covered = exact[..., 3] > 1.0 / 255.0
    for m in methods:
        if m.image is None:
            raise AssertionError(f"{m.key} has no image")
        row: dict[str, Any] = {"key": m.key, "label": m.label, "kind": m.kind,
                               "first_frame_s": m.first_frame_s,
                               "view_change_s": statistics.median(m.view_change_s) if m.view_change_s else None,
                               "view_change_samples_s": m.view_change_s,
                               "rmse": {o: rmse(m.image, r) for o, r in refs.items()},
                               "psnr": {o: psnr(m.image, r) for o, r in refs.items()},
                               "max_abs_error": float(np.abs(m.image[..., :4].astype(np.float64) - exact).max()),
                               "mean_alpha": float(m.image[..., 3][covered].mean()) if covered.any() else 0.0}
        row.update(m.info)
        rows.append(row)
    pt = next((m.image for m in methods if m.key == "vtk_pt"), None)
    for row, m in zip(rows, methods):
        if pt is not None and m.image is not None:
            row["psnr_vs_vtk_pt"] = psnr(m.image, pt)
            row["max_abs_diff_vs_vtk_pt"] = float(np.abs(m.image.astype(np.float64) - pt).max())
    tetvr_row = next((r for r in rows if r["key"] == "tetvr"), None)
    for row in rows:
        if tetvr_row and row["view_change_s"] and tetvr_row["view_change_s"]:
            row["view_change_vs_tetvr"] = row["view_change_s"] / tetvr_row["view_change_s"]
    return {
        "scene": {"mesh": scene.mesh_path, "n_tets": scene.mesh.n_tets, "n_points": scene.mesh.n_points,
                  "scalars": scene.mesh.scalar_name, "size": list(size), "camera": scene.camera.to_dict(),
                  "transfer_function": scene.tf.to_dict()},
        "timing": {"views": views, "azimuth_step_deg": step,
                   "note": "first frame: from the mesh in memory to the image read back, window/context "
                           "creation included; view change: median over the views, camera turned each "
                           "frame, image read back"},
        "machine": {"platform": platform.platform(), "processor": platform.processor(), "cpus": os.cpu_count()},
        "vtk": vtk_info,
        "methods": rows,
    }


def write_report(result: dict[str, Any], outdir: str | os.PathLike[str], *,
                 images: dict[str, NDArray[np.float32]] | None = None, diff_gain: float = 10.0,
                 background: Any = None) -> Path:
    """Write ``comparison.json``, ``comparison.md`` and, with ``images``, the pictures.

    Pictures: ``side_by_side.png`` (every method in table order, four to a row, each
    titled with its number, name and PSNR against the exact reference), ``differences.png``
    (``|image - exact reference|`` of premultiplied RGB times ``diff_gain``, same order)
    and one ``<key>.png`` / ``<key>_diff.png`` per method. Without matplotlib the two
    grids are written untitled. The images are drawn over ``background`` (the scene's;
    default :data:`tetvr.core.image.DEFAULT_BACKGROUND`), the differences over black.
    """
    bg = {} if background is None else {"background": tuple(background)}
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "comparison.json", "w") as f:
        json.dump(result, f, indent=2, default=float)
    if images:
        exact = images.get("reference_exact")
        tiles, diffs, titles = [], [], []
        for i, m in enumerate(result["methods"]):
            if m["key"] not in images:
                continue
            img = images[m["key"]]
            write_png(img, out / f"{m['key']}.png", **bg)
            tiles.append(img)
            db = (m.get("psnr") or {}).get("exact")
            name = m["label"] if len(m["label"]) <= 26 else m["key"]  # the table has the full name
            score = "" if db is None else "\nthe reference" if math.isinf(db) else f"\n{_fmt(db, '.1f')} dB"
            titles.append(f"{i + 1}. {name}{score}")
            if exact is not None:
                d = np.zeros_like(img)
                d[..., :3] = np.clip(np.abs(img[..., :3].astype(np.float64) - exact[..., :3]) * diff_gain, 0, 1)
                d[..., 3] = 1.0
                write_png(d, out / f"{m['key']}_diff.png", background=None)
                diffs.append(d)
        _write_grid(tiles, titles, out / "side_by_side.png", suptitle=None, **bg)
        if diffs:
            _write_grid(diffs, titles, out / "differences.png", suptitle=f"|image - exact reference| x {diff_gain:g}")
    (out / "comparison.md").write_text(_markdown(result, diff_gain))
    return out


def _write_grid(images: list[NDArray[np.float32]], titles: list[str], path: Path, *, suptitle: str | None,
                **background: Any) -> None:
    try:
        from tetvr.apps.annotate import panels

        data = panels(images, titles, cols=min(4, len(images)), suptitle=suptitle, **background)
    except ImportError:  # matplotlib absent: the grid without its titles
        write_png(tile_images(images), path, **background)
        return
    with atomic_output(path) as f:
        f.write(data)


def tile_images(images: list[NDArray[np.float32]], cols: int = 4, gap: int = 4) -> NDArray[np.float32]:
    """Images of one size tiled in reading order, ``cols`` per row, on a grey grid."""
    h, w = images[0].shape[:2]
    rows = -(-len(images) // cols)
    cols = min(cols, len(images))
    out = np.zeros((rows * h + (rows - 1) * gap, cols * w + (cols - 1) * gap, 4), dtype=np.float32)
    out[..., :3] = 0.5
    out[..., 3] = 1.0
    for i, img in enumerate(images):
        r, c = divmod(i, cols)
        out[r * (h + gap):r * (h + gap) + h, c * (w + gap):c * (w + gap) + w] = img
    for i in range(len(images), rows * cols):
        r, c = divmod(i, cols)
        out[r * (h + gap):r * (h + gap) + h, c * (w + gap):c * (w + gap) + w] = (0, 0, 0, 1)
    return out


def _fmt(v: Any, spec: str) -> str:
    if v is None:
        return "-"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    return format(v, spec)


def _markdown(result: dict[str, Any], gain: float) -> str:
    s = result["scene"]
    refs = list(result["methods"][0]["psnr"])
    lines = [f"# tetvr against VTK: {Path(s['mesh']).name}", "",
             f"{s['n_tets']} tets, field {s['scalars']!r}, {s['size'][0]}x{s['size'][1]} px. "
             f"{result['timing']['note']}; {result['timing']['views']} views, "
             f"{result['timing']['azimuth_step_deg']} degrees apart.", "",
             f"VTK: {result['vtk'].get('status', 'not run')}", "",
             "Error: PSNR (dB) and RMSE of premultiplied RGB against tetvr's CPU reference in each "
             "convention (`exact`: tau = -ln(1-a)/u; `linear`: tau = a/u; `vtk`: VTK's projected-"
             "tetrahedra segment formula on exact geometry; see docs/paraview.md).", "",
             "| # | method | first frame (s) | view change (s) | / tetvr | "
             + " | ".join(f"PSNR {o}" for o in refs) + " | PSNR vs VTK PT | RMSE exact | max abs err |",
             "|---|---|---|---|---|" + "---|" * len(refs) + "---|---|---|"]
    for i, m in enumerate(result["methods"]):
        lines.append(
            f"| {i + 1} | {m['label']} | {_fmt(m['first_frame_s'], '.3f')} | {_fmt(m['view_change_s'], '.3f')} | "
            f"{_fmt(m.get('view_change_vs_tetvr'), '.2f')} | "
            + " | ".join(_fmt(m["psnr"][o], ".1f") for o in refs)
            + f" | {_fmt(m.get('psnr_vs_vtk_pt'), '.1f')} | {_fmt(m['rmse']['exact'], '.2e')}"
            f" | {_fmt(m['max_abs_error'], '.3f')} |")
    lines += ["", "Pictures, numbered and titled as the table, four to a row: `side_by_side.png` "
              f"and `differences.png` (|image - exact reference| x {gain:g}); one "
              "`<key>.png` and `<key>_diff.png` per method.", ""]
    return "\n".join(lines)

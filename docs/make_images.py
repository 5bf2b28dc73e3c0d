"""Generate the pictures of the guide (docs/*.md) with tetvr itself.

    pip install -e ".[bench]"             # matplotlib, for the labelled panels
    python docs/make_images.py            # everything, ~1 minute on llvmpipe
    python docs/make_images.py methods    # one group: quickstart, defaults, before_after, methods, fusion,
                                          # limits, interactive, clipping

Every picture under docs/images/guide/ comes from this script, and the before/after
pictures docs/images/defaults_before_after_*.png (from the shared real data); docs/images/demo.png from
`tetvr demo -o docs/images/demo.png`; docs/images/fusion/ from
`tetvr fusion-demo -o docs/images/fusion`. Each panel title states what it shows and,
where there is a reference, the PSNR (dB, premultiplied RGB) against the exact CPU
renderer. Difference panels are magnified by the factor in their title. The method
pictures' numbers go to docs/images/guide/methods/psnr.json, which the docs quote through
bench/doc_values.py (`python bench/doc_tables.py --write` after this script).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import warnings
from pathlib import Path

import numpy as np

import tetvr
from tetvr import Camera, RenderSettings, TransferFunction
from tetvr.mesh import synthetic
from tetvr.apps.annotate import panels as labelled
from tetvr.core.image import DEFAULT_BACKGROUND, psnr
from tetvr.reference.tets import render_reference
from tetvr.scene.stability import CASES, case

HERE = Path(__file__).resolve().parent
OUT = HERE / "images" / "guide"
ROOT = HERE.parent


def panels(images, titles, path, *, background=DEFAULT_BACKGROUND, suptitle=None, cols=None, size_in=2.2):
    """Images side by side (or in rows of ``cols``), each under its title, as one PNG
    (tetvr.apps.annotate.panels: the same labelled grid tetvr compare and fusion-demo write)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(labelled(images, titles, background=background, suptitle=suptitle, cols=cols, width_in=size_in))
    print("wrote", path.relative_to(ROOT))


def _diff(a, b, k):
    d = np.zeros_like(a)
    d[..., :3] = np.clip(np.abs(a[..., :3] - b[..., :3]) * k, 0, 1)
    d[..., 3] = 1.0
    return d


def _nice(k: float) -> int:
    """A round magnification near k (1, 2, 5, 10, 20, ...)."""
    k = max(k, 1.0)
    e = 10 ** int(np.floor(np.log10(k)))
    return int(max(m * e for m in (1, 2, 5) if m * e <= k))


def _tf(mesh, opacity, units, preset="viridis"):
    diag = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    return TransferFunction.preset(preset, mesh.scalar_range, opacity=opacity, unit_distance=diag / units)


# ---------------------------------------------------------------- scenes
def post_scene():
    s = tetvr.load_scene(tetvr.demo_scene_path())
    return s.mesh, s.camera, s.tf


def close_perspective():
    m = synthetic.cube(8)
    return m, Camera.fit(m, direction=(-0.3, -0.2, -1.0), view_angle=60, zoom=1.6), \
        _tf(m, [(0, 0.2), (0.5, 0.6), (1, 0.9)], 4)


def rings():
    r = synthetic.interlocking_rings(10, 1)
    return r, Camera.fit(r, direction=(-0.5, -1.0, -0.6), view_up=(0, 0, 1)), _tf(r, [(0, 0.9), (1, 0.9)], 6)


def stability(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = case(name)
    return c.mesh, c.camera, c.tf


# ---------------------------------------------------------------- groups
def quickstart():
    mesh, cam, _ = post_scene()
    from tetvr.optics.colormaps import colormap

    names = ["viridis", "cool-to-warm", "hot", "grayscale", "magma"]
    ramp = [(0.0, 0.0), (0.2, 0.05), (0.5, 0.3), (0.8, 0.8), (1.0, 1.0)]
    with tetvr.Renderer() as r:
        imgs = [r.render(mesh, cam, colormap(n, (0.45, 1.4), opacity=ramp, unit_distance=0.25), size=(240, 180))
                for n in names]
        panels(imgs, names, OUT / "colormaps.png",
               suptitle="post.vtk, Pressure, one opacity ramp, five colour maps")
        units = [0.08, 0.25, 1.0]
        imgs = [r.render(mesh, cam, TransferFunction.preset("viridis", (0.45, 1.4), opacity=ramp, unit_distance=u),
                         size=(240, 180)) for u in units]
        panels(imgs, [f"unit_distance = {u}" for u in units], OUT / "unit_distance.png",
               suptitle="the same opacity points, three unit distances")


SHARED = Path(__import__("os").environ.get("TETVR_SHARED_DATA", ROOT.parent / "shared" / "data"))
#: Real results for the defaults pictures: (file in ../shared/data/tets, field).
DEFAULT_MESHES = [("bluntfin_tets.vtu", "Density"), ("pipe_flow_init_flow.vtu", "Velocity"),
                  ("beam_tet4_result_100.vtu", "VonMises_stress"), ("post.vtk", "Pressure")]


def _shared_meshes():
    """(file name, field, path, mesh) of each of DEFAULT_MESHES that the shared data holds;
    the others are named as skipped."""
    for name, field in DEFAULT_MESHES:
        path = SHARED / "tets" / name
        if not path.is_file():
            print(f"skipped {name}: {path} is absent (the shared data)")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # zero-volume tets dropped, cell data averaged
            mesh = tetvr.read(path, field)
        yield name, field, path, mesh


def defaults():
    """Real FEM/CFD results with tetvr's defaults, beside a constant opacity over the full range."""
    from tetvr.core.camera import _fit
    from tetvr.render import default_transfer_function
    from tetvr.optics.transfer import default_unit_distance

    imgs, titles = [], []
    size = (320, 240)
    for name, field, path, mesh in _shared_meshes():
        cam = _fit(mesh, aspect=size[0] / size[1])
        flat = TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.5,
                                       unit_distance=default_unit_distance(mesh.bounds))
        for tf, what in ((flat, "full range, opacity 0.5"), (default_transfer_function(mesh), "tetvr's default")):
            imgs.append(tetvr.render(mesh, camera=cam, tf=tf, size=size))
            titles.append(f"{name.split('_')[0].split('.')[0]} ({field}): {what}")
    if imgs:
        panels(imgs, titles, OUT / "defaults.png", cols=2, size_in=3.2,
               suptitle="constant opacity over the field's full range (left) and the data-driven default (right)")


def _sphere_framed(mesh, direction=(-1.0, -0.6, -1.2), view_angle=30.0):
    """The framing tetvr's defaults had before ``Camera.fit`` framed the projected extent:
    the bounding sphere fills the picture's short side (same direction and view up)."""
    from tetvr.core.camera import bounding_sphere, default_view_up

    centre, radius = bounding_sphere(mesh.bounds)
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    dist = radius / np.sin(np.radians(view_angle) / 2)
    return Camera(position=tuple(centre - d * dist), focal_point=tuple(centre), view_up=tuple(default_view_up(d)),
                  view_angle=view_angle)


def before_after(size=(640, 480)):
    """docs/images/defaults_before_after_*.png (docs/pictures.md): each real result of
    DEFAULT_MESHES as the former defaults drew it, beside the PNG `tetvr render FILE` writes."""
    import subprocess
    import tempfile

    from matplotlib.image import imread

    from tetvr.optics.transfer import default_unit_distance

    for name, field, path, mesh in _shared_meshes():
        tf = TransferFunction.preset("viridis", mesh.scalar_range, opacity=0.5,
                                     unit_distance=default_unit_distance(mesh.bounds))
        before = tetvr.render(mesh, camera=_sphere_framed(mesh), tf=tf, size=size)
        with tempfile.TemporaryDirectory() as tmp:
            png = Path(tmp) / "after.png"
            subprocess.run([str(Path(sys.executable).with_name("tetvr")), "render", str(path), "--scalars", field,
                            "--size", f"{size[0]}x{size[1]}", "-o", str(png)], check=True)
            rgb = imread(png)[..., :3]  # an opaque PNG: premultiplied is the same
        after = np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,))], axis=2).astype(np.float32)
        stem = Path(name).stem.removesuffix("_tets")  # bluntfin_tets.vtu: defaults_before_after_bluntfin.png
        panels([before, after], ["before: full range, opacity 0.5, bounding sphere framed",
                                 f"tetvr render {name} --scalars {field}"],
               ROOT / "docs" / "images" / f"defaults_before_after_{stem}.png", cols=2, size_in=5.0)


#: Projected tetrahedra with every other setting at its default: the baseline of the settings
#: only projected tetrahedra have (the default method, tet marching, ignores them).
PROJECTED = RenderSettings(method="projected")
DEFAULT = RenderSettings()
PREMULTIPLIED = RenderSettings(table_encoding="premultiplied")

#: picture name -> (scene, (baseline label, baseline settings), variant settings, what it shows).
METHOD_PICTURES = {
    "perspective_correct": (close_perspective, ("projected", PROJECTED),
                            RenderSettings(method="projected", perspective_correct=False),
                            "perspective_correct=False: scalars and thickness linear in screen space"),
    "table_encoding": (close_perspective, ("default", DEFAULT), PREMULTIPLIED,
                       "table_encoding='premultiplied': alpha interpolated across thickness slices"),
    "table_filter": (close_perspective, ("premultiplied", PREMULTIPLIED),
                     RenderSettings(table_encoding="premultiplied", table_filter="cubic"),
                     "table_filter='cubic' on the premultiplied table (baseline: the same table, linear)"),
    "table_dtype": (post_scene, ("default", DEFAULT), RenderSettings(table_dtype="uint8"),
                    "table_dtype='uint8': an 8-bit table"),
    "framebuffer": (post_scene, ("projected", PROJECTED), RenderSettings(method="projected", framebuffer="uint8"),
                    "framebuffer='uint8': 8-bit compositing (projected tetrahedra)"),
    "table_scalar_bins": (lambda: stability("spike_tf"), ("default", DEFAULT), RenderSettings(table_scalar_bins=64),
                          "table_scalar_bins=64 on a thin opacity spike (iso-layer)"),
    "table_align_nodes": (lambda: stability("camera_inside"), ("default", DEFAULT),
                          RenderSettings(table_align_nodes=False),
                          "table_align_nodes=False: even nodes miss the colour map's points at k/8"),
    "table_thickness_slices": (rings, ("default", DEFAULT), RenderSettings(table_thickness_slices=8, table_log_base=4.0),
                               "table_thickness_slices=8, table_log_base=4 on opaque rings"),
    "sort_none": (rings, ("projected", PROJECTED), RenderSettings(method="projected", sort="none"),
                  "sort='none': cells drawn in input order (projected tetrahedra)"),
    "sort_mpvonc": (close_perspective, ("projected", PROJECTED), RenderSettings(method="projected", sort="centroid"),
                    "sort='centroid' where it is slightly wrong; projected's default here is MPVONC"),
    "sort_centroid_rings": (rings, ("projected", PROJECTED), RenderSettings(method="projected", sort="centroid"),
                            "sort='centroid' on interlocking rings; projected's default here is xmpvo"),
    "sort_mpvonc_rings": (rings, ("projected", PROJECTED), RenderSettings(method="projected", sort="mpvonc"),
                          "sort='mpvonc' on interlocking rings: its depth heuristic between parts fails"),
    "optics_vtk": (post_scene, ("default", DEFAULT), RenderSettings(optics="vtk", perspective_correct=False),
                   "optics='vtk' + screen-linear: VTK's projected-tetrahedra convention"),
    "integration": (lambda: stability("spike_tf"), ("default", DEFAULT), RenderSettings(integration="exact"),
                    "integration='exact' on a thin opacity spike: tet marching without the table"),
}


def _changed(settings: RenderSettings) -> dict:
    return {f.name: getattr(settings, f.name) for f in dataclasses.fields(settings)
            if getattr(settings, f.name) != getattr(DEFAULT, f.name)}


def methods(size=(160, 160), only=None):
    """One picture per METHOD_PICTURES entry (``only``: those names): the reference, the
    baseline, the variant and both errors. Its numbers go to docs/images/guide/methods/psnr.json,
    which the docs quote through bench/doc_values.py."""
    from tetvr.optics.tablesize import resolve as table_size
    from tetvr.order.method import choose

    path = OUT / "methods" / "psnr.json"
    summary = json.loads(path.read_text()) if path.is_file() and only else {}
    refs = {}
    for name, (make, (base_label, base), settings, what) in METHOD_PICTURES.items():
        if only is not None and name not in only:
            continue
        mesh, cam, tf = make()
        key = id(make) if make not in (post_scene, close_perspective, rings) else make.__name__
        if key not in refs:
            refs[key] = render_reference(mesh, cam, tf, size)
        ref = refs[key]
        images = []
        for s in (base, settings):
            with tetvr.Renderer(s) as r:
                images.append(r.render(mesh, cam, tf, size=size))
        (b, v), (p0, p1) = images, (psnr(images[0], ref), psnr(images[1], ref))
        k = _nice(0.8 / max(float(np.abs(v[..., :3] - ref[..., :3]).max()), 1e-6))
        panels([ref, b, v, _diff(b, ref, k), _diff(v, ref, k)],
               ["exact reference", f"{base_label}: {p0:.1f} dB", f"variant: {p1:.1f} dB",
                f"|{base_label} - ref| x {k}", f"|variant - ref| x {k}"],
               OUT / "methods" / f"{name}.png", suptitle=what, size_in=2.0)
        t = table_size(base, tf, mesh)
        summary[name] = {"what": what, "size": list(size), "base": base_label,
                         "base_settings": {a: repr(x) for a, x in _changed(base).items()},
                         "variant_settings": {a: repr(x) for a, x in _changed(settings).items()},
                         "base_method": choose(base, mesh), "variant_method": choose(settings, mesh),
                         "base_table": [t.n_bins, t.n_slices], "base_table_warped": bool(t.warp),
                         "base_psnr": round(p0, 1), "variant_psnr": round(p1, 1), "magnification": k}
    path.write_text(json.dumps(summary, indent=1) + "\n")
    print("wrote", path.relative_to(ROOT))


def fusion(size=(320, 240)):
    from tetvr import FUSION_MODES, RayTextures, fuse
    from tetvr.scene.examples import carotid_fusion

    s = carotid_fusion()
    w, h = size
    end = np.ones((h, w))
    end[:, w // 2:] = 0.55
    textures = RayTextures(np.zeros((h, w)), end)
    with tetvr.Renderer() as r, tetvr.Raycaster(ctx=r.ctx) as c:
        imgs = [c.render(s.volume, s.camera, s.volume_tf, size=size), r.render(s.mesh, s.camera, s.mesh_tf, size=size)]
        for mode in FUSION_MODES:
            imgs.append(fuse(s.mesh, s.volume, s.camera, s.mesh_tf, s.volume_tf, size=size, mode=mode, renderer=r,
                             raycaster=c, ray_textures=textures if mode == "ray_textures" else None))
    titles = ["volume alone", "mesh alone", *(f"mode='{m}'" for m in FUSION_MODES)]
    titles[-1] += "\n(right half: first 55 % of each ray)"
    panels(imgs, titles, OUT / "fusion_modes.png", cols=3, size_in=3.0, background=s.background,
           suptitle="carotid flow: speed as a volume (grey) and the fast lumen as a tet mesh (hot)")


def limits(size=(96, 96)):
    names = sorted(CASES)
    gpu, diffs, titles, dtitles = [], [], [], []
    with tetvr.Renderer() as r:
        for name in names:
            mesh, cam, tf = stability(name)
            img = r.render(mesh, cam, tf, size=size)
            ref = render_reference(mesh, cam, tf, size)
            p = psnr(img, ref)
            k = _nice(0.8 / max(float(np.abs(img[..., :3] - ref[..., :3]).max()), 1e-6))
            gpu.append(img)
            diffs.append(_diff(img, ref, k))
            titles.append(f"{name}: {'exact (empty)' if p > 150 else f'{p:.1f} dB'}")
            dtitles.append(f"{name}: x {k}")
    # One line per title: panels() leaves one line of room above each row.
    panels(gpu, titles, OUT / "stability_cases.png", cols=6, size_in=1.9,
           suptitle="the stability cases, default settings, 96x96 (PSNR against the reference)")
    panels(diffs, dtitles, OUT / "stability_errors.png", cols=6, size_in=1.9,
           suptitle="|GPU - reference|, each panel magnified by its factor to show the shape of the error")


def interactive():
    from tetvr.apps.animate import orbit
    from tetvr.apps.viewer.model import TransferFunctionEditor

    mesh, cam, tf = post_scene()
    ed = TransferFunctionEditor.from_transfer_function(tf, colormap="viridis")
    img = ed.image(mesh.scalars, size=(480, 150), selected=2)
    panels([img], ["opacity points over log10(1 + count) of the Pressure values"], OUT / "tf_editor.png",
           size_in=5.0)
    with tetvr.Renderer() as r:
        frames = [r.render(mesh, c, tf, size=(160, 120)) for c in orbit(cam, 6)]
    panels(frames, [f"{60 * k} deg" for k in range(6)], OUT / "orbit.png", cols=6, size_in=1.8,
           suptitle="tetvr animate demo.json --orbit 6 (frames 0..5)")


def clipping(size=(240, 180)):
    """Clip planes, a clip box and an opaque surface in the demo's post, each against the reference."""
    from tetvr import Clip, Surface

    mesh, cam, tf = post_scene()
    lo, hi = mesh.bounds
    c = 0.5 * (lo + hi)
    # An opaque rod through the post's middle: a 24-sided cylinder, shaded smooth.
    k = 24
    ang = np.linspace(0, 2 * np.pi, k, endpoint=False)
    ring = np.stack([0.45 * np.cos(ang), 0.45 * np.sin(ang)], axis=1)
    z0, z1 = lo[2] - 0.3, hi[2] + 0.6
    pts = np.concatenate([np.column_stack([ring + c[:2], np.full(k, z0)]), np.column_stack([ring + c[:2], np.full(k, z1)]),
                          [[c[0], c[1], z0], [c[0], c[1], z1]]])
    tris = []
    for j in range(k):
        a, b = j, (j + 1) % k
        tris += [(a, b, k + b), (a, k + b, k + a), (2 * k, b, a), (2 * k + 1, k + a, k + b)]
    rod = Surface(pts, np.array(tris), color=(0.85, 0.55, 0.3), smooth=False)
    cases = [("the whole mesh", {}),
             ("Clip.plane(centre, (-1, -1, 0))", {"clip": Clip.plane(c, (-1, -1, 0))}),
             ("Clip.box: one quadrant", {"clip": Clip.box((lo[0], lo[1], lo[2]), (c[0], c[1], hi[2]))}),
             ("an opaque rod (Surface)", {"surfaces": [rod]}),
             ("rod and plane together", {"surfaces": [rod], "clip": Clip.plane(c, (-1, -1, 0))})]
    imgs, titles, diffs, dtitles = [], [], [], []
    with tetvr.Renderer() as r:
        for title, kw in cases:
            img = r.render(mesh, cam, tf, size=size, **kw)
            ref = render_reference(mesh, cam, tf, size, **kw)
            err = float(np.abs(img[..., :3] - ref[..., :3]).max())
            k = _nice(0.8 / max(err, 1e-6))
            imgs.append(img)
            titles.append(f"{title}\n{psnr(img, ref):.1f} dB, max {err:.1e}")
            diffs.append(_diff(img, ref, k))
            dtitles.append(f"|GPU - ref| x {k}")
    panels(imgs + diffs, titles + dtitles, OUT / "clipping.png", cols=5, size_in=2.4,
           suptitle="post.vtk: clip planes, a clip box, an opaque surface (default settings; PSNR against the reference)")


GROUPS = {"quickstart": quickstart, "defaults": defaults, "before_after": before_after, "methods": methods, "fusion": fusion, "limits": limits, "interactive": interactive,
          "clipping": clipping}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("groups", nargs="*", help=f"some of {', '.join(GROUPS)} (default: all)")
    args = p.parse_args(argv)
    unknown = set(args.groups) - set(GROUPS)
    if unknown:
        p.error(f"unknown groups {sorted(unknown)}; choose from {list(GROUPS)}")
    for name in args.groups or GROUPS:
        GROUPS[name]()
    return 0


if __name__ == "__main__":
    sys.exit(main())

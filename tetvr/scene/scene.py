"""Scenes as JSON: everything needed to render one image again.

Schema (keys other than these are rejected; paths are relative to the JSON file)::

    {
      "mesh": "post.vtk",                 # any meshio-readable file            (required)
      "scalars": "Pressure",              # point or cell field; default: the first
      "component": null,                  # vector fields: null = magnitude, or an index
      "transfer_function": {              # either a colour map (tetvr's or matplotlib's) ...
          "preset": "viridis", "range": null, "opacity": null, "unit_distance": null
      },                                  # ... or explicit {"color", "opacity", "unit_distance"}
      "camera": {"fit": {"direction": [-1, -0.6, -1.2], "parallel": false}},
                                          # ... or explicit Camera fields (position, ...);
                                          # without clipping_range: computed from the data
                                          # as ParaView does (camera.reset_clipping_range)
      "size": [512, 512],
      "background": [1, 1, 1],            # for PNG output; the float image is translucent
      "settings": {},                     # RenderSettings fields
      "clip": {"box": [[0, 0, 0], [1, 1, 1]]},  # optional: tetvr.Clip.from_dict ("box",
                                          # "plane": {"origin", "normal"}, "planes")
      "surfaces": [{"path": "vessel.stl", "color": [0.9, 0.4, 0.3], "ambient": 0.25,
                    "smooth": true}]      # optional: opaque surfaces (tetvr.Surface.read)
    }

Each ``null`` (or absent key) takes the default rule's part
(:func:`tetvr.render.default_transfer_function`): ``range`` the 1st..99.5th percentile of
the field weighted by volume, ``opacity`` a quadratic ramp across it, ``unit_distance``
1/20 of the mesh's bounding-box diagonal -- or, with ``"settings": {"optics": "vtk"}`` (VTK
parity), ParaView's default, the diagonal over the cube root of the cell count (also
asked for by ``"unit_distance": "paraview"``, in either form). ``"log_scale": true`` (either
form) interpolates colour and opacity in log10 of the scalar, as ParaView's "Use Log Scale"
(:meth:`~tetvr.optics.transfer.TransferFunction.log_scaled`). :meth:`Scene.to_dict` writes the
resolved, explicit form. A ParaView state file (``.pvsm``) loads as a scene too
(:mod:`tetvr.scene.paraview`).
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from tetvr.core.camera import Camera, reset_clipping_range
from tetvr.core.checks import warn
from tetvr.core.image import DEFAULT_BACKGROUND, atomic_output, image_size
from tetvr.core.outputs import check_outputs, check_writable
from tetvr.mesh.tetmesh import TetMesh
from tetvr.io.meshfile import read
from tetvr.optics.table import check_unit_distance
from tetvr.render import default_transfer_function
from tetvr.core.clip import Clip
from tetvr.settings import RenderSettings
from tetvr.core.surface import Surface
from tetvr.optics.transfer import TransferFunction

__all__ = ["Scene", "demo_scene_path"]

_KEYS = {"mesh", "scalars", "component", "transfer_function", "camera", "size", "background", "settings", "clip",
         "surfaces"}
_SURFACE_KEYS = {"path", "color", "ambient", "smooth"}


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    """A resolved scene: the mesh is loaded and every parameter is explicit."""

    mesh_path: str
    mesh: TetMesh
    tf: TransferFunction
    camera: Camera
    size: tuple[int, int] = (512, 512)
    background: tuple[float, float, float] = DEFAULT_BACKGROUND
    settings: RenderSettings = RenderSettings()
    scalars: str | None = None
    component: int | None = None
    #: True when the transfer function's unit distance came from tetvr's default rule (the
    #: scene left it null): :func:`tetvr.apps.vtkcompare.compare` then uses ParaView's default.
    unit_distance_default: bool = False
    #: Keep only this part of the mesh (:class:`tetvr.Clip`).
    clip: Clip | None = None
    #: Opaque surfaces inside the mesh, and the files they were read from.
    surfaces: tuple[Surface, ...] = ()
    surface_specs: tuple[dict[str, Any], ...] = ()
    #: The ``Camera.fit`` options of a fitted camera (``"camera": {"fit": {...}}``), None for
    #: an explicit one: a picture with another shape (a legend beside the render, an outline
    #: to keep in view) fits it again (:func:`tetvr.apps.annotate.frame`).
    camera_fit: dict[str, Any] | None = None

    @property
    def render_options(self) -> dict[str, Any]:
        """``clip`` and ``surfaces`` for :func:`tetvr.render` / ``Renderer.render``, where set."""
        out: dict[str, Any] = {}
        if self.clip is not None:
            out["clip"] = self.clip
        if self.surfaces:
            out["surfaces"] = self.surfaces
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any], base_dir: str | os.PathLike[str] = ".") -> "Scene":
        if not isinstance(data, dict):
            raise ValueError(f"a scene must be a JSON object, got {type(data).__name__}")
        unknown = set(data) - _KEYS
        if unknown:
            raise ValueError(f"unknown scene keys {sorted(unknown)}; allowed: {sorted(_KEYS)}")
        if "mesh" not in data:
            raise ValueError("the scene has no 'mesh' key (the path of the mesh file)")
        if not isinstance(data["mesh"], str) or not data["mesh"]:
            raise ValueError(f"scene 'mesh' must be the path of a mesh file (a string), got {data['mesh']!r}")
        scalars = data.get("scalars")
        if scalars is not None and not isinstance(scalars, str):
            raise ValueError(f"scene 'scalars' must be a field name or null, got {scalars!r}")
        component = data.get("component")
        if component is not None and (isinstance(component, bool) or not isinstance(component, int)):
            raise ValueError(f"scene 'component' must be an integer or null, got {component!r}")
        # The cheap checks come before the mesh is read.
        size = _int_pair(data.get("size", [512, 512]))
        bg = _background(data.get("background", list(DEFAULT_BACKGROUND)))
        settings_spec = data.get("settings", {})
        if not isinstance(settings_spec, dict):
            raise ValueError(f"scene 'settings' must be an object of RenderSettings fields, got {settings_spec!r}")
        settings = RenderSettings.from_dict(settings_spec)
        clip = Clip.from_dict(data["clip"]) if data.get("clip") is not None else None
        specs = _surface_specs(data.get("surfaces", []), base_dir)
        path = Path(base_dir) / data["mesh"]
        mesh = read(path, scalars, component=component)
        tf_spec = data.get("transfer_function", {"preset": "viridis"})
        tf = _transfer_function(tf_spec, mesh, settings)
        camera_spec = data.get("camera", {"fit": {}})
        camera = _camera(camera_spec, mesh)
        camera_fit = dict(camera_spec["fit"]) if "fit" in camera_spec else None  # _camera checked it
        defaulted = isinstance(tf_spec, dict) and "preset" in tf_spec and tf_spec.get("unit_distance") is None \
            and settings.optics != "vtk"
        return cls(mesh_path=str(path), mesh=mesh, tf=tf, camera=camera, size=size,  # type: ignore[arg-type]
                   background=bg, settings=settings, scalars=mesh.scalar_name, component=component,  # type: ignore[arg-type]
                   unit_distance_default=defaulted, clip=clip,
                   surfaces=tuple(Surface.read(sp["path"], **{k: v for k, v in sp.items() if k != "path"})
                                  for sp in specs),
                   surface_specs=specs, camera_fit=camera_fit)

    def to_dict(self, relative_to: str | os.PathLike[str] | None = None) -> dict[str, Any]:
        mesh_path = self.mesh_path if relative_to is None else os.path.relpath(self.mesh_path, relative_to)
        return {
            "mesh": mesh_path,
            "scalars": self.scalars,
            "component": self.component,
            "transfer_function": self.tf.to_dict(),
            "camera": self.camera.to_dict(),
            "size": list(self.size),
            "background": list(self.background),
            "settings": self.settings.to_dict(),
            **({"clip": self.clip.to_dict()} if self.clip is not None else {}),
            **({"surfaces": [dict(sp, path=sp["path"] if relative_to is None else os.path.relpath(sp["path"], relative_to))
                             for sp in self.surface_specs]} if self.surface_specs else {}),
        }

    def input_paths(self) -> tuple[str, ...]:
        """The files this scene was read from besides its JSON (the mesh): what a command
        rendering it must not write over."""
        return (self.mesh_path, *(sp["path"] for sp in self.surface_specs))

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the scene as JSON (atomically; never over its own mesh or surface files)."""
        check_outputs([("scene", path)], [("mesh file", self.mesh_path)]
                      + [("surface file", sp["path"]) for sp in self.surface_specs], by="the scene")
        check_writable(path, "scene")
        text = json.dumps(self.to_dict(relative_to=Path(path).resolve().parent), indent=2)
        with atomic_output(path) as f:
            f.write(text.encode("utf-8"))
        unsaved = len(self.surfaces) - len(self.surface_specs)
        if unsaved > 0:  # a ParaView state's sphere, box or outline: made in memory, read from no file
            warn(f"{os.fspath(path)}: {unsaved} of the scene's surfaces came from no file (a ParaView state's "
                 "spheres, boxes, outlines) and are not in the saved scene, which names surface files")


def _surface_specs(value: Any, base_dir: str | os.PathLike[str]) -> tuple[dict[str, Any], ...]:
    """The scene's "surfaces": a list of {"path", "color", "ambient", "smooth"} (path required),
    paths made relative to the current directory."""
    if not isinstance(value, list):
        raise ValueError(f"scene 'surfaces' must be a list of objects with a 'path', got {value!r}")
    out = []
    for i, spec in enumerate(value):
        if not isinstance(spec, dict) or not isinstance(spec.get("path"), str):
            raise ValueError(f"scene 'surfaces'[{i}] must be an object with a 'path' (a surface file), got {spec!r}")
        unknown = set(spec) - _SURFACE_KEYS
        if unknown:
            raise ValueError(f"unknown keys {sorted(unknown)} in scene 'surfaces'[{i}]; allowed: {sorted(_SURFACE_KEYS)}")
        sp = dict(spec, path=str(Path(base_dir) / spec["path"]))
        if "color" in sp:
            sp["color"] = tuple(sp["color"])
        out.append(sp)
    return tuple(out)


def _int_pair(value: Any) -> tuple[int, int]:
    try:
        return image_size(value)
    except ValueError:
        raise ValueError(f"scene 'size' must be [width, height], two positive integers, got {value!r}") from None


def _background(value: Any) -> tuple[float, float, float]:
    try:
        bg = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        bg = np.zeros(0)
    if isinstance(value, str) or bg.shape != (3,) or not np.all((bg >= 0) & (bg <= 1)):
        raise ValueError(f"scene 'background' must be [r, g, b] with components in [0, 1], got {value!r}")
    return float(bg[0]), float(bg[1]), float(bg[2])


def _transfer_function(spec: dict[str, Any], mesh: TetMesh, settings: RenderSettings | None = None) -> TransferFunction:
    if not isinstance(spec, dict):
        raise ValueError(f"transfer_function must be an object, got {spec!r}")
    spec = dict(spec)
    log_scale = spec.pop("log_scale", False)
    if not isinstance(log_scale, bool):
        raise ValueError(f"transfer_function 'log_scale' must be true or false, got {log_scale!r}")
    # ParaView's default unit distance: asked for by name, or implied by VTK parity (optics "vtk").
    if spec.get("unit_distance") == "paraview" or (
            "preset" in spec and spec.get("unit_distance") is None and settings is not None and settings.optics == "vtk"):
        from tetvr.optics.transfer import paraview_unit_distance

        spec["unit_distance"] = paraview_unit_distance(mesh.bounds, mesh.n_tets)
    tf = _tf_from_spec(spec, mesh)
    return tf.log_scaled() if log_scale else tf


def _tf_from_spec(spec: dict[str, Any], mesh: TetMesh) -> TransferFunction:
    if "preset" not in spec:
        tf = TransferFunction.from_dict(spec)
        check_unit_distance(tf.unit_distance, "transfer_function 'unit_distance'")
        return tf
    unknown = set(spec) - {"preset", "range", "opacity", "unit_distance"}
    if unknown:
        raise ValueError(f"unknown transfer_function keys {sorted(unknown)}")
    rng = spec.get("range")
    if rng is not None and not (isinstance(rng, (list, tuple)) and len(rng) == 2):
        raise ValueError(f"transfer_function 'range' must be [lo, hi] or null, got {rng!r}")
    if not isinstance(spec["preset"], str):
        raise ValueError(f"transfer_function 'preset' must be a colour-map name, got {spec['preset']!r}")
    # null (or absent) takes the default rule's part (tetvr.optics.transfer); 0 is not "unset".
    tf = default_transfer_function(mesh, preset=spec["preset"], opacity=spec.get("opacity"),
                                   scalar_range=None if rng is None else tuple(rng), unit_distance=spec.get("unit_distance"))
    check_unit_distance(tf.unit_distance, "transfer_function 'unit_distance'")
    return tf


#: The camera's fields (explicit or "fit") that are lists of numbers, and how many.
_CAMERA_VECTORS = {"position": 3, "focal_point": 3, "view_up": 3, "direction": 3, "clipping_range": 2}
_CAMERA_NUMBERS = {"view_angle", "parallel_scale", "zoom"}


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _camera_values(spec: dict[str, Any], where: str) -> None:
    """``ValueError`` naming the key for a camera field that is not a number, or not a
    list of them, as JSON writes them: ``"0"`` and ``true`` are not numbers here."""
    for key, value in spec.items():
        n = _CAMERA_VECTORS.get(key)
        if n is not None and not (where == "camera.fit" and key == "view_up" and value is None):
            if not (isinstance(value, (list, tuple)) and len(value) == n and all(_is_number(v) for v in value)):
                raise ValueError(f"scene {where} {key!r} must be a list of {n} numbers such as "
                                 f"{[0] * n}, got {value!r}")
        elif key in _CAMERA_NUMBERS and not _is_number(value):
            raise ValueError(f"scene {where} {key!r} must be a number, got {value!r}")


def _camera(spec: dict[str, Any], mesh: TetMesh) -> Camera:
    if not isinstance(spec, dict):
        raise ValueError(f"camera must be an object, got {spec!r}")
    _camera_values(spec, "camera")
    if "fit" in spec:
        if set(spec) != {"fit"}:
            raise ValueError(f"a fitted camera takes only 'fit', got keys {sorted(spec)}")
        if not isinstance(spec["fit"], dict):
            raise ValueError(f"camera 'fit' must be an object of Camera.fit options, got {spec['fit']!r}")
        fit = dict(spec["fit"])
        _camera_values(fit, "camera.fit")
        allowed = {"direction", "view_up", "view_angle", "parallel", "zoom"}
        unknown = set(fit) - allowed
        if unknown:
            raise ValueError(f"unknown camera.fit keys {sorted(unknown)}; allowed: {sorted(allowed)}")
        return Camera.fit(mesh, **fit)
    camera = Camera.from_dict(spec)
    if "clipping_range" not in spec:  # as ParaView: computed from the data (a state stores none)
        camera = reset_clipping_range(camera, mesh.bounds)
    return camera


def demo_scene_path() -> Path:
    """The bundled demo scene (``meshes/demo.json``)."""
    here = Path(__file__).resolve().parents[1]  # the tetvr package
    for candidate in (here / "meshes", here.parent / "meshes"):
        if (candidate / "demo.json").is_file():
            return candidate / "demo.json"
    raise FileNotFoundError("the bundled demo scene (meshes/demo.json) is missing from this installation")



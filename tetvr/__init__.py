"""tetvr: translucent volume rendering of tetrahedral meshes by projected tetrahedra.

The pipeline, one module per stage: :mod:`~tetvr.mesh` -> classification (GPU,
``shaders/classify.comp``) -> :mod:`~tetvr.sort` -> :mod:`~tetvr.preintegrate` ->
rasterisation (:mod:`tetvr.gl`) -> image. :mod:`~tetvr.reference` is the exact CPU
renderer every image is measured against. Nothing here imports OpenGL until a GPU
renderer is made. :func:`plot` renders and labels a picture in one call (:mod:`~tetvr.annotate`).
"""

from .annotate import Picture, plot, show
from .camera import Camera
from .clip import Clip
from .image import psnr, rmse, write_png
from .mesh import MeshReport, TetMesh, read
from .render import render
from .scene import Scene, demo_scene_path, load_scene
from .settings import RenderSettings
from .surface import Surface
from .transfer import PRESETS, TransferFunction
from .volume import Volume, read_volume
from .raycast_reference import RaycastSettings
from .fuse import FUSION_MODES, RayTextures, fuse

__version__ = "0.1.0"

__all__ = [
    "Camera",
    "Clip",
    "Picture",
    "MeshReport",
    "PRESETS",
    "RenderSettings",
    "TetMesh",
    "TransferFunction",
    "FUSION_MODES",
    "RayTextures",
    "RaycastSettings",
    "Raycaster",
    "Renderer",
    "Volume",
    "fuse",
    "read_volume",
    "Scene",
    "Surface",
    "demo_scene_path",
    "load_scene",
    "plot",
    "show",
    "psnr",
    "read",
    "render",
    "rmse",
    "write_png",
    "__version__",
]


def __getattr__(name: str):
    # The GL renderer is imported on first use, so `import tetvr` needs no OpenGL.
    if name == "Renderer":
        from .gl.renderer import Renderer

        return Renderer
    if name == "Raycaster":
        from .gl.raycaster import Raycaster

        return Raycaster
    raise AttributeError(f"module 'tetvr' has no attribute {name!r}")

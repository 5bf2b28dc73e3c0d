"""tetvr: translucent volume rendering of tetrahedral meshes on the GPU, measured against an
exact CPU reference.

One package per stage, each importing only those below it (docs/architecture.md):
:mod:`tetvr.io` reads files into :mod:`tetvr.mesh` and :mod:`tetvr.volume` objects;
:mod:`tetvr.optics` holds the optical model and its tables; :mod:`tetvr.order` decides on
the CPU what a frame draws and in which order; :mod:`tetvr.gl` draws it (tet marching or
projected tetrahedra, and the volume ray caster); :mod:`tetvr.reference` is the exact CPU
renderer every image is measured against. :func:`render` and :func:`fuse` are the one-call
facade; :mod:`tetvr.scene`, :mod:`tetvr.cluster` and :mod:`tetvr.apps` sit on top. Nothing
here imports OpenGL until a GPU renderer is made. :func:`plot` renders and labels a picture
in one call.
"""

from tetvr.apps.annotate import Picture, plot, show
from tetvr.core.camera import Camera
from tetvr.core.clip import Clip
from tetvr.core.image import psnr, rmse, write_png
from tetvr.mesh.tetmesh import MeshReport, TetMesh
from tetvr.io.meshfile import read
from tetvr.render import render
from tetvr.scene.scene import Scene, demo_scene_path
from tetvr.scene.load import load_scene
from tetvr.settings import RenderSettings
from tetvr.core.surface import Surface
from tetvr.optics.transfer import PRESETS, TransferFunction
from tetvr.volume.volume import Volume
from tetvr.io.volume_file import read_volume
from tetvr.reference.volume import RaycastSettings
from tetvr.fuse import FUSION_MODES, RayTextures, fuse

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
    "Viewer",
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
        from tetvr.gl.renderer import Renderer

        return Renderer
    if name == "Raycaster":
        from tetvr.gl.raycaster import Raycaster

        return Raycaster
    if name == "Viewer":  # the Jupyter viewer imports ipywidgets and jupyter_rfb
        from tetvr.apps.viewer.jupyter import Viewer

        return Viewer
    raise AttributeError(f"module 'tetvr' has no attribute {name!r}")

"""tetvr: translucent volume rendering of tetrahedral meshes by projected tetrahedra.

The pipeline, one module per stage: :mod:`~tetvr.mesh` -> classification (GPU,
``shaders/classify.comp``) -> :mod:`~tetvr.sort` -> :mod:`~tetvr.preintegrate` ->
rasterisation (:mod:`tetvr.gl`) -> image. :mod:`~tetvr.reference` is the exact CPU
renderer every image is measured against. Nothing here imports OpenGL until a GPU
renderer is made.
"""

from .camera import Camera
from .mesh import MeshReport, TetMesh, read
from .settings import RenderSettings
from .transfer import PRESETS, TransferFunction

__version__ = "0.1.0"

__all__ = [
    "Camera",
    "MeshReport",
    "PRESETS",
    "RenderSettings",
    "TetMesh",
    "TransferFunction",
    "read",
    "__version__",
]

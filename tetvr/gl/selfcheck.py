"""A tet-marching frame's check of itself: the pixels whose walk went wrong, traced again.

Every march pass checks its own walk (``shaders/march.frag``): a ray that reaches the step
bound, finds no face ahead of it, or leaves a tet behind where it entered it has not
followed the mesh, whatever the cause (a mesh defect the checks at read did not see, a
rounding case no test has met). The pass counts such rays and lists their pixels
(:attr:`tetvr.gl.raymarch.MarchStats.n_suspect`); :func:`retrace` then renders those pixels
by the exact CPU reference (:func:`tetvr.reference.tets.render_reference_pixels`) and puts
them in the image, so that the frame is right and says how many it traced. A clean mesh
gives none (``tests/test_selfcheck.py``); where more rays went wrong than the pass lists,
the rest stay as drawn and a warning says so. The ray limits fusion reads
(:func:`retrace_extent`) are checked and traced again the same way.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera
from tetvr.core.checks import warn
from tetvr.core.clip import Clip
from tetvr.core.surface import Surface
from tetvr.gl import march_layout
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.transfer import TransferFunction

__all__ = ["retrace", "retrace_extent"]


def retrace(image: NDArray[np.float32], n_suspect: int, suspect_pixels: NDArray[np.int64], mesh: TetMesh,
            camera: Camera, tf: TransferFunction, *, optics: str, clip: Clip | None,
            surfaces: Sequence[Surface]) -> int:
    """Replace, in ``image`` ((height, width, 4), row 0 at the top), the pixels a march
    listed as gone wrong (``suspect_pixels``: GL rows, row 0 at the bottom) by the
    reference's values for them; returns how many it traced. Warns where the march counted
    more rays (``n_suspect``, each once a pass) than its list holds."""
    if n_suspect == 0 or suspect_pixels.size == 0:
        return 0
    from tetvr.reference.tets import render_reference_pixels  # only when a walk went wrong

    height, width = image.shape[:2]
    rows, cols = suspect_pixels // width, suspect_pixels % width
    pixels = (height - 1 - rows) * width + cols
    values = render_reference_pixels(mesh, camera, tf, (width, height), pixels, optics=optics, clip=clip,
                                     surfaces=tuple(surfaces))
    image.reshape(-1, 4)[pixels] = values
    if n_suspect > march_layout.SUSPECT_LENGTH:  # the list was full: not every such ray is in it
        warn(f"the ray caster's walk went wrong on {n_suspect} rays of this {width}x{height} frame and "
             f"{pixels.size} were traced again exactly; the others may be wrong: render with "
             f"method=\"projected\", or method=\"reference\" for an exact image")
    return int(pixels.size)


def retrace_extent(extent: NDArray[np.float32], n_suspect: int, suspect_pixels: NDArray[np.int64], mesh: TetMesh,
                   camera: Camera) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """The ray limits of a march's extent frame (``extent``: (height, width, 4), row 0 at
    the top, first entry and last exit depth, 3e38 / -3e38 where none) as ``(front, back)``
    with ``inf`` / ``-inf`` where no tet covers the pixel, the pixels the march listed as gone
    wrong (``suspect_pixels``: GL rows) taken from the reference
    (:func:`tetvr.reference.segments.pixel_extents`)."""
    front = np.where(extent[..., 0] >= 3e38, np.inf, extent[..., 0]).astype(np.float32)
    back = np.where(extent[..., 1] <= -3e38, -np.inf, extent[..., 1]).astype(np.float32)
    if n_suspect == 0 or suspect_pixels.size == 0:
        return front, back
    from tetvr.reference.segments import pixel_extents  # only when a walk went wrong

    height, width = front.shape
    pixels = (height - 1 - suspect_pixels // width) * width + suspect_pixels % width
    f, b = pixel_extents(mesh, camera, (width, height), pixels)
    front.reshape(-1)[pixels], back.reshape(-1)[pixels] = f, b
    if n_suspect > march_layout.SUSPECT_LENGTH:
        warn(f"the ray caster's walk went wrong on {n_suspect} rays of this {width}x{height} frame of ray limits "
             f"and {pixels.size} were traced again exactly; the others may be wrong")
    return front, back

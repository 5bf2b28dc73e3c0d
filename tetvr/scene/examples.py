"""Example scenes built from the bundled data: the demo scenes of the CLI and notebooks.

``carotid_fusion`` is the fusion demo: VTK's carotid-artery flow data (BSD-3, bundled as
``meshes/carotid.vtk``) serves both as the image volume and, cut where the flow speed is
above a threshold, as a tetrahedral "simulation" mesh of the vessel lumen that lines up
with it exactly — the situation of a CFD result computed on the vessels of a CT.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tetvr.core.camera import Camera
from tetvr.mesh.tetmesh import TetMesh
from tetvr.mesh.synthetic import _KUHN
from tetvr.optics.transfer import TransferFunction
from tetvr.volume.volume import Volume
from tetvr.io.volume_file import read_volume

__all__ = ["image_cells_to_tets", "carotid_fusion", "FusionScene", "bundled"]


def bundled(name: str) -> Path:
    """Path of a file in the bundled ``meshes/`` folder."""
    here = Path(__file__).resolve().parents[1]  # the tetvr package
    for folder in (here / "meshes", here.parent / "meshes"):
        if (folder / name).is_file():
            return folder / name
    raise FileNotFoundError(f"bundled file {name!r} is missing from this installation")


def image_cells_to_tets(volume: Volume, mask: NDArray[np.bool_]) -> TetMesh:
    """Tetrahedra of the image cells (between 8 voxel centres) whose 8 corners are in ``mask``.

    Each cell is split into the 6 Kuhn tets around the same diagonal, so neighbouring
    cells' split faces agree (no cracks). Points are the voxel centres in world
    coordinates, carrying the voxel values: the mesh lines up with the volume exactly.
    """
    data = volume.data
    if mask.shape != data.shape:
        raise ValueError(f"mask must have the volume's shape {data.shape}, got {mask.shape}")
    nz, ny, nx = data.shape
    m = mask
    cell = m[:-1, :-1, :-1] & m[:-1, :-1, 1:] & m[:-1, 1:, :-1] & m[:-1, 1:, 1:] \
        & m[1:, :-1, :-1] & m[1:, :-1, 1:] & m[1:, 1:, :-1] & m[1:, 1:, 1:]
    k, j, i = np.nonzero(cell)
    if k.size == 0:
        raise ValueError("no image cell has all 8 corners inside the mask")
    idx = np.arange(data.size).reshape(nz, ny, nx)
    corners = np.stack([idx[k + (c >> 2 & 1), j + (c >> 1 & 1), i + (c & 1)] for c in range(8)], axis=1)
    tets = corners[:, _KUHN].reshape(-1, 4)
    used, inverse = np.unique(tets, return_inverse=True)
    kk, jj, ii = np.unravel_index(used, data.shape)
    ijk1 = np.stack([ii, jj, kk, np.ones_like(ii)], axis=1).astype(np.float64)
    pts = (ijk1 @ volume.index_to_world.T)[:, :3]
    return TetMesh.from_arrays(pts, inverse.reshape(-1, 4), data.reshape(-1)[used].astype(np.float64),
                               scalar_name=volume.scalar_name or "scalars")


@dataclasses.dataclass(frozen=True, eq=False)
class FusionScene:
    volume: Volume
    mesh: TetMesh
    camera: Camera
    volume_tf: TransferFunction
    mesh_tf: TransferFunction
    #: The scene's own background: its near-white vessels are drawn for black, as a
    #: radiology viewer shows angiography (other pictures use ``image.DEFAULT_BACKGROUND``).
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)


def carotid_fusion(threshold: float = 175.0) -> FusionScene:
    """The carotid flow as a faint "angiography" volume, with a tet mesh of the lumen
    where speed exceeds ``threshold``, coloured by speed."""
    volume = read_volume(bundled("carotid.vtk"))
    # Compared in float64: float32 data against a Python float compares in float32 (NEP 50),
    # which moves the cut for thresholds that float32 cannot hold.
    data = np.asarray(volume.data, dtype=np.float64)
    mesh = image_cells_to_tets(volume, data > threshold)
    hi = float(np.percentile(mesh.scalars, 99))
    mesh_tf = TransferFunction.preset("hot", (threshold, hi), opacity=[(0.0, 0.05), (0.5, 0.4), (1.0, 0.9)],
                                      unit_distance=4.0)
    volume_tf = TransferFunction(color=((0.0, 0.5, 0.6, 0.8), (threshold, 0.85, 0.9, 1.0), (580.0, 1.0, 1.0, 1.0)),
                                 opacity=((0.0, 0.0), (135.0, 0.0), (threshold, 0.35), (580.0, 0.6)),
                                 unit_distance=3.0)
    cam = Camera.fit(mesh, direction=(-0.3, 1.0, -0.35), view_up=(0, 0, 1), zoom=1.05)
    lo, hi_b = volume.bounds
    radius = 0.5 * float(np.linalg.norm(hi_b - lo))
    dist = float(np.linalg.norm(np.subtract(cam.position, cam.focal_point)))
    cam = dataclasses.replace(cam, clipping_range=(max(dist - radius * 1.1, dist * 1e-3), dist + radius * 1.1))
    return FusionScene(volume, mesh, cam, volume_tf, mesh_tf)

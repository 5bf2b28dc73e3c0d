"""The peers bench/speed_accuracy.py measures tetvr against, in the same run: VTK's three
unstructured-grid volume mappers (the ones ParaView offers for a tetrahedral mesh) and real
ParaView where it is installed.

* ``vtk_pt``: ``vtkProjectedTetrahedraMapper``, ParaView's "Projected tetra" (Shirley &
  Tuchman 1990 with Wylie et al.'s 2002 thick vertex; cells sorted by centroid depth);
* ``vtk_bunyk``: ``vtkUnstructuredGridVolumeRayCastMapper``, "Bunyk ray cast" (Bunyk,
  Kaufman & Silva 1997 on the CPU, pre-integrated);
* ``vtk_zsweep``: ``vtkUnstructuredGridVolumeZSweepMapper``, "Z sweep" (Farias, Mitchell &
  Silva 2000, pre-integrated).

Each runs in a child process (:class:`tetvr.apps.vtkrender.VTKProcess`: VTK's EGL window and
tetvr's moderngl context cannot share a process) on the same OpenGL as tetvr. A frame is
timed inside the child, from the camera change to the image read back into numpy, as
tetvr's frames are, as wall time and as the child's CPU time (llvmpipe's and the mapper's
threads included).
"""

from __future__ import annotations

import importlib.util
import math
import shutil
import subprocess
from typing import Any

import numpy as np

from tetvr import Camera, TetMesh, TransferFunction
from tetvr.apps.vtkrender import MAPPERS, VTKProcess, VTKUnavailableError, vtk_status

#: The peers, by key: the mapper key of :data:`tetvr.apps.vtkrender.MAPPERS`.
PEERS: dict[str, str] = {"vtk_pt": "pt", "vtk_bunyk": "bunyk", "vtk_zsweep": "zsweep"}
#: How the charts and tables name them.
LABELS: dict[str, str] = {"vtk_pt": "VTK projected tetrahedra", "vtk_bunyk": "VTK Bunyk ray cast",
                          "vtk_zsweep": "VTK Z sweep"}
#: Seconds to wait for any one reply of a VTK process (a Z sweep of 200k tets at 512x512
#: takes minutes on two cores) ...
TIMEOUT_S = 900.0
#: ... and for one small image of a failure case (VTK's ray caster can loop for many
#: minutes on an eye exactly in a face's plane; such a frame counts as failed).
SMALL_TIMEOUT_S = 300.0
#: What a failed frame or refused input raises.
FAILURES = (RuntimeError, ValueError, OSError, VTKUnavailableError)


class VtkPeer:
    """One VTK mapper in its child process, rendering one mesh view after view.

    :attr:`last_wall` is the last frame's wall time inside the child (camera change to numpy
    image), :attr:`last_cpu` the child's CPU time over it (all its threads), :attr:`first_s`
    the first frame's wall time from the window's creation on.
    """

    def __init__(self, key: str, mesh: TetMesh, tf: TransferFunction, size: tuple[int, int],
                 timeout: float = TIMEOUT_S) -> None:
        self.key = key
        self.process = VTKProcess(mesh, tf, mapper=PEERS[key], size=size, timeout=timeout)
        self.last_wall = self.last_cpu = math.nan

    @property
    def first_s(self) -> float:
        return self.process.first_seconds

    @property
    def info(self) -> dict[str, Any]:
        return {"class": MAPPERS[PEERS[self.key]][0], "paraview_name": MAPPERS[PEERS[self.key]][1],
                **{k: v for k, v in self.process.info.items() if k in ("mapper_class", "version", "window")}}

    def frame(self, camera: Camera) -> np.ndarray:
        image = self.process.render(camera)
        self.last_wall = self.process.last_seconds
        self.last_cpu = self.process.info.get("cpu_seconds", math.nan)
        return image

    def release(self) -> None:
        self.process.release()


def open_peers(mesh: TetMesh, tf: TransferFunction, size: tuple[int, int],
               keys: tuple[str, ...] = tuple(PEERS)) -> tuple[dict[str, VtkPeer], dict[str, str]]:
    """A :class:`VtkPeer` per key, and for each one that could not start, why."""
    peers: dict[str, VtkPeer] = {}
    failed: dict[str, str] = {}
    for key in keys:
        try:
            peers[key] = VtkPeer(key, mesh, tf, size)
        except FAILURES as exc:
            failed[key] = f"{type(exc).__name__}: {exc}"
    return peers, failed


def peer_images(mesh: TetMesh, tf: TransferFunction, cameras: list[Camera], size: tuple[int, int],
                timeout: float = SMALL_TIMEOUT_S) -> dict[str, list[np.ndarray | str]]:
    """Every peer's image of each camera, or why it gave none (a failed frame ends the VTK
    process, so the next camera starts a new one; ``timeout``: seconds for any one frame)."""
    out: dict[str, list[np.ndarray | str]] = {}
    for key in PEERS:
        out[key] = []
        peer: VtkPeer | None = None
        for camera in cameras:
            try:
                if peer is None:
                    peer = VtkPeer(key, mesh, tf, size, timeout)
                out[key].append(peer.frame(camera))
            except FAILURES as exc:
                out[key].append(f"{type(exc).__name__}: {exc}")
                if peer is not None:
                    peer.release()
                peer = None
        if peer is not None:
            peer.release()
    return out


def vtk_available() -> tuple[bool, str]:
    """Whether VTK renders offscreen here, and what it is (:func:`tetvr.apps.vtkrender.vtk_status`)."""
    return vtk_status()


def paraview_status() -> dict[str, Any]:
    """Whether real ParaView is installed here (``pvbatch`` or ``pvpython`` on the PATH, or
    the ``paraview`` Python package), and what it is; where it is not, why it was skipped."""
    found = {name: shutil.which(name) for name in ("pvbatch", "pvpython")}
    module = importlib.util.find_spec("paraview") is not None
    if not any(found.values()) and not module:
        return {"available": False, "measured": False,
                "reason": "ParaView is not installed here (no pvbatch or pvpython on the PATH, no paraview Python "
                          "module), so it was skipped; its volume mappers for unstructured grids are the VTK classes "
                          "measured as vtk_pt, vtk_bunyk and vtk_zsweep"}
    exe = found["pvbatch"] or found["pvpython"]
    version = ""
    if exe:
        try:
            version = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=60).stdout.strip()
        except (OSError, subprocess.SubprocessError) as exc:
            version = f"--version failed: {exc}"
    return {"available": True, "measured": False,
            "reason": f"ParaView is installed ({exe or 'paraview module'} {version}) but this script does not drive "
                      "it: its unstructured-grid volume mappers are the VTK classes measured as vtk_pt, vtk_bunyk "
                      "and vtk_zsweep",
            "found": {k: v for k, v in found.items() if v}}

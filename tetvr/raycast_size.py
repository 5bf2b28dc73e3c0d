"""How finely the volume ray caster samples and how big its table is: the "auto" sizes.

About this technique
--------------------
The GPU ray caster (:mod:`tetvr.gl.raycaster`) samples each ray at regular steps and where
it crosses a voxel-index plane, takes the scalar as linear between two samples, and
looks each piece up in a pre-integration table (Engel, Kraus & Ertl 2001). Against the
exact reference (:mod:`tetvr.raycast_reference`, 1/16-voxel pieces) its error has two
sources, and the "auto" settings size each from the scene, as :mod:`tetvr.tablesize`
does for the tets:

* **The step** (:func:`auto_step`). Inside one voxel cell the trilinear field is a
  cubic along the ray; a piece of length ``h`` voxels taken as linear errs by
  ``h^2/8 |s''|`` in the scalar, which shifts the piece's optical depth by about its
  extinction slope times that, so the error grows with ``h^2`` and with the optical
  depth ``D`` of one voxel at the transfer function's largest extinction over the data.
  The step is ``h = STEP_REF * sqrt(DEPTH_REF / D)`` voxels (smallest spacing), within
  ``STEP_BOUNDS``: measured on the CT head, MR head and aneurism, a step of a quarter
  voxel at ``D`` = 0.8 renders at ~80 dB. Maximum intensity takes ``MIP_STEP``: the
  maximum of the cubic inside a cell falls between samples (at a voxel it is sampled
  exactly, where the ray crosses its planes). The other modes keep half a voxel.
* **The table's scalar bins** (:func:`auto_bins`). Between two of its N nodes the table
  takes the transfer function as linear; control points between nodes are smoothed
  (with aligned nodes, :func:`tetvr.preintegrate.aligned_scalar_range`, those on round
  values sit on nodes). :func:`tetvr.tablesize.scalar_axis_error` measures that error
  for constant-scalar slabs ``SLAB_VOXELS`` voxels long at the volume's own values
  (a seeded sample of trilinear points where the transfer function is not transparent);
  the fewest bins of :data:`AUTO_BINS` within ``tolerance`` win, else the most.
  Above 512 bins a table takes seconds and ~1 GiB to build, on every
  transfer-function change, so "auto" stops there; a scene may name more.

Both decisions are cached per (volume, transfer function).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .optics import extinction
from .preintegrate import aligned_scalar_range, table_scalar_range
from .tablesize import SegmentSample, scalar_axis_error
from .transfer import TransferFunction
from .volume import Volume

__all__ = ["auto_step", "auto_bins", "voxel_depth", "AUTO_BINS", "STEP_BOUNDS", "MIP_STEP", "DEFAULT_TOLERANCE"]

#: Step (voxels of the smallest spacing) at the reference optical depth per voxel.
STEP_REF = 0.25
DEPTH_REF = 0.8
#: The emission-absorption step stays within these (voxels).
STEP_BOUNDS = (0.125, 0.5)
#: Maximum intensity's step (voxels); xray and isosurface keep half a voxel.
MIP_STEP = 0.25
OTHER_STEP = 0.5
#: Candidate scalar bins of an "auto" table (with the settings' thickness slices).
AUTO_BINS = (256, 512)
#: RMS error of a constant slab the "auto" bins aim for (premultiplied RGBA).
DEFAULT_TOLERANCE = 2e-4
#: Length of those slabs in voxels (a feature a ray crosses), and how many points.
SLAB_VOXELS = 8.0
_N_POINTS = 4096


def voxel_depth(volume: Volume, tf: TransferFunction) -> float:
    """Optical depth of one voxel (smallest spacing) at the transfer function's largest
    extinction over the volume's data range."""
    lo, hi = volume.scalar_range
    s = np.union1d(np.linspace(lo, hi, 1025), np.clip(tf.breakpoints, lo, hi))
    _, a = tf.evaluate(s)
    return float(extinction(a, tf.unit_distance).max()) * float(volume.spacing.min())


def auto_step(volume: Volume, tf: TransferFunction, mode: str) -> float:
    """The "auto" step in world units for ``mode`` (see the module notes).

    Examples
    --------
    >>> vol = Volume.from_array(np.linspace(0, 1, 27).reshape(3, 3, 3), spacing=(2, 2, 2))
    >>> tf = TransferFunction.preset("grayscale", (0, 1), opacity=0.5, unit_distance=10.0)
    >>> round(auto_step(vol, tf, "emission_absorption"), 4)  # depth 0.139 per voxel: half a voxel
    1.0
    >>> auto_step(vol, tf, "mip")
    0.5
    """
    h = float(volume.spacing.min())
    if mode == "emission_absorption":
        depth = voxel_depth(volume, tf)
        f = STEP_REF * math.sqrt(DEPTH_REF / depth) if depth > 0 else STEP_BOUNDS[1]
        return h * min(max(f, STEP_BOUNDS[0]), STEP_BOUNDS[1])
    return h * (MIP_STEP if mode == "mip" else OTHER_STEP)


def _visible_values(volume: Volume, tf: TransferFunction, n: int = _N_POINTS) -> np.ndarray:
    """Up to ``n`` field values at seeded random points where the opacity is not 0 (all
    the points if none is)."""
    rng = np.random.default_rng(0)
    hi = np.asarray(volume.dims, dtype=np.float64) - 1.0
    values = volume.sample_index(rng.uniform(0.0, 1.0, (16 * n, 3)) * hi)
    _, a = tf.evaluate(values)
    seen = values[a > 0]
    return (seen if seen.size else values)[:n]


def auto_bins(volume: Volume, tf: TransferFunction, *, tolerance: float = DEFAULT_TOLERANCE) -> int:
    """The fewest :data:`AUTO_BINS` whose aligned nodes keep constant slabs at the
    volume's values within ``tolerance`` (see the module notes); else the most."""
    return _bins(volume, tf, float(tolerance))


@functools.lru_cache(maxsize=32)
def _bins(volume: Volume, tf: TransferFunction, tolerance: float) -> int:
    values = _visible_values(volume, tf)
    length = np.full(values.shape, SLAB_VOXELS * float(volume.spacing.min()))
    sample = SegmentSample(front=values, back=values, length=length,
                           weight=np.full(values.shape, 1.0 / values.size))
    rng = table_scalar_range(volume.scalar_range, tf)
    for n in AUTO_BINS:
        if scalar_axis_error(tf, aligned_scalar_range(rng, tf, n), n, sample) <= tolerance:
            return n
    return AUTO_BINS[-1]

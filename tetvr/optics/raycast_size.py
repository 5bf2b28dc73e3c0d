"""How finely the volume ray caster samples and how big its table is: the "auto" sizes.

About this technique
--------------------
The GPU ray caster (:mod:`tetvr.gl.raycaster`) samples each ray at regular steps and where
it crosses a voxel-index plane, takes the scalar as linear between two samples, and
looks each piece up in a pre-integration table (Engel, Kraus & Ertl 2001). Against the
exact reference (:mod:`tetvr.reference.volume`, 1/16-voxel pieces) its error has two
sources, and the "auto" settings size each from the scene, as :mod:`tetvr.optics.tablesize`
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
  (with aligned nodes, :func:`tetvr.optics.table.aligned_scalar_range`, those on round
  values sit on nodes). :func:`tetvr.optics.tablesize.scalar_axis_error` measures that error
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

from tetvr.optics.model import extinction
from tetvr.optics.table import aligned_scalar_range, table_scalar_range
from tetvr.optics.tablesize import SegmentSample, scalar_axis_error
from tetvr.optics.transfer import TransferFunction
from tetvr.volume.volume import Volume

__all__ = ["auto_step", "auto_table", "auto_bins", "auto_integration", "voxel_depth", "feature_voxels", "AUTO_BINS",
           "STEP_BOUNDS", "MIP_STEP", "DEFAULT_TOLERANCE"]

#: Step (voxels of the smallest spacing) at the reference optical depth per voxel.
STEP_REF = 0.25
DEPTH_REF = 0.8
#: The emission-absorption step stays within these (voxels).
STEP_BOUNDS = (0.125, 0.5)
#: ... and at most this times the square root of :func:`feature_voxels`.
STEP_PER_FEATURE = 0.5
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


def feature_voxels(volume: Volume, tf: TransferFunction) -> float:
    """How many voxels a ray takes to cross the transfer function's narrowest opacity
    ramp: the ramp's scalar width over the field's change per voxel where it is seen
    (the upper quartile of neighbour differences at the sample of :func:`_visible_points`)."""
    o = np.asarray(tf.opacity, dtype=np.float64)
    lo, hi = volume.scalar_range
    widths = np.diff(o[:, 0])[(np.diff(o[:, 1]) != 0) & (o[1:, 0] > lo) & (o[:-1, 0] < hi)]
    if widths.size == 0:
        return math.inf
    gradient = _gradient_per_voxel(volume, tf)
    return float(widths.min()) / gradient if gradient > 0 else math.inf


@functools.lru_cache(maxsize=32)
def _gradient_per_voxel(volume: Volume, tf: TransferFunction) -> float:
    p = _visible_points(volume, tf)
    hi = np.asarray(volume.dims, dtype=np.float64) - 1.0
    base = volume.sample_index(p)
    diffs = [np.abs(volume.sample_index(np.minimum(p + e, hi)) - base) for e in np.eye(3)]
    d = np.concatenate(diffs)
    d = d[d > 0]
    return float(np.percentile(d, 75)) if d.size else 0.0


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
        f = min(f, STEP_PER_FEATURE * math.sqrt(feature_voxels(volume, tf)))
        return h * min(max(f, STEP_BOUNDS[0]), STEP_BOUNDS[1])
    return h * (MIP_STEP if mode == "mip" else OTHER_STEP)


def _visible_points(volume: Volume, tf: TransferFunction, n: int = _N_POINTS) -> np.ndarray:
    """Up to ``n`` seeded random index points where the opacity is not 0 (all the
    points if there is none)."""
    rng = np.random.default_rng(0)
    hi = np.asarray(volume.dims, dtype=np.float64) - 1.0
    p = rng.uniform(0.0, 1.0, (16 * n, 3)) * hi
    _, a = tf.evaluate(volume.sample_index(p))
    seen = p[a > 0]
    return (seen if seen.shape[0] else p)[:n]


def auto_table(volume: Volume, tf: TransferFunction, n_bins: int | str = "auto", *,
               tolerance: float = DEFAULT_TOLERANCE) -> tuple[int, float]:
    """The fewest bins (of :data:`AUTO_BINS`, or ``n_bins`` if given) whose aligned nodes
    keep constant slabs at the volume's values within ``tolerance`` (else the most), and
    that estimate (see the module notes)."""
    candidates = AUTO_BINS if n_bins == "auto" else (int(n_bins),)
    return _table(volume, tf, candidates, float(tolerance))


def auto_bins(volume: Volume, tf: TransferFunction, *, tolerance: float = DEFAULT_TOLERANCE) -> int:
    """:func:`auto_table`'s bins."""
    return auto_table(volume, tf, tolerance=tolerance)[0]


def auto_integration(volume: Volume, tf: TransferFunction, n_bins: int | str = "auto", *,
                     tolerance: float = DEFAULT_TOLERANCE) -> str:
    """``"table"`` where :func:`auto_table` meets ``tolerance``, else ``"exact"``."""
    return "table" if auto_table(volume, tf, n_bins, tolerance=tolerance)[1] <= tolerance else "exact"


@functools.lru_cache(maxsize=32)
def _table(volume: Volume, tf: TransferFunction, candidates: tuple[int, ...], tolerance: float) -> tuple[int, float]:
    values = volume.sample_index(_visible_points(volume, tf))
    length = np.full(values.shape, SLAB_VOXELS * float(volume.spacing.min()))
    sample = SegmentSample(front=values, back=values, length=length,
                           weight=np.full(values.shape, 1.0 / values.size))
    rng = table_scalar_range(volume.scalar_range, tf)
    error = math.inf
    for n in candidates:
        error = scalar_axis_error(tf, aligned_scalar_range(rng, tf, n), n, sample)
        if error <= tolerance:
            return n, error
    return candidates[-1], error

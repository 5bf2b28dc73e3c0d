"""Culling before work: the cells that cannot change the image, found before sorting.

About this technique
--------------------
Two tests, each conservative and each exact in what it removes: a culled cell adds
exactly nothing to the image, so drawing the rest gives the same image.

* **View frustum** (the all-vertices-outside-one-plane test of Assarsson & Möller 2000,
  "Optimized view frustum culling algorithms for bounding boxes"): a tet all four of whose
  vertices lie outside the same frustum plane — left, right, bottom, top, near or far —
  is outside the frustum, which is convex. Tets that are outside but straddle a corner of
  the frustum are kept (rare, and harmless).
* **Transfer function** (the empty-space skipping of ray casters, applied per cell):
  the scalar is linear on a tet, so every point of it
  takes a value in ``[min, max]`` of its four vertex scalars. The opacity map is piecewise
  linear, so its largest value on that interval is at an end or at an opacity breakpoint
  inside. If that is zero, the cell neither absorbs nor emits (emission is weighted by
  extinction in tetvr's model, :mod:`tetvr.optics.model`).

The GPU renderer reads its pre-integration table with linear filtering between scalar
nodes, so a cell's lookups reach up to one node spacing beyond its scalar range. Pass
``scalar_margin=gpu_scalar_margin(mesh, tf, settings)`` to cull for it with the image
unchanged bit for bit (``tests/test_cull.py``); the exact reference renderer needs no
margin. With ``table_encoding="premultiplied"`` the table's colour can keep a rounding
residue (~1e-17) where its alpha is zero, so there culling is exact only to that.

The GPU renderer culls by itself (it draws a subset of the cells through its order).
For renderers that take no subset, such as :func:`~tetvr.reference.tets.render_reference`,
:func:`submesh` builds a mesh of the visible cells that renders like the whole (same
points, scalars and table).
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tetvr.core.checks import check_instances
from tetvr.core.camera import Camera, resolve_clipping_range
from tetvr.mesh.tetmesh import TetMesh
from tetvr.optics.transfer import TransferFunction

__all__ = [
    "CullStats",
    "gpu_scalar_margin",
    "outside_view",
    "submesh",
    "transparent_cells",
    "visible_cells",
    "zero_opacity",
]

# Relative slack on the plane tests: a vertex within this of a plane counts as inside, so
# rounding never culls a cell that touches the view.
_PLANE_SLACK = 1e-9


@dataclasses.dataclass(frozen=True)
class CullStats:
    """What culling removed.

    Attributes
    ----------
    n_cells : cells tested.
    n_outside_view : cells wholly outside the view frustum.
    n_transparent : cells inside it whose scalars all map to zero opacity.
    n_visible : cells kept.
    seconds : time taken.
    """

    n_cells: int = 0
    n_outside_view: int = 0
    n_transparent: int = 0
    n_visible: int = 0
    seconds: float = 0.0

    @property
    def fraction_culled(self) -> float:
        return 1.0 - self.n_visible / self.n_cells if self.n_cells else 0.0


def visible_cells(
    mesh: TetMesh,
    camera: Camera,
    tf: TransferFunction,
    *,
    size: tuple[int, int] | None = None,
    scalar_margin: float = 0.0,
    frustum: bool = True,
    opacity: bool = True,
) -> tuple[NDArray[np.int64], CullStats]:
    """The cells that can contribute to the image, in ascending id order.

    Parameters
    ----------
    mesh, camera, tf : the scene.
    size : ``(width, height)`` of the image; it sets the horizontal extent of the view.
        Without it the left and right planes are not tested.
    scalar_margin : widen each cell's scalar range by this much before the opacity test
        (see :func:`gpu_scalar_margin`).
    frustum, opacity : which tests to run.

    Returns
    -------
    ids : (k,) int64 ids of the cells kept (rows of ``mesh.tets``), ascending.
    stats : :class:`CullStats`.

    Examples
    --------
    >>> from tetvr.mesh import synthetic
    >>> mesh = synthetic.cube(4)
    >>> tf = TransferFunction.preset("grayscale", mesh.scalar_range, opacity=[(0, 0), (0.5, 0), (1, 1)])
    >>> ids, stats = visible_cells(mesh, Camera.fit(mesh), tf, size=(64, 64))
    >>> stats.n_transparent > 0, stats.n_visible == len(ids)
    (True, True)
    """
    check_instances(mesh=(mesh, TetMesh), camera=(camera, Camera), tf=(tf, TransferFunction))
    margin = float(scalar_margin)
    if not (math.isfinite(margin) and margin >= 0):
        raise ValueError(f"scalar_margin must be a finite number >= 0, got {scalar_margin!r}")
    start = time.perf_counter()
    n = mesh.n_tets
    out_view = outside_view(mesh, camera, size=size) if frustum else np.zeros(n, dtype=bool)
    clear = np.zeros(n, dtype=bool)
    if opacity:
        rest = np.nonzero(~out_view)[0]
        clear[rest] = transparent_cells(mesh, tf, scalar_margin=margin, ids=rest)
    keep = ~(out_view | clear)
    ids = np.nonzero(keep)[0].astype(np.int64)
    stats = CullStats(n_cells=n, n_outside_view=int(out_view.sum()), n_transparent=int(clear.sum()),
                      n_visible=int(ids.shape[0]), seconds=time.perf_counter() - start)
    return ids, stats


def outside_view(mesh: TetMesh, camera: Camera, *, size: tuple[int, int] | None = None) -> NDArray[np.bool_]:
    """(m,) True for the tets wholly outside one plane of the view frustum."""
    camera = resolve_clipping_range(camera, mesh.bounds)
    view = camera.view_matrix()
    eye = mesh.points @ view[:3, :3].T + view[:3, 3]
    x, y, depth = eye[:, 0], eye[:, 1], -eye[:, 2]
    near, far = camera.near_far()
    scale = float(np.abs(eye).max()) if eye.size else 1.0
    slack = _PLANE_SLACK * max(scale, abs(near), abs(far), 1e-300)
    if camera.parallel_projection:
        ky = camera.parallel_scale
        reach_y = np.full_like(depth, ky)
    else:
        ky = math.tan(math.radians(camera.view_angle) / 2)
        reach_y = ky * depth
    # Per point, a bit per plane it is outside of; a tet is out if its points share a bit.
    code = ((depth < near - slack).astype(np.uint8) | ((depth > far + slack).astype(np.uint8) << 1)
            | ((y > reach_y + slack).astype(np.uint8) << 2) | ((y < -reach_y - slack).astype(np.uint8) << 3))
    if size is not None:
        width, height = (int(v) for v in size)
        if width < 1 or height < 1:
            raise ValueError(f"size must be two positive integers (width, height), got {size!r}")
        reach_x = reach_y * (width / height)
        code |= ((x > reach_x + slack).astype(np.uint8) << 4) | ((x < -reach_x - slack).astype(np.uint8) << 5)
    c = code[mesh.tets]
    return np.asarray((c[:, 0] & c[:, 1] & c[:, 2] & c[:, 3]) != 0)


def transparent_cells(mesh: TetMesh, tf: TransferFunction, *, scalar_margin: float = 0.0,
                      ids: NDArray[np.integer[Any]] | None = None) -> NDArray[np.bool_]:
    """True for the tets (all, or those in ``ids``) whose scalar range, widened by
    ``scalar_margin``, maps entirely to zero opacity."""
    s = mesh.corner_scalars if ids is None else mesh.corner_scalars[ids]
    lo = s.min(axis=1) - scalar_margin
    hi = s.max(axis=1) + scalar_margin
    return zero_opacity(tf, lo, hi)


def zero_opacity(tf: TransferFunction, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Whether the opacity is zero everywhere on each interval ``[lo, hi]``.

    The map is piecewise linear and clamped at its ends, so its maximum on an interval is
    at an end or at a breakpoint inside.

    Examples
    --------
    >>> tf = TransferFunction(color=((0, 1, 1, 1), (1, 1, 1, 1)), opacity=((0, 0), (0.4, 0), (0.5, 1), (1, 1)))
    >>> zero_opacity(tf, np.array([0.0, 0.1, 0.3]), np.array([0.4, 0.45, 2.0])).tolist()
    [True, False, False]
    """
    op = np.asarray(tf.opacity)
    _, a_lo = tf.evaluate(lo)
    _, a_hi = tf.evaluate(hi)
    peaks = np.sort(op[op[:, 1] > 0, 0])
    inside = np.searchsorted(peaks, hi, side="left") - np.searchsorted(peaks, lo, side="right")
    return np.asarray((a_lo == 0) & (a_hi == 0) & (inside <= 0))


def gpu_scalar_margin(mesh: TetMesh, tf: TransferFunction, settings: Any = None, *,
                      node_spacing: float | None = None) -> float:
    """The scalar margin under which culling leaves the GPU renderer's image unchanged.

    Its pre-integration table has the settings' ``table_scalar_bins`` nodes (for
    ``"auto"`` the fewest it may choose, the widest spacing)
    spanning the union of the mesh's range and the transfer function's domain
    (:func:`tetvr.optics.preintegrate.table_for`), or with aligned nodes (the settings'
    ``table_align_nodes``) a spacing up to 1 / ``ALIGN_MIN_FRACTION`` wider; a lookup
    filters between the two nodes around its scalar, which lie within one node spacing.
    ``node_spacing`` (a built table's, :attr:`PreintegrationTable.node_spacing`) replaces
    that bound. The extra 1 % covers float32 rounding of the texture coordinate.
    """
    from tetvr.optics.table import fewest_spacings
    from tetvr.settings import RenderSettings
    from tetvr.optics.tablesize import AUTO_BINS

    if node_spacing is None:
        s = settings or RenderSettings()
        n_bins = min(AUTO_BINS) if s.table_scalar_bins == "auto" else int(s.table_scalar_bins)
        lo = min(mesh.scalar_range[0], tf.domain[0])
        hi = max(mesh.scalar_range[1], tf.domain[1])
        spacings = fewest_spacings(n_bins) if s.table_align_nodes else n_bins - 1
        node_spacing = (hi - lo) / spacings
    return 1.01 * node_spacing


def submesh(mesh: TetMesh, ids: NDArray[np.integer[Any]]) -> TetMesh:
    """The mesh restricted to the cells ``ids``, rendering like the whole.

    Points and scalars stay as they are (so the scalar range and the near-plane test do),
    and so do :attr:`TetMesh.max_edge`, which sets the thickness axis of the
    pre-integration table, and the segment sample that sizes an "auto" table: the GPU
    renderer then builds the same table as for the whole mesh. The cells keep their
    canonical (ascending) order.
    """
    idx = np.unique(np.asarray(ids, dtype=np.int64))
    if idx.size and (idx[0] < 0 or idx[-1] >= mesh.n_tets):
        raise ValueError(f"ids must be cell ids in 0..{mesh.n_tets - 1}")
    if idx.size == 0:
        raise ValueError("no cells to keep: there is nothing to render")
    tets = mesh.tets[idx]
    tets.setflags(write=False)
    sub = dataclasses.replace(mesh, tets=tets)
    # max_edge is a cached_property: seeding the instance's cache keeps the whole mesh's
    # value (a frozen dataclass refuses ordinary assignment).
    object.__setattr__(sub, "max_edge", mesh.max_edge)
    # Likewise the segment sample that sizes an "auto" table (tetvr.optics.tablesize).
    from tetvr.optics.tablesize import segment_sample

    object.__setattr__(sub, "_segment_sample", segment_sample(mesh))
    return sub

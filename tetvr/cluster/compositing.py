"""Compositing sort-last images on the workers, in visibility order: radix-k.

About this technique
--------------------
Radix-k (Peterson, Kendall, Yu and Ma 2009, "A configurable algorithm for parallel
image-compositing applications"), the default of IceT (Moreland et al. 2011), which
generalises binary swap (Ma, Painter, Hansen and Krogh 1994, k = 2 in every round) and
direct send (one round, k = P). The P brick images, in the k-d tree's visibility order for
the view, are *slots* 0 .. P-1, and P is factored into rounds, P = k_1 k_2 ... k_R. In
round r the slots that differ only in their r-th digit (mixed radix, the first round's
digit the least significant) form a group of k_r; all hold the same region of the image
(the whole image before the first round). The region is cut into k_r parts, and slot j of
the group receives part j from every member and composites them "over" in member order,
which is visibility order: after round r each slot holds the composite of a run of
k_1 ... k_r consecutive bricks on its region. After the last round every slot holds the
final image on 1/P of the pixels; the client receives these P pieces, one image in all.

"Over" is associative but not commutative, so groups are runs of consecutive slots and a
group composites its members in slot order; each composite is computed in float64 and
stored as float32, as :func:`tetvr.cluster.bricks.composite_over` does for the whole
sequence (the two differ by float32 rounding, once per round).

Each slot composites about (1 - 1/P) of one image in all rounds together, and sends and
receives as much; the client receives one image. On Dask each piece that travels is a task
(a slice, run where its image is) and each composite another: P (k_r + 1) tasks per round.
:data:`RADIX_K` = 4 makes that sum least (a round of k = 2 halves the region at the cost of
3 tasks a slot; k = 4 quarters it for 5). Costs measured and projected to P = 1,024:
``docs/distributed.md``.

This module runs the schedule on a Dask client (:func:`composite_on_workers`) and, for
tests and as a model of it, in this process (:func:`composite_locally`); it imports no
OpenGL and Dask only through the client it is given.
"""

from __future__ import annotations

from typing import Any, NamedTuple, Sequence

import numpy as np
from numpy.typing import NDArray

from tetvr.cluster.bricks import Brick, Split, composite_over, leaves

__all__ = ["RADIX_K", "radix_factors", "Step", "schedule", "final_regions", "composite_locally",
           "composite_on_workers", "stitch", "runs", "subtree_owners"]

#: The largest group of a round (IceT's "magic k" is 8; on Dask 4 makes the fewest tasks).
RADIX_K = 4


def radix_factors(n_slots: int, k: int = RADIX_K) -> list[int]:
    """The group size of each round for ``n_slots`` images: the largest divisor of what is
    left that is at most ``k``, round after round (a prime factor above ``k`` is a round
    of its own: direct send among that many).

    Examples
    --------
    >>> radix_factors(16), radix_factors(8), radix_factors(6), radix_factors(7), radix_factors(1)
    ([4, 4], [4, 2], [3, 2], [7], [])
    """
    if isinstance(n_slots, bool) or not isinstance(n_slots, (int, np.integer)) or n_slots < 1:
        raise ValueError(f"n_slots must be a positive integer, got {n_slots!r}")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 2:
        raise ValueError(f"k must be an integer of at least 2, got {k!r}")
    out, left = [], int(n_slots)
    while left > 1:
        f = next((d for d in range(min(k, left), 1, -1) if left % d == 0), None)
        if f is None:  # no divisor up to k: the smallest prime factor, however large
            f = next(d for d in range(k + 1, left + 1) if left % d == 0)
        out.append(f)
        left //= f
    return out


class Step(NamedTuple):
    """What one slot does in one round: composite, in ``members``' order, the part
    ``region`` (pixel indices ``[lo, hi)`` of the flattened image) of the members'
    results of the round before, each of which covers ``previous``."""

    slot: int
    members: tuple[int, ...]
    region: tuple[int, int]
    previous: tuple[int, int]


def _parts(lo: int, hi: int, k: int) -> list[tuple[int, int]]:
    cuts = [lo + (hi - lo) * j // k for j in range(k + 1)]
    return list(zip(cuts[:-1], cuts[1:]))


def schedule(n_slots: int, n_pixels: int, factors: Sequence[int] | None = None) -> list[list[Step]]:
    """The rounds of radix-k for ``n_slots`` images of ``n_pixels`` pixels: per round, one
    :class:`Step` per slot.

    Examples
    --------
    >>> [s.members for s in schedule(4, 8, [2, 2])[1]]
    [(0, 2), (1, 3), (0, 2), (1, 3)]
    >>> [s.region for s in schedule(4, 8, [2, 2])[1]]
    [(0, 2), (4, 6), (2, 4), (6, 8)]
    """
    factors = radix_factors(n_slots) if factors is None else [int(f) for f in factors]
    if int(np.prod(factors, dtype=np.int64)) != n_slots:
        raise ValueError(f"the round sizes {factors} do not multiply to {n_slots} slots")
    region = {p: (0, int(n_pixels)) for p in range(n_slots)}
    rounds, stride = [], 1
    for k in factors:
        steps = []
        for p in range(n_slots):
            digit = (p // stride) % k
            base = p - digit * stride
            members = tuple(base + j * stride for j in range(k))
            steps.append(Step(p, members, _parts(*region[p], k)[digit], region[p]))
        for s in steps:
            region[s.slot] = s.region
        rounds.append(steps)
        stride *= k
    return rounds


def final_regions(n_slots: int, n_pixels: int, factors: Sequence[int] | None = None) -> list[tuple[int, int]]:
    """The pixels each slot holds after the last round (together, every pixel once)."""
    rounds = schedule(n_slots, n_pixels, factors)
    return [s.region for s in rounds[-1]] if rounds else [(0, int(n_pixels))]


def runs(owners: Sequence[str | None]) -> list[list[int]]:
    """Slots 0 .. P-1 (in visibility order) in runs of consecutive slots whose images are
    on one worker (``owners[slot]``; None: a run of its own). A run composites on its
    worker with no transfer, and radix-k then runs over the runs.

    Examples
    --------
    >>> runs(["a", "a", "b", "b", "a", None, None])
    [[0, 1], [2, 3], [4], [5], [6]]
    """
    out: list[list[int]] = []
    for slot, owner in enumerate(owners):
        if out and owner is not None and owners[out[-1][-1]] == owner:
            out[-1].append(slot)
        else:
            out.append([slot])
    return out


def subtree_owners(tree: "Split | Brick", n_workers: int) -> dict[int, int]:
    """Each brick's worker (0 .. n_workers-1) such that every worker's bricks are one
    subtree of the k-d tree, so they are consecutive in the visibility order of every
    view (one run each, :func:`runs`): the workers are split between a node's sides in
    proportion to their bricks.

    Examples
    --------
    >>> from tetvr.cluster.bricks import kd_bricks
    >>> from tetvr.mesh import synthetic
    >>> subtree_owners(kd_bricks(synthetic.cube(4), 6).root, 2)
    {0: 0, 1: 0, 2: 0, 3: 1, 4: 1, 5: 1}
    """
    out: dict[int, int] = {}

    def walk(node: "Split | Brick", first: int, n: int) -> None:
        if n <= 1 or isinstance(node, Brick):
            out.update({b.index: first for b in leaves(node)})
            return
        n_low, n_high = len(leaves(node.low)), len(leaves(node.high))
        w_low = min(max(1, round(n * n_low / (n_low + n_high))), n - 1)
        walk(node.low, first, w_low)
        walk(node.high, first + w_low, n - w_low)

    walk(tree, 0, max(1, int(n_workers)))
    return out


def _piece(image: NDArray[Any], lo: int, hi: int) -> NDArray[np.float32]:
    """Pixels ``[lo, hi)`` of a flattened image (a copy: the image it came from can go)."""
    return np.array(np.asarray(image).reshape(-1, 4)[lo:hi], dtype=np.float32)


def _over(*pieces: NDArray[Any]) -> NDArray[np.float32]:
    return composite_over(pieces)


def composite_locally(images_front_to_back: Sequence[NDArray[Any]], factors: Sequence[int] | None = None
                      ) -> NDArray[np.float32]:
    """The radix-k composite of ``images_front_to_back`` computed here, round by round as
    the workers do it (a model and a test of the schedule).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> imgs = [rng.random((3, 5, 4), dtype=np.float32) * 0.5 for _ in range(6)]
    >>> float(np.abs(composite_locally(imgs) - composite_over(imgs)).max()) < 1e-6
    True
    """
    images = list(images_front_to_back)
    if not images:
        raise ValueError("nothing to composite")
    shape = np.asarray(images[0]).shape
    n = shape[0] * shape[1]
    held = {p: _piece(img, 0, n) for p, img in enumerate(images)}
    for steps in schedule(len(images), n, factors):
        held = {s.slot: _over(*(held[q][s.region[0] - s.previous[0]:s.region[1] - s.previous[0]] for q in s.members))
                for s in steps}
    return stitch([held[p] for p in range(len(images))], final_regions(len(images), n, factors), shape[0], shape[1])


def composite_on_workers(client: Any, images_front_to_back: Sequence[Any], n_pixels: int, *,
                         workers: Sequence[str | None] | None = None, factors: Sequence[int] | None = None
                         ) -> tuple[list[Any], list[tuple[int, int]]]:
    """Submit radix-k over ``images_front_to_back`` (futures of float RGBA images of
    ``n_pixels`` pixels on ``client``'s workers, front first): the futures of the final
    pieces, one per slot, and the pixels each covers (:func:`stitch` joins them).

    ``workers``: the address each slot's tasks prefer (where its image is; None: Dask's
    choice); they run elsewhere if that worker goes. An error of an image's task (a brick
    that could not render) is the pieces' error.
    """
    p = len(images_front_to_back)
    if p == 0:
        raise ValueError("nothing to composite")
    n = int(n_pixels)
    where = list(workers) if workers is not None else [None] * p

    def submit(fn: Any, slot: int, *args: Any) -> Any:
        at = where[slot]
        return client.submit(fn, *args, pure=False, workers=None if at is None else [at], allow_other_workers=True)

    held = list(images_front_to_back)
    if p == 1:
        return [submit(_piece, 0, held[0], 0, n)], [(0, n)]
    for steps in schedule(p, n, factors):
        # Each member's part for this slot, cut where the member's result is.
        held = [submit(_over, s.slot, *(submit(_piece, q, held[q], s.region[0] - s.previous[0],
                                               s.region[1] - s.previous[0]) for q in s.members))
                for s in steps]
    return held, final_regions(p, n, factors)


def stitch(pieces: Sequence[NDArray[Any]], regions: Sequence[tuple[int, int]], height: int, width: int
           ) -> NDArray[np.float32]:
    """The (height, width, 4) image from pieces of its flattened pixels (row-major)."""
    out = np.empty((int(height) * int(width), 4), dtype=np.float32)
    covered = 0
    for piece, (lo, hi) in zip(pieces, regions):
        out[lo:hi] = piece
        covered += hi - lo
    if covered != out.shape[0]:
        raise ValueError(f"the pieces cover {covered} of {out.shape[0]} pixels")
    return out.reshape(int(height), int(width), 4)

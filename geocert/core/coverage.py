"""Whether the leaves of a branch-and-bound tree cover its root box: exact, no tolerance (every
proof checker's coverage check)."""

from __future__ import annotations

import numpy as np

from geocert.core.bnb import Box
from geocert.core.strict import Invalid

MAX_PIECES = 5_000  # uncovered pieces kept when leaves are subtracted one by one
MAX_WORK = 200_000  # leaf-piece tests when leaves are subtracted one by one
# Leaf tests one coverage check may make in all: this many a leaf, plus a base. Each slab tests
# its leaves once on every axis, so a leaf is tested once a level of the slabs holding it: a
# search's tree, bisected, is some tens of levels deep. A "caterpillar" (each level splitting one
# leaf off the rest) is n levels deep and costs n^2 / 2: 20,000 leaves in a 2.7 MB document took
# 34 s of CPU, some 80 minutes at the 32 MB body limit. A leaf-piece test of a subtraction (a
# Python loop) costs SUBTRACTION_VISITS of them.
VISITS_PER_LEAF = 64
VISITS_BASE = 1_000_000
SUBTRACTION_VISITS = 4


def uncovered_part(root: Box, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """A part of ``root`` that no box (lo[i], hi[i]) covers, or None when they cover it all.

    Exact (no tolerance). A branch-and-bound tree's leaves are a guillotine partition: some
    axis-aligned plane crosses no leaf. So the boxes are split along every such plane of one
    axis at once, and each slab is checked the same way: n log n per level, whatever the
    leaves. A slab with no leaf, or a gap between the leaves along an axis, is uncovered. Where
    no plane separates the leaves (not a tree's partition), the slab's leaves are subtracted one
    by one, within a budget. Boxes are closed; leaves of zero volume cover nothing a positive
    volume does not (the union of closed boxes covering a box's interior covers the box).

    The work is bounded by the leaves' count (VISITS_PER_LEAF, VISITS_BASE): an arrangement
    needing more leaf tests is refused (check "coverage") before they are made, whatever
    covers what: a search's tree never needs as many.
    """
    budget = [VISITS_PER_LEAF * len(lo) + VISITS_BASE]
    if not np.all(root.hi > root.lo):
        return _subtracted(root.lo, root.hi, lo, hi, budget)
    stack = [(root.lo, root.hi, np.arange(len(lo)))]
    while stack:
        box_lo, box_hi, index = stack.pop()
        _spend(budget, len(index))
        L = np.maximum(lo[index], box_lo)
        H = np.minimum(hi[index], box_hi)
        inside = np.all(L < H, axis=1)
        index, L, H = index[inside], L[inside], H[inside]
        if not len(index):
            return box_lo, box_hi
        if np.any(np.all(L == box_lo, axis=1) & np.all(H == box_hi, axis=1)):
            continue
        for axis in range(len(box_lo)):
            order = np.argsort(L[:, axis], kind="stable")
            starts, ends = L[order, axis], np.maximum.accumulate(H[order, axis])
            if starts[0] > box_lo[axis]:
                return _slab(box_lo, box_hi, axis, box_lo[axis], starts[0])
            if ends[-1] < box_hi[axis]:
                return _slab(box_lo, box_hi, axis, ends[-1], box_hi[axis])
            gaps = np.flatnonzero(ends[:-1] < starts[1:])
            if len(gaps):
                return _slab(box_lo, box_hi, axis, ends[gaps[0]], starts[gaps[0] + 1])
            cuts = np.flatnonzero(ends[:-1] <= starts[1:]) + 1  # planes that cross no leaf
            if len(cuts):
                bounds = np.concatenate([[box_lo[axis]], starts[cuts], [box_hi[axis]]])
                for group, (a, b) in zip(np.split(order, cuts), zip(bounds[:-1], bounds[1:])):
                    slab_lo, slab_hi = box_lo.copy(), box_hi.copy()
                    slab_lo[axis], slab_hi[axis] = a, b
                    stack.append((slab_lo, slab_hi, index[group]))
                break
        else:  # no separating plane: not a tree's partition
            gap = _subtracted(box_lo, box_hi, L, H, budget)
            if gap is not None:
                return gap
    return None


def _spend(budget: list[int], visits: int) -> None:
    budget[0] -= visits
    if budget[0] < 0:
        raise Invalid("coverage", f"the leaves are arranged so that showing they cover the box takes more than "
                                  f"{VISITS_PER_LEAF} leaf tests a leaf plus {VISITS_BASE:,} (a search's tree takes "
                                  "far fewer): not checked")


def _slab(box_lo, box_hi, axis: int, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    slab_lo, slab_hi = box_lo.copy(), box_hi.copy()
    slab_lo[axis], slab_hi[axis] = a, b
    return slab_lo, slab_hi


def _subtracted(root_lo: np.ndarray, root_hi: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                budget: list[int] | None = None):
    """uncovered_part by subtracting each closed box from the closed pieces still uncovered
    (what a subtraction leaves are slabs reaching strictly beyond the box, so nothing is lost);
    past MAX_PIECES pieces or MAX_WORK leaf-piece tests the box is reported as not shown covered."""
    pieces = [(root_lo.copy(), root_hi.copy())]
    order = np.lexsort(lo.T[::-1])  # a sweep: neighbours follow each other
    work = 0
    for i in order:
        work += len(pieces)
        if budget is not None:
            _spend(budget, SUBTRACTION_VISITS * len(pieces))
        if work > MAX_WORK:
            return root_lo, root_hi
        remaining = []
        for p_lo, p_hi in pieces:
            if np.any(lo[i] > p_hi) or np.any(hi[i] < p_lo):
                remaining.append((p_lo, p_hi))
                continue
            p_lo, p_hi = p_lo.copy(), p_hi.copy()
            for axis in range(len(p_lo)):
                if p_lo[axis] < lo[i][axis]:
                    slab_hi = p_hi.copy()
                    slab_hi[axis] = lo[i][axis]
                    remaining.append((p_lo.copy(), slab_hi))
                    p_lo[axis] = lo[i][axis]
                if p_hi[axis] > hi[i][axis]:
                    slab_lo = p_lo.copy()
                    slab_lo[axis] = hi[i][axis]
                    remaining.append((slab_lo, p_hi.copy()))
                    p_hi[axis] = hi[i][axis]
        pieces = remaining
        if not pieces:
            return None
        if len(pieces) > MAX_PIECES:
            return root_lo, root_hi
    return pieces[0] if pieces else None


# A side a proof claims may lie beyond the side its dual proves by this fraction of the box's
# size (its largest coordinate or width) when the proof counts its rounding (cones.
# rounding_margin): certificates written before it did claim the value computed without it,
# about 1e-11 beyond. Such a side is widened to the proven one (``widened``), and every box the
# proof's leaves and proofs give on the claimed box's faces is extended to the widened faces
# (``extended``), so that the points between the two are bounded as the rest.
SIDE_TOLERANCE = 1e-9


def widened(claimed_lo: np.ndarray, claimed_hi: np.ndarray, proven_lo: np.ndarray, proven_hi: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray] | None:
    """The box a proof establishes where it claims [claimed_lo, claimed_hi] and its duals prove
    [proven_lo, proven_hi] (every point lies within it): the claimed sides, each moved out to
    the proven side when that lies beyond it; None when a claimed side lies beyond the proven one
    by more than SIDE_TOLERANCE of the box's size, its largest coordinate and width (not
    rounding: a side the proof does not give)."""
    size = max(float(np.max(np.abs(claimed_lo), initial=0.0)), float(np.max(np.abs(claimed_hi), initial=0.0)),
               float(np.max(np.abs(claimed_hi - claimed_lo), initial=0.0)))
    slack = SIDE_TOLERANCE * size
    if not (np.all(claimed_lo <= proven_lo + slack) and np.all(claimed_hi >= proven_hi - slack)):
        return None
    return np.minimum(claimed_lo, proven_lo), np.maximum(claimed_hi, proven_hi)


def extended(lo: np.ndarray, hi: np.ndarray, claimed: Box, proven: Box) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (lo[i], hi[i]) with every side on or beyond a face of ``claimed`` moved out to the
    face of ``proven`` (a box holding ``claimed``). Boxes covering ``claimed`` then cover
    ``proven``: a point of ``proven`` moved into ``claimed`` (each coordinate clipped) lies in
    some box, which reaches the clipped coordinates' faces and so, extended, the point."""
    lo = np.where(lo <= claimed.lo, np.minimum(lo, proven.lo), lo)
    hi = np.where(hi >= claimed.hi, np.maximum(hi, proven.hi), hi)
    return lo, hi

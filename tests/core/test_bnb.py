"""The branch-and-bound engine's handling of boxes a problem shrinks (node tightening): the parts
cut off are leaves with their proofs, the rest is bounded and split, and together the leaves
cover the root exactly once."""

from __future__ import annotations

import math

import numpy as np

from geocert.core.bnb import BnbOptions, Box, BoxBound, BoxStatus, branch_and_bound


class Interval:
    """Minimise (x - 0.3)^2 + 1 on [0, 1]; each box's bound is its minimum less a tenth of its width. With ``cut``, a
    box not containing 0.3 is excluded whole, and a box containing it is shrunk to its middle
    half, the two outer quarters excluded."""

    def __init__(self, cut: bool):
        self.cut = cut

    def root_box(self) -> Box:
        return Box(np.zeros(1), np.ones(1))

    def objective(self, x) -> float:
        return float((x - 0.3) ** 2) + 1.0

    def improve(self, x):
        return x, self.objective(x)

    def _exact(self, box: Box) -> BoxBound:
        x = float(np.clip(0.3, box.lo[0], box.hi[0]))  # the box's minimiser; its bound is loose by the width
        bound = self.objective(x) - 0.1 * float(box.hi[0] - box.lo[0])
        return BoxBound(BoxStatus.BOUNDED, bound, x, None, ("exact", box.lo[0], box.hi[0]))

    def bound(self, box: Box, upper_bound: float) -> BoxBound:
        if not self.cut or box.hi[0] - box.lo[0] > 0.5:
            return self._exact(box)
        if not box.lo[0] <= 0.3 <= box.hi[0]:
            return BoxBound(BoxStatus.EMPTY, excluded=[(box, ("cut", box.lo[0], box.hi[0]))])
        quarter = 0.25 * (box.hi[0] - box.lo[0])
        inner = Box(box.lo + quarter, box.hi - quarter)
        if not inner.lo[0] <= 0.3 <= inner.hi[0]:
            return self._exact(box)
        result = self._exact(inner)
        result.box = inner
        result.excluded = [(Box(box.lo.copy(), inner.lo.copy()), ("cut", box.lo[0], inner.lo[0])),
                           (Box(inner.hi.copy(), box.hi.copy()), ("cut", inner.hi[0], box.hi[0]))]
        return result

    def split(self, box: Box, bound: BoxBound) -> list[Box]:
        middle = 0.5 * (box.lo + box.hi)
        return [Box(box.lo.copy(), middle), Box(middle, box.hi.copy())]


def total_length(leaves) -> float:
    return sum(float(box.hi[0] - box.lo[0]) for box, _ in leaves)


class TestExcludedParts:
    def test_cut_parts_are_leaves_and_the_leaves_tile_the_root(self):
        leaves: list = []
        result = branch_and_bound(Interval(cut=True), 0.9, Interval(True).objective(0.9),
                                  BnbOptions(abs_gap=1e-3, rel_gap=0.0, max_nodes=500), leaves=leaves)
        assert result.status == "optimal" and abs(result.candidate - 0.3) < 1e-5
        proofs = [proof for _, proof in leaves]
        assert any(p is not None and p[0] == "cut" for p in proofs)
        # No box is closed twice: a box excluded whole is not also closed with no proof.
        assert all(p is not None for p in proofs)
        assert math.isclose(total_length(leaves), 1.0, rel_tol=0, abs_tol=1e-12)
        for box, proof in leaves:  # each leaf is the box its proof speaks of
            assert (proof[1], proof[2]) == (box.lo[0], box.hi[0])

    def test_without_cuts_the_same_optimum(self):
        leaves: list = []
        result = branch_and_bound(Interval(cut=False), 0.9, Interval(False).objective(0.9),
                                  BnbOptions(abs_gap=1e-3, rel_gap=0.0, max_nodes=500), leaves=leaves)
        assert abs(result.candidate - 0.3) < 1e-5
        assert math.isclose(total_length(leaves), 1.0, rel_tol=0, abs_tol=1e-12)

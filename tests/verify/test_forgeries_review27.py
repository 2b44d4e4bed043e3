"""Review 27 (issue 33): a hostile review of the branch-and-bound trees of every kind that has
one (their leaves, root boxes and coverage), and of the direct method's proven focal interval.

Found (verified on main, the tests below failing there):

- The coverage check's work grew with the square of the leaves' count for a "caterpillar" (each
  level of the tree splitting one leaf off the rest): 20,000 such leaves in a resection's proof
  (a 2.7 MB document) took 34 s of CPU before the verifier refused them at ``leaf_bounds``, some
  80 minutes at the 32 MB body limit. The check now makes at most a fixed number of leaf tests
  a leaf (coverage.VISITS_PER_LEAF, VISITS_BASE) and refuses beyond them (check "coverage").

Tried and refused already (no test added; see the module's tests for the genuine trees): a leaf
deleted, moved off its neighbour by one unit in the last place or by a subnormal width, inverted,
pointing to no proof, the root or search box narrowed, one leaf stretched over the whole root;
duplicated or reordered leaves (true claims; a result then disagrees with its summary's count).
The direct method's focal interval: narrowed, its ``cost_increase`` raised or lowered, its ``c``
or dual vectors moved or scaled, an end dropped, ends swapped, entries duplicated, an interval
inverted, the determinacy's copy edited alone.
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.core import coverage
from geocert.core.bnb import Box
from geocert.core.strict import Invalid
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored


def _caterpillar(lo, hi, n: int, proof=0) -> list:
    """n leaves covering [lo, hi]: each level splits a thin slab off the low side of the rest
    (along the axes in turn), the rest split again."""
    lo, hi = np.array(lo, float), np.array(hi, float)
    leaves = []
    for i in range(n - 1):
        axis = i % len(lo)
        cut = lo[axis] + (hi[axis] - lo[axis]) / (n - i) * 0.5
        leaf_hi = hi.copy()
        leaf_hi[axis] = cut
        leaves.append([lo.tolist(), leaf_hi.tolist(), proof])
        lo[axis] = cut
    leaves.append([lo.tolist(), hi.tolist(), proof])
    return leaves


class _CountingNumpy:
    """numpy, counting the sorts the coverage check makes (one an axis a slab), and stopping
    past ``limit`` of them: what the check costs, on any machine."""

    def __init__(self, limit: int):
        self.sorts, self.limit = 0, limit

    def __getattr__(self, name):
        return getattr(np, name)

    def argsort(self, *args, **kwargs):
        self.sorts += 1
        if self.sorts > self.limit:
            raise AssertionError(f"the coverage check sorted the leaves more than {self.limit} times")
        return np.argsort(*args, **kwargs)


class TestCoverageCost:
    def test_a_caterpillar_of_leaves_is_refused_within_a_bounded_number_of_sorts(self, monkeypatch):
        """20,000 leaves, each level peeling one off: n levels, n^2 / 2 leaf tests unbounded
        (60,000 sorts of up to 20,000 leaves). Within the budget, about a hundred levels."""
        counting = _CountingNumpy(limit=5_000)
        monkeypatch.setattr(coverage, "np", counting)
        leaves = np.array([leaf[:2] for leaf in _caterpillar([0, 0, 0], [1, 1, 1], 20_000)])
        with pytest.raises(Invalid) as refused:
            coverage.uncovered_part(Box(np.zeros(3), np.ones(3)), leaves[:, 0], leaves[:, 1])
        assert refused.value.check == "coverage"

    def test_in_a_document_it_is_refused_at_coverage(self, monkeypatch):
        """The same in a resection's proof (every leaf naming its proof 0): refused at coverage,
        before the leaves' proofs are read (on main: at leaf_bounds, after the quadratic check)."""
        counting = _CountingNumpy(limit=5_000)
        monkeypatch.setattr(coverage, "np", counting)
        result = stored("resection_l2l2")
        proof = result["certificate"]["items"][0]["proof"]
        proof["leaves"] = _caterpillar(*proof["search_box"], 20_000)
        report = verify_any(json.loads(json.dumps(result)))
        assert not report.valid
        assert report.first_failure["check"] == "coverage", report.first_failure

    def test_a_short_caterpillar_still_covers(self):
        """The budget's base answers for trees far deeper than a search's: 1,000 leaves, each
        level peeling one off, are still shown to cover (and with one gap, not)."""
        leaves = np.array([leaf[:2] for leaf in _caterpillar([0, 0], [1, 1], 1_000)])
        root = Box(np.zeros(2), np.ones(2))
        assert coverage.uncovered_part(root, leaves[:, 0], leaves[:, 1]) is None
        leaves[500, 1, (500 % 2)] = np.nextafter(leaves[500, 1, (500 % 2)], 0)
        assert coverage.uncovered_part(root, leaves[:, 0], leaves[:, 1]) is not None


GENUINE_TREES = ("triangulation_l2l2", "resection_caps", "resection_node_tightening", "homography3_l2l1",
                 "bilinear_l1l1", "autocalibration_stratified")


def _trees(value, path=()):
    if isinstance(value, dict):
        if "leaves" in value and "proofs" in value:
            yield path
        for key, v in value.items():
            yield from _trees(v, path + (key,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _trees(v, path + (i,))


def _at(value, path):
    for key in path:
        value = value[key]
    return value


@pytest.mark.parametrize("name", GENUINE_TREES)
class TestTreeEdits:
    """Each genuine tree of these documents, edited as a forger would: refused."""

    @staticmethod
    def _each_tree(name):
        result = stored(name)
        for path in _trees(result):
            yield result, path

    def test_a_leaf_moved_off_its_neighbour_by_one_ulp_is_refused(self, name):
        for result, path in self._each_tree(name):
            tree = _at(result, path)
            if len(tree["leaves"]) < 2:
                continue
            forged = copy.deepcopy(result)
            leaf = _at(forged, path)["leaves"][0]
            others = _at(forged, path)["leaves"][1:]
            # A face the leaf shares with another (inside the root): moved inward by one ulp.
            for axis in range(len(leaf[0])):
                if any(other[0][axis] == leaf[1][axis] for other in others):
                    leaf[1][axis] = float(np.nextafter(leaf[1][axis], leaf[0][axis]))
                    break
                if any(other[1][axis] == leaf[0][axis] for other in others):
                    leaf[0][axis] = float(np.nextafter(leaf[0][axis], leaf[1][axis]))
                    break
            else:
                continue
            assert not verify_any(forged).valid, path

    def test_a_leaf_deleted_is_refused(self, name):
        for result, path in self._each_tree(name):
            forged = copy.deepcopy(result)
            _at(forged, path)["leaves"].pop(0)
            assert not verify_any(forged).valid, path

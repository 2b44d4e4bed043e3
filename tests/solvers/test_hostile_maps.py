"""Hostile map problems (bench.hostile_maps's: sources and targets scaled by 1e-6 .. 1e6 and offset
far from the origin, outliers, near-duplicates, few points). Whatever fit_map certifies, the
per-item verifier accepts; where it would not, the solver says so and does not certify.

REFUSED names the problems whose certified results the verifier refused before the solver checked
its program as the verifier does (maps.refused_by_verifier). The verifier refuses them for its own
program check's tolerance, not for a wrong proof: the xfail tests state what it should accept once
that tolerance allows the round-off of the raw data (items.py / proof.py, not mended here), and
what it accepts that it should not (the rounding slack of a claimed cost)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.hostile_maps import options_for, problem, refused
from geocert.solvers import verify
from geocert.solvers.fractional import proof
from geocert.solvers.fractional.maps import fit_map
from geocert.solvers.fractional.options import MapOptions

# (seed, problem, norm): certified and refused ("the program's residuals differ from the data's").
# 3:23 homography, sources 1e6 x their spread from the origin (about 5e8, spread 4e6); 2:2 resection
# with a near-duplicate point, targets 1e6 x their spread from it; 1:21 homography with outliers,
# sources at 1e12 with spread 4e6. Each raw residual is a difference of terms 1e8 to 1e12 times
# larger than itself (over its depth), computed in the caller's coordinates.
REFUSED = [(3, 23, "L2L1"), (3, 23, "L1L1"), (2, 2, "L2L2"), (2, 2, "L2L1"), (2, 2, "L1L1"),
           (1, 21, "L2L1"), (1, 21, "L1L1")]


def solved(seed: int, index: int, norm: str):
    p = problem(seed, index)
    return p, fit_map(p["source"], p["target"], options_for(norm))


class TestEveryCertifiedMapVerifies:
    @pytest.mark.parametrize("seed, index, norm", REFUSED)
    def test_certified_only_what_the_verifier_accepts(self, seed, index, norm):
        p, result = solved(seed, index, norm)
        if result.certified:
            assert refused(p["kind"], p["source"], p["target"], result, options_for(norm)) is None
        else:  # the search closed: the solver says why it does not certify, and keeps its bounds
            assert result.status == "not_certified"
            assert "could not check the proof against the data" in result.reason
            assert 0 <= result.lower_bound <= result.cost
            assert result.cost - result.lower_bound <= 1e-3 * result.cost

    @pytest.mark.parametrize("seed, index, norm", REFUSED)
    def test_the_verifier_refuses_them_as_certified_for_the_program_alone(self, seed, index, norm):
        """Forced to certified, the claim fails the program check and nothing else: every other
        check passes with check_program skipped (what the xfail tests below rely on)."""
        p, result = solved(seed, index, norm)
        forced = dataclasses.replace(result, status="optimal", certified=True)
        why = refused(p["kind"], p["source"], p["target"], forced, options_for(norm))
        assert why == "program: the program's residuals differ from the data's"
        original = proof.check_program
        try:
            proof.check_program = lambda *args, **kwargs: None
            assert refused(p["kind"], p["source"], p["target"], forced, options_for(norm)) is None
        finally:
            proof.check_program = original


class TestKnownVerifierDefects:  # and one mended (a claimed cost's rounding counted in its gap)
    @pytest.mark.xfail(strict=True, reason=(
        "proof.check_program judges a map's residuals with 1e-9 (1 + largest) + 1e-6 |residual| only: "
        "MapItem has no raw_sizes_many, so the round-off of raw terms far larger than the residual "
        "(sources or targets offset 1e3-1e6 times their spread) is not allowed for, as it is for tracks. "
        "The program agrees with the exact residuals of the claimed matrix as well as the raw "
        "computation does (bench.hostile_maps; items.py/proof.py are the lead's)"))
    @pytest.mark.parametrize("seed, index, norm", REFUSED)
    def test_a_genuine_claim_of_far_offset_data_verifies(self, seed, index, norm):
        p, result = solved(seed, index, norm)
        forced = dataclasses.replace(result, status="optimal", certified=True)
        assert refused(p["kind"], p["source"], p["target"], forced, options_for(norm)) is None

    # The larger offsets are refused for the claimed cost (certificates.ROUNDING, 1e-14, no longer
    # 1e-12); the smaller ones, whose cost is within that rounding of 0, for the gap it leaves.
    @pytest.mark.parametrize("norm, offset", [("L1L1", 9e-5), ("L2L1", 9e-5), ("L2L2", 2.2e-4), ("L1L1", 5e-7),
                                              ("L2L1", 5e-7)])
    def test_a_cost_of_zero_for_a_map_that_costs_more_is_refused(self, norm, offset):
        source = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.2]])
        target = source + 5e7  # exactly the translation by (5e7, 5e7): the optimum costs 0
        M = np.array([[1.0, 0.0, 5e7 + offset], [0.0, 1.0, 5e7 + offset], [0.0, 0.0, 1.0]])
        residuals = target - (source + 5e7 + offset)  # the map's, exactly: (-offset, -offset) each
        cost = {"L1L1": np.abs(residuals).sum(), "L2L1": np.sqrt((residuals ** 2).sum(axis=1)).sum(),
                "L2L2": (residuals ** 2).sum()}[norm]
        options = MapOptions(norm=norm)
        assert cost > 4 * options.abs_gap  # a false claim: its matrix is not within abs_gap of 0
        claim = {"index": 0, "status": "optimal", "certified": True, "cost": 0.0, "lower_bound": 0.0, "gap": 0.0,
                 "matrix": M.tolist(), "proof": {"type": "trivial"}}
        with pytest.raises(verify.Invalid, match="the solution costs"):
            verify.verify_arrays("homography", (source, target), dataclasses.asdict(options), claim)

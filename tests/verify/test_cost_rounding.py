"""The objective checks and a region's box sides allow the rounding another machine's BLAS kernels
give (geocert/verify/cost_rounding.py, frames.side_slack, frames.reference_candidates), and nothing
more. That every stored genuine certificate verifies under OpenBLAS's Haswell and Prescott kernels
(review 31's class 1: a near-exact fit's cost differs between kernels in its 8th digit) is
tests/verify/test_forgeries_review31.py's kernel tests."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.verify import cost_rounding
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored


@pytest.mark.parametrize("factor", [1 + 1e-3, 1 - 1e-3, 2.0, 0.5])
def test_a_claimed_cost_moved_beyond_its_rounding_is_refused(factor):
    """The stratified affine stage's claimed cost (1.03e-14, its rounding allowance 1.3e-19
    here) moved by a thousandth of itself is refused: the allowance is the terms' rounding, not
    room."""
    document = copy.deepcopy(stored("autocalibration_stratified"))
    for item in document["certificate"]["items"]:
        if item["index"] == 0:
            item["cost"] *= factor
            item["gap"] = item["cost"] - item["lower_bound"]
    report = verify_any(document)
    assert not report.valid
    assert report.first_failure["check"] == "objective", report.first_failure


def test_the_rounding_is_of_the_terms_not_the_cost():
    """Residuals 1e-8 computed from terms of magnitude 1: the allowance is 64 ulps of the terms
    times the residuals, above 1e-9 of the cost (1e-14), far below the cost itself."""
    r = np.full(40, 1e-8)
    rounding = cost_rounding.squares_rounding(r, np.ones(40))
    cost = float(r @ r)
    assert 1e-9 * cost < rounding < 1e-3 * cost
    assert cost_rounding.within(cost, cost + 0.5 * rounding, 1e-9, rounding)
    assert not cost_rounding.within(cost, cost + 2 * rounding, 1e-9, rounding)


def test_the_reference_is_the_lowest_indexed_of_the_tied():
    """Cameras conditioned alike to 1e-13 are tied for the reference (another machine's LAPACK may
    rank them otherwise), and the reference is the lowest-indexed of them whichever ranks first; one
    clearly worse conditioned is not tied; an earlier proof (naming no reference) may be posed in
    any tied camera's frame, the best first. (Alike to 1e-13, a tenth of EARLIER_TIE: a camera 1e-12
    apart lies on that tie's edge, where the SVD's rounding decides, and OpenBLAS's Prescott kernels
    left it out.)"""
    from geocert.formulations.autocalibration import frames

    rng = np.random.default_rng(0)
    R = [np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(4)]
    cameras = np.array([np.hstack([r, rng.normal(size=(3, 1))]) for r in R])
    cameras[0, :, :3] = cameras[0, :, :3] @ np.diag([1.0, 1.0, 3.0])
    cameras[2, :, :3] = cameras[2, :, :3] @ np.diag([1.0, 1.0, 1.0 + 1e-13])
    assert frames.reference_camera(cameras) == 1
    assert frames.reference_candidates(cameras, np.eye(3)) == [1]
    assert sorted(frames.earlier_references(cameras, np.eye(3))) == [1, 2, 3]

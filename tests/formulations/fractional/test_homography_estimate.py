"""A homography's determinacy estimate in a fixed order of operations (fractional.homography_estimate,
review 38 class 4): what holds on any machine. That it is bit for bit the same under OpenBLAS's
Haswell and Prescott kernels is tests/verify/test_forgeries_review38.py's class 4 (subprocesses)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from geocert.core.determinacy import information_intervals
from geocert.formulations.fractional import homography_estimate
from geocert.formulations.fractional.fixed_order import symmetric_eigen
from tests.verify.test_forgeries_review34 import _refused, _valid
from tests.verify.test_forgeries_review37 import _far_homography


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_symmetric_eigen_decomposes_the_matrix(seed):
    rng = np.random.default_rng(seed)
    J = rng.normal(size=(30, 8)) @ np.diag(np.logspace(0, 3, 8))
    A = J.T @ J
    values, vectors = symmetric_eigen(A)
    assert np.all(np.diff(values) >= 0)
    assert np.allclose(vectors.T @ vectors, np.eye(8), atol=1e-14)
    assert np.allclose(vectors @ np.diag(values) @ vectors.T, A, rtol=0, atol=1e-13 * values[-1])
    assert np.allclose(values, np.linalg.eigvalsh(A), rtol=1e-9, atol=0)


def test_symmetric_eigen_refuses_entries_not_finite():
    with pytest.raises(ArithmeticError):
        symmetric_eigen(np.array([[1.0, math.inf], [math.inf, 1.0]]))


def test_the_fixed_order_intervals_are_lapacks_to_rounding():
    """The fixed-order path reads the same ellipsoid as core.determinacy.information_intervals."""
    rng = np.random.default_rng(4)
    J = rng.normal(size=(30, 8))
    quantities = {"q": (3.0, rng.normal(size=8), None)}
    ours = homography_estimate.intervals(J.T @ J, 2.0, 22, quantities, None).intervals[0]
    theirs = information_intervals(J.T @ J, 2.0, 22, quantities).intervals[0]
    assert math.isclose(ours["upper"] - ours["lower"], theirs["upper"] - theirs["lower"], rel_tol=1e-12)


@pytest.mark.parametrize("offset", [0.0, 1e7])
def test_the_analytic_width_is_the_central_differences_near_the_origin_and_holds_far_off(offset):
    """The interval's width does not depend on where the data lie: 1 px of noise gives about 1.9 px
    at the origin and 1e7 from it at 3 standard errors (the earlier central differences drifted
    7e-3 of it there); today's form reads it at the Student quantile of its 22 degrees of freedom
    (3.380 for 3), 2.15 px."""
    from geocert.core.determinacy import level_sigmas
    from geocert.jobs.runner import solve_job

    result = solve_job(_far_homography(offset, 1.0, 5))
    determinacy = result["maps"][0]["determinacy"]
    interval = determinacy["intervals"][0]
    assert determinacy["redundancy"] == 22
    assert math.isclose(interval["upper"] - interval["lower"], 1.9107698 * level_sigmas(22) / 3.0, rel_tol=1e-6)


@pytest.fixture(scope="module")
def far_homography() -> dict:
    from geocert.jobs.runner import solve_job

    result = solve_job(_far_homography(1e6, 1e-3, 5))
    _valid(result)
    return result


@pytest.mark.parametrize("share", [-1e-2, 1e-2])
def test_a_far_homography_interval_narrowed_or_widened_by_a_hundredth_is_refused(far_homography, share):
    document = copy.deepcopy(far_homography)
    for interval in document["maps"][0]["determinacy"]["intervals"]:
        half = share * (interval["upper"] - interval["lower"]) / 2
        interval["lower"], interval["upper"] = interval["lower"] - half, interval["upper"] + half
    _refused(document, "its offset from the value")


def test_a_far_homography_value_moved_two_ulps_is_refused(far_homography):
    document = copy.deepcopy(far_homography)
    interval = document["maps"][0]["determinacy"]["intervals"][0]
    interval["value"] = np.nextafter(np.nextafter(interval["value"], math.inf), math.inf).item()
    _refused(document, "intervals/0/value")

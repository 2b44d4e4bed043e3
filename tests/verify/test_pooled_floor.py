"""The floor the verifier puts under a pooled level (fractional.pooled_floor) never exceeds the
level the solver pools (determinacy.pooled_increase, scipy's quantiles), and a determinacy read
at a pooled level states its pool, which the verifier recomputes."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy.special import chdtri, stdtrit

from geocert.formulations.fractional.determinacy import COVERAGE, OUTLIER_TAIL, pooled_increase
from geocert.verify.fractional import MAX_VIEWS
from geocert.verify.pooled_floor import (CHI2_MARGIN, Z_OUTLIER, pooled_floor, student_floor,
                                                     wilson_hilferty)
from tests.verify.test_forgeries_review5 import _valid
from tests.verify.test_forgeries_review7 import far_two_view_track  # noqa: F401 (a fixture)

DOFS = np.arange(1, 2 * MAX_VIEWS - 2, 2)  # 2 n - 3 for every track length a job may have


def test_the_chi_square_bounds_hold_for_every_track_length():
    for z, tail in ((0.0, 0.5), (Z_OUTLIER, OUTLIER_TAIL)):
        exact, approximate = chdtri(DOFS, tail), wilson_hilferty(DOFS, z)
        assert np.all(approximate * (1 - CHI2_MARGIN) <= exact) and np.all(exact <= approximate * (1 + CHI2_MARGIN))


def test_the_student_floor_is_below_the_quantile():
    dofs = np.unique(np.r_[np.arange(1, 20001), np.logspace(4, 9, 200).astype(int)])
    exact = stdtrit(dofs, 0.5 + COVERAGE / 2)
    assert np.all([student_floor(float(d)) <= q * (1 + 1e-12) for d, q in zip(dofs, exact)])  # scipy rounds at 1e8


@pytest.mark.parametrize("seed", range(40))
def test_the_floor_never_exceeds_the_pooled_level(seed):
    rng = np.random.default_rng(seed)
    views = rng.integers(2, 9, size=int(rng.integers(1, 60)))
    dofs = 2 * views - 3
    costs = rng.chisquare(dofs) * rng.uniform(0.01, 10.0)
    outliers = rng.random(len(costs)) < 0.1
    costs[outliers] *= rng.uniform(1.0, 50.0, size=int(outliers.sum()))  # some near the cut, some far beyond
    pooled = pooled_increase({n: costs[views == n] for n in np.unique(views).tolist()})
    floor = pooled_floor(costs, dofs)
    assert (pooled is None) == (floor is None)
    if pooled is not None:
        assert floor <= pooled[0] and floor > 0.3 * pooled[0] / (1 + 40 / pooled[1])


def test_the_far_tracks_pool_is_stated_and_checked(far_two_view_track):  # noqa: F811
    result = far_two_view_track[1]
    determinacy = result["tracks"][-1]["determinacy"]
    assert determinacy["pooled_tracks"] == [[0, len(result["tracks"])]]
    for edit in (lambda d: d.pop("pooled_tracks"), lambda d: d.update(pooled_tracks=[[0, 1]]),
                 lambda d: d.update(pooled_tracks=[[0, len(result["tracks"]) + 1]])):
        forged = copy.deepcopy(result)
        edit(forged["tracks"][-1]["determinacy"])
        assert not _valid(forged)

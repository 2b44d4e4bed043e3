"""Proven intervals of the metric stage's intrinsics (autocalibration.metric_sublevel): every K of
the ranges whose metric cost, for the plane at infinity stated, is at most the optimum plus the
stated cost increase has its focal lengths, skew and principal point in them. Checked against K
sampled about the optimum and the true K of synthetic scenes, and by the verifier, which refuses
intervals narrower than what its leaves prove, or at a lower level than stated, and a result
saying proven without them; a wider interval (a weaker statement) verifies."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.formulations.autocalibration import metric_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.solvers.autocalibration import scenes
from geocert.formulations.autocalibration.determinacy import intrinsics
from geocert.verify.autocalibration import read_data
from geocert.verify.checks import verify_any


def solved(seed: int, noise: float = 0.5, views: int = 8) -> tuple[dict, scenes.Scene]:
    scene = scenes.make_scene(views, noise, points=60, seed=seed)
    return solve_job({"kind": "autocalibration", "data": scene.job_data(),
                      "options": {"certificate": "full"}}), scene


def proven_bounds(result: dict) -> np.ndarray:
    found = result["stages"][1]["determinacy"]["proven_intervals"]["intervals"]
    return np.array([[i["lower"], i["upper"]] for i in found])


def metric_setup(result: dict):
    cameras, points, size = read_data(result["certificate"]["data"])
    problem = autocalibration_problem.prepare(cameras, points, size,
                                              dict(result["certificate"]["options"].get("intrinsics") or {}))
    p = autocalibration_problem.plane_from_input(problem, np.array(result["plane_at_infinity"]))
    return problem, metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)


def pixels(problem, w: np.ndarray) -> np.ndarray:
    k = intrinsics(metric_relaxation.omega_of(w))
    K = problem.K0 @ np.array([[k[0], k[2], k[3]], [0.0, k[1], k[4]], [0.0, 0.0, 1.0]])
    return np.array([K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]])


@pytest.fixture(scope="module")
def proven() -> dict:
    result, _ = solved(3)
    assert result["stages"][1]["determinacy"]["proven"] is True
    report = verify_any(result)
    assert report.valid and {"name": "proven_interval", "passed": 1, "failed": 0} in report.checks
    return result


@pytest.mark.parametrize("seed", [1, 2, 4])
def test_every_K_within_the_increase_lies_in_the_proven_intervals(seed):
    """K sampled about the optimum (omega moved along random directions and the cost's least
    determined ones): each of the ranges costing at most the level has its intrinsics inside, the
    samples reach towards the ends, and the true K, when it costs that little, is inside too."""
    result, scene = solved(seed)
    stage = result["stages"][1]
    assert stage["certified"] and stage["determinacy"]["proven"] is True
    assert verify_any(result).valid
    bounds = proven_bounds(result)
    problem, setup = metric_setup(result)
    w = autocalibration_problem.w_of_K(problem, np.array(result["K"]))
    level = stage["cost"] + stage["determinacy"]["proven_intervals"]["cost_increase"]
    lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
    rng = np.random.default_rng(seed)
    J = np.array([(metric_relaxation.residuals(setup, w + 1e-7 * e)
                   - metric_relaxation.residuals(setup, w - 1e-7 * e)) / 2e-7 for e in np.eye(5)]).T
    _, _, vt = np.linalg.svd(J)
    directions = [*vt, *(u / np.linalg.norm(u) for u in rng.normal(size=(40, 5)))]
    inside, reached, value = 0, np.zeros(5), pixels(problem, w)
    for u in directions:
        for step in np.geomspace(1e-8, 1.0, 120):
            for sign in (1.0, -1.0):
                x = w + sign * step * u
                if metric_relaxation.in_domain(setup, x, lo, hi) and metric_relaxation.cost(setup, x) <= level:
                    k = pixels(problem, x)
                    assert np.all(bounds[:, 0] <= k) and np.all(k <= bounds[:, 1]), (k, bounds)
                    reached = np.maximum(reached, np.abs(k - value))
                    inside += 1
    assert inside > 100
    assert np.all(reached[[0, 1, 3, 4]] > 0.05 * (bounds[[0, 1, 3, 4], 1] - bounds[[0, 1, 3, 4], 0]))
    truth = autocalibration_problem.w_of_K(problem, scene.K / scene.K[2, 2])
    if metric_relaxation.cost(setup, truth) <= level:
        k = pixels(problem, truth)
        assert np.all(bounds[:, 0] <= k) and np.all(k <= bounds[:, 1])


def test_the_true_K_costing_within_the_increase_lies_in_the_proven_intervals():
    """Seven scenes (8 views, 0.5% noise): the proven intervals hold the returned K, and the true
    K wherever it costs at most the level for the plane stated (seed 10 here; measured: the true
    focal length in 4 of 7, the estimate's intervals 5 of 7: the proven ones are for the plane
    stated, whose own error moves the optimum, and the truth costs 1.1 to 3.4 times the level in
    the others)."""
    within = 0
    for seed in range(5, 12):
        result, scene = solved(seed)
        bounds = proven_bounds(result)
        K = np.array(result["K"])
        value = np.array([K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]])
        assert np.all(bounds[:, 0] <= value) and np.all(value <= bounds[:, 1])
        problem, setup = metric_setup(result)
        truth = scene.K / scene.K[2, 2]
        level = result["stages"][1]["cost"] + result["stages"][1]["determinacy"]["cost_increase"]
        if metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, truth)) <= level:
            within += 1
            k = np.array([truth[0, 0], truth[1, 1], truth[0, 1], truth[0, 2], truth[1, 2]])
            assert np.all(bounds[:, 0] <= k) and np.all(k <= bounds[:, 1])
    assert within >= 1


def failed(document) -> dict | None:
    report = verify_any(document)
    return None if report.valid else report.first_failure


def forged(result: dict, **changes) -> dict:
    document = copy.deepcopy(result["certificate"])
    document["items"][1]["proof"]["sublevel"].update(changes)
    return document


class TestForgedIntervals:
    @pytest.mark.parametrize("quantity", [0, 1, 3])
    @pytest.mark.parametrize("end,change", [(0, 1e-3), (1, -1e-3), (0, 0.3), (1, -0.3)])
    def test_a_narrowed_interval_is_refused(self, proven, quantity, end, change):
        intervals = copy.deepcopy(proven["certificate"]["items"][1]["proof"]["sublevel"]["intervals"])
        width = intervals[quantity][1] - intervals[quantity][0]
        intervals[quantity][end] += change * width
        first = failed(forged(proven, intervals=intervals))
        assert first["check"] == "proven_interval"

    @pytest.mark.parametrize("end,change", [(0, -0.5), (1, 0.5)])
    def test_a_widened_interval_verifies(self, proven, end, change):
        """A weaker statement its leaves prove as well (as a resection's check reads them)."""
        intervals = copy.deepcopy(proven["certificate"]["items"][1]["proof"]["sublevel"]["intervals"])
        intervals[0][end] += change * (intervals[0][1] - intervals[0][0])
        assert failed(forged(proven, intervals=intervals)) is None

    def test_intervals_at_a_lower_level_than_stated_are_refused(self, proven):
        """A smaller cost increase with the same leaves: the rounds' caps are checked against the
        level, and the result's intervals against its estimate's increase."""
        increase = proven["certificate"]["items"][1]["proof"]["sublevel"]["cost_increase"]
        assert failed(forged(proven, cost_increase=increase * 4))["check"] == "proven_interval"
        result = copy.deepcopy(proven)
        result["certificate"] = forged(proven, cost_increase=increase * 0.5)
        assert failed(result["certificate"]) is None  # true of the lower level (its leaves exclude nothing)
        result["stages"][1]["determinacy"]["proven_intervals"]["cost_increase"] = increase * 0.5
        first = failed(result)
        assert first["check"] == "returned" and "below" in first["detail"]

    def test_a_leaf_dropped_is_refused(self, proven):
        leaves = proven["certificate"]["items"][1]["proof"]["sublevel"]["leaves"]
        assert failed(forged(proven, leaves=leaves[1:]))["check"] == "coverage"

    @pytest.mark.parametrize("increase", [-1.0, 1e300, 5e-324])
    def test_a_negative_huge_or_subnormal_cost_increase_is_refused(self, proven, increase):
        assert failed(forged(proven, cost_increase=increase))["check"] == "proven_interval"

    def test_a_field_it_does_not_have_is_refused(self, proven):
        assert failed(forged(proven, note=1.0))["check"] == "format"

    def test_a_result_saying_proven_with_other_intervals_is_refused(self, proven):
        result = copy.deepcopy(proven)
        result["stages"][1]["determinacy"]["proven_intervals"]["intervals"][0]["lower"] -= 1.0
        assert failed(result)["check"] == "returned"

    def test_a_result_saying_proven_without_a_proof_is_refused(self, proven):
        result = copy.deepcopy(proven)
        del result["certificate"]["items"][1]["proof"]["sublevel"]
        assert verify_any(result["certificate"]).valid  # the certificate alone proves its bound
        assert failed(result)["check"] == "returned"
        result["stages"][1]["determinacy"]["proven_intervals"] = None
        assert failed(result)["check"] == "returned"  # proven: true with nothing proven

    def test_the_affine_stage_saying_proven_is_refused(self, proven):
        result = copy.deepcopy(proven)
        result["stages"][0]["determinacy"]["proven"] = True
        assert failed(result)["check"] == "returned"


def test_no_proven_interval_without_a_full_certificate():
    scene = scenes.make_scene(8, 0.5, points=60, seed=3)
    result = solve_job({"kind": "autocalibration", "data": scene.job_data()})
    document = result["stages"][1]["determinacy"]
    assert document["proven"] is False and document["proven_intervals"] is None

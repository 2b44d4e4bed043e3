"""The direct autocalibration stage's proven interval of the focal length (direct_sublevel): with
a full certificate, a certified fixed-focal stage's determinacy states the interval of the focal
length (f0 sqrt of the views' weighted mean of (w11 + w22) / 2 w33) of every quadric of its scope
costing at most cost_increase more than the certified one, proven by a dual of the order-2
relaxation with the cost row; the verifier recomputes each end from the stated dual, refuses an
interval narrower than they prove, a forged dual or c, and a result whose determinacy states
another interval than its proof."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import direct_solve, scenes
from geocert.formulations.autocalibration import direct
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.core.certificates import pack, unpack
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import rehash

UNIT = {"aspect": [0.95, 1.05], "skew": [-0.01, 0.01], "principal_point": [[-0.1, 0.1], [-0.1, 0.1]],
        "focal": [0.5, 2.0]}


def quantity(K) -> float:
    """The interval's quantity for one K (pixels; here K0 = I): the root of (f_x^2 + f_y^2 + s^2 +
    u^2 + v^2) / 2."""
    K = np.asarray(K, float) / K[2][2]
    return math.sqrt((K[0, 0] ** 2 + K[1, 1] ** 2 + K[0, 1] ** 2 + K[0, 2] ** 2 + K[1, 2] ** 2) / 2)


@pytest.fixture(scope="module")
def result() -> dict:
    """Table 7.1's seed 5 (12 views, 0.2% noise, K = I), chirality "centers"."""
    scene, _ = scenes.table71_scene(5, 0.2, False)
    return solve_job({"kind": "autocalibration",
                      "data": {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()},
                      "options": {"method": "direct", "intrinsics": UNIT, "chirality": "centers",
                                  "certificate": "full", "prove_focal_interval": True,
                                  "time_limit_s": 3600}})


def interval(result: dict) -> tuple[float, float]:
    document = result["stages"][0]["determinacy"]["proven_intervals"]
    assert [i["name"] for i in document["intervals"]] == ["focal"]
    return document["intervals"][0]["lower"], document["intervals"][0]["upper"]


def forged_interval(result: dict, lower: float, upper: float) -> dict:
    """``result`` stating [lower, upper] in its proof and its determinacy alike (rehashed)."""
    from geocert.formulations.autocalibration import direct_sublevel

    forged = copy.deepcopy(result)
    sublevel = forged["certificate"]["items"][0]["proof"]["sublevel"]
    sublevel["interval"] = [lower, upper]
    forged["stages"][0]["determinacy"]["proven_intervals"] = direct_sublevel.proven_document(sublevel)
    rehash(forged["certificate"])
    return forged


class TestGenuine:
    def test_certified_and_proven(self, result):
        stage = result["stages"][0]
        assert stage["certified"], stage["reason"]
        assert stage["determinacy"]["proven"] is True
        sublevel = result["certificate"]["items"][0]["proof"]["sublevel"]
        assert sublevel["lower"] is not None and sublevel["upper"] is not None  # both ends proven by a dual

    def test_verifies(self, result):
        report = verify_any(result)
        assert report.valid, report.first_failure
        assert {"name": "proven_interval", "passed": 1, "failed": 0} in report.checks

    def test_the_truth_and_the_K_returned_lie_inside(self, result):
        """The true K (I: the quantity is 1) and the K returned; the interval a few percent wide at
        most (measured [0.99888, 1.00793])."""
        lower, upper = interval(result)
        assert lower <= 1.0 <= upper
        assert lower <= quantity(result["K"]) <= upper
        assert upper - lower < 0.05


class TestForged:
    @pytest.mark.parametrize("end", [0, 1])
    def test_narrowed_is_refused(self, result, end):
        lower, upper = interval(result)
        cut = 0.01 * (upper - lower)
        forged = forged_interval(result, lower + cut, upper) if end == 0 else forged_interval(result, lower, upper - cut)
        first = verify_any(forged).first_failure
        assert first is not None and first["check"] == "proven_interval" and "narrower" in first["detail"]

    def test_widened_verifies(self, result):
        lower, upper = interval(result)
        assert verify_any(forged_interval(result, lower * 0.9, upper * 1.1)).valid

    def test_a_c_moved_inward_is_refused(self, result):
        """The lower end's c raised to the returned K's value: its dual no longer proves it."""
        forged = copy.deepcopy(result)
        sublevel = forged["certificate"]["items"][0]["proof"]["sublevel"]
        sublevel["lower"][0]["c"] = quantity(result["K"]) ** 2
        rehash(forged["certificate"])
        first = verify_any(forged).first_failure
        assert first is not None and first["check"] == "proven_interval" and "not above 0" in first["detail"]

    def test_a_forged_dual_is_refused(self, result):
        forged = copy.deepcopy(result)
        sublevel = forged["certificate"]["items"][0]["proof"]["sublevel"]
        z = unpack(sublevel["upper"][0]["z"])
        sublevel["upper"][0]["z"] = pack(np.random.default_rng(0).normal(size=z.shape))
        rehash(forged["certificate"])
        first = verify_any(forged).first_failure
        assert first is not None and first["check"] == "proven_interval"

    def test_the_result_stating_another_interval_than_its_proof_is_refused(self, result):
        forged = copy.deepcopy(result)
        forged["stages"][0]["determinacy"]["proven_intervals"]["intervals"][0]["upper"] *= 0.999
        first = verify_any(forged).first_failure
        assert first is not None and first["check"] == "returned"

    def test_proven_without_its_proof_is_refused(self, result):
        forged = copy.deepcopy(result)
        del forged["certificate"]["items"][0]["proof"]["sublevel"]
        rehash(forged["certificate"])
        first = verify_any(forged).first_failure
        assert first is not None and first["check"] == "returned"


def test_the_solvers_interval_holds_the_true_quadrics_focal():
    """Solver side, on another scene: prove_focal's interval, as the verifier's check reads it,
    holds the certified quadric's own focal (it is in the set) and the true quadric's (Table 7.1's
    seed 0: its cost is above the level, 5.05e-4 against 4.79e-4, but its focal is inside)."""
    from types import SimpleNamespace

    from geocert.formulations.autocalibration import direct_sublevel

    scene, _ = scenes.table71_scene(0, 0.2, False)
    problem = autocalibration_problem.prepare(scene.cameras, scene.points, None, UNIT, unit_reference=False)
    setup = direct.setup_for(problem, "centers")
    stage = direct_solve.solve_direct(setup, SimpleNamespace(relaxation_order=2, metric_rel_gap=1e-4, abs_gap=1e-9),
                                      True)
    assert stage.certified
    increase = direct_sublevel.cost_increase(stage.cost, stage.lower_bound, len(setup.cameras))
    sublevel = direct_solve.prove_focal(setup, stage.Q, stage.cost, increase)
    assert sublevel is not None
    lower, upper = direct_sublevel.check(direct.setup_for(problem, "centers", exclude=False), sublevel, (), stage.cost)
    assert sublevel["interval"][0] <= lower and upper <= sublevel["interval"][1]
    assert lower <= direct_sublevel.focal_of(setup.cameras, stage.Q, 1.0) <= upper
    Hi = np.linalg.inv(scene.projective)
    true_Q = setup.from_input(Hi @ np.diag([1.0, 1.0, 1.0, 0.0]) @ Hi.T)
    assert lower <= direct_sublevel.focal_of(setup.cameras, true_Q, 1.0) <= upper


def test_without_the_option_a_full_certificate_states_no_proven_interval():
    """The interval costs tens of seconds against the solve's second: a full certificate alone
    does not ask for it, and its determinacy is the estimate's (not proven)."""
    scene, _ = scenes.table71_scene(5, 0.2, False)
    plain = solve_job({"kind": "autocalibration",
                       "data": {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()},
                       "options": {"method": "direct", "intrinsics": UNIT, "chirality": "centers",
                                   "certificate": "full", "time_limit_s": 3600}})
    assert plain["stages"][0]["certified"]
    assert '"sublevel"' not in json.dumps(plain["certificate"])
    assert not plain["stages"][0]["determinacy"].get("proven")
    assert plain["stages"][0]["determinacy"].get("proven_intervals") is None

"""Issue 37 F5: with the direct method, asking for proven intervals (prove_focal_interval,
prove_intrinsics_intervals) and getting ``proven_intervals: null`` came with no reason: the job's
time limit had stopped the focal length's proof (kinds.direct_autocalibration._prove_focal caught
its Stopped and stated nothing). Every such null now states why in the stage's determinacy
``proven_reason``, which the verifier holds to a text beside a null proven_intervals. The deadline
is simulated (the proof raises Stopped at once), so the outcome does not rest on the clock."""

from __future__ import annotations

import copy
import json

import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import direct_solve, scenes
from geocert.verify.checks import verify_any

UNIT = {"aspect": [0.95, 1.05], "skew": [-0.01, 0.01], "principal_point": [[-0.1, 0.1], [-0.1, 0.1]],
        "focal": [0.5, 2.0]}


def solved(**options) -> dict:
    """Table 7.1's seed 5 (12 views, 0.2% noise), both proofs asked for."""
    scene, _ = scenes.table71_scene(5, 0.2, False)
    return json.loads(json.dumps(solve_job({
        "kind": "autocalibration", "data": {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()},
        "options": {"method": "direct", "intrinsics": UNIT, "chirality": "centers", "prove_focal_interval": True,
                    "prove_intrinsics_intervals": True, "time_limit_s": 3600, **options}})))


def solved_with_proofs_stopped(**options) -> dict:
    """``solved(**options)`` with the proofs stopped by the job's deadline as soon as they start."""
    def at_the_deadline(*args, **kwargs):
        raise direct_solve.Stopped("time_limit", "the job's deadline")

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(direct_solve, "prove_focal", at_the_deadline)
        return solved(**options)


@pytest.fixture(scope="module")
def stopped() -> dict:
    """The proofs stopped by the job's deadline as soon as they start."""
    return solved_with_proofs_stopped(certificate="full")


def test_a_proof_the_deadline_stopped_states_why_and_the_result_verifies(stopped):
    stage = stopped["stages"][0]
    assert stage["certified"], stage.get("reason")
    determinacy = stage["determinacy"]
    assert determinacy["proven_intervals"] is None and determinacy["proven"] is False
    reason = determinacy["proven_reason"]
    assert "time limit" in reason and "focal length" in reason and "other intrinsics" in reason, reason
    report = verify_any(stopped)
    assert report.valid, report.first_failure


def test_a_reason_beside_proven_intervals_or_not_a_text_is_refused(stopped):
    forged = copy.deepcopy(stopped)
    forged["stages"][0]["determinacy"]["proven_reason"] = 37
    report = verify_any(forged)
    assert not report.valid and "proven_reason" in report.first_failure["detail"], report.first_failure


def test_without_a_full_certificate_the_reason_says_so():
    determinacy = solved(certificate="summary")["stages"][0]["determinacy"]
    assert determinacy["proven_intervals"] is None
    assert "certificate 'full'" in determinacy["proven_reason"], determinacy["proven_reason"]

"""Every kind's example job cancelled at each of its first progress calls ends with a result its
model takes, never an exception (review 14: the autocalibration kind raised when cancelled at
its metric stage's first progress); what it certified verifies."""

from __future__ import annotations

import copy

import pytest

from geocert.jobs.runner import solve_job
from geocert.kinds import KINDS
from geocert.verify.checks import verify_any

NAMES = [kind.name for kind in KINDS]


def certified_anything(result: dict) -> bool:
    for value in result.values():
        if isinstance(value, list):
            if any(isinstance(entry, dict) and entry.get("certified") is True for entry in value):
                return True
    return False


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("calls", range(5))
def test_a_cancel_at_an_early_progress_ends_cleanly(name, calls):
    kind = KINDS.get(name)
    asked = []

    def should_stop() -> bool:
        asked.append(True)
        return len(asked) > calls

    job = copy.deepcopy(kind.example)
    job["options"] = {**job.get("options", {}), **({"certificate": "full"} if kind.certifies else {})}
    result = solve_job(job, should_stop=should_stop)
    kind.result_model.model_validate(result)
    if kind.certifies and certified_anything(result):
        report = verify_any(result)
        assert report.valid, report.first_failure


@pytest.mark.parametrize("method, stages", [("direct", ["direct"]), ("stratified", ["affine", "metric"])])
def test_an_autocalibration_cancelled_before_it_starts_states_its_own_method(method, stages):
    """A job cancelled before its one item starts is the kind's never-started item: for the direct
    method its one stage, not the stratified method's two (the verifier refused such a result's
    stage names); nothing is certified and the verifier says exactly that."""
    kind = KINDS.get("autocalibration")
    job = copy.deepcopy(kind.example)
    job["options"] = {"method": method, "certificate": "full"}
    result = solve_job(job, should_stop=lambda: True)
    kind.result_model.model_validate(result)
    assert result["method"] == method
    assert [stage["name"] for stage in result["stages"]] == stages
    assert {stage["status"] for stage in result["stages"]} == {"cancelled"}
    report = verify_any(result)
    assert not report.valid and report.first_failure["detail"] == "no certified item to check"

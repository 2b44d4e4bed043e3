"""A reconstruction's summary states what claims.summarise always writes: its times (time_s,
cpu_s: each stage's elapsed_s and cpu_s) and its calibration claim's model (shared or varying),
so that a document with one deleted is not its writer's (checks.COMPLETE;
reconstruction._check_calibration). Each deletion verified before they were required."""

from __future__ import annotations

import copy
import json

import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored
from tests.verify.test_registration_record_form import off_centre  # noqa: F401 (fixture)


def _verify(document: dict):
    return verify_any(json.loads(json.dumps(document)))


@pytest.mark.parametrize("name", ["reconstruction", "reconstruction_labelled"])
@pytest.mark.parametrize("member", ["time_s", "cpu_s"])
def test_a_summary_without_its_times_is_refused(name, member):
    """Every stored form states both (written since before the first stored document)."""
    result = stored(name)
    assert _verify(result).valid
    del result["summary"][member]
    report = _verify(result)
    assert not report.valid and member in report.first_failure["detail"], report.first_failure


def test_a_calibration_claim_without_its_model_is_refused(off_centre):  # noqa: F811
    """A document of the current form (hashed_options.states_records) states the model; without it
    the claim was read as a shared K's."""
    result = copy.deepcopy(off_centre)
    assert _verify(result).valid and result["summary"]["calibration"]["model"] == "shared"
    del result["summary"]["calibration"]["model"]
    report = _verify(result)
    assert not report.valid and "'model'" in report.first_failure["detail"], report.first_failure


def test_the_stored_form_before_the_record_form_is_read_as_before():
    """An earlier form (its hash not covering registration) is read as it was: its claim's model,
    where absent, as shared (the claim's first form had none)."""
    result = stored("reconstruction")
    del result["summary"]["calibration"]["model"]
    assert _verify(result).valid

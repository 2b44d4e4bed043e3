"""Review 63 class 2: a stage's ``proven_reason`` is one of its writer's forms of words
(core.proven_reasons), on the stage and under the options where its writer states one."""

from __future__ import annotations

import pytest

from geocert.core import proven_reasons
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored

pytestmark = pytest.mark.filterwarnings("ignore")


@pytest.mark.parametrize("key", sorted(proven_reasons.TEMPLATES))
def test_every_writers_text_is_read_as_its_own_form(key):
    text = proven_reasons.reason(key, status="node_limit", seconds=1234.5, error="LinAlgError",
                                 what=proven_reasons.WHAT[1], after=proven_reasons.AFTER[1])
    assert proven_reasons.is_reason(text, (key,)) == key
    assert proven_reasons.is_reason(text + " (enclosure test)", (key,)) is None
    assert proven_reasons.is_reason("proven: " + text, tuple(proven_reasons.TEMPLATES)) is None


def _with_reason(stage: int, text) -> dict:
    document = stored("autocalibration_stratified")  # a full certificate, both stages certified
    document["stages"][stage]["determinacy"]["proven_reason"] = text
    return document


def test_a_writers_reason_on_the_stratified_metric_stage_verifies():
    report = verify_any(_with_reason(1, proven_reasons.reason("metric_none", seconds=20)))
    assert report.valid, report.first_failure


@pytest.mark.parametrize("stage,text", [
    (1, proven_reasons.reason("metric_none", seconds=20) + "; every intrinsic within 0.01%"),
    (1, proven_reasons.reason("not_certified", status="node_limit")),  # the stage is certified
    (1, proven_reasons.reason("not_full")),  # the certificate is full
    (1, proven_reasons.reason("direct_none", what=proven_reasons.WHAT[0], after="")),  # the direct method's
    (0, proven_reasons.reason("metric_none", seconds=20)),  # the affine stage proves nothing
])
def test_a_reason_not_the_writers_for_its_stage_is_refused(stage, text):
    report = verify_any(_with_reason(stage, text))
    assert not report.valid and "proven_reason" in report.first_failure["detail"], report.first_failure

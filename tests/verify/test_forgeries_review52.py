"""Review 52: the two holes review 51 left (a reconstruction's calibration model, the pooled
floor's quantiles unpaid), and a hostile review of the newest checks.

CLASSES
"""

from __future__ import annotations

import copy
import json

import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored


def _refused_naming(forged: dict, check: str, *words: str) -> None:
    report = verify_any(json.loads(json.dumps(forged)))
    assert not report.valid
    assert report.first_failure["check"] == check, report.first_failure
    for word in words:
        assert word in report.first_failure["detail"], report.first_failure


# Review 51's first hole: summary.calibration.model restated "varying" beside one K

@pytest.mark.parametrize("name", ["reconstruction", "reconstruction_labelled"])
def test_a_calibration_model_restated_varying_beside_one_shared_K_is_refused(name):
    result = stored(name)
    assert result["summary"]["calibration"]["model"] == "shared"
    assert verify_any(result).valid
    forged = copy.deepcopy(result)
    forged["summary"]["calibration"]["model"] = "varying"
    _refused_naming(forged, "returned", "summary/calibration/model")

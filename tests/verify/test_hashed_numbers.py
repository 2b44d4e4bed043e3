"""A certificate's hashes are of its numbers' values (certificates.hashed_numbers): a genuine
document re-serialised by a writer that writes 640.0 as 640 and -0.0 as 0 (JavaScript's
JSON.stringify, Go, jq) verifies, and documents hashed before (Python's text of the numbers) still
do. Review 45 class 2 found the refusal on a reconstruction (tests/verify/test_forgeries_review45.py,
slow); these are the fast cases."""

from __future__ import annotations

import json

import pytest

from geocert.core.certificates import data_hash, hashed_numbers, problem_hash
from geocert.jobs.runner import solve_job
from geocert.kinds import get_kind
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored


def _as_javascript_writes(value):
    """Every integral float as an integer, -0.0 as 0 (what JSON.stringify writes)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, list):
        return [_as_javascript_writes(item) for item in value]
    if isinstance(value, dict):
        return {key: _as_javascript_writes(item) for key, item in value.items()}
    return value


@pytest.mark.parametrize("kind", ["triangulation", "resection", "autocalibration"])
def test_a_genuine_document_rewritten_as_javascript_writes_it_verifies(kind):
    example = get_kind(kind).example
    result = solve_job({**example, "options": {"certificate": "full"}})
    rewritten = _as_javascript_writes(json.loads(json.dumps(result)))
    assert json.dumps(rewritten) != json.dumps(result)  # the premise: the document holds integral floats
    assert verify_any(rewritten).valid, verify_any(rewritten).first_failure


def test_hashed_numbers_reads_a_number_as_its_value():
    assert hashed_numbers({"a": [640, 640.0, -0.0, 0, True, None, "640"]}) == {"a": [640.0, 640.0, 0.0, 0.0, True, None, "640"]}
    assert json.dumps(hashed_numbers([-0.0, 0])) == "[0.0, 0.0]"
    assert hashed_numbers(2 ** 60 + 1) == 2 ** 60 + 1  # no float holds it: kept
    assert data_hash("k", {"x": [640, -0.0]}) == data_hash("k", {"x": [640.0, 0.0]})


def test_data_converted_once_hash_as_the_data():
    """The verifier converts a document's data once for all its hashes (converted=True)."""
    data, options = {"x": [640, -0.0, [2, 3.5]], "n": 2 ** 60 + 1}, {"gap": 0, "max_residual": None}
    once = hashed_numbers(data)
    assert data_hash("k", once, converted=True) == data_hash("k", data)
    assert problem_hash("k", once, options, ("gap",), {"f": 1}, converted=True) \
        == problem_hash("k", data, options, ("gap",), {"f": 1})
    assert problem_hash("k", data, options, ("gap",), values=False, converted=True) \
        == problem_hash("k", data, options, ("gap",), values=False)
    assert data_hash("k", once, converted=True) != data_hash("k", data, values=False)


def test_documents_hashed_before_still_verify():
    """The stored documents hashed Python's text of their numbers (data_hash(..., values=False))."""
    document = stored("triangulation_l2l2")
    certificate = document["certificate"]
    assert data_hash(certificate["kind"], certificate["data"], False) == certificate["data_sha256"]
    assert verify_any(document).valid

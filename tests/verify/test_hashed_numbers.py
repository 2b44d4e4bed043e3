"""A certificate's hashes are of its numbers' values (certificates.hashed_numbers): a genuine
document re-serialised by a writer that writes 640.0 as 640 and -0.0 as 0 (JavaScript's
JSON.stringify, Go, jq) verifies, and documents hashed before (Python's text of the numbers) still
do. Review 45 class 2 found the refusal on a reconstruction (tests/verify/test_forgeries_review45.py,
slow); these are the fast cases."""

from __future__ import annotations

import hashlib
import copy
import json
import random

import pytest

from geocert.core.certificates import canonical_json, data_digest, data_hash, hashed_numbers, problem_hash
from geocert.core.determinacy import FORMS
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
    assert hashed_numbers(2 ** 60 + 1) == float(2 ** 60)  # its nearest float, as every reader reads it
    assert hashed_numbers(10 ** 400) == 10 ** 400  # beyond the floats: kept as written
    assert data_hash("k", {"x": [640, -0.0]}) == data_hash("k", {"x": [640.0, 0.0]})


def test_data_written_once_hash_as_the_data():
    """The verifier writes a document's data once for all its hashes (digest=)."""
    data, options = {"x": [640, -0.0, [2, 3.5]], "n": 2 ** 60 + 1}, {"gap": 0, "max_residual": None}
    for values in (True, False):
        digest = data_digest(data, values)
        assert data_hash("k", data, values, digest) == data_hash("k", data, values)
        assert problem_hash("k", data, options, ("gap",), {"f": 1}, values, digest) \
            == problem_hash("k", data, options, ("gap",), {"f": 1}, values)
    assert data_hash("k", data) != data_hash("k", data, False)


def _random_value(rng: random.Random, depth: int = 0):
    pick = rng.randrange(9 if depth < 4 else 6)
    if pick == 0:
        return rng.choice([0, -0.0, 0.0, 1, -1, 640, 2 ** 53 + 1, -(2 ** 60) - 7, 10 ** 400, 5e-324, -1e308, 1e-7,
                           -2.5e-10, 123456789.125, 1e16, 3.0, -17.0])
    if pick == 1:
        return rng.uniform(-1e6, 1e6) * 10.0 ** rng.randrange(-30, 30)
    if pick == 2:
        return rng.randrange(-10 ** 6, 10 ** 6)
    if pick == 3:
        return rng.choice(["", "-0.0", "a\"b 12 -0.0 \\", "é 3.0e5", "x-1", '"12"', "\u00e9\\"])
    if pick == 4:
        return rng.choice([True, False, None])
    if pick == 5:
        return rng.random()
    if pick in (6, 7):
        return [_random_value(rng, depth + 1) for _ in range(rng.randrange(5))]
    return {rng.choice(["a", "b-1", "3", "-0.0", "é", "k\"2"]) + str(i): _random_value(rng, depth + 1)
            for i in range(rng.randrange(4))}


def test_the_hashes_are_of_the_canonical_text_of_the_values():
    """data_digest writes canonical_json(hashed_numbers(data)) to the byte (strings untouched),
    or canonical_json(data) for the earlier form."""
    rng = random.Random(47)
    for _ in range(3000):
        value = _random_value(rng)
        for values, written in ((True, hashed_numbers(value)), (False, value)):
            expected = hashlib.sha256(canonical_json({"kind": "k", "data": written})).hexdigest()
            assert data_hash("k", value, values) == expected, value


def test_documents_hashed_before_still_verify():
    """The stored documents hashed Python's text of their numbers (data_hash(..., values=False))."""
    document = stored("triangulation_l2l2")
    certificate = document["certificate"]
    assert data_hash(certificate["kind"], certificate["data"], False) == certificate["data_sha256"]
    assert verify_any(document).valid


def test_a_document_that_hashed_an_integer_no_float_holds_exactly_still_verifies():
    """Documents hashed while an integer no float holds was kept exact (the values' form before
    review 47) still verify; the same hashes over a changed problem do not."""
    example = get_kind("triangulation").example
    data = copy.deepcopy(example["data"])
    data["cameras"][0] = [[int(v * 2 ** 60) + 1 if v != 0 else 0 for v in row] for row in data["cameras"][0]]
    result = json.loads(json.dumps(solve_job({**example, "data": data,
                                              "options": {**example.get("options", {}), "certificate": "full"}})))
    certificate = result["certificate"]
    assert verify_any(result).valid
    digest = data_digest(certificate["data"], exact_integers=True)
    today = certificate["problem_sha256"]
    certificate["data_sha256"] = data_hash(certificate["kind"], certificate["data"], digest=digest)
    names = tuple(name for name in ("norm", "max_residual", "rel_gap", "abs_gap"))
    for marks in (None, *FORMS):
        rewritten = problem_hash(certificate["kind"], certificate["data"], certificate["options"], names, marks,
                                 digest=digest)
        if problem_hash(certificate["kind"], certificate["data"], certificate["options"], names, marks) == today:
            certificate["problem_sha256"] = rewritten
    assert certificate["problem_sha256"] != today and certificate["data_sha256"] != data_hash("triangulation", data)
    report = verify_any(result)
    assert report.valid, report.first_failure
    certificate["data"]["cameras"][0][0][0] += 2 ** 12  # another problem under the same hashes
    assert verify_any(result).first_failure["check"] == "data_hash"

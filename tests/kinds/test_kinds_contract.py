"""Every kind in the registry meets the same contract (in-process: no Redis, no worker): bad
input is refused naming the field, the result fits the kind's result model, a full certificate
verifies and a tampered one is refused (a kind that issues estimates only, ``certifies = False``:
no certificate is issued or accepted, and the verifier says so). And a new kind plugs in with one
registry line."""

from __future__ import annotations

import copy
import json
import subprocess
import sys

import pytest
from pydantic import ValidationError

from geocert.jobs.runner import parse_job, solve_job
from geocert.kinds import KINDS
from geocert.core.geometry import InputError
from geocert.core.certificates import FORMAT, VERSION
from geocert.verify.checks import verify_any, verify_document

KIND_NAMES = KINDS.names()


def full(job: dict) -> dict:
    return {**job, "options": {**job.get("options", {}), "certificate": "full"}}


@pytest.mark.parametrize("name", KIND_NAMES)
class TestEveryKind:
    def test_bad_input_names_the_field(self, name):
        kind = KINDS.get(name)
        job = copy.deepcopy(kind.example)
        job["data"][kind.item_key] = "not a list"
        with pytest.raises(InputError) as error:
            parse_job(job)
        assert error.value.field.startswith(f"data/{kind.item_key}")
        with pytest.raises(ValidationError):
            kind.request_model.model_validate(job)
        with pytest.raises(InputError) as error:
            parse_job({**kind.example, "options": {"rel_gap": "1e-3"}})
        assert error.value.field == "options/rel_gap"

    def test_the_example_is_a_valid_request(self, name):
        kind = KINDS.get(name)
        kind.request_model.model_validate(kind.example)

    def test_result_fits_the_model_and_its_certificate_verifies(self, name):
        kind = KINDS.get(name)
        if not certifies(kind):
            return self.check_estimates_kind(kind)
        result = solve_job(full(kind.example))
        kind.result_model.model_validate(result)
        assert all(item["certified"] for item in result[kind.item_key])
        report = verify_any(result)
        assert report.valid, report.first_failure

    def test_tampering_is_refused(self, name):
        kind = KINDS.get(name)
        if not certifies(kind):  # a certificate claimed for a kind that issues none is refused, saying why
            forged = {"format": FORMAT, "version": VERSION, "kind": name, "options": {}, "data": kind.example["data"],
                      "data_sha256": "", "problem_sha256": "", "items": [{"index": 0, "certified": True}]}
            report = verify_document(forged)
            assert not report.valid and "estimates" in report.first_failure["detail"]
            return
        result = solve_job(full(kind.example))
        forged = copy.deepcopy(result)
        forged["certificate"]["items"][0]["cost"] *= 0.5
        assert not verify_any(forged).valid
        moved = copy.deepcopy(result)
        moved[kind.item_key][0]["cost"] = 0.0
        assert verify_any(moved).first_failure["check"] == "returned"


    @staticmethod
    def check_estimates_kind(kind):
        """A kind that issues estimates, never certificates (``certifies = False``): its result fits
        its model, every item says it is not certified, asking for a certificate is refused naming
        the option, and the verifier answers that there is nothing to verify; so does ``geocert
        verify``, without suggesting the option the kind refuses."""
        result = solve_job(kind.example)
        kind.result_model.model_validate(result)
        assert result[kind.item_key] and not any(item["certified"] for item in result[kind.item_key])
        with pytest.raises(InputError) as error:
            parse_job(full(kind.example))
        assert error.value.field == "options/certificate"
        report = verify_any(result)
        assert not report.valid and "nothing to verify" in report.first_failure["detail"]
        command = subprocess.run([sys.executable, "-m", "geocert.app.cli", "verify", "-"], input=json.dumps(result),
                                 capture_output=True, text=True)
        assert command.returncode == 2 and "nothing to verify" in command.stderr
        assert "certificate" not in command.stderr.split("holds no certificate", 1)[1]


def certifies(kind) -> bool:
    """Whether a kind issues certificates (the default) or estimates only (``certifies = False``)."""
    return kind.certifies


def test_the_triangulation_example_is_a_clean_first_template():
    """The web page's first template (the triangulation kind's example, GET /v1/problems): every
    track certified and determined, no warning; its observations fitted no point before, and the
    page's first answer read "Not determined by the data: tracks #0, #1"."""
    result = solve_job(KINDS.get("triangulation").example)
    for track in result["tracks"]:
        assert track["certified"] and track["determinacy"]["determined"] is True, track["determinacy"]
        assert track["determinacy"]["warnings"] == []


class TestOneLineToAddAKind:
    """A toy kind (tests/kinds/toy_kind.py) registered with one line: solved, verified, served in the
    API's schema and /v1/problems, and checked by the same contract."""

    def test_registered_kind_is_solved_verified_and_served(self):
        code = """
import json
from geocert.kinds import KINDS
from tests.kinds import toy_kind
KINDS.register(toy_kind.KIND)  # the one line
from geocert.jobs.runner import solve_job
from geocert.core.certificates import FORMAT, VERSION
from geocert.verify.checks import verify_any, verify_document
from geocert.app.cli import openapi_document
from geocert.app.api.routes.service import list_problems
result = solve_job({**toy_kind.KIND.example, "options": {"certificate": "full"}})
forged = json.loads(json.dumps(result)); forged["certificate"]["items"][0]["point"] = [9.0, 9.0]
forged["sets"][0]["point"] = [9.0, 9.0]
schema = openapi_document()["components"]["schemas"]
print(json.dumps({"valid": verify_any(result).valid, "forged": verify_any(forged).first_failure["check"],
                  "point": result["sets"][0]["point"], "in_schema": "CentroidJob" in schema,
                  "problems": [p.kind for p in list_problems()]}))
"""
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        assert out.returncode == 0, out.stderr[-2000:]
        seen = json.loads(out.stdout.strip().splitlines()[-1])
        assert seen["valid"] and seen["forged"] in ("objective", "leaf_bounds")
        assert seen["point"] == [1.0, 1.0] and seen["in_schema"] and "centroid" in seen["problems"]

"""A number written with more digits than Python's parser reads (sys.get_int_max_str_digits, 4300)
is valid JSON, so not a syntax error: every way a body is read answers it as a 422 naming the
body, as POST /v1/certificates/verify does; it answered a generic 400 without a field
(POST /v1/jobs), a 500 (POST /v1/orient, large submissions: processes.validated) and a
traceback, exit 1 (`geocert solve`). Quick tier: no server."""

from __future__ import annotations

import json
import subprocess
import sys

from geocert.kinds import KINDS
from tests.app.test_one_pass_body import post  # noqa: F401  (the fixture: the real app, the submission stubbed)

LONG = "1" + "0" * 5000  # an integer no value the API takes is written with


def job_with_a_long_integer() -> str:
    example = json.dumps(next(kind for kind in KINDS if kind.name == "triangulation").example)
    assert '"views": [0, 1]' in example
    return example.replace('"views": [0, 1]', f'"views": [0, {LONG}]', 1)


def test_a_job_read_by_the_route_answers_422_naming_the_body(post):
    status, answer, received, _ = post(job_with_a_long_integer())
    assert status == 422 and not received, answer
    assert [e["field"] for e in answer["errors"]] == ["body"] and "4300 digits" in answer["errors"][0]["reason"]


def test_a_body_read_in_a_process_is_an_input_error_not_a_crash():
    from pydantic import TypeAdapter

    from geocert.app import processes
    from geocert.app.schemas import JOB_REQUEST, OrientRequest

    for model, body in ((TypeAdapter(OrientRequest), f'{{"cameras": [{LONG}], "points": []}}'),
                        (JOB_REQUEST, job_with_a_long_integer())):
        request, error = processes.validated(model, body.encode())
        assert request is None and error[:2] == ("input", "body") and "4300 digits" in error[2], error


def test_geocert_solve_exits_2_with_a_problem_document(tmp_path):
    path = tmp_path / "job.json"
    path.write_text(job_with_a_long_integer())
    done = subprocess.run([sys.executable, "-m", "geocert.app.cli", "solve", str(path)], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 2, done.stderr[-500:]
    problem = json.loads(done.stderr.strip().splitlines()[-1])
    assert problem["status"] in (400, 422) and "4300 digits" in problem["detail"]

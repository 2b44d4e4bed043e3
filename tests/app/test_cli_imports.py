"""`geocert solve <job>` imports what the job's kind needs, not every kind's solvers and models (a
one-shot solve's CPU time is mostly imports otherwise: issue 35's comparison with COLMAP measures
the process), and validates the job exactly as the API's union of kinds does."""

from __future__ import annotations

import copy
import json
import subprocess
import sys

import pytest
from pydantic import ValidationError

from tests.support import ROOT

EXAMPLES = ROOT / "examples"

# Loaded by other kinds only: a triangulation job needs none of them.
OTHER_KINDS_MODULES = ("geocert.app.schemas", "geocert.kinds.autocalibration", "geocert.kinds.bilinear",
                       "geocert.kinds.stereo_lines", "geocert.kinds.reconstruction",
                       "geocert.pipelines.reconstruction", "geocert.solvers.lines")

SOLVE_AND_LIST_MODULES = """
import contextlib, io, json, sys
from geocert.app.cli import main
out = io.StringIO()
with contextlib.redirect_stdout(out):
    code = main(["solve", "--compact", sys.argv[1]])
print(json.dumps({"code": code, "result": json.loads(out.getvalue()), "modules": sorted(sys.modules)}))
"""


def test_solving_a_triangulation_job_imports_no_other_kind():
    """In a fresh process, after `geocert solve` of the triangulation example: none of the other
    kinds' modules is loaded, and the result is the one the job runner gives in-process."""
    run = subprocess.run([sys.executable, "-c", SOLVE_AND_LIST_MODULES, str(EXAMPLES / "triangulation.json")],
                         capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert run.returncode == 0, run.stderr
    answer = json.loads(run.stdout)
    assert answer["code"] == 0
    loaded = [name for name in OTHER_KINDS_MODULES if name in answer["modules"]]
    assert loaded == [], f"geocert solve of a triangulation job imported {loaded}"
    assert "geocert.kinds.triangulation" in answer["modules"]

    from geocert.app.schemas import JOB_REQUEST
    from geocert.jobs.runner import solve_job

    job = json.loads((EXAMPLES / "triangulation.json").read_text())
    expected = solve_job(JOB_REQUEST.dump_python(JOB_REQUEST.validate_python(job), mode="json"))
    got = answer["result"]
    assert len(got["tracks"]) == len(expected["tracks"])
    for mine, theirs in zip(got["tracks"], expected["tracks"]):
        assert mine["certified"] == theirs["certified"]
        assert mine["point"] == pytest.approx(theirs["point"], rel=1e-6, abs=1e-6)
        assert mine["cost"] == pytest.approx(theirs["cost"], rel=1e-6, abs=1e-9)


def bodies() -> list:
    """Every example job, and each made invalid in several ways, and bodies whose kind is wrong."""
    found = []
    for path in sorted(EXAMPLES.glob("*.json")):
        job = json.loads(path.read_text())
        found.append(job)
        for change in ({"data": 5}, {"options": {"no_such_option": 1}}, {"extra_member": 1}):
            found.append(copy.deepcopy(job) | change)
        found.append({name: value for name, value in job.items() if name != "data"})
    return found + [{"kind": "no_such_kind"}, {"kind": 3}, {}, [], "text"]


def test_the_command_line_validates_a_job_as_the_api_does():
    """The validator `geocert solve` picks from the job's kind accepts and writes back what the API's
    union does, and names the same fields and reasons when it refuses."""
    from geocert.app.cli import job_request_adapter
    from geocert.app.errors import validation_problem
    from geocert.app.schemas import JOB_REQUEST

    def outcome(adapter, body):
        try:
            return adapter.dump_python(adapter.validate_python(body), mode="json")
        except ValidationError as exc:
            return validation_problem(exc.errors())

    for body in bodies():
        assert outcome(job_request_adapter(body), body) == outcome(JOB_REQUEST, body), str(body)[:200]

"""The options a submission's tasks are sized from (job_submission._as_run): those parsed with
the job's checks, or, when a default above this server's maximum was lowered to it, the
lowered ones."""

from __future__ import annotations

import numpy as np

from geocert.app import job_submission
from geocert.app.schemas import JOB_REQUEST
from geocert.settings import get_settings
from tests.support import triangulation_job


def checked(job: dict):
    body = JOB_REQUEST.validate_python(job)
    request, kind, parsed, options = job_submission._checked(body)
    return body, request, kind, parsed, options, dict(request["options"])


def test_options_parsed_with_the_checks_are_kept_unless_a_default_was_lowered(monkeypatch):
    job = triangulation_job(np.random.default_rng(3), tracks=3, views=3, norm="L2L2")
    job["options"].pop("time_limit_s", None)
    body, request, kind, parsed, options, given = checked(job)
    job_submission._check_limits(kind, parsed, body, request)
    assert job_submission._as_run(kind, request, options, given) is options  # nothing lowered: not parsed again

    body, request, kind, parsed, options, given = checked(job)
    lowered = options.time_limit_s / 4
    monkeypatch.setattr(get_settings(), "max_item_time_limit_s", lowered)
    job_submission._check_limits(kind, parsed, body, request)
    run = job_submission._as_run(kind, request, options, given)
    assert request["options"]["time_limit_s"] == lowered and run.time_limit_s == lowered
    assert kind.time_bound_s(parsed, run) < kind.time_bound_s(parsed, options)

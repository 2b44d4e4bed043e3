"""The options a submission is checked, sized and run with: held to this server's maxima (a
default above one lowered to it, one given above refused) before they are parsed, and parsed
once, as the job will run them."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.app import job_submission
from geocert.app.errors import ApiProblem
from geocert.app.schemas import JOB_REQUEST
from geocert.jobs import runner
from geocert.settings import get_settings
from tests.support import triangulation_job


def submitted(job: dict, monkeypatch):
    """_checked and _check_limits on ``job``, and how many times its options were parsed."""
    parses = []
    parse = runner.options_from
    monkeypatch.setattr(runner, "options_from", lambda *args, **kw: parses.append(args) or parse(*args, **kw))
    body = JOB_REQUEST.validate_python(job)
    request, kind, parsed, options = job_submission._checked(body)
    job_submission._check_limits(kind, parsed, request)
    return request, kind, parsed, options, len(parses)


def test_options_are_parsed_once_as_they_run_even_when_a_default_is_lowered(monkeypatch):
    job = triangulation_job(np.random.default_rng(3), tracks=3, views=3, norm="L2L2")
    job["options"].pop("time_limit_s", None)
    request, kind, parsed, options, parses = submitted(job, monkeypatch)
    assert parses == 1
    default = options.time_limit_s

    lowered = default / 4
    monkeypatch.setattr(get_settings(), "max_item_time_limit_s", lowered)
    request, kind, parsed, run, parses = submitted(job, monkeypatch)
    assert parses == 1  # not parsed again after the maxima
    assert request["options"]["time_limit_s"] == lowered and run.time_limit_s == lowered
    assert kind.time_bound_s(parsed, run) < kind.time_bound_s(parsed, options)


def test_an_option_given_above_the_servers_maximum_is_refused_naming_it(monkeypatch):
    job = triangulation_job(np.random.default_rng(3), tracks=3, views=3, norm="L2L2")
    job["options"]["time_limit_s"] = 20.0
    monkeypatch.setattr(get_settings(), "max_item_time_limit_s", 5.0)
    with pytest.raises(ApiProblem) as refused:
        submitted(job, monkeypatch)
    assert refused.value.status == 422 and refused.value.field == "options/time_limit_s"

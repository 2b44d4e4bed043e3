"""No result states a non-finite number (jobs.finite): a number that is inf or NaN fails the job
naming its field, rather than going out as null (the result models' writer) or as Infinity (not
JSON), which the verifier refuses either way. Issue 33's open item: a resection in a tiny world unit
wrote inf residuals and an all-zero camera, and nothing stopped it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from geocert.jobs.finite import NonFiniteResult, refuse_non_finite
from geocert.jobs.runner import solve_job
from geocert.kinds import get_kind
from tests.support import run_with_redis


@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan, np.float64("inf")])
def test_a_non_finite_number_anywhere_is_named(bad):
    with pytest.raises(NonFiniteResult) as refused:
        refuse_non_finite({"maps": [{"cost": 1.0}, {"residuals": [[0.5, 1.0], [2.0, bad]]}]})
    assert refused.value.field == "/maps/1/residuals/1/1"
    with pytest.raises(NonFiniteResult) as refused:
        refuse_non_finite({"point": np.array([1.0, bad, 2.0])})
    assert refused.value.field == "/point/1"
    refuse_non_finite({"maps": [{"cost": 1.0, "matrix": None, "note": "x", "count": 3, "ok": True}]})


def _inject(monkeypatch, kind_name: str, edit) -> None:
    kind = get_kind(kind_name)
    solve_item = kind.solve_item
    monkeypatch.setattr(kind, "solve_item", lambda *args, **kwargs: edit(solve_item(*args, **kwargs)))
    monkeypatch.setattr(kind, "solve_batch", None, raising=False)


@pytest.mark.parametrize("certificate", ["summary", "full"])
def test_a_kinds_item_holding_inf_fails_the_job(monkeypatch, certificate):
    def edit(item):
        item["residuals"][1][0] = math.inf
        return item

    _inject(monkeypatch, "resection", edit)
    job = {**get_kind("resection").example}
    job["options"] = {**job.get("options", {}), "certificate": certificate}
    with pytest.raises(NonFiniteResult) as refused:
        solve_job(job)
    assert refused.value.field == "/maps/0/residuals/1/0"
    assert "not a finite number" in str(refused.value)


def test_a_non_finite_stat_fails_the_job(monkeypatch):
    from geocert.jobs import runner

    stats_from = runner.stats_from
    monkeypatch.setattr(runner, "job_stats", lambda items, elapsed: {**stats_from(runner.item_sums(items), elapsed),
                                                                      "elapsed_s": math.nan})
    with pytest.raises(NonFiniteResult) as refused:
        solve_job(get_kind("triangulation").example)
    assert refused.value.field == "/stats/elapsed_s"


STORED_INF = """
import json
import math
import os
from geocert.jobs.runner import parse_job, solve_job
from geocert.kinds import get_kind
from geocert.workers import tasks
from geocert.jobs.store import JobStore

jobs = JobStore.from_url(os.environ["GEOCERT_REDIS_URL"])
job = get_kind("resection").example
job = {**job, "options": {**job.get("options", {}), "certificate": "full"}}
meta = jobs.create("resection", job, 1, 100, "someone", chunk_key="maps")
items = solve_job(job)["maps"]
items[0]["cost"] = math.inf  # as a solver's defect would leave it, stored by an older worker
assert jobs.mark_running(meta["id"])
jobs.save_items(meta["id"], dict(enumerate(items)))
kind, _, options = parse_job(job)
assert jobs.claim_end(meta["id"])
tasks.end_with_result(jobs, meta["id"], kind, options)
ended = jobs.get(meta["id"])
print(json.dumps({"status": ended["status"], "error": ended.get("error")}))
"""


def test_a_stored_item_holding_inf_ends_the_job_failed_naming_it(tmp_path):
    """The end of a job (which holds its end claim) fails it with the field named, rather than
    leaving it running or writing null."""
    ended = run_with_redis(tmp_path, STORED_INF)
    assert ended["status"] == "failed"
    assert ended["error"]["title"] == "Non-finite number in the result"
    assert ended["error"]["errors"][0]["field"] == "/maps/0/cost"


@pytest.mark.parametrize("document,field", [
    ([1.0, "x", math.nan], "/2"), ((1, None, [2.0, -math.inf]), "/2/1"), ({"a": [True, 10**400, math.inf]}, "/a/2"),
    ({"a": np.array([[1.0, 2.0], [3.0, np.nan]])}, "/a/1/1"), ([np.float32("inf")], "/0"),
])
def test_the_fast_path_misses_none(document, field):
    """The clean document's pass reads a list of numbers at once: a list mixing numbers with
    other values, or an int beyond the floats, is read member by member."""
    with pytest.raises(NonFiniteResult) as refused:
        refuse_non_finite(document)
    assert refused.value.field == field

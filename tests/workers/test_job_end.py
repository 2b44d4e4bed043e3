"""How a job ends, in a real Redis (a subprocess: the task module needs GEOCERT_REDIS_URL when it
is imported): a job cancelled after its solvers' last check ends "cancelled", its result whole."""

from __future__ import annotations

from tests.support import run_with_redis

CODE = """
import json
import os
from geocert.jobs.runner import parse_job, solve_job
from geocert.kinds import get_kind
from geocert.workers import tasks
from geocert.jobs.store import JobStore

jobs = JobStore.from_url(os.environ["GEOCERT_REDIS_URL"])
job = get_kind("triangulation").example
meta = jobs.create("triangulation", job, 2, 100, "someone", chunk_key="tracks")
items = solve_job(job)["tracks"]
assert jobs.mark_running(meta["id"])
jobs.save_items(meta["id"], dict(enumerate(items)))
jobs.request_cancel(meta["id"])  # as the last item ended: no solver saw it (a stage that ended at its root)
kind, _, options = parse_job(job)
assert jobs.claim_end(meta["id"])
tasks.end_with_result(jobs, meta["id"], kind, options)
ended = jobs.get(meta["id"])
print(json.dumps({"status": ended["status"], "items": [item["status"] for item in jobs.result(meta["id"])["tracks"]]}))
"""


def test_a_job_cancelled_after_its_last_check_ends_cancelled_with_its_result_whole(tmp_path):
    ended = run_with_redis(tmp_path, CODE)
    assert ended == {"status": "cancelled", "items": ["optimal", "optimal"]}

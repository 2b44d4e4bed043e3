"""A job's options are parsed once where a task takes it from the queue, and the job ends with
those: the task that ends a job past its clock hands on the options it parsed, and an end no task
holds them at (a worker's heartbeat, a solve task's errback) rebuilds them as the API stored them,
never parsing them again (a second parse could end the job with options its items were not
solved with). In a real Redis, in a subprocess, as tests/workers/test_job_clock.py does."""

from __future__ import annotations

from tests.support import run_with_redis

CODE = """
import copy
import json
import os
import time

from geocert.jobs.runner import solve_job
from geocert.kinds import get_kind
from geocert.workers import tasks
from geocert.jobs.store import JobStore

jobs = JobStore.from_url(os.environ["GEOCERT_REDIS_URL"])
LIMIT_S = 0.5
job = copy.deepcopy(get_kind("triangulation").example)
job["data"]["tracks"] = job["data"]["tracks"][:1] * 3
job["options"] = {**job.get("options", {}), "job_time_limit_s": LIMIT_S}
solved = solve_job(job)["tracks"]
parses = []
parse = tasks.options_from
tasks.options_from = lambda *args, **kwargs: parses.append(args) or parse(*args, **kwargs)
solve_items = tasks.solve_items


def past_clock(job_id):
    started = jobs.fields(job_id, "started_at")["started_at"]
    time.sleep(max(0.0, started + LIMIT_S - time.time()) + 0.05)


def new_job_with_its_first_item():
    job_id = jobs.create("triangulation", job, 3, 1, "someone", chunk_key="tracks", job_time_limit_s=LIMIT_S)["id"]
    assert jobs.take_slot(job_id, "a", 0) and jobs.start_chunk(job_id, 0, 1, "kind", task_id="a") is not None
    jobs.save_items(job_id, {0: solved[0]})
    tasks._leave(jobs, job_id, "a")
    return job_id


def statuses(job_id):
    return [t["status"] for t in jobs.result(job_id)["tracks"]]


out = {}
# 1. A task solving the second item while the clock runs out: the last to leave, it ends the job.
one = new_job_with_its_first_item()
tasks.solve_items = lambda *args, **kwargs: [solve_items(*args, **kwargs), past_clock(one)][0]
tasks.solve_chunk.apply(args=(one, 1, 2), task_id="b")
out["one"] = [jobs.fields(one)["status"], statuses(one), len(parses)]
# 2. No task busy past the clock: a worker's heartbeat ends it, with the options as stored.
parses.clear()
two = new_job_with_its_first_item()
past_clock(two)
ended = tasks.end_jobs_past_clock(jobs)
out["two"] = [ended == [two], statuses(two), len(parses)]
print(json.dumps(out))
"""


def test_a_job_ends_with_the_options_its_task_parsed_never_parsing_them_again(tmp_path):
    out = run_with_redis(tmp_path, CODE, timeout=300)
    assert out["one"] == ["succeeded", ["optimal", "optimal", "time_limit"], 1]  # the task's own parse only
    assert out["two"] == [True, ["optimal", "time_limit", "time_limit"], 0]

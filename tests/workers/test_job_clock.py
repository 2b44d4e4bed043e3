"""A many-item job past its clock in all (job_time_limit_s) ends as soon as none of its tasks is
busy, from whichever process sees it first: the last running task to leave, a task of it taken
from the queue, or a worker's heartbeat. It ends ``succeeded`` with the items stored (the one a
running task's clock stopped included), every other item ``time_limit`` "not started"; its tasks
taken from the queue after that solve and store nothing. In a real Redis, in a subprocess (the
task module needs GEOCERT_REDIS_URL when it is imported); the clock's passing is a precondition
waited for, never an outcome timed."""

from __future__ import annotations

from tests.support import run_with_redis

SETUP = """
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
out = {}


def new_job():
    return jobs.create("triangulation", job, 3, 1, "someone", chunk_key="tracks", job_time_limit_s=LIMIT_S)["id"]


def run(job_id, task_id, start, items=(), leave=True):
    # A task of the job: started (busy on it), its items stored, gone.
    assert jobs.take_slot(job_id, task_id, 0)
    assert jobs.start_chunk(job_id, start, start + 1, "kind", task_id=task_id) is not None
    if items:
        jobs.save_items(job_id, {start: solved[start]})


def past_clock(job_id):
    started = jobs.fields(job_id, "started_at")["started_at"]
    time.sleep(max(0.0, started + LIMIT_S - time.time()) + 0.05)


def tracks(job_id):
    return [(t["status"], "not started" in (t["reason"] or "")) for t in jobs.result(job_id)["tracks"]]
"""

CODE = SETUP + """
# 1. Two tasks running at the clock: the job waits for the last to leave, which ends it.
one = new_job()
run(one, "a", 0, items=True)
run(one, "b", 1)
tasks._leave(jobs, one, "a")
past_clock(one)
out["heartbeat_while_busy"] = tasks.end_jobs_past_clock(jobs)
out["status_while_busy"] = jobs.fields(one)["status"]
jobs.save_items(one, {1: solved[1]})  # b's item, stopped by the clock with its best answer
tasks._leave(jobs, one, "b")
out["ended_by_last_task"] = jobs.fields(one)["status"]
out["tracks_one"] = tracks(one)
events = jobs.r.xlen(jobs.key(one, "events"))
finished = jobs.fields(one, "finished_at")["finished_at"]
tasks.solve_chunk.apply(args=(one, 2, 3), task_id="late")  # its last task, taken from the queue now
out["late_task_wrote"] = [jobs.r.xlen(jobs.key(one, "events")) - events,
                          jobs.fields(one, "finished_at")["finished_at"] - finished,
                          jobs.r.exists(jobs.key(one, "items"))]

# 2. No task running at the clock (a task whose worker is gone: busy, its slot never renewed):
# the heartbeat ends it.
two = new_job()
run(two, "c", 0, items=True)
tasks._leave(jobs, two, "c")
jobs.start_chunk(two, 1, 2, "kind", task_id="ghost")
past_clock(two)
out["heartbeat_ended"] = tasks.end_jobs_past_clock(jobs) == [two]
out["tracks_two"] = tracks(two)

# 3. Its next task taken from the queue past the clock ends it, solving nothing.
three = new_job()
run(three, "d", 0, items=True)
tasks._leave(jobs, three, "d")
past_clock(three)
tasks.solve_chunk.apply(args=(three, 1, 2), task_id="next")
out["ended_by_queued_task"] = jobs.fields(three)["status"]
out["tracks_three"] = tracks(three) if out["ended_by_queued_task"] == "succeeded" else None
out["deadlines_left"] = jobs.r.zcard(jobs.DEADLINES)
print(json.dumps(out))
"""


def test_a_job_past_its_clock_ends_once_no_task_of_it_is_busy(tmp_path):
    out = run_with_redis(tmp_path, CODE, timeout=300)
    kept, not_started = ["optimal", False], ["time_limit", True]
    assert out["heartbeat_while_busy"] == [] and out["status_while_busy"] == "running"
    assert out["ended_by_last_task"] == "succeeded"
    assert out["tracks_one"] == [kept, kept, not_started]
    assert out["late_task_wrote"] == [0, 0, 0]
    assert out["heartbeat_ended"] and out["tracks_two"] == [kept, not_started, not_started]
    assert out["ended_by_queued_task"] == "succeeded" and out["tracks_three"] == [kept, not_started, not_started]
    assert out["deadlines_left"] == 0


# The options a job's tasks are solved with are parsed where a task takes the job from the queue
# (tasks.options_from), and the job ends with those: the task ending a job past its clock hands
# on the options it parsed, and an end no task holds them at (a worker's heartbeat, a solve task's
# errback) rebuilds them as the API stored them; none parses them again (a second parse could end
# the job with options its items were not solved with).
ONCE = SETUP + """
parses = []
parse, solve_items = tasks.options_from, tasks.solve_items
tasks.options_from = lambda *args, **kwargs: parses.append(args) or parse(*args, **kwargs)

# 1. A task solving the second item while the clock runs out: the last to leave, it ends the job.
one = new_job()
run(one, "a", 0, items=True)
tasks._leave(jobs, one, "a")
tasks.solve_items = lambda *args, **kwargs: [solve_items(*args, **kwargs), past_clock(one)][0]
tasks.solve_chunk.apply(args=(one, 1, 2), task_id="b")
out["one"] = [jobs.fields(one)["status"], tracks(one), len(parses)]

# 2. No task busy past the clock: a worker's heartbeat ends it.
parses.clear()
two = new_job()
run(two, "c", 0, items=True)
tasks._leave(jobs, two, "c")
past_clock(two)
out["two"] = [tasks.end_jobs_past_clock(jobs) == [two], tracks(two), len(parses)]
print(json.dumps(out))
"""


def test_a_job_ends_with_the_options_its_task_parsed_never_parsing_them_again(tmp_path):
    out = run_with_redis(tmp_path, ONCE, timeout=300)
    kept, not_started = ["optimal", False], ["time_limit", True]
    assert out["one"] == ["succeeded", [kept, kept, not_started], 1]  # the task's own parse, once
    assert out["two"] == [True, [kept, not_started, not_started], 0]

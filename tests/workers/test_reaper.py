"""The reaper's rounds, in a real Redis (a subprocess: the task module needs GEOCERT_REDIS_URL when
it is imported): a job found stranded is re-queued on its second sighting, not its first, so a task
being delivered at that moment (taken from its queue, not yet recorded as delivered) is not doubled
by a re-queue. (A stranded job rescued end to end by a worker: tests/service/test_faults.py; a
killed worker's task delivered again, not re-queued: tests/service/test_durability.py.)"""

from __future__ import annotations

from tests.support import run_with_redis

CODE = """
import json, os, sys, time
from geocert.workers import reaper, tasks
from geocert.jobs.store import JobStore

STALE_AFTER_S = 30.0
jobs = JobStore.from_url(os.environ["GEOCERT_REDIS_URL"])
requeued = []

class Sent:  # the chunks the reaper queues again, recorded instead of published
    def __init__(self, args):
        requeued.append(list(args))
        self.id = f"task-{len(requeued)}"

tasks.solve_chunk.apply_async = lambda args, **_: Sent(args)

def stranded_job():
    # running, its last sign of life long past, no task queued or delivered
    request = {"kind": "triangulation", "data": {"cameras": [], "tracks": [None] * 4}, "options": {}}
    job_id = jobs.create("triangulation", request, 4, 2, "someone")["id"]
    assert jobs.mark_running(job_id)
    lost_long_ago(job_id)
    return job_id

def lost_long_ago(job_id):
    jobs.r.zadd(JobStore.RUNNING, {job_id: time.time() - 10 * STALE_AFTER_S})

def a_round():
    jobs.r.delete(reaper.LOCK)  # rounds are every_s apart; here, at once
    return [list(done) for done in reaper.reap(jobs, STALE_AFTER_S, every_s=5)]

case = sys.argv[1]
job_id = stranded_job()
if case == "past its clock":  # its deadline long past: the heartbeat's to end (tasks.end_jobs_past_clock)
    jobs.r.zadd(JobStore.DEADLINES, {job_id: time.time() - 5 * STALE_AFTER_S})
rounds = [a_round()]
if case == "started between":
    jobs.touch(job_id)  # the task being delivered starts...
    lost_long_ago(job_id)  # ... and is lost too, long ago
    rounds.append(a_round())
rounds.append(a_round())
print(json.dumps({"job": job_id, "rounds": rounds, "requeued": requeued, "reaps": jobs.field(job_id, "reaps")}))
"""


def run_rounds(tmp_path, case: str) -> dict:
    return run_with_redis(tmp_path, CODE, case)


def test_a_stranded_job_is_requeued_on_its_second_sighting_not_its_first(tmp_path):
    seen = run_rounds(tmp_path, "stranded")
    job = seen["job"]
    assert seen["rounds"] == [[], [[job, "requeued 2"]]]  # first: its task may be on its way to a worker
    assert sorted(seen["requeued"]) == [[job, 0, 2], [job, 2, 4]]
    assert seen["reaps"] == 1


def test_a_task_starting_between_two_sightings_makes_the_next_a_first_again(tmp_path):
    seen = run_rounds(tmp_path, "started between")
    job = seen["job"]
    assert seen["rounds"] == [[], [], [[job, "requeued 2"]]]
    assert seen["reaps"] == 1


def test_a_stranded_job_past_its_clock_is_left_to_the_heartbeat(tmp_path):
    seen = run_rounds(tmp_path, "past its clock")
    assert seen["rounds"] == [[], []] and seen["requeued"] == [] and seen["reaps"] is None

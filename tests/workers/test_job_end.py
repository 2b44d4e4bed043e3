"""How a job ends, in a real Redis (a subprocess: the task module needs GEOCERT_REDIS_URL when it
is imported): a job cancelled after its solvers' last check ends "cancelled", its result whole."""

from __future__ import annotations

import pytest

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


PUBLISHED = """
import json
import os
from geocert.jobs.runner import assemble, item_sums, parse_job, result_json, solve_items, stats_from
from geocert.kinds import get_kind
from geocert.workers import tasks
from geocert.jobs.store import JobStore

jobs = JobStore.from_url(os.environ["GEOCERT_REDIS_URL"])
job = get_kind("triangulation").example
job = {**job, "data": {**job["data"], "tracks": job["data"]["tracks"] * 4}, "options": {"detail": "full"}}
kind, parsed, options = parse_job(job)
meta = jobs.create("triangulation", job, 8, 100, "someone", chunk_key="tracks")
assert jobs.mark_running(meta["id"])
publisher = tasks.ProgressPublisher(jobs, meta["id"], 0, float(os.environ["INTERVAL"]), kind, 0.0)
items = solve_items(kind, parsed, options, range(8), publisher, on_item=publisher.item_ended)
flushed = []  # the flush's own stores: none once the last progress stored every item
save_items = jobs.save_items
jobs.save_items = lambda *args: [flushed.append(1), save_items(*args)][1]
done = publisher.flush()
raw = jobs.binary.hgetall(jobs.key(meta["id"], "items"))
plan = jobs.fragment_plan(meta["id"], 8)
assert jobs.claim_end(meta["id"])
tasks.end_with_result(jobs, meta["id"], kind, options)
whole = json.loads(result_json(kind, assemble(kind, None, options, items, stats_from(item_sums(items), 0.0))))
print(json.dumps({"done": done, "largest_field": max(map(len, raw.values())), "plan": plan is not None,
                  "same": jobs.result(meta["id"])["tracks"] == whole["tracks"], "flush_stores": len(flushed)}))
"""


@pytest.mark.parametrize("interval", ["0", "3600"])  # a store at every item, or at the last only
def test_a_tasks_items_are_written_once_in_its_fragments_and_end_as_its_result(tmp_path, interval, monkeypatch):
    """A streamed result's task wrote each item twice: one by one, and in its fragment. Now each
    store writes its run of items as one fragment that holds them, the items' own fields saying
    where they are; the end joins the fragments into the result its items assemble. The batch's
    progress, sent once at its group's end, stores every item: the task's flush then makes no
    round trip, returning the count that store read."""
    monkeypatch.setenv("INTERVAL", interval)
    ended = run_with_redis(tmp_path, PUBLISHED)
    assert ended == {"done": 8, "largest_field": 2, "plan": True, "same": True, "flush_stores": 0}


STORED_WITHOUT_COLLECTIONS = """
import gc
import json
import os
from geocert.jobs.runner import parse_job, solve_items
from geocert.kinds import get_kind
from geocert.workers import tasks
from geocert.jobs.store import JobStore

jobs = JobStore.from_url(os.environ["GEOCERT_REDIS_URL"])
job = get_kind("triangulation").example
job = {**job, "data": {**job["data"], "tracks": job["data"]["tracks"] * 300}, "options": {"detail": "full"}}
kind, parsed, options = parse_job(job)
meta = jobs.create("triangulation", job, 600, 1000, "someone", chunk_key="tracks")
assert jobs.mark_running(meta["id"])
inside, started = [False], []
fragment = tasks.result_fragment


def watched(*args):
    inside[0] = True
    try:
        return fragment(*args)
    finally:
        inside[0] = False


tasks.result_fragment = watched
gc.callbacks.append(lambda phase, info: started.append(inside[0]) if phase == "start" else None)
publisher = tasks.ProgressPublisher(jobs, meta["id"], 0, 3600.0, kind, 0.0)
solve_items(kind, parsed, options, range(600), publisher, on_item=publisher.item_ended)
print(json.dumps({"done": publisher.flush(), "while_stored": sum(started), "enabled": gc.isenabled()}))
"""


def test_a_tasks_items_are_stored_without_the_cyclic_collector(tmp_path):
    """The result model's dump of 600 full track documents started the cyclic collector again and
    again over the young objects it makes (half the task's CPU storing them): it is held off."""
    ended = run_with_redis(tmp_path, STORED_WITHOUT_COLLECTIONS)
    assert ended == {"done": 600, "while_stored": 0, "enabled": True}

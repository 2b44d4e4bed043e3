"""Faults and load through real processes: a worker killed mid-job, and 500 concurrent jobs."""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest
import numpy as np

from geocert.jobs.store import JobStore
from tests.servers import SHORT_TASKS, cluster, wait_until_done
from tests.support import service_job as triangulation_job


pytestmark = pytest.mark.slow  # real servers, real data or SCIP: the full run only


def test_a_worker_killed_mid_job_leaves_its_work_to_another(tmp_path):
    """A worker SIGKILLed mid-chunk: its task is delivered again by the broker (its lease, renewed
    by the dead worker's heartbeat, runs out), not re-queued by the reaper, and the job ends
    certified with every item once. Throughout, progress never counts more items than are stored
    (read after it): the killed task's solved but unstored items were never counted."""
    import redis

    body = triangulation_job(np.random.default_rng(77), tracks=1200, views=5)
    with cluster(tmp_path, workers=2, **SHORT_TASKS) as (running, client):
        store = redis.Redis.from_url(running.redis_url, decode_responses=True)
        jobs = JobStore(store)
        job_id = client.post("/v1/jobs", json=body).json()["id"]
        wait_until_done(client, job_id, 200)
        running.kill(running.workers[0])  # SIGKILL to its whole process group, mid-chunk
        killed_at = time.monotonic()
        overcounts = []
        while (job := client.get(f"/v1/jobs/{job_id}").json())["status"] not in ("succeeded", "failed", "cancelled"):
            stored = store.hlen(f"geocert:job:{job_id}:items")
            ended = jobs.field(job_id, "status") in ("succeeded", "failed", "cancelled")
            # (the end drops the stored items with the status change, atomically: a sample the end
            # fell inside proves nothing, and is skipped)
            if job["progress"]["items_done"] > stored and not ended:
                overcounts.append((job["progress"]["items_done"], stored))
            assert time.monotonic() - killed_at < 120, f"job still {job['status']} two minutes after the kill"
            time.sleep(0.1)
        recovery = time.monotonic() - killed_at
        reaps = store.hget(f"geocert:job:{job_id}", "reaps")
    assert job["status"] == "succeeded", job["error"]
    assert not overcounts, f"progress counted items not stored (counted, stored): {overcounts[:5]}"
    assert reaps is None, "the reaper re-queued the job: the broker did not deliver the lost task again"
    tracks = job["result"]["tracks"]
    assert len(tracks) == 1200 and job["result"]["stats"]["items"] == 1200  # none lost, none twice
    # A random track may have its optimum at a camera's centre (seed 77's track 1190), where no
    # bound carries over to the data's problem: not certified, and it says why.
    assert all(track["certified"] or (track["status"] == "not_certified" and track["reason"]) for track in tracks)
    assert sum(track["certified"] for track in tracks) >= 0.99 * len(tracks)
    assert job["progress"]["items_done"] == 1200
    print(f"\nkilled a worker after 200 of 1200 tracks; the job ended certified {recovery:.1f} s after the kill")


def test_five_hundred_concurrent_jobs_all_succeed_once(tmp_path):
    rng = np.random.default_rng(500)
    bodies = [triangulation_job(rng, tracks=2, views=3) for _ in range(500)]
    keys = [f"client-key-{i:02d}" for i in range(10)]
    with cluster(tmp_path, workers=2, geocert_api_keys=",".join(keys), geocert_rate_limit_per_minute="100000",
                 geocert_progress_interval_s="1.0") as (running, _):

        def submit_and_wait(index: int) -> tuple[str, str, float, int]:
            headers = {"X-API-Key": keys[index % len(keys)]}
            with httpx.Client(base_url=running.base, timeout=60, headers=headers) as client:
                start = time.monotonic()
                created = client.post("/v1/jobs", json=bodies[index])
                assert created.status_code == 202, created.text
                job_id = created.json()["id"]
                while (job := client.get(f"/v1/jobs/{job_id}").json())["status"] in ("queued", "running"):
                    time.sleep(0.05)
                return job_id, job["status"], time.monotonic() - start, len(job["result"]["tracks"])

        began = time.monotonic()
        with ThreadPoolExecutor(max_workers=40) as pool:  # 40 clients in flight at once, 10 keys
            outcomes = list(pool.map(submit_and_wait, range(500)))
        wall = time.monotonic() - began
    ids = [o[0] for o in outcomes]
    assert len(set(ids)) == 500  # none duplicated
    assert [o[1] for o in outcomes] == ["succeeded"] * 500  # none lost or failed
    assert all(o[3] == 2 for o in outcomes)
    latency = np.array([o[2] for o in outcomes])
    print(f"\n500 jobs, 40 concurrent clients, 2 workers: {500 / wall:.1f} jobs/s; submit-to-result "
          f"p50 {1e3 * np.percentile(latency, 50):.0f} ms, p99 {1e3 * np.percentile(latency, 99):.0f} ms")

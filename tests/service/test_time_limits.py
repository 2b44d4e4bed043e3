"""A job's own time limits decide when it ends, through real servers (embedded Redis, the API and
Celery workers, each a process): a job whose limits allow longer than the server's per-item
maximum ends by those limits with its best answer, a reconstruction and a large triangulation
by their clock in all (time_bound_s, job_time_limit_s) with what they finished; and a task
killed by Celery's hard limit, the last resort, fails its job with the reason and what it
finished, never delivered again."""

from __future__ import annotations

import base64
import json
import time

import cv2
import numpy as np
import pytest
import redis

from geocert.solvers.autocalibration import scenes
from geocert.workers.priorities import queue_lists
from geocert.workers.redis_server import broker_url
from tests.servers import cluster

pytestmark = pytest.mark.slow  # real servers: the full run only

TERMINAL = ("succeeded", "failed", "cancelled")


def ended(client, job_id: str, limit_s: float = 300) -> dict:
    deadline = time.monotonic() + limit_s
    while (job := client.get(f"/v1/jobs/{job_id}").json())["status"] not in TERMINAL:
        assert time.monotonic() < deadline, f"job still {job['status']} after {limit_s} s"
        time.sleep(0.3)
    return job


def unbounded_autocalibration(time_limit_s: float) -> dict:
    """Four cameras without points: chirality leaves the plane at infinity free enough that
    neither stage closes its gap, so each runs to its time limit (and the job to twice that)."""
    data = scenes.make_scene(4, 0.1, seed=5).job_data()
    data.pop("points")
    return {"kind": "autocalibration", "data": data, "options": {"time_limit_s": time_limit_s, "max_nodes": 100_000}}


def small_reconstruction() -> dict:
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=6, points=1500, seed=3, noise_px=0.3)
    return {"kind": "reconstruction", "options": {"time_limit_s": 0.001, "autocalibration_time_limit_s": 0.05,
                                                  "structure_time_limit_s": 1.5},
            "data": {"views": [{"image_size": list(scene.image_size)}] * 6,
                     "tracks": [{"views": [int(v) for v in views],
                                 "points": [[round(float(u), 3), round(float(w), 3)] for u, w in pixels]}
                                for views, pixels in scene.tracks]}}


def queued_time_limits(store: redis.Redis) -> list[tuple[float, float]]:
    """The (soft, hard) time limits of the tasks waiting in the queue, as Celery's messages carry them."""
    limits = []
    for raw in (task for name in queue_lists("celery") for task in store.lrange(name, 0, -1)):
        hard, soft = json.loads(raw)["headers"]["timelimit"]
        limits.append((soft, hard))
    return limits


def test_a_jobs_tasks_are_limited_by_its_own_limits_and_it_ends_by_them(tmp_path):
    """A task's Celery limits follow from its job's own (they were 90 s for every task, whatever
    the job: a reconstruction allowed 10 s per point, or two autocalibration stages of 60 s, was
    killed, "SoftTimeLimitExceeded", its work lost), and do not grow with its size (a
    reconstruction's were its tracks times 10 s, a photo job's 200,000 tracks times 10 s: 23
    days). Then the job ends by its own limits: the affine stage at its time limit, its best
    plane kept."""
    reconstruction = small_reconstruction()
    reconstruction["options"] = {"time_limit_s": 10, "autocalibration_time_limit_s": 60}
    photos = {"kind": "reconstruction", "options": {"time_limit_s": 10, "features": {"time_limit_s": 100}},
              "data": {"images": [{"name": f"p{i}", "content": base64.b64encode(
                  cv2.imencode(".png", np.zeros((48, 64), np.uint8))[1].tobytes()).decode()} for i in range(2)]}}
    with cluster(tmp_path, workers=0) as (running, client):
        store = redis.Redis.from_url(running.redis_url, decode_responses=True)
        margin, soft_after, hard_after = 120, 30, 30  # GEOCERT_TASK_TIME_MARGIN_S's default, workers.queue's
        for body, own in ((reconstruction, 600 + 2 * 10 + 2 * 60),  # the points and cameras' clock, the last
                          (photos, 100 + 600 + 2 * 10 + 2 * 60)):   # of each, two stages; photos: matching
            response = client.post("/v1/jobs", json=body)
            assert response.status_code == 202, response.text
            (soft, hard), = queued_time_limits(store)
            assert soft == pytest.approx(own + margin + soft_after) and hard == pytest.approx(soft + hard_after)
            store.delete("celery")
        response = client.post("/v1/jobs", json=unbounded_autocalibration(8))
        assert response.status_code == 202, response.text
        (soft, hard), = queued_time_limits(store)
        assert soft >= 2 * 8 + margin and hard > soft  # two stages of 8 s
        running.start_worker()
        job = ended(client, response.json()["id"])
        assert job["status"] == "succeeded", job["error"]
        affine = job["result"]["stages"][0]
        assert affine["status"] == "time_limit" and affine["elapsed_s"] >= 8
        assert job["result"]["plane_at_infinity"] is not None


def test_a_reconstruction_past_its_limits_ends_by_its_own_clock_not_by_the_last_resort(tmp_path):
    """40 views whose limits add up to 0.07 s in all (time_bound_s), less than their registration
    takes: the registration and adjustments had no clock of their own, so the job ran its whole
    registration and every stage, and its task was held to the last resort only. Now they stop at
    the job's own clock: the job succeeds, its item and every stage it stopped read time_limit
    (none cancelled), and nothing is queued again."""
    from tests.kinds.test_job_time_limit import registration_past_its_limits

    with cluster(tmp_path, workers=1) as (running, client):
        job_id = client.post("/v1/jobs", json=registration_past_its_limits()).json()["id"]
        job = ended(client, job_id)
        assert job["status"] == "succeeded", job["error"]
        assert job["result"]["stats"]["statuses"] == {"time_limit": 1}
        stages = {stage["name"]: stage["status"] for stage in job["result"]["stages"]}
        assert stages["projective"] == "time_limit" and "cancelled" not in stages.values()
        store = redis.Redis.from_url(running.redis_url, decode_responses=True)
        assert store.llen(f"geocert:job:{job_id}:tasks") == 1
        time.sleep(20)  # beyond the visibility timeout and a reaper round: nothing ran it again
        again = client.get(f"/v1/jobs/{job_id}").json()
        assert again["status"] == "succeeded" and again["finished_at"] == job["finished_at"]
        assert store.hget(f"geocert:job:{job_id}", "reaps") is None and sum(store.llen(name) for name in queue_lists("celery")) == 0


def test_a_task_killed_at_its_hard_limit_fails_its_job_and_is_not_delivered_again(tmp_path):
    """A task sent with a hard time limit of 2 s alone (as if its solver ignored every check and
    Celery's soft limit): the worker kills its process, the errback fails the job with the reason
    (it used to stay running until the reaper re-queued it three times: "Tasks lost"), and the
    worker goes on to solve the next job."""
    from celery import Celery

    with cluster(tmp_path, workers=0) as (running, client):
        job_id = client.post("/v1/jobs", json=unbounded_autocalibration(30)).json()["id"]
        store = redis.Redis.from_url(running.redis_url, decode_responses=True)
        store.delete("celery")  # its queued task replaced by one with a short hard limit
        app = Celery("test", broker=broker_url(running.redis_url))
        app.send_task("geocert.solve_chunk", args=[job_id, 0, 1, None], time_limit=2,
                      link_error=app.signature("geocert.solve_chunk_failed"))
        running.start_worker()
        job = ended(client, job_id, limit_s=120)
        assert job["status"] == "failed", job
        assert job["error"]["title"] == "Task time limit exceeded" and "hard time limit" in job["error"]["detail"]
        time.sleep(20)  # beyond the visibility timeout and a reaper round
        assert client.get(f"/v1/jobs/{job_id}").json()["status"] == "failed"
        assert store.hget(f"geocert:job:{job_id}", "reaps") is None
        assert json.loads(store.hget(f"geocert:job:{job_id}", "status")) == "failed"
        follower = client.post("/v1/jobs", json={"kind": "triangulation", "data": {
            "cameras": [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]], [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]],
            "tracks": [{"views": [0, 1], "points": [[330, 250], [250, 251]]}]}}).json()["id"]
        assert ended(client, follower, limit_s=120)["status"] == "succeeded"


def test_a_large_triangulation_ends_at_its_job_time_limit_with_what_it_finished(tmp_path):
    """3000 tracks, each a search of its own (max_residual), in 6 tasks of 500 solved as batches:
    with job_time_limit_s 2 their tasks' Celery limits are sized from it (they were 500 times
    time_limit_s: 4 hours), and the job ends succeeded, the tracks finished by then kept, the
    rest time_limit, not started, uncertified."""
    from tests.support import service_job

    body = service_job(np.random.default_rng(7), 3000, views=4, max_residual=50.0, detail="brief",
                       job_time_limit_s=2)
    with cluster(tmp_path, workers=0) as (running, client):
        store = redis.Redis.from_url(running.redis_url, decode_responses=True)
        response = client.post("/v1/jobs", json=body)
        assert response.status_code == 202, response.text
        margin, soft_after, hard_after = 120, 30, 30
        limits = queued_time_limits(store)
        assert len(limits) == 6
        assert all(soft == pytest.approx(2 + margin + soft_after) and hard == pytest.approx(soft + hard_after)
                   for soft, hard in limits)
        running.start_worker()
        job = ended(client, response.json()["id"])
    assert job["status"] == "succeeded", job["error"]
    tracks = job["result"]["tracks"]
    not_started = [track for track in tracks if "not started" in (track["reason"] or "")]
    assert not_started and len(not_started) < len(tracks)
    assert all(track["status"] == "time_limit" and not track["certified"] and track["point"] is None
               for track in not_started)
    assert any(track["certified"] for track in tracks)
    assert not any(track["status"] == "cancelled" for track in tracks)

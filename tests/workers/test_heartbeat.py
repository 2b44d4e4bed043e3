"""Heartbeats as leases: what a worker holds (Celery's worker state) and what a beat renews, in a
real Redis. (A worker SIGKILLed mid-job, end to end: tests/service/test_durability.py.)"""

from __future__ import annotations

from types import SimpleNamespace

import pytest
import redis

from geocert.workers.heartbeat import KEY, UNACKED_INDEX, beat, held_solve_tasks, held_tasks
from geocert.jobs.store import JobStore


@pytest.fixture
def client(tmp_path):
    from geocert.workers.redis_server import start_embedded_redis

    process, url = start_embedded_redis(tmp_path)
    try:
        yield redis.Redis.from_url(url, decode_responses=True)
    finally:
        process.terminate()
        process.wait(timeout=10)


def fake_request(tag, name, args):
    return SimpleNamespace(message=SimpleNamespace(delivery_tag=tag), name=name, args=args)


def test_held_tasks_are_every_request_of_the_worker_state(monkeypatch):
    from celery.worker import state

    monkeypatch.setattr(state, "requests", {
        "a": fake_request("tag-a", "geocert.solve_chunk", ["job-1", 0, 60, None]),
        "b": fake_request("tag-b", "geocert.deliver_webhook", ["job-2"]),  # waiting for its countdown, say
        "c": SimpleNamespace(message=None, name="geocert.solve_chunk", args=["job-3", 0, 1]),  # no delivery
    })
    assert sorted(held_tasks()) == [("tag-a", "job-1"), ("tag-b", None)]


def test_a_helpers_slot_and_job_are_renewed_as_a_solve_tasks_are(client, monkeypatch):
    """A helper with a stage's pieces (solve_pieces) holds its job's solver slot: unrenewed, the
    slot would lapse after SLOT_LAPSE_S (30 s) while the helper still runs, and another task of
    the key would take its place beyond the key's share."""
    from celery.worker import state

    monkeypatch.setattr(state, "requests", {
        "solve": SimpleNamespace(id="solve", message=SimpleNamespace(delivery_tag="tag-s"), name="geocert.solve_chunk",
                                 args=["job-1", 0, 1]),
        "helper": SimpleNamespace(id="helper", message=SimpleNamespace(delivery_tag="tag-h"),
                                  name="geocert.solve_pieces", args=["job-2", "set", None]),
        "webhook": SimpleNamespace(id="webhook", message=SimpleNamespace(delivery_tag="tag-w"),
                                   name="geocert.deliver_webhook", args=["job-3"]),
    })
    assert sorted(held_solve_tasks()) == ["helper", "solve"]
    assert sorted(held_tasks()) == [("tag-h", "job-2"), ("tag-s", "job-1"), ("tag-w", None)]
    client.zadd(JobStore.SLOTS, {"solve": 1.0, "helper": 1.0})
    client.zadd(JobStore.RUNNING, {"job-2": 1.0})
    beat(client, "geocert@test", held_tasks(), 1, held_solve_tasks())
    slots = dict(client.zrange(JobStore.SLOTS, 0, -1, withscores=True))
    assert slots["helper"] > 1e9 and slots["solve"] > 1e9
    assert client.zscore(JobStore.RUNNING, "job-2") > 1e9


def test_a_beat_renews_the_leases_it_holds_and_adds_none(client):
    client.zadd(UNACKED_INDEX, {"held": 1.0, "not-held": 1.0})
    client.zadd(JobStore.RUNNING, {"running-job": 1.0})
    beat(client, "geocert@test", [("held", "running-job"), ("acked-meanwhile", "ended-job")])
    leases = dict(client.zrange(UNACKED_INDEX, 0, -1, withscores=True))
    assert leases["held"] > 1e9 and leases["not-held"] == 1.0  # renewed to now / left to expire
    assert "acked-meanwhile" not in leases  # a task acknowledged since is not brought back
    running = dict(client.zrange(JobStore.RUNNING, 0, -1, withscores=True))
    assert running["running-job"] > 1e9 and "ended-job" not in running  # an ended job is not revived
    assert client.zscore(KEY, "geocert@test") > 1e9

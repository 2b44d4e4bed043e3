"""One submission's cost in the API, in-process: the route's own work (``job_submission._submit``: the
request's model dump, the kind's parse, the limits, ``JobStore.create`` and queueing the tasks)
on a body already validated, against an embedded Redis, one thread, no HTTP. Prints per
submission: CPU and wall milliseconds, the socket writes to Redis (each a round trip: the caller
waits for its answer), the Redis commands run and the server's time in them (a script's time
includes the commands it runs), with the machine's load.

    .venv/bin/python -m bench.submission [--tracks 3] [--count 300] [--profile] [--loop | --app]

``--loop``: the event loop's path instead (``job_submission.submit_on_loop``, the Redis calls
through an asyncio client), which the API takes for a small body.

``--app``: the whole request through the API's ASGI app (its middlewares, FastAPI's routing,
dependencies, body validation and response model, the route's own work), its body as JSON
bytes, called one request after another on one event loop; no HTTP server and no socket to the
client (uvicorn's parsing is not counted). The access log is silenced.

``--parsers``: uvicorn's HTTP protocols alone on a submission's request (the bytes httpx sends,
the answer written to a stub transport, a trivial ASGI app): CPU a request with h11 (the API's,
``lifecycle.HeaderTimeoutH11``) and with httptools when it is importable (it is not a dependency:
``pip install httptools`` beside, or PYTHONPATH a directory holding it), and their ratio.

``--messages``: making a one-chunk job's task commands alone (``queue.task_commands`` with the
event loop's producer), CPU a job.

``--app --dinosaur``: the whole request with the Oxford Dinosaur's tracks as its body (0.49 MB).

``--parse``: the triangulation kind's parse of the Oxford Dinosaur's tracks (Oxford VGG's data,
4983 tracks; ``--tracks`` fewer), as the API checks a body and a worker reads its chunk, CPU a parse.

Instructions a submission, a figure the machine's load does not move (valgrind's callgrind
counting only the measured submissions; its "Collected" line over ``--count``):

    BENCH_CALLGRIND=1 valgrind --tool=callgrind --instr-atstart=no --callgrind-out-file=/tmp/cg.%p \
        .venv/bin/python -m bench.submission --app --count 100

``--baseline <checkout>``: before and after in one run: this measurement made ``--rounds`` times
in turn with this checkout's geocert and with that checkout's (each run a process of its own,
alternating, this bench's code in both), then the ratio of their medians. E.g. the whole request
of a small job and of a 0.9 MB one, against main:

    .venv/bin/python -m bench.submission --app --baseline ../main
    .venv/bin/python -m bench.submission --app --tracks 5000 --count 10 --baseline ../main

Nothing here asserts (tests/workers/test_queue.py checks the behaviour).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", type=int, default=3, help="tracks a job (the 3 of bench.faults' submissions)")
    parser.add_argument("--count", type=int, default=300, help="submissions measured")
    parser.add_argument("--profile", action="store_true", help=(
        "also print the Python calls a submission and cProfile's top functions (BENCH_SORT: their order, "
        "BENCH_TOP: how many)"))
    parser.add_argument("--loop", action="store_true", help="the event loop's path (submit_on_loop)")
    parser.add_argument("--app", action="store_true", help="the whole request through the ASGI app")
    parser.add_argument("--parsers", action="store_true", help="uvicorn's h11 against httptools, per request")
    parser.add_argument("--messages", action="store_true", help="making a one-chunk job's task commands alone")
    parser.add_argument("--parse", action="store_true", help="the triangulation kind's parse of the Dinosaur's tracks")
    parser.add_argument("--dinosaur", action="store_true", help="with --app: the Dinosaur's tracks as the body")
    parser.add_argument("--baseline", metavar="CHECKOUT", help="another checkout to measure against, in turn")
    parser.add_argument("--rounds", type=int, default=4, help="with --baseline: runs of each")
    args = parser.parse_args()
    if args.parsers:
        return parsers(args.tracks, args.count)
    if args.parse and not args.baseline:
        return parse_dinosaur(args.tracks, args.count)
    if args.baseline:
        return against(args.baseline, args.rounds, [a for a in sys.argv[1:] if a not in _BASELINE_ARGS(args)],
                       what="a parse" if args.parse else "a submission")

    from geocert.workers.redis_server import start_embedded_redis

    server, url = start_embedded_redis(Path(tempfile.mkdtemp(prefix="geocert-bench-submission-")))
    os.environ.update(GEOCERT_REDIS_URL=url, GEOCERT_MAX_ACTIVE_JOBS_PER_KEY="0", GEOCERT_RATE_LIMIT_PER_MINUTE="0")
    try:
        if args.messages:
            return messages(args.count)
        measure(url, args.tracks, args.count, args.profile, args.loop, args.app, args.dinosaur)
    finally:
        server.terminate()
        server.wait(timeout=10)


def measure(url: str, tracks: int, count: int, profile: bool, loop: bool = False, app: bool = False,
            dinosaur: bool = False) -> None:
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
        texts = [json.dumps(triangulation_job(rng, tracks=tracks)).encode() for _ in range(1 if dinosaur else 20)]
        if dinosaur:
            texts, tracks = [json.dumps(dinosaur_job()).encode()], 4983
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
    _callgrind("on")
    cpu, wall = time.process_time(), time.perf_counter()
    try:
        for index in range(count):
            submit(index)
    finally:
        _callgrind("off")
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
    # A script's time includes the commands it calls (counted again under their own names).
    usec = {name.removeprefix("cmdstat_"): stats["usec"] / count for name, stats in counter.info("commandstats").items()}
    print("Redis server time a submission: " + ", ".join(f"{name} {usec[name]:.1f} us" for name in sorted(usec)
                                                           if name not in ("config", "info")))
    if profile:
        profiler = cProfile.Profile()
        profiler.runcall(lambda: [submit(index) for index in range(count)])
        stats = pstats.Stats(profiler)
        # Python calls a submission: unlike its CPU, the same on a loaded machine as on a quiet one.
        print(f"Python function calls a submission (cProfile): {stats.total_calls / count:.0f}")
        stats.sort_stats(os.environ.get("BENCH_SORT", "cumulative")).print_stats(int(os.environ.get("BENCH_TOP", "30")))


def _callgrind(state: str) -> None:
    """Under valgrind's callgrind with BENCH_CALLGRIND set: its instruction counting switched
    ``state`` ("on", "off"), so that only the measured submissions are counted (started with
    ``--instr-atstart=no``, the imports and start-up uncounted and run faster)."""
    if os.environ.get("BENCH_CALLGRIND"):
        subprocess.run(["callgrind_control", "-i", state, str(os.getpid())], check=True, capture_output=True)


def messages(count: int) -> None:
    """Making a one-chunk job's task commands (``queue.task_commands`` with the event loop's
    producer, as a small submit makes them), ``count`` times: CPU a job."""
    from geocert.workers import queue

    queue.ready_loop_producer()
    producer = queue.loop_producer()
    meta = {"id": "0" * 32, "kind": "triangulation", "chunks": [(0, 3)], "task_ids": ["0" * 32]}
    for _ in range(100):
        queue.task_commands(meta, None, producer)  # first-use costs out of the figures
    cpu = time.process_time()
    for _ in range(count):
        queue.task_commands(meta, None, producer)
    cpu = time.process_time() - cpu
    print(f"{count} one-chunk jobs' task commands (queue.task_commands, the loop's producer): "
          f"{1e3 * cpu / count:.3f} ms CPU a job; load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


def dinosaur_job() -> dict:
    from bench.triangulation import DINOSAUR
    from geocert.solvers.datasets import load_dinosaur

    cameras, found = load_dinosaur(DINOSAUR)
    return {"kind": "triangulation", "data": {
        "cameras": cameras.tolist(), "tracks": [{"views": list(t.views), "points": t.points.tolist()} for t in found]}}


def parse_dinosaur(tracks: int, count: int) -> None:
    """``TriangulationKind.parse`` of the Dinosaur's first ``tracks`` tracks (all when fewer than
    the 3 default), ``count`` times: CPU a parse."""
    from geocert.kinds import get_kind

    data = json.loads(json.dumps(dinosaur_job()["data"]))
    found = data["tracks"] = data["tracks"][:tracks] if tracks > 3 else data["tracks"]
    kind = get_kind("triangulation")
    kind.parse(data)
    cpu = time.process_time()
    for _ in range(count):
        kind.parse(data)
    cpu = time.process_time() - cpu
    print(f"the Dinosaur's {len(found)} tracks parsed (TriangulationKind.parse) {count} times: {1e3 * cpu / count:.3f} "
          f"ms CPU a parse; load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


def parsers(tracks: int, count: int, rounds: int = 3) -> None:
    """uvicorn's h11 protocol (the API's) against its httptools protocol on one submission's
    request: the bytes parsed, the ASGI cycle run with a trivial app, the answer written."""
    import asyncio
    import statistics

    from uvicorn.config import Config
    from uvicorn.server import ServerState

    from bench.faults import triangulation_job
    from geocert.app.lifecycle import HeaderTimeoutH11

    body = json.dumps(triangulation_job(np.random.default_rng(1), tracks=tracks)).encode()
    request = (b"POST /v1/jobs HTTP/1.1\r\nHost: 127.0.0.1:8000\r\nAccept: */*\r\nAccept-Encoding: gzip, deflate\r\n"
               b"Connection: keep-alive\r\nUser-Agent: python-httpx/0.28\r\ncontent-type: application/json\r\n"
               b"Content-Length: " + str(len(body)).encode() + b"\r\n\r\n" + body)
    answer = json.dumps({"id": "0" * 32, "kind": "triangulation", "status": "queued", "created_at": 1.0}).encode()

    async def app(scope, receive, send):
        await receive()
        await send({"type": "http.response.start", "status": 202, "headers": [
            (b"content-type", b"application/json"), (b"content-length", str(len(answer)).encode())]})
        await send({"type": "http.response.body", "body": answer})

    class Transport(asyncio.Transport):
        def write(self, data):
            pass

        def get_extra_info(self, name, default=None):
            return {"sockname": ("127.0.0.1", 8000), "peername": ("127.0.0.1", 50000)}.get(name, default)

        def is_closing(self):
            return False

        def close(self):
            pass

    protocols = {"h11": HeaderTimeoutH11}
    try:
        from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

        protocols["httptools"] = HttpToolsProtocol
    except ImportError:
        print("httptools is not importable: h11 alone")

    async def per_request(cls) -> float:
        config = Config(app, log_level="warning", access_log=False, h11_max_incomplete_event_size=16 * 1024)
        config.load()
        state = ServerState()
        protocol = cls(config=config, server_state=state, app_state={})
        protocol.connection_made(Transport())
        for index in range(count + 50):  # 50 first ones out of the figure
            if index == 50:
                cpu = time.process_time()
            protocol.data_received(request)
            while state.tasks:
                await asyncio.sleep(0)
        protocol.connection_lost(None)
        return (time.process_time() - cpu) / count

    cpu = {name: [] for name in protocols}
    for _ in range(rounds):
        for name, cls in protocols.items():
            cpu[name].append(asyncio.run(per_request(cls)))
    for name, values in cpu.items():
        print(f"{name}: " + ", ".join(f"{1e6 * value:.0f}" for value in values) + f" us of CPU a request ({len(body)}-byte "
              f"body, {count} requests a round); load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if "httptools" in cpu:
        print(f"httptools / h11 (medians): {statistics.median(cpu['httptools']) / statistics.median(cpu['h11']):.2f}")


def _BASELINE_ARGS(args) -> set[str]:
    return {"--baseline", args.baseline, "--rounds", str(args.rounds), f"--baseline={args.baseline}",
            f"--rounds={args.rounds}", "--profile"}


# A run with one checkout's geocert (imported first, from the checkout given) and a bench of this one.
_RUN = """
import importlib
import sys
sys.path.insert(0, sys.argv[1])
import geocert
assert geocert.__file__.startswith(sys.argv[1]), geocert.__file__
sys.path.insert(0, sys.argv[2])
bench = importlib.import_module(sys.argv[3])
sys.argv = [sys.argv[3], *sys.argv[4:]]
bench.main()
"""


def against(baseline: str, rounds: int, arguments: list[str], bench: str = "bench.submission",
            what: str = "a submission") -> None:
    """This checkout's geocert and ``baseline``'s, measured in turn (this one first in even
    rounds, the baseline first in odd ones), each run a process of its own running the module
    ``bench`` of this checkout with ``arguments``; the CPU (the first figure its output gives as
    "<x> ms CPU") of each run, and the ratio of the medians (this checkout / the baseline)."""
    here = str(Path(__file__).resolve().parent.parent)
    checkouts = {"this checkout": here, "baseline": str(Path(baseline).resolve())}
    cpu: dict[str, list[float]] = {name: [] for name in checkouts}
    print(f"load average at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    for round_ in range(rounds):
        order = list(checkouts) if round_ % 2 == 0 else list(reversed(checkouts))
        for name in order:
            done = subprocess.run([sys.executable, "-c", _RUN, checkouts[name], here, bench, *arguments],
                                  capture_output=True, text=True, env={**os.environ, "PYTHONPATH": ""})
            if done.returncode != 0:
                raise SystemExit(f"{name} failed:\n{done.stderr[-3000:]}")
            line = next(line for line in done.stdout.splitlines() if " ms CPU" in line)
            cpu[name].append(float(re.search(r"([\d.]+) ms CPU", line).group(1)))
            print(f"round {round_ + 1}, {name} ({checkouts[name]}): {line}", flush=True)
    medians = {name: statistics.median(values) for name, values in cpu.items()}
    print(f"CPU {what}, median of {rounds}: this checkout {medians['this checkout']:.3f} ms, baseline "
          f"{medians['baseline']:.3f} ms: ratio {medians['this checkout'] / medians['baseline']:.2f}; load average at "
          f"the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


async def _async_client(url: str):
    import redis.asyncio

    return redis.asyncio.Redis.from_url(url, decode_responses=True)


if __name__ == "__main__":
    main()

"""The API process's CPU a small submission over HTTP, and its cyclic collector's share of it
(gc.callbacks inside the API process), this checkout's code against another's, in turn: each run
an embedded Redis and one API process (``lifecycle.run``, as ``geocert serve --workers 0``
serves) taking 20 clients' 3-track submissions back to back. Prints each run, the medians and
their ratio, and the load average.

    .venv/bin/python -m bench.api_collector --baseline ../main [--rounds 4] [--each 30]

It measured freezing the API's start-up heap (as solver processes do, jobs.collection) against
not: no gain, so the API does not (docs/benchmarks.md). Nothing here asserts.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from bench.faults import cpu_seconds, free_port, triangulation_job

# The API process: counts the collector's runs and their CPU, written out on SIGUSR1 (uvicorn
# ends the process by re-raising SIGTERM, past any atexit).
_SERVE = """
import gc, json, signal, sys, time
out, port = sys.argv[1], int(sys.argv[2])
runs, began = [], [0.0]

def timed(phase, info):
    if phase == "start":
        began[0] = time.process_time()
    else:
        runs.append((info["generation"], time.process_time() - began[0]))

def written(*_):
    with open(out, "w") as file:
        json.dump({"cpu": sum(r[1] for r in runs), "oldest": sum(1 for r in runs if r[0] == 2)}, file)

signal.signal(signal.SIGUSR1, written)
from geocert.app import lifecycle
import geocert.app.main  # noqa: F401 (imported before the counting starts, as uvicorn would)
gc.callbacks.append(timed)
lifecycle.run("geocert.app.main:app", "127.0.0.1", port)
"""


def one_run(pythonpath: str, clients: int, each: int) -> dict:
    from geocert.workers.redis_server import start_embedded_redis

    with tempfile.TemporaryDirectory(prefix="geocert-bench-collector-") as directory:
        server, url = start_embedded_redis(Path(directory))
        env = {**os.environ, "PYTHONPATH": pythonpath, "GEOCERT_REDIS_URL": url, "GEOCERT_DATA_DIR": directory,
               "GEOCERT_RATE_LIMIT_PER_MINUTE": "0", "GEOCERT_MAX_ACTIVE_JOBS_PER_KEY": "0"}
        port, stats = free_port(), f"{directory}/collector.json"
        api = subprocess.Popen([sys.executable, "-c", _SERVE, stats, str(port)], env=env, stderr=subprocess.DEVNULL)
        base = f"http://127.0.0.1:{port}"
        try:
            deadline = time.monotonic() + 90
            while True:
                try:
                    if httpx.get(base + "/healthz").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline or api.poll() is not None:
                    raise RuntimeError("the API did not start")
                time.sleep(0.2)
            rng = np.random.default_rng(1)
            bodies = [json.dumps(triangulation_job(rng, tracks=3)).encode() for _ in range(40)]
            headers = {"content-type": "application/json"}
            httpx.post(base + "/v1/jobs", content=bodies[0], headers=headers)  # first-use costs out
            api.send_signal(signal.SIGUSR1)
            time.sleep(0.5)
            before = json.loads(Path(stats).read_text())

            async def submit_all() -> None:
                async with httpx.AsyncClient(base_url=base, timeout=60,
                                             limits=httpx.Limits(max_connections=clients)) as client:
                    async def one(index: int) -> None:
                        for k in range(each):
                            response = await client.post("/v1/jobs", content=bodies[(index + k) % 40], headers=headers)
                            assert response.status_code == 202, response.text

                    await asyncio.gather(*(one(i) for i in range(clients)))

            cpu = cpu_seconds(api.pid)
            asyncio.run(submit_all())
            cpu = cpu_seconds(api.pid) - cpu
            api.send_signal(signal.SIGUSR1)
            time.sleep(0.5)
            after = json.loads(Path(stats).read_text())
        finally:
            api.terminate()
            api.wait(timeout=30)
            server.terminate()
            server.wait(timeout=10)
    count = clients * each
    return {"cpu_ms": 1e3 * cpu / count, "collector_ms": 1e3 * (after["cpu"] - before["cpu"]) / count,
            "oldest": after["oldest"] - before["oldest"], "count": count}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", required=True, metavar="CHECKOUT", help="the other checkout (its geocert/)")
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--each", type=int, default=30, help="submissions a client makes in a run")
    args = parser.parse_args()
    here = str(Path(__file__).resolve().parents[1])
    paths = {"baseline": f"{Path(args.baseline).resolve()}{os.pathsep}{here}", "this": here}
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}, {os.cpu_count()} cores")
    found: dict[str, list[dict]] = {"baseline": [], "this": []}
    for _ in range(args.rounds):
        for name, path in paths.items():
            run = one_run(path, 20, args.each)
            found[name].append(run)
            print(f"  {name:8s}: API CPU {run['cpu_ms']:.2f} ms a submission, the collector {run['collector_ms']:.3f} ms; "
                  f"its oldest generation ran {run['oldest']} times in {run['count']}; load "
                  f"{os.getloadavg()[0]:.1f}", flush=True)
    for figure in ("cpu_ms", "collector_ms"):
        base, this = (statistics.median(run[figure] for run in found[name]) for name in ("baseline", "this"))
        print(f"{'API CPU' if figure == 'cpu_ms' else 'the collector'} a submission, medians: baseline {base:.3f} ms, "
              f"this {this:.3f} ms, ratio {this / base:.2f}")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()

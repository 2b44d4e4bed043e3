"""A solver process's triangulation CPU with its start-up heap frozen out of the cyclic
collector (jobs.collection.start_up_heap_frozen: gc.freeze once the solvers are loaded, workers.signals) and
without, interleaved, each run a process of its own that starts as a solver process does (the
workers' tasks and SOLVER_MODULES imported), then parses and solves a job in the kind's chunks
(jobs.runner.solve_items, documents included). Prints each run's CPU, the collector's runs and
their CPU (gc.callbacks), the medians and their ratio, whether both ways gave the same items
(times aside), and the load average.

Jobs: the Oxford Dinosaur's 4983 tracks (Visual Geometry Group, University of Oxford), and its
first 3 tracks (a small job's).

    .venv/bin/python -m bench.worker_collector [--rounds 4] [--data DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

DATA = Path(os.environ.get("GEOCERT_SHARED_DATA", "/work/shared/data")) / "oxford_dinosaur"

_RUN = """
import gc, hashlib, json, sys, time
frozen, tracks_wanted, data = sys.argv[1] == "frozen", int(sys.argv[2]), sys.argv[3]
from geocert.workers import signals
import geocert.workers.tasks  # what a solver process holds
import importlib
for name in signals.SOLVER_MODULES:
    importlib.import_module(name)
from geocert.jobs.runner import solve_items
from geocert.kinds import get_kind
from geocert.solvers.datasets import load_dinosaur
from geocert.workers.tasks import options_from

if frozen:  # where a solver process freezes: after its imports, before any task's data
    from geocert.jobs.collection import start_up_heap_frozen
    start_up_heap_frozen()
kind = get_kind("triangulation")
cameras, tracks = load_dinosaur(data)
tracks = tracks[:tracks_wanted]
body = json.loads(json.dumps({"cameras": cameras.tolist(), "tracks": [
    {"views": [int(v) for v in t.views], "points": t.points.tolist()} for t in tracks]}))
runs, began = [], [0.0]

def timed(phase, info):
    if phase == "start":
        began[0] = time.process_time()
    else:
        runs.append(time.process_time() - began[0])

gc.callbacks.append(timed)
options = options_from(kind.options_type, {})
digest = hashlib.sha256()
start = time.process_time()
for begin in range(0, len(tracks), kind.chunk_size):
    chosen = range(begin, min(len(tracks), begin + kind.chunk_size))
    items = solve_items(kind, kind.parse(body, items=chosen), options, chosen)
    for item in items:
        item.pop("elapsed_s", None)
    digest.update(json.dumps(items, sort_keys=True, default=str).encode())
cpu = time.process_time() - start
print(json.dumps({"cpu": cpu, "collections": len(runs), "collector_cpu": sum(runs), "digest": digest.hexdigest()}))
"""


def run(frozen: bool, tracks: int, data: Path) -> dict:
    env = {**os.environ, "GEOCERT_REDIS_URL": os.environ.get("GEOCERT_REDIS_URL", "redis://127.0.0.1:1/0")}
    out = subprocess.run([sys.executable, "-c", _RUN, "frozen" if frozen else "plain", str(tracks), str(data)],
                         capture_output=True, text=True, env=env, timeout=600)
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-2000:])
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--data", type=Path, default=DATA)
    args = parser.parse_args()
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}, {os.cpu_count()} cores")
    for tracks, name in ((4983, "Oxford Dinosaur, 4983 tracks"), (3, "3 tracks")):
        found: dict[bool, list[dict]] = {False: [], True: []}
        for _ in range(args.rounds):
            for frozen in (False, True):
                found[frozen].append(run(frozen, tracks, args.data))
                last = found[frozen][-1]
                print(f"  {name}, {'frozen' if frozen else 'plain '}: CPU {1e3 * last['cpu']:.1f} ms, the collector "
                      f"{last['collections']} runs, {1e3 * last['collector_cpu']:.1f} ms", flush=True)
        plain, frozen_cpu = (statistics.median(run["cpu"] for run in found[way]) for way in (False, True))
        same = len({run["digest"] for run in found[False] + found[True]}) == 1
        print(f"{name}: median CPU plain {1e3 * plain:.1f} ms, frozen {1e3 * frozen_cpu:.1f} ms, ratio "
              f"{frozen_cpu / plain:.2f}; the collector's median CPU plain "
              f"{1e3 * statistics.median(run['collector_cpu'] for run in found[False]):.1f} ms, frozen "
              f"{1e3 * statistics.median(run['collector_cpu'] for run in found[True]):.1f} ms; same items: {same}")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()

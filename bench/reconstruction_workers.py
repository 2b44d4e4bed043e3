"""A reconstruction job through the service with one solver process and with two (issue 35: its
independent pieces, each image's features and each image pair's matches, spread over the
workers, workers.pieces).

Starts two services side by side, ``geocert serve --workers 1 --concurrency 1`` and
``--workers 2 --concurrency 1`` (each with its embedded Redis), and submits the same job to each
in turn, ``--runs`` times, interleaved (1, 2, 1, 2, ...): the wall time from the submit to the
job's end, its matches stage (the pieces) and the rest of it, and the CPU the job's own task
spent in the matches stage (the helpers' share is not in it: under load, where wall times say
little on a shared 2-core machine, it shows how the work was split), and in all its stages: the
1-solver / 2-solver ratio of the task's CPU in all is the speed-up an idle machine would see when
the helpers keep pace (their own CPU, and Redis's, not counted). Prints each run, the median
2-solver / 1-solver ratio of the job's wall time and of its matches stage, the share of the
job's wall time in its spread stage (what bounds the speed-up: the rest runs on one process),
the pieces each service's helpers solved (geocert_pieces_total), the load average before and
after, and whether both services' results are equal (times aside) to the in-process one.

Jobs: ``photos`` (Middlebury's dinoSparseRing, 14 photos 640x480, the defaults: Seitz, Curless,
Diebel, Scharstein and Szeliski, CVPR 2006), ``ring`` (the same with examples/generate.py's ring
options, K known), ``tracks`` (the Oxford Dinosaur's 4983 tracks, Visual Geometry Group,
University of Oxford: no pieces yet, the baseline of a job that does not spread).

    .venv/bin/python -m bench.reconstruction_workers [--jobs photos,ring] [--runs 3] [--data DIR]
        [--solvers 1,2] [--before CHECKOUT] [--alone]

``--before /work/main`` (any checkout of earlier code) also runs a one-solver service of that
code, interleaved with the others, and prints this code's one-solver service against it: the
job's wall time and the task's CPU, before and after a change to how one process runs its pieces.
``--alone`` measures that change in this process only (a task with no other solver: its pieces
one at a time, on two threads, and the command line's stages), free of the services' noise.

Nothing here asserts: tests/service/test_spread_pieces.py checks behaviour, this prints figures.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx


def photos_job(data: Path, ring: bool = False) -> dict:
    folder = data / "middlebury_dinoSparseRing"
    names = sorted(path.name for path in folder.glob("dinoSR*.png"))
    images = [{"name": name, "content": base64.b64encode((folder / name).read_bytes()).decode()} for name in names]
    options: dict = {}
    if ring:  # examples/generate.py's ring options: K known
        row = (folder / "dinoSR_par.txt").read_text().split("\n")[1].split()
        K = [[float(v) for v in row[1 + 3 * r:4 + 3 * r]] for r in range(3)]
        options = {"intrinsics": {"K": K}, "min_inliers": 10, "merge_components": True,
                   "features": {"max_features": 0, "contrast_threshold": 0.005, "ratio": 0.85,
                                "ransac_threshold_px": 2, "guided_ratio": 0.8}}
    return {"kind": "reconstruction", "data": {"images": images}, "options": options}


def tracks_job(data: Path) -> dict:
    from geocert.solvers.datasets import load_dinosaur

    _, loaded = load_dinosaur(data / "oxford_dinosaur")
    tracks = [{"views": [int(v) for v in track.views], "points": [[float(x), float(y)] for x, y in track.points]}
              for track in loaded]
    return {"kind": "reconstruction", "options": {"autocalibration_time_limit_s": 20},
            "data": {"tracks": tracks, "views": [{"name": f"{v}", "image_size": [720, 576]} for v in range(36)]}}


@contextlib.contextmanager
def serve(data_dir: Path, workers: int, code: str | None = None):
    """``geocert serve --workers N --concurrency 1``, its code from the checkout ``code`` (None:
    this process's)."""
    import socket

    with socket.socket() as probe:  # a free port
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    env = {key: value for key, value in os.environ.items() if key != "GEOCERT_REDIS_URL"}
    env.update(GEOCERT_DATA_DIR=str(data_dir), GEOCERT_LOG_LEVEL="WARNING")
    if code is not None:
        env["PYTHONPATH"] = str(Path(code).resolve())
    process = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(port),
                                "--workers", str(workers), "--concurrency", "1"], env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=60) as client:
            deadline = time.monotonic() + 120
            while True:
                with contextlib.suppress(httpx.TransportError):
                    if client.get("/readyz").json().get("workers", 0) >= workers:
                        break
                assert time.monotonic() < deadline, "service not ready within 120 s"
                time.sleep(0.3)
            yield client
    finally:
        process.terminate()
        process.wait(timeout=30)


def run(client: httpx.Client, job: dict) -> tuple[float, dict]:
    began = time.perf_counter()
    response = client.post("/v1/jobs", json=job)
    response.raise_for_status()
    job_id = response.json()["id"]
    while True:
        state = client.get(f"/v1/jobs/{job_id}").json()
        if state["status"] in ("succeeded", "failed", "cancelled"):
            break
        time.sleep(0.05)
    wall = time.perf_counter() - began
    assert state["status"] == "succeeded", state.get("error")
    return wall, state["result"]


def pieces(client: httpx.Client) -> dict[str, float]:
    text = client.get("/metrics").text
    return {by: float(v) for by, v in re.findall(r'geocert_pieces_total\{solved_by="(\w+)"\} ([0-9.e+]+)', text)}


def without_times(value):
    if isinstance(value, dict):
        return {k: without_times(v) for k, v in value.items() if k not in ("elapsed_s", "cpu_s", "time_s", "stats")}
    if isinstance(value, list):
        return [without_times(v) for v in value]
    return value


def alone(jobs: list[tuple[str, dict]], runs: int) -> None:
    """In this process, a worker's task with no other solver live (workers.pieces: the spreader
    runs the pieces itself) as it was, one piece at a time (core.pieces.in_order), and
    as it is, two at once (in_threads), against the command line's stages (no spreader),
    interleaved: wall and CPU of the whole job, without the service's own noise."""
    import functools

    from geocert.jobs.runner import solve_job
    from geocert.core import pieces as core

    def spreader(mapping):
        return lambda function, shared, items, stop: mapping(functools.partial(function, shared), items, stop)

    modes = {"one at a time": spreader(core.in_order), "two threads": spreader(core.in_threads),
             "command line": None}
    for name, job in jobs:
        solve_job(job)  # imports and caches warm
        rows: dict[str, list] = {mode: [] for mode in modes}
        loads = []
        for _ in range(runs):
            for mode, spread in modes.items():
                loads.append(os.getloadavg()[0])
                wall, cpu = time.perf_counter(), time.process_time()
                with core.spread_by(spread):
                    solve_job(job)
                rows[mode].append((time.perf_counter() - wall, time.process_time() - cpu))
                print(f"  {name}, {mode}: wall {rows[mode][-1][0]:.2f} s, CPU {rows[mode][-1][1]:.2f} s "
                      f"(load {loads[-1]:.1f})")
        medians = {mode: (statistics.median(r[0] for r in rows[mode]), statistics.median(r[1] for r in rows[mode]))
                   for mode in modes}
        print(f"| {name} | " + " | ".join(f"{mode}: wall {w:.2f} s, CPU {c:.2f} s" for mode, (w, c) in medians.items())
              + f" | one at a time / two threads, wall {medians['one at a time'][0] / medians['two threads'][0]:.2f}x"
              f" | load {min(loads):.1f} to {max(loads):.1f} |")


def median_rows(rows: list[tuple]) -> tuple:
    return tuple(statistics.median(run[k] for run in rows) for k in range(4))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--data", default=os.environ.get("GEOCERT_SHARED_DATA")
                        or str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    parser.add_argument("--jobs", default="photos,ring")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--solvers", default="1,2", help="the services of this code to run: 1, 2 or both")
    parser.add_argument("--before", default=None,
                        help="a checkout of earlier code (e.g. main's): a one-solver service of it runs too, "
                             "interleaved, as the baseline of the one-solver service of this code")
    parser.add_argument("--alone", action="store_true",
                        help="in this process only: a task alone, its pieces one at a time against two threads "
                             "and the command line (run with OPENBLAS_NUM_THREADS=1, as a worker)")
    args = parser.parse_args()
    data = Path(args.data)
    makers = {"photos": lambda: photos_job(data), "ring": lambda: photos_job(data, ring=True),
              "tracks": lambda: tracks_job(data)}
    if args.alone:
        print(f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores, shared machine)")
        alone([(name, makers[name]()) for name in args.jobs.split(",")], args.runs)
        return
    from geocert.jobs.runner import result_json, solve_job
    from geocert.kinds import get_kind

    # label -> (workers, code): "1 before" is the --before checkout's one-solver service
    wanted = {label: (int(label), None) for label in args.solvers.split(",")}
    if args.before:
        wanted = {"1 before": (1, args.before), **wanted}
    print(f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores, shared machine)")
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        services = {label: stack.enter_context(serve(Path(tmp) / f"service{index}", workers, code))
                    for index, (label, (workers, code)) in enumerate(wanted.items())}
        for name in args.jobs.split(","):
            job = makers[name]()
            in_process = without_times(json.loads(result_json(get_kind("reconstruction"), solve_job(job))))
            before = {label: pieces(client) for label, client in services.items()}
            rows: dict[str, list] = {label: [] for label in services}
            loads = [os.getloadavg()[0]]
            for _ in range(args.runs):
                for label, client in services.items():
                    wall, result = run(client, job)
                    matches = result["summary"]["time_s"].get("matches", 0.0)
                    task_cpu = result["summary"]["cpu_s"].get("matches", 0.0)
                    job_cpu = sum(result["summary"]["cpu_s"].values())  # the task's own process, every stage
                    rows[label].append((wall, matches, task_cpu, job_cpu))
                    same = without_times(result) == in_process
                    loads.append(os.getloadavg()[0])
                    print(f"  {name}, {label} solver(s): job {wall:.2f} s, matches stage {matches:.2f} s "
                          f"(the task's own CPU in it {task_cpu:.2f} s), rest {wall - matches:.2f} s, the task's CPU in all "
                          f"{job_cpu:.2f} s, "
                          f"result equal to in-process: {same} (load {loads[-1]:.1f})")
            after = {label: pieces(client) for label, client in services.items()}
            median = {label: median_rows(r) for label, r in rows.items()}
            helped = {label: after[label].get("helper", 0) - before[label].get("helper", 0) for label in after}
            print(f"{name}: load average {min(loads):.1f} to {max(loads):.1f}, median {statistics.median(loads):.1f}")
            if "1" in median and "2" in median:
                share = median["1"][1] / median["1"][0] if median["1"][0] else 0.0
                print(f"| {name} | 1 solver: job {median['1'][0]:.2f} s, matches {median['1'][1]:.2f} s | "
                      f"2 solvers: job {median['2'][0]:.2f} s, matches {median['2'][1]:.2f} s | "
                      f"speed-up job {median['1'][0] / median['2'][0]:.2f}x, matches "
                      f"{(median['1'][1] / median['2'][1]) if median['2'][1] else float('nan'):.2f}x | "
                      f"matches' share of the 1-solver job {share:.0%} (bound on the job's speed-up "
                      f"{1 / (1 - share / 2):.2f}x) | the task's CPU in matches: 1 solver {median['1'][2]:.2f} s, "
                      f"2 solvers {median['2'][2]:.2f} s | the task's CPU in all: 1 solver {median['1'][3]:.2f} s, "
                      f"2 solvers {median['2'][3]:.2f} s ({median['1'][3] / median['2'][3]:.2f}x) | pieces by "
                      f"helpers: 1 solver {helped['1']:.0f}, 2 solvers {helped['2']:.0f} |")
            if "1 before" in median and "1" in median:
                b, a = median["1 before"], median["1"]
                print(f"| {name} | one solver, before / this code: job wall {b[0]:.2f} / {a[0]:.2f} s "
                      f"({b[0] / a[0]:.2f}x) | matches stage wall {b[1]:.2f} / {a[1]:.2f} s "
                      f"({(b[1] / a[1]) if a[1] else float('nan'):.2f}x) | the task's CPU in matches {b[2]:.2f} / "
                      f"{a[2]:.2f} s | the task's CPU in all {b[3]:.2f} / {a[3]:.2f} s |")
    print(f"load average at end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()

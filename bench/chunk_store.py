"""What a worker's task spends storing its items (issue 38): the Oxford Dinosaur's tracks (Oxford
VGG's data), solved once in chunks of 500 as a worker solves them, then stored as a task stores
them (``workers.tasks.ProgressPublisher`` fed by the runner's ``ItemProgress``: a store at the
first item, the rest with the last, the result's fragment among them) into an embedded Redis, a
fresh job each round. Prints per 1,000 items: the task's CPU storing them, Redis's own CPU (its
INFO used_cpu_user + used_cpu_sys) and the bytes written to Redis (INFO total_net_input_bytes),
beside the solve's CPU for scale, with the machine's load.

    .venv/bin/python -m bench.chunk_store [--detail brief|full] [--tracks 4983] [--rounds 5]
    .venv/bin/python -m bench.chunk_store --detail full --baseline ../main   # before and after, in turn

``--codecs``: instead, what a fragment's compression costs beside the rest (per 1,000 items, one
process): the result model's dump of the items (runner.result_fragment), zlib at the store's level
(Results.RESULT_COMPRESSION_LEVEL) and at level 0 (stored, not compressed), each compressing and
decompressing, with the bytes each keeps, against the solve.

``--baseline <checkout>``: bench.submission's: each run a process of its own with this checkout's
geocert or that one's, alternating, and the ratio of the medians of the task's CPU.

Nothing here asserts (tests/jobs/test_store.py and tests/workers/test_job_end.py check the behaviour).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

DINOSAUR = next((folder / "shared" / "data" / "oxford_dinosaur" for folder in Path(__file__).resolve().parents[2:4]
                 if (folder / "shared").is_dir()), Path("shared") / "data" / "oxford_dinosaur")
CHUNK = 500


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--detail", choices=("brief", "full"), default="brief")
    parser.add_argument("--tracks", type=int, default=4983)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--codecs", action="store_true", help="a fragment's compression against its other costs")
    parser.add_argument("--baseline", metavar="CHECKOUT")
    parser.add_argument("--baseline-rounds", type=int, default=4)
    args = parser.parse_args()
    if args.baseline:
        from bench.submission import against

        return against(args.baseline, args.baseline_rounds,
                       ["--detail", args.detail, "--tracks", str(args.tracks), "--rounds", str(args.rounds)],
                       bench="bench.chunk_store", what="storing 1,000 items")
    if args.codecs:
        return codecs(args.detail, args.rounds)
    measure(args.detail, args.tracks, args.rounds)


def codecs(detail: str, rounds: int) -> None:
    import zlib

    from geocert.jobs.runner import parse_job, result_fragment
    from geocert.jobs.store import JobStore

    kind, parsed, options = parse_job(dinosaur_job(detail, CHUNK))
    kind.solve_batch(parsed, list(range(CHUNK)), options, lambda progress: False)  # first-use costs out
    began = time.process_time()
    items = kind.solve_batch(parsed, list(range(CHUNK)), options, lambda progress: False)
    solve = time.process_time() - began

    def per_1000(work) -> tuple[float, object]:
        times = []
        for _ in range(rounds):
            began = time.process_time()
            out = work()
            times.append(time.process_time() - began)
        return 1e3 * statistics.median(times) * 1000 / CHUNK, out

    dump_ms, text = per_1000(lambda: result_fragment(kind, items))
    raw = text.encode()
    print(f"{CHUNK} Dinosaur tracks, detail {detail}: per 1,000 items, their solve {1e3 * solve * 1000 / CHUNK:.1f} ms "
          f"CPU, the result model's dump of them {dump_ms:.1f} ms, {len(raw) * 1000 / CHUNK / 1024:.0f} KiB of JSON")
    for level in (JobStore.RESULT_COMPRESSION_LEVEL, 0):
        packed_ms, packed = per_1000(lambda: zlib.compress(raw, level))
        unpacked_ms, _ = per_1000(lambda: zlib.decompress(packed))
        print(f"  zlib level {level}: compressing {packed_ms:.2f} ms CPU, decompressing {unpacked_ms:.2f} ms, "
              f"{len(packed) * 1000 / CHUNK / 1024:.0f} KiB kept ({len(packed) / len(raw):.2f} of the JSON)")
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


def dinosaur_job(detail: str, count: int) -> dict:
    from geocert.solvers.datasets import load_dinosaur

    cameras, tracks = load_dinosaur(DINOSAUR)
    return {"kind": "triangulation", "options": {"detail": detail},
            "data": {"cameras": cameras.tolist(),
                     "tracks": [{"views": list(t.views), "points": t.points.tolist()} for t in tracks[:count]]}}


def measure(detail: str, count: int, rounds: int) -> None:
    from geocert.workers.redis_server import start_embedded_redis

    process, url = start_embedded_redis(Path(tempfile.mkdtemp(prefix="chunk-store-")))
    os.environ["GEOCERT_REDIS_URL"] = url  # before the task module is imported: it reads it
    try:
        from geocert.jobs.runner import ItemProgress, abs_gap_of, parse_job
        from geocert.jobs.store import JobStore
        from geocert.workers.tasks import ProgressPublisher

        job = dinosaur_job(detail, count)
        kind, parsed, options = parse_job(job)
        began = time.process_time()
        chunks = [(start, min(start + CHUNK, count)) for start in range(0, count, CHUNK)]
        solved = {start: kind.solve_batch(parsed, list(range(start, stop)), options, lambda progress: False)
                  for start, stop in chunks}
        solve_s = time.process_time() - began
        jobs = JobStore.from_url(url)

        def server() -> tuple[float, int]:
            info = jobs.r.info()
            return info["used_cpu_user"] + info["used_cpu_sys"], info["total_net_input_bytes"]

        task_ms, redis_ms, written = [], [], []
        for _ in range(rounds):
            meta = jobs.create("triangulation", job, count, CHUNK, "bench", chunk_key="tracks")
            jobs.mark_running(meta["id"])
            redis_before, bytes_before = server()
            began = time.process_time()
            for start, stop in chunks:
                publisher = ProgressPublisher(jobs, meta["id"], start, 0.25, kind, abs_gap_of(options))
                tracker = ItemProgress(stop - start, publisher, None, abs_gap_of(options))
                for index, item in zip(range(start, stop), solved[start]):
                    publisher.item_ended(index, item)
                    tracker.finished(item)
                publisher.flush()
            task_ms.append(1e3 * (time.process_time() - began) * 1000 / count)
            redis_after, bytes_after = server()
            redis_ms.append(1e3 * (redis_after - redis_before) * 1000 / count)
            written.append((bytes_after - bytes_before) * 1000 / count)
            assert jobs.fragment_plan(meta["id"], count) is not None
            jobs.delete(meta["id"])
        print(f"{count} Dinosaur tracks, detail {detail}, chunks of {CHUNK}, {rounds} rounds; a track's item about "
              f"{len(str(solved[0][0]))} characters as a Python repr")
        print(f"per 1,000 items: task {statistics.median(task_ms):.3f} ms CPU storing them (median; "
              f"{min(task_ms):.3f} to {max(task_ms):.3f}), Redis {statistics.median(redis_ms):.2f} ms of its CPU, "
              f"{statistics.median(written) / 1024:.1f} KiB written to Redis; their solve "
              f"{1e3 * solve_s * 1000 / count:.1f} ms CPU; load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    finally:
        process.terminate()
        process.wait(timeout=10)


if __name__ == "__main__":
    sys.exit(main())

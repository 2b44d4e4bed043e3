"""What a hostile client can do to the service, attack by attack (issue 36), against real servers
on loopback (an embedded redis-server, the API, `geocert worker` processes), with two API keys:
the attacker's and another client's. For each attack it prints the API's peak memory growth and
CPU, the other key's slowest GET /v1/jobs while the API answered it, the peak memory of any
worker process, what the attacker got and how long until its job ended, and how long the other
key's small job (one track) waited to start and took to end, submitted right after the attack.

    .venv/bin/python -m bench.abuse [--only api,bodies,whole,worker,stereo,clocks,webhooks,fairness,orient,exports,memory]

  api       the attacks the API now refuses from the request alone (photo bombs, views, a bilinear
            basis, /v1/orient, stereo segments, webhook destinations, Last-Event-ID, names), with
            the default limits;
  bodies    the largest bodies over budget (about 32 MB of numbers each): the API's CPU and peak
            memory before refusing them, parsed whole (as before) and read from their shape (now),
            in the same run; then each sent to a server;
  whole     an 11.9 MB body of a kind without an item list to stream (a reconstruction's tracks),
            within budget, sent three times: what taking it whole costs the API (its CPU, peak
            memory and another key's slowest GET /v1/jobs meanwhile); the first spawns the API's
            submission processes;
  worker    the same jobs with the budgets raised so that they reach a worker: the worker's own
            bounds (its memory limit, the solvers' clock checks) and the other key's wait;
  stereo    the stereo_lines jobs of ``worker`` alone;
  clocks    jobs whose size alone would hold a worker far past their time limits: a triangulation of
            20,000 tracks each searched alone (tasks of 500, solved as batches), ended by its
            job_time_limit_s; a reconstruction of 100 views whose registration outlasts its
            limits in all (time_bound_s);
  webhooks  a tarpit receiver (a byte every 5 s) and a delete racing a delivery;
  fairness  the attacker queues 12 long jobs on one worker of two solver processes; the other
            key's wait with the per-key share and without it (GEOCERT_SOLVERS_KEPT_FOR_OTHERS=0:
            first come, first served), in the same run;
  orient    two /v1/orient at once at the cameras-times-points budget, three rounds: the other
            key's slowest GET /v1/jobs, and what the API and its orientation processes hold after;
  exports   eight exports at once (COLMAP, PLY, binary PLY) from one key of a 100,000-point
            reconstruction result;
  memory    the API's resident memory after each of a large streamed submission, its large result
            read, and two large certificate verifications at once (twice).

Each figure is printed beside what the review reproduced on the code before these limits (its
report's figures, on its machine: measuring them again would mean holding gigabytes and minutes
of this one); the fairness section measures both in the same run.

Nothing here asserts (tests/service/test_abuse.py checks behaviour); figures depend on the
machine and its load, printed with them.
"""

from __future__ import annotations

import base64
import json
import os
import threading
import time
from pathlib import Path

import cv2
import httpx
import numpy as np

from bench.faults import FIGURES, cluster, cpu_seconds, peak_rss_kib, run
from testing.receivers import Receiver

TERMINAL = ("succeeded", "failed", "cancelled")
ATTACKER, OTHER = {"X-API-Key": "attacker"}, {"X-API-Key": "other"}
KEYS = {"geocert_api_keys": "attacker,other", "geocert_max_active_jobs_per_key": "200"}
SMALL = {"kind": "triangulation", "data": {
    "cameras": [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]], [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]],
    "tracks": [{"views": [0, 1], "points": [[330, 250], [250, 251]]}]}}


RECONSTRUCTION_100 = ("reconstruction from tracks, 100 views, 5000 points, time_limit_s 0.001, "
                     "autocalibration_time_limit_s 0.05, structure_time_limit_s 1.5 (1.6 s in all)")


# What the review reproduced on the code before (one worker, embedded Redis, loopback).
PHOTO_BOMB = "202, queued; the API held +2.4 GB (every photo decoded at submission)"
WORKER_BOMB = ("a solver peaked at 5.9 GB, was killed at the 100 s hard limit and re-queued three times: 'Tasks "
               "lost' after 440 s; another key's one-track job waited 102 s")
DIRECT = "ran 205 s (killed, re-queued, then SoftTimeLimitExceeded); 1000 views: 7.8 GB"
STRATIFIED = "ran 19 times its limit, reported time_limit"
STEREO = "accepted; 2000 segments and 100,000 iterations held the worker 35 s a pair"
BEFORE = {
    "100 blank 5000x5000 PNGs (3.3 MB)": PHOTO_BOMB,
    "100 truncated JPEGs claiming 5000x5000 (53 kB)": PHOTO_BOMB + ", the decoder filling the missing data",
    "6 blank 5000x5000 PNGs, time_limit_s 1": WORKER_BOMB,
    "6 blank 5000x5000 PNGs, time_limit_s 1 (worker memory limit 4096 MiB)": WORKER_BOMB,
    "direct autocalibration, 300 views, time_limit_s 2": DIRECT,
    "stratified autocalibration, 200 views, time_limit_s 2": STRATIFIED,
    "bilinear, 300 shapes of 400 points (2.9 MB)": "100 s of the API's CPU before queueing; other keys' GET /v1/jobs "
                                                   "took 1.7-5.6 s",
    "/v1/orient, 300 cameras, 200k points": "the API held +2.1 GB",
    "stereo_lines, 2000 segments an image": STEREO,
    "stereo_lines, 2000 segments an image, 100000 iterations, time_limit_s 2": STEREO,
    "callback_url http://169.254.169.254/latest/meta-data": "accepted, and delivered to; the record told a closed "
                                                            "port from an open one",
    "Last-Event-ID 18446744073709551616-0": "an ASGI exception, or a dropped connection",
    "a view named 'a\\n1 0 0 0 ...' (a COLMAP record)": "accepted; the newline injected a record into images.txt",
    "a tarpit receiver (a byte every 5 s), 3 attempts of 10 s": "held the only worker 89 s; the record stayed 'waiting', "
                                                               "attempts 0, for ever",
    "a job deleted while its webhook is delivered": "geocert:job:{id} re-created with the callback URL and no expiry",
    # Not in the review: the batches' and the registration's missing clocks (from the code
    # before: a task of 500 tracks was held to 500 times time_limit_s).
    **{f"triangulation, 20,000 tracks each searched alone, time_limit_s 30, job_time_limit_s {limit}":
       "no clock in all: each task of 500 tracks allowed 500 x 30 s (its Celery limits 15,000 s + 180 s); the "
       "20,000 searches about 10 ms each: 200 s of a solver" for limit in (10, 2)},
    RECONSTRUCTION_100: "no clock in the registration or the adjustments (they asked for a cancel only): they ran "
                        "to their end whatever the job's limits in all",
}


def report(what: str, measured: str) -> None:
    before = BEFORE.get(what, "")
    FIGURES.append((what, measured, before))
    print(f"  {what}: {measured}" + (f"\n    before: {before}" if before else ""), flush=True)


# --- the attacks' bodies -----------------------------------------------------------------------
def blank_png(side: int) -> str:
    return base64.b64encode(cv2.imencode(".png", np.zeros((side, side), np.uint8))[1].tobytes()).decode()


def truncated_jpeg(side: int) -> str:
    """A JPEG whose header claims side x side, cut after its first 400 bytes."""
    data = cv2.imencode(".jpg", np.random.default_rng(0).integers(0, 255, (64, 64), dtype=np.uint8))[1].tobytes()
    at = data.find(b"\xff\xc0") + 5
    data = data[:at] + side.to_bytes(2, "big") + side.to_bytes(2, "big") + data[at + 4:]
    return base64.b64encode(data[:400]).decode()


def photos(contents: list[str], **options) -> dict:
    return {"kind": "reconstruction", "options": options,
            "data": {"images": [{"name": f"p{i}", "content": c} for i, c in enumerate(contents)]}}


def autocalibration(views: int, method: str, time_limit_s: float) -> dict:
    from geocert.solvers.autocalibration import scenes

    return {"kind": "autocalibration", "data": scenes.make_scene(views, 0.1, seed=5).job_data(),
            "options": {"method": method, "time_limit_s": time_limit_s,
                        **({"chirality": "none"} if method == "direct" else {})}}  # else too many pairs


def bilinear(shapes: int, points: int) -> dict:
    rng = np.random.default_rng(0)
    return {"kind": "bilinear", "data": {"basis": np.round(rng.normal(size=(shapes, points, 3)), 4).tolist(),
                                         "frames": [{"points": np.round(rng.normal(size=(points, 2)), 3).tolist()}]}}


def orient(cameras: int, points: int) -> dict:
    rng = np.random.default_rng(1)
    return {"cameras": np.round(rng.normal(size=(cameras, 3, 4)), 4).tolist(),
            "points": np.round(rng.normal(size=(points, 3)), 3).tolist(),
            "views": [[0, 1]] * points}


def stereo(segments: int, time_limit_s: float = 10.0) -> dict:
    job = json.loads((Path(__file__).parents[1] / "examples" / "stereo-lines-pair.json").read_text())
    rng = np.random.default_rng(2)
    for frame in job["data"]["frames"]:
        for side in ("left", "right"):
            frame[side] = np.round(rng.uniform(0, 640, size=(segments, 4)), 2).tolist()
    job["options"] = {"ransac": {"max_iterations": 100_000}, "time_limit_s": time_limit_s}
    return job


# --- measuring ---------------------------------------------------------------------------------
def tree(pid: int) -> list[int]:
    """A process and its descendants."""
    found, todo = [], [pid]
    while todo:
        current = todo.pop()
        found.append(current)
        try:
            with open(f"/proc/{current}/task/{current}/children") as children:
                todo.extend(int(child) for child in children.read().split())
        except OSError:
            pass
    return found


def rss_kib(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))
    except (OSError, StopIteration):
        return 0


class WorkerPeak:
    """The largest resident size of any one process of the workers, sampled every 0.1 s."""

    def __init__(self, running):
        self.running, self.peak, self.stopped = running, 0, threading.Event()
        self.thread = threading.Thread(target=self._sample, daemon=True)
        self.thread.start()

    def _sample(self):
        while not self.stopped.wait(0.1):
            for worker in self.running.workers:
                for pid in tree(worker.pid):
                    self.peak = max(self.peak, rss_kib(pid))

    def stop(self) -> float:
        self.stopped.set()
        self.thread.join()
        return self.peak / 1024


def wait_end(client, job_id: str, headers: dict, limit_s: float) -> dict | None:
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        job = client.get(f"/v1/jobs/{job_id}", headers=headers).json()
        if job["status"] in TERMINAL:
            return job
        time.sleep(0.2)
    return None


def other_keys_job(client) -> tuple[float, float]:
    """The other key's one-track job, submitted now: seconds until it started and until it ended."""
    job_id = client.post("/v1/jobs", json=SMALL, headers=OTHER).json()["id"]
    job = wait_end(client, job_id, OTHER, 900)
    if job is None:
        return float("nan"), float("nan")
    return job["started_at"] - job["created_at"], job["finished_at"] - job["created_at"]


class OtherKeysReads:
    """The other key listing its jobs (GET /v1/jobs) every 0.1 s while an attack is answered: the
    slowest answer."""

    def __init__(self, running):
        self.client = httpx.Client(base_url=str(running.client.base_url), timeout=120)
        self.slowest, self.stopped = 0.0, threading.Event()
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self):
        while not self.stopped.is_set():
            began = time.monotonic()
            self.client.get("/v1/jobs", headers=OTHER)
            self.slowest = max(self.slowest, time.monotonic() - began)
            self.stopped.wait(0.1)

    def stop(self) -> float:
        self.stopped.set()
        self.thread.join()
        self.client.close()
        return self.slowest


def attack(running, name: str, send, limit_s: float = 900) -> None:
    """Send an attack (``send(client)`` -> the response), then the other key's small job; report."""
    client = running.client
    api_before, api_cpu = peak_rss_kib(running.api.pid), cpu_seconds(running.api.pid)
    workers = WorkerPeak(running)
    reads = OtherKeysReads(running)
    began = time.monotonic()
    response = send(client)
    answered = time.monotonic() - began
    slowest_read = reads.stop()
    outcome = f"{response.status_code} in {answered:.1f} s"
    job_id = response.json().get("id") if response.status_code in (200, 202) and "jobs" in str(response.url) else None
    started, finished = other_keys_job(client)
    if job_id is not None:
        job = wait_end(client, job_id, ATTACKER, limit_s)
        if job is None:
            outcome += f"; the job had not ended after {limit_s:.0f} s"
            client.post(f"/v1/jobs/{job_id}/cancel", headers=ATTACKER)
        else:
            why = (job["error"] or {}).get("title") or ", ".join(
                f"{s['name']} {s['status']}" for s in (job["result"] or {}).get("stages", [])[:3]) or ""
            outcome += f"; the job ended {job['status']} ({why}) {time.monotonic() - began:.1f} s after it was sent"
    else:
        detail = (response.json().get("detail") or "")[:170] if response.headers.get("content-type", "").endswith("json") else ""
        outcome += f": {detail}"
    api_grew = (peak_rss_kib(running.api.pid) - api_before) / 1024
    report(name, f"{outcome}; API peak +{api_grew:.0f} MiB, {cpu_seconds(running.api.pid) - api_cpu:.1f} s CPU; "
                 f"the other key's GET /v1/jobs meanwhile at most {slowest_read:.2f} s; largest worker process {workers.stop():.0f} MiB; the other key's job started after "
                 f"{started:.1f} s, ended after {finished:.1f} s")


def post(path: str, body: dict, headers: dict | None = None):
    return lambda client: client.post(path, json=body, headers=headers or ATTACKER, timeout=600)


# --- sections ----------------------------------------------------------------------------------
def bench_api() -> None:
    print("api: refused from the request, default limits", flush=True)
    with cluster(workers=1, concurrency=2, **KEYS) as running:
        attack(running, "100 blank 5000x5000 PNGs (3.3 MB)", post("/v1/jobs", photos([blank_png(5000)] * 100)))
        attack(running, "100 truncated JPEGs claiming 5000x5000 (53 kB)", post("/v1/jobs", photos([truncated_jpeg(5000)] * 100)))
        attack(running, "6 blank 5000x5000 PNGs, time_limit_s 1", post("/v1/jobs", photos([blank_png(5000)] * 6, time_limit_s=1)))
        attack(running, "direct autocalibration, 300 views, time_limit_s 2", post("/v1/jobs", autocalibration(300, "direct", 2)))
        attack(running, "stratified autocalibration, 200 views, time_limit_s 2",
               post("/v1/jobs", autocalibration(200, "stratified", 2)))
        attack(running, "bilinear, 300 shapes of 400 points (2.9 MB)", post("/v1/jobs", bilinear(300, 400)))
        attack(running, "/v1/orient, 300 cameras, 200k points", post("/v1/orient", orient(300, 200_000)))
        attack(running, "stereo_lines, 2000 segments an image", post("/v1/jobs", stereo(2000)))
        attack(running, "callback_url http://169.254.169.254/latest/meta-data",
               post("/v1/jobs", {**SMALL, "callback_url": "http://169.254.169.254/latest/meta-data"}))
        job_id = running.client.post("/v1/jobs", json=SMALL, headers=ATTACKER).json()["id"]
        attack(running, "Last-Event-ID 18446744073709551616-0",
               lambda client: client.get(f"/v1/jobs/{job_id}/events", headers={**ATTACKER,
                                                                                "Last-Event-ID": "18446744073709551616-0"}))
        attack(running, "a view named 'a\\n1 0 0 0 ...' (a COLMAP record)", post("/v1/jobs", {
            "kind": "reconstruction", "data": {"views": [{"name": "a\n1 1 0 0 0 0 0 0 1 x.png", "image_size": [640, 480]}] * 2,
                                               "tracks": [{"views": [0, 1], "points": [[1, 2], [3, 4]]}]}}))
        report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


def bench_worker() -> None:
    print("worker: the same jobs with the budgets raised, so that they reach a worker", flush=True)
    raised = {"geocert_max_image_pixels": "25000000", "geocert_max_image_pixels_per_job": "1000000000",
              "geocert_max_autocalibration_views": "1000", "geocert_max_segments_per_frame": "100000"}
    with cluster(workers=1, concurrency=2, **KEYS, **raised) as running:
        attack(running, "6 blank 5000x5000 PNGs, time_limit_s 1 (worker memory limit 4096 MiB)",
               post("/v1/jobs", photos([blank_png(5000)] * 6, time_limit_s=1)))
        attack(running, "direct autocalibration, 300 views, time_limit_s 2", post("/v1/jobs", autocalibration(300, "direct", 2)))
        attack(running, "stratified autocalibration, 200 views, time_limit_s 2",
               post("/v1/jobs", autocalibration(200, "stratified", 2)))
        attack(running, "stratified autocalibration, 50 views (the default limit), time_limit_s 2",
               post("/v1/jobs", autocalibration(50, "stratified", 2)))
        attack(running, "stereo_lines, 2000 segments an image, 100000 iterations, time_limit_s 2",
               post("/v1/jobs", stereo(2000, 2)))
        attack(running, "stereo_lines, 1000 segments an image (the default limit), 100000 iterations, time_limit_s 2",
               post("/v1/jobs", stereo(1000, 2)))
        report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


def bench_stereo() -> None:
    """The stereo attacks of ``worker`` alone: random segments a frame pair, time_limit_s 2, with
    the segment budget raised so that they reach a worker."""
    print("stereo: random segments a pair, time_limit_s 2, the budget raised", flush=True)
    with cluster(workers=1, concurrency=2, **KEYS, geocert_max_segments_per_frame="100000") as running:
        for segments in (2000, 1000):
            attack(running, f"stereo_lines, {segments} segments an image, 100000 iterations, time_limit_s 2, alone",
                   post("/v1/jobs", stereo(segments, 2)))
        report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


def searched_tracks(tracks: int, job_time_limit_s: float) -> dict:
    """Tracks each solved by a search of its own (a scope limit, max_residual, sends every track
    of a batch to the search alone): milliseconds each, one after another in its batch."""
    from testing.jobs import service_job

    return service_job(np.random.default_rng(7), tracks, views=4, max_residual=50.0, detail="brief",
                       time_limit_s=30, job_time_limit_s=job_time_limit_s)


def reconstruction_tracks(views: int, points: int) -> dict:
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=views, points=points, seed=3, noise_px=0.3)
    return {"kind": "reconstruction",
            "options": {"time_limit_s": 0.001, "autocalibration_time_limit_s": 0.05, "structure_time_limit_s": 1.5},
            "data": {"views": [{"image_size": list(scene.image_size)}] * views,
                     "tracks": [{"views": [int(v) for v in seen], "points": np.round(pixels, 3).tolist()}
                                for seen, pixels in scene.tracks]}}


def kept_and_stopped(client, job_id: str) -> str:
    """What a job the clock ended kept: its items' statuses (a triangulation's tracks), or its
    stages' (a reconstruction's)."""
    job = client.get(f"/v1/jobs/{job_id}", headers=ATTACKER).json()
    ran = f"ran {job['finished_at'] - job['started_at']:.1f} s from its start; " if job.get("finished_at") else ""
    result = job.get("result") or {}
    if "tracks" in result:
        not_started = sum("not started" in (track["reason"] or "") for track in result["tracks"])
        return (f"{ran}tracks {result['stats']['statuses']}, {not_started} of them not started, "
                f"{result['stats']['certified']} certified")
    registered = sum(camera["registered"] for camera in result["cameras"])
    return f"{ran}item {result['stats']['statuses']}, {registered} views registered, {len(result['points'])} points"


def bench_clocks() -> None:
    """Jobs whose size alone would hold a worker far past their limits, ended by their clock in
    all: job_time_limit_s (a triangulation's tracks, solved 500 at a time) and a reconstruction's
    time_bound_s (its registration and adjustments, which had no clock)."""
    print("clocks: large jobs ended by their time limit in all", flush=True)
    with cluster(workers=1, concurrency=2, **KEYS) as running:
        jobs = [(f"triangulation, 20,000 tracks each searched alone, time_limit_s 30, job_time_limit_s {limit}",
                 searched_tracks(20_000, limit)) for limit in (10, 2)]
        jobs.append((RECONSTRUCTION_100, reconstruction_tracks(100, 5000)))
        for name, body in jobs:
            sent = {}

            def send(client, body=body, sent=sent):
                response = client.post("/v1/jobs", json=body, headers=ATTACKER, timeout=600)
                sent["id"] = response.json().get("id")
                return response
            attack(running, name, send)
            report("  what it kept", kept_and_stopped(running.client, sent["id"]))
        report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


def bench_webhooks() -> None:
    print("webhooks: a tarpit receiver, a delete racing a delivery", flush=True)
    release = threading.Event()

    def tarpit(handler):
        while not release.wait(5.0):
            try:
                handler.wfile.write(b"H")
                handler.wfile.flush()
            except OSError:
                return

    with cluster(workers=1, concurrency=1, geocert_webhook_allowed_networks="127.0.0.1/32",
                 geocert_webhook_attempts="3", **KEYS) as running:
        receiver = Receiver(tarpit)
        client = running.client
        began = time.monotonic()
        job_id = client.post("/v1/jobs", json={**SMALL, "callback_url": receiver.url}, headers=ATTACKER).json()["id"]
        wait_end(client, job_id, ATTACKER, 120)
        while receiver.received == 0 and time.monotonic() - began < 120:
            time.sleep(0.1)
        started, finished = other_keys_job(client)
        hook = None
        while time.monotonic() - began < 600:
            hook = client.get(f"/v1/jobs/{job_id}", headers=ATTACKER).json()["webhook"]
            if hook["state"] in ("failed", "delivered", "refused"):
                break
            time.sleep(0.5)
        report("a tarpit receiver (a byte every 5 s), 3 attempts of 10 s",
               f"the record said {hook['state']} after {hook['attempts']} attempts, {time.monotonic() - began:.0f} s "
               f"after the job was sent ({hook['last_error']}); the other key's job meanwhile started after "
               f"{started:.1f} s, ended after {finished:.1f} s")
        release.set()
        deleted = threading.Event()

        def after_delete(handler):
            deleted.wait(30)
            handler.send_response(200)
            handler.send_header("Content-Length", "0")
            handler.end_headers()

        receiver = Receiver(after_delete)
        job_id = client.post("/v1/jobs", json={**SMALL, "callback_url": receiver.url}, headers=ATTACKER).json()["id"]
        wait_end(client, job_id, ATTACKER, 120)
        while receiver.received == 0:
            time.sleep(0.05)
        client.delete(f"/v1/jobs/{job_id}", headers=ATTACKER)
        deleted.set()
        time.sleep(3)
        store = running.redis_client()
        left = list(store.scan_iter(f"geocert:job:{job_id}*"))
        unexpiring = [key for key in store.scan_iter("geocert:job:*") if store.ttl(key) == -1]
        report("a job deleted while its webhook is delivered", f"{len(left)} keys of it left; {len(unexpiring)} job keys "
                                                               "without an expiry in all")


def bench_fairness(flood: int = 12) -> None:
    print(f"fairness: {flood} long jobs of one key, one worker of two solver processes", flush=True)
    for kept, label in (("1", "with the per-key share (GEOCERT_SOLVERS_KEPT_FOR_OTHERS=1)"),
                        ("0", "first come, first served (GEOCERT_SOLVERS_KEPT_FOR_OTHERS=0)")):
        with cluster(workers=1, concurrency=2, geocert_solvers_kept_for_others=kept, **KEYS) as running:
            client = running.client
            long_job = autocalibration(4, "stratified", 5)
            long_job["data"].pop("points")  # neither stage closes its gap: each runs its 5 s
            jobs = [client.post("/v1/jobs", json=long_job, headers=ATTACKER).json()["id"] for _ in range(flood)]
            time.sleep(3)
            started, finished = other_keys_job(client)
            report(f"the other key's job behind {flood} jobs of 2 x 5 s, {label}",
                   f"started after {started:.1f} s, ended after {finished:.1f} s")
            for job_id in jobs:
                client.post(f"/v1/jobs/{job_id}/cancel", headers=ATTACKER)
    report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


def _parse_cost(body: bytes, route: str, how: str, answer) -> None:
    """In a child process: the CPU seconds and peak memory growth of what the API does with a
    body before it can refuse it over budget, ``how``: "parsed" (the JSON parsed and validated by
    the route's model, as the API did) or "shape" (app.shape, as it does now)."""
    def peak_mib() -> float:
        with open("/proc/self/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:")) / 1024

    from geocert.app import shape
    from geocert.app.schemas import JobRequest, OrientRequest
    from pydantic import TypeAdapter

    model = TypeAdapter(OrientRequest if route == "/v1/orient" else JobRequest)
    figures = shape.orient_figures if route == "/v1/orient" else shape.job_figures
    base, began = peak_mib(), time.process_time()
    try:
        if how == "parsed":
            model.validate_python(json.loads(body))
        refused = shape.over_budget_by_shape(body, figures) is not None  # the figure: from the shape, or once parsed
    except Exception as exc:  # noqa: BLE001 - said in the figures, not a hang
        answer.put((time.process_time() - began, peak_mib() - base, f"{type(exc).__name__}"[:80]))
        return
    answer.put((time.process_time() - began, peak_mib() - base, refused))


def bench_bodies() -> None:
    """The largest bodies the body limit lets through (about 32 MB of numbers), each over its
    budget: what reading them costs the API before the refusal, parsed whole (as before) and read
    from their shape (now), in the same run, each in a fresh process; then the attack itself on a
    server (its API's CPU and peak memory)."""
    import multiprocessing

    print("bodies: the largest bodies over budget, parsed whole against read from their shape", flush=True)
    rng = np.random.default_rng(4)
    frames = [{"left": np.round(rng.uniform(0, 640, (160_000, 4)), 2).tolist(),
               "right": np.round(rng.uniform(0, 640, (160_000, 4)), 2).tolist()} for _ in range(2)]
    stereo_job = json.loads((Path(__file__).parents[1] / "examples" / "stereo-lines-pair.json").read_text())
    stereo_job["data"]["frames"] = frames
    from geocert.solvers.autocalibration import scenes

    many_points = scenes.make_scene(50, 0.1, seed=5).job_data()
    many_points["points"] = np.round(rng.normal(size=(800_000, 4)), 3).tolist()
    bodies = {
        "/v1/orient, 300 cameras, 1M points": ("/v1/orient", orient(300, 1_000_000)),
        "bilinear, a basis of 2700 shapes of 400 points": ("/v1/jobs", bilinear(2700, 400)),
        "autocalibration, 50 views, 800k points": ("/v1/jobs", {"kind": "autocalibration", "data": many_points}),
        "stereo_lines, 160,000 segments an image": ("/v1/jobs", stereo_job),
    }
    context = multiprocessing.get_context("fork")
    for name, (route, request) in bodies.items():
        body = json.dumps(request).encode()
        figures = []
        for how in ("parsed", "shape"):
            answer = context.Queue()
            child = context.Process(target=_parse_cost, args=(body, route, how, answer))
            child.start()
            cpu, grew, refused = answer.get()
            child.join()
            said = "" if refused is True else " (not refused!)" if refused is False else f" ({refused})"
            figures.append(f"{how}: {cpu:.2f} s CPU, +{grew:.0f} MiB{said}")
        report(f"{name} ({len(body) / 1e6:.1f} MB)", "; ".join(figures))
    with cluster(workers=1, concurrency=2, **KEYS) as running:
        for name, (route, request) in bodies.items():
            attack(running, f"{name}, sent", post(route, request))
    report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


def bench_whole() -> None:
    print("whole: a large body taken whole, three times", flush=True)
    body = reconstruction_tracks(100, 5000)
    with cluster(workers=1, concurrency=2, **KEYS) as running:
        for which in ("first", "second", "third"):
            attack(running, f"reconstruction from tracks, 100 views, 5000 points (11.9 MB), sent whole, {which}",
                   post("/v1/jobs", body))
    report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


def resident_mib(running) -> tuple[float, float]:
    """The API process's resident memory now, and that of its child processes (submissions,
    orientations) together, in MiB."""
    api = running.api.pid
    return rss_kib(api) / 1024, sum(rss_kib(pid) for pid in tree(api) if pid != api) / 1024


def at_once(running, name: str, sends: list) -> None:
    """Send requests at once (``send(client)`` each, from threads); report their answers, the API's
    peak growth and CPU, the other key's slowest GET /v1/jobs meanwhile, and the memory the API
    and its child processes hold afterwards."""
    api_before, api_cpu = peak_rss_kib(running.api.pid), cpu_seconds(running.api.pid)
    reads = OtherKeysReads(running)
    answers: list[str] = []
    began = time.monotonic()

    def one(send):
        with httpx.Client(base_url=str(running.client.base_url), timeout=600) as own:
            sent = time.monotonic()
            response = send(own)
            answers.append(f"{response.status_code} in {time.monotonic() - sent:.1f} s")

    threads = [threading.Thread(target=one, args=(send,)) for send in sends]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    took = time.monotonic() - began
    slowest_read = reads.stop()
    time.sleep(1)  # what is still held a second after the answers
    api_now, children_now = resident_mib(running)
    answers.sort()
    report(name, f"{', '.join(answers)} ({took:.1f} s in all); API peak +{(peak_rss_kib(running.api.pid) - api_before) / 1024:.0f} MiB, "
                 f"{cpu_seconds(running.api.pid) - api_cpu:.1f} s CPU; the other key's GET /v1/jobs meanwhile at most "
                 f"{slowest_read:.2f} s; resident a second later: the API {api_now:.0f} MiB, its child processes "
                 f"{children_now:.0f} MiB")


def bench_orient() -> None:
    body = orient(20, 200_000)  # at the budget: 4M cameras x points
    size = len(json.dumps(body)) / 1e6
    print("orient: /v1/orient at its budget, two at once (GEOCERT_MAX_CONCURRENT_ORIENTATIONS)", flush=True)
    with cluster(workers=1, concurrency=2, **KEYS) as running:
        api_now, _ = resident_mib(running)
        report("the API's resident memory at the start", f"{api_now:.0f} MiB")
        for which in ("first", "second", "third"):
            at_once(running, f"two /v1/orient at once, 20 cameras x 200k points ({size:.1f} MB each), {which}",
                    [post("/v1/orient", body)] * 2)
    report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


def bench_exports(at_once_count: int = 8, copies: int = 50) -> None:
    """Exports of a large reconstruction's result (COLMAP's text model, PLY), many at once: each
    reads the whole result, decodes it and writes the export in the API process. The result is a
    solved reconstruction's (12 views, 2000 points) with its points repeated ``copies`` times,
    stored in its place (a reconstruction of 100,000 points is within the job limits, and would
    take the worker far longer to solve)."""
    import zlib

    import redis

    print(f"exports: {at_once_count} exports at once of a large reconstruction", flush=True)
    body = reconstruction_tracks(12, 2000)
    body["options"] = {}
    with cluster(workers=1, concurrency=2, **KEYS) as running:
        client = running.client
        job_id = client.post("/v1/jobs", json=body, headers=ATTACKER, timeout=600).json()["id"]
        job = wait_end(client, job_id, ATTACKER, 900)
        result = job["result"]
        result["points"] = result["points"] * copies
        text = json.dumps(result).encode()
        store = redis.Redis.from_url(running.redis_url)
        store.set(f"geocert:job:{job_id}:result", zlib.compress(text, 1))
        store.hset(f"geocert:job:{job_id}", mapping={"result_encoding": json.dumps("zlib"), "result_form": json.dumps("model")})
        report("the reconstruction exported", f"{job['status']}, {sum(c['registered'] for c in result['cameras'])} views "
                                              f"registered, its {len(result['points']) // copies} points repeated {copies} "
                                              f"times: {len(result['points'])} points, a result of {len(text) / 1e6:.0f} MB")
        for query in ("format=colmap", "format=ply", "format=ply&binary=true"):
            path = f"/v1/jobs/{job_id}/export?{query}"
            at_once(running, f"{at_once_count} exports at once, {query}",
                    [lambda own, path=path: own.get(path, headers=ATTACKER)] * at_once_count)
    report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


def bench_memory() -> None:
    """What the API process keeps after large requests it answers itself, one after another: its
    resident memory a second after each (glibc keeps what a request freed in its arenas, unless
    given back)."""
    print("memory: the API's resident memory after large requests", flush=True)
    rng = np.random.default_rng(8)
    tracks = [{"views": [0, 1], "points": [[float(x), float(y)], [float(x) - 80, float(y) + 1]]}
              for x, y in np.round(rng.uniform(100, 500, (100_000, 2)), 2)]
    many = {**SMALL, "data": {**SMALL["data"], "tracks": tracks}, "options": {"job_time_limit_s": 1}}
    document = {"kind": "triangulation", "items": np.round(rng.normal(size=(250_000, 10)), 6).tolist()}
    with cluster(workers=1, concurrency=2, **KEYS) as running:
        report("the API's resident memory at the start", f"{resident_mib(running)[0]:.0f} MiB")
        sent: dict = {}

        def submit(own):
            response = own.post("/v1/jobs", json=many, headers=ATTACKER)
            sent["id"] = response.json().get("id")
            return response
        at_once(running, f"a triangulation of 100,000 tracks ({len(json.dumps(many)) / 1e6:.1f} MB, read item by item)",
                [submit])
        wait_end(running.client, sent["id"], ATTACKER, 900)
        at_once(running, "its result read twice at once (100,000 tracks, most not started)",
                [lambda own: own.get(f"/v1/jobs/{sent['id']}", headers=ATTACKER)] * 2)
        at_once(running, f"two certificate verifications at once of a {len(json.dumps(document)) / 1e6:.0f} MB document",
                [post("/v1/certificates/verify", document)] * 2)
        at_once(running, "the same again", [post("/v1/certificates/verify", document)] * 2)
    report("the machine meanwhile (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


SECTIONS = {"api": bench_api, "bodies": bench_bodies, "whole": bench_whole, "worker": bench_worker, "stereo": bench_stereo,
            "clocks": bench_clocks, "webhooks": bench_webhooks, "fairness": bench_fairness, "orient": bench_orient,
            "exports": bench_exports, "memory": bench_memory}


def main() -> None:
    run(SECTIONS, __doc__, "attack", "before (the review's figure)")


if __name__ == "__main__":
    main()

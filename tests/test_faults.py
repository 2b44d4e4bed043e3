"""Faults a production service meets, through real processes on loopback: Redis going away and
coming back, bodies over the limit sent chunked, SIGTERM with streams open, slow-header clients,
and one client flooding the others' budget."""

from __future__ import annotations

import time

import numpy as np
import pytest

from .servers import cluster
from .support import service_job as triangulation_job

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

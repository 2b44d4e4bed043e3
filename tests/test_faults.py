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

"""A service other services can depend on: keys, limits, idempotency, deletion, webhooks and
metrics, through real processes on loopback."""

from __future__ import annotations

import hashlib
import hmac
import http.server
import json
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from tests.servers import cluster
from tests.support import service_job as triangulation_job

KEY_A, KEY_B, KEY_C = "key-alpha-0123456789", "key-beta-9876543210", "key-gamma-listing-only"
SECRET = "webhook-test-secret"
A, B, C = {"X-API-Key": KEY_A}, {"X-API-Key": KEY_B}, {"X-API-Key": KEY_C}


pytestmark = pytest.mark.slow  # real servers, real data or SCIP: the full run only


def wait_for_end(client, job_id: str, headers: dict, limit_s: float = 60) -> dict:
    deadline = time.monotonic() + limit_s
    while True:
        job = client.get(f"/v1/jobs/{job_id}", headers=headers).json()
        if job["status"] in ("succeeded", "failed", "cancelled"):
            return job
        assert time.monotonic() < deadline, f"job {job_id} still {job['status']} after {limit_s} s"
        time.sleep(0.1)


def small_job(seed: int = 0, tracks: int = 3, **options) -> dict:
    return triangulation_job(np.random.default_rng(seed), tracks, **options)


@pytest.fixture(scope="module")
def keyed(tmp_path_factory):
    digest_b = hashlib.sha256(KEY_B.encode()).hexdigest()
    with cluster(tmp_path_factory.mktemp("keyed"), workers=1, geocert_api_keys=f"{KEY_A}, sha256:{digest_b}, {KEY_C}",
                 geocert_webhook_secret=SECRET, geocert_webhook_backoff_s="0.2", geocert_webhook_attempts="3",
                 geocert_webhook_allowed_networks="127.0.0.1/32",  # the receivers below listen on loopback
                 geocert_progress_interval_s="0.05") as (_, client):
        yield client


class TestAuthentication:
    def test_no_key_is_401_and_a_wrong_key_403(self, keyed):
        for method, path in (("POST", "/v1/jobs"), ("GET", "/v1/jobs/abc"), ("GET", "/v1/problems")):
            missing = keyed.request(method, path, json=small_job())
            assert missing.status_code == 401
            assert missing.headers["content-type"] == "application/problem+json"
            assert "X-API-Key" in missing.json()["detail"]
            wrong = keyed.request(method, path, json=small_job(), headers={"X-API-Key": "not-a-key"})
            assert wrong.status_code == 403 and wrong.json()["status"] == 403

    def test_a_job_is_visible_only_to_its_key(self, keyed):
        created = keyed.post("/v1/jobs", json=small_job(), headers=A)
        assert created.status_code == 202
        job_id = created.json()["id"]
        assert keyed.get(f"/v1/jobs/{job_id}", headers=A).status_code == 200
        for method, path in (("GET", f"/v1/jobs/{job_id}"), ("POST", f"/v1/jobs/{job_id}/cancel"),
                             ("GET", f"/v1/jobs/{job_id}/events"), ("DELETE", f"/v1/jobs/{job_id}")):
            other = keyed.request(method, path, headers=B)  # B is configured as a sha256: digest
            assert other.status_code == 404, (method, path)
        assert wait_for_end(keyed, job_id, A)["status"] == "succeeded"

    def test_health_and_metrics_need_no_key(self, keyed):
        assert keyed.get("/healthz").status_code == 200
        assert keyed.get("/metrics").status_code == 200


class TestIdempotency:
    def test_same_key_and_body_give_the_same_job(self, keyed):
        body = small_job(seed=5)
        first = keyed.post("/v1/jobs", json=body, headers={**A, "Idempotency-Key": "order-17"})
        again = keyed.post("/v1/jobs", json=body, headers={**A, "Idempotency-Key": "order-17"})
        assert first.status_code == 202 and again.status_code == 200
        assert again.json()["id"] == first.json()["id"] and again.headers["Idempotent-Replayed"] == "true"
        other_body = small_job(seed=6)
        conflict = keyed.post("/v1/jobs", json=other_body, headers={**A, "Idempotency-Key": "order-17"})
        assert conflict.status_code == 422
        assert conflict.json()["errors"][0]["field"] == "Idempotency-Key"
        # Keys belong to their caller: B's "order-17" is a job of its own.
        theirs = keyed.post("/v1/jobs", json=body, headers={**B, "Idempotency-Key": "order-17"})
        assert theirs.status_code == 202 and theirs.json()["id"] != first.json()["id"]

    def test_an_invalid_body_does_not_take_the_key(self, keyed):
        bad = small_job()
        bad["data"]["tracks"][0]["views"] = [0, 99]
        assert keyed.post("/v1/jobs", json=bad, headers={**A, "Idempotency-Key": "k2"}).status_code == 422
        assert keyed.post("/v1/jobs", json=small_job(), headers={**A, "Idempotency-Key": "k2"}).status_code == 202


class TestDeletion:
    def test_only_finished_jobs_are_deleted(self, keyed):
        slow = keyed.post("/v1/jobs", json=small_job(seed=9, tracks=400), headers=A).json()
        refused = keyed.delete(f"/v1/jobs/{slow['id']}", headers=A)
        assert refused.status_code == 409 and "cancel it first" in refused.json()["detail"]
        keyed.post(f"/v1/jobs/{slow['id']}/cancel", headers=A)
        assert wait_for_end(keyed, slow["id"], A)["status"] in ("cancelled", "succeeded")
        assert keyed.delete(f"/v1/jobs/{slow['id']}", headers=A).status_code == 204
        assert keyed.get(f"/v1/jobs/{slow['id']}", headers=A).status_code == 404


class TestListing:
    """GET /v1/jobs: the caller's jobs (KEY_C makes jobs only here), newest first, by pages."""

    @staticmethod
    def pages(client, query: str, headers: dict) -> list[dict]:
        listed, url = [], f"/v1/jobs?{query}"
        while url:
            response = client.get(url, headers=headers)
            assert response.status_code == 200, response.text
            page = response.json()
            listed.append(page)
            url = page["links"]["next"]
            assert (page["next_cursor"] is None) == (url is None)
            if url:
                assert response.headers["Link"] == f'<{url}>; rel="next"'
        return listed

    def test_newest_first_in_pages_with_a_status_filter_and_only_the_callers(self, keyed):
        made = []
        for seed in range(5):
            made.append(keyed.post("/v1/jobs", json=small_job(seed=40 + seed, tracks=1), headers=C).json()["id"])
        for job_id in made:
            assert wait_for_end(keyed, job_id, C)["status"] == "succeeded"
        long = keyed.post("/v1/jobs", json=small_job(seed=46, tracks=1, views=6, norm="L1L1", rel_gap=0.0,
                                                     abs_gap=0.0, max_nodes=100_000, time_limit_s=30), headers=C)
        long_id = long.json()["id"]
        keyed.post(f"/v1/jobs/{long_id}/cancel", headers=C)
        assert wait_for_end(keyed, long_id, C)["status"] == "cancelled"
        newest_first = [long_id, *reversed(made)]

        pages = self.pages(keyed, "limit=2", C)
        assert [len(page["jobs"]) for page in pages] == [2, 2, 2]
        listed = [job for page in pages for job in page["jobs"]]
        assert [job["id"] for job in listed] == newest_first
        assert [job["created_at"] for job in listed] == sorted((job["created_at"] for job in listed), reverse=True)
        assert listed[0]["status"] == "cancelled" and "result" not in listed[0]
        assert listed[1]["links"]["self"] == f"/v1/jobs/{listed[1]['id']}"

        succeeded = [job["id"] for page in self.pages(keyed, "status=succeeded&limit=3", C) for job in page["jobs"]]
        assert succeeded == list(reversed(made))
        either = keyed.get("/v1/jobs?status=cancelled&status=failed", headers=C).json()
        assert [job["id"] for job in either["jobs"]] == [long_id] and either["next_cursor"] is None

        others = [job["id"] for page in self.pages(keyed, "limit=100", A) for job in page["jobs"]]
        assert not set(others) & set(newest_first)  # another key's jobs are not listed

        assert keyed.delete(f"/v1/jobs/{made[2]}", headers=C).status_code == 204
        remaining = [job["id"] for page in self.pages(keyed, "limit=4", C) for job in page["jobs"]]
        assert remaining == [job_id for job_id in newest_first if job_id != made[2]]

    def test_bad_parameters_are_422_naming_them(self, keyed):
        for query, field in (("cursor=not-a-cursor", "cursor"), ("limit=0", "limit"), ("limit=101", "limit"),
                             ("status=done", "status/0")):
            response = keyed.get(f"/v1/jobs?{query}", headers=C)
            assert response.status_code == 422, query
            assert response.headers["content-type"] == "application/problem+json"
            assert response.json()["errors"][0]["field"] == field, response.json()
        assert keyed.get("/v1/jobs").status_code == 401


def test_the_job_index_forgets_expired_jobs(tmp_path):
    """Jobs expire GEOCERT_RESULT_TTL_S after they end; the listing drops them from its index."""
    from geocert.workers.redis_server import start_embedded_redis
    from geocert.jobs.store import JobStore

    process, url = start_embedded_redis(tmp_path)
    try:
        store = JobStore.from_url(url, result_ttl_s=1)
        kept = store.create("triangulation", {}, 1, 1, "someone")
        gone = store.create("triangulation", {}, 1, 1, "someone")
        store.end(gone["id"], "succeeded", result={})
        assert [meta["id"] for meta in store.list_jobs("someone", 10)[0]] == [gone["id"], kept["id"]]
        time.sleep(1.5)
        jobs, following = store.list_jobs("someone", 10)
        assert [meta["id"] for meta in jobs] == [kept["id"]] and following is None
        assert store.r.zrange(JobStore.owner_key("someone", "jobs"), 0, -1) == [kept["id"]]
        store.delete(kept["id"])
        assert store.r.zcard(JobStore.owner_key("someone", "jobs")) == 0
    finally:
        process.terminate()
        process.wait(timeout=10)


class Receiver:
    """A webhook receiver on loopback that fails its first ``failures`` deliveries with 500."""

    def __init__(self, failures: int):
        self.failures, self.received = failures, []
        outer = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_POST(self):
                body = self.rfile.read(int(self.headers["Content-Length"]))
                outer.received.append((dict(self.headers), body))
                self.send_response(500 if len(outer.received) <= outer.failures else 200)
                self.end_headers()

            def log_message(self, *args):
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/hook"

    def close(self):
        self.server.shutdown()


class TestWebhooks:
    def test_a_receiver_that_fails_twice_gets_the_signed_document_on_the_third_try(self, keyed):
        receiver = Receiver(failures=2)
        try:
            job = keyed.post("/v1/jobs", json={**small_job(), "callback_url": receiver.url}, headers=A).json()
            deadline = time.monotonic() + 60
            while (keyed.get(f"/v1/jobs/{job['id']}", headers=A).json()["webhook"]["state"] != "delivered"):
                assert time.monotonic() < deadline, "webhook not delivered within 60 s"
                time.sleep(0.1)
        finally:
            receiver.close()
        final = keyed.get(f"/v1/jobs/{job['id']}", headers=A).json()
        assert final["webhook"]["attempts"] == 3 and final["webhook"]["last_error"] is None
        assert len(receiver.received) == 3
        headers, body = receiver.received[-1]
        stamp, _, signature = headers["X-Geocert-Signature"].partition(",v1=")
        timestamp = stamp.removeprefix("t=")
        expected = hmac.new(SECRET.encode(), timestamp.encode() + b"." + body, hashlib.sha256).hexdigest()
        assert hmac.compare_digest(signature, expected)
        document = json.loads(body)
        assert document["id"] == job["id"] and document["status"] == "succeeded"
        assert document["result"]["stats"]["certified"] == 3

    def test_a_receiver_that_never_accepts_is_recorded_as_failed(self, keyed):
        receiver = Receiver(failures=100)
        try:
            job = keyed.post("/v1/jobs", json={**small_job(), "callback_url": receiver.url}, headers=A).json()
            deadline = time.monotonic() + 60
            while (hook := keyed.get(f"/v1/jobs/{job['id']}", headers=A).json()["webhook"])["state"] != "failed":
                assert time.monotonic() < deadline, f"webhook still {hook['state']} after 60 s"
                time.sleep(0.1)
        finally:
            receiver.close()
        # The record says it failed, not how (an HTTP status, a closed port, a timeout: a port scanner's oracle).
        assert hook["attempts"] == 3 and hook["last_error"].startswith("failed:") and "500" not in hook["last_error"]
        assert len(receiver.received) == 3
        assert keyed.get(f"/v1/jobs/{job['id']}", headers=A).json()["status"] == "succeeded"  # the job is intact

    def test_metrics_count_jobs_and_deliveries(self, keyed):
        text = keyed.get("/metrics").text
        assert 'geocert_jobs_total{kind="triangulation",status="succeeded"}' in text
        assert 'geocert_webhook_deliveries_total{state="delivered"}' in text
        assert "geocert_item_solve_seconds_bucket" in text and "geocert_queue_depth" in text


@pytest.fixture(scope="module")
def limited(tmp_path_factory):
    """No workers: jobs stay queued, so the active-job limit is reached deterministically."""
    with cluster(tmp_path_factory.mktemp("limited"), workers=0, geocert_max_items_per_job="5",
                 geocert_max_points_per_job="12", geocert_max_active_jobs_per_key="2",
                 geocert_rate_limit_per_minute="25", geocert_max_item_time_limit_s="10",
                 geocert_max_item_nodes="1000") as (_, client):
        yield client


class TestLimits:
    def test_each_limit_is_named_with_its_value(self, limited):
        too_many = limited.post("/v1/jobs", json=small_job(tracks=6))
        assert too_many.status_code == 413
        assert too_many.json()["errors"][0]["field"] == "data/tracks" and "limit of 5" in too_many.json()["detail"]
        assert "GEOCERT_MAX_ITEMS_PER_JOB" in too_many.json()["detail"]
        points = small_job(tracks=5)
        for track in points["data"]["tracks"]:  # 4 views each: 20 observations
            track["views"], track["points"] = [0, 1, 2, 3], [[100.0, 100.0], [110, 100], [120, 100], [130, 100]]
        over = limited.post("/v1/jobs", json=points)
        assert over.status_code == 413 and "limit of 12" in over.json()["detail"]
        slow = limited.post("/v1/jobs", json=small_job(time_limit_s=11))
        assert slow.status_code == 422 and slow.json()["errors"][0]["field"] == "options/time_limit_s"
        assert "maximum of 10" in slow.json()["detail"]
        deep = limited.post("/v1/jobs", json=small_job(max_nodes=1001))
        assert deep.status_code == 422 and deep.json()["errors"][0]["field"] == "options/max_nodes"

    def test_active_jobs_per_key(self, limited):
        assert limited.post("/v1/jobs", json=small_job(1)).status_code == 202
        assert limited.post("/v1/jobs", json=small_job(2)).status_code == 202
        third = limited.post("/v1/jobs", json=small_job(3))
        assert third.status_code == 429 and "GEOCERT_MAX_ACTIVE_JOBS_PER_KEY" in third.json()["detail"]
        assert "Retry-After" in third.headers

    def test_not_ready_without_workers_and_answered_at_once(self, limited):
        start = time.perf_counter()
        response = limited.get("/readyz")
        assert time.perf_counter() - start < 0.25
        assert response.status_code == 503 and response.json() == {"status": "not ready", "redis": True, "workers": 0}

    def test_rate_per_key(self, limited):
        answers = [limited.get("/v1/problems").status_code for _ in range(60)]  # 2 windows: one sees > 25
        assert answers.count(429) >= 1
        last = limited.get("/v1/problems")
        assert last.status_code == 429 and int(last.headers["Retry-After"]) <= 61
        assert "GEOCERT_RATE_LIMIT_PER_MINUTE" in last.json()["detail"] and "25" in last.json()["detail"]


def test_serve_refuses_other_addresses_without_keys(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("GEOCERT_")}
    env["GEOCERT_DATA_DIR"] = str(tmp_path)
    done = subprocess.run([sys.executable, "-m", "geocert.app.cli", "serve", "--host", "0.0.0.0", "--workers", "0"],
                          env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "GEOCERT_API_KEYS" in done.stderr

"""End to end through HTTP: a real `geocert serve` (embedded Redis, a real Celery worker)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time

import httpx
import numpy as np
import pytest

from geocert.jobs.runner import solve_job

from tests.servers import free_port
from tests.support import assert_problem, random_cameras, service_job as triangulation_job

BODY_LIMIT = 2_000_000
STREAM_THRESHOLD = 20_000  # bodies over this are taken item by item (TestLargeBodies)


pytestmark = pytest.mark.slow  # real servers, real data or SCIP: the full run only


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    port = free_port()
    env = os.environ.copy()
    env.pop("GEOCERT_REDIS_URL", None)
    env.update(GEOCERT_DATA_DIR=str(tmp_path_factory.mktemp("geocert")), GEOCERT_MAX_BODY_BYTES=str(BODY_LIMIT),
               GEOCERT_CHUNK_SIZES='{"triangulation": 40}', GEOCERT_PROGRESS_INTERVAL_S="0.05",
               GEOCERT_STREAM_THRESHOLD_BYTES=str(STREAM_THRESHOLD))
    process = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(port), "--workers", "1",
                                "--concurrency", "1"], env=env)
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 90
    with httpx.Client(base_url=base, timeout=10) as client:
        while True:
            try:
                if client.get("/readyz").status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert process.poll() is None, "geocert serve exited"
            assert time.monotonic() < deadline, "service not ready within 90 s"
            time.sleep(0.3)
        client.serve_pid = process.pid  # for TestWorkerProcesses
        yield client
    process.terminate()
    process.wait(timeout=30)


def sse_events(client: httpx.Client, job_id: str, last_event_id: str | None = None, limit_s: float = 60):
    """Yield (id, event, data) from the job's event stream until it closes."""
    headers = {"Last-Event-ID": last_event_id} if last_event_id else {}
    with client.stream("GET", f"/v1/jobs/{job_id}/events", headers=headers, timeout=limit_s) as response:
        assert response.status_code == 200
        assert response.headers["content-type"].startswith("text/event-stream")
        event: dict = {}
        for line in response.iter_lines():
            if line == "":
                if "event" in event:
                    yield event.get("id"), event["event"], json.loads(event["data"])
                event = {}
            elif not line.startswith(":"):
                key, _, value = line.partition(": ")
                event[key] = value


def wait_for(client: httpx.Client, job_id: str, statuses=("succeeded", "failed", "cancelled"), limit_s=120) -> dict:
    deadline = time.monotonic() + limit_s
    while True:
        job = client.get(f"/v1/jobs/{job_id}").json()
        if job["status"] in statuses:
            return job
        assert time.monotonic() < deadline, f"job still {job['status']}"
        time.sleep(0.1)


def assert_progress_agrees(client: httpx.Client, job: dict) -> None:
    """A finished job's progress is its result's: items done, nodes, bounds; and the last
    progress event of its stream says the same."""
    result, progress = job["result"], job["progress"]
    items = result.get("tracks", result.get("maps"))
    assert progress["items_total"] == len(items)
    assert progress["items_done"] == sum(1 for item in items if item["status"] != "cancelled")
    assert (progress["tracks_done"], progress["tracks_total"]) == (progress["items_done"], progress["items_total"])
    assert progress["nodes"] == result["stats"]["nodes"] == sum(item["nodes"] for item in items)
    bounded = [item for item in items if item["cost"] is not None and item["lower_bound"] is not None]
    if bounded:
        assert progress["upper_bound"] == pytest.approx(sum(item["cost"] for item in bounded), rel=1e-12)
        assert progress["lower_bound"] == pytest.approx(sum(item["lower_bound"] for item in bounded), rel=1e-12)
    last = [data for _, event, data in sse_events(client, job["id"]) if event == "progress"][-1]
    assert {"stage": None, **last} == progress  # an event names a stage only for a staged solve; the job shows null


class TestSubmitStreamResult:
    def test_batch_result_in_track_order_with_progress_events(self, service):
        rng = np.random.default_rng(21)
        body = triangulation_job(rng, tracks=100, norm="L2L2")  # 3 chunks of 40, 40, 20
        response = service.post("/v1/jobs", json=body)
        assert response.status_code == 202
        job_id = response.json()["id"]
        assert response.headers["location"] == f"/v1/jobs/{job_id}"
        events = list(sse_events(service, job_id))
        kinds = [event for _, event, _ in events]
        assert kinds[0] == "status" and kinds[-1] == "end"
        progress = [data for _, event, data in events if event == "progress"]
        assert progress, "no progress event"
        # Bounds are null until a task has real ones (none is 0 for want of a figure).
        assert all(p["lower_bound"] is None or p["lower_bound"] <= p["upper_bound"] + 1e-9 for p in progress)
        assert progress[-1]["lower_bound"] is not None
        assert progress[-1]["items_done"] == 100 and progress[-1]["items_total"] == 100
        assert all((p["tracks_done"], p["tracks_total"]) == (p["items_done"], p["items_total"]) for p in progress)
        job = service.get(f"/v1/jobs/{job_id}").json()
        assert job["status"] == "succeeded"
        tracks = job["result"]["tracks"]
        assert len(tracks) == 100 and all(t["certified"] for t in tracks)
        # The same job solved in this process gives the same answers, in the same order.
        local = solve_job(body)["tracks"]
        for remote, mine in zip(tracks, local):
            assert remote["cost"] == pytest.approx(mine["cost"], rel=1e-9, abs=1e-12)
            assert np.allclose(remote["point"], mine["point"], rtol=1e-6, atol=1e-9)

    def test_last_event_id_resumes_after_that_event(self, service):
        body = triangulation_job(np.random.default_rng(22), tracks=3)
        job_id = service.post("/v1/jobs", json=body).json()["id"]
        events = list(sse_events(service, job_id))
        assert len(events) >= 3
        resumed = list(sse_events(service, job_id, last_event_id=events[1][0]))
        assert resumed == events[2:]

    def test_problems_lists_triangulation_with_schema_and_defaults(self, service):
        kinds = {k["kind"]: k for k in service.get("/v1/problems").json()}
        assert kinds["triangulation"]["default_options"]["norm"] == "L2L2"
        assert "data" in kinds["triangulation"]["request_schema"]["properties"]


class TestMapsThroughTheService:
    def test_resection_job_returns_certified_maps_in_order(self, service):
        rng = np.random.default_rng(27)
        cameras = random_cameras(rng, 3)
        maps = []
        for camera in cameras:
            source = rng.normal(size=(8, 3))
            proj = np.hstack([source, np.ones((8, 1))]) @ camera.T
            target = proj[:, :2] / proj[:, 2:3] + rng.normal(size=(8, 2)) * 0.5
            maps.append({"source": source.tolist(), "target": target.tolist()})
        body = {"kind": "resection", "data": {"maps": maps}, "options": {"norm": "L2L2"}}
        job_id = service.post("/v1/jobs", json=body).json()["id"]
        job = wait_for(service, job_id)
        assert job["status"] == "succeeded"
        result = job["result"]
        assert result["kind"] == "resection" and len(result["maps"]) == 3
        for camera, fitted in zip(cameras, result["maps"]):
            assert fitted["certified"]
            M, P = np.array(fitted["matrix"]), camera / np.linalg.norm(camera)
            assert min(np.abs(M - P).max(), np.abs(M + P).max()) < 0.05  # 0.5 px noise: close to the truth

    def test_coplanar_resection_is_a_422_that_says_why(self, service):
        source = [[x, y, 0.0] for x in range(3) for y in range(3)]
        body = {"kind": "resection", "data": {"maps": [{"source": source, "target": [[1.0, 2.0]] * 9}]}}
        response = service.post("/v1/jobs", json=body)
        assert response.status_code == 422
        assert "one plane" in response.json()["errors"][0]["reason"]


class TestCancel:
    def test_running_job_stops_and_keeps_its_best_result(self, service):
        # An unreachable gap keeps the search running until it is told to stop.
        body = triangulation_job(np.random.default_rng(23), tracks=3, views=6, norm="L1L1", rel_gap=0.0,
                                 abs_gap=0.0, max_nodes=100_000, time_limit_s=60)
        job_id = service.post("/v1/jobs", json=body).json()["id"]
        for _, event, data in sse_events(service, job_id):
            if event == "progress" and data["nodes"] > 20:
                break
        assert service.post(f"/v1/jobs/{job_id}/cancel").status_code == 202
        job = wait_for(service, job_id, limit_s=30)
        assert job["status"] == "cancelled"
        first = job["result"]["tracks"][0]
        assert first["status"] == "cancelled" and first["point"] is not None
        # An anytime answer: its cost, and no bound (a stopped search's is checked by no proof).
        assert first["cost"] is not None and first["lower_bound"] is None and first["gap"] is None
        assert all(t["status"] == "cancelled" for t in job["result"]["tracks"])
        assert_progress_agrees(service, job)

    def test_after_a_cancel_the_final_progress_agrees_with_the_result(self, service):
        # Chunks of 40: some finish, one is stopped mid-track, the queued ones never solve.
        body = triangulation_job(np.random.default_rng(31), tracks=200, views=5, norm="L1L1", rel_gap=1e-6)
        job_id = service.post("/v1/jobs", json=body).json()["id"]
        for _, event, data in sse_events(service, job_id):
            if event == "progress" and data["items_done"] >= 15:
                break
        assert service.post(f"/v1/jobs/{job_id}/cancel").status_code == 202
        job = wait_for(service, job_id, limit_s=60)
        assert job["status"] in ("cancelled", "succeeded")
        statuses = job["result"]["stats"]["statuses"]
        assert job["progress"]["items_done"] == sum(n for status, n in statuses.items() if status != "cancelled")
        assert_progress_agrees(service, job)

    def test_cancelling_a_finished_job_is_a_409_naming_its_status(self, service):
        job_id = service.post("/v1/jobs", json=triangulation_job(np.random.default_rng(32), tracks=1)).json()["id"]
        assert wait_for(service, job_id)["status"] == "succeeded"
        response = service.post(f"/v1/jobs/{job_id}/cancel")
        assert response.status_code == 409
        assert response.headers["content-type"] == "application/problem+json"
        assert "succeeded" in response.json()["detail"] and "nothing to cancel" in response.json()["detail"]
        assert service.get(f"/v1/jobs/{job_id}").json()["status"] == "succeeded"  # untouched

    def test_queued_job_never_starts(self, service):
        blocker = triangulation_job(np.random.default_rng(24), tracks=1, views=6, norm="L1L1", rel_gap=0.0,
                                    abs_gap=0.0, max_nodes=100_000, time_limit_s=60)
        blocker_id = service.post("/v1/jobs", json=blocker).json()["id"]
        wait_for(service, blocker_id, statuses=("running",))
        queued_id = service.post("/v1/jobs", json=triangulation_job(np.random.default_rng(25), tracks=2)).json()["id"]
        assert service.get(f"/v1/jobs/{queued_id}").json()["status"] == "queued"
        cancelled = service.post(f"/v1/jobs/{queued_id}/cancel").json()
        assert cancelled["status"] == "cancelled"
        service.post(f"/v1/jobs/{blocker_id}/cancel")
        wait_for(service, blocker_id)
        time.sleep(1.0)  # time for the worker to have picked the queued job up, were it to
        job = service.get(f"/v1/jobs/{queued_id}").json()
        assert job["status"] == "cancelled" and job["started_at"] is None and job["result"] is None
        assert [e for _, e, _ in sse_events(service, queued_id)] == ["status", "end"]


class TestBodyLimit:
    def test_body_over_the_limit_gets_413(self, service):
        response = service.post("/v1/jobs", content=b" " * (BODY_LIMIT + 1), headers={"content-type": "application/json"})
        assert response.status_code == 413
        assert response.headers["content-type"].startswith("application/problem+json")
        assert str(BODY_LIMIT) in response.json()["detail"]


class TestReadiness:
    def test_readyz_answers_from_heartbeats_well_under_a_second(self, service):
        for _ in range(5):
            start = time.perf_counter()
            response = service.get("/readyz")
            took = time.perf_counter() - start
            assert response.status_code == 200 and response.json()["workers"] == 1
            assert took < 0.25, f"/readyz took {took:.3f} s"


class TestDocs:
    def test_docs_and_redoc_load_every_asset_from_the_service_itself(self, service):
        for page in ("/docs", "/redoc"):
            response = service.get(page)
            assert response.status_code == 200 and response.headers["content-type"].startswith("text/html")
            assert not re.search(r"(?i)(https?:)?//[a-z0-9.-]+\.[a-z]{2,}", response.text), "an external host"
            assets = re.findall(r'(?:src|href)="([^"]+)"', response.text)
            assert any(a.endswith(".js") for a in assets)
            for asset in assets:
                assert asset.startswith("/"), asset
                loaded = service.get(asset)
                assert loaded.status_code == 200 and len(loaded.content) > 1000, asset
        spec = re.search(r"url: '([^']+)'", service.get("/docs").text).group(1)
        assert service.get(spec).json()["info"]["title"] == "geocert"


README_CAMERAS = [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]], [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]]
README_TRACK = {"views": [0, 1], "points": [[330, 250], [250, 251]]}


class TestOrient:
    def test_a_negated_camera_is_oriented_and_its_track_then_certified(self, service):
        flipped = [README_CAMERAS[0], (-np.array(README_CAMERAS[1])).tolist()]
        before = wait_for(service, service.post("/v1/jobs", json={
            "kind": "triangulation", "data": {"cameras": flipped, "tracks": [README_TRACK]}}).json()["id"])
        assert before["result"]["tracks"][0]["status"] == "infeasible"
        points = [[0.125, 0.125, 10.0], [0.0, 0.0, 8.0], [1.0, -1.0, 12.0, 1.0]]
        response = service.post("/v1/orient", json={"cameras": flipped, "points": points})
        assert response.status_code == 200
        oriented = response.json()
        assert oriented["camera_signs"] == [1, -1] and oriented["oriented"] and not oriented["frame_changed"]
        assert np.allclose(np.array(oriented["points"])[:, :3], [point[:3] for point in points])
        after = wait_for(service, service.post("/v1/jobs", json={
            "kind": "triangulation", "data": {"cameras": oriented["cameras"], "tracks": [README_TRACK]}}).json()["id"])
        track = after["result"]["tracks"][0]
        assert track["certified"] and track["cost"] == pytest.approx(0.5, rel=1e-6)

    def test_bad_input_names_the_field(self, service):
        problem = service.post("/v1/orient", json={"cameras": README_CAMERAS, "points": [[1, 2, 3]],
                                                   "views": [[0, 2]]}).json()
        assert problem["status"] == 422 and problem["errors"][0]["field"] == "views/0/1"
        problem = service.post("/v1/orient", json={"cameras": README_CAMERAS, "points": [[0, 0, 0, 0]]}).json()
        assert problem["status"] == 422 and problem["errors"][0]["field"] == "points/0"


class TestPreferWait:
    """Prefer: wait=N (RFC 7240) on POST /v1/jobs, for every kind: the finished job when it ends
    within N seconds, else the usual 202."""

    def test_a_job_that_ends_within_the_wait_comes_back_whole(self, service):
        body = triangulation_job(np.random.default_rng(41), tracks=2)
        response = service.post("/v1/jobs", json=body, headers={"Prefer": "wait=60"}, timeout=90)
        assert response.status_code == 200
        assert response.headers["Preference-Applied"] == "wait=60"
        job = response.json()
        assert job["status"] == "succeeded" and len(job["result"]["tracks"]) == 2
        assert response.headers["Location"] == f"/v1/jobs/{job['id']}"
        assert response.content == service.get(f"/v1/jobs/{job['id']}").content  # the GET's document, as stored

    def test_a_job_longer_than_the_wait_is_the_usual_202(self, service):
        blocker = triangulation_job(np.random.default_rng(42), tracks=1, views=6, norm="L1L1", rel_gap=0.0,
                                    abs_gap=0.0, max_nodes=100_000, time_limit_s=60)
        response = service.post("/v1/jobs", json=blocker, headers={"Prefer": "respond-async, wait=1"})
        assert response.status_code == 202
        job = response.json()
        assert job["status"] in ("queued", "running") and job["result"] is None
        service.post(f"/v1/jobs/{job['id']}/cancel")
        assert wait_for(service, job["id"])["status"] == "cancelled"

    def test_without_the_preference_nothing_waits(self, service):
        response = service.post("/v1/jobs", json=triangulation_job(np.random.default_rng(43), tracks=1))
        assert response.status_code == 202 and "Preference-Applied" not in response.headers
        wait_for(service, response.json()["id"])


class TestStereoLines:
    def test_the_example_is_solved_through_the_api_as_an_estimate(self, service):
        from geocert.kinds.stereo_lines import KIND

        response = service.post("/v1/jobs", json=KIND.example, headers={"Prefer": "wait=60"}, timeout=90)
        assert response.status_code == 200
        result = response.json()["result"]
        assert result["status"] == "estimate" and result["pairs"][0]["status"] == "estimate"
        assert result["pairs"][0]["certified"] is False and len(result["trajectory"]) == 2

    def test_a_rig_whose_R_is_not_a_rotation_is_a_422_naming_it(self, service):
        from geocert.kinds.stereo_lines import KIND

        body = json.loads(json.dumps(KIND.example))
        body["data"]["rig"]["R"] = [[1, 0, 0], [0, 2, 0], [0, 0, 1]]
        problem = service.post("/v1/jobs", json=body).json()
        assert problem["status"] == 422 and problem["errors"][0]["field"] == "data/rig/R"


class TestLargeBodies:
    """A body over GEOCERT_STREAM_THRESHOLD_BYTES is taken item by item (app.streamed): the same
    job, kept as the ordinary path keeps it, and the same errors naming the item."""

    @staticmethod
    def large_body(seed: int = 31) -> dict:
        body = triangulation_job(np.random.default_rng(seed), tracks=150)
        body["data"]["tracks"][5]["points"][0] = [320, 240]  # ints, which the model makes floats
        assert len(json.dumps(body)) > STREAM_THRESHOLD
        return body

    def test_a_large_job_is_solved_and_its_request_kept_as_checked(self, service):
        from geocert.app.schemas import JOB_REQUEST

        body = self.large_body()
        headers = {"Idempotency-Key": "large-31"}
        response = service.post("/v1/jobs", json=body, headers=headers)
        assert response.status_code == 202
        job_id = response.json()["id"]
        again = service.post("/v1/jobs", json=body, headers=headers)  # the same key and body: a replay
        assert again.status_code == 200 and again.json()["id"] == job_id
        job = wait_for(service, job_id)
        assert job["status"] == "succeeded"
        tracks = job["result"]["tracks"]
        assert len(tracks) == 150 and all(t["certified"] for t in tracks)
        for remote, mine in zip(tracks, solve_job(body)["tracks"]):
            assert remote["cost"] == pytest.approx(mine["cost"], rel=1e-9, abs=1e-12)
        kept = service.get(f"/v1/jobs/{job_id}/request").json()
        assert kept == JOB_REQUEST.validate_python(body).model_dump(mode="json")
        assert kept["data"]["tracks"][5]["points"][0] == [320.0, 240.0]

    @pytest.mark.parametrize("change, field", [
        (lambda tracks: tracks[120]["points"].__setitem__(1, ["x", 2]), "data/tracks/120/points/1/0"),
        (lambda tracks: tracks[130]["views"].__setitem__(0, 99), "data/tracks/130/views/0"),
        (lambda tracks: tracks.__setitem__(140, {"views": [0], "points": [[1.0, 2.0]]}), "data/tracks/140/views"),
    ])
    def test_a_bad_item_of_a_large_body_is_named(self, service, change, field):
        body = self.large_body(32)
        change(body["data"]["tracks"])
        listed = [job["id"] for job in service.get("/v1/jobs", params={"limit": 100}).json()["jobs"]]
        assert_problem(service.post("/v1/jobs", json=body), 422, field)
        assert [job["id"] for job in service.get("/v1/jobs", params={"limit": 100}).json()["jobs"]] == listed


class TestWorkerProcesses:
    def test_workers_run_blas_on_one_thread(self, service):
        """geocert serve starts its workers with OPENBLAS_NUM_THREADS=1 (cli.worker_environment)
        unless the operator set it: read from the worker processes' own environment."""
        assert "OPENBLAS_NUM_THREADS" not in os.environ  # else the test says nothing
        pid = service.serve_pid
        children = open(f"/proc/{pid}/task/{pid}/children").read().split()
        workers = [c for c in children if b"celery" in open(f"/proc/{c}/cmdline", "rb").read()]
        assert workers
        for worker in workers:
            environment = open(f"/proc/{worker}/environ", "rb").read().split(b"\0")
            assert b"OPENBLAS_NUM_THREADS=1" in environment and b"OMP_NUM_THREADS=1" in environment

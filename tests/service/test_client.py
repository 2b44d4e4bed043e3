"""The Python client (app/client.py) against a real `geocert serve` (embedded Redis, a real Celery
worker), with API keys configured."""

from __future__ import annotations

import httpx
import numpy as np
import pytest

from geocert.app.client import (
    BadRequest,
    Client,
    Conflict,
    Event,
    InvalidRequest,
    JobFailed,
    NotFound,
    Unauthorized,
    WaitTimeout,
)

from tests.servers import cluster
from tests.support import ROOT
from tests.support import service_job as triangulation_job

KEY = "client-test-key-0123456789"


pytestmark = pytest.mark.slow  # real servers, real data or SCIP: the full run only


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    with cluster(tmp_path_factory.mktemp("client"), workers=1, geocert_api_keys=KEY,
                 geocert_progress_interval_s="0.05", geocert_chunk_sizes='{"triangulation": 5}') as (running, _):
        yield running.base


@pytest.fixture
def client(served, monkeypatch):
    monkeypatch.setenv("GEOCERT_API_KEY", KEY)  # the key from the environment
    with Client(served, backoff_s=0.05) as geocert:
        yield geocert


def job_parts(seed: int, tracks: int = 3, **options):
    body = triangulation_job(np.random.default_rng(seed), tracks=tracks, **options)
    return body["kind"], body["data"], body["options"]


def hard_job(seed: int):
    """An unreachable gap: runs until cancelled."""
    return job_parts(seed, tracks=1, views=6, norm="L1L1", rel_gap=0.0, abs_gap=0.0, max_nodes=100_000,
                     time_limit_s=30)


class TestJobs:
    def test_submit_wait_result_and_certificate(self, client):
        job = client.submit(*job_parts(1, tracks=4, certificate="full"))
        document = job.wait(timeout=60)
        assert document["status"] == "succeeded" and document["id"] == job.id
        result = job.result()
        assert len(result["tracks"]) == 4 and all(track["certified"] for track in result["tracks"])
        certificate = job.certificate()
        assert certificate["format"] == "geocert-certificate" and certificate == result["certificate"]
        assert client.verify(document)["valid"] is True
        assert any(listed["id"] == job.id for listed in client.jobs(status="succeeded"))

    def test_stream_yields_progress_and_resumes_after_an_event(self, client):
        job = client.submit(*job_parts(2, tracks=12))
        events = list(job.stream(timeout=60))
        assert all(isinstance(event, Event) for event in events)
        assert events[0].event == "status" and events[-1].event == "end"
        assert any(event.event == "progress" for event in events)
        assert events[-1].data["status"] == "succeeded"
        resumed = list(job.stream(last_event_id=events[2].id))
        assert resumed == events[3:]

    def test_a_dropped_stream_is_resumed_with_last_event_id(self, served):
        class DropsAfterFirstConnection(httpx.HTTPTransport):
            """Cuts the first event stream after its second event, as a flaky network would."""

            def __init__(self):
                super().__init__()
                self.streams, self.resumed_from = 0, []

            def handle_request(self, request):
                response = super().handle_request(request)
                if not request.url.path.endswith("/events"):
                    return response
                self.streams += 1
                self.resumed_from.append(request.headers.get("last-event-id"))
                if self.streams > 1:
                    return response
                inner = response.stream

                class Cut(httpx.SyncByteStream):
                    def __iter__(self):
                        seen = b""
                        for chunk in inner:
                            for line in chunk.splitlines(keepends=True):
                                seen += line
                                yield line
                                if seen.count(b"\n\n") >= 2:
                                    raise httpx.ReadError("connection reset")

                    def close(self):
                        inner.close()

                return httpx.Response(response.status_code, headers=response.headers, stream=Cut())

        transport = DropsAfterFirstConnection()
        with Client(served, api_key=KEY, transport=transport, backoff_s=0.05) as geocert:
            job = geocert.submit(*job_parts(3, tracks=12))
            events = list(job.stream(timeout=60))
            assert transport.streams == 2 and transport.resumed_from[0] is None
            assert transport.resumed_from[1] == events[1].id  # resumed after the last event it had
            complete = list(geocert.stream(job.id))
            assert events == complete  # nothing lost, nothing repeated

    def test_cancel_then_cancel_again_is_a_conflict_with_the_problem(self, client):
        job = client.submit(*hard_job(4))
        for event in job.stream(timeout=60):
            if event.event == "progress" and event.data["nodes"] > 5:
                break
        assert job.cancel()["id"] == job.id
        assert job.wait(timeout=30)["status"] == "cancelled"
        result = job.result()
        assert result["tracks"][0]["status"] == "cancelled"
        with pytest.raises(Conflict) as error:
            job.cancel()
        assert error.value.status == 409 and "cancelled" in error.value.detail
        assert error.value.problem["status"] == 409
        job.delete()
        with pytest.raises(NotFound):
            client.job(job.id)

    def test_wait_times_out_with_the_last_document(self, client):
        job = client.submit(*hard_job(5))
        with pytest.raises(WaitTimeout) as error:
            job.wait(timeout=0.5)
        assert error.value.job["status"] in ("queued", "running")
        job.cancel()
        job.wait(timeout=30)


def python_snippet(document: str) -> str:
    """The indented code block of a markdown page that starts with the client's import."""
    lines = (ROOT / document).read_text(encoding="utf-8").splitlines()
    start = lines.index("    from geocert.app.client import Client, InvalidRequest")
    block = []
    for line in lines[start:]:
        if line and not line.startswith("    "):
            break
        block.append(line[4:])
    return "\n".join(block).strip() + "\n"


@pytest.mark.parametrize("document", ["README.md", "docs/api.md"])
def test_the_documented_python_snippet_runs_as_written(served, monkeypatch, capsys, document):
    """The snippet as a reader copies it (only the service's address is this test's): it used a
    ``data`` it never defined, and failed with a NameError."""
    monkeypatch.setenv("GEOCERT_API_KEY", KEY)
    code = python_snippet(document)
    assert '"http://127.0.0.1:8000"' in code
    scope: dict = {}
    exec(compile(code.replace('"http://127.0.0.1:8000"', repr(served)), document, "exec"), scope)
    assert scope["result"]["tracks"][0]["certified"] is True
    assert scope["certificate"]["format"] == "geocert-certificate"
    assert any(job["id"] == scope["job"].id for job in scope["recent"])
    assert "end" in capsys.readouterr().out  # the stream was printed to its end


class TestErrors:
    def test_invalid_input_raises_with_the_fields_named(self, client):
        kind, data, options = job_parts(6, tracks=1)
        data["tracks"][0]["views"] = [0, 99]
        with pytest.raises(InvalidRequest) as error:
            client.submit(kind, data, options)
        assert error.value.status == 422
        assert error.value.fields[0]["field"] == "data/tracks/0/views/1"
        assert error.value.problem["title"] == "Invalid request"

    def test_no_key_is_unauthorized(self, served, monkeypatch):
        monkeypatch.delenv("GEOCERT_API_KEY", raising=False)
        with Client(served) as anonymous, pytest.raises(Unauthorized) as error:
            anonymous.submit(*job_parts(7, tracks=1))
        assert "X-API-Key" in error.value.detail

    def test_a_failed_job_raises_job_failed(self):
        document = {"id": "x", "status": "failed",
                    "error": {"type": "about:blank", "title": "Solver failure", "status": 500, "detail": "boom"}}
        error = JobFailed(document)
        assert error.job is document and error.status == 500 and "boom" in str(error)

    def test_problem_of_a_bad_body_is_kept(self, client):
        with pytest.raises(BadRequest) as error:
            client._request("POST", "/v1/jobs", content=b"{oops", headers={"content-type": "application/json"})
        assert (error.value.problem["line"], error.value.problem["column"]) == (1, 2)


class TestRetries:
    def test_a_lost_answer_is_retried_with_the_same_idempotency_key_and_makes_one_job(self, served):
        class LosesFirstAnswer(httpx.HTTPTransport):
            """The server makes the job, but its first answer is lost on the way back."""

            def __init__(self):
                super().__init__()
                self.keys = []

            def handle_request(self, request):
                response = super().handle_request(request)
                if request.method == "POST" and request.url.path == "/v1/jobs":
                    self.keys.append(request.headers["idempotency-key"])
                    if len(self.keys) == 1:
                        response.read()
                        raise httpx.ReadError("connection reset after the request was sent")
                return response

        transport = LosesFirstAnswer()
        with Client(served, api_key=KEY, transport=transport, backoff_s=0.05) as geocert:
            before = {job["id"] for job in geocert.jobs()}
            job = geocert.submit(*job_parts(8, tracks=1))
            assert len(transport.keys) == 2 and transport.keys[0] == transport.keys[1]
            made = [j["id"] for j in geocert.jobs() if j["id"] not in before]
            assert made == [job.id]  # one job, though the request was sent twice
            assert job.wait(timeout=60)["status"] == "succeeded"

    def test_an_unreachable_service_raises_after_the_retries(self):
        with Client("http://127.0.0.1:9", api_key=KEY, retries=2, backoff_s=0.01) as geocert:
            with pytest.raises(httpx.ConnectError):
                geocert.job("0" * 32)
            assert not geocert.ready()

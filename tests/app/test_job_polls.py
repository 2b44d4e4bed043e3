"""GET /v1/jobs/{id}: a poll of a job that has not ended is answered on the event loop (no
thread of the pool: each took the interpreter lock from the loop serving the submissions), and an
ended job's document, made in a thread, is the bytes the route's response model writes."""

from __future__ import annotations

import fastapi.routing
from fastapi.routing import APIRoute

from geocert.app.api.routes import jobs as job_routes
from geocert.app.api.deps import get_store
from tests.app.test_routes import exact_job


def _pool_calls(monkeypatch) -> list[str]:
    """Every call to the pool by FastAPI (a sync route, its response model) or by the jobs routes."""
    calls: list[str] = []

    def counted(module, original):
        async def run(func, *args, **kwargs):
            calls.append(getattr(func, "__name__", repr(func)))
            return await original(func, *args, **kwargs)
        return run

    monkeypatch.setattr(fastapi.routing, "run_in_threadpool", counted(fastapi.routing, fastapi.routing.run_in_threadpool))
    monkeypatch.setattr(job_routes, "run_in_threadpool", counted(job_routes, job_routes.run_in_threadpool))
    return calls


def test_a_queued_jobs_poll_takes_no_thread_and_says_what_the_record_holds(api, monkeypatch):
    job_id = api.post("/v1/jobs", json=exact_job(7)[0]).json()["id"]  # queued: no task run here
    calls = _pool_calls(monkeypatch)
    response = api.get(f"/v1/jobs/{job_id}")
    assert response.status_code == 200
    assert calls == []
    job = response.json()
    assert job["id"] == job_id and job["status"] == "queued" and job["result"] is None
    assert job["links"]["self"] == f"/v1/jobs/{job_id}"
    assert job["progress"]["items_total"] == 3


def test_an_ended_jobs_document_is_made_in_a_thread_as_the_response_model_writes_it(api, monkeypatch):
    job_id = api.post("/v1/jobs", json=exact_job(8)[0]).json()["id"]
    assert api.post(f"/v1/jobs/{job_id}/cancel").json()["status"] == "cancelled"
    calls = _pool_calls(monkeypatch)
    response = api.get(f"/v1/jobs/{job_id}")
    assert response.status_code == 200 and response.headers["content-type"] == "application/json"
    assert calls == ["finished_document"]
    # What FastAPI's response model of this route writes for the store's document of the job.
    route = next(r for r in job_routes.router.routes if isinstance(r, APIRoute) and r.name == "get_job")
    store = get_store()
    value, errors = route.response_field.validate(store.document(store.get(job_id)), {}, loc=("response",))
    assert not errors
    assert response.content == route.response_field.serialize_json(value, by_alias=True)
    assert response.json()["status"] == "cancelled"

"""Jobs: submit, read, stream, cancel."""

from __future__ import annotations

import re
from typing import Annotated

from fastapi import APIRouter, Depends, Header, HTTPException, Response
from fastapi.sse import EventSourceResponse, ServerSentEvent

from app.api.deps import get_store, submit_chunks
from app.core.config import get_settings
from app.problems import PROBLEM_JSON
from app.schemas import Job, JobRequest, ProblemDetails
from solvers.geometry import InputError
from solvers.jobs import parse_job
from workers.store import TERMINAL, JobStore

router = APIRouter(prefix="/v1/jobs", tags=["jobs"])

_ERRORS = {
    404: {"model": ProblemDetails, "content": {PROBLEM_JSON: {}}, "description": "no such job"},
    413: {"model": ProblemDetails, "content": {PROBLEM_JSON: {}}, "description": "body over the size limit"},
    422: {"model": ProblemDetails, "content": {PROBLEM_JSON: {}}, "description": "invalid job: names the field"},
}


def job_document(store: JobStore, meta: dict) -> dict:
    document = {
        key: meta.get(key) for key in ("id", "kind", "status", "created_at", "started_at", "finished_at",
                                       "progress", "error")
    }
    document["result"] = store.result(meta["id"]) if meta["status"] in TERMINAL else None
    document["links"] = {"self": f"/v1/jobs/{meta['id']}", "events": f"/v1/jobs/{meta['id']}/events",
                         "cancel": f"/v1/jobs/{meta['id']}/cancel"}
    return document


@router.post("", status_code=202, response_model=Job, responses={k: _ERRORS[k] for k in (413, 422)})
def submit_job(body: JobRequest, response: Response, store: Annotated[JobStore, Depends(get_store)]):
    """Queue a job; answers 202 with its id and a Location to poll."""
    request = body.model_dump(mode="json")  # validated by its kind's model (discriminated on "kind")
    kind, parsed, _ = parse_job(request)  # the solvers' own checks: rank, indices, duplicates
    items = kind.count(parsed)
    settings = get_settings()
    if items > settings.max_items_per_job:
        raise InputError(f"data/{kind.item_name}",
                         f"{items} items exceed the limit of {settings.max_items_per_job} per job")
    meta = store.create(kind.name, request, items, settings.chunk_size)
    submit_chunks(store, meta)
    response.headers["Location"] = f"/v1/jobs/{meta['id']}"
    return job_document(store, meta)


def _load(store: JobStore, job_id: str) -> dict:
    meta = store.get(job_id)
    if meta is None:
        raise HTTPException(404, f"no job {job_id}")
    return meta


def _existing(job_id: str, store: Annotated[JobStore, Depends(get_store)]) -> dict:
    return _load(store, job_id)


@router.get("/{job_id}", response_model=Job, responses={404: _ERRORS[404]})
def get_job(job_id: str, store: Annotated[JobStore, Depends(get_store)]):
    """Status, progress, and once finished the result (or the error as problem details)."""
    return job_document(store, _load(store, job_id))


@router.post("/{job_id}/cancel", response_model=Job, status_code=202, responses={404: _ERRORS[404]})
def cancel_job(job_id: str, store: Annotated[JobStore, Depends(get_store)]):
    """A queued job never starts; a running one stops at its next node and keeps its best result."""
    meta = _load(store, job_id)
    if meta["status"] not in TERMINAL:
        store.request_cancel(job_id)
        if store.cancel_if_queued(job_id):
            from workers.celery_app import celery_app

            for task_id in meta.get("task_ids") or []:
                celery_app.control.revoke(task_id)
    return job_document(store, _load(store, job_id))


def _resume_point(last_event_id: Annotated[str | None, Header()] = None) -> str:
    if not last_event_id:
        return "0-0"
    if not re.fullmatch(r"\d{1,20}-\d{1,20}", last_event_id):
        raise InputError("Last-Event-ID", "must be an event id this stream sent (digits-digits)")
    return last_event_id


@router.get("/{job_id}/events", response_class=EventSourceResponse, responses={k: _ERRORS[k] for k in (404, 422)})
def job_events(
    job_id: str,
    store: Annotated[JobStore, Depends(get_store)],
    after: Annotated[str, Depends(_resume_point)],
    _job: Annotated[dict, Depends(_existing)],
):
    """Server-Sent Events: `status` and `progress` events, then one `end` event after which the
    stream closes; resumes after `Last-Event-ID`. Event data is JSON."""
    for event_id, event, data in store.events(job_id, after):
        if event == "keepalive":
            yield ServerSentEvent(comment="keepalive")
            continue
        yield ServerSentEvent(id=event_id, event=event, data=data)

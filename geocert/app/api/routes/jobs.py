"""Jobs: submit, read, stream, cancel, delete. Every route needs the caller's key (when keys are
configured) and shows a job only to the key that created it."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import itertools
import json
import math
import re
from typing import Annotated
from urllib.parse import urlencode

from fastapi import APIRouter, Body, Depends, Header, Path, Query, Request, Response
from fastapi.responses import StreamingResponse
from fastapi.concurrency import run_in_threadpool
from fastapi.routing import APIRoute
from fastapi.sse import EventSourceResponse, ServerSentEvent
from pydantic import ValidationError
from starlette.exceptions import HTTPException
from starlette.requests import ClientDisconnect

from geocert.app.api.deps import (JobStoreDep, Owner, error_responses, get_async_redis, get_store,
                                  stream_slot)
from geocert.settings import get_settings
from geocert.app import lifecycle
from geocert.app import exports, processes, shape, streamed, submissions
from geocert.app import job_submission
from geocert.app.job_submission import _submit
from geocert.jobs.collection import collector_held
from geocert.app.errors import ApiProblem, is_json_media_type, long_number_reason
from geocert.app.schemas import JOB_EXAMPLES, JOB_REQUEST, JOB_STATUSES, Job, JobList, JobRequest
from geocert.core.geometry import InputError
from geocert.workers.queue import loop_producer, loop_producer_tried, ready_loop_producer, withdraw_queued
from geocert.jobs.store import REDIS_GONE, TERMINAL, JobStore, ResultGone, events, read_job

# As many export processes as exports may run at once (the gate on the export path refuses more).
_EXPORTS = processes.Pool(lambda: get_settings().max_concurrent_exports or 2, exports.ready,
                          "the process writing this export")


class StreamedItemsRoute(APIRoute):
    """POST routes of this router check a large JSON body's budget from its shape before parsing
    it (app.shape), and take a large body of an itemised kind item by item (app.streamed): the
    route's model checks the body's head, the items are checked and stored a batch at a time by
    ``_submit``; a large body of any other kind is submitted whole in a process of its own
    (app.submissions). Every other request is handled as usual."""

    def get_route_handler(self):
        handler = super().get_route_handler()
        if "POST" not in self.methods:
            return handler

        async def route_handler(request: Request) -> Response:
            threshold = get_settings().stream_threshold_bytes
            # A large body over budget: 413, unparsed; one to stream: read here either way.
            body = await shape.check_body(request, shape.job_figures, min(shape.CHECK_ABOVE_BYTES, threshold))
            if body is not None and len(body) <= threshold:
                request._body = bytes(body)
            elif body is not None:
                split = streamed.split_items(body)
                if split is not None:
                    request._body = split.head.encode()  # what the route's model reads and checks
                    request.state.streamed = split
                elif self.endpoint is submit_job:  # taken whole in a submission process: the model reads a stand-in
                    request._body = submissions.STAND_IN
                    request.state.whole_body = bytes(body)
                else:
                    request._body = bytes(body)  # the ordinary path reads it whole
                del body
            if self.endpoint is submit_job:
                await read_in_one_pass(request)
            try:
                return await handler(request)
            except HTTPException as exc:
                # FastAPI's bare 400 "There was an error parsing the body", without a field, for a
                # body json.loads refused with a ValueError that is not a JSONDecodeError: bytes
                # that are not UTF-8 (worded as a body read in a process words them), or valid JSON
                # holding an integer longer than the parser converts (not a syntax error: 422)
                cause = exc.__cause__
                if exc.status_code == 400 and isinstance(cause, UnicodeDecodeError):
                    processes.raise_carried(("json", cause.start, f"not UTF-8 ({cause.reason})"), request._body)
                if exc.status_code == 400 and isinstance(cause, ValueError) and not isinstance(cause, json.JSONDecodeError):
                    raise InputError("body", long_number_reason(cause)) from None
                raise

        return route_handler


async def read_in_one_pass(request: Request) -> None:
    """A job's JSON body validated from its bytes in one pass (``JOB_REQUEST.validate_json``)
    instead of FastAPI's two (``json.loads``, then validating the objects it made): 0.6 of their
    CPU for a 0.9 MB body, 0.4 for a 2 kB one (bench/results/service.md). The model it gives stands as the
    request's parsed JSON (Starlette's ``Request.json`` keeps it in ``_json``), which FastAPI then
    validates as an instance of the model: passed through, not read again. A body this pass
    refuses is left to FastAPI's two passes, so that its errors are worded exactly as they were
    (the JSON parser's message and position, pydantic's messages on Python objects: they differ
    from validate_json's, e.g. "a valid list" against "a valid array")."""
    if not is_json_media_type(request.headers.get("content-type")):
        return  # FastAPI answers it (415, or the body's own errors)
    try:
        body = await request.body()
    except ClientDisconnect:
        return  # FastAPI's own read meets it too, and answers it as it always did
    if not body:
        return
    try:
        with collector_held():
            request._json = JOB_REQUEST.validate_json(body)
    except ValidationError:
        pass


# Every route is rate limited through its caller (Owner, or OwnedJob's), not by a router dependency
# beside it: one walk of the caller's dependencies a request instead of two (deps.Owner).
router = APIRouter(prefix="/v1/jobs", tags=["jobs"], route_class=StreamedItemsRoute)


MAX_WAIT_S = 60  # the longest Prefer: wait honoured (a larger N waits this long)


def preferred_wait(prefer: str | None) -> int | None:
    """The seconds of a ``wait=N`` preference (RFC 7240) in Prefer headers, capped at MAX_WAIT_S;
    None without one. Preferences are comma-separated ``token[=value][; params]``; one not
    understood (or a wait that is not a non-negative integer) is ignored, as the RFC asks."""
    if not prefer:
        return None
    for preference in prefer.split(","):
        name, _, value = preference.split(";", 1)[0].strip().partition("=")
        value = value.strip().strip('"')
        if name.strip().lower() == "wait" and value.isdigit():
            return min(int(value), MAX_WAIT_S)
    return None


async def wait_for_end(job_id: str, seconds: float) -> bool:
    """Whether the job ends within ``seconds``: waits on its event stream's end event (a blocking
    XREAD on the loop, from the stream's start, so an end already announced counts), holding no
    thread. False at the deadline, when the server stops, or when the job is gone."""
    settings = get_settings()
    try:
        async with asyncio.timeout(seconds):
            stream = events(get_async_redis(streams=True), job_id, "0-0",
                            int(1000 * min(settings.stream_heartbeat_s, max(seconds, 0.001))), lifecycle.stop_event())
            async with contextlib.aclosing(stream):
                async for _, event, _ in stream:
                    if event == "end":
                        return True
                    if event == "stopping":
                        return False
    except TimeoutError:
        return False
    return False


@router.post("", status_code=202, response_model=Job, responses={
    200: {"model": Job, "description": "a replay: the job made earlier for this Idempotency-Key and body; or, "
                                       "with Prefer: wait=N, the job, finished within N seconds"},
    **error_responses(400, 409, 413, 415, 422)})
async def submit_job(
    body: Annotated[JobRequest, Body(openapi_examples=JOB_EXAMPLES)],
    request: Request,
    response: Response,
    owner: Owner,
    idempotency_key: Annotated[str | None, Header(max_length=255, description=(
        "repeat a submission safely: the same key and body give the same job; "
        "another body with the same key is a 422"))] = None,
    prefer: Annotated[str | None, Header(max_length=1000, description=(
        f"wait=N (RFC 7240): answer with the finished job (200) if it ends within N seconds (at most "
        f"{MAX_WAIT_S}), else the usual 202; Preference-Applied says the wait was honoured"))] = None,
):
    """Queue a job; answers 202 with its id and a Location to poll. With ``Prefer: wait=N`` the
    answer waits up to N seconds (at most 60) for the job to end: a job that ends in time comes
    back whole (200, its result or error), one that does not as the usual 202."""
    store = get_store()  # not a dependency: each costs FastAPI more than the call
    whole = getattr(request.state, "whole_body", None)
    if whole is not None:  # a large body of a kind without an item list to stream
        request.state.whole_body = None  # not kept while waiting
        document = await submissions.submit(whole, owner, idempotency_key, response)
        del whole
    elif (split := getattr(request.state, "streamed", None)) is None and \
            len(await request.body()) <= get_settings().submit_on_loop_bytes and (producer := await _loop_producer()):
        document = await job_submission.submit_on_loop(body, response, store, get_async_redis(), owner,
                                                       idempotency_key, producer)
    else:
        document = await run_in_threadpool(_submit, body, response, store, owner, idempotency_key, split)
    request.state.streamed = None  # the body's text, not kept while waiting
    wait = preferred_wait(prefer)
    if wait is None:
        return document
    response.headers["Preference-Applied"] = f"wait={wait}"
    if document["status"] not in TERMINAL and not await wait_for_end(document["id"], wait):
        return document
    meta = await read_job(get_async_redis(), document["id"])
    if meta is None or meta["status"] not in TERMINAL:
        return document
    response.status_code = 200
    finished = await run_in_threadpool(job_document, store, meta)
    if isinstance(finished, Response):  # sent as it is: the headers set above go with it
        finished.status_code = 200
        finished.headers.update({k: v for k, v in response.headers.items() if k != "content-length"})
    return finished


async def _loop_producer():
    """queue.loop_producer, made in a thread the first time (it connects to the broker); None
    when the broker cannot queue tasks in a job's transaction (then submissions use the pool)."""
    if not loop_producer_tried():
        await run_in_threadpool(ready_loop_producer)
    return loop_producer()


_JOB_ID = re.compile(r"[0-9a-f]{32}")  # JobStore.create's ids


async def _owned(job_id: Annotated[str, Path(description="the job's id (32 hex digits)")],
                 owner: Owner) -> dict:
    if not _JOB_ID.fullmatch(job_id):  # no such job; never a Redis key made of what the client sent
        raise ApiProblem(404, f"no job {job_id}")
    meta = await read_job(get_async_redis(), job_id)  # on the loop: every job route reads the job first
    if meta is None or meta.get("owner") != owner:  # another key's job does not exist for this one
        raise ApiProblem(404, f"no job {job_id}")
    return meta


OwnedJob = Annotated[dict, Depends(_owned)]


def _encode_cursor(position: tuple[float, str]) -> str:
    return base64.urlsafe_b64encode(f"{position[0]!r}/{position[1]}".encode()).decode().rstrip("=")


def _decode_cursor(cursor: str) -> tuple[float, str]:
    try:
        text = base64.urlsafe_b64decode(cursor + "=" * (-len(cursor) % 4)).decode()
        created, job_id = text.split("/", 1)
        position = float(created), job_id
    except ValueError:
        position = None
    if position is None or not math.isfinite(position[0]) or not re.fullmatch(r"[0-9a-f]{32}", position[1]):
        raise ApiProblem(422, "not a cursor this listing gave (use next_cursor as it came)", "cursor")
    return position


@router.get("", response_model=JobList, responses=error_responses(422))
def list_jobs(
    response: Response,
    store: JobStoreDep,
    owner: Owner,
    limit: Annotated[int, Query(ge=1, le=100, description="jobs per page")] = 20,
    cursor: Annotated[str | None, Query(max_length=200, description="next_cursor of the previous page")] = None,
    status: Annotated[list[JOB_STATUSES] | None, Query(
        description="only jobs in this status (repeat for several)")] = None,
):
    """The caller's jobs, newest first, a page at a time: follow ``next_cursor`` (or the ``next``
    link, also sent as a ``Link: <...>; rel="next"`` header) until it is null. Jobs are listed
    until they are deleted or expire (GEOCERT_RESULT_TTL_S after they end)."""
    after = _decode_cursor(cursor) if cursor is not None else None
    metas, following = store.list_jobs(owner, limit, after, tuple(status) if status else None)
    next_cursor = _encode_cursor(following) if following else None
    next_link = None
    if next_cursor:
        query = [("limit", str(limit)), ("cursor", next_cursor)] + [("status", s) for s in status or ()]
        next_link = "/v1/jobs?" + urlencode(query)
        response.headers["Link"] = f'<{next_link}>; rel="next"'
    return {"jobs": [store.summary(meta) for meta in metas], "next_cursor": next_cursor, "links": {"next": next_link}}


@router.get("/{job_id}", response_model=Job, responses=error_responses(404))
async def get_job(job: OwnedJob, store: JobStoreDep):
    """Status, progress, and once finished the result (or the error as problem details)."""
    if job["status"] not in TERMINAL:
        # A small document made of the record already read, no I/O: answered on the loop. A
        # route run in the pool took two threads' turns (the route, then its response model),
        # each taking the interpreter lock from the loop, for every poll of a running job.
        return store.document(job)
    return await run_in_threadpool(finished_document, store, job)


def finished_document(store: JobStore, job: dict) -> Response:
    """An ended job's document, read, validated and written in the calling thread (its result
    may be large): as the route's response model would write it."""
    found = job_document(store, job)
    if isinstance(found, Response):
        return found
    return Response(Job.model_validate(found).model_dump_json(by_alias=True), media_type="application/json")


def job_document(store: JobStore, job: dict) -> dict | Response:
    """The job document to answer with (GET, and a POST that waited for the end): a finished
    job whose worker stored the result as the result model writes it (batch.result_json) goes out
    as stored, in a Response; any other as the store's document, for the route's model to write.
    Parsing, validating (through the union of every kind's results) and writing a stored result
    again took most of a large job's GET: over 1 s for 5,000 tracks on this machine under load."""
    if job["status"] not in TERMINAL or job.get("result_form") != "model":
        return store.document(job)
    try:
        pieces = store.result_pieces(job["id"], job)
    except ResultGone:  # it expired (or was deleted) between reading its status and its result
        raise ApiProblem(404, f"job {job['id']} not found (it expired while it was read)") from None
    shell = store.head(job)
    text = Job.model_validate(shell | {"result": None, "links": store.links(job["id"])}).model_dump_json(by_alias=True)
    head, marker, tail = text.partition('"result":null')  # the one top-level key of that name (strings escape quotes)
    assert marker, "a job document always has a result key"
    if pieces is None:
        return Response(head + '"result":null' + tail, media_type="application/json")
    # Sent as read: a large result (12 times its request for tracks) is never whole in memory.
    return StreamingResponse(itertools.chain([(head + '"result":').encode()], pieces, [tail.encode()]),
                             media_type="application/json")


@router.get("/{job_id}/request", response_class=Response, responses={
    200: {"content": {"application/json": {"schema": {"type": "object", "description": "a job request (POST /v1/jobs)"}}},
          "description": "the job as submitted"}, **error_responses(404)})
def get_job_request(job: OwnedJob, store: JobStoreDep):
    """The job as submitted (``kind``, ``data``, ``options`` with the defaults filled in): what a
    result's items refer to (e.g. the cameras and observations a triangulation's residuals come from)."""
    raw = store.request_text(job["id"])
    if raw is None:
        raise ApiProblem(404, f"no request kept for job {job['id']}")
    return Response(raw, media_type="application/json")  # stored as JSON: sent as it is


@router.get("/{job_id}/export", response_class=Response, responses={
    200: {"content": {"application/zip": {}, "application/octet-stream": {}, "text/plain": {}},
          "description": "format=colmap: a zip of COLMAP's text model (cameras.txt, images.txt, points3D.txt); "
                         "format=ply: the points as PLY (ascii, or binary with binary=true)"},
    **error_responses(404, 409, 422, 429, 503)})
async def export_job(job: OwnedJob, format: Annotated[str, Query(description="colmap or ply")],
                     binary: Annotated[bool, Query(description="ply: binary little-endian")] = False):
    """A finished reconstruction job's result in a format other tools open. Written in an export
    process (app.exports); at most GEOCERT_MAX_CONCURRENT_EXPORTS at once per API process, and
    GEOCERT_MAX_CONCURRENT_EXPORTS_PER_KEY of one key's (429 with Retry-After beyond)."""
    from geocert.solvers.reconstruction.export import FORMATS

    if format not in FORMATS:
        raise ApiProblem(422, f"unknown format {format!r} (served: {', '.join(FORMATS)})", "format")
    if job["status"] != "succeeded":
        raise ApiProblem(409, f"job {job['id']} is {job['status']}: only a succeeded job's result is exported")
    outcome = await _EXPORTS.run(exports.export_job, job["id"], format, binary, processes.environment())
    if outcome[0] != "export":
        processes.raise_carried(outcome, b"")
    _, content, media_type, suffix = outcome
    return Response(content, media_type=media_type,
                    headers={"content-disposition": f'attachment; filename="{job["id"]}{suffix}"'})


@router.post("/{job_id}/cancel", response_model=Job, status_code=202, responses=error_responses(404, 409))
def cancel_job(job: OwnedJob, store: JobStoreDep):
    """A queued job never starts; a running one stops at its next node and keeps its best result.
    A job that has already ended is a 409 naming its status (nothing to cancel)."""
    job_id = job["id"]
    if job["status"] in TERMINAL:
        raise ApiProblem(409, f"job {job_id} has already ended ({job['status']}): there is nothing to cancel")
    store.request_cancel(job_id)
    if store.cancel_if_queued(job_id):
        withdraw_queued(store, job_id)
    return store.document(store.get(job_id))


@router.delete("/{job_id}", status_code=204, responses=error_responses(404, 409))
def delete_job(job: OwnedJob, store: JobStoreDep):
    """Remove a finished job and everything kept for it (409 while it is queued or running)."""
    if job["status"] not in TERMINAL:
        raise ApiProblem(409, f"job {job['id']} is {job['status']}: cancel it first, then delete it")
    store.delete(job["id"])
    return Response(status_code=204)


_STREAM_ID_PART_MAX = 2**64 - 1  # a Redis stream id: two unsigned 64-bit numbers


def _resume_point(last_event_id: Annotated[str | None, Header(max_length=41)] = None) -> str:
    if not last_event_id:
        return "0-0"
    parts = re.fullmatch(r"(\d{1,20})-(\d{1,20})", last_event_id)
    if parts is None or any(int(part) > _STREAM_ID_PART_MAX for part in parts.groups()):
        raise InputError("Last-Event-ID", "must be an event id this stream sent (two numbers below 2^64, "
                                          "joined by '-')")
    return last_event_id


@router.get("/{job_id}/events", response_class=EventSourceResponse, responses=error_responses(404, 422),
            dependencies=[Depends(stream_slot)])
async def job_events(job: OwnedJob, after: Annotated[str, Depends(_resume_point)]):
    """Server-Sent Events: `status` and `progress` events, then one `end` event after which the
    stream closes; resumes after `Last-Event-ID`. Event data is JSON. An idle stream carries a
    `: keepalive` comment every GEOCERT_STREAM_HEARTBEAT_S (10 s). A key may hold
    GEOCERT_MAX_STREAMS_PER_KEY streams open at once (429 beyond). When the server is stopping, or
    its job store stops answering, the stream ends early with a `retry` hint and no `end` event:
    reconnect with `Last-Event-ID`."""
    settings = get_settings()
    try:
        async for event_id, event, data in events(get_async_redis(streams=True), job["id"], after,
                                                  int(1000 * settings.stream_heartbeat_s), lifecycle.stop_event()):
            if event == "stopping":
                yield ServerSentEvent(comment="server stopping: reconnect with Last-Event-ID", retry=1000)
                return
            if event == "keepalive":
                yield ServerSentEvent(comment="keepalive")
                continue
            yield ServerSentEvent(id=event_id, event=event, data=data)
    except REDIS_GONE:
        yield ServerSentEvent(comment="the job store is not answering: reconnect with Last-Event-ID", retry=5000)

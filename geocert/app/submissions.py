"""A large job body taken whole (a kind without an item list to stream: app.streamed) is submitted
in a process of its own, not in the API process.

Decoding it (json.loads), validating it by its model, dumping it back and storing it cost about
0.3 s of CPU a megabyte, and the decoder and parts of the model's work each hold the interpreter
lock for the whole body: in a thread of the API process they would still stop its event loop,
and every other client's request with it, for seconds. In a submission process they cost the API
process nothing but the body's bytes sent through a pipe; its answer is the job's document (or
the error), a few hundred bytes.

The route still runs its dependencies (the caller's key, its rate limit, its headers) with a
small stand-in body in place of the large one (StreamedItemsRoute); the submission process then
does what ``_submit`` does with the body itself, with the API process's settings (its GEOCERT_*
environment), so the job it makes, the request stored and the errors answered are those of a
body submitted in process. The processes start with the first large body, which is taken in a
thread of the API process while they do (seconds: they import what a submission needs). A
submission process that dies (killed for memory, say) fails the
submission it held with a 503 to retry; the next large body starts new ones.
"""

from __future__ import annotations

import asyncio
import json
import multiprocessing
import os
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

import redis
from fastapi import Response
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError

from geocert.app.errors import ApiProblem
from geocert.settings import get_settings
from geocert.solvers.core.geometry import InputError
from geocert.workers.store import REDIS_GONE

PROCESSES = 2  # submissions of large bodies at once; more wait their turn
# What the route's model reads in place of a large body (its validation is then cheap); the body
# itself is validated in the submission process.
STAND_IN = json.dumps({"kind": "triangulation", "data": {
    "cameras": [[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], [[1, 0, 0, -1], [0, 1, 0, 0], [0, 0, 1, 0]]],
    "tracks": [{"views": [0, 1], "points": [[0, 0], [-1, 0]]}]}}).encode()

_POOL: ProcessPoolExecutor | None = None
_STARTING: list[Future] = []  # each process's first task: its imports (_ready)
_POOL_LOCK = threading.Lock()


def _ready() -> None:
    """A submission process's first task: what a submission imports, imported."""
    from geocert.app import job_submission  # noqa: F401


def _pool() -> ProcessPoolExecutor | None:
    """The submission processes once they have started; None while they start (begun by the
    first call: a process takes seconds to import what it needs, and the first large body is
    not held that long)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            # spawned, not forked: the API process has an event loop and threads a fork would copy
            _POOL = ProcessPoolExecutor(PROCESSES, mp_context=multiprocessing.get_context("spawn"))
            _STARTING[:] = [_POOL.submit(_ready) for _ in range(PROCESSES)]
        pool = _POOL
    if not all(started.done() for started in _STARTING):
        return None
    if any(started.exception() is not None for started in _STARTING):
        _forget(pool)
        return None
    return pool


def _forget(pool: ProcessPoolExecutor) -> None:
    """Drop a pool whose process died (every later submission to it would fail)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is pool:
            _POOL = None
    pool.shutdown(wait=False, cancel_futures=True)


async def submit(body: bytes, owner: str, idempotency_key: str | None, response: Response) -> dict:
    """Submit the job whose JSON body is ``body`` in a submission process: the job's document
    (``response`` given its headers and status), or the error raised here as it would be in process."""
    pool = _pool()
    if pool is None:  # starting: taken in a thread of this process, as before there were any
        outcome = await run_in_threadpool(_submit_body, bytes(body), owner, idempotency_key, _environment())
        return _answer(outcome, body, response)
    try:
        outcome = await asyncio.wrap_future(pool.submit(_submit_body, bytes(body), owner, idempotency_key,
                                                        _environment()))
    except BrokenProcessPool:
        _forget(pool)
        raise ApiProblem(503, "the process taking this large body stopped before it was stored; send it again",
                         headers={"Retry-After": "1"}) from None
    return _answer(outcome, body, response)


def _answer(outcome: tuple, body: bytes, response: Response) -> dict:
    """The job's document from ``_submit_body``'s outcome, or its error raised."""
    what = outcome[0]
    if what == "json":
        _, position, message = outcome
        raise RequestValidationError([{"type": "json_invalid", "loc": ("body", position), "msg": "JSON decode error",
                                       "input": {}, "ctx": {"error": message}}], body=body)
    if what == "invalid":
        raise RequestValidationError(outcome[1])
    if what == "problem":
        _, status, detail, field, headers = outcome
        raise ApiProblem(status, detail, field, headers)
    if what == "input":
        raise InputError(*outcome[1:])
    if what == "redis":
        raise redis.exceptions.ConnectionError(outcome[1])
    _, document, status, headers = outcome
    if status is not None:  # a replay's 200; else the route's own
        response.status_code = status
    response.headers.update(headers)
    return document


def _submit_body(body: bytes, owner: str, idempotency_key: str | None, environment: dict[str, str]) -> tuple:
    """In a submission process: what the route and ``_submit`` do with a body, as a tuple that
    crosses the pipe: ("document", document, status, headers), ("json", position, message),
    ("invalid", errors), ("problem", status, detail, field, headers), ("input", field, reason) or
    ("redis", message): only plain values, so that nothing fails to cross back."""
    from pydantic import ValidationError

    from geocert.app.api.deps import get_store
    from geocert.app.job_submission import _submit
    from geocert.app.schemas import JOB_REQUEST

    _use(environment)
    try:  # the model reads the text itself: a third less than json.loads and validating what it gives
        request = JOB_REQUEST.validate_json(body)
    except ValidationError:  # the errors as the route gives them: from json.loads and the decoded body
        try:
            decoded = json.loads(body)
        except json.JSONDecodeError as exc:
            return "json", exc.pos, exc.msg
        try:
            request = JOB_REQUEST.validate_python(decoded)
        except ValidationError as exc:  # as FastAPI words a body's errors: under "body", the input left out
            return "invalid", [{key: value for key, value in error.items() if key != "input"} | {
                "loc": ("body", *error["loc"]), "ctx": {k: str(v) for k, v in (error.get("ctx") or {}).items()}}
                for error in exc.errors(include_url=False)]
        del decoded
    response = Response()  # as FastAPI gives a route: no status of its own until one is set
    response.status_code = None
    try:
        document = _submit(request, response, get_store(), owner, idempotency_key)
    except ApiProblem as exc:
        return "problem", exc.status, exc.detail, exc.field, exc.headers
    except InputError as exc:  # the kind's own checks
        return "input", exc.field, exc.reason
    except REDIS_GONE as exc:
        return "redis", str(exc)
    headers = {name: value for name, value in response.headers.items() if name != "content-length"}
    return "document", document, response.status_code, headers


def _environment() -> dict[str, str]:
    return {name: value for name, value in os.environ.items() if name.startswith("GEOCERT_")}


def _use(environment: dict[str, str]) -> None:
    """The API process's settings (GEOCERT_* variables, read when it submits) in this one."""
    if environment == _environment():
        return
    from geocert.app.api.deps import get_store

    for name in _environment():
        del os.environ[name]
    os.environ.update(environment)
    get_settings.cache_clear()
    get_store.cache_clear()

"""Shared dependencies: the job store, the caller, the rate limit, and the queue."""

from __future__ import annotations

import asyncio
import weakref
from functools import lru_cache
from typing import Annotated, AsyncIterator

import redis.asyncio
from fastapi import Depends, Request

from geocert.settings import get_settings
from geocert.app.core.security import PUBLIC_OWNER, caller
from geocert.app.errors import PROBLEM_JSON, ApiProblem
from geocert.app.schemas import ProblemDetails
from geocert.jobs.store import JobStore, count_request


@lru_cache
def get_store() -> JobStore:
    from redis.backoff import ExponentialBackoff
    from redis.retry import Retry

    from geocert.settings import redis_url

    # Bounded waits: a request during a Redis outage fails over to 503 within a few seconds
    # instead of hanging (the socket timeout exceeds the SSE stream's 1 s blocking XREAD).
    return JobStore.from_url(redis_url(), get_settings().result_ttl_s, socket_connect_timeout=2, socket_timeout=5,
                             retry=Retry(ExponentialBackoff(cap=0.5, base=0.05), 2))


async def _store() -> JobStore:
    return get_store()  # as a coroutine, FastAPI resolves it on the loop instead of in a thread


JobStoreDep = Annotated[JobStore, Depends(_store)]
Caller = Annotated[str, Depends(caller)]

_ASYNC_CLIENTS: "weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, dict]" = weakref.WeakKeyDictionary()


def get_async_redis(streams: bool = False) -> redis.asyncio.Redis:
    """This event loop's asyncio Redis clients. The plain one serves the reads every request makes
    (rate limit, the job) on the loop, with the sync store's bounded waits (a request during an
    outage fails over to 503 within a few seconds). The ``streams`` one serves event streams: each
    open stream holds one of its connections in a blocking XREAD (hence the large pool, and a read
    timeout longer than the heartbeat) and none of the API's threads."""
    loop = asyncio.get_running_loop()
    clients = _ASYNC_CLIENTS.setdefault(loop, {})
    if streams not in clients:
        from redis.asyncio.retry import Retry
        from redis.backoff import ExponentialBackoff

        from geocert.settings import redis_url

        settings = get_settings()
        clients[streams] = redis.asyncio.Redis.from_url(
            redis_url(), decode_responses=True, socket_connect_timeout=2,
            socket_timeout=settings.stream_heartbeat_s + 5 if streams else 5,
            max_connections=100_000 if streams else 1000, retry=Retry(ExponentialBackoff(cap=0.5, base=0.05), 2))
    return clients[streams]


def client_bucket(request: Request, owner: str) -> str:
    """Whom a limit counts: the key's owner, or without keys (every caller the same owner) the
    client's address, so that one flooding client does not spend the others' budget."""
    if owner == PUBLIC_OWNER:
        return f"{PUBLIC_OWNER}@{request.client.host if request.client else 'unknown'}"
    return owner


async def rate_limited(request: Request, owner: Caller) -> str:
    """At most GEOCERT_RATE_LIMIT_PER_MINUTE requests per key per minute (a fixed window in Redis,
    shared by every API process), per client address without keys (``client_bucket``). On the
    event loop, with the asyncio client: every /v1 request passes here. Returns the caller's
    owner (``Owner``)."""
    limit = get_settings().rate_limit_per_minute
    if limit <= 0:
        return owner
    count, retry_after = await count_request(get_async_redis(), client_bucket(request, owner))
    if count > limit:
        raise ApiProblem(429, f"more than {limit} requests this minute (GEOCERT_RATE_LIMIT_PER_MINUTE)",
                         headers={"Retry-After": str(retry_after)})
    return owner


# The caller, counted against the rate limit: what the job routes take, instead of the router
# depending on rate_limited and each route on Caller besides. FastAPI walks a dependency's whole
# tree on every request even when its value is cached (the caller's twice, with its key header),
# and solving them was some 80 us of a small submission's 1.4 ms in the app (bench/results/service.md).
Owner = Annotated[str, Depends(rate_limited)]


_OPEN_STREAMS: dict[str, int] = {}  # client_bucket -> event streams open in this process


async def stream_slot(request: Request, owner: Owner) -> AsyncIterator[None]:
    """Holds one of the caller's GEOCERT_MAX_STREAMS_PER_KEY event-stream slots in this API
    process from the request until its stream has ended (429 when none is free). Runs on the event
    loop, so the count needs no lock; a request-scoped dependency, released after the response."""
    limit = get_settings().max_streams_per_key
    bucket = client_bucket(request, owner)
    if limit > 0 and _OPEN_STREAMS.get(bucket, 0) >= limit:
        raise ApiProblem(429, f"this key already has {limit} event streams open (GEOCERT_MAX_STREAMS_PER_KEY); "
                              "close one first", headers={"Retry-After": "5"})
    _OPEN_STREAMS[bucket] = _OPEN_STREAMS.get(bucket, 0) + 1
    try:
        yield
    finally:
        _OPEN_STREAMS[bucket] -= 1
        if not _OPEN_STREAMS[bucket]:
            del _OPEN_STREAMS[bucket]


def _problem(description: str) -> dict:
    return {"model": ProblemDetails, "content": {PROBLEM_JSON: {}}, "description": description}


ERRORS = {
    400: _problem("the body is not parseable JSON (the parser's message, line and column)"),
    401: _problem("no X-API-Key header (keys are configured)"),
    403: _problem("the X-API-Key is not one of the configured keys"),
    404: _problem("no such job (for this key)"),
    409: _problem("the job is not in a state that allows this, or an idempotent request is in progress"),
    413: _problem("body, items or observations over a limit (named in the detail)"),
    415: _problem("the body was not sent as content-type: application/json"),
    422: _problem("invalid request: names the field"),
    429: _problem("rate, active-job or open-stream limit reached (named in the detail); see Retry-After"),
    503: _problem("the job store (Redis) is not answering, e.g. while it restarts; see Retry-After"),
}


def error_responses(*codes: int) -> dict:
    """OpenAPI responses of a keyed, rate-limited route: 401, 403, 429, 503 and ``codes``."""
    return {code: ERRORS[code] for code in (401, 403, 429, 503) + codes}

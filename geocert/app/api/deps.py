"""Shared dependencies: the job store, the caller, the rate limit, and the queue."""

from __future__ import annotations

from functools import lru_cache
from typing import Annotated

from fastapi import Depends, Request

from geocert.settings import get_settings
from geocert.app.core.security import PUBLIC_OWNER, caller
from geocert.app.errors import PROBLEM_JSON, ApiProblem
from geocert.app.schemas import ProblemDetails
from geocert.workers.store import JobStore


@lru_cache
def get_store() -> JobStore:
    from redis.backoff import ExponentialBackoff
    from redis.retry import Retry

    from geocert.workers.celery_app import redis_url

    # Bounded waits: a request during a Redis outage fails over to 503 within a few seconds
    # instead of hanging (the socket timeout exceeds the SSE stream's 1 s blocking XREAD).
    return JobStore.from_url(redis_url(), get_settings().result_ttl_s, socket_connect_timeout=2, socket_timeout=5,
                             retry=Retry(ExponentialBackoff(cap=0.5, base=0.05), 2))


JobStoreDep = Annotated[JobStore, Depends(get_store)]
Caller = Annotated[str, Depends(caller)]


def rate_limited(request: Request, owner: Caller, store: JobStoreDep) -> None:
    """At most GEOCERT_RATE_LIMIT_PER_MINUTE requests per key per minute (a fixed window in Redis,
    shared by every API process). Without keys every caller is the same owner, so the budget is
    per client address instead: one flooding client does not spend the others'."""
    limit = get_settings().rate_limit_per_minute
    if limit <= 0:
        return
    bucket = owner
    if owner == PUBLIC_OWNER:
        bucket = f"{PUBLIC_OWNER}@{request.client.host if request.client else 'unknown'}"
    count, retry_after = store.count_request(bucket)
    if count > limit:
        raise ApiProblem(429, f"more than {limit} requests this minute (GEOCERT_RATE_LIMIT_PER_MINUTE)",
                         headers={"Retry-After": str(retry_after)})


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
    429: _problem("rate or active-job limit reached (named in the detail); see Retry-After"),
    503: _problem("the job store (Redis) is not answering, e.g. while it restarts; see Retry-After"),
}


def error_responses(*codes: int) -> dict:
    """OpenAPI responses of a keyed, rate-limited route: 401, 403, 429, 503 and ``codes``."""
    return {code: ERRORS[code] for code in (401, 403, 429, 503) + codes}

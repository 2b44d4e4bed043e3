"""Request ids, access logs and Prometheus metrics of the API.

Every request gets an id (the caller's ``X-Request-ID`` when it is sane, else a new one), echoed
in the response and carried in the log context, which the job's tasks inherit. ``/metrics``
shows this process's request counters and latencies plus the job figures every worker keeps in
Redis (``app.metrics``).
"""

from __future__ import annotations

import logging
import re
import time
import uuid

from fastapi import APIRouter, Response
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, Counter, Gauge, Histogram, generate_latest
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from geocert import logs
from geocert.app.metrics import RedisCollector

log = logging.getLogger("geocert.api")
REGISTRY = CollectorRegistry()
REQUESTS = Counter("geocert_http_requests", "HTTP requests by method, route and status",
                   ["method", "route", "status"], registry=REGISTRY)
LATENCY = Histogram("geocert_http_request_seconds", "Time to the response's first byte, by method and route",
                    ["method", "route"], registry=REGISTRY,
                    buckets=(0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0))
GATED = Gauge("geocert_gated_requests", "Requests in flight behind one of this API process's concurrency gates "
              "(GEOCERT_MAX_CONCURRENT_*): verifications, orientations, exports", ["gate"], registry=REGISTRY)
_SANE_ID = re.compile(r"[A-Za-z0-9._:-]{1,128}")
_collector_registered = False


class RequestContext:
    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        given = dict(scope.get("headers") or []).get(b"x-request-id", b"").decode("latin-1")
        request_id = given if _SANE_ID.fullmatch(given) else uuid.uuid4().hex
        start = time.perf_counter()
        status_seen = {"status": 500}

        async def send_with_id(message: Message) -> None:
            if message["type"] == "http.response.start":
                status_seen["status"] = message["status"]
                message.setdefault("headers", [])
                message["headers"] = list(message["headers"]) + [(b"x-request-id", request_id.encode())]
                route = getattr(scope.get("route"), "path", "unmatched")
                LATENCY.labels(scope["method"], route).observe(time.perf_counter() - start)
            await send(message)

        with logs.context(request_id=request_id):
            try:
                await self.app(scope, receive, send_with_id)
            finally:
                route = getattr(scope.get("route"), "path", "unmatched")
                REQUESTS.labels(scope["method"], route, str(status_seen["status"])).inc()
                log.info("request", extra={"method": scope["method"], "path": scope["path"],
                                           "status": status_seen["status"],
                                           "duration_ms": round(1e3 * (time.perf_counter() - start), 2)})


router = APIRouter(tags=["service"])


@router.get("/metrics", response_class=Response,
            responses={200: {"content": {CONTENT_TYPE_LATEST: {}}, "description": "Prometheus text format"},
                       503: {"content": {"application/problem+json": {}},
                             "description": "the job store (Redis) is not answering; see Retry-After"}})
def metrics():
    """Prometheus metrics: requests of this API process, and jobs, items, solve times, webhook
    deliveries and queue depth over the whole service."""
    global _collector_registered
    if not _collector_registered:
        from geocert.app.api.deps import get_store

        REGISTRY.register(RedisCollector.of_store(get_store()))
        _collector_registered = True
    return Response(generate_latest(REGISTRY), media_type=CONTENT_TYPE_LATEST)

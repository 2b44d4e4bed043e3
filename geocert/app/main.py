"""The FastAPI application."""

from __future__ import annotations

import re

from fastapi import FastAPI
from fastapi.concurrency import run_in_threadpool
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from geocert.app import docs, errors, observability, processes, webui
from geocert.app.api.routes import certificates, jobs, orient, service
from geocert.settings import get_settings
from geocert import logs


class BodySizeLimit:
    """Rejects bodies over ``max_body_bytes`` with 413 problem+json: at once when content-length
    says so, else (chunked bodies) while the bytes arrive. Nothing beyond the limit is read: on
    overflow this middleware answers 413 itself and tells the app the client has gone (an
    ``http.disconnect``), whose own answer to that is dropped. So a request never holds more than
    the limit plus one chunk in memory."""

    def __init__(self, app: ASGIApp, limit: int):
        self.app, self.limit = app, limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        declared = dict(scope.get("headers") or []).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.limit:
            return await self._reject(scope, receive, send)
        seen = 0
        state = {"started": False, "rejected": False}

        async def limited_receive() -> Message:
            nonlocal seen
            if state["rejected"]:
                return {"type": "http.disconnect"}
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    state["rejected"] = True
                    if not state["started"]:
                        await self._reject(scope, receive, send)
                    return {"type": "http.disconnect"}
            return message

        async def guarded_send(message: Message) -> None:
            if state["rejected"]:
                return  # the 413 is the answer; the app's reply to the "disconnect" is dropped
            if message["type"] == "http.response.start":
                state["started"] = True
            await send(message)

        await self.app(scope, limited_receive, guarded_send)

    async def _reject(self, scope, receive, send):
        # named like every other refusal: the field (as the 400 for a body that is not JSON) and the route
        reason = f"the request body exceeds the limit of {self.limit} bytes (GEOCERT_MAX_BODY_BYTES)"
        response = errors.problem(413, "Payload too large", reason, errors=[{"field": "body", "reason": reason}],
                                  instance=scope.get("path"), headers={"Connection": "close"})
        await response(scope, receive, send)


class GiveBackMemory:
    """After a request whose body or answer passed ``above`` bytes, the heap's free pages go back
    to the system (processes.give_back_memory: glibc's malloc_trim, in a thread: it releases the
    interpreter lock). glibc keeps what a request freed in its arenas for later allocations, so
    the API process stayed at the size of its largest requests for good; the trim costs some
    milliseconds, once per large request."""

    def __init__(self, app: ASGIApp, above: int = 1 << 20):
        self.app, self.above = app, above

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        moved = 0

        async def counted_receive() -> Message:
            nonlocal moved
            message = await receive()
            moved += len(message.get("body", b""))
            return message

        async def counted_send(message: Message) -> None:
            nonlocal moved
            moved += len(message.get("body", b""))
            await send(message)

        try:
            await self.app(scope, counted_receive, counted_send)
        finally:
            if moved > self.above:
                await run_in_threadpool(processes.give_back_memory)


class VerificationGate:
    """At most ``limit`` requests to ``path`` at once in this process (429 problem+json with
    Retry-After beyond it), counted from before the body is read: the API computes these itself,
    and a body is parsed into Python objects some 25 times its size (29 MB of empty lists: 760 MB
    and 19 s, for a one-line refusal), so their memory is bounded by the limit times that,
    whatever the request rate. Certificate verifications by default; /v1/orient and exports too
    (each done in a process of its own, as many as the gate lets in). ``path``: the path, or a
    pattern a path must match whole. ``per_key``: at most this many of one API key's (its
    X-API-Key header) among them (0: no such limit), so that one key cannot hold every place. On
    the event loop: the counts need no lock."""

    PATH = "/v1/certificates/verify"

    def __init__(self, app: ASGIApp, limit: int, path: str | re.Pattern = PATH, what: str = "certificate verifications",
                 variable: str = "GEOCERT_MAX_CONCURRENT_VERIFICATIONS", per_key: int = 0, per_key_variable: str = ""):
        self.app, self.limit, self.active = app, limit, 0
        self.path, self.what, self.variable = path, what, variable
        self.per_key, self.per_key_variable, self.by_key = per_key, per_key_variable, {}
        self.in_flight = observability.GATED.labels(what.split()[-1])  # /metrics: how many this gate holds

    def _gated(self, path: str | None) -> bool:
        if path is None:
            return False
        return self.path.fullmatch(path) is not None if isinstance(self.path, re.Pattern) else path == self.path

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not self._gated(scope.get("path")) or self.limit <= 0:
            return await self.app(scope, receive, send)
        key = dict(scope.get("headers") or []).get(b"x-api-key") if self.per_key > 0 else None
        if self.active >= self.limit:
            return await self._refuse(scope, receive, send, f"{self.limit} {self.what} are running in this process "
                                                            f"({self.variable})")
        if key is not None and self.by_key.get(key, 0) >= self.per_key:
            return await self._refuse(scope, receive, send, f"{self.per_key} {self.what} of this key are running in "
                                                            f"this process ({self.per_key_variable})")
        self.active += 1
        self.in_flight.inc()
        if key is not None:
            self.by_key[key] = self.by_key.get(key, 0) + 1
        try:
            await self.app(scope, receive, send)
        finally:
            self.active -= 1
            self.in_flight.dec()
            if key is not None:
                self.by_key[key] -= 1
                if not self.by_key[key]:
                    del self.by_key[key]

    @staticmethod
    async def _refuse(scope, receive, send, why: str) -> None:
        response = errors.problem(429, "Too many requests", f"{why}: retry shortly", headers={"Retry-After": "5"})
        await response(scope, receive, send)


EXPORT_PATH = re.compile(r"/v1/jobs/[^/]+/export")


def create_app() -> FastAPI:
    app = FastAPI(
        docs_url=None,  # served by app.docs, with local assets
        redoc_url=None,
        title="geocert",
        version="1.0.0",
        summary="Certified globally optimal multiview-geometry solves.",
        description=(
            "Submit a job, poll it or stream its progress (lower bound, upper bound, gap) over "
            "Server-Sent Events, cancel it, and fetch a result whose every item carries an "
            "optimality certificate. Errors are RFC 9457 problem+json naming the field. Methods "
            "after M. Chandraker, *From Pictures to 3D: Global Optimization for Scene Reconstruction* (2009)."
        ),
    )
    logs.configure()
    errors.install(app)
    docs.install(app)
    app.include_router(jobs.router)
    app.include_router(certificates.router)
    app.include_router(orient.router)
    app.include_router(service.router)
    app.include_router(observability.router)
    webui.install(app)  # after the API's routes: /web is a mount
    app.add_middleware(VerificationGate, limit=get_settings().max_concurrent_verifications,
                       per_key=get_settings().max_concurrent_verifications_per_key,
                       per_key_variable="GEOCERT_MAX_CONCURRENT_VERIFICATIONS_PER_KEY")
    app.add_middleware(VerificationGate, limit=get_settings().max_concurrent_orientations, path="/v1/orient",
                       what="orientations", variable="GEOCERT_MAX_CONCURRENT_ORIENTATIONS",
                       per_key=get_settings().max_concurrent_orientations_per_key,
                       per_key_variable="GEOCERT_MAX_CONCURRENT_ORIENTATIONS_PER_KEY")
    app.add_middleware(VerificationGate, limit=get_settings().max_concurrent_exports, path=EXPORT_PATH,
                       what="exports", variable="GEOCERT_MAX_CONCURRENT_EXPORTS",
                       per_key=get_settings().max_concurrent_exports_per_key,
                       per_key_variable="GEOCERT_MAX_CONCURRENT_EXPORTS_PER_KEY")
    app.add_middleware(BodySizeLimit, limit=get_settings().max_body_bytes)
    app.add_middleware(GiveBackMemory)
    app.add_middleware(observability.RequestContext)  # outermost: sees every answer, 413s included
    return app


app = create_app()

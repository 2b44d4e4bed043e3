"""The FastAPI application."""

from __future__ import annotations

from fastapi import FastAPI
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from geocert.app import docs, errors, observability, webui
from geocert.app.api.routes import certificates, jobs, orient, service
from geocert.settings import get_settings
from geocert.workers import logs


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
        response = errors.problem(413, "Payload too large",
                                  f"the request body exceeds the limit of {self.limit} bytes (GEOCERT_MAX_BODY_BYTES)",
                                  headers={"Connection": "close"})
        await response(scope, receive, send)


class VerificationGate:
    """At most ``limit`` requests to ``path`` at once in this process (429 problem+json with
    Retry-After beyond it), counted from before the body is read: the API computes these itself,
    and a body is parsed into Python objects some 25 times its size (29 MB of empty lists: 760 MB
    and 19 s, for a one-line refusal), so their memory is bounded by the limit times that,
    whatever the request rate. Certificate verifications by default; /v1/orient too (its dense
    cameras x points arrays: some 700 MB and 12 s at its budget each). On the event loop: the
    count needs no lock."""

    PATH = "/v1/certificates/verify"

    def __init__(self, app: ASGIApp, limit: int, path: str = PATH, what: str = "certificate verifications",
                 variable: str = "GEOCERT_MAX_CONCURRENT_VERIFICATIONS"):
        self.app, self.limit, self.active = app, limit, 0
        self.path, self.what, self.variable = path, what, variable

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope.get("path") != self.path or self.limit <= 0:
            return await self.app(scope, receive, send)
        if self.active >= self.limit:
            response = errors.problem(429, "Too many requests",
                                      f"{self.limit} {self.what} are running in this process "
                                      f"({self.variable}): retry shortly",
                                      headers={"Retry-After": "5"})
            return await response(scope, receive, send)
        self.active += 1
        try:
            await self.app(scope, receive, send)
        finally:
            self.active -= 1


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
    app.add_middleware(VerificationGate, limit=get_settings().max_concurrent_verifications)
    app.add_middleware(VerificationGate, limit=get_settings().max_concurrent_orientations, path="/v1/orient",
                       what="orientations", variable="GEOCERT_MAX_CONCURRENT_ORIENTATIONS")
    app.add_middleware(BodySizeLimit, limit=get_settings().max_body_bytes)
    app.add_middleware(observability.RequestContext)  # outermost: sees every answer, 413s included
    return app


app = create_app()

"""The FastAPI application."""

from __future__ import annotations

from fastapi import FastAPI
from starlette.types import ASGIApp, Receive, Scope, Send

from geocert.app import docs, observability, problems
from geocert.app.api.routes import certificates, jobs, orient, service
from geocert.settings import get_settings
from geocert.workers import logs


class BodySizeLimit:
    """Rejects bodies over ``max_body_bytes`` with 413 problem+json, by header or while reading."""

    def __init__(self, app: ASGIApp, limit: int):
        self.app, self.limit = app, limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        declared = dict(scope.get("headers") or []).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.limit:
            return await self._reject(scope, receive, send)
        seen = 0

        async def limited_receive():
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    raise _TooLarge()
            return message

        try:
            await self.app(scope, limited_receive, send)
        except _TooLarge:
            await self._reject(scope, receive, send)

    async def _reject(self, scope, receive, send):
        response = problems.problem(413, "Payload too large",
                                    f"the request body exceeds the limit of {self.limit} bytes (GEOCERT_MAX_BODY_BYTES)")
        await response(scope, receive, send)


class _TooLarge(Exception):
    pass


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
    problems.install(app)
    docs.install(app)
    app.include_router(jobs.router)
    app.include_router(certificates.router)
    app.include_router(orient.router)
    app.include_router(service.router)
    app.include_router(observability.router)
    app.add_middleware(BodySizeLimit, limit=get_settings().max_body_bytes)
    app.add_middleware(observability.RequestContext)  # outermost: sees every answer, 413s included
    return app


app = create_app()

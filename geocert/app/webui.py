"""The web pages: ``/`` (the caller's jobs and a form to submit one) and ``/jobs/{id}`` (a job,
live from its event stream, and once finished its items, residuals, 3D view and verification).

Static files shipped in the package (``geocert/app/web``), no build step, nothing fetched from
elsewhere: the pages call the same ``/v1`` routes as any client, with the caller's API key (asked
once, kept in the tab's sessionStorage) in ``X-API-Key``. The pages themselves need no key; they
show nothing until the API answers."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.responses import FileResponse, JSONResponse
from fastapi.staticfiles import StaticFiles

from geocert.app.core.security import configured_digests

WEB = Path(__file__).resolve().parent / "web"
ASSETS_URL = "/web"

# Scripts and styles from this origin only: no inline script, nothing from another site.
HEADERS = {
    "Content-Security-Policy": ("default-src 'self'; img-src 'self' blob: data:; style-src 'self'; "
                                "script-src 'self'; connect-src 'self'; object-src 'none'; base-uri 'none'; "
                                "frame-ancestors 'none'"),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "same-origin",
    "Cache-Control": "no-cache",
}

router = APIRouter(include_in_schema=False)


def _page(name: str) -> FileResponse:
    return FileResponse(WEB / name, media_type="text/html; charset=utf-8", headers=HEADERS)


@router.api_route("/", methods=["GET", "HEAD"])
def jobs_page() -> FileResponse:
    return _page("index.html")


@router.api_route("/jobs/{job_id}", methods=["GET", "HEAD"])
def job_page(job_id: str) -> FileResponse:  # the id is read by the page's script from its address
    return _page("job.html")


@router.get(f"{ASSETS_URL}/config.json")
def config() -> JSONResponse:
    """What the pages need before their first API call: whether to ask for a key (so they never
    draw a 401 first)."""
    return JSONResponse({"keys_required": bool(configured_digests())}, headers={"Cache-Control": "no-store"})


def install(app: FastAPI) -> None:
    app.include_router(router)
    app.mount(ASSETS_URL, StaticFiles(directory=WEB), name="web")

"""Problem kinds served, liveness and readiness."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends
from fastapi.responses import JSONResponse

from geocert.app.api.deps import error_responses, get_store, rate_limited
from geocert.app.schemas import ProblemKindInfo
from geocert.kinds import KINDS, default_options
from geocert.settings import get_settings
from geocert.jobs.store import JobStore

router = APIRouter()


@router.get("/v1/problems", response_model=list[ProblemKindInfo], tags=["problems"],
            dependencies=[Depends(rate_limited)], responses=error_responses())
def list_problems():
    """The problem kinds served, with the JSON schema of a job, the default options and a small
    example job of each."""
    return [
        ProblemKindInfo(kind=kind.name, description=kind.description, item_name=kind.item_key,
                        certifies=kind.certifies, request_schema=kind.request_model.model_json_schema(),
                        default_options=served_defaults(kind), example=kind.example)
        for kind in KINDS
    ]


def served_defaults(kind) -> dict:
    """The options a job of this kind gets here when it gives none: its model's defaults, with
    time_limit_s, max_nodes and job_time_limit_s lowered to this server's maxima as a submission's
    are (so that submitting them as they are is accepted)."""
    settings = get_settings()
    options = default_options(kind)
    for name, maximum in (("time_limit_s", settings.max_item_time_limit_s), ("max_nodes", settings.max_item_nodes),
                          ("job_time_limit_s", settings.max_job_time_limit_s)):
        if options.get(name) is not None and options[name] > maximum:
            options[name] = type(options[name])(maximum)
    return options


@router.get("/healthz", tags=["service"])
def healthz():
    """The API process is alive."""
    return {"status": "ok"}


@router.get("/readyz", tags=["service"], responses={503: {"description": "Redis or the workers do not answer"}})
def readyz(store: Annotated[JobStore, Depends(get_store)]):
    """Ready when Redis answers and at least one worker beat within the last 10 s (each worker
    writes a heartbeat into Redis every 2 s): two Redis commands, no waiting on workers."""
    checks = {"redis": False, "workers": 0}
    try:
        checks["redis"] = store.ping()
        checks["workers"] = store.live_workers()
    except Exception as exc:  # not ready is an answer, not an error
        checks["error"] = type(exc).__name__
    ready = checks["redis"] and checks["workers"] > 0
    return JSONResponse({"status": "ready" if ready else "not ready", **checks}, status_code=200 if ready else 503)

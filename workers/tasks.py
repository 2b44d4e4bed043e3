"""Thin tasks: load a chunk of a job, solve it with ``solvers``, publish progress, store results."""

from __future__ import annotations

import logging
import time
import traceback

from app.core.config import get_settings
from solvers.geometry import InputError
from solvers.jobs import get_kind, job_stats, options_from, solve_items
from workers.celery_app import celery_app, redis_url
from workers.store import JobStore

log = logging.getLogger("geocert.worker")
_STORE: JobStore | None = None


def store() -> JobStore:
    global _STORE
    if _STORE is None:
        _STORE = JobStore.from_url(redis_url(), get_settings().result_ttl_s)
    return _STORE


class _Throttle:
    """Publishes a chunk's progress at most every ``interval`` seconds (always the last one)."""

    def __init__(self, jobs: JobStore, job_id: str, chunk: int, interval: float):
        self.jobs, self.job_id, self.chunk, self.interval = jobs, job_id, chunk, interval
        self.last = 0.0
        self.cancel_checked = 0.0
        self.cancelled = False

    def __call__(self, progress: dict) -> None:
        if time.monotonic() - self.last >= self.interval or progress["tracks_done"] == progress["tracks_total"]:
            self.last = time.monotonic()
            self.jobs.save_chunk_progress(self.job_id, self.chunk, progress)

    def should_stop(self) -> bool:
        if not self.cancelled and time.monotonic() - self.cancel_checked >= 0.05:
            self.cancel_checked = time.monotonic()
            self.cancelled = self.jobs.cancel_requested(self.job_id)
        return self.cancelled


@celery_app.task(name="geocert.solve_chunk")
def solve_chunk(job_id: str, chunk: int) -> None:
    jobs = store()
    meta = jobs.get(job_id)
    if meta is None or not jobs.mark_running(job_id):
        return  # expired, or ended (cancelled) before it started: nothing to do
    start, stop = meta["chunks"][chunk]
    try:
        request = jobs.request(job_id)
        kind = get_kind(request["kind"])
        options = options_from(kind.options_type, request.get("options"))
        parsed = kind.parse(request["data"], items=range(start, stop))
        throttle = _Throttle(jobs, job_id, chunk, get_settings().progress_interval_s)
        items = solve_items(kind, parsed, options, range(start, stop), throttle, throttle.should_stop)
        done = jobs.save_chunk_items(job_id, chunk, items)
        if done == len(meta["chunks"]) and jobs.claim_finalisation(job_id):
            finalise(jobs, job_id, meta, kind, options)
    except InputError as exc:  # the API validates first, so this is a stored job gone bad
        fail(jobs, job_id, 422, "Invalid job data", str(exc), exc.field)
    except Exception as exc:  # never lose the reason: the job keeps its error
        log.exception("chunk %s of job %s failed", chunk, job_id)
        fail(jobs, job_id, 500, "Solver failure", f"{type(exc).__name__}: {exc}", None,
             traceback.format_exc(limit=5))


def finalise(jobs: JobStore, job_id: str, meta: dict, kind, options) -> None:
    items = jobs.chunk_items(job_id, len(meta["chunks"]))
    elapsed = time.time() - (meta["started_at"] or meta["created_at"])
    result = kind.assemble(options, items, job_stats(items, elapsed))
    status = "cancelled" if any(item["status"] == "cancelled" for item in items) else "succeeded"
    jobs.finish(job_id, status, result=result)


def fail(jobs: JobStore, job_id: str, status: int, title: str, detail: str, field: str | None,
         trace: str | None = None) -> None:
    error = {"type": "about:blank", "title": title, "status": status, "detail": detail}
    if field is not None:
        error["errors"] = [{"field": field, "reason": detail}]
    if trace:
        error["trace"] = trace
    if jobs.claim_finalisation(job_id):
        jobs.finish(job_id, "failed", error=error)

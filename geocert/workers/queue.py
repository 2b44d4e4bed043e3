"""Putting a job's work on the queue and taking it off: what the API asks of the workers, without
importing the tasks' solver code at module level."""

from __future__ import annotations

import threading

from geocert.workers.store import JobStore

_LOCK = threading.Lock()
_SOLVE_CHUNK = None


def _solve_chunk_task():
    """The solve task, resolved once under a lock: Celery's task objects are lazy proxies whose
    first evaluation is not thread-safe, and the API submits from many threads at once (a burst
    of first submissions answered 500 with AttributeError: 'PromiseProxy' ... '_Proxy__local')."""
    global _SOLVE_CHUNK
    with _LOCK:
        if _SOLVE_CHUNK is None:
            from geocert.workers.tasks import solve_chunk

            solve_chunk.name  # noqa: B018 (evaluates the proxy here, under the lock)
            _SOLVE_CHUNK = solve_chunk
    return _SOLVE_CHUNK


def submit_chunks(meta: dict, request_id: str | None) -> None:
    """One task per chunk, so a batch runs in parallel across every worker (a Celery group), each
    under the id ``JobStore.create`` recorded for it (``meta["task_ids"]``)."""
    from celery import group

    solve_chunk = _solve_chunk_task()
    signatures = [solve_chunk.s(meta["id"], start, stop, request_id).set(task_id=task_id)
                  for (start, stop), task_id in zip(meta["chunks"], meta["task_ids"])]
    group(signatures).apply_async()


def withdraw_queued(store: JobStore, job_id: str) -> None:
    """A job ended while queued (``JobStore.cancel_if_queued``): its tasks are revoked and its end
    counted (metrics, webhook)."""
    from geocert.workers.celery_app import celery_app
    from geocert.workers.tasks import after_end

    for task_id in store.task_ids(job_id):
        celery_app.control.revoke(task_id)
    after_end(store, job_id)

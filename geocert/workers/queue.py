"""Putting a job's work on the queue and taking it off: what the API asks of the workers, without
importing the tasks' solver code at module level."""

from __future__ import annotations

from geocert.workers.store import JobStore


def submit_chunks(store: JobStore, meta: dict, request_id: str | None) -> None:
    """One task per chunk, so a batch runs in parallel across every worker (a Celery group)."""
    from celery import group

    from geocert.workers.tasks import solve_chunk

    signatures = [solve_chunk.s(meta["id"], start, stop, request_id) for start, stop in meta["chunks"]]
    result = group(signatures).apply_async()
    store.add_task_ids(meta["id"], *(task.id for task in result.results))


def withdraw_queued(store: JobStore, job_id: str) -> None:
    """A job cancelled before it started: its tasks are revoked and its end recorded (metrics,
    webhook)."""
    from geocert.workers.celery_app import celery_app
    from geocert.workers.tasks import ended

    for task_id in store.task_ids(job_id):
        celery_app.control.revoke(task_id)
    ended(store, job_id)

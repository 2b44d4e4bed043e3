"""Shared dependencies: the job store and the queue."""

from __future__ import annotations

from functools import lru_cache

from app.core.config import get_settings
from workers.store import JobStore


@lru_cache
def get_store() -> JobStore:
    from workers.celery_app import redis_url

    return JobStore.from_url(redis_url(), get_settings().result_ttl_s)


def submit_chunks(store: JobStore, meta: dict) -> None:
    """One task per chunk, so a batch runs in parallel across every worker (a Celery group)."""
    from celery import group

    from workers.tasks import solve_chunk

    signatures = [solve_chunk.s(meta["id"], index) for index in range(len(meta["chunks"]))]
    result = group(signatures).apply_async()
    store.set_fields(meta["id"], task_ids=[r.id for r in result.results])

"""The Celery application: Redis as broker, JSON only, acknowledgement after the work is done."""

from __future__ import annotations

import os

from celery import Celery

from app.core.config import get_settings
from workers.redis_server import broker_url


def redis_url() -> str:
    url = get_settings().redis_url or os.environ.get("GEOCERT_REDIS_URL")
    if not url:
        raise RuntimeError("GEOCERT_REDIS_URL is not set (geocert serve sets it for its embedded Redis)")
    return url


def make_celery() -> Celery:
    app = Celery("geocert", broker=broker_url(redis_url()), include=["workers.tasks"])
    app.conf.update(
        task_serializer="json",
        accept_content=["json"],
        task_ignore_result=True,  # results live in the job store, not in a Celery backend
        task_acks_late=True,  # a task lost with its worker is delivered again
        task_reject_on_worker_lost=True,
        worker_prefetch_multiplier=1,  # long tasks: never hoard work another worker could do
        broker_connection_retry_on_startup=True,
        worker_hijack_root_logger=False,
        broker_transport_options={"visibility_timeout": 3600},
    )
    return app


celery_app = make_celery()

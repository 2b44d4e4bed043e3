"""The Celery application: Redis as broker, JSON only, acknowledgement after the work is done."""

from __future__ import annotations

import os

from celery import Celery
from celery.signals import worker_process_init, worker_ready, worker_shutdown

from geocert.settings import get_settings
from geocert.workers.redis_server import broker_url


def redis_url() -> str:
    url = get_settings().redis_url or os.environ.get("GEOCERT_REDIS_URL")
    if not url:
        raise RuntimeError("GEOCERT_REDIS_URL is not set (geocert serve sets it for its embedded Redis)")
    return url


def make_celery() -> Celery:
    settings = get_settings()
    app = Celery("geocert", broker=broker_url(redis_url()), include=["geocert.workers.tasks", "geocert.workers.webhooks"])
    app.conf.update(
        task_serializer="json",
        accept_content=["json"],
        task_ignore_result=True,  # results live in the job store, not in a Celery backend
        task_acks_late=True,  # a task lost with its worker is delivered again
        task_reject_on_worker_lost=True,
        worker_prefetch_multiplier=1,  # never hoard work another worker could do
        broker_connection_retry_on_startup=True,
        worker_hijack_root_logger=False,
        worker_redirect_stdouts=False,  # our JSON lines go straight to standard error
        # Each live worker renews the delivery time of every task it holds with its heartbeat
        # (workers.heartbeat), so a task is delivered again only when its worker is gone; the
        # restore sweep runs every 5 s, so that happens within visibility_timeout_s + 5 s of the
        # worker's last beat.
        broker_transport_options={"visibility_timeout": settings.visibility_timeout_s,
                                  "unacked_restore_interval": 5, "unacked_restore_throttle": 1},
        # No global time limits: each solve task carries its own, sized from its job's limits
        # (queue.task_options); one killed at its hard limit is acknowledged, not delivered again.
        task_acks_on_failure_or_timeout=True,
    )
    return app


celery_app = make_celery()


@worker_process_init.connect
def _json_logs(**_) -> None:
    from geocert.workers import logs

    logs.configure()


_HEARTBEAT = None


@worker_ready.connect
def _start_heartbeat(sender=None, **_) -> None:
    """From the moment the worker takes tasks, it beats (``workers.heartbeat``; read by /readyz)."""
    global _HEARTBEAT
    from geocert.workers.heartbeat import Heartbeat

    from geocert.workers.reaper import reap
    from geocert.workers.store import JobStore

    name = getattr(sender, "hostname", None) or "geocert@unknown"
    settings = get_settings()
    jobs = JobStore.from_url(redis_url(), settings.result_ttl_s, socket_timeout=10, socket_connect_timeout=5)
    every_s = 5.0
    _HEARTBEAT = Heartbeat(redis_url(), name, reaper=lambda: reap(jobs, settings.visibility_timeout_s, every_s),
                           reap_every_s=every_s).start()


@worker_shutdown.connect
def _stop_heartbeat(**_) -> None:
    if _HEARTBEAT is not None:
        _HEARTBEAT.stop()

"""The Celery application: Redis as broker, JSON only, acknowledgement after the work is done.

A leaf: it imports none of the tasks, nor the worker's signal handlers (workers.signals), which
Celery imports with the tasks (``include``) in a worker only; the API names tasks through it."""

from __future__ import annotations


from celery import Celery

from geocert.settings import get_settings, redis_url
from geocert.workers.redis_server import broker_url


SOLVE_QUEUE = "celery"  # Celery's default queue: the solve tasks
WEBHOOK_QUEUE = "webhooks"


def make_celery() -> Celery:
    settings = get_settings()
    app = Celery("geocert", broker=broker_url(redis_url()), include=["geocert.workers.tasks", "geocert.workers.webhooks", "geocert.workers.signals"])
    app.conf.update(
        task_serializer="json",
        accept_content=["json"],
        task_ignore_result=True,  # results live in the job store, not in a Celery backend
        task_acks_late=True,  # a task lost with its worker is delivered again
        # ... but not one whose solver process died under it while the worker lived (out of memory,
        # a crash): run again, it would die again (a photo bomb was delivered four times, holding a
        # worker 440 s). It is acknowledged, and its errback fails its job with the reason.
        task_reject_on_worker_lost=False,
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
        # Webhook deliveries wait on other machines: a queue and workers of their own (geocert
        # worker and geocert serve start them), so that a slow receiver never holds a solver.
        task_routes={"geocert.deliver_webhook": {"queue": WEBHOOK_QUEUE},
                     "geocert.deliver_webhook_failed": {"queue": WEBHOOK_QUEUE}},
    )
    return app


celery_app = make_celery()

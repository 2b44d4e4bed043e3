"""The Celery application: Redis as broker, JSON only, acknowledgement after the work is done."""

from __future__ import annotations


from celery import Celery
from celery.signals import worker_process_init, worker_ready, worker_shutdown

from geocert.settings import get_settings, redis_url
from geocert.workers.redis_server import broker_url


SOLVE_QUEUE = "celery"  # Celery's default queue: the solve tasks
WEBHOOK_QUEUE = "webhooks"


def make_celery() -> Celery:
    settings = get_settings()
    app = Celery("geocert", broker=broker_url(redis_url()), include=["geocert.workers.tasks", "geocert.workers.webhooks"])
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


@worker_process_init.connect
def _json_logs(**_) -> None:
    from geocert.workers import logs

    logs.configure()
    limit_memory(get_settings().worker_memory_mb)


def limit_memory(megabytes: int) -> None:
    """Bound this solver process's address space (GEOCERT_WORKER_MEMORY_MB; 0: unbounded): an
    allocation past it fails (MemoryError, or OpenCV's "Insufficient memory") in the task that made
    it, whose job then fails with the reason (workers.tasks), instead of the kernel killing a
    process (or the machine swapping) for one client's job."""
    import resource

    if megabytes > 0:
        limit = megabytes << 20
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        resource.setrlimit(resource.RLIMIT_AS, (limit if hard == resource.RLIM_INFINITY else min(limit, hard), hard))


_HEARTBEAT = None


@worker_ready.connect
def _start_heartbeat(sender=None, **_) -> None:
    """From the moment the worker takes tasks, it beats (``workers.heartbeat``; read by /readyz)."""
    global _HEARTBEAT
    from geocert.workers.heartbeat import Heartbeat

    from geocert.workers.reaper import reap
    from geocert.jobs.store import JobStore
    from geocert.workers.tasks import end_jobs_past_clock

    name = getattr(sender, "hostname", None) or "geocert@unknown"
    settings = get_settings()
    if SOLVE_QUEUE not in sender.app.amqp.queues.consume_from:  # a webhook worker: it renews its leases only
        _HEARTBEAT = Heartbeat(redis_url(), name, solvers=None).start()
        return
    jobs = JobStore.from_url(redis_url(), settings.result_ttl_s, socket_timeout=10, socket_connect_timeout=5)
    every_s = 5.0
    solvers = getattr(getattr(sender, "controller", None), "concurrency", None) or 1
    _HEARTBEAT = Heartbeat(redis_url(), name, reaper=lambda: reap(jobs, settings.visibility_timeout_s, every_s),
                           reap_every_s=every_s, solvers=solvers, clock=lambda: end_jobs_past_clock(jobs)).start()


@worker_shutdown.connect
def _stop_heartbeat(**_) -> None:
    if _HEARTBEAT is not None:
        _HEARTBEAT.stop()

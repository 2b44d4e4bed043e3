"""What follows a job's end, wherever it ended (a worker's task, or the API withdrawing a queued
job): the job counted in the metrics, and its webhook queued. The webhook task is named, not
imported, so that the API process imports no task code (the workers have it)."""

from __future__ import annotations

import logging

from geocert.jobs.store import JobStore

log = logging.getLogger("geocert.worker")

DELIVER_WEBHOOK = "geocert.deliver_webhook"
DELIVER_WEBHOOK_FAILED = "geocert.deliver_webhook_failed"


def after_end(jobs: JobStore, job_id: str) -> None:
    """After a job has ended (``JobStore.end`` or ``cancel_if_queued``): count it, and queue its
    webhook if it has one."""
    meta = jobs.get(job_id)
    if meta is None:
        return
    jobs.record_job_end(meta)
    log.info("job ended %s", meta["status"])
    if meta.get("webhook"):
        queue_delivery(job_id)


def queue_delivery(job_id: str) -> None:
    """Queue a job's webhook on the webhook queue (celery_app's routes), with its errback."""
    from geocert.workers.celery_app import celery_app

    celery_app.send_task(DELIVER_WEBHOOK, (job_id,), link_error=celery_app.signature(DELIVER_WEBHOOK_FAILED),
                         ignore_result=True)

"""Webhooks: the terminal job document POSTed to the job's ``callback_url``, signed.

Signature: ``X-Geocert-Signature: t=<unix seconds>,v1=<hex HMAC-SHA256 of "<t>.<body>">`` keyed
by GEOCERT_WEBHOOK_SECRET (or the secret kept in Redis, printed by ``geocert webhook-secret``).

Deliveries have a queue and worker processes of their own (``WEBHOOK_QUEUE``: a slow receiver
never holds a solver). A delivery goes only to a public address, checked on the address connected
to (``workers.destinations``), unless the operator allows networks; each attempt ends within
GEOCERT_WEBHOOK_TIMEOUT_S in all. Failed attempts are retried by Celery with doubling delays;
every attempt's outcome is written on the job (``webhook``: state, attempts, last_error), so a
delivery that never succeeds is visible there as ``failed``, one to a destination not allowed as
``refused`` (not retried), never lost silently. The record says only that: not how the
destination failed (a closed port, a timeout, an HTTP status), which would make the service a
port scanner's oracle; the worker's log has the detail.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import time

import httpcore

from geocert.settings import get_settings
from geocert.jobs.destinations import CheckedBackend, Refused, allowed_networks
from geocert import logs
from geocert.workers.celery_app import celery_app
from geocert.workers.endings import DELIVER_WEBHOOK, DELIVER_WEBHOOK_FAILED
from geocert.jobs.store import shared_store as store

log = logging.getLogger("geocert.webhooks")


def webhook_secret(jobs) -> str:
    """GEOCERT_WEBHOOK_SECRET, or the secret kept in Redis (``JobStore.webhook_secret``, made once)."""
    configured = get_settings().webhook_secret
    if configured:
        return configured
    return jobs.webhook_secret()


def sign(secret: str, timestamp: str, body: bytes) -> str:
    return hmac.new(secret.encode(), timestamp.encode() + b"." + body, hashlib.sha256).hexdigest()


FINAL = ("delivered", "failed", "refused")


def post(url: str, body: bytes, headers: dict[str, str]) -> tuple[str, str | None]:
    """One attempt: ("delivered", None), ("refused", why) or ("failed", why), the reasons as the
    record shows them. The whole exchange ends within GEOCERT_WEBHOOK_TIMEOUT_S; the receiver's
    answer is not read beyond its status."""
    settings = get_settings()
    allowed = allowed_networks(settings.webhook_allowed_networks)
    limit = settings.webhook_timeout_s
    backend = CheckedBackend(time.monotonic() + limit, allowed)
    try:
        with httpcore.ConnectionPool(network_backend=backend, max_connections=1) as pool:
            with pool.stream("POST", url, headers=list(headers.items()), content=body,
                             extensions={"timeout": {"connect": limit, "read": limit, "write": limit, "pool": limit}}
                             ) as response:
                status = response.status
    except Refused as exc:
        log.warning("webhook refused: %s", exc)
        return "refused", ("refused: the destination is not a public address (loopback, private, link-local, "
                           "multicast and reserved addresses are refused unless the operator allows their network: "
                           "GEOCERT_WEBHOOK_ALLOWED_NETWORKS); nothing was sent")
    except (httpcore.TimeoutException, httpcore.NetworkError, httpcore.ProtocolError, httpcore.UnsupportedProtocol,
            OSError) as exc:
        log.warning("webhook attempt failed: %s: %s", type(exc).__name__, exc)
        return "failed", f"failed: no 2xx answer within {limit:g} s"
    if 200 <= status < 300:
        return "delivered", None
    log.warning("webhook attempt failed: the receiver answered HTTP %d", status)
    return "failed", f"failed: no 2xx answer within {limit:g} s"


@celery_app.task(name=DELIVER_WEBHOOK, bind=True, max_retries=None,
                 soft_time_limit=get_settings().webhook_timeout_s + 20, time_limit=get_settings().webhook_timeout_s + 30)
def deliver_webhook(self, job_id: str, deferrals: int = 0) -> None:
    with logs.context(job_id=job_id):
        jobs = store()
        meta = jobs.get(job_id)
        if meta is None or not meta.get("webhook") or meta["webhook"]["state"] in FINAL:
            return
        settings = get_settings()
        share = settings.webhook_deliveries_per_key if settings.api_keys else 0
        place = self.request.id
        if share > 0 and not jobs.take_delivery(meta["owner"], place, share, settings.webhook_timeout_s + 60):
            # Its key's deliveries hold their share of the webhook threads: later, not an attempt.
            raise self.retry(args=(job_id,), kwargs={"deferrals": deferrals + 1},
                             countdown=min(5.0, 0.25 * 2 ** deferrals))
        try:
            _attempt(self, jobs, meta, settings)
        finally:
            if share > 0:
                jobs.free_delivery(meta["owner"], place)


def _attempt(task, jobs, meta: dict, settings) -> None:
    """One delivery attempt of the job ``meta``, written on its record; a retry scheduled after a
    failed attempt but the last."""
    job_id = meta["id"]
    hook = meta["webhook"]
    body = json.dumps(jobs.document(meta), separators=(",", ":")).encode()
    timestamp = str(int(time.time()))
    attempt = hook["attempts"] + 1
    headers = {"Content-Type": "application/json", "User-Agent": "geocert-webhook",
               "X-Geocert-Job": job_id, "X-Geocert-Attempt": str(attempt),
               "X-Geocert-Signature": f"t={timestamp},v1={sign(webhook_secret(jobs), timestamp, body)}"}
    outcome, error = post(hook["url"], body, headers)
    hook.update(attempts=attempt, last_error=error, last_attempt_at=time.time())
    if outcome == "delivered":
        hook.update(state="delivered", delivered_at=time.time())
    elif outcome == "refused" or attempt >= settings.webhook_attempts:
        hook["state"] = outcome
    else:
        hook["state"] = "retrying"
    if not jobs.set_fields(job_id, webhook=hook):
        return  # the job was deleted meanwhile: nothing of it is written again
    jobs.record_webhook(hook["state"])
    log.info("webhook attempt %d: %s", attempt, error or "delivered")
    if hook["state"] == "retrying":
        raise task.retry(args=(job_id,), kwargs={}, countdown=settings.webhook_backoff_s * 2 ** (attempt - 1))


@celery_app.task(name=DELIVER_WEBHOOK_FAILED)
def deliver_webhook_failed(request, exc, traceback) -> None:
    """Errback of a delivery that ended outside its own handling (killed at its time limit): the
    record says ``failed``, never stays ``waiting`` for ever."""
    job_id = request.args[0]
    jobs = store()
    hook = jobs.field(job_id, "webhook")
    if hook and hook["state"] not in FINAL:
        hook.update(state="failed", attempts=hook["attempts"] + 1, last_attempt_at=time.time(),
                    last_error="failed: the attempt did not end within its time limit")
        if jobs.set_fields(job_id, webhook=hook):
            jobs.record_webhook("failed")

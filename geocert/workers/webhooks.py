"""Webhooks: the terminal job document POSTed to the job's ``callback_url``, signed.

Signature: ``X-Geocert-Signature: t=<unix seconds>,v1=<hex HMAC-SHA256 of "<t>.<body>">`` keyed
by GEOCERT_WEBHOOK_SECRET (or the secret kept in Redis, printed by ``geocert webhook-secret``).
Failed attempts are retried by Celery with doubling delays; every attempt's outcome is written
on the job (``webhook``: state, attempts, last_error), so a delivery that never succeeds is
visible there as ``failed``, never lost silently.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import secrets
import time

import httpx

from geocert.settings import get_settings
from geocert.workers import logs, metrics
from geocert.workers.celery_app import celery_app
from geocert.workers.store import shared_store as store

log = logging.getLogger("geocert.webhooks")
_SECRET_KEY = "geocert:webhook_secret"


def webhook_secret(client) -> str:
    configured = get_settings().webhook_secret
    if configured:
        return configured
    client.set(_SECRET_KEY, secrets.token_hex(32), nx=True)
    return client.get(_SECRET_KEY)


def sign(secret: str, timestamp: str, body: bytes) -> str:
    return hmac.new(secret.encode(), timestamp.encode() + b"." + body, hashlib.sha256).hexdigest()


@celery_app.task(name="geocert.deliver_webhook", bind=True, max_retries=None)
def deliver_webhook(self, job_id: str) -> None:
    with logs.context(job_id=job_id):
        jobs = store()
        meta = jobs.get(job_id)
        if meta is None or not meta.get("webhook") or meta["webhook"]["state"] in ("delivered", "failed"):
            return
        settings = get_settings()
        hook = meta["webhook"]
        body = json.dumps(jobs.document(meta), separators=(",", ":")).encode()
        timestamp = str(int(time.time()))
        attempt = hook["attempts"] + 1
        headers = {"Content-Type": "application/json", "User-Agent": "geocert-webhook",
                   "X-Geocert-Job": job_id, "X-Geocert-Attempt": str(attempt),
                   "X-Geocert-Signature": f"t={timestamp},v1={sign(webhook_secret(jobs.r), timestamp, body)}"}
        try:
            response = httpx.post(hook["url"], content=body, headers=headers, timeout=settings.webhook_timeout_s)
            error = None if 200 <= response.status_code < 300 else f"the receiver answered HTTP {response.status_code}"
        except httpx.HTTPError as exc:
            error = f"{type(exc).__name__}: {exc}"
        hook.update(attempts=attempt, last_error=error, last_attempt_at=time.time())
        if error is None:
            hook.update(state="delivered", delivered_at=time.time())
        elif attempt >= settings.webhook_attempts:
            hook["state"] = "failed"
        else:
            hook["state"] = "retrying"
        jobs.set_fields(job_id, webhook=hook)
        metrics.record_webhook(jobs.r, hook["state"])
        log.info("webhook attempt %d: %s", attempt, error or "delivered")
        if hook["state"] == "retrying":
            raise self.retry(countdown=settings.webhook_backoff_s * 2 ** (attempt - 1))

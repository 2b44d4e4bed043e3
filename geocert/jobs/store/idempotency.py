"""Idempotency keys: a key reserved for a body, then settled with the job made for it (or freed)."""

from __future__ import annotations

import hashlib
import json

import redis.asyncio

from geocert.jobs.store.base import StoreBase, dumps


class Idempotency(StoreBase):
    def _idempotency_key(self, owner: str, idempotency_key: str) -> str:
        return self.owner_key(owner, f"idempotency:{hashlib.sha256(idempotency_key.encode()).hexdigest()}")

    def remember_idempotent(self, owner: str, idempotency_key: str, body_digest: str) -> dict | None:
        """Reserve ``idempotency_key`` for a body; returns None when newly reserved, else what
        was stored before: ``{"body": digest, "job": id or None while being created}``."""
        key = self._idempotency_key(owner, idempotency_key)
        entry = dumps({"body": body_digest, "job": None})
        if self.r.set(key, entry, nx=True, ex=self.ttl):
            return None
        raw = self.r.get(key)
        return json.loads(raw) if raw else None

    async def remember_idempotent_async(self, client: redis.asyncio.Redis, owner: str, idempotency_key: str,
                                        body_digest: str) -> dict | None:
        """``remember_idempotent`` through an asyncio client."""
        key = self._idempotency_key(owner, idempotency_key)
        entry = dumps({"body": body_digest, "job": None})
        if await client.set(key, entry, nx=True, ex=self.ttl):
            return None
        raw = await client.get(key)
        return json.loads(raw) if raw else None

    def settle_idempotent(self, owner: str, idempotency_key: str, body_digest: str, job_id: str | None) -> None:
        """Record the job made for a reserved key (or, with None, free the key: creation failed)."""
        key = self._idempotency_key(owner, idempotency_key)
        if job_id is None:
            self.r.delete(key)
        else:
            self.r.set(key, dumps({"body": body_digest, "job": job_id}), ex=self.ttl)

    async def settle_idempotent_async(self, client: redis.asyncio.Redis, owner: str, idempotency_key: str,
                                      body_digest: str, job_id: str | None) -> None:
        """``settle_idempotent`` through an asyncio client."""
        key = self._idempotency_key(owner, idempotency_key)
        if job_id is None:
            await client.delete(key)
        else:
            await client.set(key, dumps({"body": body_digest, "job": job_id}), ex=self.ttl)

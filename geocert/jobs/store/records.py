"""A job's record (the hash ``geocert:job:{id}``): read whole or by field, written while it
exists, shown as the API shows it; and the ids of its tasks."""

from __future__ import annotations

import json
from typing import Any

import redis.asyncio

from geocert.jobs.store.base import TERMINAL, StoreBase, dumps


class Records(StoreBase):
    """``document`` reads the result (``results``)."""

    def get(self, job_id: str) -> dict | None:
        raw = self.r.hgetall(self.key(job_id))
        if not raw:
            return None
        return {k: json.loads(v) for k, v in raw.items()}

    def field(self, job_id: str, name: str) -> Any:
        raw = self.r.hget(self.key(job_id), name)
        return None if raw is None else json.loads(raw)

    _SET_IF_EXISTS = """
    if redis.call('EXISTS', KEYS[1]) == 0 then return 0 end
    redis.call('HSET', KEYS[1], unpack(ARGV))
    return 1
    """

    def set_fields(self, job_id: str, **fields: Any) -> bool:
        """Set fields of an existing job (False: it is gone, e.g. deleted while a webhook was being
        delivered, and nothing is written: an HSET would re-create it without an expiry)."""
        pairs = [part for name, value in fields.items() for part in (name, dumps(value))]
        return bool(self.r.eval(self._SET_IF_EXISTS, 1, self.key(job_id), *pairs))

    _SUMMARY = ("id", "kind", "status", "created_at", "started_at", "finished_at", "progress")

    def summary(self, meta: dict) -> dict:
        """The job as a listing shows it: its state and progress, no result."""
        return {key: meta.get(key) for key in self._SUMMARY} | {"links": self.links(meta["id"])}

    def head(self, meta: dict) -> dict:
        """The job as the API shows it without its result and links."""
        return {key: meta.get(key) for key in self._SUMMARY + ("error", "webhook")}

    def document(self, meta: dict) -> dict:
        """The job as the API shows it (and as webhooks deliver it)."""
        document = self.head(meta)
        document["result"] = self.result(meta["id"], meta) if meta["status"] in TERMINAL else None
        document["links"] = self.links(meta["id"])
        return document

    @staticmethod
    def links(job_id: str) -> dict:
        base = f"/v1/jobs/{job_id}"
        return {"self": base, "events": f"{base}/events", "cancel": f"{base}/cancel"}

    # The list lives as long as its job: not written for a job that is gone, and given the job's
    # expiry when the job has one (it has ended).
    _ADD_TASK_IDS = """
    local ttl = redis.call('TTL', KEYS[1])
    if ttl == -2 then return 0 end
    redis.call('RPUSH', KEYS[2], unpack(ARGV))
    if ttl > 0 then redis.call('EXPIRE', KEYS[2], ttl) end
    return 1
    """

    def add_task_ids(self, job_id: str, *task_ids: str) -> None:
        if task_ids:
            self.r.eval(self._ADD_TASK_IDS, 2, self.key(job_id), self.key(job_id, "tasks"), *task_ids)

    def task_ids(self, job_id: str) -> list[str]:
        return self.r.lrange(self.key(job_id, "tasks"), 0, -1)

    def fields(self, job_id: str, *names: str) -> dict | None:
        """Some fields of the job (None when there is no such job): a task reads these, not the
        whole record (whose chunk list grows with the job)."""
        raw = self.r.hmget(self.key(job_id), "status", *names)
        return None if raw[0] is None else self._decoded(("status",) + names, raw)

    @staticmethod
    def _decoded(names, raw) -> dict:
        return {name: None if value is None else json.loads(value) for name, value in zip(names, raw)}


async def read_job(client: redis.asyncio.Redis, job_id: str) -> dict | None:
    """``JobStore.get`` from an asyncio client (``decode_responses``): the API's reads on the loop."""
    raw = await client.hgetall(StoreBase.key(job_id))
    return {k: json.loads(v) for k, v in raw.items()} if raw else None

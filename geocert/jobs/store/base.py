"""The job store's shared ground: the Redis client (text and binary), the key scheme every
concern writes under, and the constants and encoder they share.

Every key of a job starts with ``geocert:job:{id}`` (``StoreBase.key``) and expires
``result_ttl_s`` after the job ends; an owner's keys start with ``geocert:owner:{owner}``
(``StoreBase.owner_key``); the few service-wide sets (running jobs, deadlines, solver slots) are
named here too.
"""

from __future__ import annotations

import json
import time
from typing import Any, Callable

import redis

TERMINAL = ("succeeded", "failed", "cancelled")
PUBLIC_OWNER = "public"  # the owner of every job when no API keys are configured (loopback only)
# Redis restarting, loading its append-only file or unreachable (BusyLoadingError is a ConnectionError).
REDIS_GONE = (redis.exceptions.ConnectionError, redis.exceptions.TimeoutError)
# The workers' heartbeats (workers.heartbeat writes them; take_slot reads which workers live and
# their solver processes): here, below the workers, so that the store needs nothing of theirs.
WORKERS_KEY = "geocert:workers"  # worker name -> its last beat
SOLVERS_KEY = "geocert:workers:solvers"  # worker name -> its solver processes
FRESH_S = 10.0  # a worker whose last beat is older is gone
PAST_CLOCK_CLAIM_S = 300  # how long a claim to end a job past its clock holds (JobStore.claim_past_clock)
STREAM_MAXLEN = 2000  # a job's event stream keeps about its last this many events


def now() -> float:
    return time.time()


def _shared_encoder() -> Callable[[Any], str]:
    """json.dumps with its default arguments, its text to the byte, made by one C encoder shared
    by every call: json.dumps makes a new one each call, which cost more than encoding a small
    value (a track's 16 us against 11; None's 5 us against 1). No circular check: what is stored
    was read from JSON or built of JSON types."""
    from json import encoder

    if encoder.c_make_encoder is None:  # an interpreter without the C accelerator
        return json.dumps
    make = encoder.c_make_encoder(None, encoder.JSONEncoder().default, encoder.encode_basestring_ascii, None, ": ",
                                  ", ", False, False, True)
    return lambda value: "".join(make(value, 0))


dumps = _shared_encoder()


class StoredBytesExceeded(Exception):
    """The owner's jobs that exist would hold more than their limit with this one."""

    def __init__(self, limit: int):
        super().__init__(limit)
        self.limit = limit


class ResultGone(LookupError):
    """The job's result expired (or was deleted) while it was being read: the job is gone."""


class StoreBase:
    """The client, the expiry and the key scheme that every concern of the store shares."""

    def __init__(self, client: redis.Redis, result_ttl_s: int = 7 * 24 * 3600):
        self.r = client
        self.ttl = result_ttl_s
        # The same server without decoding, for the values kept compressed (results).
        pool = client.connection_pool
        self.binary = redis.Redis(connection_pool=redis.ConnectionPool(
            connection_class=pool.connection_class, **{**pool.connection_kwargs, "decode_responses": False}))

    @classmethod
    def from_url(cls, url: str, result_ttl_s: int = 7 * 24 * 3600, **options: Any) -> "StoreBase":
        return cls(redis.Redis.from_url(url, decode_responses=True, **options), result_ttl_s)

    @staticmethod
    def key(job_id: str, part: str = "") -> str:
        return f"geocert:job:{job_id}" + (f":{part}" if part else "")

    @staticmethod
    def owner_key(owner: str, part: str) -> str:
        return f"geocert:owner:{owner}:{part}"

    # Every key of a job (deleted together, and expiring together once it ends).
    _PARTS = ("", "request", "request:items", "result", "events", "cancel", "final", "items", "chunkprogress",
              "progressparts", "gaps", "tasks", "fragments", "fragmentsums", "busy")

    RUNNING = "geocert:running"  # running job id -> the last time a task of it showed life
    DEADLINES = "geocert:deadlines"  # running job id -> when its clock in all (job_time_limit_s) runs out
    # Solver slots (``slots.Slots``): task id -> its last sign of life, and task id -> its job's owner.
    SLOTS = "geocert:slots"
    SLOT_OWNERS = "geocert:slots:owners"
    SLOT_LAPSE_S = 30.0

    def ping(self) -> bool:
        """Redis answers (raises when it does not)."""
        return bool(self.r.ping())

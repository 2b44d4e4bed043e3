"""Solver slots (how many solve tasks of one key's jobs run at once), webhook deliveries in flight
per key and the key that signs them, and the live workers whose heartbeats say how many solvers
there are."""

from __future__ import annotations

import math
import secrets

from geocert.jobs.store.base import FRESH_S, PUBLIC_OWNER, SOLVERS_KEY, WORKERS_KEY, StoreBase, dumps, now


class Slots(StoreBase):
    # Solver slots: the solve tasks running, each by its task id, with the last sign of its
    # life (renewed by its worker's heartbeat) and its job's owner. A key holds at most every live
    # solver process (the workers' heartbeats say how many) but ``kept_for_others``, and at
    # least one; a slot not renewed for SLOT_LAPSE_S (its worker gone) lapses. Without keys
    # (every job PUBLIC_OWNER's: one user, on loopback) there is no one to keep solvers for: a
    # short job then runs beside a long one as the solvers allow.
    _TAKE_SLOT = """
    local owner = redis.call('HGET', KEYS[5], 'owner')
    if not owner then return 1 end
    for _, id in ipairs(redis.call('ZRANGEBYSCORE', KEYS[1], '-inf', ARGV[3])) do
        redis.call('ZREM', KEYS[1], id)
        redis.call('HDEL', KEYS[2], id)
    end
    if redis.call('ZSCORE', KEYS[1], ARGV[1]) then
        redis.call('ZADD', KEYS[1], ARGV[2], ARGV[1])
        return 1
    end
    local kept = tonumber(ARGV[5])
    if kept > 0 and owner ~= ARGV[6] then
        local solvers = 0
        local names = redis.call('ZRANGEBYSCORE', KEYS[3], ARGV[4], '+inf')
        if #names > 0 then
            for _, n in ipairs(redis.call('HMGET', KEYS[4], unpack(names))) do solvers = solvers + (tonumber(n) or 0) end
        end
        if solvers > 0 then
            local held = 0
            for _, o in ipairs(redis.call('HVALS', KEYS[2])) do if o == owner then held = held + 1 end end
            if held >= math.max(1, solvers - kept) then return 0 end
        end
    end
    redis.call('ZADD', KEYS[1], ARGV[2], ARGV[1])
    redis.call('HSET', KEYS[2], ARGV[1], owner)
    return 1
    """

    def take_slot(self, job_id: str, slot: str, kept_for_others: int) -> bool:
        """Take a solver slot for a task of this job (True), unless the job's key holds its share
        already (False: the task waits). A job that is gone takes one (its task finds it gone)."""
        moment = now()
        return bool(self.r.eval(self._TAKE_SLOT, 5, self.SLOTS, self.SLOT_OWNERS, WORKERS_KEY, SOLVERS_KEY, self.key(job_id),
                                slot, moment, moment - self.SLOT_LAPSE_S, moment - FRESH_S, kept_for_others,
                                dumps(PUBLIC_OWNER)))

    def free_slot(self, slot: str) -> None:
        pipe = self.r.pipeline()
        pipe.zrem(self.SLOTS, slot)
        pipe.hdel(self.SLOT_OWNERS, slot)
        pipe.execute()

    # Webhook deliveries in flight, per API key: a sorted set per key (its deliveries' task ids,
    # scored by when each was taken). An entry older than ARGV[3] (its webhook worker gone) lapses,
    # and so does the whole set when no delivery takes a place in it (EXPIRE).
    _TAKE_DELIVERY = """
    redis.call('ZREMRANGEBYSCORE', KEYS[1], '-inf', ARGV[3])
    if not redis.call('ZSCORE', KEYS[1], ARGV[1]) and redis.call('ZCARD', KEYS[1]) >= tonumber(ARGV[4]) then
      return 0
    end
    redis.call('ZADD', KEYS[1], ARGV[2], ARGV[1])
    redis.call('EXPIRE', KEYS[1], ARGV[5])
    return 1
    """

    def take_delivery(self, owner: str, delivery: str, share: int, lapse_s: float) -> bool:
        """Take one of ``owner``'s ``share`` places for a webhook delivery (True), unless its
        deliveries hold them all; one not freed lapses after ``lapse_s``."""
        moment = now()
        return bool(self.r.eval(self._TAKE_DELIVERY, 1, self.owner_key(owner, "deliveries"), delivery, moment,
                                moment - lapse_s, share, max(1, math.ceil(lapse_s))))

    def free_delivery(self, owner: str, delivery: str) -> None:
        self.r.zrem(self.owner_key(owner, "deliveries"), delivery)

    def live_workers(self) -> int:
        """How many workers beat within the last ``FRESH_S`` seconds (one Redis command; the
        workers write their beats: ``workers.heartbeat``)."""
        return int(self.r.zcount(WORKERS_KEY, now() - FRESH_S, "+inf"))

    WEBHOOK_SECRET = "geocert:webhook_secret"

    def webhook_secret(self) -> str:
        """The key signing webhooks when none is configured: made at random by the first caller
        (SET NX), the same for every worker after."""
        self.r.set(self.WEBHOOK_SECRET, secrets.token_hex(32), nx=True)
        return self.r.get(self.WEBHOOK_SECRET)

"""An owner's jobs: its index (listed newest first), the bytes its jobs hold, its active jobs, and
its requests per minute."""

from __future__ import annotations

import json

import redis.asyncio

from geocert.jobs.store.base import StoreBase, now


class Accounts(StoreBase):
    # --- listing -----------------------------------------------------------------------------
    def list_jobs(self, owner: str, limit: int, after: tuple[float, str] | None = None,
                  statuses: tuple[str, ...] | None = None) -> tuple[list[dict], tuple[float, str] | None]:
        """The owner's jobs, newest first: up to ``limit`` after the position ``after`` (the
        created time and id of the last job of the previous page), only those whose status is in
        ``statuses`` when given. Returns the jobs and the position to continue after (None when
        no job follows). The index is a sorted set per owner (created time -> id), written on
        create and delete; ids whose job expired are dropped from it here, when met."""
        index = self.owner_key(owner, "jobs")
        top = "+inf" if after is None else repr(after[0])
        found: list[tuple[float, str, dict]] = []
        gone: list[str] = []
        offset, batch = 0, max(2 * limit + 2, 50)
        while len(found) <= limit:
            entries = self.r.zrevrangebyscore(index, top, "-inf", start=offset, num=batch, withscores=True)
            if not entries:
                break
            offset += len(entries)
            pipe = self.r.pipeline()
            for job_id, _ in entries:
                pipe.hgetall(self.key(job_id))
            for (job_id, score), raw in zip(entries, pipe.execute()):
                # Equal times are ordered by id, descending: skip up to and including ``after``.
                if after is not None and score == after[0] and job_id >= after[1]:
                    continue
                if not raw:
                    gone.append(job_id)
                    continue
                meta = {k: json.loads(v) for k, v in raw.items()}
                if statuses and meta["status"] not in statuses:
                    continue
                found.append((score, job_id, meta))
                if len(found) > limit:
                    break
        if gone:
            pipe = self.r.pipeline()
            for job_id in gone:
                pipe.eval(self._FORGET, 3, *self._accounts(owner), job_id)
            pipe.execute()
        following = (found[limit - 1][0], found[limit - 1][1]) if len(found) > limit else None
        return [meta for _, _, meta in found[:limit]], following

    # An owner's accounts of its jobs that exist: the index (created time -> id), each job's
    # bytes, and their sum. A job leaves them when deleted, when a listing meets it expired, and
    # when a submission of its owner finds it expired among the index's ARGV[2] oldest entries
    # (_CREATE: so a key that never lists keeps about its jobs that exist, not every job it made).
    def _accounts(self, owner: str) -> tuple[str, str, str]:
        return self.owner_key(owner, "jobs"), self.owner_key(owner, "stored"), self.owner_key(owner, "stored_bytes")

    PRUNED_PER_JOB = 8
    STORED_BYTES_FLOOR = 16 << 10  # a job's record and events (its result is counted when it ends)
    _FORGET_LUA = """
    local function forget(id)
      local bytes = redis.call('HGET', KEYS[2], id)
      redis.call('ZREM', KEYS[1], id)
      if bytes then
        redis.call('HDEL', KEYS[2], id)
        redis.call('DECRBY', KEYS[3], bytes)
      end
    end
    """
    _FORGET = _FORGET_LUA + "forget(ARGV[1])"

    # A job that ends adds what its result holds (the stored result, and the fragments a streamed
    # result is kept as) to its bytes in its owner's accounts, when it is still counted there (not
    # deleted meanwhile): a result is about 3 times its request compressed (a track's 12 times
    # uncompressed), so a key counted by its requests alone kept several times its limit.
    _COUNT_RESULT = """
    if redis.call('HEXISTS', KEYS[3], ARGV[1]) == 0 then return 0 end
    local bytes = redis.call('STRLEN', KEYS[1])
    for _, start in ipairs(redis.call('HKEYS', KEYS[2])) do bytes = bytes + redis.call('HSTRLEN', KEYS[2], start) end
    redis.call('HINCRBY', KEYS[3], ARGV[1], bytes)
    redis.call('INCRBY', KEYS[4], bytes)
    return bytes
    """

    def release(self, owner: str, job_id: str) -> None:
        self.r.srem(self.owner_key(owner, "active"), job_id)


async def count_request(client: redis.asyncio.Redis, owner: str, window_s: int = 60) -> tuple[int, int]:
    """Requests by ``owner`` in the current fixed window, and the seconds until it ends."""
    window = int(now() // window_s)
    key = StoreBase.owner_key(owner, f"rate:{window}")
    async with client.pipeline(transaction=False) as pipe:
        pipe.incr(key)
        pipe.expire(key, 2 * window_s)
        count = (await pipe.execute())[0]
    return count, int((window + 1) * window_s - now()) + 1

"""A job's state machine: queued -> running -> succeeded, failed or cancelled. A task starts it
(``mark_running``, ``start_chunk``) and leaves it; one caller claims its end and ends it; a queued
job is cancelled at once, a running one asked to stop; a job is deleted whole."""

from __future__ import annotations

import zlib

from geocert.jobs.store.base import STREAM_MAXLEN
from geocert.jobs.store.base import StoreBase, dumps, now


class Lifecycle(StoreBase):
    """Uses the record (``records``), the request's chunk (``requests``), events (``events``) and
    the owner's accounts (``accounts``)."""

    # --- cancellation ------------------------------------------------------------------------
    def request_cancel(self, job_id: str) -> None:
        self.r.set(self.key(job_id, "cancel"), "1", ex=self.ttl)

    def cancel_if_queued(self, job_id: str) -> bool:
        """Queued -> cancelled atomically (so a worker cannot start it meanwhile); True if done.
        The one way a job ends other than ``end``: nothing of it ran, so there is nothing to store."""
        script = """
        if redis.call('HGET', KEYS[1], 'status') ~= '"queued"' then return 0 end
        redis.call('HSET', KEYS[1], 'status', '"cancelled"', 'finished_at', ARGV[1])
        redis.call('XADD', KEYS[2], 'MAXLEN', '~', ARGV[2], '*', 'event', 'end', 'data', ARGV[3])
        for i = 3, #KEYS do redis.call('EXPIRE', KEYS[i], ARGV[4]) end
        return 1
        """
        keys = [self.key(job_id), self.key(job_id, "events"), *(self.key(job_id, part) for part in self._PARTS)]
        if self.r.eval(script, len(keys), *keys, dumps(now()), STREAM_MAXLEN,
                       dumps({"status": "cancelled", "error": None}), self.ttl) != 1:
            return False
        self.release(self.field(job_id, "owner") or "", job_id)
        return True

    def cancel_requested(self, job_id: str) -> bool:
        return bool(self.r.exists(self.key(job_id, "cancel")))

    # --- worker side -------------------------------------------------------------------------
    # Queued -> running once, with its status event (1); running already (2); ended or gone (0).
    # A job queued or running is touched (its task shows life: the reaper reads RUNNING), and the
    # task starting it, when named, counted among its busy ones (``claim_past_clock``). A job with
    # a clock in all (job_time_limit_s) has its deadline kept in DEADLINES from its start.
    _MARK_RUNNING = """
    local s = redis.call('HGET', KEYS[1], 'status')
    local answer = 0
    if s == '"queued"' then
        redis.call('HSET', KEYS[1], 'status', '"running"', 'started_at', ARGV[1])
        redis.call('XADD', KEYS[2], 'MAXLEN', '~', ARGV[2], '*', 'event', 'status', 'data', ARGV[3])
        local limit = tonumber(redis.call('HGET', KEYS[1], 'job_time_limit_s'))
        if limit then redis.call('ZADD', KEYS[4], tonumber(ARGV[1]) + limit, ARGV[5]) end
        answer = 1
    elseif s == '"running"' then answer = 2 end
    if answer ~= 0 then
        redis.call('ZADD', KEYS[3], ARGV[4], ARGV[5])
        if ARGV[6] ~= '' then redis.call('SADD', KEYS[5], ARGV[6]) end
    end
    return answer
    """

    def _mark_running(self, client, job_id: str, task_id: str | None = None):
        """_MARK_RUNNING run by ``client`` (its answer) or queued on a pipeline."""
        moment = now()
        return client.eval(self._MARK_RUNNING, 5, self.key(job_id), self.key(job_id, "events"), self.RUNNING,
                           self.DEADLINES, self.key(job_id, "busy"),
                           dumps(moment), STREAM_MAXLEN, dumps({"status": "running"}), moment, job_id,
                           task_id or "")

    def mark_running(self, job_id: str) -> bool:
        """Queued -> running, once; False when the job already ended (e.g. cancelled while queued)."""
        return self._mark_running(self.r, job_id) != 0

    def start_chunk(self, job_id: str, start: int, stop: int, *names: str,
                    task_id: str | None = None) -> tuple[dict, dict] | None:
        """What a task needs to start items ``start`` to ``stop - 1``, in one round trip: the job's
        fields ``names`` (as ``fields``), the job marked running (as ``mark_running``, the task
        ``task_id`` counted busy on it until it ``leave``s) and the chunk's request (as
        ``chunk_request``). None when the job is gone or has ended."""
        pipe = self.r.pipeline()
        pipe.hmget(self.key(job_id), "status", *names)
        self._mark_running(pipe, job_id, task_id)
        self._read_chunk(pipe, job_id, start, stop)
        raw, running, *chunk = pipe.execute()
        if raw[0] is None or not running or chunk[0][0] is None:
            return None
        return self._decoded(("status",) + names, raw), self._chunk(start, stop, *chunk[0])

    def leave(self, job_id: str, task_id: str, claim_past_clock: bool = False) -> bool | None:
        """The task ``task_id`` no longer works on the job (its items stored, or it stopped).
        With ``claim_past_clock``, then ``claim_past_clock`` in the same round trip (a task's
        last two calls: one wait for Redis instead of two), returning its answer."""
        if not claim_past_clock:
            self.r.srem(self.key(job_id, "busy"), task_id)
            return None
        pipe = self.r.pipeline()
        pipe.srem(self.key(job_id, "busy"), task_id)
        self._claim_past_clock(pipe, job_id)
        return bool(pipe.execute()[1])

    def reopen_end(self, job_id: str) -> None:
        """Drop a claim to end the job whose holder is gone (the job is running but nobody moves)."""
        self.r.delete(self.key(job_id, "final"))

    _CLAIM_END = """
    local status = redis.call('HGET', KEYS[1], 'status')
    if status ~= '"queued"' and status ~= '"running"' then return 0 end
    if redis.call('SET', KEYS[2], '1', 'NX', 'EX', ARGV[1]) then return 1 end
    return 0
    """

    def claim_end(self, job_id: str) -> bool:
        """Become the one caller that ends this job (``end``): the task that stored its last items,
        or one that failed; False when another already has the claim, or the job has ended or is
        gone (deleted: ending it would write it again)."""
        return bool(self.r.eval(self._CLAIM_END, 2, self.key(job_id), self.key(job_id, "final"), self.ttl))

    def end(self, job_id: str, status: str, result: dict | None = None, error: dict | None = None,
            result_text: str | None = None, fragments: tuple[str, str, list[int]] | None = None) -> None:
        """The job ends (the caller holds ``claim_end``): its status becomes ``status`` (one of
        TERMINAL) with its result or error, its working state is dropped, the end event is
        published and every key of it expires ``result_ttl_s`` from now. ``result_text``: the
        result as its kind's model writes it (``batch.result_json``), stored in place of our own
        JSON of ``result`` and marked so (``result_form``) for the API to send as it is.
        ``fragments`` (head, tail, first indices): the result is the stored fragments between
        that head and tail (batch.result_shell), kept as they are."""
        pipe = self.r.pipeline()
        if fragments is not None:
            pipe.set(self.key(job_id, "result"), zlib.compress(dumps(list(fragments)).encode()))
            pipe.hset(self.key(job_id), mapping={"result_form": dumps("model"),
                                                  "result_encoding": dumps("zlib-fragments")})
        elif result is not None:
            if result_text is not None:
                pipe.hset(self.key(job_id), "result_form", dumps("model"))
            text = result_text if result_text is not None else dumps(result)
            pipe.set(self.key(job_id, "result"), zlib.compress(text.encode(), self.RESULT_COMPRESSION_LEVEL))
            pipe.hset(self.key(job_id), "result_encoding", dumps("zlib"))
        pipe.hset(self.key(job_id), mapping={"status": dumps(status), "finished_at": dumps(now()),
                                              "error": dumps(error)})
        pipe.delete(self.key(job_id, "items"), self.key(job_id, "chunkprogress"), self.key(job_id, "progressparts"),
                    self.key(job_id, "gaps"), self.key(job_id, "fragmentsums"))
        if fragments is None:
            pipe.delete(self.key(job_id, "fragments"))
        owner = self.field(job_id, "owner") or ""
        pipe.srem(self.owner_key(owner, "active"), job_id)
        pipe.zrem(self.RUNNING, job_id)
        pipe.zrem(self.DEADLINES, job_id)
        pipe.eval(self._COUNT_RESULT, 4, self.key(job_id, "result"), self.key(job_id, "fragments"),
                  *self._accounts(owner)[1:], job_id)
        self._announce_end(job_id, status, error, pipe)
        pipe.execute()

    def _announce_end(self, job_id: str, status: str, error: dict | None, pipe) -> None:
        """Queue on ``pipe`` the end event and every key's expiry (with the end itself, in one
        transaction: a job deleted as soon as it showed as ended is never written again)."""
        self.publish(job_id, "end", {"status": status, "error": error}, pipe)
        for part in self._PARTS:
            pipe.expire(self.key(job_id, part), self.ttl)

    def delete(self, job_id: str) -> None:
        owner = self.field(job_id, "owner")
        pipe = self.r.pipeline()
        self._stage_delete(pipe, job_id, owner)
        pipe.execute()

    def _stage_delete(self, pipe, job_id: str, owner: str | None) -> None:
        pipe.delete(*(self.key(job_id, part) for part in self._PARTS))
        pipe.zrem(self.RUNNING, job_id)
        pipe.zrem(self.DEADLINES, job_id)
        if owner is not None:
            pipe.eval(self._FORGET, 3, *self._accounts(owner), job_id)

"""Clocks and reaping: the running jobs' last signs of life (read by ``workers.reaper``) and their
deadlines in all (a job past its clock is ended by whoever claims it first)."""

from __future__ import annotations

from geocert.jobs.store.base import PAST_CLOCK_CLAIM_S, StoreBase, now


class Clocks(StoreBase):
    # A job past its clock in all ends as soon as no task of it is busy (each stores the item its
    # clock stopped, with its best answer, before it leaves): the busy tasks whose solver slot
    # lapsed (their worker gone) do not count.
    _CLAIM_PAST_CLOCK = """
    if redis.call('HGET', KEYS[1], 'status') ~= '"running"' then return 0 end
    local deadline = redis.call('ZSCORE', KEYS[3], ARGV[1])
    if not deadline or tonumber(deadline) > tonumber(ARGV[2]) then return 0 end
    for _, task in ipairs(redis.call('SMEMBERS', KEYS[2])) do
        local seen = redis.call('ZSCORE', KEYS[4], task)
        if seen and tonumber(seen) >= tonumber(ARGV[3]) then return 0 end
    end
    if redis.call('SET', KEYS[5], '1', 'NX', 'EX', ARGV[4]) then return 1 end
    return 0
    """

    def claim_past_clock(self, job_id: str) -> bool:
        """``claim_end`` for a running job past its clock in all with no task of it busy (True:
        the caller ends it); False while it is within its clock, a task of it still runs, or
        another caller has the claim. The claim lapses after PAST_CLOCK_CLAIM_S: the reaper
        leaves such a job alone, so a claim whose holder died is not dropped by it, and a
        later heartbeat ends the job (an end takes seconds, 2.5 s for 20,000 items)."""
        moment = now()
        return bool(self.r.eval(self._CLAIM_PAST_CLOCK, 5, self.key(job_id), self.key(job_id, "busy"), self.DEADLINES,
                                self.SLOTS, self.key(job_id, "final"), job_id, moment, moment - self.SLOT_LAPSE_S,
                                min(self.ttl, PAST_CLOCK_CLAIM_S)))

    def past_clock(self) -> list[str]:
        """The running jobs whose clock in all has run out."""
        return self.r.zrangebyscore(self.DEADLINES, "-inf", now())

    def touch(self, job_id: str) -> None:
        """A task of this job is alive (read by the reaper, ``workers.reaper``)."""
        self.r.zadd(self.RUNNING, {job_id: now()})

    def stale_running(self, older_than_s: float) -> list[str]:
        return self.r.zrangebyscore(self.RUNNING, "-inf", now() - older_than_s)

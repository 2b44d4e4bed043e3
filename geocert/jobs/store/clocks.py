"""Clocks and reaping: the running jobs' last signs of life (read by ``workers.reaper``) and their
deadlines in all (a job past its clock is ended by whoever claims it first); the reaper's lock,
its marks on the jobs it found stranded, and its look at the broker's waiting and delivered tasks."""

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
        return bool(self._claim_past_clock(self.r, job_id))

    def _claim_past_clock(self, client, job_id: str):
        """_CLAIM_PAST_CLOCK run by ``client`` (its answer) or queued on a pipeline."""
        moment = now()
        return client.eval(self._CLAIM_PAST_CLOCK, 5, self.key(job_id), self.key(job_id, "busy"), self.DEADLINES,
                           self.SLOTS, self.key(job_id, "final"), job_id, moment, moment - self.SLOT_LAPSE_S,
                           min(self.ttl, PAST_CLOCK_CLAIM_S))

    def past_clock(self) -> list[str]:
        """The running jobs whose clock in all has run out."""
        return self.r.zrangebyscore(self.DEADLINES, "-inf", now())

    def touch(self, job_id: str) -> None:
        """A task of this job is alive (read by the reaper, ``workers.reaper``)."""
        self.r.zadd(self.RUNNING, {job_id: now()})

    def stale_running(self, older_than_s: float) -> list[str]:
        return self.r.zrangebyscore(self.RUNNING, "-inf", now() - older_than_s)

    REAPER_LOCK = "geocert:reaper"
    STRANDED = "stranded_since"  # a job's field: its last sign of life when a round first found it stranded

    def take_reaper_lock(self, every_s: float) -> bool:
        """The reaper's round is this caller's (True) for ``every_s`` (at least 1 s): one worker
        reaps at a time."""
        return bool(self.r.set(self.REAPER_LOCK, "1", nx=True, ex=max(1, int(every_s))))

    def forget_running(self, job_id: str) -> None:
        """Drop a job no longer running from the running jobs' signs of life."""
        self.r.zrem(self.RUNNING, job_id)

    def count_reap(self, job_id: str) -> int:
        """A stranded job is re-queued (or failed): its stranded mark cleared, and the rounds that
        found it so counted (the count after this one)."""
        self.r.hdel(self.key(job_id), self.STRANDED)
        return int(self.r.hincrby(self.key(job_id), "reaps", 1))

    def pending_task_messages(self, lists: list[str]) -> str:
        """Every waiting and delivered task's message, read in one transaction: kombu's restore sweep
        moves a task from its delivered hash back to a queue list atomically, and a read of the lists
        then of the hash, apart, could fall between and see it in neither."""
        pipe = self.r.pipeline(transaction=True)
        for name in lists:
            pipe.lrange(name, 0, -1)
        pipe.hvals("unacked")
        return "\n".join(task for tasks in pipe.execute() for task in tasks)

    def seen_stranded_before(self, job_id: str) -> bool:
        """Whether an earlier round found this job stranded with the same last sign of life (and
        if not, this round's sighting marked on it). A task taken from a queue is in neither the
        queue nor kombu's delivered hash until its worker has recorded the delivery; a round falling
        in that moment would re-queue a job whose task is starting. So a job is re-queued on its
        second sighting, a round later: a task delivered in between has started and marked the job
        alive (a new sign of life), and it is left alone."""
        last_life = self.r.zscore(self.RUNNING, job_id)
        if last_life is None:  # it ended meanwhile
            return False
        seen = self.r.hget(self.key(job_id), self.STRANDED)
        if seen is not None and float(seen) == last_life:
            return True
        self.set_fields(job_id, **{self.STRANDED: last_life})  # not on a job deleted meanwhile
        return False

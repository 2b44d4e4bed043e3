"""Worker heartbeats in Redis: ``/readyz`` answers from them at once, and they are the leases on
the tasks a worker holds.

Each worker's main process writes its name and the time into one sorted set every
``INTERVAL_S`` seconds from the moment it is ready to take tasks, and removes itself when it shuts
down. A worker counts as alive while its last beat is at most ``FRESH_S`` old; one killed outright
stops beating and drops out of the count within ``FRESH_S``. The count is the store's
(``JobStore.live_workers``, which /readyz asks).

With each beat the worker also renews its leases (``renew_leases``): every task it holds
(running, reserved, or waiting for its countdown) gets the time of the beat as its delivery time
in the broker's index of unacknowledged messages (Kombu's ``unacked_index``), and every job those
tasks belong to is marked alive for the reaper. Kombu's own restore sweep (every 5 s) hands a
message back to the queue once its delivery time is older than the visibility timeout: so a task
whose worker died runs again within GEOCERT_VISIBILITY_TIMEOUT_S + 5 s of the worker's last beat,
while one held by a live worker is never delivered twice however long it runs.
"""

from __future__ import annotations

import logging
import threading
import time

import redis

from geocert.jobs.store import SOLVERS_KEY, WORKERS_KEY, JobStore
from geocert.workers.pieces import SOLVE_PIECES

KEY, SOLVERS = WORKERS_KEY, SOLVERS_KEY  # (JobStore.take_slot reads them)
INTERVAL_S = 2.0
FORGET_S = 3600.0  # entries older than this are removed by the next beat of any worker

log = logging.getLogger("geocert.worker")


UNACKED_INDEX = "unacked_index"  # Kombu's Redis transport: delivery tag -> when it was delivered
SOLVE_TASK = "geocert.solve_chunk"
# The tasks that hold a solver slot of their job (JobStore.take_slot): the solve tasks and their
# helpers with a stage's pieces (workers.pieces); the job is each one's first argument.
SLOT_TASKS = (SOLVE_TASK, SOLVE_PIECES)


def held_tasks() -> list[tuple[str, str | None]]:
    """(delivery tag, job id of a task holding a solver slot, else None) of every task this
    worker process holds: running, reserved, or waiting for its countdown (Celery's worker state,
    main process)."""
    from celery.worker import state

    held = []
    for request in list(state.requests.values()):  # copied at once: the consumer thread adds and removes
        tag = getattr(getattr(request, "message", None), "delivery_tag", None)
        if tag is None:
            continue
        args = request.args or ()
        held.append((tag, args[0] if request.name in SLOT_TASKS and args else None))
    return held


def held_solve_tasks() -> list[str]:
    """The ids of the tasks this worker process holds that take solver slots (SLOT_TASKS: the
    solve tasks and their helpers): their slots (JobStore.take_slot), which lapse unrenewed."""
    from celery.worker import state

    return [request.id for request in list(state.requests.values()) if request.name in SLOT_TASKS]


def beat(client: redis.Redis, name: str, held: list[tuple[str, str | None]] = (), solvers: int | None = 0,
         slots: list[str] = ()) -> None:
    """Beat, and renew the leases of the tasks held (only entries that exist are updated: XX) and
    the solver ``slots`` of its solve tasks. ``solvers``: the worker's solver processes (counted by
    /readyz and the per-key share); None for a worker that solves nothing (webhooks), which only
    renews leases."""
    now = time.time()
    pipe = client.pipeline()
    if solvers is not None:
        pipe.zadd(KEY, {name: now})
        pipe.hset(SOLVERS, name, solvers)
    pipe.zremrangebyscore(KEY, "-inf", now - FORGET_S)
    tags = {tag: now for tag, _ in held}
    jobs = {job: now for _, job in held if job}
    if tags:
        pipe.zadd(UNACKED_INDEX, tags, xx=True)
    if slots:
        pipe.zadd(JobStore.SLOTS, {slot: now for slot in slots}, xx=True)
    if jobs:
        pipe.zadd(JobStore.RUNNING, jobs, xx=True)
    pipe.execute()


class Heartbeat:
    """A daemon thread beating for one worker (and renewing the leases of what ``held()`` lists)
    until ``stop()``; with each beat it also calls ``clock()`` (ending the jobs past their clock
    in all that no task works on: tasks.end_jobs_past_clock), and ``reaper()`` every ``reap_every_s``."""

    def __init__(self, url: str, name: str, interval_s: float = INTERVAL_S, reaper=None, reap_every_s: float = 5.0,
                 held=held_tasks, solvers: int | None = 0, clock=None):
        self.client = redis.Redis.from_url(url, socket_timeout=5, socket_connect_timeout=5)
        self.name, self.interval_s, self.solvers = name, interval_s, solvers
        self.reaper, self.reap_every_s, self.reaped_at = reaper, reap_every_s, 0.0
        self.held = held
        self.clock = clock
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._run, name="geocert-heartbeat", daemon=True)

    def start(self) -> "Heartbeat":
        self.thread.start()
        return self

    def _run(self) -> None:
        while not self.stopped.is_set():
            try:
                beat(self.client, self.name, self.held(), self.solvers,
                     held_solve_tasks() if self.solvers else ())
            except redis.RedisError as exc:  # Redis away for a moment: beat again next time
                log.warning("heartbeat not written: %s", exc)
            if self.clock is not None:
                try:
                    self.clock()
                except Exception as exc:  # Redis away, say: look again next time
                    log.warning("ending the jobs past their clock failed: %s", exc)
            if self.reaper is not None and time.monotonic() - self.reaped_at >= self.reap_every_s:
                self.reaped_at = time.monotonic()
                try:
                    self.reaper()
                except Exception as exc:  # Redis away, say: look again next time
                    log.warning("reaper round failed: %s", exc)
            self.stopped.wait(self.interval_s)

    def stop(self) -> None:
        self.stopped.set()
        self.thread.join(timeout=5)
        try:
            self.client.zrem(KEY, self.name)
            self.client.hdel(SOLVERS, self.name)
        except redis.RedisError:
            pass

"""A running task's independent pieces (core.pieces: a reconstruction's images read and
image pairs matched) spread over the service's other solver processes, as a batch's chunks are.

The task running the stage (``SpreadOverSolvers``) stores the pieces (JobStore.put_pieces),
queues a helper task (``solve_pieces``, workers.tasks) for each other live solver process, and takes pieces
itself from the same counter as the helpers do, one at a time. So nothing waits on a queue: with
no solver free the task does every piece itself (a helper that starts later finds none left),
and each free solver takes a share. A helper takes its job's solver slot first
(JobStore.take_slot: a key's fair share holds for its helpers too) or leaves the pieces to others.
Results come back in the pieces' order, each computed as alone (the same on any process), so a
job's result does not depend on how many solvers shared it.

A cancel (or the task's stop) stops the set: no piece is taken any more, and helpers also stop
at their job's cancel. A piece that raises in a helper fails the job with its error (the task's
own failure path: the items finished are kept). A piece a helper took and never returned (its
process gone, or the helper stopped by its time limit) is computed again by the task after a
grace time. A helper holds its job's solver slot as the task does (the worker's heartbeat renews
both), and its Celery time limits end it soon after its task's last-resort deadline.

Pieces travel through Redis as pickles read back by an unpickler that makes only numpy arrays,
plain containers and geocert's dataclasses, and runs only registered piece functions: what is in
Redis names data and a registered function, never code to run. A float32 array of byte values
(SIFT's descriptors) travels as its bytes, read back as the same float32 array.
"""

from __future__ import annotations

import dataclasses
import io
import logging
import pickle
import time
import uuid

import numpy as np
from celery.exceptions import SoftTimeLimitExceeded

from geocert.core import pieces
from geocert.workers.priorities import FIRST
from geocert.jobs.store import JobStore

log = logging.getLogger("geocert.worker")

SOLVE_PIECES = "geocert.solve_pieces"
POLL_S = 0.01  # how often the task looks for its helpers' results while it has no piece to take
LOST_AFTER_S = 2.0  # a helper's piece is computed again after this long, or 4 times the slowest piece
TTL_S = 3600  # the pieces' keys outlive a vanished task at most this long


class PieceFailed(RuntimeError):
    """A piece raised in another solver process: its error, as that process saw it."""


# what numpy's arrays, dtypes and scalars pickle as (protocol 5: an array as its bytes)
_NUMPY = {(module, name) for module in ("numpy.core.multiarray", "numpy._core.multiarray")
          for name in ("_reconstruct", "scalar")} | {
          (module, "_frombuffer") for module in ("numpy.core.numeric", "numpy._core.numeric")} | {
          ("numpy", "ndarray"), ("numpy", "dtype")}


def _float32_of(small: np.ndarray) -> np.ndarray:
    """A float32 array sent as its uint8 values (_Compact), as it was."""
    return small.astype(np.float32)


COMPACT_FROM = 1024  # elements: a smaller array is not worth the check


class _Compact(pickle.Pickler):
    """Pickles a float32 array whose values are all whole numbers from 0 to 255 (and no -0.0) as
    its uint8 values, a quarter of the bytes, read back exactly (_float32_of): SIFT's descriptors,
    which OpenCV rounds to bytes and returns as float32, are most of what the matches stage's
    pieces share and what its features' pieces return."""

    def reducer_override(self, value):
        if (type(value) is np.ndarray and value.dtype == np.float32 and value.size >= COMPACT_FROM
                and value.min() >= 0 and value.max() <= 255):  # (NaN fails both)
            small = value.astype(np.uint8)
            if np.array_equal(small, value) and not np.signbit(value).any():
                return _float32_of, (small,)
        return NotImplemented


class _DataOnly(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        if (module, name) in _NUMPY:
            return super().find_class(module, name)
        if (module, name) == (__name__, _float32_of.__name__):
            return _float32_of
        if module.startswith("geocert."):
            found = super().find_class(module, name)
            if dataclasses.is_dataclass(found) and isinstance(found, type):
                return found
        raise pickle.UnpicklingError(f"a piece may not hold {module}.{name}")


def encode(value) -> bytes:
    out = io.BytesIO()
    _Compact(out, protocol=pickle.HIGHEST_PROTOCOL).dump(value)
    return out.getvalue()


def decode(data: bytes):
    return _DataOnly(io.BytesIO(data)).load()


def helper_time_limits(stop_by: float | None) -> dict:
    """Celery's soft and hard time limits of a helper task queued now by a task stopped as a last
    resort at ``stop_by`` (time.monotonic(); queue.task_deadline_s: its job's own limits plus
    GEOCERT_TASK_TIME_MARGIN_S), as queue.task_options sizes the task's own: a helper has nothing
    to do once its task is stopped. None: a task of unknown deadline, held to the longest any task
    may run (GEOCERT_MAX_JOB_TIME_LIMIT_S, GEOCERT_CHUNK_TIME_BUDGET_S and
    GEOCERT_MAX_ITEM_TIME_LIMIT_S, plus the margin)."""
    from geocert.settings import get_settings
    from geocert.workers.queue import HARD_AFTER_S, SOFT_AFTER_S

    if stop_by is None:
        settings = get_settings()
        left = (max(settings.max_job_time_limit_s, settings.chunk_time_budget_s + settings.max_item_time_limit_s)
                + settings.task_time_margin_s)
    else:
        left = stop_by - time.monotonic()
    soft = max(1.0, left) + SOFT_AFTER_S
    return {"soft_time_limit": soft, "time_limit": soft + HARD_AFTER_S}


class SpreadOverSolvers:
    """The spreader (core.pieces.spread_by) of a task of job ``job_id``, stopped as a
    last resort at ``stop_by`` (time.monotonic(); None: not known), which bounds its helpers'
    time limits (helper_time_limits)."""

    def __init__(self, jobs: JobStore, job_id: str, request_id: str | None = None, stop_by: float | None = None):
        self.jobs, self.job_id, self.request_id, self.stop_by = jobs, job_id, request_id, stop_by
        self.solved = 0  # pieces of the current set this task solved itself

    def __call__(self, function, shared, items, stop):
        jobs, job_id, total = self.jobs, self.job_id, len(items)
        helpers = min(total - 1, max(0, jobs.live_solvers() - 1))  # one per other live solver process
        if not helpers:  # no other solver: the pieces here, two threads at once, nothing through Redis
            return self._alone(function, shared, items, stop)
        set_id = uuid.uuid4().hex[:16]
        jobs.put_pieces(job_id, set_id, pieces.name_of(function), encode(shared), [encode(item) for item in items],
                        TTL_S)
        try:
            self.queue_helpers(set_id, helpers)
            return self._run(function, shared, items, stop, set_id)
        finally:
            jobs.count_own_pieces(self.solved)
            self.solved = 0
            jobs.stop_pieces(job_id, set_id, total)
            jobs.drop_pieces(job_id, set_id)

    def queue_helpers(self, set_id: str, count: int) -> None:
        """Queue ``count`` solve_pieces tasks for the set (ahead of the jobs' later tasks), each
        with time limits that end it soon after its task's (helper_time_limits)."""
        from geocert.workers.celery_app import celery_app  # (needs the broker's address: a worker's)

        limits = helper_time_limits(self.stop_by)
        for _ in range(count):
            celery_app.send_task(SOLVE_PIECES, (self.job_id, set_id, self.request_id), priority=FIRST,
                                 ignore_result=True, **limits)

    def _alone(self, function, shared, items, stop):
        solved = []

        def one(item):  # (in threads: each returns its own value; append is atomic)
            value = function(shared, item)
            solved.append(True)
            return value

        try:  # threads, as the command line's stages use: each piece's result is the same as alone
            return pieces.in_threads(one, items, stop)
        finally:
            self.jobs.count_own_pieces(len(solved))

    def _run(self, function, shared, items, stop, set_id: str):
        jobs, job_id, total = self.jobs, self.job_id, len(items)
        results: dict[int, object] = {}
        slowest = 0.0
        taken = total
        while True:
            asked = stop(len(results))
            if asked is None or asked:
                taken = jobs.stop_pieces(job_id, set_id, total)
                if asked is None:
                    return None  # a cancel: the helpers stop too (the set stopped, their job cancelled)
                break
            piece = jobs.take_piece(job_id, set_id)
            if piece is None:
                break
            index = piece[0]
            began = time.monotonic()
            results[index] = function(shared, items[index])
            self.solved += 1
            slowest = max(slowest, time.monotonic() - began)
        # the pieces the helpers took: wait for them, a lost one computed here after a grace time
        missing = [k for k in range(taken) if k not in results]
        waited_since = time.monotonic()
        while missing:
            found, errors = jobs.piece_results(job_id, set_id, missing)
            if errors:
                index = min(errors)
                raise PieceFailed(f"piece {index} of {total} ({function.__name__}) failed in another solver "
                                  f"process: {errors[index]}")
            for index, value in found.items():
                results[index] = decode(value)
            missing = [k for k in missing if k not in results]
            if not missing:
                break
            if stop(len(results)) is None:
                return None
            if time.monotonic() - waited_since > max(LOST_AFTER_S, 4 * slowest):
                index = missing.pop(0)
                log.warning("piece %d of job %s not returned by its helper: computed here", index, job_id)
                results[index] = function(shared, items[index])
                self.solved += 1
                waited_since = time.monotonic()
                continue
            time.sleep(POLL_S)
        return [results[k] for k in range(taken)]


def help_with(jobs: JobStore, job_id: str, set_id: str) -> int:
    """Take and solve pieces of the set until none is left; returns how many this call solved."""
    function = shared = None
    solved = 0
    while not jobs.cancel_requested(job_id):
        piece = jobs.take_piece(job_id, set_id)
        if piece is None:
            break
        index, item = piece
        try:
            if function is None:
                stated = jobs.piece_function(job_id, set_id)
                if stated is None:
                    break
                function, shared = pieces.registered(stated[0]), decode(stated[1])
            value = encode(function(shared, decode(item)))
        except SoftTimeLimitExceeded:
            raise  # the helper's own time limit, not the piece's fault: its task computes the piece
        except Exception as exc:  # noqa: BLE001 (the task that put the piece fails its job with it)
            log.exception("piece %d of job %s failed", index, job_id)
            jobs.put_piece_result(job_id, set_id, index, error=f"{type(exc).__name__}: {exc}", ttl_s=TTL_S)
            break
        jobs.put_piece_result(job_id, set_id, index, value, ttl_s=TTL_S)
        solved += 1
    return solved

"""Thin tasks: solve a chunk of a job with ``solvers``, publish progress, store results.

A job's items are split into chunks, one task each, run in parallel across workers. A task
starts no new item after GEOCERT_CHUNK_TIME_BUDGET_S and queues the rest of its chunk as a new
task. A live worker renews the broker's lease on every task it holds (``workers.heartbeat``), so a
task is delivered again only when its worker is gone: within GEOCERT_VISIBILITY_TIMEOUT_S + 5 s
of its last beat. Results are stored per item as they end, with the progress that counts them,
so a repeated task overwrites what it wrote before and nothing is counted twice.

A job ends in one place, ``JobStore.end``, under the job's ``claim_end`` (one caller ends it):
``end_with_result`` when the last items are stored, ``end_with_error`` when a task fails (or the
reaper gives up). A queued job cancelled ends in ``JobStore.cancel_if_queued`` instead. Either
way ``after_end`` then counts the job and queues its webhook.

Time limits: a job's own (each kind's time_limit_s; a many-item job's job_time_limit_s, one
clock its tasks share from the job's ``started_at``) end it, keeping its best answers. A job past
its clock in all ends as soon as none of its tasks is busy (``end_past_clock``): the tasks
running then stop their item at the clock, store it and leave, the last to leave ends the job
(its items not stored read "not started"), or a worker's heartbeat does when no task was running
(``end_jobs_past_clock``); its tasks still queued then drop out, solving and storing nothing. A task
still running past what those allow plus GEOCERT_TASK_TIME_MARGIN_S (queue.task_deadline_s) is
stopped as a last resort, at the solvers' next check (the cancel's path), else by Celery's soft
time limit, else by its hard one (the process killed; ``solve_chunk_failed`` runs in the
worker's main process): its job ends ``failed`` with the reason and the items it finished, and
the task is never delivered again.
"""

from __future__ import annotations

import logging
import re
import signal
import time

from geocert.settings import get_settings
from geocert.core.geometry import InputError
from geocert.core.pieces import spread_by
from geocert.jobs.finite import TITLE as FINITE_TITLE, NonFiniteResult
from geocert.jobs.runner import (abs_gap_of, assemble, item_counts, item_sums, job_deadline, merged_sums, not_started_item,
                           result_fragment, result_json, result_shell, solve_items, stats_from, streams_result)
from geocert.kinds import KINDS, get_kind, options_from
from geocert import logs
from geocert.workers.endings import after_end
from geocert.workers.pieces import SOLVE_PIECES, SpreadOverSolvers, help_with
from geocert.workers.celery_app import celery_app
from geocert.workers.priorities import LATER
from geocert.workers.queue import SOFT_AFTER_S, SOLVE_CHUNK, SOLVE_CHUNK_FAILED, task_deadline_s, task_options
from geocert.jobs.collection import collector_held
from geocert.jobs.store import REDIS_GONE, JobStore, shared_store as store
from celery.exceptions import SoftTimeLimitExceeded

log = logging.getLogger("geocert.worker")

# A worker solves every kind: import them all now (the registry would on each kind's first job), so
# the pool's processes share them and no job waits on its kind's imports.
tuple(KINDS)


class ProgressPublisher:
    """Stores a task's items as they end and publishes its progress, both at most every
    ``interval`` seconds (and always at the last item), in the same round trip: the job's
    progress counts stored items only, so a task that dies never leaves progress counting items
    that are not stored (they would be solved again, and progress would fall back).

    With ``kind`` (a streamed result: batch.streams_result), each store writes its run of items
    as one fragment of the result, which holds them (they are not written again one by one)."""

    def __init__(self, jobs: JobStore, job_id: str, start: int, interval: float, kind=None, abs_gap: float = 0.0,
                 stop_by: float = float("inf")):
        self.jobs, self.job_id, self.start, self.interval = jobs, job_id, start, interval
        self.abs_gap = abs_gap
        self.stop_by = stop_by  # time.monotonic() past which the task is stopped as a last resort
        self.overrun = False
        self.last = 0.0
        self.cancel_checked = 0.0
        self.cancelled = False
        self.job_ended = False  # its writes were refused: the job ended (or is gone) under this task
        self.unsaved: dict[int, dict] = {}
        self.stored: int | None = None  # the job's items stored, as this task's last store read them
        self.kind = kind

    def item_ended(self, index: int, item: dict) -> None:
        self.unsaved[index] = item

    def _fragment(self) -> tuple[int, dict, str] | None:
        """The fragment of the items not stored yet (a run: items end in order), None without
        them or a streamed result, or when the model refuses them (they are then stored one by
        one, and the end reads every item)."""
        if self.kind is None or not self.unsaved:
            return None
        items = list(self.unsaved.values())
        text = result_fragment(self.kind, items)
        return None if text is None else (next(iter(self.unsaved)), item_sums(items, self.abs_gap), text)

    def __call__(self, progress: dict) -> None:
        last = progress["items_done"] == progress["items_total"]
        if time.monotonic() - self.last >= self.interval or last:
            self.last = time.monotonic()
            with collector_held():  # the fragment's model makes a tree of objects an item
                saved = self.jobs.save_progress(self.job_id, self.start, progress, self.unsaved, self._fragment())
            if saved is None:
                self.job_ended = True
            else:
                self.stored = saved["items_done"]
            self.unsaved = {}

    @collector_held()
    def flush(self) -> int | None:
        """Store the items not stored yet (and the fragment); returns how many items of the job
        are stored (None: the job has ended or is gone, and nothing was stored). With every item
        stored already (the last progress stored them), the count that store read: no round trip
        (the task that stores a job's last items reads the whole count in that same store)."""
        if not self.unsaved and self.stored is not None and not self.job_ended:
            return self.stored
        done = self.jobs.save_items(self.job_id, self.unsaved, self._fragment())
        self.unsaved = {}
        if done is None:
            self.job_ended = True
        else:
            self.stored = done
        return done

    def should_stop(self) -> bool:
        """A cancel (read from Redis at most every 50 ms), the job ended already (another task
        failed it), or the task past its last-resort deadline."""
        if not self.cancelled and time.monotonic() - self.cancel_checked >= 0.05:
            self.cancel_checked = time.monotonic()
            self.cancelled = self.jobs.cancel_requested(self.job_id)
        if not self.overrun and time.monotonic() > self.stop_by:
            self.overrun = True
        return self.cancelled or self.overrun or self.job_ended


@celery_app.task(name=SOLVE_CHUNK, bind=True, max_retries=5)
def solve_chunk(self, job_id: str, start: int, stop: int, request_id: str | None = None, deferrals: int = 0) -> None:
    """Solve items ``start`` to ``stop - 1`` of a job (or the first of them, within the budget).

    Fairness: the task first takes one of its key's solver slots (``JobStore.take_slot``: a key's
    tasks run on every live solver process but GEOCERT_SOLVERS_KEPT_FOR_OTHERS); with none free it
    is put back on the queue to start later (``_defer``), its job still queued, so that another
    key's job starts on the solver kept free. A task of a job past its time limit in all
    (job_time_limit_s) takes no slot and solves and stores nothing: it ends the job when no task of
    it is busy (``end_past_clock``), else drops out (the last busy one ends it).

    When Redis goes away under the task, the job is not failed (that needs Redis too): the task
    waits for Redis to come back and is retried (its items are stored per item, so solving them
    again counts nothing twice). Should even that fail, the reaper (``workers.reaper``) finds the
    job without a live task and queues its missing chunks again."""
    with logs.context(job_id=job_id, request_id=request_id, items=f"{start}-{stop}"):
        slot = self.request.id
        try:
            if _past_its_time_limit(store(), job_id):
                end_past_clock(store(), job_id)
                return
            if not store().take_slot(job_id, slot, get_settings().solvers_kept_for_others):
                _defer(self.request.id, job_id, start, stop, request_id, deferrals)
                return
            try:
                _solve_chunk(job_id, start, stop, request_id, slot)
            finally:
                _free_slot(slot)
        except REDIS_GONE as exc:
            log.warning("Redis went away under items %d-%d of job %s (%s): retrying", start, stop, job_id,
                        type(exc).__name__)
            _wait_for_redis(store(), limit_s=60)
            raise self.retry(exc=exc, countdown=1)


@celery_app.task(name=SOLVE_PIECES, bind=True, ignore_result=True)
def solve_pieces(self, job_id: str, set_id: str, request_id: str | None = None) -> None:
    """Help a running task of the job with its stage's pieces (workers.pieces): take them until
    none is left, the set is stopped or the job cancelled. Without a solver slot for the job's key
    (JobStore.take_slot) it leaves them to the task and the other helpers. Its slot is renewed by
    the worker's heartbeat (heartbeat.held_solve_tasks); past its soft time limit
    (pieces.helper_time_limits) it leaves the piece it holds to its task."""
    with logs.context(job_id=job_id, request_id=request_id, pieces=set_id):
        slot = self.request.id
        try:
            if not store().take_slot(job_id, slot, get_settings().solvers_kept_for_others):
                return
            try:
                help_with(store(), job_id, set_id)
            finally:
                _free_slot(slot)
        except SoftTimeLimitExceeded:  # its time limit (after its task's): the task computes the piece left
            log.warning("the pieces %s of job %s: a helper stopped at its time limit", set_id, job_id)
        except REDIS_GONE:  # the task that put the pieces computes those not returned
            log.warning("Redis went away under the pieces %s of job %s", set_id, job_id)


def _defer(task_id: str, job_id: str, start: int, stop: int, request_id: str | None, deferrals: int) -> None:
    """Queue the task again (the same id: a cancel still revokes it) to start after a delay that
    doubles with each deferral, up to 5 s: its key holds all the solver slots it may."""
    fields = store().fields(job_id, "kind", "item_time_bound_s", "job_time_limit_s")
    if fields is None or fields["status"] not in ("queued", "running"):
        return  # ended or gone meanwhile: nothing to run
    solve_chunk.apply_async((job_id, start, stop, request_id, deferrals + 1), task_id=task_id,
                            countdown=min(5.0, 0.25 * 2 ** deferrals), priority=LATER,
                            **task_options(fields["kind"], fields["item_time_bound_s"], stop - start,
                                           fields["job_time_limit_s"]))


def _free_slot(slot: str) -> None:
    try:
        store().free_slot(slot)
    except REDIS_GONE:
        pass  # unrenewed, the slot lapses by itself (JobStore.take_slot)


def _wait_for_redis(jobs: JobStore, limit_s: float) -> None:
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        try:
            if jobs.ping():
                return
        except REDIS_GONE:
            time.sleep(0.5)


def _solve_chunk(job_id: str, start: int, stop: int, request_id: str | None, task_id: str | None = None) -> None:
    jobs = store()
    # Its fields, the job marked running (this task busy on it) and its own items only (see
    # JobStore.create): one round trip.
    started = jobs.start_chunk(job_id, start, stop, "items_total", "kind", "item_time_bound_s", "job_time_limit_s",
                               "started_at", task_id=task_id)
    if started is None:
        return  # expired, deleted, or ended (cancelled) before it started: nothing to do
    parsed = (None, None)
    try:
        parsed = _solve_started_chunk(jobs, job_id, start, stop, request_id, *started)
    finally:
        if task_id is not None:
            _leave(jobs, job_id, task_id, *parsed)


def _leave(jobs: JobStore, job_id: str, task_id: str, kind=None, options=None) -> None:
    """The task leaves the job (its items stored): past its clock in all, the last to leave ends it,
    with the kind and options the task parsed when it took the job from the queue."""
    try:
        end_past_clock(jobs, job_id, kind, options, claimed=jobs.leave(job_id, task_id, claim_past_clock=True))
    except REDIS_GONE:
        pass  # its slot lapses unrenewed, and a worker's heartbeat ends the job (end_jobs_past_clock)


def _solve_started_chunk(jobs: JobStore, job_id: str, start: int, stop: int, request_id: str | None,
                         meta: dict, request: dict) -> tuple:
    """Solve the chunk and store its items, ending the job when they are its last; returns the
    job's kind and options as the task parsed them (None where it did not get that far), for the
    job's end when this task is the last to leave it."""
    settings = get_settings()
    began = time.monotonic()
    deadline_s = task_deadline_s(meta["kind"], meta["item_time_bound_s"], stop - start, meta["job_time_limit_s"])
    publisher = kind = options = None
    try:
        kind = get_kind(request["kind"])
        options = options_from(kind.options_type, request.get("options"))
        parsed = kind.parse(request["data"], items=range(start, stop))
        publisher = ProgressPublisher(jobs, job_id, start, settings.progress_interval_s,
                                      kind if streams_result(kind, options) else None, abs_gap_of(options),
                                      stop_by=began + deadline_s)
        # a stage's independent pieces (a reconstruction's images and pairs) go to the other solvers too
        with spread_by(SpreadOverSolvers(jobs, job_id, request_id, stop_by=began + deadline_s)):
            items = solve_items(kind, parsed, options, range(start, stop), publisher, publisher.should_stop,
                                stop_at=began + settings.chunk_time_budget_s, on_item=publisher.item_ended,
                                deadline=job_deadline(options, began - _ran_before(meta["started_at"])))
        done = publisher.flush()
        jobs.record_items(kind.name, items)
        cut = start + len(items)
        if publisher.job_ended:
            log.info("job %s ended under items %d-%d: nothing of them stored", job_id, start, stop)
        elif publisher.overrun and not publisher.cancelled:  # stopped by the clock, not by the job's own limits
            end_over_time(jobs, job_id, kind, options, time.monotonic() - began, deadline_s, "stopped at its next check")
        elif cut < stop and not _past_its_time_limit(jobs, job_id):  # over the budget: the rest, a task of its own
            log.info("continuing items %d-%d in a new task", cut, stop)
            task = solve_chunk.apply_async((job_id, cut, stop, request_id),
                                           **task_options(kind.name, meta["item_time_bound_s"], stop - cut,
                                                          meta["job_time_limit_s"]))
            jobs.add_task_ids(job_id, task.id)
        elif done == meta["items_total"] and jobs.claim_end(job_id):
            end_with_result(jobs, job_id, kind, options)
    except SoftTimeLimitExceeded:  # Celery's soft limit: the solvers did not reach a check in time
        if publisher is not None:
            publisher.flush()
        end_over_time(jobs, job_id, kind, options, time.monotonic() - began, deadline_s + SOFT_AFTER_S,
                      "stopped by Celery's soft time limit")
    except InputError as exc:  # the API validates first, so this is a stored job gone bad
        end_with_error(jobs, job_id, 422, "Invalid job data", str(exc), exc.field)
    except NonFiniteResult as exc:  # jobs.finite: refused rather than written as null
        log.error("items %d-%d of job %s: %s", start, stop, job_id, exc)
        end_with_error(jobs, job_id, 500, FINITE_TITLE, str(exc), exc.field, kind=kind, options=options)
    except REDIS_GONE:
        raise  # not the job's fault: retried (solve_chunk), never recorded as its failure
    except Exception as exc:  # never lose the reason: the job keeps its error
        log.exception("items %d-%d of job %s failed", start, stop, job_id)  # the traceback: in the log only
        if out_of_memory(exc):
            end_with_error(jobs, job_id, 500, MEMORY_TITLE,
                           f"a task of this job needed more memory than a solver process may hold "
                           f"({settings.worker_memory_mb} MiB, GEOCERT_WORKER_MEMORY_MB): {type(exc).__name__}; "
                           "what it finished is kept in the result", None, kind=kind, options=options)
        else:
            end_with_error(jobs, job_id, 500, "Solver failure", f"{type(exc).__name__}: {exc}", None,
                           kind=kind, options=options)
    return kind, options


def end_past_clock(jobs: JobStore, job_id: str, kind=None, options=None, claimed: bool | None = None) -> bool:
    """End a running job past its clock in all (job_time_limit_s) once no task of it is busy
    (``JobStore.claim_past_clock``): ``succeeded`` with the items stored, every other item its
    kind's not started item (status ``time_limit``, uncertified). True when this call ended it.
    ``kind`` and ``options``: as the task ending it parsed them; without them, as stored
    (_kind_and_options). ``claimed``: the claim made already (a task's leave makes it in the
    same round trip), else it is made here."""
    if not (jobs.claim_past_clock(job_id) if claimed is None else claimed):
        return False
    if kind is None or options is None:
        kind, options = _kind_and_options(jobs, job_id)
    try:
        assembled = _stored_result(jobs, job_id, kind, options, lambda: not_started_item(kind, options))
        if assembled is None:
            return False  # deleted meanwhile: writing its end would make it again
        result, sums, stats = assembled
    except Exception as exc:  # noqa: BLE001 - the job must end all the same, saying why
        log.exception("job %s: past its clock, its result could not be assembled", job_id)
        jobs.end(job_id, "failed", error={"type": "about:blank", "title": "Solver failure", "status": 500,
                                          "detail": f"the job's clock in all ran out and its result could not be "
                                                    f"assembled: {type(exc).__name__}"})
        after_end(jobs, job_id)
        return True
    log.info("job %s: past its clock in all, ended", job_id)
    _end(jobs, job_id, sums, stats, result=result, result_text=result_json(kind, result))
    return True


def end_jobs_past_clock(jobs: JobStore) -> list[str]:
    """A worker's heartbeat: end the running jobs past their clock in all that no task works on
    (their tasks queued behind others, or gone); returns their ids."""
    return [job_id for job_id in jobs.past_clock() if end_past_clock(jobs, job_id)]


def _past_its_time_limit(jobs: JobStore, job_id: str) -> bool:
    """Whether the job's clock in all (its options' job_time_limit_s, from ``started_at``) has run out."""
    fields = jobs.fields(job_id, "started_at", "job_time_limit_s")
    return bool(fields and fields["started_at"] is not None and fields["job_time_limit_s"] is not None
                and time.time() > fields["started_at"] + fields["job_time_limit_s"])


def _ran_before(started_at: float | None) -> float:
    """Seconds since the job started (its first task: ``started_at``, as the task's start read it
    before marking the job running), 0 for this task's own start: the job's time limit is one
    clock its tasks share, wherever and whenever they run."""
    if started_at is None:
        return 0.0
    return max(0.0, time.time() - started_at)


MEMORY_TITLE = "Memory limit exceeded"


def out_of_memory(exc: BaseException) -> bool:
    """An allocation refused under the process's memory limit: Python's and numpy's MemoryError,
    or OpenCV's error for it (cv2.error "Insufficient memory")."""
    return isinstance(exc, MemoryError) or "Insufficient memory" in str(exc)


TIME_LIMIT_TITLE = "Task time limit exceeded"
PROCESS_DIED_TITLE = "Solver process died"


def end_over_time(jobs: JobStore, job_id: str, kind, options, ran_s: float, limit_s: float, how: str) -> None:
    """A task ran past the last resort its job's own limits allow (queue.task_deadline_s): the job
    ends ``failed`` with the reason, keeping what it finished."""
    log.warning("job %s: a task ran %.0f s, past its limit of %.0f s (%s)", job_id, ran_s, limit_s, how)
    end_with_error(jobs, job_id, 500, TIME_LIMIT_TITLE,
                   f"a task of this job ran {ran_s:.0f} s, past the {limit_s:.0f} s its own time limits allow it "
                   f"(with GEOCERT_TASK_TIME_MARGIN_S for the work between the solvers' clock checks), and was "
                   f"{how}; what it finished is kept in the result (what was stopped reads cancelled there)",
                   None, kind=kind, options=options)


@celery_app.task(name=SOLVE_CHUNK_FAILED)
def solve_chunk_failed(request, exc, traceback) -> None:
    """Celery's errback for a solve task that failed outside its own handling (run by the worker's
    main process): killed at its hard time limit, its solver process dead (out of memory, a
    crash), or out of retries. Its job ends ``failed`` with the reason and what it finished; the
    task is not delivered again (it is acknowledged). Only a solver process stopped with its
    worker (``_stopped_by_shutdown``) has its task queued again."""
    from billiard.exceptions import WorkerLostError
    from celery.exceptions import TimeLimitExceeded

    job_id = request.args[0]
    jobs = store()
    jobs.free_slot(request.id)
    fields = jobs.fields(job_id, "kind", "item_time_bound_s", "job_time_limit_s")
    if fields is None or fields["status"] in ("succeeded", "failed", "cancelled"):
        return
    kind, options = _kind_and_options(jobs, job_id)
    if isinstance(exc, TimeLimitExceeded):
        limit = exc.args[0] if exc.args else None
        end_with_error(jobs, job_id, 500, TIME_LIMIT_TITLE,
                       f"a task of this job was killed at Celery's hard time limit ({limit} s), the last resort after "
                       "its own time limits and GEOCERT_TASK_TIME_MARGIN_S; what it finished is kept in the result",
                       None, kind=kind, options=options)
    elif isinstance(exc, WorkerLostError) and _stopped_by_shutdown(exc):
        log.warning("job %s: its solver process was stopped with its worker (%s): queued again", job_id, exc)
        solve_chunk.apply_async(tuple(request.args), task_id=request.id,
                                **task_options(fields["kind"], fields["item_time_bound_s"], request.args[2] - request.args[1],
                                               fields["job_time_limit_s"]))
    elif isinstance(exc, WorkerLostError):  # its process died under it: never run again (celery_app)
        end_with_error(jobs, job_id, 500, PROCESS_DIED_TITLE,
                       f"the solver process running a task of this job died ({exc}): most likely killed for "
                       f"memory (each may hold {get_settings().worker_memory_mb} MiB, GEOCERT_WORKER_MEMORY_MB), "
                       "or crashed; the task is not run again. What it finished is kept in the result",
                       None, kind=kind, options=options)
    else:
        end_with_error(jobs, job_id, 500, "Solver failure", f"{type(exc).__name__}: {exc}", None,
                       kind=kind, options=options)


# A solver process stopped by these signals went down with its worker (a deploy, systemd stopping
# the worker's control group): its task is queued again, as a task whose whole worker died is
# delivered again. Any other death (SIGKILL from the kernel's out-of-memory killer, a crash) fails
# the job: run again, it would die again.
_SHUTDOWN_SIGNALS = {signal.SIGTERM, signal.SIGINT, signal.SIGHUP, signal.SIGQUIT}


def _stopped_by_shutdown(exc) -> bool:
    found = re.search(r"signal (\d+)", str(exc))
    return found is not None and int(found.group(1)) in _SHUTDOWN_SIGNALS


def _kind_and_options(jobs: JobStore, job_id: str):
    """The job's kind and its options as stored, for an end no task of it holds them at (its
    errback, a worker's heartbeat, a task taken from the queue past the job's clock). The API
    stored them as it parsed them (the server's maxima applied, the defaults filled in) and every
    task that took the job from the queue parsed them once more: they are rebuilt here, not parsed
    again, so a job ends with the very options its items were solved with."""
    try:
        request = jobs.chunk_request(job_id, 0, 0)
        kind = get_kind(request["kind"])
        return kind, kind.options_type(**(request.get("options") or {}))
    except Exception:  # noqa: BLE001 (the failure is recorded without the partial result then)
        return None, None


def end_with_result(jobs: JobStore, job_id: str, kind, options) -> None:
    """Every item is stored: the job ends ``succeeded`` (or ``cancelled`` when some item was
    stopped) with its result document. The caller holds the job's ``claim_end``. The whole
    request is read only when the result carries it (a full certificate holds the data)."""
    meta = jobs.fields(job_id, "items_total", "started_at", "created_at")
    elapsed = time.time() - (meta["started_at"] or meta["created_at"])
    if streams_result(kind, options) and _end_with_fragments(jobs, job_id, kind, options, meta["items_total"], elapsed):
        return
    request = jobs.request(job_id) if kind.certifies and options.certificate == "full" else None
    items = jobs.all_items(job_id, meta["items_total"])
    sums = item_sums(items, abs_gap_of(options))
    stats = stats_from(sums, elapsed)
    try:
        result = assemble(kind, request, options, items, stats)
    except NonFiniteResult as exc:  # the caller holds the claim: end_with_error could not take it
        log.error("job %s: %s", job_id, exc)
        jobs.end(job_id, "failed", error=exc.problem())
        after_end(jobs, job_id)
        return
    _end(jobs, job_id, sums, stats, result=result, result_text=result_json(kind, result))


def _end_with_fragments(jobs: JobStore, job_id: str, kind, options, total: int, elapsed: float) -> bool:
    """End a streamed result from its tasks' fragments and sums, reading no item; False (nothing
    done) when the fragments do not hold every item once."""
    plan = jobs.fragment_plan(job_id, total)
    if plan is None:
        return False
    sums = merged_sums([part for _, part in plan])
    stats = stats_from(sums, elapsed)
    shell = result_shell(kind, options, stats)
    if shell is None:
        return False
    _end(jobs, job_id, sums, stats, fragments=(*shell, [start for start, _ in plan]))
    return True


def _end(jobs: JobStore, job_id: str, sums: dict, stats: dict, **stored) -> None:
    # The last progress of each task may be throttled away or, after a cancel, stop short of
    # its items: the job's final progress is computed from the very items of the result. A job
    # cancelled while it ran ends "cancelled", with everything it finished, even when its last
    # stage ended before it saw the cancel.
    progress = final_progress(sums, stats)
    cancelled = sums["statuses"].get("cancelled") or jobs.cancel_requested(job_id)
    status = "cancelled" if cancelled else "succeeded"
    jobs.publish_progress(job_id, progress)
    jobs.end(job_id, status, **stored)
    after_end(jobs, job_id)


def final_progress(sums: dict, stats: dict) -> dict:
    """A finished job's progress, from its items' sums (batch.item_sums): ``items_done`` counts
    the items that ran to an end of their own (every status but ``cancelled``), ``nodes`` is
    ``stats.nodes``, the bounds sum the lower bounds and costs of the items that have both."""
    bounded = sums["bounded"] > 0
    return {"nodes": stats["nodes"], "open_boxes": 0,
            "lower_bound": sums["lower"] if bounded else None, "upper_bound": sums["upper"] if bounded else None,
            "gap_abs": max(0.0, sums["upper"] - sums["lower"]) if bounded else None,
            "gap_rel": sums["gap_rel"] if bounded else None,
            **item_counts(sums["ran"], sums["items"]),
            "items_certified": stats["certified"],
            "elapsed_s": stats["elapsed_s"]}


def end_with_error(jobs: JobStore, job_id: str, http_status: int, title: str, detail: str, field: str | None,
                   kind=None, options=None) -> None:
    """The job ends ``failed`` with this error (problem details: title and detail, never a server
    traceback, which stays in the worker's log), unless another caller already holds its
    ``claim_end``. With its ``kind`` and ``options``, the items it finished are kept as its result
    (partial_result)."""
    error = {"type": "about:blank", "title": title, "status": http_status, "detail": detail}
    if field is not None:
        error["errors"] = [{"field": field, "reason": detail}]
    if jobs.claim_end(job_id):
        jobs.request_cancel(job_id)  # the job's other tasks stop at their next check
        result = None
        if kind is not None and options is not None:
            try:
                result = partial_result(jobs, job_id, kind, options, f"not solved: the job failed ({title})")
            except Exception:  # noqa: BLE001 (the error is what must be kept)
                log.exception("job %s: its finished items could not be assembled", job_id)
        jobs.end(job_id, "failed", error=error, result=result,
                 result_text=None if result is None else result_json(kind, result))
        after_end(jobs, job_id)


def partial_result(jobs: JobStore, job_id: str, kind, options, reason: str) -> dict | None:
    """The result of the items a failed job stored (None when it stored none): every other item
    is its kind's unsolved item, saying why."""
    def unsolved() -> dict:
        item = kind.cancelled_item(options)
        return {**item, "reason": reason} if "reason" in item else item

    assembled = _stored_result(jobs, job_id, kind, options, unsolved, none_stored=None)
    return None if assembled is None else assembled[0]


def _stored_result(jobs: JobStore, job_id: str, kind, options, unsolved, none_stored: str | None = "assembled"):
    """(result, sums, stats) of the job's items stored, ``unsolved()`` for every other (one each:
    assembling may write into an item); None when the job is gone, or when it stored no item and
    ``none_stored`` is None."""
    stored = jobs.stored_items(job_id)
    meta = jobs.fields(job_id, "items_total", "started_at", "created_at")
    if meta is None or (not stored and none_stored is None):
        return None
    items = [stored[index] if index in stored else unsolved() for index in range(meta["items_total"])]
    sums = item_sums(items, abs_gap_of(options))
    stats = stats_from(sums, time.time() - (meta["started_at"] or meta["created_at"]))
    request = jobs.request(job_id) if kind.certifies and options.certificate == "full" else None
    return assemble(kind, request, options, items, stats), sums, stats

"""The reaper: no job stays ``running`` without a live task.

A running job is marked alive (``JobStore.touch``) when a task of it starts, stores items or
publishes progress, and with every heartbeat of a worker holding a task of it
(``workers.heartbeat``, every 2 s). So a running job unmarked for longer than the visibility
timeout, with no task queued or delivered and due back, has no live task: its tasks were lost,
e.g. with a Redis restart that dropped them from the queue. The
reaper (run by every worker's heartbeat thread, one at a time through a lock in Redis) queues the
chunks of such a job that still miss items again, when a second round finds it so (a first could
fall in the moment a task is between its queue and its worker); results are stored per item, so solving a chunk
again overwrites what was stored and counts nothing twice. After ``MAX_REAPS`` rounds without the
job ending, it is failed with the reason.
"""

from __future__ import annotations

import logging

from geocert.jobs.store import JobStore

log = logging.getLogger("geocert.worker")
LOCK = JobStore.REAPER_LOCK  # (the store's: JobStore.take_reaper_lock)
STRANDED = JobStore.STRANDED  # a job's field: its last sign of life when a round first found it stranded
MAX_REAPS = 3


def reap(jobs: JobStore, stale_after_s: float, every_s: float) -> list[tuple[str, str]]:
    """One round: returns (job id, what was done) for each stranded job found."""
    if not jobs.take_reaper_lock(every_s):
        return []  # another worker reaps this round
    from geocert.workers.celery_app import SOLVE_QUEUE
    from geocert.workers.priorities import queue_lists
    from geocert.workers.queue import task_options
    from geocert.workers.tasks import end_with_error, solve_chunk

    done = []
    stale = jobs.stale_running(stale_after_s)
    if stale:  # a job with a task still queued, or delivered and due back (kombu's unacked), waits
        pending = jobs.pending_task_messages(queue_lists(SOLVE_QUEUE))
        # A job past its clock in all is ended by the heartbeat (tasks.end_jobs_past_clock), its
        # items not stored reading "not started": a re-queued chunk would only drop out, and
        # dropping the claim to end it could take it from a heartbeat assembling its result.
        past_clock = set(jobs.past_clock())
    for job_id in stale:
        if job_id in past_clock:
            continue
        if job_id in pending:
            jobs.touch(job_id)
            continue
        meta = jobs.get(job_id)
        if meta is None or meta["status"] != "running":
            jobs.forget_running(job_id)
            continue
        if not jobs.seen_stranded_before(job_id):
            continue
        reaps = jobs.count_reap(job_id)
        if reaps > MAX_REAPS:
            jobs.reopen_end(job_id)
            end_with_error(jobs, job_id, 500, "Tasks lost",
                 f"the job's tasks were lost {MAX_REAPS} times (workers or Redis gone) and re-queued each time "
                 "without the job ending", None)
            done.append((job_id, "failed"))
            continue
        missing = set(jobs.missing_items(job_id, meta["items_total"]))
        chunks = [(start, stop) for start, stop in jobs.chunks(meta) if missing.intersection(range(start, stop))]
        if not chunks:  # every item stored, but the task that was to end it is gone
            chunks = jobs.chunks(meta)[-1:]
        jobs.reopen_end(job_id)
        jobs.touch(job_id)  # give the re-queued tasks a full period before the next look
        for start, stop in chunks:
            task = solve_chunk.apply_async((job_id, start, stop), **task_options(
                meta["kind"], meta.get("item_time_bound_s"), stop - start, meta.get("job_time_limit_s")))
            jobs.add_task_ids(job_id, task.id)
        log.warning("job %s had no live task for %.0f s: re-queued %d chunk(s), %d item(s) missing (round %d)",
                    job_id, stale_after_s, len(chunks), len(missing), reaps)
        done.append((job_id, f"requeued {len(chunks)}"))
    return done

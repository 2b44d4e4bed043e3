"""Putting a job's work on the queue and taking it off: what the API asks of the workers, naming
their tasks without importing them (the API process imports no task code)."""

from __future__ import annotations

import contextlib
import functools
import re
import threading

from geocert.workers.priorities import FIRST, LATER
from geocert.jobs.store import JobStore

SOLVE_CHUNK = "geocert.solve_chunk"
SOLVE_CHUNK_FAILED = "geocert.solve_chunk_failed"


def _task(name: str, *args):
    """The task ``name`` with ``args``, as a signature by its name: the workers have its code, the
    API process never imports it (nor the solvers behind it). A result is never kept (the job
    store holds them)."""
    from geocert.workers.celery_app import celery_app

    return celery_app.signature(name, args=args, options={"ignore_result": True})


# After the cooperative stop a task is given (``task_deadline_s``), Celery's soft time limit
# (SoftTimeLimitExceeded raised in the task), and after that its hard one (the process killed).
SOFT_AFTER_S = 30.0
HARD_AFTER_S = 30.0


def task_deadline_s(kind_name: str, item_bound_s: float | None, items: int, job_limit_s: float | None = None) -> float:
    """Seconds after which a task solving ``items`` items of a job is stopped as a last resort:
    what the job's own time limits allow it (batch.task_time_bound_s: its items' and, with
    ``job_limit_s``, its job_time_limit_s) plus GEOCERT_TASK_TIME_MARGIN_S.
    ``item_bound_s`` None: a job recorded without it, held to the server's per-item maximum."""
    from geocert.jobs.runner import task_time_bound_s
    from geocert.kinds import get_kind
    from geocert.settings import get_settings

    settings = get_settings()
    bound = settings.max_item_time_limit_s if item_bound_s is None else item_bound_s
    return task_time_bound_s(get_kind(kind_name), bound, items, settings.chunk_time_budget_s,
                             job_limit_s) + settings.task_time_margin_s


def task_options(kind_name: str, item_bound_s: float | None, items: int, job_limit_s: float | None = None) -> dict:
    """Celery's options for such a task: soft and hard time limits after its deadline, and the
    errback that ends its job ``failed`` (keeping what it finished) when the hard limit kills it,
    so that a killed task is never delivered again."""
    soft = task_deadline_s(kind_name, item_bound_s, items, job_limit_s) + SOFT_AFTER_S
    return {"soft_time_limit": soft, "time_limit": soft + HARD_AFTER_S, "link_error": _task(SOLVE_CHUNK_FAILED)}


def _chunk_group(meta: dict, request_id: str | None):
    """One task per chunk, so a batch runs in parallel across every worker (a Celery group), each
    under the id ``JobStore.create`` recorded for it (``meta["task_ids"]``), with time limits
    sized from the job's own (task_options). The first is queued ahead of every job's later ones
    (priorities.FIRST, LATER): another key's job is not queued behind all of a large job's tasks."""
    from celery import group

    return group([_task(SOLVE_CHUNK, meta["id"], start, stop, request_id).set(
                      task_id=task_id, priority=FIRST if index == 0 else LATER,
                      **task_options(meta["kind"], meta.get("item_time_bound_s"), stop - start,
                                     meta.get("job_time_limit_s")))
                  for index, ((start, stop), task_id) in enumerate(zip(meta["chunks"], meta["task_ids"]))])


def submit_chunks(meta: dict, request_id: str | None) -> None:
    """Publish the job's chunk tasks now (each publish a round trip of its own to the broker)."""
    _chunk_group(meta, request_id).apply_async()


class _Collected:
    """Stands where kombu's publish batch (``Producer.batch``) stands, and as the Redis transport's
    batch does, takes each message's final Redis commands (``add``): kept here, not sent."""

    def __init__(self):
        self.commands: list[tuple[str, tuple]] = []

    def publish(self, channel, message, **kwargs):
        return channel.basic_publish(message, _publish_batch=self, **kwargs)

    def add(self, name: str, *args) -> None:
        self.commands.append((name, args))


@functools.cache
def can_collect() -> bool:
    """Whether the broker's channel hands each message's final Redis commands to a publish batch
    (kombu's Redis transport since 5.7): then ``task_commands`` can collect them. They can run on
    the job store's connection because the broker is the store's Redis and database
    (celery_app.make_celery: broker_url(redis_url())), its keys unprefixed (no global_keyprefix)."""
    from geocert.workers.celery_app import celery_app

    with celery_app.producer_or_acquire() as producer:
        return callable(getattr(producer.channel, "create_publish_batch", None))


def task_commands(meta: dict, request_id: str | None, producer=None) -> list[tuple[str, tuple]]:
    """The broker's Redis commands (name, arguments) that publish the job's chunk tasks, made by
    Celery and kombu as a publish makes them (the same messages, queues and headers) but not
    sent: JobStore.create runs them in the job's own transaction (``enqueue``), so a submission
    is one round trip to Redis whatever its number of chunks, instead of one more a chunk.
    ``producer``: kombu's producer to make them with (``loop_producer``), else one of the pool's."""
    from geocert.workers.celery_app import celery_app

    with contextlib.ExitStack() as stack:
        if producer is None:
            producer = stack.enter_context(celery_app.producer_or_acquire())
        return _collected(producer, meta, request_id)


def _collected(producer, meta: dict, request_id: str | None) -> list[tuple[str, tuple]]:
    collected = _Collected()
    # kombu's Producer publishes through its current batch (thread-local, as Producer.batch sets it).
    producer._batch_local.current = collected
    try:
        _send_as_group(meta, request_id, producer)
    finally:
        del producer._batch_local.current
    return collected.commands


def _send_as_group(meta: dict, request_id: str | None, producer) -> None:
    """``_chunk_group(meta, request_id).apply_async(producer=producer)`` without the canvas: each
    chunk's task message made and published as ``send_task`` makes and publishes it, with the
    options the group's apply hands it (its group's id and its index in it, the app's reply
    address), for this case alone: no countdown, eta or expiry, its result ignored, no parent task
    (the API is not a worker), the task named, not registered here. The same messages
    (tests/workers/test_queue.py compares them with the group's, headers, body and properties) for
    about half the CPU: the group froze, cloned and merged each signature, and send_task looked
    the task up, routed it, and made a result object, before the same message and publish."""
    from celery.utils import uuid

    from geocert.workers.celery_app import celery_app

    amqp = celery_app.amqp
    group_id, reply_to = uuid(), celery_app.thread_oid
    failed = [_task(SOLVE_CHUNK_FAILED)]
    for index, ((start, stop), task_id) in enumerate(zip(meta["chunks"], meta["task_ids"])):
        limits = task_options(meta["kind"], meta.get("item_time_bound_s"), stop - start, meta.get("job_time_limit_s"))
        args = (meta["id"], start, stop, request_id)
        options = amqp.router.route({"priority": FIRST if index == 0 else LATER}, SOLVE_CHUNK, args, {}, None)
        # Celery's saferepr of these arguments (a hex id, two ints, a request id of the API's
        # characters or None, well under its size limit) is their repr, without its cost.
        reprs = {"argsrepr": repr(args), "kwargsrepr": "{}"} if _plain(request_id) else {}
        message = amqp.create_task_message(
            task_id, SOLVE_CHUNK, args, {}, None, None, group_id, index, None, 0, None, None, failed, reply_to,
            limits["time_limit"], limits["soft_time_limit"], celery_app.conf.task_send_sent_event, None, None, None,
            None, ignore_result=True, replaced_task_nesting=0, **reprs, **options)
        with producer.connection._reraise_as_library_errors():
            amqp.send_task_message(producer, SOLVE_CHUNK, message, **options, **_declared(producer, options))


def _declared(producer, options: dict) -> dict:
    """``declare=[]`` when the producer's connection has declared the task's queue already (kombu's
    own cache, ``declared_entities``, which a reconnection empties): send_task_message would ask
    kombu to declare it again, and kombu would find it in that cache after binding and wrapping
    it for a retry, about a third of what making a one-chunk job's commands costs. Otherwise
    nothing: the first publish on a connection declares the queue (on Redis: its binding, without
    which a message finds no queue) as before."""
    queue = options.get("queue")
    declared = getattr(producer.connection, "declared_entities", None)
    if queue is not None and getattr(queue, "can_cache_declaration", False) and declared and hash(queue) in declared:
        return {"declare": []}
    return {}


def _plain(request_id: str | None) -> bool:
    return request_id is None or _PLAIN.fullmatch(request_id) is not None


_PLAIN = re.compile(r"[A-Za-z0-9._:-]{1,128}")


_LOOP_PRODUCER: list = []  # what ready_loop_producer made: the producer, or None (the broker cannot collect)
_LOOP_PRODUCER_LOCK = threading.Lock()


def loop_producer():
    """The producer whose task commands an event loop may make without waiting on the network:
    its connection made and the queue declared (``ready_loop_producer``, in a thread, first); None
    until then, or when the broker cannot collect them (can_collect). Collecting sends nothing,
    so from then on making the commands is computation alone. Its thread-local batch makes it
    safe for one thread at a time: an event loop's."""
    return _LOOP_PRODUCER[0] if _LOOP_PRODUCER else None


def loop_producer_tried() -> bool:
    """Whether ``ready_loop_producer`` has run (and ``loop_producer`` is what it will stay)."""
    return bool(_LOOP_PRODUCER)


def ready_loop_producer() -> None:
    """Make ``loop_producer`` (blocking: connects to the broker): a producer taken from the pool
    for good, and a first job's commands made with it and dropped, through which Celery declares
    the queue (cached from then on)."""
    from geocert.workers.celery_app import celery_app

    with _LOOP_PRODUCER_LOCK:
        if _LOOP_PRODUCER:
            return
        if not can_collect():
            _LOOP_PRODUCER.append(None)
            return
        producer = celery_app.producer_pool.acquire(block=True)
        _collected(producer, {"id": "ready", "kind": "triangulation", "chunks": [(0, 1)], "task_ids": ["ready"]}, None)
        _LOOP_PRODUCER.append(producer)


def withdraw_queued(store: JobStore, job_id: str) -> None:
    """A job ended while queued (``JobStore.cancel_if_queued``): its tasks are revoked and its end
    counted (metrics, webhook)."""
    from geocert.workers.celery_app import celery_app
    from geocert.workers.endings import after_end

    for task_id in store.task_ids(job_id):
        celery_app.control.revoke(task_id)
    after_end(store, job_id)

"""A job's submission, free of the routes: the limits and budget a request is held to, the job
created with its tasks queued in one transaction, and an idempotent replay. The route calls it
in its thread pool, or for a small body on its event loop (submit_on_loop: the same checks, the
Redis calls through the loop's asyncio client); a large whole body is submitted by a submission
process (app.submissions) through the same code."""

from __future__ import annotations

import asyncio
import hashlib
import json
from urllib.parse import urlsplit

from fastapi import Response
from fastapi.concurrency import run_in_threadpool

from geocert.app import streamed
from geocert.jobs.collection import collector_held
from geocert.app.errors import ApiProblem
from geocert.jobs.runner import parse_job
from geocert.kinds import get_kind
from geocert.settings import chunk_size_for, get_settings, over_budget
from geocert import logs
from geocert.jobs.destinations import allowed_networks, literal_refusal
from geocert.workers.queue import can_collect, submit_chunks, task_commands
from geocert.jobs.store import TERMINAL, JobStore, StoredBytesExceeded, read_job


def _check_count(kind, items: int) -> None:
    settings = get_settings()
    if items > settings.max_items_per_job:
        raise ApiProblem(413, f"{items} {kind.item_key} exceed the limit of {settings.max_items_per_job} per job "
                              "(GEOCERT_MAX_ITEMS_PER_JOB)", f"data/{kind.item_key}")


def _check_callback(request: dict) -> None:
    """A callback_url whose host is written as an address webhooks may not go to (loopback,
    private, link-local, multicast, reserved; localhost) is a 422 at once; a name is checked when
    the webhook is delivered, on the address connected to (workers.destinations)."""
    url = request.get("callback_url")
    if url:
        reason = literal_refusal(urlsplit(url).hostname or "", allowed_networks(get_settings().webhook_allowed_networks))
        if reason is not None:
            raise ApiProblem(422, f"webhooks go only to public addresses, and this one is {reason} (an operator may "
                                  "allow networks: GEOCERT_WEBHOOK_ALLOWED_NETWORKS)", "callback_url")


def _check_budget(request: dict) -> None:
    """The job's figures (its kind's request_figures: from the request alone, photos read from
    their headers) within the server's budget (settings.BUDGETS), else a 413 naming the figure."""
    exceeded = over_budget(get_kind(request["kind"]).request_figures(request["data"]))
    if exceeded is not None:
        raise ApiProblem(413, *exceeded)


def _check_limits(kind, parsed, request: dict, counts: tuple[int, int] | None = None) -> int:
    """Raises on a limit passed; returns the item count. ``counts``: the items and observations,
    when not all of them are in ``parsed`` (a large body's, checked a batch at a time)."""
    settings = get_settings()
    items, points = counts if counts is not None else (kind.count(parsed), kind.observations(parsed))
    _check_count(kind, items)
    if points > settings.max_points_per_job:
        raise ApiProblem(413, f"{points} observations exceed the limit of {settings.max_points_per_job} per job "
                              "(GEOCERT_MAX_POINTS_PER_JOB)", f"data/{kind.item_key}")
    return items


def _hold_to_server_maxima(body, request: dict) -> None:
    """This server's maxima of an item's time and nodes and a job's time, applied to the request's
    options before they are parsed (once, as the job will run): an option given above its maximum
    is refused, naming it; a default above it is lowered to it."""
    settings = get_settings()
    options, given = request["options"], body.options.model_fields_set
    for name, maximum, unit, variable in (
            ("time_limit_s", settings.max_item_time_limit_s, " s per item", "MAX_ITEM_TIME_LIMIT_S"),
            ("max_nodes", settings.max_item_nodes, " nodes per item", "MAX_ITEM_NODES"),
            ("job_time_limit_s", settings.max_job_time_limit_s, " s per job", "MAX_JOB_TIME_LIMIT_S")):
        if name not in options or options[name] <= maximum:  # a kind without the option (stereo_lines)
            continue
        if name in given:
            raise ApiProblem(422, f"exceeds this server's maximum of {maximum:g}{unit} (GEOCERT_{variable})",
                             f"options/{name}")
        options[name] = maximum  # a default above the server's maximum is lowered to it


def _checked(body) -> tuple[dict, object, object, object]:
    """The request (as JSON types, validated by its kind's model: discriminated on "kind"), its
    kind, its parsed data and options, after every check made before anything is stored. The
    options are parsed once, here, as the job will run them (the server's maxima applied first)."""
    request = body.model_dump(mode="json")
    _check_callback(request)
    _check_budget(request)  # before anything of the job is decoded or built
    _hold_to_server_maxima(body, request)
    kind, parsed, options = parse_job(request)  # the solvers' own checks: rank, indices, duplicates
    return request, kind, parsed, options


def _digest(request: dict) -> str:
    return hashlib.sha256(json.dumps(request, sort_keys=True).encode()).hexdigest()


@collector_held()
def _submit(body, response: Response, store: JobStore, owner: str, idempotency_key: str | None,
            split: streamed.Split | None = None) -> dict:
    """The submission itself (synchronous Redis calls: run in FastAPI's thread pool). ``split``:
    a large body's items, when ``body`` is its head (StreamedItemsRoute)."""
    request, kind, parsed, options = _checked(body)
    upload = None
    if split is not None:
        _check_count(kind, split.count)  # before any item is read
        upload = streamed.upload_items(store, split, request, with_digest=idempotency_key is not None)
    try:
        items = _check_limits(kind, parsed, request,
                              (upload.count, upload.observations) if upload is not None else None)
        digest = None
        if idempotency_key is not None:  # the body's digest only for a key (a whole body hashed: not on every submit)
            digest = upload.digest if upload is not None else _digest(request)
            earlier = store.remember_idempotent(owner, idempotency_key, digest)
            if earlier is not None:
                return _replay(store, earlier, digest, response)
        try:
            # Its tasks' last-resort time limits follow from its own limits (held to the server's maxima).
            bound = kind.time_bound_s(parsed, options)
            meta = _create(store, owner, kind, request, items, upload.key if upload is not None else None, bound,
                           upload.bytes if upload is not None else 0)
        except BaseException:
            if idempotency_key is not None:
                store.settle_idempotent(owner, idempotency_key, digest, None)  # free the key for a retry
            raise
    finally:
        if upload is not None:
            store.drop_upload(upload.key)  # gone already once it became a job's item list
    if idempotency_key is not None:
        store.settle_idempotent(owner, idempotency_key, digest, meta["id"])
    response.headers["Location"] = f"/v1/jobs/{meta['id']}"
    return store.document(meta)


def _create_arguments(owner: str, kind, request: dict, items: int, items_key: str | None, item_time_bound_s,
                      items_bytes: int, enqueue) -> tuple[tuple, dict]:
    settings = get_settings()
    return (kind.name, request, items, chunk_size_for(kind), owner, request.get("callback_url"),
            settings.max_active_jobs_per_key), dict(
        chunk_key=kind.chunk_key, items_key=items_key, item_time_bound_s=item_time_bound_s,
        job_time_limit_s=request.get("options", {}).get("job_time_limit_s"), enqueue=enqueue,
        items_bytes=items_bytes, stored_bytes_limit=settings.max_stored_bytes_per_key)


def _enqueue(producer=None):
    """The job's tasks queued in its own transaction (JobStore.create's ``enqueue``)."""
    request_id = logs.current("request_id")

    def enqueue(meta: dict) -> list[tuple[str, tuple]]:
        with logs.context(job_id=meta["id"]):
            return task_commands(meta, request_id, producer)

    return enqueue


def _refused(exc: StoredBytesExceeded | None) -> ApiProblem:
    """A job not admitted: over its key's stored bytes (``exc``), else its active jobs."""
    settings = get_settings()
    if exc is not None:
        return ApiProblem(429, f"this key's jobs kept on the server would hold more than {settings.max_stored_bytes_per_key} "
                               "bytes with this one (GEOCERT_MAX_STORED_BYTES_PER_KEY): delete finished jobs "
                               "(DELETE /v1/jobs/{id}) or wait for them to expire", headers={"Retry-After": "60"})
    return ApiProblem(429, f"this key already has {settings.max_active_jobs_per_key} jobs queued or running "
                           "(GEOCERT_MAX_ACTIVE_JOBS_PER_KEY); wait for one to end", headers={"Retry-After": "5"})


def _create(store: JobStore, owner: str, kind, request: dict, items: int, items_key: str | None = None,
            item_time_bound_s: float | None = None, items_bytes: int = 0) -> dict:
    collect = can_collect()
    args, options = _create_arguments(owner, kind, request, items, items_key, item_time_bound_s, items_bytes,
                                      _enqueue() if collect else None)
    try:
        meta = store.create(*args, **options)
    except StoredBytesExceeded as exc:
        raise _refused(exc) from None
    if meta is None:
        raise _refused(None)
    if not collect:  # a broker whose publishes cannot join the job's transaction: published after it
        with logs.context(job_id=meta["id"]):
            submit_chunks(meta, logs.current("request_id"))
    return meta


# A body up to GEOCERT_SUBMIT_ON_LOOP_BYTES is submitted on the API's event loop (submit_on_loop)
# when the loop can queue tasks without waiting (queue.loop_producer): its checks and job cost
# about a millisecond of CPU (3 tracks; some 40 us a track more), while a thread of the pool given
# it competed with the loop for the interpreter lock at each of the loop's system calls. Larger
# bodies go to the pool.


async def submit_on_loop(body, response: Response, store: JobStore, client, owner: str,
                         idempotency_key: str | None, producer) -> dict:
    """``_submit`` for a small body on the event loop: the same checks, the same job created with
    its tasks in one transaction, and the same idempotent replay, the Redis calls through the
    loop's asyncio ``client`` (the store's server) and the tasks made with ``producer``
    (queue.loop_producer). What follows the checks runs to its end as a thread would, even if
    the request is cancelled meanwhile (a job is never left half made, nor a key reserved)."""
    with collector_held():
        request, kind, parsed, options = _checked(body)
        items = _check_limits(kind, parsed, request)
        bound = kind.time_bound_s(parsed, options)
        digest = _digest(request) if idempotency_key is not None else None
    args, options = _create_arguments(owner, kind, request, items, None, bound, 0, _enqueue(producer))

    async def store_it() -> dict:
        if idempotency_key is not None:
            earlier = await store.remember_idempotent_async(client, owner, idempotency_key, digest)
            if earlier is not None:
                return await _replay_async(store, client, earlier, digest, response)
        try:
            meta = await store.create_async(client, *args, **options)
            if meta is None:
                raise _refused(None)
        except BaseException as exc:
            if idempotency_key is not None:
                await store.settle_idempotent_async(client, owner, idempotency_key, digest, None)  # free the key
            if isinstance(exc, StoredBytesExceeded):
                raise _refused(exc) from None
            raise
        if idempotency_key is not None:
            await store.settle_idempotent_async(client, owner, idempotency_key, digest, meta["id"])
        response.headers["Location"] = f"/v1/jobs/{meta['id']}"
        return store.document(meta)  # queued: nothing more to read

    return await asyncio.shield(asyncio.ensure_future(store_it()))


def _replay(store: JobStore, earlier: dict, digest: str, response: Response) -> dict:
    _check_replay(earlier, digest)
    return store.document(_replayed(earlier, store.get(earlier["job"]), response))


async def _replay_async(store: JobStore, client, earlier: dict, digest: str, response: Response) -> dict:
    _check_replay(earlier, digest)
    meta = _replayed(earlier, await read_job(client, earlier["job"]), response)
    # An ended job's document reads its result (the sync store's calls): in a thread.
    return await run_in_threadpool(store.document, meta) if meta["status"] in TERMINAL else store.document(meta)


def _check_replay(earlier: dict, digest: str) -> None:
    if earlier["body"] != digest:
        raise ApiProblem(422, "this Idempotency-Key was used with a different body", "Idempotency-Key")
    if earlier["job"] is None:
        raise ApiProblem(409, "a request with this Idempotency-Key is still being processed; retry shortly",
                         "Idempotency-Key", headers={"Retry-After": "1"})


def _replayed(earlier: dict, meta: dict | None, response: Response) -> dict:
    if meta is None:
        raise ApiProblem(404, f"the job made for this Idempotency-Key ({earlier['job']}) no longer exists")
    response.status_code = 200
    response.headers["Location"] = f"/v1/jobs/{meta['id']}"
    response.headers["Idempotent-Replayed"] = "true"
    return meta

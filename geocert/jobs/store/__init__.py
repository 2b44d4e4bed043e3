"""Jobs in Redis: their state, request, chunk results, progress and event stream.

Shared by the API (reads, cancels, streams) and the workers (progress, results). ``JobStore``
composes one class per concern, each in its own module over the client and key scheme of
``base``:

- ``base``: the Redis client (text and binary), the key scheme, shared constants and encoder;
- ``creation`` (with ``commands``, the writes it records): a job admitted and written in one script;
- ``records``: the job's record, read and written, and as the API shows it; its task ids;
- ``requests``: the request, whole or a chunk's items;
- ``lifecycle``: the state machine (running, a task's leaving, the claim to end, the end,
  cancellation, deletion);
- ``items``: what tasks store as they go (items, a streamed result's fragments, summed progress);
- ``results``: the stored result, read whole or by pieces;
- ``events``: the event stream and its published progress;
- ``accounts``: an owner's index, stored bytes, active jobs and rate window;
- ``idempotency``: Idempotency-Key reservations;
- ``slots``: solver slots, webhook deliveries in flight, live workers;
- ``clocks``: the running jobs' signs of life and deadlines, and the reaper's lock, stranded
  marks and look at the broker's queues;
- ``metrics``: the shared job metrics (counted by the workers, read by ``/metrics``);
- ``uploads``: a large body's items, written a batch at a time before its job exists;
- ``pieces``: a running task's independent pieces, taken by the other solver processes too.
"""

from __future__ import annotations

from geocert.jobs.store.accounts import Accounts, count_request
from geocert.jobs.store.base import (FRESH_S, PAST_CLOCK_CLAIM_S, PUBLIC_OWNER, REDIS_GONE, SOLVERS_KEY, STREAM_MAXLEN,
                                     TERMINAL, WORKERS_KEY, ResultGone, StoreBase, StoredBytesExceeded, dumps, now)
from geocert.jobs.store.clocks import Clocks
from geocert.jobs.store.commands import _Commands
from geocert.jobs.store.creation import Creation
from geocert.jobs.store.events import Events, events
from geocert.jobs.store.idempotency import Idempotency
from geocert.jobs.store.items import Items
from geocert.jobs.store.lifecycle import Lifecycle
from geocert.jobs.store.metrics import Metrics
from geocert.jobs.store.pieces import Pieces
from geocert.jobs.store.records import Records, read_job
from geocert.jobs.store.requests import Requests
from geocert.jobs.store.results import Results
from geocert.jobs.store.slots import Slots
from geocert.jobs.store.uploads import Uploads

__all__ = ["FRESH_S", "PAST_CLOCK_CLAIM_S", "PUBLIC_OWNER", "REDIS_GONE", "SOLVERS_KEY", "STREAM_MAXLEN", "TERMINAL",
           "WORKERS_KEY", "JobStore", "ResultGone", "StoredBytesExceeded", "count_request", "dumps", "events", "now",
           "read_job", "shared_store", "_Commands"]


class JobStore(Creation, Records, Requests, Lifecycle, Items, Results, Events, Accounts, Idempotency, Slots, Clocks,
               Metrics, Uploads, Pieces, StoreBase):
    """The job store: every concern's methods on one object over one client."""


_SHARED: JobStore | None = None


def shared_store() -> JobStore:
    """This worker process's job store (one connection pool for its tasks and webhooks)."""
    global _SHARED
    if _SHARED is None:
        from geocert.settings import get_settings
        from geocert.settings import redis_url

        _SHARED = JobStore.from_url(redis_url(), get_settings().result_ttl_s)
    return _SHARED

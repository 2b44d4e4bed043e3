"""A job's events: a Redis stream per job, whose entry ids are the SSE event ids, so that a client
that reconnects with ``Last-Event-ID`` resumes exactly where it stopped; and its progress, set
and published while it is queued or running."""

from __future__ import annotations

import asyncio
import json
from typing import AsyncIterator

import redis.asyncio

from geocert.jobs.store.base import STREAM_MAXLEN
from geocert.jobs.store.base import StoreBase, dumps


class Events(StoreBase):
    def publish(self, job_id: str, event: str, data: dict, pipe=None) -> str | None:
        """Append an event to the job's stream; returns its id (None when added to ``pipe``)."""
        return (pipe or self.r).xadd(self.key(job_id, "events"), {"event": event, "data": dumps(data)},
                                     maxlen=STREAM_MAXLEN, approximate=True)

    _PUBLISH_PROGRESS = """
    local status = redis.call('HGET', KEYS[1], 'status')
    if status ~= '"queued"' and status ~= '"running"' then return false end
    redis.call('HSET', KEYS[1], 'progress', ARGV[1])
    return redis.call('XADD', KEYS[2], 'MAXLEN', '~', ARGV[2], '*', 'event', 'progress', 'data', ARGV[1])
    """

    def publish_progress(self, job_id: str, progress: dict) -> bool:
        """Set the job's progress and publish it, while the job is queued or running (False: it
        has ended or is gone, and nothing was written)."""
        return bool(self.r.eval(self._PUBLISH_PROGRESS, 2, self.key(job_id), self.key(job_id, "events"),
                                dumps(progress), STREAM_MAXLEN))


async def events(client: redis.asyncio.Redis, job_id: str, after: str, block_ms: int,
                 stop: asyncio.Event) -> AsyncIterator[tuple[str, str, dict]]:
    """Yield a job's events (id, event, data) after ``after`` until its end event, from an asyncio
    Redis client (``decode_responses``), without holding a thread: each read blocks up to
    ``block_ms`` on the Redis side while the event loop serves other requests. After a read that
    found nothing, ("", "keepalive", {}) is yielded (the caller's heartbeat), or nothing more when
    the job has expired or been removed. When ``stop`` is set, ("", "stopping", {}) is yielded at
    once and the iteration ends (the blocking read is abandoned)."""
    stream = StoreBase.key(job_id, "events")
    last = after
    halt = asyncio.ensure_future(stop.wait())
    read: asyncio.Future | None = None
    try:
        while True:
            read = asyncio.ensure_future(client.xread({stream: last}, count=100, block=block_ms))
            await asyncio.wait({read, halt}, return_when=asyncio.FIRST_COMPLETED)
            if not read.done():
                yield "", "stopping", {}
                return
            answer = read.result()
            if not answer:
                if await client.hget(StoreBase.key(job_id), "status") is None:
                    return  # the job expired or was removed
                yield "", "keepalive", {}
                continue
            for entry_id, fields in answer[0][1]:
                last = entry_id
                yield entry_id, fields["event"], json.loads(fields["data"])
                if fields["event"] == "end":
                    return
    finally:
        halt.cancel()
        if read is not None and not read.done():
            read.cancel()  # redis-py drops that connection rather than reuse it mid-reply

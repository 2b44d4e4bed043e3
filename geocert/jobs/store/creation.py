"""A job's creation: admitted against its owner's limits and written, with its tasks' messages,
by one Lua script in one round trip (from a thread, or from the API's event loop)."""

from __future__ import annotations

import uuid
from typing import Callable

import redis.asyncio

from geocert.jobs.store.accounts import Accounts
from geocert.jobs.store.base import StoreBase, StoredBytesExceeded, dumps, now
from geocert.jobs.store.commands import _Commands


class Creation(StoreBase):
    """Uses the request's writes (``requests``), the status event (``events``) and the owner's
    accounts (``accounts``)."""

    def create(self, kind: str, request: dict, items_total: int, chunk_size: int, owner: str,
               callback_url: str | None = None, active_limit: int = 0, task_ids=None,
               chunk_key: str | None = None, items_key: str | None = None,
               item_time_bound_s: float | None = None, job_time_limit_s: float | None = None,
               enqueue: Callable[[dict], list[tuple[str, tuple]]] | None = None,
               items_bytes: int = 0, stored_bytes_limit: int = 0) -> dict | None:
        """Record a new queued job, counted among the owner's active jobs, with its ``status``
        event and the ids its tasks will have (one per chunk; made here unless given), in one
        round trip. None when the owner already has ``active_limit`` jobs queued or running (0:
        no limit): nothing of the job is kept then.

        ``chunk_key``: the data list whose entries are the job's items one to one (a kind's
        ``chunk_key``). Those entries are kept a chunk (``chunk_size`` of them) per element of a
        Redis list beside the rest of the request (Requests), so that a task reads its own items
        (``chunk_request``), not the whole request: read traffic stays about the request's size
        whatever the number of chunks.

        ``items_key``: a Redis list already holding those entries' JSON texts, one an element (a
        large body's items, written a batch at a time: app.streamed); it becomes the job's item
        list, and the request's own list is ignored.

        ``item_time_bound_s``: the longest one of its items runs while the job's own time limits
        hold (its kind's ``time_bound_s``), from which its tasks' last-resort limits are sized, with
        ``job_time_limit_s`` (a many-item kind's option: the job's limit in all).

        ``enqueue``: given the job's record, the broker's Redis commands that queue its tasks
        (workers.queue.task_commands); they run in the same script, only if the job is
        admitted: a submission is one round trip, and no task is ever queued without its job.

        ``stored_bytes_limit``: what the owner's jobs that exist may hold in all (0: no limit),
        each counted as its request's bytes (``items_bytes``: those of ``items_key``'s texts), at
        least STORED_BYTES_FLOOR, and from its end its stored result's (``_COUNT_RESULT``);
        StoredBytesExceeded beyond it, nothing of the job kept."""
        meta, keys, args, bulk = self._stage_create(kind, request, items_total, chunk_size, owner, callback_url,
                                                    active_limit, task_ids, chunk_key, items_key, item_time_bound_s,
                                                    job_time_limit_s, enqueue, items_bytes, stored_bytes_limit)
        if not bulk:
            return self._admitted(meta, self.r.eval(self._CREATE, len(keys), *keys, *args), stored_bytes_limit)
        pipe = self.r.pipeline()
        for command in bulk:
            pipe.execute_command(*command)
        pipe.eval(self._CREATE, len(keys), *keys, *args)
        admitted = pipe.execute()[-1]
        if admitted != 1:
            self.r.delete(*{command[1] for command in bulk})  # written before the script refused the job
        return self._admitted(meta, admitted, stored_bytes_limit)

    async def create_async(self, client: redis.asyncio.Redis, *args, **kwargs) -> dict | None:
        """``create`` (the same arguments after ``client``) through an asyncio client
        (``decode_responses``, the same server): the same script, for the API's event loop."""
        arguments = _create_arguments(*args, **kwargs)
        meta, keys, script_args, bulk = self._stage_create(*arguments)
        if not bulk:
            admitted = await client.eval(self._CREATE, len(keys), *keys, *script_args)
        else:
            pipe = client.pipeline()
            for command in bulk:
                pipe.execute_command(*command)
            pipe.eval(self._CREATE, len(keys), *keys, *script_args)
            admitted = (await pipe.execute())[-1]
            if admitted != 1:
                await client.delete(*{command[1] for command in bulk})
        return self._admitted(meta, admitted, arguments[-1])

    @staticmethod
    def _admitted(meta: dict, admitted: int, stored_bytes_limit: int) -> dict | None:
        if admitted == -1:
            raise StoredBytesExceeded(stored_bytes_limit)
        return meta if admitted == 1 else None

    def _stage_create(self, kind, request, items_total, chunk_size, owner, callback_url, active_limit, task_ids,
                      chunk_key, items_key, item_time_bound_s, job_time_limit_s, enqueue, items_bytes,
                      stored_bytes_limit) -> tuple[dict, list, list, list]:
        """A new job's record, the keys and arguments of the one script (``_CREATE``) that admits
        and writes it, and its large writes (``_Commands.BULK``: a large request's text or
        items, sent beside the script in a transaction, deleted if it refuses the job): its writes
        are recorded here (``_Commands``), not sent, and run by the script only when the job is
        admitted. One command instead of a transaction of a dozen: a dozen fewer replies to parse
        and commands to pack in the API, nothing written for a job refused (nothing to take back),
        and the same atomicity (a script runs whole, alone)."""
        job_id = uuid.uuid4().hex
        chunks = [(start, min(start + chunk_size, items_total)) for start in range(0, items_total, chunk_size)]
        meta = {
            "id": job_id, "kind": kind, "owner": owner, "status": "queued", "created_at": now(), "started_at": None,
            "finished_at": None, "items_total": items_total, "chunk_size": chunk_size,
            "progress": {"nodes": 0, "open_boxes": 0, "lower_bound": None, "upper_bound": None, "gap_abs": None,
                         "gap_rel": None, "items_done": 0, "items_total": items_total,
                         "tracks_done": 0, "tracks_total": items_total, "elapsed_s": 0.0},  # tracks_*: deprecated names
            "error": None, "item_time_bound_s": item_time_bound_s, "job_time_limit_s": job_time_limit_s,
            "webhook": {"url": callback_url, "state": "waiting", "attempts": 0, "last_error": None,
                        "delivered_at": None} if callback_url else None,
        }
        meta["task_ids"] = list(task_ids) if task_ids is not None else [uuid.uuid4().hex for _ in chunks]
        pipe = _Commands()
        request_bytes = self._put_request(pipe, job_id, request, chunk_key, items_key, chunk_size) + items_bytes
        pipe.hset(self.key(job_id), mapping={k: dumps(v) for k, v in meta.items() if k != "task_ids"})
        meta["chunks"] = chunks  # not stored: every read of the job (each poll) would read them (JobStore.chunks)
        pipe.zadd(self.owner_key(owner, "jobs"), {job_id: meta["created_at"]})
        self.publish(job_id, "status", {"status": "queued"}, pipe)
        if meta["task_ids"]:
            pipe.rpush(self.key(job_id, "tasks"), *meta["task_ids"])
        if enqueue is not None:
            for name, args in enqueue(meta):
                pipe.command(name, *args)
        keys = [*self._accounts(owner), self.owner_key(owner, "active")]
        args = [self.key(""), self.PRUNED_PER_JOB, job_id, active_limit, max(request_bytes, self.STORED_BYTES_FLOOR),
                stored_bytes_limit, pipe.text()]
        return meta, keys, args, pipe.bulk

    @staticmethod
    def chunks(meta: dict) -> list[tuple[int, int]]:
        """The job's chunks (start, stop), one task each: from its chunk size (a job stored by an
        earlier version lists them)."""
        if "chunks" in meta:
            return [tuple(chunk) for chunk in meta["chunks"]]
        total, size = meta["items_total"], meta["chunk_size"]
        return [(start, min(start + size, total)) for start in range(0, total, size)]

    # A job's creation, whole (JobStore._stage_create), KEYS its owner's accounts (_accounts) and
    # active jobs. The owner's index pruned: those of its ARGV[2] oldest entries whose job (key
    # prefix ARGV[1]) has expired are forgotten. The job ARGV[3] admitted: counted among the
    # owner's active jobs unless they are at its limit (ARGV[4]; 0: no limit), and its bytes
    # (ARGV[5]) among those of the owner's stored jobs unless they would pass theirs (ARGV[6]; 0:
    # no limit). Only then the commands in ARGV[7] run (a JSON array: each its name, its argument
    # count, its arguments): the job's writes and its tasks' messages. 1, else 0 (active) or -1
    # (stored bytes).
    _CREATE = Accounts._FORGET_LUA + """
    for _, id in ipairs(redis.call('ZRANGE', KEYS[1], 0, tonumber(ARGV[2]) - 1)) do
      if redis.call('EXISTS', ARGV[1] .. id) == 0 then forget(id) end
    end
    if tonumber(ARGV[4]) > 0 and redis.call('SCARD', KEYS[4]) >= tonumber(ARGV[4]) then return 0 end
    local stored = tonumber(redis.call('GET', KEYS[3]) or '0')
    if tonumber(ARGV[6]) > 0 and stored + tonumber(ARGV[5]) > tonumber(ARGV[6]) then return -1 end
    redis.call('SADD', KEYS[4], ARGV[3])
    redis.call('HSET', KEYS[2], ARGV[3], ARGV[5])
    redis.call('INCRBY', KEYS[3], ARGV[5])
    local commands = cjson.decode(ARGV[7])
    local at = 1
    while at <= #commands do
      local count = commands[at + 1]
      redis.call(commands[at], unpack(commands, at + 2, at + 1 + count))
      at = at + 2 + count
    end
    return 1
    """


def _create_arguments(kind, request, items_total, chunk_size, owner, callback_url=None, active_limit=0, task_ids=None,
                      chunk_key=None, items_key=None, item_time_bound_s=None, job_time_limit_s=None, enqueue=None,
                      items_bytes=0, stored_bytes_limit=0) -> tuple:
    """``Creation.create``'s arguments (its parameters, defaults and order exactly: a test compares
    them), as ``_stage_create`` takes them, for ``create_async``: bound by the interpreter's call,
    not by ``inspect.Signature.bind`` at each submission."""
    return (kind, request, items_total, chunk_size, owner, callback_url, active_limit, task_ids, chunk_key, items_key,
            item_time_bound_s, job_time_limit_s, enqueue, items_bytes, stored_bytes_limit)

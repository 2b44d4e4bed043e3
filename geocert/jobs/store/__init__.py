"""Jobs in Redis: their state, request, chunk results, progress and event stream.

Shared by the API (reads, cancels, streams) and the workers (progress, results). Every key of
a job starts with ``geocert:job:{id}`` and expires ``result_ttl_s`` after the job ends.

Events form a Redis stream per job; a stream entry's id is the SSE event id, so a client that
reconnects with ``Last-Event-ID`` resumes exactly where it stopped.
"""

from __future__ import annotations

import asyncio
import hashlib
import inspect
import json
import math
import time
import uuid
import zlib
from typing import Any, AsyncIterator, Callable, Iterator

import redis
import redis.asyncio

TERMINAL = ("succeeded", "failed", "cancelled")
PUBLIC_OWNER = "public"  # the owner of every job when no API keys are configured (loopback only)
# Redis restarting, loading its append-only file or unreachable (BusyLoadingError is a ConnectionError).
REDIS_GONE = (redis.exceptions.ConnectionError, redis.exceptions.TimeoutError)
_STREAM_MAXLEN = 2000
# The workers' heartbeats (workers.heartbeat writes them; take_slot reads which workers live and
# their solver processes): here, below the workers, so that the store needs nothing of theirs.
WORKERS_KEY = "geocert:workers"  # worker name -> its last beat
SOLVERS_KEY = "geocert:workers:solvers"  # worker name -> its solver processes
FRESH_S = 10.0  # a worker whose last beat is older is gone
PAST_CLOCK_CLAIM_S = 300  # how long a claim to end a job past its clock holds (JobStore.claim_past_clock)


def now() -> float:
    return time.time()


def _shared_encoder() -> Callable[[Any], str]:
    """json.dumps with its default arguments, its text to the byte, made by one C encoder shared
    by every call: json.dumps makes a new one each call, which cost more than encoding a small
    value (a track's 16 us against 11; None's 5 us against 1). No circular check: what is stored
    was read from JSON or built of JSON types."""
    from json import encoder

    if encoder.c_make_encoder is None:  # an interpreter without the C accelerator
        return json.dumps
    make = encoder.c_make_encoder(None, encoder.JSONEncoder().default, encoder.encode_basestring_ascii, None, ": ",
                                  ", ", False, False, True)
    return lambda value: "".join(make(value, 0))


dumps = _shared_encoder()
_COMMANDS_ENCODER = json.JSONEncoder(separators=(",", ":")).encode


class StoredBytesExceeded(Exception):
    """The owner's jobs that exist would hold more than their limit with this one."""

    def __init__(self, limit: int):
        super().__init__(limit)
        self.limit = limit


class ResultGone(LookupError):
    """The job's result expired (or was deleted) while it was being read: the job is gone."""


def _text(value) -> str:
    """A command's argument as redis-py would send it, as text (bytes must be UTF-8)."""
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    raise TypeError(f"not a Redis argument: {type(value).__name__}")


class _Commands:
    """Stands where a pipeline stands for the writes of a job's creation (JobStore._stage_create):
    records each command as _CREATE takes it (its name, its argument count, its arguments, every
    one a string) instead of sending it. Only the commands that creation makes."""

    def __init__(self):
        self.arguments: list = []
        self.bulk: list[tuple] = []  # the large writes, sent as commands of their own (``BULK``)

    # _CREATE passes a command's arguments to redis.call by one Lua unpack, which takes at most
    # LUAI_MAXCSTACK (8000) values: a push of more is split.
    PUSHED_AT_ONCE = 1000
    # A SET or RPUSH of more bytes than this (a large request's text or items) is not run by the
    # script but sent as a command of its own, in a transaction with it (JobStore.create): a
    # script copies each value into Lua and back and decodes it from JSON, where Redis keeps a
    # command's argument as it read it (a 12 MB request: tens of ms of the server in the script,
    # against microseconds).
    BULK = 16 << 10

    def command(self, name: str, *args) -> None:
        self.arguments += (name, len(args), *(arg if isinstance(arg, str) else _text(arg) for arg in args))

    def text(self) -> str:
        """The commands as one JSON array (decoded by the script's cjson to the same strings): one
        argument for redis-py to pack instead of one a value, which cost it more than the rest of
        the submission's Redis work (some 80 values a 3-track job)."""
        return _COMMANDS_ENCODER(self.arguments)

    def set(self, key: str, value: str) -> None:
        if len(value) > self.BULK:
            self.bulk.append(("SET", key, value))
        else:
            self.command("SET", key, value)

    def hset(self, key: str, field: str | None = None, value: str | None = None, mapping: dict | None = None) -> None:
        pairs = [] if field is None else [field, value]
        self.command("HSET", key, *pairs, *(part for pair in (mapping or {}).items() for part in pair))

    def rpush(self, key: str, *values: str) -> None:
        if sum(map(len, values)) > self.BULK:
            self.bulk.append(("RPUSH", key, *values))
            return
        for begin in range(0, len(values), self.PUSHED_AT_ONCE):
            self.command("RPUSH", key, *values[begin:begin + self.PUSHED_AT_ONCE])

    def rename(self, source: str, target: str) -> None:
        self.command("RENAME", source, target)

    def persist(self, key: str) -> None:
        self.command("PERSIST", key)

    def zadd(self, key: str, mapping: dict) -> None:
        self.command("ZADD", key, *(part for member, score in mapping.items() for part in (float(score), member)))

    def xadd(self, key: str, fields: dict, maxlen: int, approximate: bool = True) -> None:
        self.command("XADD", key, "MAXLEN", *(("~",) if approximate else ()), maxlen, "*",
                     *(part for pair in fields.items() for part in pair))


class JobStore:
    def __init__(self, client: redis.Redis, result_ttl_s: int = 7 * 24 * 3600):
        self.r = client
        self.ttl = result_ttl_s
        # The same server without decoding, for the values kept compressed (results).
        pool = client.connection_pool
        self.binary = redis.Redis(connection_pool=redis.ConnectionPool(
            connection_class=pool.connection_class, **{**pool.connection_kwargs, "decode_responses": False}))

    @classmethod
    def from_url(cls, url: str, result_ttl_s: int = 7 * 24 * 3600, **options: Any) -> "JobStore":
        return cls(redis.Redis.from_url(url, decode_responses=True, **options), result_ttl_s)

    @staticmethod
    def key(job_id: str, part: str = "") -> str:
        return f"geocert:job:{job_id}" + (f":{part}" if part else "")

    # --- creation and reads ------------------------------------------------------------------
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
        ``chunk_key``). Those entries are kept one per element of a Redis list beside the rest of
        the request, so that a task reads its own items (``chunk_request``), not the whole request:
        read traffic stays about the request's size whatever the number of chunks.

        ``items_key``: a Redis list already holding those entries' JSON texts (a large body's
        items, written a batch at a time: app.streamed); it becomes the job's item list, and the
        request's own list is ignored.

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
        bound = _CREATE_SIGNATURE.bind(self, *args, **kwargs)
        bound.apply_defaults()
        meta, keys, script_args, bulk = self._stage_create(*bound.args[1:])
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
        return self._admitted(meta, admitted, bound.arguments["stored_bytes_limit"])

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
        request_bytes = self._put_request(pipe, job_id, request, chunk_key, items_key) + items_bytes
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

    def get(self, job_id: str) -> dict | None:
        raw = self.r.hgetall(self.key(job_id))
        if not raw:
            return None
        return {k: json.loads(v) for k, v in raw.items()}

    def field(self, job_id: str, name: str) -> Any:
        raw = self.r.hget(self.key(job_id), name)
        return None if raw is None else json.loads(raw)

    _SET_IF_EXISTS = """
    if redis.call('EXISTS', KEYS[1]) == 0 then return 0 end
    redis.call('HSET', KEYS[1], unpack(ARGV))
    return 1
    """

    def set_fields(self, job_id: str, **fields: Any) -> bool:
        """Set fields of an existing job (False: it is gone, e.g. deleted while a webhook was being
        delivered, and nothing is written: an HSET would re-create it without an expiry)."""
        pairs = [part for name, value in fields.items() for part in (name, dumps(value))]
        return bool(self.r.eval(self._SET_IF_EXISTS, 1, self.key(job_id), *pairs))

    _SUMMARY = ("id", "kind", "status", "created_at", "started_at", "finished_at", "progress")

    def summary(self, meta: dict) -> dict:
        """The job as a listing shows it: its state and progress, no result."""
        return {key: meta.get(key) for key in self._SUMMARY} | {"links": self.links(meta["id"])}

    def document(self, meta: dict) -> dict:
        """The job as the API shows it (and as webhooks deliver it)."""
        document = {key: meta.get(key) for key in self._SUMMARY + ("error", "webhook")}
        document["result"] = self.result(meta["id"], meta) if meta["status"] in TERMINAL else None
        document["links"] = self.links(meta["id"])
        return document

    @staticmethod
    def links(job_id: str) -> dict:
        base = f"/v1/jobs/{job_id}"
        return {"self": base, "events": f"{base}/events", "cancel": f"{base}/cancel"}

    # The list lives as long as its job: not written for a job that is gone, and given the job's
    # expiry when the job has one (it has ended).
    _ADD_TASK_IDS = """
    local ttl = redis.call('TTL', KEYS[1])
    if ttl == -2 then return 0 end
    redis.call('RPUSH', KEYS[2], unpack(ARGV))
    if ttl > 0 then redis.call('EXPIRE', KEYS[2], ttl) end
    return 1
    """

    def add_task_ids(self, job_id: str, *task_ids: str) -> None:
        if task_ids:
            self.r.eval(self._ADD_TASK_IDS, 2, self.key(job_id), self.key(job_id, "tasks"), *task_ids)

    def task_ids(self, job_id: str) -> list[str]:
        return self.r.lrange(self.key(job_id, "tasks"), 0, -1)

    # --- the request, whole or by chunk ------------------------------------------------------
    # A request whose items sit in ``data[chunk_key]`` is kept as its head (that list replaced by
    # a placeholder naming the job) and its items, one JSON text per element of a list; written
    # with json.dumps's separators, so the whole request's text is rebuilt byte for byte.

    @staticmethod
    def _placeholder(job_id: str) -> str:
        return dumps(f"geocert-items-{job_id}")

    _ITEMS_PER_PUSH = 10_000

    def _put_request(self, pipe, job_id: str, request: dict, chunk_key: str | None, items_key: str | None) -> int:
        """Queue the request's writes on ``pipe``; the bytes written (not those of ``items_key``)."""
        data = request.get("data")
        items = data.get(chunk_key) if chunk_key and isinstance(data, dict) else None
        if (not isinstance(items, list) or not items) and items_key is None:
            text = dumps(request)
            pipe.set(self.key(job_id, "request"), text)
            return len(text)
        head = dumps({**request, "data": {**data, chunk_key: f"geocert-items-{job_id}"}})
        pipe.set(self.key(job_id, "request"), head)
        pipe.hset(self.key(job_id), "request_items", dumps(chunk_key))
        if items_key is not None:
            pipe.rename(items_key, self.key(job_id, "request:items"))
            pipe.persist(self.key(job_id, "request:items"))  # the job's keys expire when it ends
            return len(head)
        written = len(head)
        for begin in range(0, len(items), self._ITEMS_PER_PUSH):
            texts = [dumps(item) for item in items[begin:begin + self._ITEMS_PER_PUSH]]
            written += sum(map(len, texts))
            pipe.rpush(self.key(job_id, "request:items"), *texts)
        return written

    def request_text(self, job_id: str) -> str | None:
        """The job as submitted, as JSON text (None when no request is kept)."""
        pipe = self.r.pipeline()
        pipe.get(self.key(job_id, "request"))
        pipe.hget(self.key(job_id), "request_items")
        head, chunk_key = pipe.execute()
        if head is None or chunk_key is None:
            return head
        items = self.r.lrange(self.key(job_id, "request:items"), 0, -1)
        return head.replace(self._placeholder(job_id), "[" + ", ".join(items) + "]", 1)

    def request(self, job_id: str) -> dict:
        return json.loads(self.request_text(job_id))

    def chunk_request(self, job_id: str, start: int, stop: int) -> dict:
        """The request with only items ``start`` to ``stop - 1`` of its item list read (the
        others None, indices unchanged): what a task solving that chunk needs. The whole request
        when its items are not kept apart."""
        pipe = self.r.pipeline()
        self._read_chunk(pipe, job_id, start, stop)
        return self._chunk(start, *pipe.execute())

    def _read_chunk(self, pipe, job_id: str, start: int, stop: int) -> None:
        pipe.get(self.key(job_id, "request"))
        pipe.hget(self.key(job_id), "request_items")
        pipe.llen(self.key(job_id, "request:items"))
        # An empty range reads nothing: LRANGE's stop -1 (for start 0) would read to the list's end.
        pipe.lrange(self.key(job_id, "request:items"), *((start, stop - 1) if stop > start else (1, 0)))

    @staticmethod
    def _chunk(start: int, head: str, chunk_key: str | None, total: int, items: list[str]) -> dict:
        request = json.loads(head)
        if chunk_key is not None:
            chunk_key = json.loads(chunk_key)
            request["data"][chunk_key] = ([None] * start + [json.loads(item) for item in items]
                                          + [None] * max(0, total - start - len(items)))
        return request

    def fields(self, job_id: str, *names: str) -> dict | None:
        """Some fields of the job (None when there is no such job): a task reads these, not the
        whole record (whose chunk list grows with the job)."""
        raw = self.r.hmget(self.key(job_id), "status", *names)
        return None if raw[0] is None else self._decoded(("status",) + names, raw)

    @staticmethod
    def _decoded(names, raw) -> dict:
        return {name: None if value is None else json.loads(value) for name, value in zip(names, raw)}

    def result(self, job_id: str, meta: dict | None = None) -> dict | None:
        text = self.result_text(job_id, meta)
        return None if text is None else json.loads(text)

    # A result is kept compressed (zlib, marked by the job's ``result_encoding``): a track's
    # result is about 12 times its request, so the stored result is most of what a job leaves in
    # Redis for result_ttl_s and most of what every read of it moves; compressed it is about a
    # quarter (measured: 358 MiB of JSON kept as 95 MiB for 200,000 tracks).
    RESULT_COMPRESSION_LEVEL = 1  # zlib's fastest: most of the gain at a few ms per MB

    def _encoding(self, job_id: str, meta: dict | None) -> str | None:
        """How the job's result is stored: "zlib" (compressed), "zlib-fragments" (a streamed
        result: save_fragment), None (plain JSON, stored before results were compressed)."""
        return meta.get("result_encoding") if meta is not None else self.field(job_id, "result_encoding")

    EAGER_FRAGMENTS = 64  # a streamed result of at most this many fragments is read in one command
    RESULT_PIECE_BYTES = 1 << 16  # compressed bytes read at a time when a result is sent (about 4x that decompressed)

    def result_pieces(self, job_id: str, meta: dict | None = None) -> Iterator[bytes] | None:
        """The stored result's JSON text as UTF-8 pieces, read and decompressed a piece at a
        time (GETRANGE), so that sending a large result holds one piece, not the whole (None
        when there is none). A result removed while it is read ends with an error."""
        key = self.key(job_id, "result")
        encoding = self._encoding(job_id, meta)
        if encoding == "zlib-fragments":
            return self._fragment_pieces(job_id)
        if encoding != "zlib":
            text = self.r.get(key)
            return None if text is None else iter([text.encode()])
        length = self.binary.strlen(key)
        if not length:
            return None
        if length <= self.RESULT_PIECE_BYTES:
            # Read whole before anything is sent: a result that expires between STRLEN and its
            # read is then a job that is gone (ResultGone: a 404), not a response cut short.
            raw = self.binary.get(key)
            if raw is None:
                raise ResultGone(job_id)
            return iter([zlib.decompress(raw)])

        def pieces() -> Iterator[bytes]:
            decompressor = zlib.decompressobj()
            for start in range(0, length, self.RESULT_PIECE_BYTES):
                yield decompressor.decompress(self.binary.getrange(key, start, start + self.RESULT_PIECE_BYTES - 1))
            yield decompressor.flush()
            if not decompressor.eof:
                raise RuntimeError(f"the result of job {job_id} changed while it was sent")

        return pieces()

    def _fragment_pieces(self, job_id: str) -> Iterator[bytes] | None:
        raw = self.binary.get(self.key(job_id, "result"))
        if raw is None:
            return None
        head, tail, starts = json.loads(zlib.decompress(raw))
        if len(starts) <= self.EAGER_FRAGMENTS:
            # A result of few fragments is read whole (one HMGET) before anything is sent, so
            # that one expiring meanwhile is a job that is gone, not a response cut short.
            fragments = self.binary.hmget(self.key(job_id, "fragments"), [str(start) for start in starts])
            if any(fragment is None for fragment in fragments):
                raise ResultGone(job_id)
            return iter([head.encode(), b",".join(zlib.decompress(f) for f in fragments), tail.encode()])

        def pieces() -> Iterator[bytes]:
            yield head.encode()
            for number, start in enumerate(starts):
                fragment = self.binary.hget(self.key(job_id, "fragments"), str(start))
                if fragment is None:
                    raise RuntimeError(f"the result of job {job_id} was removed while it was sent")
                yield (b"," if number else b"") + zlib.decompress(fragment)
            yield tail.encode()

        return pieces()

    def result_text(self, job_id: str, meta: dict | None = None) -> str | None:
        """The stored result as JSON text (None when there is none), read in one piece."""
        encoding = self._encoding(job_id, meta)
        if encoding == "zlib-fragments":
            try:
                pieces = self._fragment_pieces(job_id)
            except ResultGone:
                return None
            return None if pieces is None else b"".join(pieces).decode()
        if encoding == "zlib":
            raw = self.binary.get(self.key(job_id, "result"))
            return None if raw is None else zlib.decompress(raw).decode()
        return self.r.get(self.key(job_id, "result"))  # stored before results were compressed

    # --- events ------------------------------------------------------------------------------
    def publish(self, job_id: str, event: str, data: dict, pipe=None) -> str | None:
        """Append an event to the job's stream; returns its id (None when added to ``pipe``)."""
        return (pipe or self.r).xadd(self.key(job_id, "events"), {"event": event, "data": dumps(data)},
                                     maxlen=_STREAM_MAXLEN, approximate=True)

    # --- cancellation ------------------------------------------------------------------------
    def request_cancel(self, job_id: str) -> None:
        self.r.set(self.key(job_id, "cancel"), "1", ex=self.ttl)

    def cancel_if_queued(self, job_id: str) -> bool:
        """Queued -> cancelled atomically (so a worker cannot start it meanwhile); True if done.
        The one way a job ends other than ``end``: nothing of it ran, so there is nothing to store."""
        script = """
        if redis.call('HGET', KEYS[1], 'status') ~= '"queued"' then return 0 end
        redis.call('HSET', KEYS[1], 'status', '"cancelled"', 'finished_at', ARGV[1])
        redis.call('XADD', KEYS[2], 'MAXLEN', '~', ARGV[2], '*', 'event', 'end', 'data', ARGV[3])
        for i = 3, #KEYS do redis.call('EXPIRE', KEYS[i], ARGV[4]) end
        return 1
        """
        keys = [self.key(job_id), self.key(job_id, "events"), *(self.key(job_id, part) for part in self._PARTS)]
        if self.r.eval(script, len(keys), *keys, dumps(now()), _STREAM_MAXLEN,
                       dumps({"status": "cancelled", "error": None}), self.ttl) != 1:
            return False
        self.release(self.field(job_id, "owner") or "", job_id)
        return True

    def cancel_requested(self, job_id: str) -> bool:
        return bool(self.r.exists(self.key(job_id, "cancel")))

    # --- worker side -------------------------------------------------------------------------
    # Queued -> running once, with its status event (1); running already (2); ended or gone (0).
    # A job queued or running is touched (its task shows life: the reaper reads RUNNING), and the
    # task starting it, when named, counted among its busy ones (``claim_past_clock``). A job with
    # a clock in all (job_time_limit_s) has its deadline kept in DEADLINES from its start.
    _MARK_RUNNING = """
    local s = redis.call('HGET', KEYS[1], 'status')
    local answer = 0
    if s == '"queued"' then
        redis.call('HSET', KEYS[1], 'status', '"running"', 'started_at', ARGV[1])
        redis.call('XADD', KEYS[2], 'MAXLEN', '~', ARGV[2], '*', 'event', 'status', 'data', ARGV[3])
        local limit = tonumber(redis.call('HGET', KEYS[1], 'job_time_limit_s'))
        if limit then redis.call('ZADD', KEYS[4], tonumber(ARGV[1]) + limit, ARGV[5]) end
        answer = 1
    elseif s == '"running"' then answer = 2 end
    if answer ~= 0 then
        redis.call('ZADD', KEYS[3], ARGV[4], ARGV[5])
        if ARGV[6] ~= '' then redis.call('SADD', KEYS[5], ARGV[6]) end
    end
    return answer
    """

    def _mark_running(self, client, job_id: str, task_id: str | None = None):
        """_MARK_RUNNING run by ``client`` (its answer) or queued on a pipeline."""
        moment = now()
        return client.eval(self._MARK_RUNNING, 5, self.key(job_id), self.key(job_id, "events"), self.RUNNING,
                           self.DEADLINES, self.key(job_id, "busy"),
                           dumps(moment), _STREAM_MAXLEN, dumps({"status": "running"}), moment, job_id,
                           task_id or "")

    def mark_running(self, job_id: str) -> bool:
        """Queued -> running, once; False when the job already ended (e.g. cancelled while queued)."""
        return self._mark_running(self.r, job_id) != 0

    def start_chunk(self, job_id: str, start: int, stop: int, *names: str,
                    task_id: str | None = None) -> tuple[dict, dict] | None:
        """What a task needs to start items ``start`` to ``stop - 1``, in one round trip: the job's
        fields ``names`` (as ``fields``), the job marked running (as ``mark_running``, the task
        ``task_id`` counted busy on it until it ``leave``s) and the chunk's request (as
        ``chunk_request``). None when the job is gone or has ended."""
        pipe = self.r.pipeline()
        pipe.hmget(self.key(job_id), "status", *names)
        self._mark_running(pipe, job_id, task_id)
        self._read_chunk(pipe, job_id, start, stop)
        raw, running, *chunk = pipe.execute()
        if raw[0] is None or not running or chunk[0] is None:
            return None
        return self._decoded(("status",) + names, raw), self._chunk(start, *chunk)

    RUNNING = "geocert:running"  # running job id -> the last time a task of it showed life
    DEADLINES = "geocert:deadlines"  # running job id -> when its clock in all (job_time_limit_s) runs out

    def leave(self, job_id: str, task_id: str) -> None:
        """The task ``task_id`` no longer works on the job (its items stored, or it stopped)."""
        self.r.srem(self.key(job_id, "busy"), task_id)

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
        moment = now()
        return bool(self.r.eval(self._CLAIM_PAST_CLOCK, 5, self.key(job_id), self.key(job_id, "busy"), self.DEADLINES,
                                self.SLOTS, self.key(job_id, "final"), job_id, moment, moment - self.SLOT_LAPSE_S,
                                min(self.ttl, PAST_CLOCK_CLAIM_S)))

    def past_clock(self) -> list[str]:
        """The running jobs whose clock in all has run out."""
        return self.r.zrangebyscore(self.DEADLINES, "-inf", now())

    # Solver slots: the solve tasks running, each by its task id, with the last sign of its
    # life (renewed by its worker's heartbeat) and its job's owner. A key holds at most every live
    # solver process (the workers' heartbeats say how many) but ``kept_for_others``, and at
    # least one; a slot not renewed for SLOT_LAPSE_S (its worker gone) lapses. Without keys
    # (every job PUBLIC_OWNER's: one user, on loopback) there is no one to keep solvers for: a
    # short job then runs beside a long one as the solvers allow.
    SLOTS = "geocert:slots"
    SLOT_OWNERS = "geocert:slots:owners"
    SLOT_LAPSE_S = 30.0
    _TAKE_SLOT = """
    local owner = redis.call('HGET', KEYS[5], 'owner')
    if not owner then return 1 end
    for _, id in ipairs(redis.call('ZRANGEBYSCORE', KEYS[1], '-inf', ARGV[3])) do
        redis.call('ZREM', KEYS[1], id)
        redis.call('HDEL', KEYS[2], id)
    end
    if redis.call('ZSCORE', KEYS[1], ARGV[1]) then
        redis.call('ZADD', KEYS[1], ARGV[2], ARGV[1])
        return 1
    end
    local kept = tonumber(ARGV[5])
    if kept > 0 and owner ~= ARGV[6] then
        local solvers = 0
        local names = redis.call('ZRANGEBYSCORE', KEYS[3], ARGV[4], '+inf')
        if #names > 0 then
            for _, n in ipairs(redis.call('HMGET', KEYS[4], unpack(names))) do solvers = solvers + (tonumber(n) or 0) end
        end
        if solvers > 0 then
            local held = 0
            for _, o in ipairs(redis.call('HVALS', KEYS[2])) do if o == owner then held = held + 1 end end
            if held >= math.max(1, solvers - kept) then return 0 end
        end
    end
    redis.call('ZADD', KEYS[1], ARGV[2], ARGV[1])
    redis.call('HSET', KEYS[2], ARGV[1], owner)
    return 1
    """

    def take_slot(self, job_id: str, slot: str, kept_for_others: int) -> bool:
        """Take a solver slot for a task of this job (True), unless the job's key holds its share
        already (False: the task waits). A job that is gone takes one (its task finds it gone)."""
        moment = now()
        return bool(self.r.eval(self._TAKE_SLOT, 5, self.SLOTS, self.SLOT_OWNERS, WORKERS_KEY, SOLVERS_KEY, self.key(job_id),
                                slot, moment, moment - self.SLOT_LAPSE_S, moment - FRESH_S, kept_for_others,
                                dumps(PUBLIC_OWNER)))

    def free_slot(self, slot: str) -> None:
        pipe = self.r.pipeline()
        pipe.zrem(self.SLOTS, slot)
        pipe.hdel(self.SLOT_OWNERS, slot)
        pipe.execute()

    # Webhook deliveries in flight, per API key: a sorted set per key (its deliveries' task ids,
    # scored by when each was taken). An entry older than ARGV[3] (its webhook worker gone) lapses,
    # and so does the whole set when no delivery takes a place in it (EXPIRE).
    _TAKE_DELIVERY = """
    redis.call('ZREMRANGEBYSCORE', KEYS[1], '-inf', ARGV[3])
    if not redis.call('ZSCORE', KEYS[1], ARGV[1]) and redis.call('ZCARD', KEYS[1]) >= tonumber(ARGV[4]) then
      return 0
    end
    redis.call('ZADD', KEYS[1], ARGV[2], ARGV[1])
    redis.call('EXPIRE', KEYS[1], ARGV[5])
    return 1
    """

    def take_delivery(self, owner: str, delivery: str, share: int, lapse_s: float) -> bool:
        """Take one of ``owner``'s ``share`` places for a webhook delivery (True), unless its
        deliveries hold them all; one not freed lapses after ``lapse_s``."""
        moment = now()
        return bool(self.r.eval(self._TAKE_DELIVERY, 1, self.owner_key(owner, "deliveries"), delivery, moment,
                                moment - lapse_s, share, max(1, math.ceil(lapse_s))))

    def free_delivery(self, owner: str, delivery: str) -> None:
        self.r.zrem(self.owner_key(owner, "deliveries"), delivery)

    def touch(self, job_id: str) -> None:
        """A task of this job is alive (read by the reaper, ``workers.reaper``)."""
        self.r.zadd(self.RUNNING, {job_id: now()})

    def stale_running(self, older_than_s: float) -> list[str]:
        return self.r.zrangebyscore(self.RUNNING, "-inf", now() - older_than_s)

    def missing_items(self, job_id: str, total: int) -> list[int]:
        stored = set(self.r.hkeys(self.key(job_id, "items")))
        return [index for index in range(total) if str(index) not in stored]

    def reopen_end(self, job_id: str) -> None:
        """Drop a claim to end the job whose holder is gone (the job is running but nobody moves)."""
        self.r.delete(self.key(job_id, "final"))

    # The job's progress sums its tasks' progress (and takes the worst gap): each task's last
    # figures are kept, and the sums moved by the change, in Redis, so that storing a task's
    # progress costs the same however many chunks the job has (reading every task's progress at
    # every save made a large job's traffic grow with the square of its chunks).
    # "bounded" counts the tasks whose progress has bounds: with none, the bounds are null (a
    # reconstruction's stages, or a search not started), not the 0 or rounding residue the sums
    # hold (1e-17 once a stage's bounds were added and taken away again), which a chart would draw.
    _SUMS = ("nodes", "open_boxes", "lower_bound", "upper_bound", "gap_abs", "bounded")
    _ADD_PROGRESS = """
    local status = redis.call('HGET', KEYS[4], 'status')
    if status ~= '"queued"' and status ~= '"running"' then return false end
    local old = redis.call('HGET', KEYS[1], ARGV[1])
    redis.call('HSET', KEYS[1], ARGV[1], ARGV[2])
    local before = {}
    if old then for v in string.gmatch(old, '[^,]+') do table.insert(before, tonumber(v)) end end
    local i = 0
    for v in string.gmatch(ARGV[2], '[^,]+') do
        i = i + 1
        local change = tonumber(v) - (before[i] or 0)
        if change ~= 0 then redis.call('HINCRBYFLOAT', KEYS[2], ARGV[2 + i], change) end
    end
    if ARGV[9] == '' then redis.call('ZREM', KEYS[3], ARGV[1]) else redis.call('ZADD', KEYS[3], ARGV[9], ARGV[1]) end
    local sums = redis.call('HMGET', KEYS[2], ARGV[3], ARGV[4], ARGV[5], ARGV[6], ARGV[7], ARGV[8])
    local worst = redis.call('ZREVRANGE', KEYS[3], 0, 0, 'WITHSCORES')
    return {sums, worst}
    """

    def save_progress(self, job_id: str, start: int, progress: dict, items: dict[int, dict] | None = None,
                      fragment: tuple[int, dict, str] | None = None) -> dict | None:
        """Store the items given (index -> item) and the progress of the task that started at item
        ``start``, and return (and publish) the job's aggregate over all its tasks. Its
        ``items_done`` is the number of items stored, read after this call's items are written:
        progress never counts an item whose result is not stored (a task that dies loses only
        items it had not counted). ``fragment``: see save_fragment (written in the same
        transaction, so whoever sees the last item counted sees its fragment too). None, writing
        nothing, once the job has ended or is gone (``_SAVE``)."""
        bounded = progress.get("lower_bound") is not None and progress.get("upper_bound") is not None
        figures = ",".join(repr(float(v)) if math.isfinite(v := float(progress.get(name) or 0.0)) else "0.0"
                           for name in self._SUMS[:-1]) + (",1.0" if bounded else ",0.0")
        gap = progress.get("gap_rel")
        pipe = self.r.pipeline()  # one round trip for the writes and reads, one for the aggregate
        self._save(pipe, job_id, items or {}, fragment)
        pipe.eval(self._ADD_PROGRESS, 4, self.key(job_id, "chunkprogress"), self.key(job_id, "progressparts"),
                  self.key(job_id, "gaps"), self.key(job_id), str(start), figures, *self._SUMS,
                  repr(float(gap)) if gap is not None and math.isfinite(gap) else "")
        pipe.hmget(self.key(job_id), "items_total", "started_at")
        done, added, (raw_total, raw_started) = pipe.execute()
        if done is None or added is None:
            return None  # the job has ended (or is gone): nothing was written
        sums, worst = added
        total = None if raw_total is None else json.loads(raw_total)
        started = (None if raw_started is None else json.loads(raw_started)) or now()
        sums = [float(v) if v is not None else 0.0 for v in sums]
        bounded = sums[5] > 0.5
        aggregate = {
            "nodes": int(round(sums[0])),
            "open_boxes": int(round(sums[1])),
            "lower_bound": sums[2] if bounded else None,
            "upper_bound": sums[3] if bounded else None,
            "gap_abs": sums[4] if bounded else None,
            "gap_rel": float(worst[1]) if worst else None,
            "items_done": done,
            "items_total": total,
            "tracks_done": done,  # deprecated names of items_done and items_total
            "tracks_total": total,
            "elapsed_s": now() - started,
        }
        # A staged solve (autocalibration) says which stage runs: the latest task's.
        if progress.get("stage"):
            aggregate["stage"] = progress["stage"]
        return aggregate if self.publish_progress(job_id, aggregate) else None

    # What a task writes into its job, only while the job is queued or running: a task still
    # running after its job ended (failed by another task, or deleted since) writes nothing, where
    # it used to re-create the job's keys without an expiry. Items are index -> packed item pairs.
    _SAVE = """
    local status = redis.call('HGET', KEYS[1], 'status')
    if status ~= '"queued"' and status ~= '"running"' then return false end
    local last = 3 + 2 * tonumber(ARGV[3])
    for first = 4, last, 2000 do
        redis.call('HSET', KEYS[2], unpack(ARGV, first, math.min(first + 1999, last)))
    end
    if ARGV[last + 1] ~= '' then
        redis.call('HSET', KEYS[3], ARGV[last + 1], ARGV[last + 2])
        redis.call('HSET', KEYS[4], ARGV[last + 1], ARGV[last + 3])
    end
    redis.call('ZADD', KEYS[5], ARGV[2], ARGV[1])
    return redis.call('HLEN', KEYS[2])
    """

    def _save(self, pipe, job_id: str, items: dict[int, dict], fragment: tuple[int, dict, str] | None) -> None:
        """Queue ``_SAVE`` on ``pipe``: its answer is the number of the job's items stored, or None."""
        pairs = [part for pair in self._packed(items).items() for part in pair]
        extra = ("",) if fragment is None else (
            str(fragment[0]), zlib.compress(fragment[2].encode(), self.RESULT_COMPRESSION_LEVEL), dumps(fragment[1]))
        pipe.eval(self._SAVE, 5, self.key(job_id), self.key(job_id, "items"), self.key(job_id, "fragments"),
                  self.key(job_id, "fragmentsums"), self.RUNNING, job_id, now(), len(items), *pairs, *extra)

    def save_items(self, job_id: str, items: dict[int, dict], fragment: tuple[int, dict, str] | None = None) -> int | None:
        """Store items (index -> item; idempotent: a redelivered task overwrites the same fields,
        so nothing is counted twice), and a fragment (save_fragment); returns how many items of
        the job are stored (None, writing nothing, once the job has ended or is gone)."""
        pipe = self.r.pipeline()
        self._save(pipe, job_id, items, fragment)
        return pipe.execute()[0]

    # A streamed result (batch.streams_result) is kept as its tasks wrote it: each task's run of
    # items as one compressed fragment of the result's JSON (keyed by its first index), with the
    # sums the end needs (batch.item_sums). The end then reads those sums, not the items, and the
    # result is read a fragment at a time when it is sent: a large job's result is read once.
    def save_fragment(self, job_id: str, start: int, sums: dict, text: str) -> None:
        """Store the fragment of the result holding items ``start`` to ``start + sums["items"] - 1``
        (a redelivered task overwrites its own)."""
        self.save_items(job_id, {}, (start, sums, text))

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
                                dumps(progress), _STREAM_MAXLEN))

    def fragment_plan(self, job_id: str, total: int) -> list[tuple[int, dict]] | None:
        """The fragments that hold items 0 to ``total - 1`` once each, in order, with their sums;
        None when the stored ones do not (a task redelivered with another split, a chunk queued
        again by the reaper, an item stored without its fragment): the end then reads every item."""
        stored = {int(start): json.loads(sums) for start, sums in self.r.hgetall(self.key(job_id, "fragmentsums")).items()}
        plan, at = [], 0
        while at < total:
            sums = stored.get(at)
            if sums is None or sums["items"] < 1:
                return None
            plan.append((at, sums))
            at += sums["items"]
        return plan if at == total else None

    _CLAIM_END = """
    local status = redis.call('HGET', KEYS[1], 'status')
    if status ~= '"queued"' and status ~= '"running"' then return 0 end
    if redis.call('SET', KEYS[2], '1', 'NX', 'EX', ARGV[1]) then return 1 end
    return 0
    """

    def claim_end(self, job_id: str) -> bool:
        """Become the one caller that ends this job (``end``): the task that stored its last items,
        or one that failed; False when another already has the claim, or the job has ended or is
        gone (deleted: ending it would write it again)."""
        return bool(self.r.eval(self._CLAIM_END, 2, self.key(job_id), self.key(job_id, "final"), self.ttl))

    # Items wait in Redis compressed too, one by one (zlib; an item stored as JSON text by an
    # earlier version starts with "{" and is read as it is): the end reads them all. An item is
    # a few hundred bytes to a few KB: a 4 KB window and a small memory level compress it as
    # well as zlib.compress's defaults (32 KB, level 8), whose set-up costs several times the
    # compression itself (measured on a 272-byte track: 49 us a call against 7.6 us, both 168
    # bytes); zlib.decompress reads either.
    ITEM_WINDOW_BITS, ITEM_MEMORY_LEVEL = 12, 4

    def _packed(self, items: dict[int, dict]) -> dict[str, bytes]:
        return {str(i): self._compressed_item(dumps(item).encode()) for i, item in items.items()}

    @classmethod
    def _compressed_item(cls, text: bytes) -> bytes:
        packer = zlib.compressobj(cls.RESULT_COMPRESSION_LEVEL, zlib.DEFLATED, cls.ITEM_WINDOW_BITS,
                                  cls.ITEM_MEMORY_LEVEL)
        return packer.compress(text) + packer.flush()

    @staticmethod
    def _unpacked(raw: bytes) -> dict:
        return json.loads(raw if raw[:1] == b"{" else zlib.decompress(raw))

    def stored_items(self, job_id: str) -> dict[int, dict]:
        """The items stored so far, by index (a job that fails keeps these)."""
        return {int(index): self._unpacked(raw) for index, raw in self.binary.hgetall(self.key(job_id, "items")).items()}

    def all_items(self, job_id: str, total: int) -> list[dict]:
        raw = self.binary.hgetall(self.key(job_id, "items"))
        return [self._unpacked(raw[str(index).encode()]) for index in range(total)]

    def end(self, job_id: str, status: str, result: dict | None = None, error: dict | None = None,
            result_text: str | None = None, fragments: tuple[str, str, list[int]] | None = None) -> None:
        """The job ends (the caller holds ``claim_end``): its status becomes ``status`` (one of
        TERMINAL) with its result or error, its working state is dropped, the end event is
        published and every key of it expires ``result_ttl_s`` from now. ``result_text``: the
        result as its kind's model writes it (``batch.result_json``), stored in place of our own
        JSON of ``result`` and marked so (``result_form``) for the API to send as it is.
        ``fragments`` (head, tail, first indices): the result is the stored fragments between
        that head and tail (batch.result_shell), kept as they are."""
        pipe = self.r.pipeline()
        if fragments is not None:
            pipe.set(self.key(job_id, "result"), zlib.compress(dumps(list(fragments)).encode()))
            pipe.hset(self.key(job_id), mapping={"result_form": dumps("model"),
                                                  "result_encoding": dumps("zlib-fragments")})
        elif result is not None:
            if result_text is not None:
                pipe.hset(self.key(job_id), "result_form", dumps("model"))
            text = result_text if result_text is not None else dumps(result)
            pipe.set(self.key(job_id, "result"), zlib.compress(text.encode(), self.RESULT_COMPRESSION_LEVEL))
            pipe.hset(self.key(job_id), "result_encoding", dumps("zlib"))
        pipe.hset(self.key(job_id), mapping={"status": dumps(status), "finished_at": dumps(now()),
                                              "error": dumps(error)})
        pipe.delete(self.key(job_id, "items"), self.key(job_id, "chunkprogress"), self.key(job_id, "progressparts"),
                    self.key(job_id, "gaps"), self.key(job_id, "fragmentsums"))
        if fragments is None:
            pipe.delete(self.key(job_id, "fragments"))
        owner = self.field(job_id, "owner") or ""
        pipe.srem(self.owner_key(owner, "active"), job_id)
        pipe.zrem(self.RUNNING, job_id)
        pipe.zrem(self.DEADLINES, job_id)
        pipe.eval(self._COUNT_RESULT, 4, self.key(job_id, "result"), self.key(job_id, "fragments"),
                  *self._accounts(owner)[1:], job_id)
        self._announce_end(job_id, status, error, pipe)
        pipe.execute()

    def _announce_end(self, job_id: str, status: str, error: dict | None, pipe) -> None:
        """Queue on ``pipe`` the end event and every key's expiry (with the end itself, in one
        transaction: a job deleted as soon as it showed as ended is never written again)."""
        self.publish(job_id, "end", {"status": status, "error": error}, pipe)
        for part in self._PARTS:
            pipe.expire(self.key(job_id, part), self.ttl)

    _PARTS = ("", "request", "request:items", "result", "events", "cancel", "final", "items", "chunkprogress",
              "progressparts", "gaps", "tasks", "fragments", "fragmentsums", "busy")

    def delete(self, job_id: str) -> None:
        owner = self.field(job_id, "owner")
        pipe = self.r.pipeline()
        self._stage_delete(pipe, job_id, owner)
        pipe.execute()

    def _stage_delete(self, pipe, job_id: str, owner: str | None) -> None:
        pipe.delete(*(self.key(job_id, part) for part in self._PARTS))
        pipe.zrem(self.RUNNING, job_id)
        pipe.zrem(self.DEADLINES, job_id)
        if owner is not None:
            pipe.eval(self._FORGET, 3, *self._accounts(owner), job_id)

    # --- listing -----------------------------------------------------------------------------
    def list_jobs(self, owner: str, limit: int, after: tuple[float, str] | None = None,
                  statuses: tuple[str, ...] | None = None) -> tuple[list[dict], tuple[float, str] | None]:
        """The owner's jobs, newest first: up to ``limit`` after the position ``after`` (the
        created time and id of the last job of the previous page), only those whose status is in
        ``statuses`` when given. Returns the jobs and the position to continue after (None when
        no job follows). The index is a sorted set per owner (created time -> id), written on
        create and delete; ids whose job expired are dropped from it here, when met."""
        index = self.owner_key(owner, "jobs")
        top = "+inf" if after is None else repr(after[0])
        found: list[tuple[float, str, dict]] = []
        gone: list[str] = []
        offset, batch = 0, max(2 * limit + 2, 50)
        while len(found) <= limit:
            entries = self.r.zrevrangebyscore(index, top, "-inf", start=offset, num=batch, withscores=True)
            if not entries:
                break
            offset += len(entries)
            pipe = self.r.pipeline()
            for job_id, _ in entries:
                pipe.hgetall(self.key(job_id))
            for (job_id, score), raw in zip(entries, pipe.execute()):
                # Equal times are ordered by id, descending: skip up to and including ``after``.
                if after is not None and score == after[0] and job_id >= after[1]:
                    continue
                if not raw:
                    gone.append(job_id)
                    continue
                meta = {k: json.loads(v) for k, v in raw.items()}
                if statuses and meta["status"] not in statuses:
                    continue
                found.append((score, job_id, meta))
                if len(found) > limit:
                    break
        if gone:
            pipe = self.r.pipeline()
            for job_id in gone:
                pipe.eval(self._FORGET, 3, *self._accounts(owner), job_id)
            pipe.execute()
        following = (found[limit - 1][0], found[limit - 1][1]) if len(found) > limit else None
        return [meta for _, _, meta in found[:limit]], following

    # --- per-key accounting ------------------------------------------------------------------
    @staticmethod
    def owner_key(owner: str, part: str) -> str:
        return f"geocert:owner:{owner}:{part}"

    # An owner's accounts of its jobs that exist: the index (created time -> id), each job's
    # bytes, and their sum. A job leaves them when deleted, when a listing meets it expired, and
    # when a submission of its owner finds it expired among the index's ARGV[2] oldest entries
    # (_CREATE: so a key that never lists keeps about its jobs that exist, not every job it made).
    def _accounts(self, owner: str) -> tuple[str, str, str]:
        return self.owner_key(owner, "jobs"), self.owner_key(owner, "stored"), self.owner_key(owner, "stored_bytes")

    PRUNED_PER_JOB = 8
    STORED_BYTES_FLOOR = 16 << 10  # a job's record and events (its result is counted when it ends)
    _FORGET_LUA = """
    local function forget(id)
      local bytes = redis.call('HGET', KEYS[2], id)
      redis.call('ZREM', KEYS[1], id)
      if bytes then
        redis.call('HDEL', KEYS[2], id)
        redis.call('DECRBY', KEYS[3], bytes)
      end
    end
    """
    _FORGET = _FORGET_LUA + "forget(ARGV[1])"
    # A job's creation, whole (JobStore._stage_create), KEYS its owner's accounts (_accounts) and
    # active jobs. The owner's index pruned: those of its ARGV[2] oldest entries whose job (key
    # prefix ARGV[1]) has expired are forgotten. The job ARGV[3] admitted: counted among the
    # owner's active jobs unless they are at its limit (ARGV[4]; 0: no limit), and its bytes
    # (ARGV[5]) among those of the owner's stored jobs unless they would pass theirs (ARGV[6]; 0:
    # no limit). Only then the commands in ARGV[7] run (a JSON array: each its name, its argument
    # count, its arguments): the job's writes and its tasks' messages. 1, else 0 (active) or -1
    # (stored bytes).
    _CREATE = _FORGET_LUA + """
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

    # A job that ends adds what its result holds (the stored result, and the fragments a streamed
    # result is kept as) to its bytes in its owner's accounts, when it is still counted there (not
    # deleted meanwhile): a result is about 3 times its request compressed (a track's 12 times
    # uncompressed), so a key counted by its requests alone kept several times its limit.
    _COUNT_RESULT = """
    if redis.call('HEXISTS', KEYS[3], ARGV[1]) == 0 then return 0 end
    local bytes = redis.call('STRLEN', KEYS[1])
    for _, start in ipairs(redis.call('HKEYS', KEYS[2])) do bytes = bytes + redis.call('HSTRLEN', KEYS[2], start) end
    redis.call('HINCRBY', KEYS[3], ARGV[1], bytes)
    redis.call('INCRBY', KEYS[4], bytes)
    return bytes
    """

    def release(self, owner: str, job_id: str) -> None:
        self.r.srem(self.owner_key(owner, "active"), job_id)

    def _idempotency_key(self, owner: str, idempotency_key: str) -> str:
        return self.owner_key(owner, f"idempotency:{hashlib.sha256(idempotency_key.encode()).hexdigest()}")

    def remember_idempotent(self, owner: str, idempotency_key: str, body_digest: str) -> dict | None:
        """Reserve ``idempotency_key`` for a body; returns None when newly reserved, else what
        was stored before: ``{"body": digest, "job": id or None while being created}``."""
        key = self._idempotency_key(owner, idempotency_key)
        entry = dumps({"body": body_digest, "job": None})
        if self.r.set(key, entry, nx=True, ex=self.ttl):
            return None
        raw = self.r.get(key)
        return json.loads(raw) if raw else None

    async def remember_idempotent_async(self, client: redis.asyncio.Redis, owner: str, idempotency_key: str,
                                        body_digest: str) -> dict | None:
        """``remember_idempotent`` through an asyncio client."""
        key = self._idempotency_key(owner, idempotency_key)
        entry = dumps({"body": body_digest, "job": None})
        if await client.set(key, entry, nx=True, ex=self.ttl):
            return None
        raw = await client.get(key)
        return json.loads(raw) if raw else None

    def settle_idempotent(self, owner: str, idempotency_key: str, body_digest: str, job_id: str | None) -> None:
        """Record the job made for a reserved key (or, with None, free the key: creation failed)."""
        key = self._idempotency_key(owner, idempotency_key)
        if job_id is None:
            self.r.delete(key)
        else:
            self.r.set(key, dumps({"body": body_digest, "job": job_id}), ex=self.ttl)

    async def settle_idempotent_async(self, client: redis.asyncio.Redis, owner: str, idempotency_key: str,
                                      body_digest: str, job_id: str | None) -> None:
        """``settle_idempotent`` through an asyncio client."""
        key = self._idempotency_key(owner, idempotency_key)
        if job_id is None:
            await client.delete(key)
        else:
            await client.set(key, dumps({"body": body_digest, "job": job_id}), ex=self.ttl)



_CREATE_SIGNATURE = inspect.signature(JobStore.create)  # create_async takes create's arguments


async def read_job(client: redis.asyncio.Redis, job_id: str) -> dict | None:
    """``JobStore.get`` from an asyncio client (``decode_responses``): the API's reads on the loop."""
    raw = await client.hgetall(JobStore.key(job_id))
    return {k: json.loads(v) for k, v in raw.items()} if raw else None


async def count_request(client: redis.asyncio.Redis, owner: str, window_s: int = 60) -> tuple[int, int]:
    """Requests by ``owner`` in the current fixed window, and the seconds until it ends."""
    window = int(now() // window_s)
    key = JobStore.owner_key(owner, f"rate:{window}")
    async with client.pipeline(transaction=False) as pipe:
        pipe.incr(key)
        pipe.expire(key, 2 * window_s)
        count = (await pipe.execute())[0]
    return count, int((window + 1) * window_s - now()) + 1


async def events(client: redis.asyncio.Redis, job_id: str, after: str, block_ms: int,
                 stop: asyncio.Event) -> AsyncIterator[tuple[str, str, dict]]:
    """Yield a job's events (id, event, data) after ``after`` until its end event, from an asyncio
    Redis client (``decode_responses``), without holding a thread: each read blocks up to
    ``block_ms`` on the Redis side while the event loop serves other requests. After a read that
    found nothing, ("", "keepalive", {}) is yielded (the caller's heartbeat), or nothing more when
    the job has expired or been removed. When ``stop`` is set, ("", "stopping", {}) is yielded at
    once and the iteration ends (the blocking read is abandoned)."""
    stream = JobStore.key(job_id, "events")
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
                if await client.hget(JobStore.key(job_id), "status") is None:
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


_SHARED: JobStore | None = None


def shared_store() -> JobStore:
    """This worker process's job store (one connection pool for its tasks and webhooks)."""
    global _SHARED
    if _SHARED is None:
        from geocert.settings import get_settings
        from geocert.settings import redis_url

        _SHARED = JobStore.from_url(redis_url(), get_settings().result_ttl_s)
    return _SHARED

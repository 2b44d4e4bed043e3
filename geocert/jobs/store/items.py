"""What a job's tasks store as they go: their items (compressed one by one), the fragments of a
streamed result with their sums, and the progress summed over the job's tasks."""

from __future__ import annotations

import json
import math
import zlib

from geocert.jobs.store.base import StoreBase, dumps, now


class Items(StoreBase):
    """Publishes the summed progress (``events``); compresses as results do (``results``)."""

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

    # Items wait in Redis compressed too, one by one (zlib; an item stored as JSON text by an
    # earlier version starts with "{" and is read as it is): the end reads them all. An item is
    # a few hundred bytes to a few KB: a 4 KB window and a small memory level compress it as
    # well as zlib.compress's defaults (32 KB, level 8), whose set-up costs several times the
    # compression itself (measured on a 272-byte track: 49 us a call against 7.6 us, both 168
    # bytes); zlib.decompress reads either. An item of at most ITEM_STORED_AS_TEXT bytes waits as
    # its JSON text: a brief track (some 320 bytes) compressed to about 220 for 16 us, 1.7 times
    # what encoding it cost, and the workers stored each of a job's items so (a Dinosaur job's
    # brief items took more of the workers' CPU than its solve); items wait only while their job
    # runs (its end deletes them), a full track (some 2.4 KB) is still compressed, to half.
    ITEM_WINDOW_BITS, ITEM_MEMORY_LEVEL = 12, 4
    ITEM_STORED_AS_TEXT = 1024

    def _packed(self, items: dict[int, dict]) -> dict[str, bytes]:
        texts = ((str(i), dumps(item).encode()) for i, item in items.items())
        return {i: text if len(text) <= self.ITEM_STORED_AS_TEXT else self._compressed_item(text) for i, text in texts}

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

    def missing_items(self, job_id: str, total: int) -> list[int]:
        stored = set(self.r.hkeys(self.key(job_id, "items")))
        return [index for index in range(total) if str(index) not in stored]

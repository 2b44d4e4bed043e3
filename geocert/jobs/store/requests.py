"""A job's request as submitted: kept whole, or as its head and its items one per list element
so that a task reads only its chunk's items."""

from __future__ import annotations

import json

from geocert.jobs.store.base import StoreBase, dumps


class Requests(StoreBase):
    # A request whose items sit in ``data[chunk_key]`` is kept as its head (that list replaced by
    # a placeholder naming the job) and its items, in a list whose elements each hold a run of
    # ``request_run`` items (a field of the job; 1 when absent: a large body's upload writes one
    # an element), their JSON texts joined by ", " as json.dumps writes a list; written with
    # json.dumps's separators, so the whole request's text is rebuilt byte for byte. A run is the
    # job's chunk: a task reads one element and parses it once (one text an item cost the API a
    # json.dumps and an RPUSH argument a track, and each task a reply and a parse an item: 14 and
    # 2 ms for the Dinosaur's 4983 tracks and a 500-track chunk, against 8 and 0.5 ms).

    @staticmethod
    def _placeholder(job_id: str) -> str:
        return dumps(f"geocert-items-{job_id}")

    _ITEMS_PER_PUSH = 10_000

    def _put_request(self, pipe, job_id: str, request: dict, chunk_key: str | None, items_key: str | None,
                     run: int = 1) -> int:
        """Queue the request's writes on ``pipe``, its items ``run`` an element; the bytes written
        (not those of ``items_key``; an item's bytes counted as its own text's)."""
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
        run = max(1, run)
        if run > 1:
            pipe.hset(self.key(job_id), "request_run", dumps(run))
        texts = []
        for begin in range(0, len(items), run):
            part = items[begin:begin + run]
            text = dumps(part)[1:-1]  # the run's texts joined by ", ", as the whole list writes them
            texts.append(text)
            written += len(text) - 2 * (len(part) - 1)
        for begin in range(0, len(texts), self._ITEMS_PER_PUSH):
            pipe.rpush(self.key(job_id, "request:items"), *texts[begin:begin + self._ITEMS_PER_PUSH])
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
        return self._chunk(start, stop, *pipe.execute()[0])

    # The head, the items' key, the item count and the elements holding items ARGV[1] to
    # ARGV[2] - 1 with the index of their first item (none for an empty range).
    _READ_CHUNK = """
    local run = tonumber(redis.call('HGET', KEYS[2], 'request_run') or '1')
    local start, stop = tonumber(ARGV[1]), tonumber(ARGV[2])
    local total
    if run == 1 then total = redis.call('LLEN', KEYS[3])
    else total = tonumber(redis.call('HGET', KEYS[2], 'items_total') or '0') end
    local first = math.floor(start / run)
    local elements = {}
    if stop > start then elements = redis.call('LRANGE', KEYS[3], first, math.floor((stop - 1) / run)) end
    return {redis.call('GET', KEYS[1]), redis.call('HGET', KEYS[2], 'request_items'), total, first * run, elements}
    """

    def _read_chunk(self, pipe, job_id: str, start: int, stop: int) -> None:
        pipe.eval(self._READ_CHUNK, 3, self.key(job_id, "request"), self.key(job_id), self.key(job_id, "request:items"),
                  start, stop)

    @staticmethod
    def _chunk(start: int, stop: int, head: str, chunk_key: str | None, total: int, offset: int,
               elements: list[str]) -> dict:
        request = json.loads(head)
        if chunk_key is not None:
            chunk_key = json.loads(chunk_key)
            # the elements' runs parsed as one JSON array, then the chunk's own items taken
            read = json.loads("[" + ",".join(elements) + "]")[start - offset:stop - offset] if elements else []
            request["data"][chunk_key] = [None] * start + read + [None] * max(0, total - start - len(read))
        return request

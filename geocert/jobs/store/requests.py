"""A job's request as submitted: kept whole, or as its head and its items one per list element
so that a task reads only its chunk's items."""

from __future__ import annotations

import json

from geocert.jobs.store.base import StoreBase, dumps


class Requests(StoreBase):
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
            # one parse of the run as a JSON array: the same objects as one json.loads an item, in
            # 0.6 of the CPU (a call's set-up an item was half the cost of a 500-track chunk's)
            read = json.loads("[" + ",".join(items) + "]") if items else []
            request["data"][chunk_key] = [None] * start + read + [None] * max(0, total - start - len(items))
        return request

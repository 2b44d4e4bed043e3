"""A job's stored result: compressed whole, or as the fragments its tasks streamed; read whole or a
piece at a time for sending."""

from __future__ import annotations

import json
import zlib
from typing import Iterator

from geocert.jobs.store.base import ResultGone, StoreBase


class Results(StoreBase):
    """``_encoding`` reads the record's field (``records``)."""

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

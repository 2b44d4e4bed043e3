"""A running task's pieces (core.pieces) handed to the service's other solver processes:
one set of pieces at a time per stage, taken one by one from a shared counter, so that the task
that put them and every helper take each piece once, in the pieces' order (the pieces taken at
any moment are the first ones: a stop keeps a prefix). Values are bytes the caller encodes
(workers.pieces); the keys expire on their own after ``ttl_s`` should their task vanish."""

from __future__ import annotations

from geocert.jobs.store.base import FRESH_S, SOLVERS_KEY, WORKERS_KEY, StoreBase, now
from geocert.jobs.store.metrics import METRICS_KEY, _field

STOPPED = 1 << 40  # added to a set's counter to stop it: every later take reads past its end


class Pieces(StoreBase):
    def _piece_keys(self, job_id: str, set_id: str) -> tuple[str, str, str, str]:
        base = self.key(job_id, f"pieces:{set_id}")
        return base + ":input", base + ":next", base + ":out", base + ":failed"

    def put_pieces(self, job_id: str, set_id: str, function: str, shared: bytes, items: list[bytes],
                   ttl_s: float) -> None:
        """Store a set of pieces: the function's registered name, what they share, each item."""
        inputs, counter, out, failed = self._piece_keys(job_id, set_id)
        pipe = self.binary.pipeline()
        pipe.hset(inputs, mapping={"function": function, "shared": shared, "n": len(items),
                                   **{f"item:{k}": item for k, item in enumerate(items)}})
        pipe.set(counter, 0)
        for key in (inputs, counter):
            pipe.expire(key, max(1, int(ttl_s)))
        pipe.execute()

    _TAKE = """
    local n = tonumber(redis.call('HGET', KEYS[1], 'n'))
    if not n then return nil end
    local taken = redis.call('INCR', KEYS[2])
    if taken > n then return nil end
    return {taken - 1, redis.call('HGET', KEYS[1], 'item:' .. (taken - 1))}
    """

    def take_piece(self, job_id: str, set_id: str) -> tuple[int, bytes] | None:
        """The next piece not taken (its index and item), or None: every piece is taken, the set
        was stopped, or it is gone."""
        inputs, counter, _, _ = self._piece_keys(job_id, set_id)
        taken = self.binary.eval(self._TAKE, 2, inputs, counter)
        return None if taken is None else (int(taken[0]), taken[1])

    def piece_function(self, job_id: str, set_id: str) -> tuple[str, bytes] | None:
        """The set's function name and what its pieces share (None: the set is gone)."""
        inputs, _, _, _ = self._piece_keys(job_id, set_id)
        function, shared = self.binary.hmget(inputs, "function", "shared")
        return None if function is None or shared is None else (function.decode(), shared)

    def stop_pieces(self, job_id: str, set_id: str, total: int) -> int:
        """Let no piece of the set be taken any more; returns how many were taken before (the
        first ones)."""
        _, counter, _, _ = self._piece_keys(job_id, set_id)
        return min(total, int(self.binary.incrby(counter, STOPPED)) - STOPPED)

    def put_piece_result(self, job_id: str, set_id: str, index: int, value: bytes | None = None,
                         error: str | None = None, ttl_s: float = 3600) -> None:
        """A helper's piece: its result (encoded), or the error it raised (counted in the metrics:
        pieces solved by a helper)."""
        _, _, out, failed = self._piece_keys(job_id, set_id)
        key, field = (failed, error.encode()) if error is not None else (out, value)
        pipe = self.binary.pipeline()
        pipe.hset(key, str(index), field)
        pipe.expire(key, max(1, int(ttl_s)))
        if error is None:
            pipe.hincrby(METRICS_KEY, _field("pieces", solved_by="helper"), 1)
        pipe.execute()

    def count_own_pieces(self, solved: int) -> None:
        """Count the pieces a task solved itself (the metrics: pieces solved by their task)."""
        if solved:
            self.r.hincrby(METRICS_KEY, _field("pieces", solved_by="task"), solved)

    def piece_results(self, job_id: str, set_id: str, indices: list[int]) -> tuple[dict[int, bytes], dict[int, str]]:
        """Of these pieces, the results stored and the errors raised, by index."""
        _, _, out, failed = self._piece_keys(job_id, set_id)
        if not indices:
            return {}, {}
        pipe = self.binary.pipeline()
        pipe.hmget(out, [str(k) for k in indices])
        pipe.hmget(failed, [str(k) for k in indices])
        values, errors = pipe.execute()
        return ({k: v for k, v in zip(indices, values) if v is not None},
                {k: e.decode() for k, e in zip(indices, errors) if e is not None})

    def drop_pieces(self, job_id: str, set_id: str) -> None:
        self.binary.delete(*self._piece_keys(job_id, set_id))

    def live_solvers(self) -> int:
        """The solver processes of the workers that beat within the last FRESH_S seconds."""
        names = self.r.zrangebyscore(WORKERS_KEY, now() - FRESH_S, "+inf")
        if not names:
            return 0
        return sum(int(n or 0) for n in self.r.hmget(SOLVERS_KEY, names))

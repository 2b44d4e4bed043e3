"""core.pieces' in-process mappings: in_threads (and in_order) tell a caller each item's
end through ``done``, in the calling thread, before the next ``stop`` is asked."""

from __future__ import annotations

import threading
import time

import pytest

from geocert.core import pieces


def slow_square(item: int) -> int:
    time.sleep(0.002 * (item % 3))  # items of unequal length end out of order
    return item * item


@pytest.mark.parametrize("threads", [1, 2])
def test_done_sees_each_item_end_in_the_calling_thread(threads):
    items = list(range(12))
    seen, caller = [], threading.get_ident()
    results = pieces.in_threads(slow_square, items, lambda k: False, threads,
                                done=lambda k, result: seen.append((k, result, threading.get_ident())))
    assert results == [k * k for k in items]
    assert sorted((k, result) for k, result, _ in seen) == [(k, k * k) for k in items]
    assert {ident for _, _, ident in seen} == {caller}


@pytest.mark.parametrize("threads", [1, 2])
def test_a_cancel_asked_after_an_end_keeps_what_ended(threads):
    """The caller's own collection (through done) holds the items that ended, in flight ones
    included, though a cancel returns None; ``stop`` is asked only after ``done`` has seen an end."""
    ended: dict = {}
    events = []

    def stop(k):
        events.append(("stop", k))
        return None if ended else False

    def done(k, result):
        events.append(("done", k))
        ended[k] = result

    assert pieces.in_threads(slow_square, list(range(8)), stop, threads, done=done) is None
    assert ended == {k: k * k for k in ended} and len(ended) == threads
    first_done = events.index(next(e for e in events if e[0] == "done"))
    assert [e for e in events[:first_done] if e[0] == "stop"] == [("stop", k) for k in range(threads)]

"""Python's cyclic garbage collector held off while a job's body is taken in (the API) and while a
task stores its items (the workers).

Both make a tree of objects per item (pydantic's validation from the bytes, the request dumped
back as JSON types, the kind's parse; the items' documents validated and written by the result
model): many young objects that survive, so the collector ran again and again over them, and
over what the process already held, finding nothing (JSON makes no cycles; reference counting
frees the trees). On the Oxford Dinosaur's 0.49 MB body it was most of the intake's CPU: the
whole intake 190 ms with it, 62 without (bench.submission --app). Held off, nothing leaks:
whatever cycles appear meanwhile are collected once it runs again, at its next threshold.
"""

from __future__ import annotations

import contextlib
import gc
import threading
from typing import Iterator

_lock = threading.Lock()
_holders = 0  # intakes under way (threads of the pool, the event loop): the collector runs when none is
_held_here = False  # whether this module turned it off (it may have been off already)


@contextlib.contextmanager
def collector_held() -> Iterator[None]:
    """The cyclic collector off for the block (and for as long as any other intake holds it)."""
    global _holders, _held_here
    with _lock:
        _holders += 1
        if _holders == 1 and gc.isenabled():
            gc.disable()
            _held_here = True
    try:
        yield
    finally:
        with _lock:
            _holders -= 1
            if _holders == 0 and _held_here:
                _held_here = False
                gc.enable()

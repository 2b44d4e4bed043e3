"""Python's cyclic garbage collector held off while a job's body is taken in (the API) and while a
task stores its items (the workers); and a solver process's start-up heap frozen out of it.

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


def start_up_heap_frozen() -> None:
    """What a solver process holds once started (modules, classes, Celery's and the solvers'
    objects, all kept for its life) moved out of the cyclic collector's generations (gc.freeze),
    called once its solvers are loaded (workers.signals). A solve makes many young objects that
    survive a while (a chunk's parse, its items' documents), so the collector ran again and again,
    its older generations' runs scanning that whole start-up heap and finding nothing in it. On
    the Oxford Dinosaur (4983 tracks, the kind's chunks) a process started as a solver process
    spent 0.42 s of CPU instead of 0.53, the collector 0.017 s instead of 0.12, the items the same
    (bench.worker_collector); a 3-track job never ran the collector. Through the service the
    workers' CPU for that job moved less than its noise (bench/results/service.md). Cycles made later are
    collected as before; the frozen objects are only never scanned (nor, in a forked process,
    written to by the collector, so their pages stay shared with the parent's).

    Not done in the API process: there small submissions' collections cost 0.1 ms of its 2 ms a
    submission with or without it (bench.api_collector), the body's intake already holding the
    collector off (collector_held)."""
    gc.freeze()

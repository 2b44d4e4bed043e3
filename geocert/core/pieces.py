"""A stage's independent work as pieces a caller may spread over processes.

A stage whose work splits into independent pieces (an image's features, an image pair's matches)
states each as ``function(shared, item)``: a module-level function (a process elsewhere finds it
by name), ``shared`` what every piece reads (options, the images' features) and ``item`` the
piece's own input. ``mapped`` runs them: in this process, as the stage always did (its own
``in_process`` mapping, e.g. two threads), unless a caller has set a spreader for the code it
runs (``spread_by``): the service's worker sets one that hands the pieces to the service's other
solver processes (geocert.workers.pieces). Either way the results come back in the items' order,
each the same as computed alone, so the stage's result does not depend on where they ran.

``stop(k)`` is asked before the k-th piece starts (its answer as in_order and in_threads
reads it): True starts no more (the results are then the prefix of the pieces started), None is
a cancel (the pieces running finish, and None is returned). A piece that raises raises here.

Only the functions registered here (``piece``) are run from a spreader's pieces: what a process
reads from a shared store names one of them, never arbitrary code.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import os
from typing import Any, Callable, Sequence

Stop = Callable[[int], "bool | None"]
Spreader = Callable[[Callable, Any, Sequence, Stop], "list | None"]

_SPREADER: contextvars.ContextVar[Spreader | None] = contextvars.ContextVar("geocert_spreader", default=None)
REGISTERED: dict[str, Callable] = {}


def piece(function: Callable) -> Callable:
    """Register ``function(shared, item)`` as a piece a spreader may run in another process."""
    REGISTERED[name_of(function)] = function
    return function


def name_of(function: Callable) -> str:
    return f"{function.__module__}:{function.__qualname__}"


def registered(name: str) -> Callable:
    """The registered piece function of this name (KeyError: not one)."""
    if name not in REGISTERED:
        module = name.partition(":")[0]
        if module.startswith("geocert."):  # registered when its module is imported
            import importlib

            importlib.import_module(module)
    return REGISTERED[name]


def mapped(function: Callable, shared: Any, items: Sequence, stop: Stop,
           in_process: Callable[[Callable, Sequence, Stop], "list | None"]) -> list | None:
    """``function(shared, item)`` for the items, results in order (see the module docstring): by
    the spreader set for this code, else by ``in_process(one, items, stop)``."""
    spreader = _SPREADER.get()
    if spreader is None or name_of(function) not in REGISTERED or len(items) < 2:
        return in_process(functools.partial(function, shared), items, stop)
    return spreader(function, shared, items, stop)


Done = Callable[[int, Any], None]


def in_order(one: Callable, items: Sequence, stop: Stop, done: Done | None = None) -> list | None:
    """``one(item)`` for the items, here, in order: an ``in_process`` mapping without threads
    (``done`` as in_threads calls it)."""
    results = []
    for k, item in enumerate(items):
        asked = stop(k)
        if asked is None:
            return None
        if asked:
            break
        results.append(one(item))
        if done is not None:
            done(k, results[-1])
    return results


# Pieces at once in one process (in_threads): OpenCV's SIFT and RANSAC, numpy's products and the
# conic solver release the interpreter's lock, so two threads use two cores; more would only
# contend on a 2-core machine, and the stages' own mappings use two as well.
THREADS = 2


def in_threads(one: Callable, items: Sequence, stop: Stop, threads: int | None = None,
               done: Done | None = None) -> list | None:
    """``one(item)`` for the items, ``threads`` at a time (None: THREADS; at most the
    processors), in this process: an ``in_process`` mapping with ``in_order``'s results and
    ``stop`` (asked in this thread before the k-th item starts; a cancel returns None once the
    items in flight end). An item starts as soon as any running one ends, so one long item does
    not hold the others back; each item's result is what it computes alone. ``done(k, result)``,
    when given, is called in this thread as each item ends (in the order they end, before the
    next ``stop`` is asked): progress, or a caller's own collection of what ended before a cancel."""
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    threads = max(1, min(THREADS if threads is None else threads, os.cpu_count() or 1, len(items)))
    if threads == 1:
        return in_order(one, items, stop, done)
    results: dict[int, Any] = {}
    started, asked = 0, False
    with ThreadPoolExecutor(max_workers=threads) as pool:
        running: dict = {}
        while True:
            while asked is False and started < len(items) and len(running) < threads:
                asked = stop(started)
                asked = None if asked is None else bool(asked)
                if asked is False:
                    running[pool.submit(one, items[started])] = started
                    started += 1
            if not running:
                break
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in finished:
                k = running.pop(future)
                results[k] = future.result()  # a piece that raised raises here
                if done is not None:
                    done(k, results[k])
    if asked is None:
        return None
    return [results[k] for k in range(started)]


def spreading() -> bool:
    """Whether a spreader is set for this code (a stage then hands it every piece, with a
    threadless ``in_process`` mapping: the spreader chooses how its process runs them, in
    threads when no other process takes a share)."""
    return _SPREADER.get() is not None


@contextlib.contextmanager
def spread_by(spreader: Spreader | None):
    """Within the block, ``mapped`` hands its pieces to ``spreader`` (None: in this process)."""
    token = _SPREADER.set(spreader)
    try:
        yield
    finally:
        _SPREADER.reset(token)

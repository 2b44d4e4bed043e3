"""A stage's independent work as pieces a caller may spread over processes.

A stage whose work splits into independent pieces (an image's features, an image pair's matches)
states each as ``function(shared, item)``: a module-level function (a process elsewhere finds it
by name), ``shared`` what every piece reads (options, the images' features) and ``item`` the
piece's own input. ``mapped`` runs them: in this process, as the stage always did (its own
``in_process`` mapping, e.g. two threads), unless a caller has set a spreader for the code it
runs (``spread_by``): the service's worker sets one that hands the pieces to the service's other
solver processes (geocert.workers.pieces). Either way the results come back in the items' order,
each the same as computed alone, so the stage's result does not depend on where they ran.

``stop(k)`` is asked before the k-th piece starts (its answer as features.in_order_threads
reads it): True starts no more (the results are then the prefix of the pieces started), None is
a cancel (the pieces running finish, and None is returned). A piece that raises raises here.

Only the functions registered here (``piece``) are run from a spreader's pieces: what a process
reads from a shared store names one of them, never arbitrary code.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
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


def in_order(one: Callable, items: Sequence, stop: Stop) -> list | None:
    """``one(item)`` for the items, here, in order: an ``in_process`` mapping without threads."""
    results = []
    for k, item in enumerate(items):
        asked = stop(k)
        if asked is None:
            return None
        if asked:
            break
        results.append(one(item))
    return results


def spreading() -> bool:
    """Whether a spreader is set for this code (a stage may then run its pieces one at a time
    in this process: the other processes are its parallelism)."""
    return _SPREADER.get() is not None


@contextlib.contextmanager
def spread_by(spreader: Spreader | None):
    """Within the block, ``mapped`` hands its pieces to ``spreader`` (None: in this process)."""
    token = _SPREADER.set(spreader)
    try:
        yield
    finally:
        _SPREADER.reset(token)

"""Work the API does for a request in processes of its own, not in the API process.

What holds the interpreter lock for seconds (decoding a large body, validating it by its model,
numpy work between releases of the lock) stops the API's event loop, and every other client's
request with it, when done in a thread of the API process; and what it allocates stays in that
process's heap afterwards (glibc keeps freed memory in its arenas). In a process of its own it
costs the API process the bytes sent through a pipe, and the memory is that process's.

A ``Pool`` starts its processes with its first use (spawned, not forked: the API process has an
event loop and threads a fork would copy) and each imports what its work needs first (``ready``),
at a lower scheduling priority than the API process's (NICENESS).
A process that dies (killed for memory, say) breaks its pool: the request it held is answered
503 (retry), and the next use starts new processes.

Errors cross the pipe as plain tuples (``carried``), raised again in the API process as the route
would have raised them in process (``raise_carried``): a body's JSON and model errors, a problem,
a kind's input error, Redis gone.
"""

from __future__ import annotations

import asyncio
import ctypes
import multiprocessing
import os
import threading
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable

import redis
from fastapi.exceptions import RequestValidationError

from geocert.app.errors import ApiProblem
from geocert.settings import get_settings
from geocert.core.geometry import InputError


class Pool:
    def __init__(self, size: Callable[[], int], ready: Callable[[], None], what: str):
        self.size, self.ready, self.what = size, ready, what  # what: "the process taking this large body"
        self._pool: ProcessPoolExecutor | None = None
        self._lock = threading.Lock()

    def _executor(self) -> ProcessPoolExecutor:
        with self._lock:
            if self._pool is None:
                count = max(1, self.size())
                self._pool = ProcessPoolExecutor(count, mp_context=multiprocessing.get_context("spawn"))
                for _ in range(count):  # each process's first task: its imports (``ready``)
                    self._pool.submit(_start, self.ready)
            return self._pool

    def _forget(self, pool: ProcessPoolExecutor) -> None:
        """Drop a pool whose process died (every later submission to it would fail)."""
        with self._lock:
            if self._pool is pool:
                self._pool = None
        pool.shutdown(wait=False, cancel_futures=True)

    async def run(self, function: Callable, *args: Any) -> Any:
        """``function(*args)`` in one of the processes (waiting for them to start, and for a free
        one); a 503 to retry when its process dies meanwhile."""
        pool = self._executor()
        try:
            return await asyncio.wrap_future(pool.submit(function, *args))
        except BrokenProcessPool:
            self._forget(pool)
            raise ApiProblem(503, f"{self.what} stopped before it answered; send it again",
                             headers={"Retry-After": "1"}) from None


NICENESS = 5  # the processes' scheduling priority below the API process's


def _start(ready: Callable[[], None]) -> None:
    """A process's first task: below the API process's priority (on a loaded machine the API's
    event loop, answering every client, comes before one client's heavy request), then ``ready``."""
    try:
        os.nice(NICENESS)
    except OSError:
        pass
    ready()


def validated(model, body: bytes) -> tuple[Any, tuple | None]:
    """In a process: the body read by ``model`` (a pydantic TypeAdapter), or the error as FastAPI
    words a body's errors, carried (("json", position, message) or ("invalid", errors))."""
    import json

    from pydantic import ValidationError

    try:  # the model reads the text itself: a third less than json.loads and validating what it gives
        return model.validate_json(body), None
    except ValidationError:  # the errors as the route gives them: from json.loads and the decoded body
        try:
            decoded = json.loads(body)
        except json.JSONDecodeError as exc:
            return None, ("json", exc.pos, exc.msg)
        except UnicodeDecodeError as exc:  # not UTF-8 text (json.loads decodes bytes first)
            return None, ("json", exc.start, f"not UTF-8 ({exc.reason})")
        except ValueError as exc:  # valid JSON, an integer longer than the parser converts: not a syntax error
            from geocert.app.errors import long_number_reason

            return None, ("input", "body", long_number_reason(exc))
        try:
            return model.validate_python(decoded), None
        except ValidationError as exc:  # under "body", the input left out
            return None, ("invalid", [{key: value for key, value in error.items() if key != "input"} | {
                "loc": ("body", *error["loc"]), "ctx": {k: str(v) for k, v in (error.get("ctx") or {}).items()}}
                for error in exc.errors(include_url=False)])


def carried(exc: Exception) -> tuple | None:
    """An error raised in a process as a tuple that crosses the pipe (None: not one carried)."""
    from geocert.jobs.store import REDIS_GONE

    if isinstance(exc, ApiProblem):
        return "problem", exc.status, exc.detail, exc.field, exc.headers
    if isinstance(exc, InputError):
        return "input", exc.field, exc.reason
    if isinstance(exc, REDIS_GONE):
        return "redis", str(exc)
    return None


def carried_or_raised(exc: Exception) -> tuple:
    """``carried(exc)`` in a process's except clause: an error no request answers with (a bug) is
    raised again, its traceback kept."""
    error = carried(exc)
    if error is None:
        raise exc
    return error


def raise_carried(outcome: tuple, body: bytes) -> None:
    """Raise the error ``outcome`` carries (``validated``'s or ``carried``'s), as in process."""
    what = outcome[0]
    if what == "json":
        _, position, message = outcome
        raise RequestValidationError([{"type": "json_invalid", "loc": ("body", position), "msg": "JSON decode error",
                                       "input": {}, "ctx": {"error": message}}], body=body)
    if what == "invalid":
        raise RequestValidationError(outcome[1])
    if what == "problem":
        _, status, detail, field, headers = outcome
        raise ApiProblem(status, detail, field, headers)
    if what == "input":
        raise InputError(*outcome[1:])
    if what == "redis":
        raise redis.exceptions.ConnectionError(outcome[1])
    raise ValueError(f"not a carried error: {what!r}")


def environment() -> dict[str, str]:
    """The API process's settings: its GEOCERT_* variables, for a process to ``use``."""
    return {name: value for name, value in os.environ.items() if name.startswith("GEOCERT_")}


def use(settings: dict[str, str]) -> None:
    """The API process's settings (GEOCERT_* variables, read when it sent the work) in this one."""
    if settings == environment():
        return
    from geocert.app.api.deps import get_store

    for name in environment():
        del os.environ[name]
    os.environ.update(settings)
    get_settings.cache_clear()
    get_store.cache_clear()


def give_back_memory() -> None:
    """Return the heap's free pages to the system (glibc's malloc_trim; nothing elsewhere): glibc
    keeps what a large request freed in its arenas, so a process's resident size stayed at its
    largest request's for good."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass

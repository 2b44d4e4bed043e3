"""Structured logs: one JSON object per line, carrying the request id and job id in context.

The API sets the request id (from ``X-Request-ID`` or a new one) for each request; it travels
with the job's tasks, so a worker's lines about a job carry the id of the request that made it.
"""

from __future__ import annotations

import contextlib
import contextvars
import json
import logging
import sys
import time

_CONTEXT: contextvars.ContextVar[dict] = contextvars.ContextVar("geocert_log_context", default={})


@contextlib.contextmanager
def context(**fields):
    """Add fields (None ones skipped) to every log line written inside the block."""
    token = _CONTEXT.set({**_CONTEXT.get(), **{k: v for k, v in fields.items() if v is not None}})
    try:
        yield
    finally:
        _CONTEXT.reset(token)


def current(name: str):
    return _CONTEXT.get().get(name)


class JsonFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        line = {"time": round(time.time(), 3), "level": record.levelname, "logger": record.name,
                "message": record.getMessage(), **_CONTEXT.get()}
        for key in ("method", "path", "status", "duration_ms"):
            if hasattr(record, key):
                line[key] = getattr(record, key)
        if record.exc_info:
            line["exception"] = self.formatException(record.exc_info)
        return json.dumps(line, default=str)


def configure(level: int = logging.INFO) -> None:
    """JSON lines on standard error for the ``geocert`` loggers (idempotent)."""
    logger = logging.getLogger("geocert")
    if any(getattr(h, "_geocert", False) for h in logger.handlers):
        return
    handler = logging.StreamHandler(sys.__stderr__)  # not a worker's redirected stderr
    handler.setFormatter(JsonFormatter())
    handler._geocert = True  # type: ignore[attr-defined]
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False

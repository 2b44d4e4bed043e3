"""Worker heartbeats in Redis, so that ``/readyz`` answers at once instead of pinging workers.

Each worker's main process writes its name and the time into one sorted set every
``INTERVAL_S`` seconds from the moment it is ready to take tasks, and removes itself when it shuts
down. A worker counts as alive while its last beat is at most ``FRESH_S`` old; one killed outright
stops beating and drops out of the count within ``FRESH_S``.
"""

from __future__ import annotations

import logging
import threading
import time

import redis

KEY = "geocert:workers"
INTERVAL_S = 2.0
FRESH_S = 10.0
FORGET_S = 3600.0  # entries older than this are removed by the next beat of any worker

log = logging.getLogger("geocert.worker")


def live_workers(client: redis.Redis, now: float | None = None) -> int:
    """How many workers beat within the last ``FRESH_S`` seconds (one Redis command)."""
    now = time.time() if now is None else now
    return int(client.zcount(KEY, now - FRESH_S, "+inf"))


def beat(client: redis.Redis, name: str) -> None:
    now = time.time()
    pipe = client.pipeline()
    pipe.zadd(KEY, {name: now})
    pipe.zremrangebyscore(KEY, "-inf", now - FORGET_S)
    pipe.execute()


class Heartbeat:
    """A daemon thread beating for one worker until ``stop()``."""

    def __init__(self, url: str, name: str, interval_s: float = INTERVAL_S, reaper=None, reap_every_s: float = 5.0):
        self.client = redis.Redis.from_url(url, socket_timeout=5, socket_connect_timeout=5)
        self.name, self.interval_s = name, interval_s
        self.reaper, self.reap_every_s, self.reaped_at = reaper, reap_every_s, 0.0
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._run, name="geocert-heartbeat", daemon=True)

    def start(self) -> "Heartbeat":
        self.thread.start()
        return self

    def _run(self) -> None:
        while not self.stopped.is_set():
            try:
                beat(self.client, self.name)
            except redis.RedisError as exc:  # Redis away for a moment: beat again next time
                log.warning("heartbeat not written: %s", exc)
            if self.reaper is not None and time.monotonic() - self.reaped_at >= self.reap_every_s:
                self.reaped_at = time.monotonic()
                try:
                    self.reaper()
                except Exception as exc:  # Redis away, say: look again next time
                    log.warning("reaper round failed: %s", exc)
            self.stopped.wait(self.interval_s)

    def stop(self) -> None:
        self.stopped.set()
        self.thread.join(timeout=5)
        try:
            self.client.zrem(KEY, self.name)
        except redis.RedisError:
            pass

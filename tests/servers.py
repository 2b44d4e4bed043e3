"""Real processes for end-to-end tests: an embedded Redis, the API (`geocert serve`) and Celery
workers (`geocert worker`), each a process of its own on loopback, so a test can kill one."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import httpx


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_ready(client: httpx.Client, process: subprocess.Popen, limit_s: float = 90, workers: bool = True) -> None:
    deadline = time.monotonic() + limit_s
    while True:
        try:
            if client.get("/readyz" if workers else "/healthz").status_code == 200:
                return
        except httpx.TransportError:
            pass
        assert process.poll() is None, "geocert serve exited"
        assert time.monotonic() < deadline, f"service not ready within {limit_s} s"
        time.sleep(0.3)


# Many short tasks, so that a job has several in flight when a fault strikes and a worker freed
# takes up a redelivered one soon.
SHORT_TASKS = {"geocert_chunk_sizes": '{"triangulation": 60}', "geocert_chunk_time_budget_s": "2",
               "geocert_max_item_time_limit_s": "10"}


def wait_until_done(client: httpx.Client, job_id: str, tracks: int, limit_s: float = 120) -> None:
    """Until at least ``tracks`` items of the job are done (its progress)."""
    deadline = time.monotonic() + limit_s
    while client.get(f"/v1/jobs/{job_id}").json()["progress"]["items_done"] < tracks:
        assert time.monotonic() < deadline, "the job did not get going"
        time.sleep(0.05)


class Cluster:
    """Redis + API (no embedded workers) + separately started workers."""

    def __init__(self, data_dir: Path, env: dict[str, str]):
        from geocert.workers.redis_server import start_embedded_redis

        self.redis, self.redis_url = start_embedded_redis(data_dir)
        self.env = {**os.environ, **env, "GEOCERT_REDIS_URL": self.redis_url, "GEOCERT_DATA_DIR": str(data_dir)}
        self.port = free_port()
        self.api = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(self.port),
                                     "--workers", "0"], env=self.env)
        self.base = f"http://127.0.0.1:{self.port}"
        self.workers: list[subprocess.Popen] = []

    def start_worker(self, concurrency: int = 1) -> subprocess.Popen:
        # A session of its own, so that a kill takes the worker's pool processes (and its webhook
        # worker) too, as when a machine or container dies.
        worker = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "worker", "--concurrency", str(concurrency)],
                                  env=self.env, start_new_session=True)
        self.workers.append(worker)
        return worker

    @staticmethod
    def kill(worker: subprocess.Popen) -> None:
        os.killpg(worker.pid, signal.SIGKILL)
        worker.wait(timeout=10)

    def stop(self) -> None:
        for process in [self.api, *self.workers]:
            if process.poll() is None:
                try:
                    os.killpg(process.pid, signal.SIGTERM) if process in self.workers else process.terminate()
                except ProcessLookupError:
                    pass
        for process in [self.api, *self.workers]:
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
        self.redis.terminate()
        self.redis.wait(timeout=10)


@contextmanager
def cluster(data_dir: Path, workers: int = 1, **env: str):
    running = Cluster(data_dir, {key.upper(): str(value) for key, value in env.items()})
    try:
        for _ in range(workers):
            running.start_worker()
        with httpx.Client(base_url=running.base, timeout=30) as client:
            wait_ready(client, running.api, workers=workers > 0)
            yield running, client
    finally:
        running.stop()


class Streams:
    """``count`` event streams of ``path`` held open by one asyncio thread (no thread each), opened
    one after another: the status each was answered with, and the lines each received until the
    server ended it."""

    def __init__(self, base: str, path: str, count: int):
        import asyncio
        import threading

        self.statuses: list[int] = []
        self.lines: list[list[str]] = [[] for _ in range(count)]
        self._answered = threading.Semaphore(0)
        self._count = count

        async def hold() -> None:
            limits = httpx.Limits(max_connections=count + 5, max_keepalive_connections=0)
            async with httpx.AsyncClient(base_url=base, timeout=httpx.Timeout(30, read=None), limits=limits) as client:
                async def one(index: int, answered: asyncio.Event) -> None:
                    try:
                        async with client.stream("GET", path) as response:
                            self.statuses.append(response.status_code)
                            answered.set()
                            async for line in response.aiter_lines():
                                self.lines[index].append(line)
                    except httpx.TransportError as exc:
                        self.lines[index].append(f"transport error: {exc!r}")
                    finally:
                        answered.set()

                running = []
                for index in range(count):  # one after another: a stream opens once the last is answered
                    answered = asyncio.Event()
                    running.append(asyncio.create_task(one(index, answered)))
                    await answered.wait()
                    self._answered.release()
                await asyncio.gather(*running)

        self.thread = threading.Thread(target=lambda: asyncio.run(hold()), daemon=True)
        self.thread.start()

    def wait_answered(self, limit_s: float = 60) -> None:
        deadline = time.monotonic() + limit_s
        for _ in range(self._count):
            assert self._answered.acquire(timeout=max(0.0, deadline - time.monotonic())), \
                f"only {len(self.statuses)} of {self._count} streams answered within {limit_s} s"

    def join(self, limit_s: float = 30) -> None:
        self.thread.join(timeout=limit_s)


def thread_count(pid: int) -> int:
    with open(f"/proc/{pid}/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("Threads:"))


def spawned(pid: int) -> list[int]:
    """The API process's spawned helper processes (multiprocessing's: submission, orientation,
    export and verification processes) under ``pid``."""
    found, todo = [], [pid]
    while todo:
        current = todo.pop()
        try:
            with open(f"/proc/{current}/task/{current}/children") as children:
                todo.extend(int(child) for child in children.read().split())
            with open(f"/proc/{current}/cmdline", "rb") as cmdline:
                if b"spawn_main" in cmdline.read():
                    found.append(current)
        except OSError:
            pass
    return found

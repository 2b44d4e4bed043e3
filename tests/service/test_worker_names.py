"""Several ``geocert worker`` processes on one host each count as a worker with their solver
processes (their heartbeats' names differ, workers.signals.beat_name): under one shared name
(``geocert@host``) two workers' beats counted as one, and /readyz, a key's fair share of the
solvers and a reconstruction's helpers (workers.pieces) saw half the solvers there are."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from geocert.jobs.store import JobStore

pytestmark = pytest.mark.slow  # real worker processes


def test_two_workers_on_one_host_count_as_two_with_their_solvers(tmp_path):
    from geocert.workers.redis_server import start_embedded_redis

    redis_process, url = start_embedded_redis(tmp_path / "redis")
    env = {**os.environ, "GEOCERT_REDIS_URL": url, "GEOCERT_DATA_DIR": str(tmp_path)}
    # each a session of its own, so that stopping it stops its solver processes too
    workers = [subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "worker", "--role", "solve",
                                 "--concurrency", str(concurrency)], env=env, start_new_session=True)
               for concurrency in (1, 2)]
    try:
        jobs = JobStore.from_url(url)
        deadline = time.monotonic() + 120
        while (jobs.live_workers(), jobs.live_solvers()) != (2, 3):
            assert all(worker.poll() is None for worker in workers), "a worker exited"
            assert time.monotonic() < deadline, (f"live workers {jobs.live_workers()}, solvers "
                                                 f"{jobs.live_solvers()}: expected 2 and 3")
            time.sleep(0.2)
    finally:
        for worker in workers:
            os.killpg(worker.pid, signal.SIGTERM)
        for worker in workers:
            try:
                worker.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(worker.pid, signal.SIGKILL)
                worker.wait(timeout=10)
        redis_process.terminate()
        redis_process.wait(timeout=10)

"""The queue's use of Celery from the API's many threads."""

from __future__ import annotations

import json
import subprocess
import sys


def test_the_solve_task_resolves_once_from_many_threads_at_once():
    # In a fresh process (Celery's lazy task proxy not yet evaluated), 32 threads ask for the
    # task at the same moment, as a burst of first submissions does: every one gets the same
    # evaluated task, and none an error. (The race this guards against, an AttributeError from a
    # half-evaluated proxy, showed once in the 500-job durability test through a real server; it
    # does not reproduce in a process this small, so this checks the guarded path, not the race.)
    code = """
import json, threading
from geocert.workers import queue
barrier = threading.Barrier(32)
seen, errors = [], []
def ask():
    barrier.wait()
    try:
        task = queue._solve_chunk_task()
        seen.append((id(task), task.name, task.s("job", 0, 1).task))
    except Exception as exc:
        errors.append(repr(exc))
threads = [threading.Thread(target=ask) for _ in range(32)]
[t.start() for t in threads]; [t.join() for t in threads]
print(json.dumps({"errors": errors, "distinct": len(set(seen)), "count": len(seen)}))
"""
    env = {"GEOCERT_REDIS_URL": "redis://127.0.0.1:1/0", "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen == {"errors": [], "distinct": 1, "count": 32}

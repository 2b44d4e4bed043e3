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
    # does not reproduce in a process this small; so the task's first evaluation is made slow and
    # counted here: it must run once, never two threads inside it at a time, which fails without
    # the lock.)
    code = """
import json, threading, time
from geocert.workers import queue, tasks
real = tasks.solve_chunk
state = {"inside": 0, "most": 0, "evaluations": 0}
class SlowFirstEvaluation:
    @property
    def name(self):
        state["inside"] += 1
        state["most"] = max(state["most"], state["inside"])
        state["evaluations"] += 1
        time.sleep(0.05)
        state["inside"] -= 1
        return real.name
    def s(self, *args):
        return real.s(*args)
tasks.solve_chunk = SlowFirstEvaluation()
barrier = threading.Barrier(32)
seen, errors = [], []
def ask():
    barrier.wait()
    try:
        task = queue._solve_chunk_task()
        seen.append((id(task), real.name, task.s("job", 0, 1).task))
    except Exception as exc:
        errors.append(repr(exc))
threads = [threading.Thread(target=ask) for _ in range(32)]
[t.start() for t in threads]; [t.join() for t in threads]
print(json.dumps({"errors": errors, "distinct": len(set(seen)), "count": len(seen), "most_inside": state["most"],
                  "evaluations": state["evaluations"]}))
"""
    env = {"GEOCERT_REDIS_URL": "redis://127.0.0.1:1/0", "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen == {"errors": [], "distinct": 1, "count": 32, "most_inside": 1, "evaluations": 1}

"""Task priorities on kombu's Redis transport: one list per step, a worker taking from the list of
the lowest number first. A job's first task is queued FIRST, its others LATER (and a task
deferred for its key's share LATER again), so that another key's new job is taken before a
flood's queued tasks, not after each of them has been taken and deferred in turn. A leaf module:
the queue, the tasks, the reaper and the metrics read it."""

from __future__ import annotations

FIRST, LATER = 0, 9
PRIORITY_STEPS = (0, 3, 6, 9)  # kombu's default steps


def queue_lists(queue: str) -> list[str]:
    """The Redis lists holding a queue's waiting tasks, one per priority step (kombu's names)."""
    return [queue if step == 0 else f"{queue}\x06\x16{step}" for step in PRIORITY_STEPS]

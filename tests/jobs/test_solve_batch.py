"""batch.solve_items with a kind that solves many items at once (solve_batch): groups of
batch_size in order, progress once a group (its items end together), a cancel or the time budget seen between groups, and the
job's deadline given to every group and seen between them."""

from __future__ import annotations

import time
from types import SimpleNamespace

from geocert.jobs.runner import solve_items


class CountingKind:
    """Items are numbers; an item's document is its square. Records each batch it is given."""

    def __init__(self, batch_size: int, pause_s: float = 0.0):
        self.batch_size = batch_size
        self.pause_s = pause_s
        self.batches: list[list[int]] = []
        self.deadlines: list[float | None] = []

    def solve_batch(self, parsed, indices, options, callback, deadline=None):
        self.batches.append(list(indices))
        self.deadlines.append(deadline)
        time.sleep(self.pause_s)
        return [{"value": parsed[i] ** 2, "status": "optimal", "certified": True, "nodes": 1, "cost": 1.0,
                 "lower_bound": 1.0} for i in indices]

    def solve_item(self, parsed, index, options, callback):
        raise AssertionError("a batching kind is given batches")

    @staticmethod
    def cancelled_item(options):
        return {"status": "cancelled", "certified": False, "nodes": 0, "cost": None, "lower_bound": None,
                "reason": "cancelled"}


class TestSolveBatch:
    def test_groups_in_order_and_progress_per_group(self):
        kind = CountingKind(batch_size=4)
        seen, progress = [], []
        items = solve_items(kind, list(range(20)), None, range(3, 13), sink=progress.append,
                            on_item=lambda index, item: seen.append((index, item["value"])))
        assert kind.batches == [[3, 4, 5, 6], [7, 8, 9, 10], [11, 12]]
        assert [item["value"] for item in items] == [i * i for i in range(3, 13)]
        assert seen == [(i, i * i) for i in range(3, 13)]
        # each item seen, progress once a group with every item of it counted
        assert [p["items_done"] for p in progress] == [4, 8, 10]
        assert [p["nodes"] for p in progress] == [4, 8, 10]

    def test_a_cancel_is_seen_between_groups(self):
        kind = CountingKind(batch_size=4)
        checks = iter([False, False, True])
        progress = []
        items = solve_items(kind, list(range(10)), None, range(10), sink=progress.append,
                            should_stop=lambda: next(checks, True))
        assert kind.batches == [[0, 1, 2, 3], [4, 5, 6, 7]]
        assert [item["status"] for item in items] == ["optimal"] * 8 + ["cancelled"] * 2
        assert progress[-1]["items_done"] == 8  # the cancelled were never started

    def test_the_budget_stops_between_groups(self):
        kind = CountingKind(batch_size=3)
        items = solve_items(kind, list(range(10)), None, range(10), stop_at=time.monotonic() - 1)
        assert kind.batches == [[0, 1, 2]] and len(items) == 3  # one group at least, then the caller goes on

    def test_the_jobs_deadline_is_one_clock_for_every_group(self):
        """Each group is given the job's deadline (its searches stop by it), and once it has
        passed no group starts: those items read time_limit, not started, uncertified, while
        the items finished before it are kept."""
        kind = CountingKind(batch_size=4, pause_s=0.2)
        deadline = time.monotonic() + 0.1
        progress = []
        items = solve_items(kind, list(range(10)), SimpleNamespace(job_time_limit_s=0.1), range(10),
                            sink=progress.append, deadline=deadline)
        assert kind.batches == [[0, 1, 2, 3]] and kind.deadlines == [deadline]
        assert [item["status"] for item in items] == ["optimal"] * 4 + ["time_limit"] * 6
        assert [item["value"] for item in items[:4]] == [0, 1, 4, 9]
        assert not any(item["certified"] for item in items[4:])
        assert all("job_time_limit_s" in item["reason"] and "not started" in item["reason"] for item in items[4:])
        assert progress[-1]["items_done"] == 10  # ended by the clock: counted, as a search's time_limit is

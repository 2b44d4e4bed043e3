"""Job metrics kept in Redis, so that every worker (on any machine) adds to the same figures and
the API's ``/metrics`` shows them (``app.metrics.RedisCollector`` reads them): jobs ended by
kind and status, items solved by kind and status, webhook attempts by outcome, and histograms of
item solve times and job times, all as fields of one hash."""

from __future__ import annotations

import bisect
import json

from geocert.jobs.store.base import StoreBase

METRICS_KEY = "geocert:metrics"
SOLVE_BUCKETS = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 60.0)
JOB_BUCKETS = (0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)


def _field(name: str, **labels) -> str:
    return json.dumps([name, labels], sort_keys=True)


def _observe(pipe, name: str, buckets, values: list[float], **labels) -> None:
    """Add ``values`` to a histogram: one increment per bucket (each answered by Redis, so a
    chunk's items are counted together rather than one command per item and bucket). The values
    are sorted once and each bucket's count found by bisection (a pass over every value for each
    of the 11 buckets cost 5,500 steps a 500-item chunk)."""
    ordered = sorted(values)
    for bound in buckets:
        count = bisect.bisect_right(ordered, bound)
        if count:
            pipe.hincrby(METRICS_KEY, _field(name + "_bucket", le=str(bound), **labels), count)
    pipe.hincrby(METRICS_KEY, _field(name + "_bucket", le="+Inf", **labels), len(values))
    pipe.hincrbyfloat(METRICS_KEY, _field(name + "_sum", **labels), sum(values))


def record_items(client, kind: str, items: list[dict]) -> None:
    statuses: dict[str, int] = {}
    for item in items:
        statuses[item["status"]] = statuses.get(item["status"], 0) + 1
    pipe = client.pipeline()
    for status, count in statuses.items():
        pipe.hincrby(METRICS_KEY, _field("items", kind=kind, status=status), count)
    times = [float(item["elapsed_s"]) for item in items if item["status"] != "cancelled"]
    if times:
        _observe(pipe, "item_solve_seconds", SOLVE_BUCKETS, times, kind=kind)
    pipe.execute()


def record_job_end(client, meta: dict) -> None:
    pipe = client.pipeline()
    pipe.hincrby(METRICS_KEY, _field("jobs", kind=meta["kind"], status=meta["status"]), 1)
    if meta.get("finished_at") and meta.get("created_at"):
        _observe(pipe, "job_seconds", JOB_BUCKETS, [meta["finished_at"] - meta["created_at"]], kind=meta["kind"])
    pipe.execute()


def record_webhook(client, state: str) -> None:
    client.hincrby(METRICS_KEY, _field("webhooks", state=state), 1)


class Metrics(StoreBase):
    def record_items(self, kind: str, items: list[dict]) -> None:
        """Count a chunk's items by status, and their solve times (one pipeline)."""
        record_items(self.r, kind, items)

    def record_job_end(self, meta: dict) -> None:
        """Count an ended job by kind and status, and its time from submission to end."""
        record_job_end(self.r, meta)

    def record_webhook(self, state: str) -> None:
        """Count one webhook attempt's outcome."""
        record_webhook(self.r, state)

    def metric_fields(self) -> dict[str, str]:
        """Every figure kept: field (a JSON [name, labels]) -> value."""
        return self.r.hgetall(METRICS_KEY)

    def list_lengths(self, names) -> int:
        """The tasks waiting in the broker's lists ``names`` (a queue's, by priority), in all."""
        return sum(self.r.llen(name) for name in names)

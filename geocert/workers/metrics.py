"""Job metrics kept in Redis, so that every worker (on any machine) adds to the same figures and
the API's ``/metrics`` shows them: jobs ended by kind and status, items solved by kind and
status, a histogram of item solve times, and the queue's depth."""

from __future__ import annotations

import json
import math

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily

METRICS_KEY = "geocert:metrics"
SOLVE_BUCKETS = (0.001, 0.003, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 60.0)
JOB_BUCKETS = (0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)
def _field(name: str, **labels) -> str:
    return json.dumps([name, labels], sort_keys=True)


def _observe(pipe, name: str, buckets, values: list[float], **labels) -> None:
    """Add ``values`` to a histogram: one increment per bucket (each answered by Redis, so a
    chunk's items are counted together rather than one command per item and bucket)."""
    for bound in buckets:
        count = sum(1 for value in values if value <= bound)
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


class RedisCollector:
    """A prometheus_client collector reading the shared figures (registered by the API)."""

    def __init__(self, client, queue_names=("celery", "webhooks")):  # celery_app.SOLVE_QUEUE, WEBHOOK_QUEUE
        self.client = client
        self.queue_names = queue_names

    @classmethod
    def of_store(cls, store) -> "RedisCollector":
        """The collector reading the Redis server of ``store`` (a JobStore): the API hands it its
        store, not the store's client."""
        return cls(store.r)

    def collect(self):
        raw = self.client.hgetall(METRICS_KEY)
        values: dict[str, list[tuple[dict, float]]] = {}
        for field, value in raw.items():
            name, labels = json.loads(field)
            values.setdefault(name, []).append((labels, float(value)))
        jobs = CounterMetricFamily("geocert_jobs", "Jobs ended, by kind and status", labels=["kind", "status"])
        for labels, value in values.get("jobs", []):
            jobs.add_metric([labels["kind"], labels["status"]], value)
        yield jobs
        items = CounterMetricFamily("geocert_items", "Items solved, by kind and status", labels=["kind", "status"])
        for labels, value in values.get("items", []):
            items.add_metric([labels["kind"], labels["status"]], value)
        yield items
        hooks = CounterMetricFamily("geocert_webhook_deliveries", "Webhook attempts by outcome", labels=["state"])
        for labels, value in values.get("webhooks", []):
            hooks.add_metric([labels["state"]], value)
        yield hooks
        yield from self._histograms(values, "item_solve_seconds", "Seconds to solve one item", SOLVE_BUCKETS)
        yield from self._histograms(values, "job_seconds", "Seconds from submission to the end of a job", JOB_BUCKETS)
        from geocert.workers.priorities import queue_lists

        depth = GaugeMetricFamily("geocert_queue_depth", "Tasks waiting in the queue", labels=["queue"])
        for queue in self.queue_names:
            depth.add_metric([queue], float(sum(self.client.llen(name) for name in queue_lists(queue))))
        yield depth

    @staticmethod
    def _histograms(values, name: str, documentation: str, buckets):
        family = HistogramMetricFamily(f"geocert_{name}", documentation, labels=["kind"])
        kinds = {labels["kind"] for labels, _ in values.get(name + "_bucket", [])}
        for kind in sorted(kinds):
            counts = {labels["le"]: value for labels, value in values[name + "_bucket"] if labels["kind"] == kind}
            total = sum(value for labels, value in values.get(name + "_sum", []) if labels["kind"] == kind)
            cumulative = [(str(bound), counts.get(str(bound), 0.0)) for bound in buckets]
            cumulative.append(("+Inf", counts.get("+Inf", 0.0)))
            family.add_metric([kind], cumulative, sum_value=total if math.isfinite(total) else 0.0)
        yield family

"""Job metrics kept in Redis, so that every worker (on any machine) adds to the same figures and
the API's ``/metrics`` shows them: jobs ended by kind and status, items solved by kind and
status, a histogram of item solve times, and the queue's depth. The workers write them through
the store (``JobStore.record_items``, ``record_job_end``, ``record_webhook``, in
geocert/jobs/store/metrics.py); this module reads them, through the store too, for /metrics."""

from __future__ import annotations

import json
import math

from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, HistogramMetricFamily

from geocert.jobs.store.metrics import JOB_BUCKETS, SOLVE_BUCKETS


class RedisCollector:
    """A prometheus_client collector reading the shared figures (registered by the API)."""

    def __init__(self, store, queue_names=("celery", "webhooks")):  # celery_app.SOLVE_QUEUE, WEBHOOK_QUEUE
        self.store = store
        self.queue_names = queue_names

    @classmethod
    def of_store(cls, store) -> "RedisCollector":
        """The collector reading the figures of ``store`` (a JobStore): the API hands it its
        store, not the store's client."""
        return cls(store)

    def collect(self):
        raw = self.store.metric_fields()
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
        pieces = CounterMetricFamily("geocert_pieces", "A task's independent pieces solved, by the task itself or by "
                                     "a helper on another solver process", labels=["solved_by"])
        for labels, value in values.get("pieces", []):
            pieces.add_metric([labels["solved_by"]], value)
        yield pieces
        yield from self._histograms(values, "item_solve_seconds", "Seconds to solve one item", SOLVE_BUCKETS)
        yield from self._histograms(values, "job_seconds", "Seconds from submission to the end of a job", JOB_BUCKETS)
        from geocert.workers.priorities import queue_lists

        depth = GaugeMetricFamily("geocert_queue_depth", "Tasks waiting in the queue", labels=["queue"])
        for queue in self.queue_names:
            depth.add_metric([queue], float(self.store.list_lengths(queue_lists(queue))))
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

"""Job metrics in a real Redis: a chunk's items are counted together (a few commands per chunk,
not one per item and bucket) into the same figures /metrics shows."""

from __future__ import annotations

import pytest


from geocert.jobs.store import JobStore
from geocert.app import metrics
from geocert.jobs.store import metrics as figures
from tests.support import embedded_redis_client


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    yield from embedded_redis_client(tmp_path_factory, decode_responses=True)


def families(client) -> dict:
    return {family.name: family for family in metrics.RedisCollector(JobStore(client)).collect()}


class TestRecordItems:
    def test_counts_statuses_and_a_cumulative_histogram(self, client):
        client.delete(figures.METRICS_KEY)
        items = ([{"status": "optimal", "elapsed_s": 0.002}] * 3 + [{"status": "optimal", "elapsed_s": 0.02}] * 2
                 + [{"status": "node_limit", "elapsed_s": 2.0}] + [{"status": "cancelled", "elapsed_s": 0.0}] * 4)
        figures.record_items(client, "triangulation", items[:5])
        figures.record_items(client, "triangulation", items[5:])
        found = families(client)
        counted = {sample.labels["status"]: sample.value for sample in found["geocert_items"].samples
                   if sample.name == "geocert_items_total"}
        assert counted == {"optimal": 5, "node_limit": 1, "cancelled": 4}
        buckets = {sample.labels["le"]: sample.value for sample in found["geocert_item_solve_seconds"].samples
                   if sample.name.endswith("_bucket")}
        assert (buckets["0.001"], buckets["0.003"], buckets["0.03"], buckets["1.0"], buckets["3.0"], buckets["+Inf"]) \
            == (0, 3, 5, 5, 6, 6)  # cancelled items are not timed
        total = [sample.value for sample in found["geocert_item_solve_seconds"].samples if sample.name.endswith("_sum")]
        assert total == [pytest.approx(3 * 0.002 + 2 * 0.02 + 2.0)]

    def test_a_time_on_a_buckets_bound_counts_in_it(self, client):
        """Prometheus's buckets are "less than or equal": a time equal to a bound counts in that
        bucket (the counts are found by bisection of the sorted times)."""
        client.delete(figures.METRICS_KEY)
        times = [0.001, 0.003, 0.003, 0.0031, 1.0, 60.0, 61.0]
        figures.record_items(client, "triangulation", [{"status": "optimal", "elapsed_s": t} for t in reversed(times)])
        buckets = {sample.labels["le"]: sample.value for sample in families(client)["geocert_item_solve_seconds"].samples
                   if sample.name.endswith("_bucket")}
        assert (buckets["0.001"], buckets["0.003"], buckets["0.01"], buckets["1.0"], buckets["60.0"], buckets["+Inf"]) \
            == (1, 3, 4, 5, 6, 7)

    def test_a_chunk_costs_a_few_commands_whatever_its_size(self, client):
        def commands(count: int) -> int:
            before = client.info("stats")["total_commands_processed"]
            figures.record_items(client, "triangulation", [{"status": "optimal", "elapsed_s": 0.01 * (i % 50)}
                                                           for i in range(count)])
            return client.info("stats")["total_commands_processed"] - before

        assert commands(500) == commands(50) <= 20

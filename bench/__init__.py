"""Benchmarks: each prints its figures and ratios measured side by side in one run."""

import time


def machine_speed_ms() -> float:
    """How long a fixed pure-Python loop (3 million additions) takes, in ms. The development
    machine's speed drifts by up to 70% between runs; printed beside a run's figures, this says
    how fast the machine was while they were measured."""
    start = time.perf_counter()
    total = 0
    for i in range(3_000_000):
        total += i
    return 1e3 * (time.perf_counter() - start)

"""What the map benchmarks share: applying a map, and fitting a set of problems at one norm and gap."""

from __future__ import annotations

import time

import numpy as np

from geocert.solvers.fractional.maps import MapOptions, fit_map


def apply(M: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Images of ``points`` (k, n) under the (m+1)x(n+1) map ``M``."""
    proj = np.hstack([points, np.ones((len(points), 1))]) @ M.T
    return proj[:, :-1] / proj[:, -1:]


def fit_all(problems, norm: str, gap: float, best_l2: list[float],
            **options) -> tuple[list[float], list[int], int, list[float]]:
    """Seconds and nodes per problem, how many were certified, and processor seconds per problem
    (wall times on a shared machine are inflated by the other work on it); records in ``best_l2``
    the best certified L2L2 cost of each problem (for the baselines)."""
    times, nodes, certified, cpu = [], [], 0, []
    for index, (source, target) in enumerate(problems):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = fit_map(source, target, MapOptions(norm=norm, rel_gap=gap, **options))
        cpu.append(time.process_time() - start_cpu)
        times.append(time.perf_counter() - start)
        nodes.append(result.nodes)
        certified += result.certified
        if norm == "L2L2" and result.certified:
            best_l2[index] = min(best_l2[index], result.cost)
    return times, nodes, certified, cpu

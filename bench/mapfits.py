"""What the map benchmarks share: applying a map, and fitting a set of problems at one norm and gap."""

from __future__ import annotations

import time

import numpy as np

from geocert.solvers.fractional.maps import MapOptions, fit_map


def apply(M: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Images of ``points`` (k, n) under the (m+1)x(n+1) map ``M``."""
    proj = np.hstack([points, np.ones((len(points), 1))]) @ M.T
    return proj[:, :-1] / proj[:, -1:]


def fit_all(problems, norm: str, gap: float, best_l2: list[float], **options) -> tuple[list[float], list[int], int]:
    """Seconds and nodes per problem and how many were certified; records in ``best_l2`` the best
    certified L2L2 cost of each problem (for the baselines)."""
    times, nodes, certified = [], [], 0
    for index, (source, target) in enumerate(problems):
        start = time.perf_counter()
        result = fit_map(source, target, MapOptions(norm=norm, rel_gap=gap, **options))
        times.append(time.perf_counter() - start)
        nodes.append(result.nodes)
        certified += result.certified
        if norm == "L2L2" and result.certified:
            best_l2[index] = min(best_l2[index], result.cost)
    return times, nodes, certified

"""Options and anytime statuses: node and time limits report the gap reached; max_residual
narrows the certificate's scope."""

import numpy as np
import pytest

from geocert.solvers.fractional.triangulation import TriangulationOptions, triangulate

from tests.support import noisy_track, random_cameras


def instance(seed: int, views: int = 5):
    rng = np.random.default_rng(seed)
    cameras = random_cameras(rng, views)
    _, points = noisy_track(rng, cameras, noise_px=3.0)
    return cameras, points


class TestAnytimeStatuses:
    @pytest.mark.parametrize("limit", [{"max_nodes": 1}, {"time_limit_s": 0.0}])
    def test_limit_stops_with_a_valid_uncertified_gap(self, limit):
        cameras, points = instance(31)
        full = triangulate(cameras, points, TriangulationOptions(norm="L1L1", rel_gap=1e-9))
        stopped = triangulate(cameras, points, TriangulationOptions(norm="L1L1", rel_gap=0.0, abs_gap=0.0, **limit))
        assert stopped.status == ("node_limit" if "max_nodes" in limit else "time_limit")
        assert not stopped.certified
        assert stopped.point is not None and stopped.gap > 0
        # The bound reached is still a bound, and the point still a point of the domain.
        assert stopped.lower_bound <= full.cost * (1 + 1e-9)
        assert stopped.cost >= full.lower_bound * (1 - 1e-9)


class TestMaxResidual:
    def test_generous_bound_changes_nothing_but_the_scope(self):
        cameras, points = instance(32)
        plain = triangulate(cameras, points, TriangulationOptions())
        bounded = triangulate(cameras, points, TriangulationOptions(max_residual=50.0))
        assert bounded.certified
        assert bounded.cost == pytest.approx(plain.cost, rel=1e-3)
        assert "every residual <= 50.0" in bounded.certificate.scope

    def test_bound_below_every_solution_is_found_empty_and_not_certified(self):
        cameras, points = instance(33)
        plain = triangulate(cameras, points, TriangulationOptions())
        worst = float(np.max(np.linalg.norm(np.array(plain.residuals), axis=1)))
        # Every point X has a residual >= sqrt(cost(X) / views) >= sqrt(optimum / views)
        # >= worst / sqrt(views), and worst / 100 is far below that: no point meets the bound.
        bounded = triangulate(cameras, points, TriangulationOptions(max_residual=worst / 100))
        # Every box closes empty, but that proof is not carried: not_certified, the reason says it.
        assert bounded.status == "not_certified" and not bounded.certified
        assert "max_residual" in bounded.reason and "every box" in bounded.reason

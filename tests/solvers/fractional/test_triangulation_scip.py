"""3 to 6 views: agreement with an independent global solver (SCIP) under every norm."""

import math

import numpy as np
import pytest

pyscipopt = pytest.importorskip("pyscipopt")

from testing.baselines import scip_triangulate
from geocert.core.geometry import norm_cost
from geocert.solvers.fractional.triangulation import NORMS, TriangulationOptions, triangulate

from tests.support import noisy_track, random_cameras


pytestmark = pytest.mark.slow  # real servers, real data or SCIP: the full run only


class TestAgainstSCIP:
    @pytest.mark.parametrize("norm", NORMS)
    def test_twenty_instances(self, norm):
        rng = np.random.default_rng({"L2L2": 11, "L2L1": 12, "L1L1": 13}[norm])
        options = TriangulationOptions(norm=norm, rel_gap=1e-6)
        closed = 0
        for _ in range(20):
            count = int(rng.integers(3, 7))
            cameras = random_cameras(rng, count)
            truth, points = noisy_track(rng, cameras, noise_px=2.0)
            ours = triangulate(cameras, points, options)
            assert ours.certified, ours.reason
            # SCIP needs a bounded search box: one that holds our optimum with a wide margin
            # (2 px noise moves the optimum about 0.02 scene units from the truth).
            assert np.max(np.abs(np.array(ours.point) - truth[:3])) < 0.25
            X, reached_gap, scip_lower = scip_triangulate(cameras, points, norm, truth[:3], radius=0.5)
            if X is None:
                continue
            proj = cameras @ X
            scip_cost = norm_cost(proj[:, :2] / proj[:, 2:3] - points, norm)  # recomputed at SCIP's point
            # SCIP's point is feasible, so it can never beat our certified lower bound ...
            assert ours.lower_bound <= scip_cost * (1 + 1e-7) + 1e-9
            # ... and SCIP's proven lower bound can never exceed the cost of our point.
            assert scip_lower <= ours.cost * (1 + 1e-7) + 1e-9
            if reached_gap:  # both solvers claim the global optimum: the values agree tightly
                closed += 1
                assert math.isclose(ours.cost, scip_cost, rel_tol=2e-5, abs_tol=1e-7), (ours.cost, scip_cost)
        assert closed >= 15, f"SCIP reached its gap on only {closed} of 20 instances"

"""3 to 6 views: agreement with an independent global solver (SCIP) under every norm."""

import math

import numpy as np
import pytest

pyscipopt = pytest.importorskip("pyscipopt")

from solvers.geometry import norm_cost
from solvers.triangulation import NORMS, TriangulationOptions, triangulate

from .scenes import noisy_track, random_cameras


def scip_triangulate(cameras: np.ndarray, points: np.ndarray, norm: str, centre: np.ndarray, radius: float,
                     quiet: bool = True, time_limit: float = 15) -> tuple[np.ndarray | None, bool, float]:
    """SCIP's spatial branch and bound: (its best point, whether it reached its gap, its dual bound).

    Residuals (in units of 100 px) are variables tied to X by bilinear equalities
    ``d * depth = (row - u * depth_row) . X``; X is searched in the box ``centre +- radius``.
    """
    scale = 100.0
    model = pyscipopt.Model()
    model.hideOutput(quiet)
    model.setParam("numerics/feastol", 1e-9)
    model.setParam("limits/gap", 1e-5)
    model.setParam("limits/time", time_limit)
    X = [model.addVar(lb=centre[k] - radius, ub=centre[k] + radius, name=f"x{k}") for k in range(3)]

    def linear(row):
        return row[0] * X[0] + row[1] * X[1] + row[2] * X[2] + row[3]

    terms = []
    for i, P in enumerate(cameras):
        P = P / np.linalg.norm(P[2, :3])
        depth = linear(P[2])
        model.addCons(depth >= 1e-3)
        residuals = []
        for row in range(2):
            d = model.addVar(lb=-20, ub=20, name=f"d{i}{row}")
            model.addCons(d * depth * scale == linear(P[row] - points[i, row] * P[2]))
            residuals.append(d)
        if norm == "L2L2":
            terms.append(residuals[0] * residuals[0] + residuals[1] * residuals[1])
        elif norm == "L2L1":
            e = model.addVar(lb=0, ub=30, name=f"e{i}")
            # sqrt, not e*e >= ...: the squared form hides a 1e-3 px residual inside the tolerance
            model.addCons(e >= pyscipopt.sqrt(residuals[0] * residuals[0] + residuals[1] * residuals[1]))
            terms.append(e)
        else:
            for row in range(2):
                a = model.addVar(lb=0, ub=20, name=f"a{i}{row}")
                model.addCons(a >= residuals[row])
                model.addCons(a >= -residuals[row])
                terms.append(a)
    objective = model.addVar(lb=0, ub=1e4, name="objective")
    model.addCons(objective >= pyscipopt.quicksum(terms))
    model.setObjective(objective, "minimize")
    try:
        model.optimize()
    except Exception:  # SCIP's own LP trouble ("unresolved numerical troubles"): no answer from it
        return None, False, -math.inf
    status = model.getStatus()
    assert status in ("optimal", "gaplimit", "timelimit"), status
    dual_bound = model.getDualbound() * scale**2 if norm == "L2L2" else model.getDualbound() * scale
    return np.array([model.getVal(x) for x in X] + [1.0]), status != "timelimit", dual_bound


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

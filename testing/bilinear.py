"""Bilinear fitting scenes (thesis 8.5.1) and SCIP's answer on them, shared by the bilinear tests
and bench/bilinear.py."""

from __future__ import annotations

import numpy as np

from geocert.formulations.bilinear import problem


def scene(K: int, N: int, noise: float, seed: int, outliers: float = 0.0, image: float = 100.0):
    """Thesis 8.5.1: exemplars uniform in [-1, 1]^3, convex coefficients, camera entries uniform in
    [-1, 1] (times ``image``, so the image spans about 2 * image units); Gaussian noise of
    ``noise`` (a fraction of the image size, 2 * image) and a fraction ``outliers`` of points moved
    by 10% of the image size."""
    rng = np.random.default_rng(seed)
    basis = rng.uniform(-1, 1, (K, N, 3))
    alpha = rng.uniform(0, 1, K)
    alpha /= alpha.sum()
    camera = rng.uniform(-1, 1, (2, 4)) * image
    clean = problem.shape_of(basis, alpha) @ camera[:, :3].T + camera[:, 3]
    size = 2 * image
    points = clean + rng.normal(size=clean.shape) * noise * size
    bad = rng.choice(N, int(round(outliers * N)), replace=False)
    directions = rng.normal(size=(len(bad), 2))
    points[bad] += 0.1 * size * directions / np.linalg.norm(directions, axis=1, keepdims=True)
    return basis, points, camera, alpha, clean


def scip_bilinear(basis: np.ndarray, points: np.ndarray, norm: str, camera_bound: float, time_limit: float = 60,
                  gap: float = 1e-7) -> tuple[float, float, bool]:
    """SCIP's spatial branch and bound on the same problem (convex coefficients, |M_rk| <=
    camera_bound, any translation): (its best cost, its dual bound, whether it reached its gap)."""
    import pyscipopt

    K, N, _ = basis.shape
    seen = np.flatnonzero(~np.isnan(points[:, 0]))
    model = pyscipopt.Model()
    model.hideOutput()
    model.setParam("numerics/feastol", 1e-9)
    model.setParam("limits/gap", gap)
    model.setParam("limits/time", time_limit)
    M = [[model.addVar(lb=-camera_bound, ub=camera_bound, name=f"M{r}{k}") for k in range(3)] for r in range(2)]
    reach = float(np.abs(points[seen]).max() + 3 * camera_bound * np.abs(basis).max() + 1)
    t = [model.addVar(lb=-reach, ub=reach, name=f"t{r}") for r in range(2)]
    alpha = [model.addVar(lb=0, ub=1, name=f"a{i}") for i in range(K)]
    model.addCons(pyscipopt.quicksum(alpha) == 1)
    terms = []
    for j in seen:
        for r in range(2):
            image = pyscipopt.quicksum(float(basis[i, j, k]) * M[r][k] * alpha[i] for i in range(K) for k in range(3))
            res = model.addVar(lb=-reach * 2, ub=reach * 2, name=f"r{j}{r}")
            model.addCons(res == float(points[j, r]) - image - t[r])
            if norm == "L2L2":
                terms.append(res * res)
            else:
                e = model.addVar(lb=0, ub=reach * 2, name=f"e{j}{r}")
                model.addCons(e >= res)
                model.addCons(e >= -res)
                terms.append(e)
    objective = model.addVar(lb=0, ub=1e12, name="objective")
    model.addCons(objective >= pyscipopt.quicksum(terms))
    model.setObjective(objective, "minimize")
    model.optimize()
    return model.getObjVal(), model.getDualbound(), model.getStatus() in ("optimal", "gaplimit")

"""Baselines measured beside our solver: SCIP (an independent global solver) and OpenCV's
linear triangulation followed by Levenberg-Marquardt (what most pipelines do)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pyscipopt
import scipy.optimize


def norm_terms(model, residuals: list, norm: str, tag: str, bound: float) -> list:
    """SCIP objective terms of one observation's residual variables under the norm."""
    if norm == "L2L2":
        return [pyscipopt.quicksum(r * r for r in residuals)]
    if norm == "L2L1":
        e = model.addVar(lb=0, ub=bound, name=f"e{tag}")
        # sqrt, not e*e >= ...: the squared form hides a 1e-3 px residual inside the tolerance
        model.addCons(e >= pyscipopt.sqrt(pyscipopt.quicksum(r * r for r in residuals)))
        return [e]
    terms = []
    for k, r in enumerate(residuals):
        a = model.addVar(lb=0, ub=bound, name=f"a{tag}_{k}")
        model.addCons(a >= r)
        model.addCons(a >= -r)
        terms.append(a)
    return terms


def scip_triangulate(cameras: np.ndarray, points: np.ndarray, norm: str, centre: np.ndarray, radius: float,
                     quiet: bool = True, time_limit: float = 15, gap: float = 1e-5,
                     ) -> tuple[np.ndarray | None, bool, float]:
    """SCIP's spatial branch and bound: (its best point, whether it reached its gap, its dual bound).

    Residuals (in units of 100 px) are variables tied to X by bilinear equalities
    ``d * depth = (row - u * depth_row) . X``; X is searched in the box ``centre +- radius``.
    """
    scale = 100.0
    model = pyscipopt.Model()
    model.hideOutput(quiet)
    model.setParam("numerics/feastol", 1e-9)
    model.setParam("limits/gap", gap)
    model.setParam("timing/clocktype", 1)  # the limit in CPU seconds, which other processes cannot use up
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
        terms += norm_terms(model, residuals, norm, f"{i}", bound=30)
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


def dlt_lm(cameras: np.ndarray, points: np.ndarray) -> np.ndarray:
    """OpenCV's linear triangulation (N-view DLT for more than two views), then LM on the
    reprojection error in Euclidean coordinates; no chirality constraint, as usually done."""
    if len(cameras) == 2:
        X = cv2.triangulatePoints(cameras[0], cameras[1], points[0].reshape(2, 1), points[1].reshape(2, 1)).ravel()
    else:
        rows = np.concatenate([points[:, 0:1] * cameras[:, 2] - cameras[:, 0],
                               points[:, 1:2] * cameras[:, 2] - cameras[:, 1]])
        X = np.linalg.svd(rows)[2][-1]
    start = X[:3] / X[3]

    def residuals(x):
        proj = cameras @ np.append(x, 1.0)
        return (proj[:, :2] / proj[:, 2:3] - points).ravel()

    fit = scipy.optimize.least_squares(residuals, start, method="lm" if residuals(start).size >= 3 else "trf")
    return np.append(fit.x, 1.0)


def dlt_leastsq(cameras: np.ndarray, points: np.ndarray) -> np.ndarray:
    """dlt_lm's start (OpenCV's linear triangulation), then MINPACK's Levenberg-Marquardt
    (scipy.optimize.leastsq, lmder with the analytic Jacobian): the cheapest good local solve of
    one track in plain scipy."""
    if len(cameras) == 2:
        X = cv2.triangulatePoints(cameras[0], cameras[1], points[0].reshape(2, 1), points[1].reshape(2, 1)).ravel()
    else:
        rows = np.concatenate([points[:, 0:1] * cameras[:, 2] - cameras[:, 0],
                               points[:, 1:2] * cameras[:, 2] - cameras[:, 1]])
        X = np.linalg.svd(rows)[2][-1]
    A, b = cameras[:, :, :3], cameras[:, :, 3]

    def residuals(x):
        proj = A @ x + b
        return (proj[:, :2] / proj[:, 2:3] - points).ravel()

    def jacobian(x):
        proj = A @ x + b
        image = proj[:, :2] / proj[:, 2:3]
        return ((A[:, :2] - image[:, :, None] * A[:, 2:3]) / proj[:, 2:3, None]).reshape(-1, 3)

    return np.append(scipy.optimize.leastsq(residuals, X[:3] / X[3], Dfun=jacobian)[0], 1.0)


def map_dlt_lm(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The usual pipeline for a projective map: normalised DLT, then LM on the reprojection
    error (OpenCV's findHomography does the same for 2D homographies)."""
    from geocert.solvers.fractional.maps import dlt

    M0 = dlt(source, target)
    homogeneous = np.hstack([source, np.ones((len(source), 1))])

    def residuals(flat):
        proj = homogeneous @ flat.reshape(M0.shape).T
        return (proj[:, :-1] / proj[:, -1:] - target).ravel()

    start = (M0 / np.linalg.norm(M0)).ravel()
    fit = scipy.optimize.least_squares(residuals, start, method="lm" if residuals(start).size >= start.size else "trf")
    return fit.x.reshape(M0.shape)


def scip_map(source: np.ndarray, target: np.ndarray, norm: str, box: float = 10.0, time_limit: float = 30,
             gap: float = 1e-5) -> tuple[np.ndarray | None, bool, float, float]:
    """SCIP on a P^n -> P^m map: (its map in the caller's coordinates, whether it reached its
    gap, its dual bound in the caller's units, the largest |entry| of our normalisation of
    its map — to check the box held).

    Coordinates are normalised (source and target similarities, which leave the norms unchanged
    up to the target's scale); the scale is fixed by the first point's depth being 1 and every
    entry of the normalised map lies in [-box, box]. Residuals d are variables tied to the map by
    ``d * depth = M_k . X - x_k * depth``.
    """
    from geocert.formulations.fractional.charts import normaliser

    n, m = source.shape[1], target.shape[1]
    S, T = normaliser(source), normaliser(target)
    X = (S @ np.hstack([source, np.ones((len(source), 1))]).T).T
    x = (T @ np.hstack([target, np.ones((len(target), 1))]).T).T[:, :m]
    model = pyscipopt.Model()
    model.hideOutput()
    model.setParam("numerics/feastol", 1e-9)
    model.setParam("limits/gap", gap)
    model.setParam("timing/clocktype", 1)  # the limit in CPU seconds, which other processes cannot use up
    model.setParam("limits/time", time_limit)
    M = [[model.addVar(lb=-box, ub=box, name=f"M{r}{c}") for c in range(n + 1)] for r in range(m + 1)]

    def row_dot(r, point):
        return pyscipopt.quicksum(float(point[c]) * M[r][c] for c in range(n + 1))

    model.addCons(row_dot(m, X[0]) == 1)
    terms = []
    for j in range(len(X)):
        depth = model.addVar(lb=1e-4, ub=1e4, name=f"g{j}")
        model.addCons(depth == row_dot(m, X[j]))
        d = [model.addVar(lb=-100, ub=100, name=f"d{j}{k}") for k in range(m)]
        for k in range(m):
            model.addCons(d[k] * depth == row_dot(k, X[j]) - float(x[j, k]) * depth)
        terms += norm_terms(model, d, norm, f"{j}", bound=200)
    objective = model.addVar(lb=0, ub=1e6, name="objective")
    model.addCons(objective >= pyscipopt.quicksum(terms))
    model.setObjective(objective, "minimize")
    try:
        model.optimize()
    except Exception:  # SCIP's own LP trouble: no answer from it
        return None, False, -math.inf, math.nan
    status = model.getStatus()
    if model.getNSols() == 0:
        return None, False, -math.inf, math.nan
    Mn = np.array([[model.getVal(v) for v in row] for row in M])
    scale = T[0, 0]  # target units -> normalised units
    dual = model.getDualbound() / (scale**2 if norm == "L2L2" else scale)
    return np.linalg.inv(T) @ Mn @ S, status in ("optimal", "gaplimit"), dual, float(np.abs(Mn).max())

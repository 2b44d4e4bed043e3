"""How well the data fix an answer: intervals from the cost's local curvature, and warnings.

A certificate proves that nothing in the scope costs less than the bound; it does not say that the
answer is the only one that fits. Near the optimum the squared residuals grow like
``|r(theta* + d)|^2 ~ cost* + d' J'J d`` (J the residuals' Jacobian, Gauss-Newton), so the
parameters costing at most ``cost* + delta`` form an ellipsoid, and a quantity g(theta) ranges
over ``g* +- sqrt(delta g' (J'J)^+ g)`` on it. Along a direction where J'J is (numerically) singular
the data do not fix the answer at all: a quantity with a component there is unbounded.

``delta`` is ``sigmas^2`` times the residual variance the fit itself estimates (cost / (n - p),
the usual least-squares standard error; 3 by default, so an interval is 3 standard errors), and
never less than the certified gap (cost - lower_bound). These intervals are estimates (the
curvature is the local one), not proofs; the result says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

SIGMAS = 3.0
SINGULAR = 1e-10  # an eigenvalue of J'J below this fraction of the largest: a direction the data do not fix


@dataclass
class Determinacy:
    intervals: list[dict] = field(default_factory=list)  # {name, value, lower, upper} (None: unbounded)
    warnings: list[dict] = field(default_factory=list)  # {code, detail}
    cost_increase: float | None = None  # delta
    redundancy: int = 0  # n - p: residuals beyond the parameters
    method: str = "curvature"
    proven: bool = False

    def document(self) -> dict:
        determined = all(i["lower"] is not None and i["upper"] is not None for i in self.intervals)
        return {"method": self.method, "proven": self.proven, "determined": determined and not self.warnings,
                "level": (f"parameters whose squared residuals exceed the optimum's by at most cost_increase "
                          f"(max of {SIGMAS:g}^2 times the fit's residual variance and the certified gap), "
                          "by the local curvature (Gauss-Newton)"),
                "cost_increase": _finite(self.cost_increase), "redundancy": self.redundancy,
                "intervals": self.intervals, "warnings": self.warnings}


def safely(function, *args, **kwargs) -> dict | None:
    """A determinacy document, or None when the data defeat the estimate's own linear algebra (it
    is an estimate beside the answer: it never fails a solve)."""
    try:
        with np.errstate(all="ignore"):
            return function(*args, **kwargs)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None


def certified_gap(cost: float | None, lower: float | None) -> float | None:
    """cost - lower_bound when both are finite numbers (None otherwise)."""
    if cost is None or lower is None or not (math.isfinite(cost) and math.isfinite(lower)):
        return None
    return max(cost - lower, 0.0)


def _finite(value: float | None) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def numeric_jacobian(function, theta: np.ndarray, step: float = 1e-6) -> np.ndarray:
    """Central differences, the step relative to each parameter's size."""
    theta = np.asarray(theta, dtype=float)
    columns = []
    for k in range(len(theta)):
        h = step * max(1.0, abs(theta[k]))
        e = np.zeros_like(theta)
        e[k] = h
        columns.append((np.asarray(function(theta + e)) - np.asarray(function(theta - e))) / (2 * h))
    return np.array(columns).T


def curvature_intervals(J: np.ndarray, residuals: np.ndarray, quantities: dict[str, tuple[float, np.ndarray]],
                        gap: float | None = None, sigmas: float = SIGMAS) -> Determinacy:
    """Intervals for quantities (name -> (value, gradient in the parameters)) around an optimum
    with residual Jacobian J (n x p) and residuals r."""
    J = np.asarray(J, dtype=float)
    r = np.asarray(residuals, dtype=float)
    n, p = J.shape
    information = J.T @ J if np.all(np.isfinite(J)) else np.full((p, p), np.nan)
    return information_intervals(information, float(r @ r), n - p, quantities, gap, sigmas)


def information_intervals(information: np.ndarray, cost: float, redundancy: int,
                          quantities: dict[str, tuple[float, np.ndarray]], gap: float | None = None,
                          sigmas: float = SIGMAS) -> Determinacy:
    """The same from J'J itself (or a Schur complement of it, for parameters of interest with the
    others eliminated), the squared residuals' sum and n - p."""
    delta = sigmas ** 2 * cost / redundancy if redundancy > 0 else 0.0
    if gap is not None and math.isfinite(gap):
        delta = max(delta, gap)
    out = Determinacy(cost_increase=delta, redundancy=redundancy)
    if not (np.all(np.isfinite(information)) and math.isfinite(delta)):
        for name, (value, _) in quantities.items():
            out.intervals.append({"name": name, "value": _finite(value), "lower": None, "upper": None})
        return out
    values, vectors = np.linalg.eigh(0.5 * (information + information.T))
    largest = max(float(values[-1]), 1e-300)
    fixed = values > SINGULAR * largest
    for name, (value, gradient) in quantities.items():
        g = vectors.T @ np.asarray(gradient, dtype=float)
        free = np.abs(g[~fixed]).max(initial=0.0)
        if free > 1e-6 * max(np.abs(g).max(), 1e-300) or not math.isfinite(value):
            out.intervals.append({"name": name, "value": _finite(value), "lower": None, "upper": None})
            continue
        half = math.sqrt(delta * float(np.sum(g[fixed] ** 2 / values[fixed])))
        out.intervals.append({"name": name, "value": float(value), "lower": float(value - half),
                              "upper": float(value + half)})
    return out


def spread(points: np.ndarray) -> np.ndarray:
    """Singular values of the centred points over the largest (1, then smaller: how flat they are)."""
    points = np.asarray(points, dtype=float)
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return s / max(float(s[0]), 1e-300)

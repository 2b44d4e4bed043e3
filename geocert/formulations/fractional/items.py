"""One fractional item (a track, a map) as the solver and the verifier both read it, numpy only:
its raw arrays, its program rebuilt with the solver's charts, its residuals and depths from the raw
data; and what a solver asks before it returns a certified bound: the bound as the verifier proves
it for the data's problem (``discounted``) and whether the verifier would refuse the solution
(``refused_by_verifier``). The verifier's adapters of the fractional kinds, which read whole
documents of items, are geocert/verify/fractional.py."""

from __future__ import annotations

import numpy as np

from geocert.core import exact
from geocert.core.certificates import OBJECTIVE_TOLERANCE, residual_rounding
from geocert.core.geometry import cost_rounding, norm_cost
from geocert.core.strict import Invalid, numbers
from geocert.formulations.fractional.charts import Chart, MapChart
from geocert.formulations.fractional.results import LocalCertificate
from geocert.formulations.fractional.proof import (SOLVER_DISCOUNT_FACTOR, check_program, program_allowance,
                                              program_discount, raw_sizes, residual_uncertainty, track_uncertainty)


class TrackItem:
    """One track's program and the maps between its point and the program's variables."""

    def __init__(self, arrays: tuple, norm: str, chart: Chart | None = None):
        """``chart``: the one the solver built from these arrays, when a solver checks its own
        result as the verifier will (the verifier always rebuilds it)."""
        self.norm = norm
        self.cameras, self.points = arrays
        if chart is False:  # its residuals only: no program is built
            return
        self.chart = chart if chart is not None else Chart.build(self.cameras, self.points, norm)
        self.program = self.chart.program

    def solution(self, claim: dict) -> np.ndarray:
        """A finite point [x, y, z], or a point at infinity (a 4-vector with last coordinate
        exactly 0, signed so that its depths are positive)."""
        point = claim.get("point")
        at_infinity = claim.get("at_infinity")
        if at_infinity is True:
            X = numbers(point, "point", (4,))
            if X[3] != 0:
                raise Invalid("claim", "a point at infinity must have last coordinate 0")
            return X
        if at_infinity is not False:
            raise Invalid("claim", "at_infinity must be true or false")
        return np.append(numbers(point, "point", (3,)), 1.0)

    def raw_residuals(self, solution) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Residuals and depths of the solution from the raw data, computed as the solver
        computes them (projection minus observation), and a bound on each residual coordinate's
        rounding error (certificates.ROUNDING of the two's sizes)."""
        proj = self.cameras @ solution
        image = proj[:, :2] / proj[:, 2:3]
        return image - self.points, proj[:, 2], residual_rounding(image, self.points)

    def raw_parts_many(self, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each residual as numerator / depth, from the raw data only, at the points of the
        program's variables ``vs`` (n, 3), at once."""
        solutions = np.hstack([vs, np.ones((len(vs), 1))]) @ self.chart.T.T  # (n, 4)
        proj = np.einsum("Nij,nj->nNi", self.cameras, solutions)  # (n, N, 3)
        return proj[..., :2] - self.points * proj[..., 2:3], proj[..., 2]

    def residual_uncertainty(self, solution: np.ndarray) -> np.ndarray:
        return track_uncertainty(self.cameras, solution)

    def exact_residuals(self, solution: np.ndarray) -> np.ndarray:
        """raw_residuals' residuals computed exactly and rounded once (core.exact)."""
        return -exact.residuals(self.cameras, solution, self.points)

    def raw_sizes_many(self, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The size of the terms behind each numerator and depth of raw_parts_many (the sums of
        their products' magnitudes): their round-off is a tiny part of it."""
        solutions = np.hstack([vs, np.ones((len(vs), 1))]) @ self.chart.T.T
        return raw_sizes(self.cameras, self.points, solutions)

    def depths_agree(self, depths: np.ndarray) -> bool:
        return bool(np.all(depths > 0))

    def to_program(self, solution) -> np.ndarray | None:
        w = np.linalg.solve(self.chart.T, solution)
        return w[:3] / w[3] if w[3] > 0 else None

    def from_program(self, v: np.ndarray):
        return self.chart.T @ np.append(v, 1.0)


class MapItem:
    """One map's program and the maps between its matrix and the program's variables."""

    def __init__(self, arrays: tuple, norm: str, chart: MapChart | None = None):
        """``chart``: as TrackItem's."""
        self.norm = norm
        self.source, self.target = arrays
        if chart is False:  # its residuals only: no program is built
            return
        self.chart = chart if chart is not None else MapChart.build(self.source, self.target, norm)
        self.program = self.chart.program

    def solution(self, claim: dict) -> np.ndarray:
        return numbers(claim.get("matrix"), "matrix", (self.target.shape[1] + 1, self.source.shape[1] + 1))

    def raw_residuals(self, solution) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        proj = np.hstack([self.source, np.ones((len(self.source), 1))]) @ solution.T
        image = proj[:, :-1] / proj[:, -1:]
        return self.target - image, proj[:, -1], residual_rounding(image, self.target)

    def raw_parts(self, solution) -> tuple[np.ndarray, np.ndarray]:
        homogeneous = np.hstack([self.source, np.ones((len(self.source), 1))])
        proj = homogeneous @ solution.T
        return self.target * proj[:, -1:] - proj[:, :-1], proj[:, -1]

    def raw_parts_many(self, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each residual as numerator / depth, from the raw data only, at each of ``vs``."""
        parts = [self.raw_parts(self.from_program(v)) for v in vs]
        return np.array([p[0] for p in parts]), np.array([p[1] for p in parts])

    def residual_uncertainty(self, solution: np.ndarray) -> np.ndarray:
        homogeneous = np.hstack([self.source, np.ones((len(self.source), 1))])
        return residual_uncertainty(homogeneous @ solution.T, np.abs(homogeneous) @ np.abs(solution).T)

    def exact_residuals(self, solution: np.ndarray) -> np.ndarray:
        """raw_residuals' residuals computed exactly and rounded once (core.exact)."""
        return exact.residuals(solution, np.hstack([self.source, np.ones((len(self.source), 1))]), self.target)

    def raw_sizes_many(self, vs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The size of the terms behind each numerator ``target * depth - row . X`` and depth
        ``last row . X`` of raw_parts_many: the sums of their products' magnitudes."""
        homogeneous = np.abs(np.hstack([self.source, np.ones((len(self.source), 1))]))
        terms = np.array([homogeneous @ np.abs(self.from_program(v)).T for v in vs])  # (n, count, m + 1)
        return np.abs(self.target)[None] * terms[..., -1:] + terms[..., :-1], terms[..., -1]

    def depths_agree(self, depths: np.ndarray) -> bool:
        return bool(np.all(depths > 0) or np.all(depths < 0))  # a map is defined up to its sign

    def to_program(self, solution) -> np.ndarray | None:
        v = self.chart.from_matrix(solution)
        return v if v is not None else self.chart.from_matrix(-solution)

    def from_program(self, v: np.ndarray):
        return self.chart.matrix(v)


def stated_residuals(item, solution: np.ndarray, residuals: np.ndarray, norm: str,
                     always: bool = False) -> tuple[np.ndarray, float]:
    """The residuals and cost a result states, as the verifier reads them (checks.
    _check_residual_claim): the floats where their rounding cannot move the cost past
    exact.FLOAT_SHARE of OBJECTIVE_TOLERANCE, the residuals computed exactly otherwise (far-off
    data, a near-exact fit), or ``always``."""
    with np.errstate(all="ignore"):
        cost = float(norm_cost(residuals, norm))
        if always or exact.needs_exact(residuals, item.residual_uncertainty(solution), cost, norm,
                                       OBJECTIVE_TOLERANCE):
            residuals = item.exact_residuals(solution)
            cost = exact.cost(residuals, norm)
    return residuals, cost


def stated_tolerance(certificate, status: str, lower: float | None, cost: float, options) -> None:
    """A certified search's summary states its tolerance from the cost the result states, as the
    verifier recomputes it (checks: max(abs_gap, rel_gap * cost)), not from the search's incumbent
    in its program, which far off differs from the data's cost past the check's 1e-6 relative (a
    resection 1e5 from the origin under L2L1: 1.1e-6)."""
    if (status == "optimal" and lower is not None and isinstance(getattr(certificate, "tolerance", None), float)
            and not isinstance(certificate, LocalCertificate) and np.isfinite(cost)):
        certificate.tolerance = max(options.abs_gap, options.rel_gap * abs(cost))


PROGRAM_REFUSED = "the verifier could not check the proof against the data at this solution ({})"
UNDISCOUNTABLE = ("an observation's depth is round-off at the solution (a point on a view's principal plane "
                  "or at its centre): the search's bound does not carry over to the data's problem, only the trivial bound 0 does")


def discounted(item, solution: np.ndarray, residuals: np.ndarray, lower: float,
               scale: float | None) -> tuple[float, str | None]:
    """A search's lower bound (caller's units) as the verifier proves it for the data's problem:
    less the program's distance from it at the solution (proof.program_discount); the trivial
    bound (``scale`` None) needs no program. A solution outside the chart keeps the bound: the
    verifier refuses it anyway. Where the distance is unbounded (an observation whose depth is
    round-off there) the verifier proves nothing beyond the trivial bound 0: that bound is
    returned, with the reason (the second value; None otherwise)."""
    if scale is None or item.to_program(solution) is None:
        return lower, None
    with np.errstate(all="ignore"):
        discount = SOLVER_DISCOUNT_FACTOR * program_discount(item, solution, residuals,
                                                            program_allowance(item, solution, scale))
    return (lower - discount, None) if np.isfinite(discount) else (min(lower, 0.0), UNDISCOUNTABLE)


def refused_by_verifier(item, solution: np.ndarray, residuals: np.ndarray, cost: float, options,
                        scale: float | None) -> str | None:
    """Why the verifier would refuse this solution of a certified solve of ``item`` (built on the
    solver's own chart), if it would: its depths from the raw data; a cost the data determine
    only to more than half the tolerance (a point nearly on a principal plane: a residual is the
    difference of far larger numbers); a program that does not agree with the data (half the
    verifier's tolerance; only with ``scale``, the search's: the trivial bound needs no program)."""
    _, depths, _ = item.raw_residuals(solution)
    if not item.depths_agree(depths):
        return "the solution as returned puts a point at non-positive depth once recomputed from the data"
    spread = cost_rounding(residuals, item.residual_uncertainty(solution), options.norm)
    tolerance = max(options.abs_gap, options.rel_gap * abs(cost))
    if not spread <= 0.5 * tolerance:
        return (f"the data determine the solution's cost only to within {spread!r}, too near the tolerance "
                f"{tolerance!r} (a point nearly on a principal plane, or data far from the origin)")
    if scale is None:
        return None
    try:
        check_program(item, solution, scale, strictness=0.5)
    except Invalid as exc:
        return PROGRAM_REFUSED.format(exc.detail)
    return None

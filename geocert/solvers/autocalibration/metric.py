"""The metric upgrade: the DIAC minimising the infinite-homography relations over every omega
the intrinsics ranges allow, positive semidefinite inside the relaxation, to certified global
optimality (thesis 6.6; branch on omega's five free entries). Also the thesis's linear baseline."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import least_squares

from geocert.solvers.autocalibration import cuts
from geocert.formulations.autocalibration import metric_relaxation
from geocert.core.bnb import BnbOptions, Box, Progress, asks_to_stop, branch_and_bound, tolerance
from geocert.core.conic import ConicStatus, ReusableConicProgram
from geocert.core.cones import safe_lower_bound


@dataclass
class MetricStage:
    status: str
    certified: bool
    w: np.ndarray | None
    cost: float
    lower_bound: float
    nodes: int
    lo: np.ndarray
    hi: np.ndarray
    leaves: list = field(default_factory=list)
    reason: str | None = None
    rounds: list = field(default_factory=list)  # Tightening rounds, the first on lo..hi
    search_lo: np.ndarray | None = None  # the box searched: the last round's
    search_hi: np.ndarray | None = None
    unit: float = 1.0


homographies, setup_for = metric_relaxation.homographies, metric_relaxation.setup_for


CutProof = cuts.CutProof


class MetricProblem(cuts.BoxSearch):
    """The metric stage's branch-and-bound problem. Before a box is split it is tightened the way
    the root is (each entry of omega minimised and maximised with the cost capped at the
    incumbent's): the children are the halves of what remains, and the slabs cut off are leaves
    closed by their cut (measured on 10 views at 1% noise, seed 2, before the relaxation held the
    intrinsics ranges: 547 nodes, slabs included, certified, against 3000 nodes uncertified
    without; with the ranges held it certifies at the root)."""

    def __init__(self, setup: metric_relaxation.MetricSetup, lo: np.ndarray, hi: np.ndarray, record: bool):
        super().__init__(lo, hi, record)
        self.setup, self.lo, self.hi = setup, lo, hi

    def build(self, lo: np.ndarray, hi: np.ndarray, cap: float, cap_row: bool = False):
        return metric_relaxation.build(self.setup, lo, hi, cap, cap_row)

    @property
    def unit(self) -> float:
        return self.setup.unit

    search_box: Box | None = None  # the root box after tightening

    def root_box(self) -> Box:
        box = self.search_box or Box(self.lo, self.hi)
        return Box(box.lo.copy(), box.hi.copy())

    def objective(self, w: np.ndarray) -> float:
        if not metric_relaxation.in_domain(self.setup, w, self.lo, self.hi):
            return math.inf
        return metric_relaxation.cost(self.setup, w)

    def improve(self, w: np.ndarray) -> tuple[np.ndarray, float]:
        """A local minimum from w, searched over the intrinsics themselves (fx, aspect, skew, u, v
        within their ranges), so that every point tried is a calibration of the domain."""
        start = self.objective(w)
        ranges = self.setup.ranges
        k = metric_relaxation.intrinsics_of(w)
        if ranges is None or k is None:
            return w, start
        names = ("focal", "aspect", "skew", "u", "v")
        lower = np.array([ranges[n][0] for n in names])
        upper = np.array([ranges[n][1] for n in names])
        x0 = np.clip([k["fx"], k["fy"] / k["fx"], k["skew"], k["u"], k["v"]], lower, upper)
        flat = upper <= lower  # a fixed intrinsic (a range of one value) is not a variable
        free = ~flat

        def w_of(x_free):
            x = x0.copy()
            x[free] = x_free
            f, aspect, skew, u, v = x
            K = np.array([[f, skew, u], [0.0, f * aspect, v], [0.0, 0.0, 1.0]])
            omega = K @ K.T
            return np.array([omega[a, b] for a, b in metric_relaxation.ENTRIES])

        try:
            fit = least_squares(lambda x: metric_relaxation.residuals(self.setup, w_of(x)), x0[free],
                                bounds=(lower[free], upper[free]), method="trf", max_nfev=60, xtol=1e-14,
                                ftol=1e-14, gtol=1e-14)
            candidate = w_of(fit.x)
            value = self.objective(candidate)
            if value < start:
                return candidate, value
        except ValueError:
            pass
        return w, start

@dataclass
class Tightening:
    """One round: over ``lo_in..hi_in``, every omega costing at most ``cap`` lies in
    ``lo_out..hi_out``; duals[2k] proves lo_out[k], duals[2k + 1] hi_out[k] (None: unchanged)."""

    cap: float
    lo_in: np.ndarray
    hi_in: np.ndarray
    lo_out: np.ndarray
    hi_out: np.ndarray
    duals: list


def tighten(setup: metric_relaxation.MetricSetup, lo: np.ndarray, hi: np.ndarray, cap: float, tolerance: float = 0.0,
            rounds: int = 12, progress: float = 0.02, stop: Callable[[], bool] | None = None
            ) -> tuple[np.ndarray, np.ndarray, list[Tightening]]:
    """Optimality-based bound tightening: each entry of omega minimised and maximised over the
    relaxation with the cost capped at the incumbent's, repeated while the box shrinks by more
    than ``progress`` of its volume a round, and until the relaxation's own bound on the box is
    within ``tolerance`` of the cap (the search then certifies at its root). Every new side is
    a safe dual bound. ``stop()`` is asked before each program (the stage's time limit, a cancel:
    with many views one round is ten programs of seconds each); once true, the box as tightened
    so far is returned."""
    record: list[Tightening] = []
    for _ in range(rounds):
        if stop is not None and stop():
            break
        program = metric_relaxation.build(setup, lo, hi, cap, cap_row=True)
        if program is None:
            break
        solver = ReusableConicProgram(lean=False)
        if record:  # is the box tight enough already?
            result = solver.solve(program.q, program.A, program.b, program.cones)
            if result.status is ConicStatus.OPTIMAL and cap - safe_lower_bound(
                    program.q, program.A, program.b, program.cones, result.z, program.lower,
                    program.upper) / setup.unit <= tolerance:
                break
        new_lo, new_hi, duals = lo.copy(), hi.copy(), [None] * 10
        found = cuts.side_bounds(program, 5, stop)
        # The verifier bounds each round's sides over its box as it proves it, the claimed one
        # widened by rounding (proofs._check_rounds): each side is taken where it holds over the box
        # grown by that much too (review 46: a side 1.3e-9 beyond, over a slack of 8.1e-10).
        found = [(k, sign, value, z) for (k, sign, _, z), value in zip(found, cuts.grown_values(
            lambda l, h, c: metric_relaxation.build(setup, l, h, c, cap_row=True), Box(lo, hi), cap,
            cuts.verifier_growth(lo, hi), program, found))] if found else found
        for k, sign, value, z in found:
            if sign > 0 and value > new_lo[k]:
                new_lo[k], duals[2 * k] = value, z.copy()
            if sign < 0 and -value < new_hi[k]:
                new_hi[k], duals[2 * k + 1] = -value, z.copy()
        if np.any(new_lo > new_hi):
            break  # nothing of the box costs at most cap: a search leaf will say so
        shrink = np.prod((new_hi - new_lo) / np.maximum(hi - lo, 1e-300))
        record.append(Tightening(cap, lo, hi, new_lo, new_hi, duals))
        lo, hi = new_lo, new_hi
        if shrink > 1 - progress:
            break
    return lo, hi, record


linear_baseline = metric_relaxation.linear_baseline


def solve_metric(setup: metric_relaxation.MetricSetup, lo: np.ndarray, hi: np.ndarray, bnb: BnbOptions, record: bool,
                 callback=None) -> MetricStage:
    began = time.perf_counter()  # the stage's clock covers its first fits too
    problem = MetricProblem(setup, lo, hi, record)
    problem.deadline = began + bnb.time_limit_s
    best, upper = None, math.inf
    baseline, _ = linear_baseline(setup)
    centre = metric_relaxation.w_of_intrinsics({name: 0.5 * (a + b) for name, (a, b) in setup.ranges.items()}) \
        if setup.ranges is not None else 0.5 * (lo + hi)
    for start in (np.clip(baseline, lo, hi), centre):
        w, value = problem.improve(start)
        if value < upper:
            best, upper = w, value
    setup.unit = 1.0 / upper if 0 < upper < math.inf else 1.0
    search_lo, search_hi, rounds = lo, hi, []
    if math.isfinite(upper):
        def stop() -> bool:  # the stage's own time limit, or a cancel (asked of the callback as the search asks)
            elapsed = time.perf_counter() - began
            return elapsed > bnb.time_limit_s or asks_to_stop(
                callback, Progress(0, 0, -math.inf, upper, math.inf, math.inf, elapsed))

        search_lo, search_hi, rounds = tighten(setup, lo, hi, upper, tolerance(upper, bnb), stop=stop)
        problem.search_box = Box(search_lo, search_hi)
    bnb = dataclasses.replace(bnb, time_limit_s=max(1e-3, bnb.time_limit_s - (time.perf_counter() - began)))
    leaves: list | None = [] if record else None
    result = branch_and_bound(problem, best, upper, bnb, callback, trivial_lower_bound=0.0, leaves=leaves)
    certified = result.status == "optimal" and math.isfinite(result.upper_bound)
    w = result.candidate if math.isfinite(result.upper_bound) else None
    reason = None if w is not None else "no omega within the intrinsics ranges was found (widen the ranges?)"
    return MetricStage(result.status if w is not None else "failed", certified, w, result.upper_bound,
                       result.lower_bound, result.nodes, lo, hi, leaves or [], reason, rounds, search_lo, search_hi,
                       setup.unit)

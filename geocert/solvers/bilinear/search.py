"""Certified bilinear fitting of one frame (thesis chapter 8): the linear baseline, alternating
least squares for incumbents, and the branch and bound on the camera's 2x3 part M alone
(appendix C: branching on one side of the bilinear terms converges) through the shared engine.

Everything here is in the frame's normalised units (problem.normalise); the result is converted
back exactly (powers of two) and its cost recomputed from the raw data.
"""

from __future__ import annotations

import copy
import math
import time
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.optimize

from geocert.formulations.bilinear import problem as bilinear_problem
from geocert.formulations.bilinear.options import BilinearOptions
from geocert.formulations.bilinear.relaxation import Relaxation, tightening_objective, with_cost_cap
from geocert.core.bnb import BnbOptions, Box, BoxBound, BoxStatus, branch_and_bound
from geocert.core.certificates import pack
from geocert.core.conic import ConicStatus, ReusableConicProgram
from geocert.core.cones import proves_infeasible, safe_lower_bounds_and_margins
from geocert.formulations.fractional.results import ItemResult

# With camera_bound null the box is problem.default_half_width of the incumbent; when the camera the
# search returns asks a wider one, the search runs again on it (at most this many times in all).
BOX_ROUNDS = 3
ALS_STARTS = 4  # random starts at the root, beside the baseline's and the mean shape's
# Bound tightening's solves stop at this gap instead of 1e-9: each side is the safe bound of the
# dual returned, so a looser solve moves a side by about this much of the cost scale (about 1),
# and programs that stall short of 1e-9 (AlmostSolved, a third of the solves at K = 20) are not
# solved again.
TIGHTENING_TOLERANCE = 1e-7


class Model:
    """The frame's exact cost and the alternating steps, in normalised units."""

    def __init__(self, frame: bilinear_problem.Frame, norm: str, coefficients: str, bound: float):
        self.X, self.u, self.norm = frame.X, frame.u, norm
        self.coefficients, self.bound = coefficients, bound
        self.K, self.n = frame.X.shape[0], frame.X.shape[1]

    def shape(self, alpha: np.ndarray) -> np.ndarray:
        return np.einsum("i,ijk->jk", alpha, self.X)

    def cost(self, M: np.ndarray, alpha: np.ndarray, t: np.ndarray) -> float:
        r = self.u - (self.shape(alpha) @ M.T + t)
        return float(np.sum(np.abs(r))) if self.norm == "L1L1" else float(np.sum(r * r))

    def best_t(self, M: np.ndarray, alpha: np.ndarray) -> np.ndarray:
        r = self.u - self.shape(alpha) @ M.T
        return np.median(r, axis=0) if self.norm == "L1L1" else r.mean(axis=0)

    def camera_step(self, alpha: np.ndarray, lo: np.ndarray | None, hi: np.ndarray | None):
        """The best camera for these coefficients (M within [lo, hi] when given)."""
        S = self.shape(alpha)
        design = np.hstack([S, np.ones((self.n, 1))])
        M, t = np.zeros((2, 3)), np.zeros(2)
        for r in range(2):
            blo = np.append(lo[3 * r:3 * r + 3], -np.inf) if lo is not None else -np.inf
            bhi = np.append(hi[3 * r:3 * r + 3], np.inf) if hi is not None else np.inf
            if self.norm == "L2L2":
                if lo is None:
                    x = np.linalg.lstsq(design, self.u[:, r], rcond=None)[0]
                else:
                    x = scipy.optimize.lsq_linear(design, self.u[:, r], bounds=(blo, bhi), method="bvls").x
            else:
                x = _l1_fit(design, self.u[:, r], list(zip(np.broadcast_to(blo, 4), np.broadcast_to(bhi, 4))), None)
                if x is None:
                    return None
            # the LP solver may overshoot a bound by its tolerance: the camera must stay in the box
            M[r], t[r] = (x[:3] if lo is None else np.clip(x[:3], lo[3 * r:3 * r + 3], hi[3 * r:3 * r + 3])), x[3]
        return M, t

    def alpha_step(self, M: np.ndarray, t: np.ndarray) -> np.ndarray | None:
        """The best coefficients for this camera (within the scope's set)."""
        D = np.einsum("ijk,rk->jri", self.X, M).reshape(2 * self.n, self.K)
        y = (self.u - t).ravel()
        lo, hi = (0.0, 1.0) if self.coefficients == "convex" else (-self.bound, self.bound)
        if self.norm == "L2L2":
            weight = 1e3 * (1.0 + np.linalg.norm(D))
            A = np.vstack([D, weight * np.ones((1, self.K))])
            rhs = np.append(y, weight)
            if self.coefficients == "convex":
                alpha = scipy.optimize.nnls(A, rhs, maxiter=50 * self.K)[0]
            else:
                alpha = scipy.optimize.lsq_linear(A, rhs, bounds=(lo, hi), method="bvls").x
        else:
            alpha = _l1_fit(D, y, [(lo, hi)] * self.K, np.ones(self.K))
            if alpha is None:
                return None
        return bilinear_problem.project_coefficients(alpha, self.coefficients, self.bound)

    def als(self, M, alpha, t, iterations: int, lo=None, hi=None, deadline: float = math.inf):
        """Alternating steps from (M, alpha, t); the best point met and its cost. No step starts
        after ``deadline`` (time.perf_counter())."""
        best = (M, alpha, t, self.cost(M, alpha, t))
        for _ in range(iterations):
            if time.perf_counter() > deadline:
                break
            try:
                step = self.camera_step(alpha, lo, hi)
                if step is None:
                    break
                M, t = step
                new_alpha = self.alpha_step(M, t)
                if new_alpha is None:
                    break
                alpha = new_alpha
                t = self.best_t(M, alpha)
            except (ValueError, np.linalg.LinAlgError):
                break
            value = self.cost(M, alpha, t)
            if value < best[3] * (1 - 1e-7):
                best = (M, alpha, t, value)
            else:
                if value < best[3]:
                    best = (M, alpha, t, value)
                break
        return best


def _l1_fit(design: np.ndarray, target: np.ndarray, bounds: list, equality: np.ndarray | None):
    """min sum |design x - target| (an LP: HiGHS), x within bounds, 1'x = 1 when equality."""
    m, d = design.shape
    c = np.concatenate([np.zeros(d), np.ones(m)])
    A = np.block([[design, -np.eye(m)], [-design, -np.eye(m)]])
    b = np.concatenate([target, -target])
    eq = dict(A_eq=np.concatenate([equality, np.zeros(m)])[None, :], b_eq=[1.0]) if equality is not None else {}
    bounds = [(None if not math.isfinite(a) else a, None if not math.isfinite(b_) else b_) for a, b_ in bounds] + \
        [(0, None)] * m
    result = scipy.optimize.linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs", **eq)
    return result.x[:d] if result.status == 0 else None


def linear_baseline(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Thesis 8.3.3's linear estimate (problem.linear_baseline, which the verifier recomputes)."""
    return bilinear_problem.linear_baseline(model.X, model.u, model.norm, model.coefficients, model.bound)


@dataclass
class FrameResult(ItemResult):
    """One frame's outcome (ItemResult's fields; its ``certificate`` stays None: the frame's
    summary is built by the kind from camera_box, tolerance and leaves, the proof is ``proof``)."""

    camera: list | None = None
    coefficients: list | None = None
    shape: list | None = None
    residuals: list | None = None
    camera_box: tuple[list, list] | None = None  # raw units, M's 2x3 entries row by row
    tolerance: float | None = None
    leaves: int = 0
    baseline: dict | None = None
    proof: dict | None = None  # with a full certificate


@dataclass
class CameraBox(Box):
    """A box of M' with the coefficients' box proven for it: by the root's rounds (source None)
    or by the node tightening record ``source``."""

    alpha_lo: np.ndarray = None
    alpha_hi: np.ndarray = None
    source: int | None = None
    depth: int = 0


@dataclass
class NodeProof:
    """Why no point of ``box`` costing at most ``upper_bound`` costs less than ``bound``, the
    coefficients' box taken from node tightening record ``alpha_from`` (None: the root's)."""

    box: Box
    upper_bound: float
    kind: str  # dual, farkas, empty (no translation fits), alpha_empty (the tightening left no coefficient)
    z: np.ndarray | None
    bound: float
    alpha_from: int | None


class BoxProblem:
    """The branch-and-bound problem over boxes of M' (6 entries). At every node below the root the
    coefficients' box is tightened first (2K small solves: each alpha_i minimised and maximised
    over the relaxation with "cost at most the incumbent's"), so that McCormick's error, the
    product of the camera's and the coefficients' widths, shrinks as fast as the boxes do: on
    K = 4, N = 15, 1% noise it took the search from over 5000 nodes to 13 to 45 (measured)."""

    def __init__(self, model: Model, relaxation: Relaxation, root: CameraBox, node_tightening: bool = True,
                 deadline: float = math.inf):
        self.model, self.relaxation, self.root = model, relaxation, root
        self.deadline = deadline  # past it a node's tightening stops early (its sides left as they were)
        self.node_tightening = node_tightening and relaxation.K > 1
        self.tightenings: list[dict] = []  # node tightening records (the proof's node_tightening)
        self._solver = ReusableConicProgram(lean=False)
        self._tightener = ReusableConicProgram(lean=False, tolerance=TIGHTENING_TOLERANCE)

    def root_box(self) -> Box:
        return self.root

    def _tighten_alpha(self, box: CameraBox, cap: float):
        """(alpha_lo, alpha_hi, record index) proven for the box, or None when nothing changed."""
        rel = self.relaxation
        data = rel.conic_data(box.lo, box.hi, cap, box.alpha_lo, box.alpha_hi)
        if data is None:
            return None
        data = with_cost_cap(rel, data, cap)
        lo, hi = box.alpha_lo.copy(), box.alpha_hi.copy()
        duals = _tighten_sides(self._tightener, rel, data, range(6, 6 + rel.K), lo, hi, -6, self.deadline)
        if all(z is None for z in duals):
            return None
        self.tightenings.append({"parent": box.source, "upper_bound": cap,
                                 "box_in": [box.lo.tolist() + box.alpha_lo.tolist(),
                                            box.hi.tolist() + box.alpha_hi.tolist()],
                                 "box_out": [box.lo.tolist() + lo.tolist(), box.hi.tolist() + hi.tolist()],
                                 "duals": [pack(z) for z in duals]})
        return lo, hi, len(self.tightenings) - 1

    def bound(self, box: CameraBox, upper_bound: float) -> BoxBound:
        cap = upper_bound
        alpha_lo, alpha_hi, source = box.alpha_lo, box.alpha_hi, box.source
        if self.node_tightening and box.depth > 0:
            tightened = self._tighten_alpha(box, cap)
            if tightened is not None:
                alpha_lo, alpha_hi, source = tightened
                if not np.all(alpha_lo <= alpha_hi):
                    return BoxBound(BoxStatus.EMPTY, proof=NodeProof(box, cap, "alpha_empty", None, math.inf, source))
        hint = (alpha_lo, alpha_hi, source)
        data = self.relaxation.conic_data(box.lo, box.hi, cap, alpha_lo, alpha_hi)
        if data is None:
            return BoxBound(BoxStatus.EMPTY, proof=NodeProof(box, cap, "empty", None, math.inf, source))
        res = self._solver.solve(data.q, data.A, data.b, data.cones)
        if res.status is ConicStatus.INFEASIBLE:
            if proves_infeasible(data.A, data.b, data.cones, res.z, data.lower, data.upper):
                return BoxBound(BoxStatus.EMPTY, proof=NodeProof(box, cap, "farkas", res.z, math.inf, source))
            return BoxBound(BoxStatus.UNRESOLVED, split_hint=hint)
        if res.status is not ConicStatus.OPTIMAL:
            return BoxBound(BoxStatus.UNRESOLVED, split_hint=hint)
        value = self.relaxation.bound(data, res.z)
        M, alpha, _ = self.relaxation.split_variables(res.x)
        M = np.clip(M, box.lo.reshape(2, 3), box.hi.reshape(2, 3))
        alpha = bilinear_problem.project_coefficients(alpha, self.model.coefficients, self.model.bound)
        candidate = (M, alpha, self.model.best_t(M, alpha))
        return BoxBound(BoxStatus.BOUNDED, min(value, cap), candidate=candidate, split_hint=hint,
                        proof=NodeProof(box, cap, "dual", res.z, value, source))

    def objective(self, candidate) -> float:
        return self.model.cost(*candidate)

    def improve(self, candidate):
        M, alpha, t, value = self.model.als(*candidate, iterations=20, lo=self.root.lo, hi=self.root.hi,
                                            deadline=self.deadline)
        return (M, alpha, t), value

    def split(self, box: CameraBox, bound: BoxBound) -> list[Box]:
        """Bisect the widest camera entry (thesis 8.4: the camera only); the children inherit the
        coefficients' box proven for their parent. (Cutting through the incumbent instead, where
        McCormick's envelope is exact, was measured: no fewer nodes on K = 3..10, more on K = 3
        with L1.)"""
        alpha_lo, alpha_hi, source = bound.split_hint if bound.split_hint is not None else (
            box.alpha_lo, box.alpha_hi, box.source)
        axis = int(np.argmax(box.width))
        mid = 0.5 * (box.lo[axis] + box.hi[axis])
        left_hi, right_lo = box.hi.copy(), box.lo.copy()
        left_hi[axis] = right_lo[axis] = mid
        return [CameraBox(box.lo.copy(), left_hi, alpha_lo, alpha_hi, source, box.depth + 1),
                CameraBox(right_lo, box.hi.copy(), alpha_lo, alpha_hi, source, box.depth + 1)]


# Each side a tightening moves is stated short of the safe bound computed, by SIDE_MARGIN of its
# box's size (its largest coordinate or width, as coverage.widened measures it) or ROUNDING_TIMES
# the rounding margin that bound subtracted (cones.rounding_margin), whichever is more, so that
# the verifier's own safe bound of the same dual (computed in another order: a sparse matrix, one
# dual at a time, another machine's BLAS; each within its rounding margin of the exact value)
# proves at least the side stated. coverage.widened then leaves the stated box as it is, and the
# verifier builds the next round (and the nodes' programs) on the very box the solver did.
# Stated at the value computed, a side the verifier proved a little weaker was widened to its
# value, each round's program was read over a slightly wider box than the solver's, and the
# difference compounded over the rounds: with affine coefficients within 1000 the 23rd round's
# sides were some 2e-9 of the box's size inside the verifier's, beyond its tolerance (review 41,
# class 5). Measured on the stored bilinear frames with affine coefficients within 10 to 1e6,
# both norms, OpenBLAS's Haswell and Prescott kernels: over the same box the verifier's bound of
# each dual is the solver's (to the bit, the 1608 of one L1L1 solve within 1e6), and every side
# it proves is at least the side stated.
SIDE_MARGIN = 1e-10
ROUNDING_TIMES = 4.0


def _tighten_sides(solver: ReusableConicProgram, relaxation: Relaxation, data, entries: range, lo: np.ndarray,
                   hi: np.ndarray, offset: int, deadline: float) -> list:
    """Minimise and maximise each (M, alpha) entry over ``data`` (the relaxation with its cost cap),
    moving lo[entry + offset] / hi[entry + offset] in place to the safe bound of each dual, less
    its margin (SIDE_MARGIN of the box's size, lo and hi as given, or ROUNDING_TIMES its
    rounding); returns the duals (None where unsolved, or
    past ``deadline``). Any dual a solve returns gives a safe bound (an inaccurate one a weaker
    bound at worst), so none is solved again."""
    size = max(float(np.max(np.abs(lo), initial=0.0)), float(np.max(np.abs(hi), initial=0.0)),
               float(np.max(hi - lo, initial=0.0)))
    least = SIDE_MARGIN * size
    duals: list = []
    solved = []  # (index in duals, entry, sign, objective)
    for entry in entries:
        for sign in (1.0, -1.0):
            if time.perf_counter() > deadline:
                duals.append(None)
                continue
            q = tightening_objective(relaxation, entry, sign)
            first = not solved  # the program is set up by the first solve of this call
            res = solver.solve(q, data.A, data.b, data.cones) if first else solver.solve_objective(q)
            if res.z is None or res.status in (ConicStatus.INFEASIBLE, ConicStatus.UNBOUNDED, ConicStatus.FAILED):
                duals.append(None)
                continue
            solved.append((len(duals), entry, sign, q))
            duals.append(res.z)
    if not solved:
        return duals
    # one projection and one product for all the duals (they share the feasible set)
    values, roundings = safe_lower_bounds_and_margins(np.array([q for *_, q in solved]), data.A, data.b, data.cones,
                                                      np.array([duals[n] for n, *_ in solved]), data.lower,
                                                      data.upper)
    for (n, entry, sign, _), value, rounding in zip(solved, values, roundings):
        if not math.isfinite(value):
            duals[n] = None
            continue
        value = sign * (float(value) - max(least, ROUNDING_TIMES * float(rounding)))
        if sign > 0 and value > lo[entry + offset]:
            lo[entry + offset] = value
        elif sign < 0 and value < hi[entry + offset]:
            hi[entry + offset] = value
    return duals


TIGHTENING_ROUNDS = 60  # half rounds: the camera's entries, then the coefficients, and so on
MIN_MOVE = 0.02


def tighten(relaxation: Relaxation, lo: np.ndarray, hi: np.ndarray, cap: float, rounds: int | None = None,
            deadline: float = math.inf, enough: float = -math.inf):
    """Bound tightening at the root: the entries of M, then the coefficients, then M again and
    so on, each minimised and maximised over the relaxation with "cost at most cap"; every side
    moved is the safe bound of a dual vector (points of the box outside the new one cost more
    than cap). The coefficients' ranges shrinking is what makes McCormick's envelopes tight as
    the camera boxes shrink (their error is the product of both widths). Alternating the two
    halves lets each use the other's newest box: a round of all 6 + K entries solved over the
    same box did the same work at nearly twice the solves (on K = 5, the first full round cut M
    from 32 to 0.2 wide and left alpha at 0.87: its alpha solves had M's old box). Rounds stop
    once neither half moves a side by more than 2% of its width (MIN_MOVE), and no new round
    starts after ``deadline`` (time.perf_counter()); a round stopped by it leaves its remaining
    sides as they were. Returns the camera box, the coefficients' box and the rounds' records
    (proof; a half round's record has null duals for the other half). Rounds stop too once the
    relaxation's own bound on the box reaches ``enough`` (the search's root node then closes at
    once). (Stopping earlier, once a round took less than a tenth off the gap, was measured: on
    K = 3, N = 8 at rel_gap 1e-6 the search then needed 37-213 nodes where it needed 1-9.)"""
    records = []
    solver = ReusableConicProgram(lean=False, tolerance=TIGHTENING_TOLERANCE)
    K = relaxation.K
    rounds = TIGHTENING_ROUNDS if rounds is None else rounds
    box_lo = np.concatenate([lo, np.full(K, relaxation.alpha_range[0])])
    box_hi = np.concatenate([hi, np.full(K, relaxation.alpha_range[1])])
    halves = (range(6), range(6, 6 + K))
    still = 0  # consecutive half rounds that moved no side by MIN_MOVE
    for number in range(rounds):
        part = halves[number % 2]
        data = relaxation.conic_data(box_lo[:6], box_hi[:6], cap, box_lo[6:], box_hi[6:])
        if data is None:
            break
        data = with_cost_cap(relaxation, data, cap)
        new_lo, new_hi = box_lo.copy(), box_hi.copy()
        duals: list = [None] * (2 * (6 + K))
        duals[2 * part.start:2 * part.stop] = _tighten_sides(solver, relaxation, data, part, new_lo, new_hi, 0,
                                                             deadline)
        if not np.all(new_lo <= new_hi):
            break  # nothing costs at most cap: keep the last box (the incumbent is in it)
        moved = float(np.max(((new_lo - box_lo) + (box_hi - new_hi)) / np.maximum(box_hi - box_lo, 1e-300)))
        records.append({"upper_bound": cap, "box_in": [box_lo.tolist(), box_hi.tolist()],
                        "box_out": [new_lo.tolist(), new_hi.tolist()], "duals": [pack(z) for z in duals]})
        box_lo, box_hi = new_lo, new_hi
        still = still + 1 if moved < MIN_MOVE else 0
        if still >= 2 or time.perf_counter() > deadline:
            break
        if number % 2 == 0:
            continue  # look at the cost after the coefficients' half only
        res = solver.solve_objective(data.q)  # the cost over this round's (looser) box: a cheap look
        if res.status is ConicStatus.OPTIMAL and relaxation.bound(data, res.z) >= enough:
            break
    return box_lo[:6], box_hi[:6], box_lo[6:], box_hi[6:], records


def root_incumbent(model: Model, seed: int = 0, deadline: float = math.inf):
    """The best of alternating least squares from the baseline, the mean shape and a few random
    coefficient vectors (unconstrained camera). For L1L1 the starts run least squares first (fast)
    and only the two best are polished with L1 steps (each an LP). Past ``deadline``
    (time.perf_counter()) no start and no step begins, but the first start's first step (an
    incumbent is needed: the camera box is derived from it)."""
    starts = [linear_baseline(model)[1], np.full(model.K, 1.0 / model.K)]
    rng = np.random.default_rng(seed)
    for _ in range(ALS_STARTS if model.K > 1 else 0):
        starts.append(bilinear_problem.project_coefficients(rng.dirichlet(np.ones(model.K)), model.coefficients,
                                                            model.bound))
    squares = model if model.norm == "L2L2" else copy.copy(model)
    squares.norm = "L2L2"
    found = []
    for alpha in starts:
        if found and time.perf_counter() > deadline:
            break
        step = squares.camera_step(alpha, None, None)
        if step is None:
            continue
        found.append(squares.als(step[0], alpha, step[1], iterations=50, deadline=deadline))
    if squares is not model:
        found.sort(key=lambda point: model.cost(*point[:3]))
        found = [model.als(M, alpha, model.best_t(M, alpha), iterations=10, deadline=deadline)
                 for M, alpha, _, _ in found[:2]]
    return min(found, key=lambda point: point[3]) if found else None


def root_half_width(M: np.ndarray, camera_bound: float | None, frame: bilinear_problem.Frame) -> float:
    """The camera box's half-width (normalised): camera_bound when given, else the default box of
    the camera M (problem.default_half_width)."""
    if camera_bound is not None:
        return camera_bound / frame.camera_scale
    return bilinear_problem.default_half_width(M)


def fit_frame(basis: np.ndarray, points: np.ndarray, options: BilinearOptions, callback=None) -> FrameResult:
    """One frame's certified fit (the kind's solve_item)."""
    start = time.perf_counter()
    norm = options.norm
    frame = bilinear_problem.normalise(basis, points)
    model = Model(frame, norm, options.coefficients, options.coefficient_bound)
    unit = bilinear_problem.cost_unit(frame, norm)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        Mb, ab, tb = linear_baseline(model)
    baseline_camera = bilinear_problem.to_raw(frame, Mb, tb)
    baseline = {"method": "linear", "camera": baseline_camera.tolist(), "coefficients": ab.tolist(),
                "cost": bilinear_problem.cost(bilinear_problem.residuals(basis, points, baseline_camera, ab), norm)}
    # the time limit is shared: a quarter for the incumbent, the root's tightening up to half of it,
    # the search what remains (every step below stops at its deadline)
    incumbent = root_incumbent(model, deadline=start + 0.25 * options.time_limit_s)
    if incumbent is None:  # every start's first step failed (an LP solver refusing): the baseline
        incumbent = (Mb, ab, tb, model.cost(Mb, ab, tb))
    half = root_half_width(incumbent[0], options.camera_bound, frame)
    relaxation = Relaxation(frame.X, frame.u, norm, options.coefficients, options.coefficient_bound)
    for round_ in range(BOX_ROUNDS):
        found = _search(model, relaxation, frame, options, incumbent, half, start, callback)
        wider = bilinear_problem.default_half_width(found.candidate[0])
        if options.camera_bound is not None or wider <= half or round_ == BOX_ROUNDS - 1:
            break
        # the camera found asks a wider default box than the incumbent's: the proof must cover it
        half, incumbent = wider, (*found.candidate, model.cost(*found.candidate))
    status, lower, nodes, candidate, trivial = found.status, found.lower, found.nodes, found.candidate, found.trivial
    M, alpha, t = candidate
    camera = bilinear_problem.to_raw(frame, M, t)
    r = bilinear_problem.residuals(basis, points, camera, alpha)
    cost = bilinear_problem.cost(r, norm)
    lower_raw = lower * unit
    gap = max(0.0, cost - lower_raw)
    tolerance = max(options.abs_gap, options.rel_gap * abs(cost))
    certified = status == "optimal" and gap <= tolerance * (1 + 1e-12) and \
        bilinear_problem.feasible_coefficients(alpha, options.coefficients, options.coefficient_bound)
    reason = None
    if certified and not trivial and options.camera_bound is None and wider > half:
        certified, status = False, "not_certified"
        reason = "the camera found lies beyond a quarter of every box searched: set camera_bound"
    elif status == "optimal" and not certified:
        status, reason = "not_certified", "the gap at the solution as returned exceeds the tolerance"
    elif not certified:
        reason = {"node_limit": "the node limit was reached", "time_limit": "the time limit was reached",
                  "cancelled": "the job was cancelled", "not_certified": "some box could not be bounded"}.get(
            status, status)
    if certified:
        lower_raw = cost - gap
    shape = bilinear_problem.shape_of(basis, alpha)
    out = FrameResult(
        status=status, certified=certified, cost=cost, lower_bound=lower_raw, gap=gap, nodes=nodes,
        elapsed_s=time.perf_counter() - start, reason=reason, camera=camera.tolist(), coefficients=alpha.tolist(),
        shape=shape.tolist(), residuals=[None if np.isnan(row[0]) else row.tolist() for row in r],
        camera_box=None if trivial else found.box_raw, tolerance=tolerance, leaves=len(found.leaves),
        baseline=baseline)
    if certified and options.certificate == "full":
        out.proof = {"type": "trivial"} if trivial else encode(found.box_raw, found.rounds, found.tightenings,
                                                               found.leaves)
    return out


@dataclass
class _Searched:
    """One search of a camera box: the engine's outcome, and what the proof encodes."""

    status: str
    lower: float
    nodes: int
    candidate: tuple
    trivial: bool
    box_raw: tuple
    rounds: list
    tightenings: list
    leaves: list


def _search(model: Model, relaxation: Relaxation, frame: bilinear_problem.Frame, options: BilinearOptions,
            incumbent: tuple, half: float, start: float, callback) -> _Searched:
    """The branch and bound over the camera box |M_rk| <= half (normalised) from ``incumbent``
    (M, alpha, t, cost), within the frame's time limit counted from ``start``."""
    norm, unit = model.norm, bilinear_problem.cost_unit(frame, model.norm)
    lo, hi = np.full(6, -half), np.full(6, half)
    M, alpha, t, value = incumbent
    if np.any(np.abs(M) > half):  # a camera_bound below the incumbent: the best camera inside it
        M, alpha, t, value = model.als(np.clip(M, -half, half), alpha, t, 50, lo, hi,
                                       deadline=start + 0.25 * options.time_limit_s)
        M = np.clip(M, -half, half)
        t = model.best_t(M, alpha)
        value = model.cost(M, alpha, t)
    box_raw = ((lo * frame.camera_scale).tolist(), (hi * frame.camera_scale).tolist())
    abs_gap = options.abs_gap / unit
    if value > abs_gap:
        # at most half the time limit at the root: the search has the rest
        deadline = start + 0.5 * options.time_limit_s
        enough = value - max(abs_gap, options.rel_gap * value)
        tight_lo, tight_hi, alpha_lo, alpha_hi, rounds = tighten(relaxation, lo, hi, value * (1 + 1e-9),
                                                                 deadline=deadline, enough=enough)
    else:
        tight_lo, tight_hi, alpha_lo, alpha_hi, rounds = lo, hi, None, None, []
    if alpha_lo is None:
        alpha_lo, alpha_hi = np.full(model.K, relaxation.alpha_range[0]), np.full(model.K, relaxation.alpha_range[1])
    problem = BoxProblem(model, relaxation, CameraBox(tight_lo, tight_hi, alpha_lo, alpha_hi, None, 0),
                         deadline=start + options.time_limit_s)
    leaves: list = []
    bnb_options = BnbOptions(rel_gap=options.rel_gap, abs_gap=abs_gap, max_nodes=options.max_nodes,
                             time_limit_s=max(1e-3, options.time_limit_s - (time.perf_counter() - start)))
    trivial = value <= abs_gap
    if trivial:
        status, lower, nodes, candidate = "optimal", 0.0, 0, (M, alpha, t)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = branch_and_bound(problem, (M, alpha, t), value, bnb_options, callback, 0.0, leaves)
        status, lower, nodes, candidate = result.status, result.lower_bound, result.nodes, result.candidate
    return _Searched(status, lower, nodes, candidate, trivial, box_raw, rounds, problem.tightenings, leaves)


def encode(box_raw: tuple[list, list], rounds: list, node_tightening: list, leaves: list) -> dict:
    """The JSON form of a search's proof (docs/certificate.md, "Bilinear fitting")."""
    proofs: list[dict] = []
    index: dict[int, int] = {}
    rows = []
    for box, leaf in leaves:
        if leaf is not None and id(leaf) not in index:
            index[id(leaf)] = len(proofs)
            proofs.append({"box": [leaf.box.lo.tolist(), leaf.box.hi.tolist()], "upper_bound": leaf.upper_bound,
                           "kind": leaf.kind, "z": pack(leaf.z), "alpha_from": leaf.alpha_from,
                           "bound": leaf.bound if math.isfinite(leaf.bound) else None})
        rows.append([box.lo.tolist(), box.hi.tolist(), index[id(leaf)] if leaf is not None else None])
    return {"type": "bilinear_bnb", "camera_box": [list(box_raw[0]), list(box_raw[1])], "tightening": rounds,
            "node_tightening": node_tightening, "proofs": proofs, "leaves": rows}

"""Sums of ratios ``sum_i f(n_i(v)) / g_i(v)`` (thesis chapter 5): what triangulation,
resectioning and P^n -> P^m maps have in common.

``v`` is a vector of d unknowns; observation i has m affine numerator rows ``n_i(v)`` (its
residual times its depth) and an affine depth ``g_i(v) > 0``. Observations whose depth is
constant are "exact": stored with depth identically 1, their terms are convex and need no
envelope. The lower bound on a box of branching functionals ``z = B v`` is one SOCP holding each
ratio above the convex envelope of ``t / s`` (docs/algorithms.md, section 4).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np

from geocert.core.bnb import BnbOptions, Box, BoxBound, BoxStatus, Progress, branch_and_bound
from geocert.core.certificates import CapProof, LeafProof, RootProof, SearchProof, TighteningProof, encode
from geocert.core.conic import ConicStatus, ReusableConicProgram, solve_conic
from geocert.core.cones import ConeSpec, proves_infeasible, safe_lower_bound
from geocert.core.geometry import cost_rounding, lengths, norm_cost, norm_terms, residual_lengths
from geocert.formulations.fractional.options import FractionalOptions
from geocert.formulations.fractional.results import SearchCertificate
from geocert.formulations.fractional.relaxation import (EPS_DEPTH, ConicData, FractionalProgram, Relaxation, complete_functionals,
                         cost_unit, gamma_for, residual_region, root_bounds, tightening_objective, with_cost_cap)

MAX_SCALE = 1e3
# Bound tightening's solves stop at this gap instead of 1e-9: each side is the safe bound of the
# dual returned, so a looser solve can only move a side by about this much of the cost scale
# (about 1). Measured side by side: 1000-point homographies 19% (L2L2), 10% (L2L1) and 2% (L1L1)
# less CPU, the Dinosaur cameras that branch 20% at the median, the same nodes or fewer.
TIGHTENING_TOLERANCE = 1e-7
NODE_CUT = 0.05  # node tightening cuts a side off when that shrinks the box by this much of its width
NODE_MARGIN = 0.01  # and cuts that much of the width short of the proven side (an interior left)
# Node bounds of large programs (maps) stop at this gap instead of 1e-9: their relaxations (1,500
# variables on a 500-point camera) often stall above 1e-9 and answer AlmostSolved, which the
# retries (full settings at 1e-9, then 1e-7) repeat or fail: three solves a node and the box left
# unresolved. Measured on 118 node relaxations of Dinosaur camera 12 (L2L2), lean settings:
# AlmostSolved 66 at 1e-9, 26 at 1e-8, 11 at 1e-7, with safe bounds within 5e-8 (1e-8) and 4e-7
# (1e-7) of those at 1e-9 on costs scaled to about 1, far below any gap searched for. The bound is
# the safe bound of the dual returned either way.
LARGE_BOUND_TOLERANCE = 1e-7
# Terms capped: those costing at least CAP_SHARE of the incumbent's cost, at most CAP_LIMIT. Against
# 1% and 16 on Dinosaur cameras 12, 14, 16, 18 (L2L2): nodes within 20%, CPU from 0.4 s less (few
# nodes) to the same (many).
CAP_SHARE = 0.02
CAP_LIMIT = 8
CAP_AFTER = 3  # caps are computed before bounding the box after this many (the root and its children)


def branch_directions(program: FractionalProgram, subspace: np.ndarray) -> np.ndarray:
    """Rows spanning ``subspace`` (k orthonormal rows): the best-conditioned depth gradients
    first (greedy Gram-Schmidt), completed with orthogonal directions of the subspace."""
    gradients = program.den[~program.exact, :-1]
    sizes = lengths(gradients, 1)
    candidates = gradients[sizes > 0] / sizes[sizes > 0, None]
    residuals = candidates.copy()  # each candidate's part orthogonal to the basis so far
    k = subspace.shape[0]
    chosen: list[np.ndarray] = []
    basis: list[np.ndarray] = []
    while len(chosen) < k and len(candidates):
        norms = lengths(residuals, 1)
        best = int(np.argmax(norms))
        if norms[best] < 0.25:
            break
        chosen.append(candidates[best])
        basis.append(residuals[best] / norms[best])
        keep = np.arange(len(candidates)) != best
        candidates, residuals = candidates[keep], residuals[keep]
        residuals = residuals - np.outer(residuals @ basis[-1], basis[-1])
    for e in subspace:
        if len(basis) == k:
            break
        r = e - sum((e @ b) * b for b in basis)
        if np.linalg.norm(r) > 0.5:
            basis.append(r / np.linalg.norm(r))
            chosen.append(basis[-1])
    return np.array(chosen)


def depth_subspace(program: FractionalProgram) -> np.ndarray:
    """Orthonormal rows spanning the gradients of the depths that vary (the whole space when
    none does). Only along these do the envelopes need bounds: a search branches on them alone,
    and the directions it leaves out are bounded by the root region's proven bounds. Directions
    below round-off are left out."""
    gradients = program.den[~program.exact, :-1]
    if len(gradients):
        _, singular, vt = np.linalg.svd(gradients)
        # Depth rows are scaled to a unit gradient or (barely varying) a unit row: directions
        # below 1e-12 vary by round-off only, and their variation is still counted in every
        # depth range once the root region bounds them.
        rank = int((singular > 1e-12 * max(1.0, singular[0])).sum())
        if rank:
            return vt[:rank]
    return np.eye(program.dim)


def root_region(program: FractionalProgram, B: np.ndarray, gamma: float) -> tuple[str, Box | None, RootProof | None]:
    """Bound B v over the residual region, and the complement of B's rows too: 2d small SOCPs,
    every bound proven (RootProof). Every mode proves its bounds: a summary certificate differs
    from a full one only in what is returned, never in what the search relies on.

    An inaccurate solve is retried with gamma inflated slightly: a larger residual bound still
    gives a region holding every better point, and a different problem often solves cleanly.
    """
    rows = complete_functionals(B)
    subset = _root_subset(program)
    # Inflated a little from the start: every point whose residuals are within gamma (the
    # incumbent, and so the solution returned) is then strictly inside the region, which is the
    # witness a verifier asks for (verify._check_root).
    for inflation in (1 + 1e-6, 1.001, 1.01):
        region = residual_region(program, gamma * inflation)
        state = "not_certified"
        if subset is not None:
            state, lo, hi, duals = _root_region_once(residual_region(_restricted(program, subset), gamma * inflation), rows)
            if state == "ok":
                duals = [_padded(z, subset, program) for z in duals]
        if state != "ok":
            state, lo, hi, duals = _root_region_once(region, rows)
        if state != "not_certified":
            break
    if state != "ok":
        return state, None, None
    k = len(B)
    proof = prove_root(region, gamma * inflation, rows, lo, hi, duals)
    if proof is None:
        return "not_certified", None, None
    return "ok", Box(proof.lower[:k].copy(), proof.upper[:k].copy()), proof


# Programs of more observations than this bound their root region by a subset of them first.
ROOT_SUBSET = 64


def _root_subset(program: FractionalProgram) -> np.ndarray | None:
    """Observations whose residual region holds the whole program's (it has fewer constraints):
    the exact ones and, greedily, the varying ones farthest apart in their depth rows (the
    region's extent along the depths is set by its extreme points). None for small programs."""
    count = len(program.den)
    if count <= ROOT_SUBSET:
        return None
    rows = program.den / np.maximum(lengths(program.den, 1), 1e-300)[:, None]
    chosen = list(np.flatnonzero(program.exact)) or [0]
    distance = np.min(lengths(rows[:, None, :] - rows[None, chosen, :], 2), axis=1)
    while len(chosen) < ROOT_SUBSET:
        best = int(np.argmax(distance))
        if distance[best] <= 0:
            break
        chosen.append(best)
        distance = np.minimum(distance, lengths(rows - rows[best], 1))
    return np.sort(np.array(chosen))


def _restricted(program: FractionalProgram, subset: np.ndarray) -> FractionalProgram:
    return FractionalProgram(program.num[subset], program.den[subset], program.exact[subset], program.linear,
                             program.norm, program.max_residual)


def _padded(z: np.ndarray, subset: np.ndarray, program: FractionalProgram) -> np.ndarray:
    """A dual vector of the subset's residual region as one of the whole program's: zero on the
    other observations' cones (a point of their dual cone), so it proves the same bound."""
    L, per = len(program.linear), program.num.shape[1] + 1
    full = np.zeros(L + per * len(program.den))
    full[:L] = z[:L]
    full[L:].reshape(-1, per)[subset] = z[L:].reshape(-1, per)
    return full


def _root_region_once(region: tuple[np.ndarray, np.ndarray, ConeSpec], rows: np.ndarray):
    A, b, cones = region
    solver = ReusableConicProgram()  # 2 objectives per row over one feasible set
    lo, hi = np.zeros(len(rows)), np.zeros(len(rows))
    duals = []
    for k in range(len(rows)):
        for sign, out in ((1.0, lo), (-1.0, hi)):
            res = solver.solve(sign * rows[k], A, b, cones) if not duals else solver.solve_objective(sign * rows[k])
            if res.status is ConicStatus.UNBOUNDED:
                return "degenerate", None, None, None
            if res.status is ConicStatus.INFEASIBLE:
                return "infeasible", None, None, None
            if res.status is not ConicStatus.OPTIMAL:
                return "not_certified", None, None, None
            out[k] = sign * res.lower_bound  # min(primal, dual): the outer side for both ends
            duals.append(res.z)
    return "ok", lo, hi, duals


def prove_root(region: tuple[np.ndarray, np.ndarray, ConeSpec], gamma: float, F: np.ndarray, lo: np.ndarray,
               hi: np.ndarray, duals: list[np.ndarray]) -> RootProof | None:
    """Safe bounds on ``F v`` over the residual region of ``gamma``, proven over a claimed box
    half as wide again on each side; None when a safe bound does not fall strictly inside it."""
    pad = 0.5 * (hi - lo) + 1e-6 * (1 + np.abs(lo) + np.abs(hi))
    claim_lo, claim_hi = lo - pad, hi + pad
    lower, upper = root_bounds(region, F, duals, claim_lo, claim_hi)
    if not (np.all(claim_lo < lower) and np.all(upper < claim_hi) and np.all(lower <= upper)):
        return None
    # Padded a little (looser than proven, so still proven).
    pad = 1e-7 * (1 + np.abs(lower) + np.abs(upper))
    return RootProof(gamma, F, claim_lo, claim_hi, lower - pad, upper + pad, duals)


def feasible_point(program: FractionalProgram) -> np.ndarray | None:
    """A point of the domain with small largest residual (bisection on the L-infinity cost);
    None when the domain is empty."""

    def feasible(gamma: float) -> np.ndarray | None:
        res = solve_conic(np.zeros(program.dim), *residual_region(program, gamma))
        if res.status is ConicStatus.OPTIMAL and math.isfinite(program.cost(res.x)):
            return res.x
        return None

    hi = 1e7
    best = feasible(hi)
    if best is None:
        return None
    lo = 0.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        v = feasible(mid)
        if v is None:
            lo = mid
        else:
            hi, best = mid, v
        if hi - lo < 1e-3 * hi:
            break
    return best


def local_refine(program: FractionalProgram, v: np.ndarray, norm: str | None = None) -> tuple[np.ndarray, float]:
    """A short local descent (LM) that never returns a worse or infeasible point. ``norm``
    overrides the program's (L2L2 first makes a good start for the other norms)."""
    norm = norm or program.norm
    d = program.dim

    def cost(x: np.ndarray) -> float:
        return program.cost(x) if norm == program.norm else _cost_in(program, x, norm)

    best_v, best_cost = v, cost(v)

    # Every norm as least squares: L2L2 on the residuals, the others on square roots of their
    # terms (sum_i sqrt(term_i)^2 is the cost). Zero padding: MINPACK's LM needs at least as
    # many residuals as unknowns.
    def terms(x: np.ndarray) -> np.ndarray:
        r = program.residuals(x)
        return r.ravel() if norm == "L2L2" else np.linalg.norm(r, axis=1) if norm == "L2L1" else np.abs(r).ravel()

    def terms_and_jacobian(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r, J = program.residuals(x), program.residual_jacobian(x)
        if norm == "L2L2":
            return r.ravel(), J.reshape(-1, d)
        if norm == "L2L1":
            size = np.linalg.norm(r, axis=1)
            return size, np.einsum("ka,kab->kb", r, J) / np.maximum(size, 1e-300)[:, None]
        return np.abs(r).ravel(), (np.sign(r)[:, :, None] * J).reshape(-1, d)

    def values(x: np.ndarray) -> np.ndarray:
        out = terms(x)
        out = out if norm == "L2L2" else np.sqrt(out + 1e-30)
        return np.concatenate([out, np.zeros(max(0, d - out.size))])

    def jacobian(x: np.ndarray) -> np.ndarray:
        values_, dterms = terms_and_jacobian(x)
        if norm != "L2L2":
            dterms = dterms / (2 * np.sqrt(values_ + 1e-30))[:, None]
        return np.vstack([dterms, np.zeros((max(0, d - values_.size), d))])

    # MINPACK's LM through scipy's leastsq, with least_squares' defaults (tolerances 1e-8, unit
    # scaling): the same routine as least_squares(method="lm") at a third of its overhead, which
    # on a 3-unknown track is most of the refinement's time. Its warnings (iteration limit,
    # tolerances too small) say only that the descent stopped: the better point is kept either way.
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            import scipy.optimize  # here: a job that never polishes skips its import (about 0.15 s of CPU)

            trial = scipy.optimize.leastsq(values, v, Dfun=jacobian, ftol=1e-8, xtol=1e-8, gtol=1e-8,
                                           maxfev=30 if norm == "L2L2" else 50, diag=np.ones(d))[0]
        trial_cost = cost(trial)
        if trial_cost < best_cost:
            best_v, best_cost = trial, trial_cost
    except (ValueError, TypeError, np.linalg.LinAlgError, FloatingPointError):
        pass
    return best_v, best_cost


def _cost_in(program: FractionalProgram, v: np.ndarray, norm: str) -> float:
    value = program.cost(v)
    return value if not math.isfinite(value) else norm_cost(program.residuals(v), norm)


def _proven_minimum(solver: ReusableConicProgram, data: ConicData, objective: np.ndarray, first: bool):
    """Minimise ``objective`` over the relaxation ``data`` (set up by the first call, the
    objective alone changed after): the solve's result, and the safe bound of its dual (-inf
    when the solve is not clean)."""
    result = (solver.solve(objective, data.A, data.b, data.cones) if first
              else solver.solve_objective(objective))
    value = -math.inf
    if result.status is ConicStatus.OPTIMAL:
        value = safe_lower_bound(objective, data.A, data.b, data.cones, result.z, data.lower, data.upper,
                                 data.transform)
    return result, value


class BoxProblem:
    """The branch-and-bound problem of a fractional program over boxes of ``z = B v``.

    Given the root region's proof, every bound is the safe bound of its dual vector
    (cones.safe_lower_bound) and carries a LeafProof: the leaves make a certificate, in every
    mode (a summary certificate just does not return them).
    """

    def __init__(self, program: FractionalProgram, B: np.ndarray, root: Box, root_proof: RootProof):
        self.program = program
        self.norm = program.norm
        self.B = B
        self.root = root
        k = len(B)
        complement = (root_proof.lower[k:], root_proof.upper[k:])
        self.relaxation = Relaxation(program, B, complement, root_proof.functionals)
        self.tightening: list[TighteningProof] = []
        self.caps: list[CapProof] = []  # rounds of per-term caps (cap_terms), after the root's tightening
        self.interior: np.ndarray | None = None  # a point of the domain (the first incumbent)
        self._cheapest: np.ndarray | None = None  # the cheapest point seen (_seen) and its cost
        self._best = math.inf
        self._nodes = 0  # boxes bounded so far
        # Per-term caps (cap_terms) on the root box before the box after CAP_AFTER (maps), when some
        # box below the root so far had a gap of at least cap_gap times the upper bound.
        self.capping = False
        self.cap_gap = 0.0
        self._widest_gap = 0.0
        # Lean settings (no equilibration, no iterative refinement) at every size: relaxations are
        # built well scaled (a normalised chart, costs scaled to about 1), and a lean solve that does
        # not end cleanly is repeated with the full settings (core.conic._retried).
        self._solver = ReusableConicProgram(lean=True)
        self.node_tightening = False  # a round of bound tightening at every node below the root (maps)
        self._tightener = ReusableConicProgram(lean=True, tolerance=TIGHTENING_TOLERANCE)
        self._kept_bound: tuple[Box, float, BoxBound] | None = None  # (box, upper bound, its bound): tighten's last
        # A time.perf_counter() reading past which no more tightening or capping programs are
        # solved (a side or cap not solved for stays unproven: sound, only looser); the search's
        # own clock stops the nodes. None: no clock.
        self.deadline: float | None = None

    def _past_deadline(self) -> bool:
        return self.deadline is not None and time.perf_counter() >= self.deadline

    def use_bound_tolerance(self, tolerance: float) -> None:
        """Node bounds solved to ``tolerance`` (lean settings) instead of 1e-9."""
        self._solver = ReusableConicProgram(lean=True, tolerance=tolerance)

    # --- BranchProblem interface -------------------------------------------------------------
    def root_box(self) -> Box:
        return self.root

    def objective(self, v: np.ndarray) -> float:
        value = self.program.cost(v)
        self._seen(v, value)
        return value

    def improve(self, v: np.ndarray) -> tuple[np.ndarray, float]:
        v, value = local_refine(self.program, v)
        self._seen(v, value)
        return v, value

    def _seen(self, v: np.ndarray, value: float) -> None:
        """Keep the cheapest point seen, from the first incumbent on (the search's incumbent)."""
        if self._cheapest is None and self.interior is not None:
            self._cheapest, self._best = self.interior, self.program.cost(self.interior)
        if self._cheapest is not None and value < self._best:
            self._cheapest, self._best = v, value

    def conic_data(self, box: Box, upper_bound: float, envelope: bool = True) -> ConicData | None:
        return self.relaxation.conic_data(box, upper_bound, envelope)

    def bound(self, box: Box, upper_bound: float) -> BoxBound:
        """The box's relaxation bound; with node tightening (below the root, once an incumbent
        is known), the box is first cut to the range its points costing at most ``upper_bound``
        can have, and the rest is bounded: fewer, smaller boxes for 6 small solves a node."""
        self._nodes += 1
        if self.capping and self._nodes > CAP_AFTER and math.isfinite(upper_bound) and self.interior is not None:
            self.capping = False
            if self._widest_gap >= self.cap_gap * upper_bound:
                self._seen(self.interior, self.program.cost(self.interior))
                self.cap_terms(self.root, upper_bound, self._cheapest)
        result = self._tightened_bound(box, upper_bound)
        if result.status == BoxStatus.BOUNDED and self._nodes > 1:
            self._widest_gap = max(self._widest_gap, upper_bound - result.lower_bound)
        return result

    def _tightened_bound(self, box: Box, upper_bound: float) -> BoxBound:
        if not (self.node_tightening and box is not self.root and math.isfinite(upper_bound)):
            return self._bound(box, upper_bound)
        tightened, excluded = self._tighten_node(box, upper_bound)
        if tightened is None:
            return BoxBound(BoxStatus.EMPTY, excluded=excluded)
        result = self._bound(tightened, upper_bound)
        if tightened is box:
            return result
        if result.status == BoxStatus.UNRESOLVED:
            # A box cut to hug the points within the cap can leave a relaxation with almost no
            # interior, which the conic solver may not end cleanly: then the box as it was.
            return self._bound(box, upper_bound)
        result.box, result.excluded = tightened, excluded
        return result

    def _closes(self, box: Box, upper_bound: float, gap: float) -> bool:
        """Whether ``box``'s bound is within ``gap`` of ``upper_bound`` (relative); the bound is
        kept for the search's first look at that box."""
        result = self._bound(box, upper_bound)
        self._kept_bound = (box, upper_bound, result)
        return result.status == BoxStatus.BOUNDED and upper_bound - result.lower_bound <= gap * upper_bound

    def _bound(self, box: Box, upper_bound: float) -> BoxBound:
        kept = self._kept_bound
        if kept is not None and kept[0] is box and kept[1] == upper_bound:
            self._kept_bound = None
            return kept[2]
        data = self.conic_data(box, upper_bound)
        if data is None:  # some depth is negative on the whole box
            return BoxBound(BoxStatus.EMPTY, proof=LeafProof(box, upper_bound, "depth", None, math.inf))
        result = self._solver.solve(data.q, data.A, data.b, data.cones)
        if result.status is ConicStatus.INFEASIBLE:
            if proves_infeasible(data.A, data.b, data.cones, result.z, data.lower, data.upper, data.transform):
                return BoxBound(BoxStatus.EMPTY, proof=LeafProof(box, upper_bound, "farkas", result.z, math.inf,
                                                                    caps=len(self.caps)))
            return BoxBound(BoxStatus.UNRESOLVED)
        if result.status is not ConicStatus.OPTIMAL:
            return BoxBound(BoxStatus.UNRESOLVED)
        v = result.x[: self.program.dim]
        candidate = self._candidate(v)
        safe = safe_lower_bound(data.q, data.A, data.b, data.cones, result.z, data.lower, data.upper, data.transform)
        if not math.isfinite(safe):
            return BoxBound(BoxStatus.UNRESOLVED, candidate=candidate, split_hint=self.B @ v)
        return BoxBound(BoxStatus.BOUNDED, safe, candidate, self.B @ v,
                        LeafProof(box, upper_bound, "dual", result.z, safe, caps=len(self.caps)))

    def _candidate(self, v: np.ndarray) -> np.ndarray | None:
        """The relaxation's point as a candidate incumbent. It often lies on the domain's boundary
        (a depth or the chart's last coordinate at 0), where round-off can put it just outside:
        then a point slightly towards a known interior point (the domain is convex) is tried."""
        if math.isfinite(self.program.cost(v)):
            return v
        if self.interior is not None:
            for step in (1e-9, 1e-6, 1e-3):
                w = v + step * (self.interior - v)
                if math.isfinite(self.program.cost(w)):
                    return w
        return None

    def tighten(self, box: Box, upper_bound: float, rounds: int, closing_gap: float | None = None) -> Box:
        """Shrink ``box`` to the range of ``z = B v`` over the relaxation's points costing at most
        ``upper_bound`` (optimality-based bound tightening), repeated while it shrinks the volume
        by half. Valid: every point costing at most ``upper_bound`` is such a point, because the
        relaxation under-estimates the cost. The tighter box makes the envelopes tighter, so a
        round can shrink it again. A solve that is not accurate leaves its side as it was. Each
        side is the safe bound of its dual, recorded in ``self.tightening``.

        ``closing_gap``: the box is bounded before each round (one solve, against a round's 2k),
        and tightening stops once that bound is within ``closing_gap`` of ``upper_bound``
        (relative): the search then closes at its root, whose bound is the one kept here.
        Measured on resections of 30 to 800 points (0.5 px noise): the untightened root left
        0.1% to 1.6%, one round closed every one, and the three more rounds made before this
        stop were 60% to 70% of the solve."""
        solver = ReusableConicProgram(lean=True, tolerance=TIGHTENING_TOLERANCE)  # 2k objectives, one feasible set
        for _ in range(rounds):
            if self._past_deadline():
                return box
            if closing_gap is not None and self._closes(box, upper_bound, closing_gap):
                return box
            data = self.conic_data(box, upper_bound, envelope=False)
            if data is None:
                return box
            low, high, duals = self._proven_range(solver, with_cost_cap(data, upper_bound))
            if duals is None:
                return box  # infeasible: cannot happen with the incumbent inside; keep what is proven
            lo, hi = np.maximum(box.lo, low), np.minimum(box.hi, high)
            hi = np.maximum(hi, lo)
            ratio = float(np.prod((hi - lo) / np.maximum(box.width, 1e-300)))
            self.tightening.append(TighteningProof(upper_bound, box, Box(lo, hi), duals))
            box = Box(lo, hi)
            if ratio > 0.5:
                break
        return box

    def cap_terms(self, box: Box, upper_bound: float, incumbent: np.ndarray, rounds: int = 2,
                  share: float = CAP_SHARE, limit: int = CAP_LIMIT) -> None:
        """Per-term caps (Relaxation.others): for the observations costing at least ``share`` of
        ``upper_bound`` at ``incumbent`` (at most ``limit``, largest first), a proven lower bound
        on the sum of the other terms over the relaxation's points of ``box`` costing at most
        ``upper_bound``: the minimum of that sum over the relaxation with its cost cap, the safe
        bound of its dual. Each term of a better point is then within ``upper_bound`` less it,
        which tightens its envelope (u_i) and its residual cone (gamma_i) at every node in
        ``box``. Repeated ``rounds`` times (each round's relaxation has the previous caps)."""
        terms = norm_terms(self.program.residuals(incumbent), self.norm)
        order = np.argsort(-terms)[:limit]
        chosen = order[terms[order] >= share * upper_bound]
        if not len(chosen):
            return
        relaxation = self.relaxation
        others = np.zeros(len(self.program.den)) if relaxation.others is None else relaxation.others.copy()
        solver = ReusableConicProgram(lean=True, tolerance=LARGE_BOUND_TOLERANCE)
        for _ in range(rounds):
            data = self.conic_data(box, upper_bound)
            if data is None:
                return
            data = with_cost_cap(data, upper_bound)
            variables = relaxation.term_variables(chosen)
            duals: list[np.ndarray | None] = []
            proven = others[chosen].copy()
            for number, (i, index) in enumerate(zip(chosen, variables)):
                if self._past_deadline():  # this term's cap stays what was proven before
                    duals.append(None)
                    continue
                objective = data.q.copy()
                objective[index] = 0.0
                result, value = _proven_minimum(solver, data, objective, first=not duals)
                duals.append(result.z if math.isfinite(value) else None)
                if math.isfinite(value):
                    proven[number] = max(proven[number], value)
            self.caps.append(CapProof(upper_bound, box, chosen.copy(), duals))
            others[chosen] = proven
            relaxation.others = others.copy()

    def _proven_range(self, solver: ReusableConicProgram, data: ConicData):
        """The range of each ``B_i v`` over a relaxation with its cost cap: proven sides (-inf or
        inf where a solve was not clean) and their dual vectors, lower then upper side of each
        (None: not proven); duals None when the relaxation is infeasible."""
        k = len(self.B)
        low, high = np.full(k, -np.inf), np.full(k, np.inf)
        duals: list[np.ndarray | None] = []
        for i in range(k):
            for sign, side in ((1.0, low), (-1.0, high)):
                if self._past_deadline():  # this side stays unproven (infinite)
                    duals.append(None)
                    continue
                objective = tightening_objective(data, self.B[i], sign)
                result, value = _proven_minimum(solver, data, objective, first=not duals)
                if result.status is ConicStatus.INFEASIBLE:
                    return low, high, None
                duals.append(result.z if math.isfinite(value) else None)
                if math.isfinite(value):
                    side[i] = sign * value
        return low, high, duals

    def _tighten_node(self, box: Box, upper_bound: float) -> tuple[Box | None, list[tuple[Box, LeafProof]]]:
        """One round of bound tightening on a node's box: the range of each ``z_i = B_i v`` over
        the relaxation's points of ``box`` costing at most ``upper_bound``, proven by the duals.
        Returns the box left to bound (None: nothing left) and the parts cut off, each with a
        ``tightened`` proof: a part lies strictly outside a proven range, so no point of it costs
        at most ``upper_bound``. A side is only cut when that shrinks it by NODE_CUT of its width."""
        data = self.conic_data(box, upper_bound, envelope=False)
        if data is None:
            return box, []
        low, high, duals = self._proven_range(self._tightener, with_cost_cap(data, upper_bound))
        if duals is None:
            return box, []
        proven = np.vstack([np.maximum(box.lo, low), np.minimum(box.hi, high)])
        proof = LeafProof(box, upper_bound, "tightened", None, math.inf, duals, caps=len(self.caps))
        lo, hi = box.lo.copy(), box.hi.copy()
        parts: list[tuple[Box, LeafProof]] = []
        width = box.width
        for i in range(len(self.B)):
            low, high = proven[0, i], proven[1, i]
            if low > high:  # no point of the box costs at most upper_bound
                return None, [(box, proof)]
            # Cut just short of the proven side, so that each part lies strictly outside it.
            cut = low - NODE_MARGIN * width[i]
            if cut < low and cut - lo[i] > NODE_CUT * width[i]:
                part_hi = hi.copy()
                part_hi[i] = cut
                parts.append((Box(lo.copy(), part_hi), proof))
                lo[i] = cut
            cut = high + NODE_MARGIN * width[i]
            if cut > high and hi[i] - cut > NODE_CUT * width[i]:
                part_lo = lo.copy()
                part_lo[i] = cut
                parts.append((Box(part_lo, hi.copy()), proof))
                hi[i] = cut
        if not parts:
            return box, []
        return Box(lo, hi), parts

    def split(self, box: Box, bound: BoxBound) -> list[Box]:
        """Split where the depths vary most relative to their size, at the relaxation's point."""
        width = box.width
        if len(self.relaxation.env):
            low = np.maximum(self.relaxation.depth_range(box)[0], EPS_DEPTH)
            score = width * np.max(np.abs(self.relaxation.coef) / low[:, None], axis=0)
        else:
            score = width.copy()
        k = int(np.argmax(score))
        cut = 0.5 * (box.lo[k] + box.hi[k])
        if bound.split_hint is not None:
            cut = float(np.clip(bound.split_hint[k], box.lo[k] + 0.1 * width[k], box.hi[k] - 0.1 * width[k]))
        left_hi, right_lo = box.hi.copy(), box.lo.copy()
        left_hi[k], right_lo[k] = cut, cut
        return [Box(box.lo.copy(), left_hi), Box(right_lo, box.hi.copy())]


@dataclass
class Prepared:
    """What :func:`prepare` returns when a search is needed."""

    problem: BoxProblem
    incumbent: np.ndarray
    upper: float  # the incumbent's scaled cost (inf when outside the user's bound)
    scale: float  # the residuals' factor
    root_proof: RootProof
    reasons: Reasons

    @property
    def unit(self) -> float:
        """Scaled cost = unit * cost in the caller's units."""
        return cost_unit(self.scale, self.problem.norm)


@dataclass
class Early:
    """What :func:`prepare` returns when the answer is known before any search."""

    status: str  # optimal (trivial bound), infeasible, degenerate, not_certified
    incumbent: np.ndarray | None
    cost: float | None  # in the caller's units
    reason: str | None


@dataclass
class Reasons:
    """Why a solve ended before any search, in the words of the problem kind."""

    no_domain_found: str  # no point of the domain (every depth positive) was found
    degenerate: str  # the data do not bound the solutions within the residual bound
    over_max_residual: str = "no solution with every residual within max_residual was found"
    proven_over_max_residual: str = ("no solution has every residual within max_residual (every box of the search "
                                     "closed empty; the proof is not carried, so the item reads not_certified)")
    not_certified: str = "the root region's bounds could not be computed accurately"


def _in_scope_start(program: FractionalProgram, v: np.ndarray) -> np.ndarray | None:
    """A point of the scope (every residual within max_residual) near ``v``: ``v`` itself when
    it is in scope, else a point of the residual region of max_residual (one SOCP)."""
    if math.isfinite(program.cost(v)):
        return v
    res = solve_conic(np.zeros(program.dim), *residual_region(program, program.max_residual * (1 - 1e-6)))
    if res.status is ConicStatus.OPTIMAL and math.isfinite(program.cost(res.x)):
        return res.x
    return None


def prepare(program: FractionalProgram, start: np.ndarray | None, subspace: np.ndarray,
            abs_gap: float, max_residual: float | None, reasons: Reasons) -> Prepared | Early:
    """Incumbent, scaling and root region. ``start``: an initial point (None or infeasible: one
    is searched for); ``subspace``: rows spanning the directions the depths depend on;
    ``max_residual``: the scope (every residual's 2-norm within it; None: no limit); incumbents
    are always in it. The root region is not tightened here: a caller whose nodes are many and
    costly (maps) tightens it (BoxProblem.tighten); triangulation's searches take a few nodes.
    Every bound is proven (Prepared.root_proof, leaves' proofs), in every mode."""
    norm = program.norm
    if start is None or not math.isfinite(program.cost(start)):
        start = feasible_point(program)
        if start is None:  # no proof that the domain is empty: only that none was found
            return Early("not_certified", None, None, reasons.no_domain_found)
    v0, cost0 = local_refine(program, start, "L2L2")  # program.cost(v0) when the norm is L2L2
    if norm != "L2L2":
        v0, cost0 = local_refine(program, v0)
    program.max_residual = max_residual
    in_scope = _in_scope_start(program, v0) if max_residual is not None else v0
    if in_scope is not None and in_scope is not v0:
        v0, cost0 = local_refine(program, in_scope)
    if in_scope is not None and cost0 <= abs_gap:  # within tolerance of the trivial bound 0
        return Early("optimal", v0, cost0, None)
    # Scale residuals so the incumbent costs 1 (raw costs near 1e-5 lose accuracy), but by no more
    # than MAX_SCALE: nearly exact data would make residual rows 1e6 times the depth rows.
    factor = min(MAX_SCALE, 1.0 / math.sqrt(cost0) if norm == "L2L2" else 1.0 / cost0)
    program.rescale(factor)
    unit = cost_unit(factor, norm)
    upper = program.cost(v0)  # inf when no point of the scope was found
    gamma = gamma_for(upper, norm)
    if program.max_residual is not None:
        gamma = min(gamma, program.max_residual)
    if not math.isfinite(upper):
        # No incumbent: the root region must hold the whole scope. That of the out-of-scope
        # point's residual bound does (it is larger than max_residual), and it is not empty, so
        # its bounds can be proven; the search then proves each box empty of in-scope points
        # (or finds one).
        gamma = max(program.max_residual, gamma_for(cost0 * unit, norm))
    B = branch_directions(program, subspace)
    state, root, root_proof = root_region(program, B, gamma)
    if root is None:
        # The conic solver's words, not proofs a verifier checks: the item is not certified,
        # and its reason says what the solver found (docs/certificate.md, "Uncertified items").
        reason_state = "not_certified" if state == "infeasible" else state
        state = "not_certified"
        reason = {"degenerate": reasons.degenerate, "not_certified":
                  reasons.not_certified if math.isfinite(upper) else reasons.over_max_residual}[reason_state]
        if not math.isfinite(upper):
            return Early(state, None, None, reason)
        return Early(state, v0, upper / unit, reason)
    problem = BoxProblem(program, B, root, root_proof)
    problem.interior = v0
    return Prepared(problem, v0, upper, factor, root_proof, reasons)


def recomputed_status(status: str, residuals: np.ndarray, cost: float, lower: float | None,
                      options: FractionalOptions, rounding: np.ndarray | None = None) -> tuple[str, str | None]:
    """The status of a solution whose residuals and cost were recomputed from the raw data at
    the point as returned (rounded from the search's variables), as the verifier recomputes
    them: "optimal" stays only when that cost, plus what each residual coordinate's ``rounding``
    (the verifier's: certificates.ROUNDING of the sizes of image and observation) can add, is
    still within the tolerance of the proven bound, and every residual still within max_residual."""
    if status != "optimal" or lower is None:
        return status, None
    slack = 0.0 if rounding is None else cost_rounding(residuals, rounding, options.norm) * (1 + 1e-6)
    if cost + slack - lower > max(options.abs_gap, options.rel_gap * cost):
        return "not_certified", (f"the solution's cost recomputed from the data, {cost!r} (to within {slack!r}), is "
                                 f"not within the tolerance of the proven bound {lower!r}")
    if options.max_residual is not None and not np.all(residual_lengths(residuals) <= options.max_residual):
        return "not_certified", ("the solution as returned has a residual beyond max_residual "
                                 f"{options.max_residual!r} once recomputed from the data")
    return status, None


@dataclass
class Searched:
    status: str
    solution: np.ndarray | None  # None: nothing within max_residual was found
    lower_bound: float | None  # in the caller's units
    nodes: int
    certificate: SearchCertificate | None
    reason: str | None = None


def search(prepared: Prepared, options: FractionalOptions, scope: str, reference: int,
           functionals: np.ndarray, denominator: np.ndarray, callback=None) -> Searched:
    """Branch and bound from a prepared program; progress and bounds in the caller's units.
    ``functionals`` maps the caller's unknown to ``B v`` up to the ``denominator``'s scale."""
    unit = prepared.unit

    def unscaled(p: Progress):
        return callback(Progress(p.nodes, p.open_boxes, p.lower_bound / unit, p.upper_bound / unit,
                                 p.gap_abs / unit, p.gap_rel, p.elapsed_s))

    leaves: list = []
    bnb = branch_and_bound(
        prepared.problem, prepared.incumbent, prepared.upper,
        BnbOptions(rel_gap=options.rel_gap, abs_gap=options.abs_gap * unit, max_nodes=options.max_nodes,
                   time_limit_s=options.time_limit_s),
        callback=unscaled if callback else None,
        leaves=leaves,
    )
    if not math.isfinite(bnb.upper_bound):  # no point of the scope was found
        if all(proof is not None and math.isinf(proof.bound) for _, proof in leaves):
            # Every box of the root region (which holds the whole scope) proven to hold none.
            # Status not_certified: "infeasible" is said only where the verifier checks it
            # (docs/certificate.md), and this proof is not carried.
            return Searched("not_certified", None, None, bnb.nodes, None, prepared.reasons.proven_over_max_residual)
        status = bnb.status if bnb.status != "optimal" else "not_certified"
        return Searched(status, None, None, bnb.nodes, None, prepared.reasons.over_max_residual)
    if options.max_residual is not None:
        scope = f"{scope} with every residual <= {options.max_residual}"
    root = prepared.problem.root
    certificate = SearchCertificate(scope, reference, np.asarray(functionals).tolist(),
                                    np.asarray(denominator).tolist(), root.lo.tolist(), root.hi.tolist(),
                                    bnb.tolerance / unit, bnb.upper_bound - bnb.lower_bound <= bnb.tolerance,
                                    bnb.leaves)
    if options.certificate == "full":
        certificate.proof = encode(SearchProof(prepared.scale, prepared.root_proof, prepared.problem.tightening,
                                               root, leaves, prepared.problem.caps,
                                               prepared.problem.relaxation.quadratic))
    return Searched(bnb.status, bnb.candidate, bnb.lower_bound / unit, bnb.nodes, certificate)

"""Sums of ratios ``sum_i f(n_i(v)) / g_i(v)`` (thesis chapter 5): what triangulation,
resectioning and P^n -> P^m maps have in common.

``v`` is a vector of d unknowns; observation i has m affine numerator rows ``n_i(v)`` (its
residual times its depth) and an affine depth ``g_i(v) > 0``. Observations whose depth is
constant are "exact": stored with depth identically 1, their terms are convex and need no
envelope. The lower bound on a box of branching functionals ``z = B v`` is one SOCP holding each
ratio above the convex envelope of ``t / s`` (ALGORITHMS.md section 2).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.sparse as sp

from .bnb import BnbOptions, Box, BoxBound, BoxStatus, Progress, branch_and_bound
from .conic import ConeSpec, ConicStatus, ReusableConicProgram, solve_conic
from .geometry import InputError, norm_cost

EPS_DEPTH = 1e-12
MAX_SCALE = 1e3
NORMS = ("L2L2", "L2L1", "L1L1")


@dataclass
class FractionalOptions:
    """Options every fractional-program kind shares (each kind sets its own defaults)."""

    norm: str = "L2L2"
    rel_gap: float = 1e-3
    # In the cost's units (squared for L2L2). Below about 1e-7 the conic solves cannot resolve
    # the bound (measured on a Dinosaur track whose optimum is 1e-6 px).
    abs_gap: float = 1e-7
    max_nodes: int = 2000
    time_limit_s: float = 30.0
    max_residual: float | None = None  # the kind's residual units; narrows the certificate's scope

    def check(self) -> None:
        if self.norm not in NORMS:
            raise InputError("options/norm", f"must be one of {', '.join(NORMS)}")
        for name in ("rel_gap", "abs_gap", "time_limit_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"options/{name}", "must be a finite number >= 0")
        if self.max_nodes < 1:
            raise InputError("options/max_nodes", "must be at least 1")
        if self.max_residual is not None and not (math.isfinite(self.max_residual) and self.max_residual > 0):
            raise InputError("options/max_residual", "must be a finite number > 0")


def gamma_for(upper_bound: float, norm: str) -> float:
    """Largest single residual (2-norm) of any point costing at most ``upper_bound``."""
    return math.sqrt(upper_bound) if norm == "L2L2" else upper_bound


@dataclass
class FractionalProgram:
    num: np.ndarray  # (N, m, d + 1): numerator rows, last column constant
    den: np.ndarray  # (N, d + 1): depths; exact observations hold e_{d+1}
    exact: np.ndarray  # (N,) bool
    linear: np.ndarray  # (L, d + 1): linear(v) >= 0 on the domain
    norm: str

    @property
    def dim(self) -> int:
        return self.num.shape[2] - 1

    def rescale(self, factor: float) -> None:
        self.num = self.num * factor

    def __post_init__(self) -> None:
        self._linear_slack = 1e-12 * np.linalg.norm(self.linear, axis=1)  # round-off allowed

    def cost(self, v: np.ndarray) -> float:
        V = np.append(v, 1.0)
        g = self.den @ V
        if np.any(g <= 0) or np.any(self.linear @ V < -self._linear_slack * np.linalg.norm(V)):
            return math.inf
        return norm_cost((self.num @ V) / g[:, None], self.norm)

    def residuals(self, v: np.ndarray) -> np.ndarray:
        V = np.append(v, 1.0)
        return (self.num @ V) / (self.den @ V)[:, None]

    def residual_jacobian(self, v: np.ndarray) -> np.ndarray:
        """(N, m, d): derivative of each residual coordinate."""
        V = np.append(v, 1.0)
        n, g = self.num @ V, self.den @ V
        d = self.dim
        return self.num[:, :, :d] / g[:, None, None] - n[:, :, None] * self.den[:, None, :d] / (g**2)[:, None, None]


def branch_directions(program: FractionalProgram, subspace: np.ndarray) -> np.ndarray:
    """Rows spanning ``subspace`` (k orthonormal rows): the best-conditioned depth gradients
    first (greedy), completed with orthogonal directions of the subspace."""
    candidates = [program.den[i, :-1] for i in np.flatnonzero(~program.exact)]
    candidates = [c / np.linalg.norm(c) for c in candidates if np.linalg.norm(c) > 0]
    k = subspace.shape[0]
    chosen: list[np.ndarray] = []
    basis: list[np.ndarray] = []
    while len(chosen) < k and candidates:
        residuals = [c - sum((c @ b) * b for b in basis) for c in candidates]
        norms = [np.linalg.norm(r) for r in residuals]
        best = int(np.argmax(norms))
        if norms[best] < 0.25:
            break
        chosen.append(candidates.pop(best))
        basis.append(residuals[best] / norms[best])
    for e in subspace:
        if len(basis) == k:
            break
        r = e - sum((e @ b) * b for b in basis)
        if np.linalg.norm(r) > 0.5:
            basis.append(r / np.linalg.norm(r))
            chosen.append(basis[-1])
    return np.array(chosen)


def residual_region(program: FractionalProgram, gamma: float) -> tuple[np.ndarray, np.ndarray, ConeSpec]:
    """Conic data (A, b, cones) of {v : ||residual_i(v)|| <= gamma for all i, linear(v) >= 0}.

    ``||n_i|| <= gamma * g_i`` also gives positive depths.
    """
    m = program.num.shape[1]
    rows = list(program.linear)
    for i in range(len(program.num)):
        rows.append(gamma * program.den[i])
        rows.extend(program.num[i])
    E = np.array(rows)  # each row: coefficients of v, then the constant
    cones = ConeSpec(nonneg=len(program.linear), soc=(m + 1,) * len(program.num))
    return -E[:, :-1], E[:, -1].copy(), cones


def root_region(program: FractionalProgram, B: np.ndarray, gamma: float) -> tuple[str, Box | None]:
    """Bound B v over the residual region: 2k small SOCPs.

    An inaccurate solve is retried with gamma inflated slightly: a larger residual bound still
    gives a region holding every better point, and a different problem often solves cleanly.
    """
    for inflation in (1.0, 1.001, 1.01):
        state, box = _root_region_once(program, B, gamma * inflation)
        if state != "not_certified":
            return state, box
    return state, box


def _root_region_once(program: FractionalProgram, B: np.ndarray, gamma: float) -> tuple[str, Box | None]:
    A, b, cones = residual_region(program, gamma)
    solver = ReusableConicProgram()  # 2k objectives over one feasible set
    lo, hi = np.zeros(len(B)), np.zeros(len(B))
    for k in range(len(B)):
        for sign, out in ((1.0, lo), (-1.0, hi)):
            res = solver.solve(sign * B[k], A, b, cones)
            if res.status is ConicStatus.UNBOUNDED:
                return "degenerate", None
            if res.status is ConicStatus.INFEASIBLE:
                return "infeasible", None
            if res.status is not ConicStatus.OPTIMAL:
                return "not_certified", None
            out[k] = sign * res.lower_bound  # min(primal, dual): the outer side for both ends
    pad = 1e-7 * (1 + np.abs(lo) + np.abs(hi))
    return "ok", Box(lo - pad, hi + pad)


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

    try:
        trial = scipy.optimize.least_squares(values, v, jac=jacobian, method="lm",
                                             max_nfev=30 if norm == "L2L2" else 50).x
        trial_cost = cost(trial)
        if trial_cost < best_cost:
            best_v, best_cost = trial, trial_cost
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        pass
    return best_v, best_cost


def _cost_in(program: FractionalProgram, v: np.ndarray, norm: str) -> float:
    value = program.cost(v)
    return value if not math.isfinite(value) else norm_cost(program.residuals(v), norm)


_DENSE_LIMIT = 200_000  # relaxations with fewer matrix entries are assembled dense


class _Rows:
    """A block of rows ``c + E x``: E as a dense part over the d unknowns plus (row, column,
    value) triplets for the per-observation columns, so that assembly stays linear in size."""

    def __init__(self, rows: int, d: int):
        self.v = np.zeros((rows, d))
        self.c = np.zeros(rows)
        self.triplets: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def set(self, rows: np.ndarray, cols: np.ndarray, values) -> None:
        """Entries (rows[i], cols[i]) = values[i] (or the one value given); rows, cols alike."""
        if np.isscalar(values):
            values = np.full(len(rows), float(values))
        self.triplets.append((rows, cols, values))


def _assemble(blocks: list[_Rows], n: int):
    """A = -E for Clarabel (dense when small, CSC otherwise) and the constants b = c."""
    offsets = np.cumsum([0] + [len(b.c) for b in blocks])
    V = np.vstack([b.v for b in blocks])
    rows = np.concatenate([r + offsets[i] for i, b in enumerate(blocks) for r, _, _ in b.triplets])
    cols = np.concatenate([k for b in blocks for _, k, _ in b.triplets])
    vals = np.concatenate([x for b in blocks for _, _, x in b.triplets])
    c = np.concatenate([b.c for b in blocks])
    d = V.shape[1]
    if V.shape[0] * n <= _DENSE_LIMIT:
        E = np.zeros((V.shape[0], n))
        E[:, :d] = V
        E[rows, cols] = vals
        return -E, c
    vr, vc = np.nonzero(V)
    E = sp.coo_matrix((np.concatenate([V[vr, vc], vals]), (np.concatenate([vr, rows]), np.concatenate([vc, cols]))),
                      shape=(V.shape[0], n))
    return (-E).tocsc(), c


class BoxProblem:
    """The branch-and-bound problem of a fractional program over boxes of ``z = B v``."""

    def __init__(self, program: FractionalProgram, user_gamma: float | None, B: np.ndarray, root: Box):
        self.program = program
        self.norm = program.norm
        self.user_gamma = user_gamma
        self.B = B
        self.root = root
        self.env = np.flatnonzero(~program.exact)  # observations bounded by the envelope
        self.exact = np.flatnonzero(program.exact)
        # Depth of envelope observation j in terms of z: coef[j] @ z + offset[j]. Exact because
        # every depth gradient lies in the row space of B (B spans the depths' subspace).
        self.coef = program.den[self.env, :-1] @ B.T @ np.linalg.inv(B @ B.T)  # B's pseudo-inverse
        self.offset = program.den[self.env, -1]
        self._solver = ReusableConicProgram()

    # --- BranchProblem interface -------------------------------------------------------------
    def root_box(self) -> Box:
        return self.root

    def objective(self, v: np.ndarray) -> float:
        return self.program.cost(v)

    def improve(self, v: np.ndarray) -> tuple[np.ndarray, float]:
        return local_refine(self.program, v)

    def depth_range(self, box: Box) -> tuple[np.ndarray, np.ndarray]:
        pos, neg = np.clip(self.coef, 0, None), np.clip(self.coef, None, 0)
        return self.offset + pos @ box.lo + neg @ box.hi, self.offset + pos @ box.hi + neg @ box.lo

    def conic_data(self, box: Box, upper_bound: float, envelope: bool = True):
        """The relaxation on ``box`` as (q, A, b, cones), or None when some depth is negative on
        the whole box."""
        low, high = self.depth_range(box)
        if np.any(high <= EPS_DEPTH):
            return None
        low = np.maximum(low, EPS_DEPTH)
        high = np.maximum(high, low * (1 + 1e-9) + 1e-15)
        gamma = gamma_for(upper_bound, self.norm) if math.isfinite(upper_bound) else math.inf
        if self.user_gamma is not None:
            gamma = min(gamma, self.user_gamma)
        return self.relaxation(box, low, high, gamma, envelope)

    def bound(self, box: Box, upper_bound: float) -> BoxBound:
        data = self.conic_data(box, upper_bound)
        if data is None:
            return BoxBound(BoxStatus.EMPTY)  # some depth is negative on the whole box
        result = self._solver.solve(*data)
        if result.status is ConicStatus.INFEASIBLE:
            return BoxBound(BoxStatus.EMPTY)
        if result.status is not ConicStatus.OPTIMAL:
            return BoxBound(BoxStatus.UNRESOLVED)
        v = result.x[: self.program.dim]
        candidate = v if math.isfinite(self.program.cost(v)) else None
        return BoxBound(BoxStatus.BOUNDED, result.lower_bound, candidate, self.B @ v)

    def tighten(self, box: Box, upper_bound: float, rounds: int) -> Box:
        """Shrink ``box`` to the range of ``z = B v`` over the relaxation's points costing at most
        ``upper_bound`` (optimality-based bound tightening), repeated while it shrinks the volume
        by half. Valid: every point costing at most ``upper_bound`` is such a point, because the
        relaxation under-estimates the cost. The tighter box makes the envelopes tighter, so a
        round can shrink it again. A solve that is not accurate leaves its side as it was."""
        solver = ReusableConicProgram()  # 2k objectives over one feasible set per round
        d, k = self.program.dim, len(self.B)
        for _ in range(rounds):
            data = self.conic_data(box, upper_bound, envelope=False)
            if data is None:
                return box
            q, A, b, cones = data
            # sum r <= upper_bound: one more nonnegative row, ahead of the others
            A = sp.vstack([sp.csr_matrix(q[None, :]), A]).tocsc() if sp.issparse(A) else np.vstack([q[None, :], A])
            b = np.concatenate([[upper_bound], b])
            cones = ConeSpec(nonneg=cones.nonneg + 1, soc=cones.soc)
            lo, hi = box.lo.copy(), box.hi.copy()
            for i in range(k):
                for sign, side in ((1.0, lo), (-1.0, hi)):
                    objective = np.zeros(len(q))
                    objective[:d] = sign * self.B[i]
                    result = solver.solve(objective, A, b, cones)
                    if result.status is ConicStatus.INFEASIBLE:
                        return box  # cannot happen with the incumbent inside; keep what is proven
                    if result.status is ConicStatus.OPTIMAL:
                        value = sign * result.lower_bound  # min(primal, dual): the outer side
                        value -= sign * 1e-7 * (1 + abs(value))
                        side[i] = max(side[i], value) if sign > 0 else min(side[i], value)
            hi = np.maximum(hi, lo)
            ratio = float(np.prod((hi - lo) / np.maximum(box.width, 1e-300)))
            box = Box(lo, hi)
            if ratio > 0.5:
                break
        return box

    def split(self, box: Box, bound: BoxBound) -> list[Box]:
        """Split where the depths vary most relative to their size, at the relaxation's point."""
        width = box.width
        if len(self.env):
            low = np.maximum(self.depth_range(box)[0], EPS_DEPTH)
            score = width * np.max(np.abs(self.coef) / low[:, None], axis=0)
        else:
            score = width.copy()
        k = int(np.argmax(score))
        cut = 0.5 * (box.lo[k] + box.hi[k])
        if bound.split_hint is not None:
            cut = float(np.clip(bound.split_hint[k], box.lo[k] + 0.1 * width[k], box.hi[k] - 0.1 * width[k]))
        left_hi, right_lo = box.hi.copy(), box.lo.copy()
        left_hi[k], right_lo[k] = cut, cut
        return [Box(box.lo.copy(), left_hi), Box(right_lo, box.hi.copy())]

    def relaxation(self, box: Box, low: np.ndarray, high: np.ndarray, gamma: float, envelope: bool = True):
        """``min sum r`` over the box in Clarabel's form (ALGORITHMS.md section 2).

        Rows are expressions ``c + E x`` that must lie in the cone (Clarabel wants ``b - A x``,
        so ``A = -E``). Variables: v (d), then t, w, r per envelope observation, then one
        epigraph variable per exact observation. Blocks are filled for all observations at once,
        and assembled dense for small problems, sparse for large ones.

        Without ``envelope``, each ratio ``t / s`` is bounded below by ``t / U`` instead: weaker
        on wide depth intervals, nearly as tight on narrow ones, and a third of the size (no w,
        r and their six rows), which is what bound tightening wants.
        """
        program, norm = self.program, self.norm
        d, m = program.dim, program.num.shape[1]
        env, exact = self.env, self.exact
        nE, nX = len(env), len(exact)
        per_env = 3 if envelope else 1
        n = d + per_env * nE + nX
        t_idx = d + np.arange(nE)
        w_idx, r_idx = t_idx + nE, t_idx + 2 * nE
        q_idx = d + per_env * nE + np.arange(nX)
        finite_gamma = math.isfinite(gamma)
        u = (gamma**2 if norm == "L2L2" else gamma) * high if finite_gamma else 1e12 * high
        obs = np.concatenate([env, exact])
        top_idx = np.concatenate([t_idx, q_idx])  # the variable above each observation's numerator
        depth = program.den[obs]
        num = program.num[obs]  # (V, m, d + 1)
        V = len(obs)
        blocks: list[_Rows] = []

        def block(rows: int) -> _Rows:
            blocks.append(_Rows(rows, d))
            return blocks[-1]

        k = len(self.B)
        L = len(program.linear)
        B = block(2 * k + L)  # the box on z = B v, and the domain's linear constraints
        B.v[:k], B.c[:k] = self.B, -box.lo
        B.v[k:2 * k], B.c[k:2 * k] = -self.B, box.hi
        B.v[2 * k:], B.c[2 * k:] = program.linear[:, :-1], program.linear[:, -1]
        if envelope:  # envelope of t/s on [0, u] x [L, U], first cone vacuous since l = 0 (5 rows each)
            B = block(5 * nE)
            rows = 5 * np.arange(nE)
            g = program.den[env]
            B.set(rows, w_idx, 1.0), B.set(rows, t_idx, -low / u)
            B.set(rows + 1, t_idx, high / u), B.set(rows + 1, w_idx, -1.0)
            B.v[rows + 2], B.c[rows + 2] = g[:, :-1], g[:, -1] - low
            B.set(rows + 2, w_idx, -1.0), B.set(rows + 2, t_idx, low / u)
            B.v[rows + 3], B.c[rows + 3] = -g[:, :-1], high - g[:, -1]
            B.set(rows + 3, w_idx, 1.0), B.set(rows + 3, t_idx, -high / u)
            B.set(rows + 4, t_idx, -1.0)
            B.c[rows + 4] = u
        socs: list[int] = []
        if norm == "L1L1":  # top >= sum |n_a|, and sum |n_a| <= gamma * depth
            signs = np.array(list(itertools.product((1.0, -1.0), repeat=m)))
            for with_gamma in ([False, True] if finite_gamma else [False]):
                B = block(len(signs) * V)
                for s_index, sign in enumerate(signs):
                    rows = len(signs) * np.arange(V) + s_index
                    combined = -np.einsum("a,vab->vb", sign, num)
                    B.v[rows], B.c[rows] = combined[:, :-1], combined[:, -1]
                    if with_gamma:
                        B.v[rows] += gamma * depth[:, :-1]
                        B.c[rows] += gamma * depth[:, -1]
                    else:
                        B.set(rows, top_idx, 1.0)
        n_lin = sum(len(b.c) for b in blocks)
        if norm == "L2L2":  # top * depth >= |n|^2: (top + depth, 2 n, top - depth) in the SOC
            B = block((m + 2) * V)
            rows = (m + 2) * np.arange(V)
            B.set(rows, top_idx, 1.0)
            B.v[rows], B.c[rows] = depth[:, :-1], depth[:, -1]
            for a in range(m):
                B.v[rows + 1 + a], B.c[rows + 1 + a] = 2 * num[:, a, :-1], 2 * num[:, a, -1]
            B.set(rows + m + 1, top_idx, 1.0)
            B.v[rows + m + 1], B.c[rows + m + 1] = -depth[:, :-1], -depth[:, -1]
            socs += [m + 2] * V
        elif norm == "L2L1":  # top >= |n|
            B = block((m + 1) * V)
            rows = (m + 1) * np.arange(V)
            B.set(rows, top_idx, 1.0)
            for a in range(m):
                B.v[rows + 1 + a], B.c[rows + 1 + a] = num[:, a, :-1], num[:, a, -1]
            socs += [m + 1] * V
        if finite_gamma and norm != "L1L1":  # every residual of a better point is below gamma
            B = block((m + 1) * V)
            rows = (m + 1) * np.arange(V)
            B.v[rows], B.c[rows] = gamma * depth[:, :-1], gamma * depth[:, -1]
            for a in range(m):
                B.v[rows + 1 + a], B.c[rows + 1 + a] = num[:, a, :-1], num[:, a, -1]
            socs += [m + 1] * V
        q = np.zeros(n)
        q[q_idx] = 1.0
        if envelope:  # r * (u w) >= t^2 (the envelope's second cone), everything divided by u
            B = block(3 * nE)
            rows = 3 * np.arange(nE)
            B.set(rows, r_idx, 1.0), B.set(rows, w_idx, 1.0 / u)
            B.set(rows + 1, t_idx, 2.0 / u)
            B.set(rows + 2, r_idx, 1.0), B.set(rows + 2, w_idx, -1.0 / u)
            socs += [3] * nE
            q[r_idx] = 1.0
        else:
            q[t_idx] = 1.0 / high
        A, c = _assemble(blocks, n)
        return q, A, c, ConeSpec(nonneg=n_lin, soc=tuple(socs))


@dataclass
class Prepared:
    """What :func:`prepare` returns when a search is needed."""

    problem: BoxProblem
    incumbent: np.ndarray
    upper: float  # the incumbent's scaled cost (inf when outside the user's bound)
    unit: float  # scaled cost = unit * cost in the caller's units


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

    no_domain: str  # nothing satisfies the domain (every depth positive)
    degenerate: str  # the data do not bound the solutions within the residual bound
    over_max_residual: str = "no solution has every residual within max_residual"
    not_certified: str = "the root region's bounds could not be computed accurately"


def prepare(program: FractionalProgram, start: np.ndarray | None, subspace: np.ndarray,
            abs_gap: float, max_residual: float | None, reasons: Reasons, tighten_rounds: int = 0) -> Prepared | Early:
    """Incumbent, scaling and root region. ``start``: an initial point (None or infeasible: one
    is searched for); ``subspace``: rows spanning the directions the depths depend on;
    ``tighten_rounds``: rounds of bound tightening on the root region (worth it when nodes are
    many and costly, as for maps; not for triangulation, whose searches take a few nodes)."""
    norm = program.norm
    if start is None or not math.isfinite(program.cost(start)):
        start = feasible_point(program)
        if start is None:
            return Early("infeasible", None, None, reasons.no_domain)
    v0, _ = local_refine(program, start, "L2L2")
    if norm != "L2L2":
        v0, _ = local_refine(program, v0)
    cost0 = program.cost(v0)
    if cost0 <= abs_gap:  # within tolerance of the trivial bound 0
        return Early("optimal", v0, cost0, None)
    # Scale residuals so the incumbent costs 1 (raw costs near 1e-5 lose accuracy), but by no more
    # than MAX_SCALE: nearly exact data would make residual rows 1e6 times the depth rows.
    factor = min(MAX_SCALE, 1.0 / math.sqrt(cost0) if norm == "L2L2" else 1.0 / cost0)
    program.rescale(factor)
    unit = factor**2 if norm == "L2L2" else factor
    upper = program.cost(v0)
    user_gamma = max_residual * factor if max_residual is not None else None
    gamma = gamma_for(upper, norm)
    if user_gamma is not None:
        if np.max(np.linalg.norm(program.residuals(v0), axis=1)) > user_gamma:
            upper = math.inf  # the incumbent lies outside the user's domain
        gamma = min(gamma, user_gamma)
    B = branch_directions(program, subspace)
    state, root = root_region(program, B, gamma)
    if root is None:
        if state == "infeasible" and math.isfinite(upper):
            state = "not_certified"  # the incumbent is inside: the solve, not the data, failed
        reason = {"degenerate": reasons.degenerate, "infeasible": reasons.over_max_residual,
                  "not_certified": reasons.not_certified}[state]
        if not math.isfinite(upper):
            return Early(state, None, None, reason)
        return Early(state, v0, upper / unit, reason)
    problem = BoxProblem(program, user_gamma, B, root)
    if tighten_rounds and math.isfinite(upper):
        problem.root = problem.tighten(root, upper, tighten_rounds)
    return Prepared(problem, v0, upper, unit)


@dataclass
class Certificate:
    """What a finished search proves: the scope, the root region the search covered (in the
    caller's coordinates: ``lower <= (F u) / (d . u) <= upper`` for the kind's unknown u), the
    tolerance and whether it was met, and the number of leaves."""

    scope: str
    reference: int  # the observation whose depth is fixed to 1
    functionals: list[list[float]]
    denominator: list[float]
    lower: list[float]
    upper: list[float]
    tolerance: float
    tolerance_met: bool
    leaves: int


@dataclass
class Searched:
    status: str
    solution: np.ndarray | None  # None: nothing within max_residual
    lower_bound: float | None  # in the caller's units
    nodes: int
    certificate: Certificate | None


def search(prepared: Prepared, options: FractionalOptions, scope: str, reference: int,
           functionals: np.ndarray, denominator: np.ndarray, callback=None) -> Searched:
    """Branch and bound from a prepared program; progress and bounds in the caller's units.
    ``functionals`` maps the caller's unknown to ``B v`` up to the ``denominator``'s scale."""
    unit = prepared.unit

    def unscaled(p: Progress):
        return callback(Progress(p.nodes, p.open_boxes, p.lower_bound / unit, p.upper_bound / unit,
                                 p.gap_abs / unit, p.gap_rel, p.elapsed_s))

    bnb = branch_and_bound(
        prepared.problem, prepared.incumbent, prepared.upper,
        BnbOptions(rel_gap=options.rel_gap, abs_gap=options.abs_gap * unit, max_nodes=options.max_nodes,
                   time_limit_s=options.time_limit_s),
        callback=unscaled if callback else None,
    )
    if not math.isfinite(bnb.upper_bound):
        return Searched("infeasible", None, None, bnb.nodes, None)
    if options.max_residual is not None:
        scope = f"{scope} with every residual <= {options.max_residual}"
    root = prepared.problem.root
    certificate = Certificate(scope, reference, np.asarray(functionals).tolist(), np.asarray(denominator).tolist(),
                              root.lo.tolist(), root.hi.tolist(), bnb.tolerance / unit,
                              bnb.upper_bound - bnb.lower_bound <= bnb.tolerance, bnb.leaves)
    return Searched(bnb.status, bnb.candidate, bnb.lower_bound / unit, bnb.nodes, certificate)

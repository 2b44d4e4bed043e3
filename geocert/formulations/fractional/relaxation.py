"""The convex relaxations of sums of ratios, as plain conic data (numpy; the solver's stacked relaxations scipy.sparse).

What the branch-and-bound search solves and what a certificate verifier rebuilds are the same
arrays, built here, so a verifier can check a solver's dual vectors without trusting its code
paths or importing any conic solver. docs/algorithms.md (section 4) states the relaxation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from geocert.core.bnb import Box
from geocert.core.cones import ConeSpec, safe_lower_bounds
from geocert.core.geometry import norm_cost, residual_lengths

# Only for the split heuristic (a relative variation): the domain is every positive depth, cut
# nowhere short of 0, so that no point of the scope is left out of a bound.
EPS_DEPTH = 1e-12
NORMS = ("L2L2", "L2L1", "L1L1")


def cost_unit(scale: float, norm: str) -> float:
    """What a program's cost is multiplied by when its residuals are multiplied by ``scale``."""
    return scale**2 if norm == "L2L2" else scale


def gamma_for(upper_bound: float, norm: str) -> float:
    """Largest single residual of any point costing at most ``upper_bound``: its 2-norm, and
    for L1L1 its 1-norm too (which bounds the 2-norm)."""
    return math.sqrt(upper_bound) if norm == "L2L2" else upper_bound


# A point is in a program's scope when every residual's 2-norm is at most max_residual. The
# solver's incumbents must satisfy it with this much to spare, so that the same point, its
# residuals recomputed from the raw data by anyone, is in scope too.
SCOPE_MARGIN = 1e-9


@dataclass
class FractionalProgram:
    num: np.ndarray  # (N, m, d + 1): numerator rows, last column constant
    den: np.ndarray  # (N, d + 1): depths; exact observations hold e_{d+1}
    exact: np.ndarray  # (N,) bool
    linear: np.ndarray  # (L, d + 1): linear(v) >= 0 on the domain
    norm: str
    # The scope: every residual's 2-norm (pixel distance, whatever the norm) at most this, in
    # the program's units; None for no limit. Scaled with the residuals.
    max_residual: float | None = None

    @property
    def dim(self) -> int:
        return self.num.shape[2] - 1

    def rescale(self, factor: float) -> None:
        self.num = self.num * factor
        if self.max_residual is not None:
            self.max_residual = self.max_residual * factor

    def __post_init__(self) -> None:
        self._linear_slack = 1e-12 * np.linalg.norm(self.linear, axis=1)  # round-off allowed

    def cost(self, v: np.ndarray) -> float:
        V = np.concatenate((v, (1.0,)))
        g = self.den @ V
        if (g <= 0).any():
            return math.inf
        if len(self.linear):
            linear = self.linear @ V
            if (linear < 0).any() and (linear < -self._linear_slack * np.linalg.norm(V)).any():
                return math.inf
        residuals = (self.num @ V) / g[:, None]
        if self.max_residual is not None and not self.in_scope(residuals):
            return math.inf
        return norm_cost(residuals, self.norm)

    def in_scope(self, residuals: np.ndarray) -> bool:
        """Every residual within max_residual, with SCOPE_MARGIN to spare (see there)."""
        return self.max_residual is None or bool(
            np.all(residual_lengths(residuals) <= self.max_residual * (1 - SCOPE_MARGIN)))

    def residuals(self, v: np.ndarray) -> np.ndarray:
        V = np.concatenate((v, (1.0,)))
        return (self.num @ V) / (self.den @ V)[:, None]

    def residual_jacobian(self, v: np.ndarray) -> np.ndarray:
        """(N, m, d): derivative of each residual coordinate."""
        V = np.concatenate((v, (1.0,)))
        n, g = self.num @ V, self.den @ V
        d = self.dim
        return self.num[:, :, :d] / g[:, None, None] - n[:, :, None] * self.den[:, None, :d] / (g**2)[:, None, None]


def residual_region(program: FractionalProgram, gamma: float) -> tuple[np.ndarray, np.ndarray, ConeSpec]:
    """Conic data (A, b, cones) of {v : ||residual_i(v)|| <= gamma for all i, linear(v) >= 0}.

    ``||n_i|| <= gamma * g_i`` also gives positive depths.
    """
    m = program.num.shape[1]
    # Each row: coefficients of v, then the constant. Per observation: gamma * depth, numerator.
    per_observation = np.concatenate((gamma * program.den[:, None, :], program.num), axis=1)
    E = np.concatenate((program.linear, per_observation.reshape(-1, program.num.shape[2])))
    cones = ConeSpec(nonneg=len(program.linear), soc=(m + 1,) * len(program.num))
    return -E[:, :-1], E[:, -1].copy(), cones


def root_bounds(region: tuple[np.ndarray, np.ndarray, ConeSpec], F: np.ndarray, duals: list[np.ndarray],
                claim_lo: np.ndarray, claim_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Safe lower and upper bounds on ``F v`` over a residual region (A, b, cones), from dual
    vectors (index 2j for ``min F_j v``, 2j + 1 for ``max F_j v``) with their residuals charged to
    the claimed box on ``y = F v``: what a root proof claims and what its verifier recomputes.

    Each bound is cones.safe_lower_bound's, for all 2d vectors at once (cones.safe_lower_bounds:
    one projection and one matrix product instead of 2d of each, a fifth of the time on a track)."""
    A, b, cones = region
    objectives = np.empty((2 * len(F), F.shape[1]))
    objectives[0::2], objectives[1::2] = F, -F
    bounds = safe_lower_bounds(objectives, A, b, cones, np.array([np.asarray(z, dtype=float) for z in duals]),
                               claim_lo, claim_hi, np.linalg.inv(F))  # residuals charged to y = F v
    return bounds[0::2], -bounds[1::2]


_DENSE_LIMIT = 200_000  # relaxations with fewer matrix entries are assembled dense


class _Rows:
    """``count`` groups of ``per`` rows ``c + E x``, one group per observation (or a single group
    of rows that belong to none). E's columns over the d unknowns are held dense, (count, per, d);
    its per-observation columns as entries ``(slot, columns, values)``: row ``slot`` of group i
    has ``values[i]`` in column ``columns[i]``. Assembly stays linear in size and, for small
    problems, a handful of array operations."""

    def __init__(self, count: int, per: int, d: int):
        self.v = np.zeros((count, per, d))
        self.c = np.zeros((count, per))
        self.entries: list[tuple[int, np.ndarray, np.ndarray | float]] = []

    def set(self, slot: int, columns: np.ndarray, values) -> None:
        self.entries.append((slot, columns, values))


def _assemble(blocks: list[_Rows], n: int):
    """A = -E for Clarabel (dense when small, CSC otherwise) and the constants b = c."""
    d = blocks[0].v.shape[2]
    total = sum(b.c.size for b in blocks)
    c = np.concatenate([b.c.ravel() for b in blocks])
    if total * n <= _DENSE_LIMIT:
        E = np.zeros((total, n))
        start = 0
        for b in blocks:
            count, per = b.c.shape
            group = E[start:start + count * per].reshape(count, per, n)  # a view of E's rows
            group[:, :, :d] = b.v
            every = np.arange(count)
            for slot, columns, values in b.entries:
                group[every, slot, columns] = values
            start += count * per
        return -E, c
    rows, cols, vals = [], [], []
    start = 0
    for b in blocks:
        count, per = b.c.shape
        dense = b.v.reshape(count * per, d)
        vr, vc = np.nonzero(dense)
        rows.append(start + vr), cols.append(vc), vals.append(dense[vr, vc])
        first = start + per * np.arange(count)
        for slot, columns, values in b.entries:
            rows.append(first + slot), cols.append(columns), vals.append(np.broadcast_to(values, (count,)))
        start += count * per
    import scipy.sparse as sp  # the solver's stacked relaxations only: the verifier's are dense (numpy alone)

    E = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(total, n))
    return (-E).tocsc(), c


@dataclass
class ConicData:
    """``min q'x`` s.t. ``A x + s = b``, ``s`` in ``cones``; every point of the domain costing at
    most the upper bound the data were built with lifts to a feasible x within ``lower``,
    ``upper``, where the first d entries bound ``y = F v`` (``v = transform @ y``)."""

    q: np.ndarray
    A: np.ndarray  # or a scipy.sparse.csc_matrix (the solver's stacked relaxations: _assemble)
    b: np.ndarray
    cones: ConeSpec
    lower: np.ndarray
    upper: np.ndarray
    transform: np.ndarray


def complete_functionals(B: np.ndarray) -> np.ndarray:
    """B's rows followed by an orthonormal basis of the complement of their span: a square,
    invertible F, so that a box on ``F v`` bounds every variable."""
    d = B.shape[1]
    if len(B) == d:
        return B
    _, _, vt = np.linalg.svd(B)
    return np.vstack([B, vt[len(B):d]])


class Relaxation:
    """The relaxations of a fractional program over boxes of branching functionals ``z = B v``.

    ``complement``: proven bounds on the remaining functionals ``F v`` (rows of F past B's),
    known after the root region's proof (which also fixes F); without them the variable bounds
    of v are infinite.
    """

    def __init__(self, program: FractionalProgram, B: np.ndarray,
                 complement: tuple[np.ndarray, np.ndarray] | None = None, F: np.ndarray | None = None,
                 quadratic: bool = False):
        self.program = program
        # L2L2 only: each term above the convex envelope of |n|^2 / s^2 on its depth interval
        # instead of the envelope of t / s (see relaxation()). A proof says which it used.
        self.quadratic = quadratic and program.norm == "L2L2"
        self.norm = program.norm
        self.B = B
        self.F = complete_functionals(B) if F is None else F  # F's first rows are B's
        self.transform = np.linalg.inv(self.F)
        extra = len(self.F) - len(B)
        self.complement = complement or (np.full(extra, -np.inf), np.full(extra, np.inf))
        self.env = np.flatnonzero(~program.exact)  # observations bounded by the envelope
        self.exact = np.flatnonzero(program.exact)
        # Depth of envelope observation j on the whole of y = F v: exact, since F is invertible.
        depth_y = program.den[self.env, :-1] @ self.transform
        self.coef = depth_y[:, :len(B)]
        self.coef_complement = depth_y[:, len(B):]
        self.offset = program.den[self.env, -1]
        # Per observation (program order), a proven lower bound on the sum of the other terms
        # over the points the relaxations are asked about (None: 0 for all); see relaxation().
        self.others: np.ndarray | None = None

    def term_variables(self, observations: np.ndarray) -> np.ndarray:
        """The index, in the relaxation's variables (with the envelope), of the variable whose
        sum is the objective: each observation's ``r`` (envelope) or epigraph (exact)."""
        d, nE = self.program.dim, len(self.env)
        position = np.empty(len(self.program.den), dtype=int)
        position[self.env] = d + 2 * nE + np.arange(nE)
        position[self.exact] = d + 3 * nE + np.arange(len(self.exact))
        return position[observations]

    def gammas(self, upper_bound: float) -> tuple[float, float]:
        """(cost_gamma, scope_gamma): every residual of a point of the scope costing at most
        ``upper_bound`` has norm at most cost_gamma (the 1-norm for L1L1, the 2-norm otherwise)
        and 2-norm at most scope_gamma (max_residual; inf without one)."""
        cost_gamma = gamma_for(upper_bound, self.norm) if math.isfinite(upper_bound) else math.inf
        scope = self.program.max_residual
        return cost_gamma, (scope if scope is not None else math.inf)

    def y_bounds(self, box: Box) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate([box.lo, self.complement[0]]), np.concatenate([box.hi, self.complement[1]])

    def depth_range(self, box: Box) -> tuple[np.ndarray, np.ndarray]:
        """Each envelope depth's range over the box. B spans the depths' gradients, so the
        complement's coefficients are round-off; they are counted once their bounds are proven."""
        ranges = [(self.coef, box.lo, box.hi)]
        if self.coef_complement.size and np.all(np.isfinite(self.complement)):
            ranges.append((self.coef_complement, *self.complement))
        low, high = self.offset.copy(), self.offset.copy()
        size = np.abs(self.offset)
        for coef, lo, hi in ranges:
            pos, neg = np.clip(coef, 0, None), np.clip(coef, None, 0)
            low += pos @ lo + neg @ hi
            high += pos @ hi + neg @ lo
            size = size + np.abs(coef) @ np.maximum(np.abs(lo), np.abs(hi))
        # Rounded outwards: the sums above round, and a range must hold every true depth.
        return low - 1e-12 * size, high + 1e-12 * size

    def conic_data(self, box: Box, upper_bound: float, envelope: bool = True) -> ConicData | None:
        """The relaxation on ``box`` for points costing at most ``upper_bound``, or None when
        some depth is at most 0 on the whole box (no point of the domain is in it). A depth
        range reaching down to 0 keeps 0 as its lower end: the envelope of t/s stays valid there
        (w = s t / u and r = t / s lift every point with s > 0)."""
        low, high = self.depth_range(box)
        if np.any(high <= 0):
            return None
        low = np.maximum(low, 0.0)
        high = np.maximum(high, low * (1 + 1e-9) + 1e-15)
        return self.relaxation(box, low, high, *self.gammas(upper_bound), upper_bound, envelope)

    def relaxation(self, box: Box, low: np.ndarray, high: np.ndarray, cost_gamma: float, scope_gamma: float,
                   upper_bound: float, envelope: bool = True) -> ConicData:
        """``min sum r`` over the box in Clarabel's form (docs/algorithms.md, section 4).

        Rows are expressions ``c + E x`` that must lie in the cone (Clarabel wants ``b - A x``,
        so ``A = -E``). Variables: v (d), then t, w, r per envelope observation, then one
        epigraph variable per exact observation, then (L1L1) one ``a >= |n_a|`` per residual
        coordinate of every observation (linear in the dimension, no sign enumeration). Blocks are filled for all observations at once,
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
        V = nE + nX
        n_abs = m * V if norm == "L1L1" else 0
        n = d + per_env * nE + nX + n_abs
        t_idx = d + np.arange(nE)
        w_idx, r_idx = t_idx + nE, t_idx + 2 * nE
        q_idx = d + per_env * nE + np.arange(nX)
        a_idx = (d + per_env * nE + nX + np.arange(n_abs)).reshape(V, m if n_abs else 0)
        obs = np.concatenate([env, exact])
        # Each observation's largest cost term (its t / s) and the 2-norm bound on its residual.
        # A point costing at most upper_bound has each term within upper_bound less what the
        # other terms cost at least (self.others: proven lower bounds, 0 when unknown).
        cost_gamma = np.full(V, cost_gamma)
        if self.others is not None and math.isfinite(upper_bound):
            budget = np.maximum(upper_bound - self.others[obs], 0.0)
            cost_gamma = np.minimum(cost_gamma, np.sqrt(budget) if norm == "L2L2" else budget)
        if norm == "L2L2":
            gamma = np.minimum(cost_gamma, scope_gamma)
            term = gamma**2
        elif norm == "L2L1":
            gamma = term = np.minimum(cost_gamma, scope_gamma)
        else:  # the term is the 1-norm: at most cost_gamma, and sqrt(m) times the 2-norm
            gamma = np.full(V, scope_gamma)
            term = np.minimum(cost_gamma, math.sqrt(m) * scope_gamma)
        u = np.where(np.isfinite(term[:nE]), term[:nE] * high, 1e12 * high)
        top_idx = np.concatenate([t_idx, q_idx])  # the variable above each observation's numerator
        depth = program.den[obs]
        num = program.num[obs]  # (V, m, d + 1)
        blocks: list[_Rows] = []

        def block(count: int, per: int) -> _Rows:
            blocks.append(_Rows(count, per, d))
            return blocks[-1]

        k = len(self.B)
        L = len(program.linear)
        B = block(1, 2 * k + L)  # the box on z = B v, and the domain's linear constraints
        B.v[0, :k], B.c[0, :k] = self.B, -box.lo
        B.v[0, k:2 * k], B.c[0, k:2 * k] = -self.B, box.hi
        B.v[0, 2 * k:], B.c[0, 2 * k:] = program.linear[:, :-1], program.linear[:, -1]
        if envelope:  # envelope of t/s on [0, u] x [L, U], first cone vacuous since l = 0 (5 rows each)
            B = block(nE, 5)
            g = program.den[env]
            B.set(0, w_idx, 1.0), B.set(0, t_idx, -low / u)
            B.set(1, t_idx, high / u), B.set(1, w_idx, -1.0)
            B.v[:, 2], B.c[:, 2] = g[:, :-1], g[:, -1] - low
            B.set(2, w_idx, -1.0), B.set(2, t_idx, low / u)
            B.v[:, 3], B.c[:, 3] = -g[:, :-1], high - g[:, -1]
            B.set(3, w_idx, 1.0), B.set(3, t_idx, -high / u)
            B.set(4, t_idx, -1.0)
            B.c[:, 4] = u
        socs: list[int] = []
        if norm == "L1L1":  # a_a >= |n_a|, top >= sum a_a, and sum a_a <= cost_gamma * depth
            finite_cost = bool(np.all(np.isfinite(cost_gamma)))
            B = block(V, 2 * m + 1 + finite_cost)
            for a in range(m):
                B.v[:, 2 * a], B.c[:, 2 * a] = -num[:, a, :-1], -num[:, a, -1]
                B.set(2 * a, a_idx[:, a], 1.0)
                B.v[:, 2 * a + 1], B.c[:, 2 * a + 1] = num[:, a, :-1], num[:, a, -1]
                B.set(2 * a + 1, a_idx[:, a], 1.0)
                B.set(2 * m, a_idx[:, a], -1.0)
                if finite_cost:
                    B.set(2 * m + 1, a_idx[:, a], -1.0)
            B.set(2 * m, top_idx, 1.0)
            if finite_cost:
                B.v[:, 2 * m + 1], B.c[:, 2 * m + 1] = cost_gamma[:, None] * depth[:, :-1], cost_gamma * depth[:, -1]
        n_lin = sum(b.c.size for b in blocks)
        if norm == "L2L2":  # top * depth >= |n|^2: (top + depth, 2 n, top - depth) in the SOC
            B = block(V, m + 2)
            B.set(0, top_idx, 1.0)
            B.v[:, 0], B.c[:, 0] = depth[:, :-1], depth[:, -1]
            B.v[:, 1:m + 1], B.c[:, 1:m + 1] = 2 * num[:, :, :-1], 2 * num[:, :, -1]
            B.set(m + 1, top_idx, 1.0)
            B.v[:, m + 1], B.c[:, m + 1] = -depth[:, :-1], -depth[:, -1]
            socs += [m + 2] * V
        elif norm == "L2L1":  # top >= |n|
            B = block(V, m + 1)
            B.set(0, top_idx, 1.0)
            B.v[:, 1:], B.c[:, 1:] = num[:, :, :-1], num[:, :, -1]
            socs += [m + 1] * V
        if np.all(np.isfinite(gamma)):  # every residual's 2-norm (of a better point, or in scope) within gamma
            B = block(V, m + 1)
            B.v[:, 0], B.c[:, 0] = gamma[:, None] * depth[:, :-1], gamma * depth[:, -1]
            B.v[:, 1:], B.c[:, 1:] = num[:, :, :-1], num[:, :, -1]
            socs += [m + 1] * V
        q = np.zeros(n)
        q[q_idx] = 1.0
        quadratic = envelope and self.quadratic and nE > 0
        if envelope and not quadratic:  # r * (u w) >= t^2 (the envelope's second cone), everything divided by u
            B = block(nE, 3)
            B.set(0, r_idx, 1.0), B.set(0, w_idx, 1.0 / u)
            B.set(1, t_idx, 2.0 / u)
            B.set(2, r_idx, 1.0), B.set(2, w_idx, -1.0 / u)
            socs += [3] * nE
        if envelope:
            q[r_idx] = 1.0
            if quadratic:
                # r >= |n|^2 / (s (L + U) - L U), the convex envelope of |n|^2 / s^2 over s in
                # [L, U] (a point between the faces s = L and s = U mixes one of each; the cheapest
                # mix gives this), valid since s (L + U) - L U >= s^2 there. It replaces the cone
                # over the envelope of t / s (Dinosaur camera 14, 533 points: the root's gap 3.6e-2 becomes
                # 1.6e-3); with both cones on r, Clarabel stalls near a 1e-6 gap. t, w and their rows
                # stay, though r no longer reads them: without them (measured) the solves
                # were 7% faster with the same nodes, but the relaxation's minimisers moved onto the
                # scope's edge, and a search whose start is out of scope (max_residual a hair above
                # the least possible, test_certificates' TestNodeTighteningHostile) found no
                # incumbent in 5,000 nodes where it now certifies in 51.
                g = program.den[env]
                B = block(nE, m + 2)
                B.set(0, r_idx, 1.0)
                B.v[:, 0] = (low + high)[:, None] * g[:, :-1]
                B.c[:, 0] = (low + high) * g[:, -1] - low * high
                B.v[:, 1:m + 1], B.c[:, 1:m + 1] = 2 * num[:nE, :, :-1], 2 * num[:nE, :, -1]
                B.set(m + 1, r_idx, 1.0)
                B.v[:, m + 1] = -(low + high)[:, None] * g[:, :-1]
                B.c[:, m + 1] = -((low + high) * g[:, -1] - low * high)
                socs += [m + 2] * nE
        else:
            q[t_idx] = 1.0 / high
        A, c = _assemble(blocks, n)
        # Where the lift of a point costing at most upper_bound lies: t = s * term <= min(u, high * ub)
        # (its smallest feasible value), w = s t / u in [0, high], r = term <= ub, epigraphs <= ub.
        # r and the epigraphs are one observation's term: at most the upper bound and ``term``
        # (finite whenever either is, so that every variable is bounded in a safe bound).
        top = np.minimum(upper_bound, term)  # each observation's term
        lower, upper = np.zeros(n), np.full(n, float(np.max(top)))
        lower[:d], upper[:d] = self.y_bounds(box)
        upper[t_idx] = np.minimum(u, high * upper_bound)
        upper[q_idx] = top[nE:]
        if envelope:
            upper[w_idx] = high
            upper[r_idx] = top[:nE]
        if n_abs:  # a_a <= sum a = the observation's top variable, at the smallest lift
            upper[a_idx] = upper[top_idx][:, None]
        return ConicData(q, A, c, ConeSpec(nonneg=n_lin, soc=tuple(socs)), lower, upper, self.transform)




def with_cost_cap(data: ConicData, upper_bound: float) -> ConicData:
    """The same relaxation with ``q'x <= upper_bound`` as one more (first) nonnegative row: the
    feasible set of bound tightening. (Relaxations have no equality rows to keep ahead of it.)"""
    assert data.cones.zero == 0
    if hasattr(data.A, "tocsc"):  # scipy.sparse (only a solver's data are: _assemble), so scipy is loaded already
        import scipy.sparse as sp

        A = sp.vstack([sp.csr_matrix(data.q[None, :]), data.A]).tocsc()
    else:
        A = np.vstack([data.q[None, :], data.A])
    return ConicData(data.q, A, np.concatenate([[upper_bound], data.b]),
                     ConeSpec(zero=data.cones.zero, nonneg=data.cones.nonneg + 1, soc=data.cones.soc),
                     data.lower, data.upper, data.transform)


def tightening_objective(data: ConicData, functional: np.ndarray, sign: float) -> np.ndarray:
    """``sign * functional . v`` as a linear objective over the relaxation's variables."""
    objective = np.zeros(len(data.q))
    objective[:len(functional)] = sign * functional
    return objective

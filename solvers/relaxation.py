"""The convex relaxations of sums of ratios, as plain conic data (numpy and scipy.sparse only).

What the branch-and-bound search solves and what a certificate verifier rebuilds are the same
arrays, built here, so a verifier can check a solver's dual vectors without trusting its code
paths or importing any conic solver. ALGORITHMS.md section 2 states the relaxation.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .bnb import Box
from .cones import ConeSpec
from .geometry import norm_cost

EPS_DEPTH = 1e-12  # depths below this (in the program's units) are outside the domain
NORMS = ("L2L2", "L2L1", "L1L1")


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
        V = np.concatenate((v, (1.0,)))
        g = self.den @ V
        if (g <= 0).any():
            return math.inf
        if len(self.linear):
            linear = self.linear @ V
            if (linear < 0).any() and (linear < -self._linear_slack * np.linalg.norm(V)).any():
                return math.inf
        return norm_cost((self.num @ V) / g[:, None], self.norm)

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
    rows = list(program.linear)
    for i in range(len(program.num)):
        rows.append(gamma * program.den[i])
        rows.extend(program.num[i])
    E = np.array(rows)  # each row: coefficients of v, then the constant
    cones = ConeSpec(nonneg=len(program.linear), soc=(m + 1,) * len(program.num))
    return -E[:, :-1], E[:, -1].copy(), cones


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


@dataclass
class ConicData:
    """``min q'x`` s.t. ``A x + s = b``, ``s`` in ``cones``; every point of the domain costing at
    most the upper bound the data were built with lifts to a feasible x within ``lower``,
    ``upper``, where the first d entries bound ``y = F v`` (``v = transform @ y``)."""

    q: np.ndarray
    A: np.ndarray | sp.csc_matrix
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

    def __init__(self, program: FractionalProgram, B: np.ndarray, user_gamma: float | None = None,
                 complement: tuple[np.ndarray, np.ndarray] | None = None, F: np.ndarray | None = None):
        self.program = program
        self.norm = program.norm
        self.B = B
        self.user_gamma = user_gamma
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

    def gamma(self, upper_bound: float) -> float:
        gamma = gamma_for(upper_bound, self.norm) if math.isfinite(upper_bound) else math.inf
        return min(gamma, self.user_gamma) if self.user_gamma is not None else gamma

    def y_bounds(self, box: Box) -> tuple[np.ndarray, np.ndarray]:
        return np.concatenate([box.lo, self.complement[0]]), np.concatenate([box.hi, self.complement[1]])

    def depth_range(self, box: Box) -> tuple[np.ndarray, np.ndarray]:
        """Each envelope depth's range over the box. B spans the depths' gradients, so the
        complement's coefficients are round-off; they are counted once their bounds are proven."""
        ranges = [(self.coef, box.lo, box.hi)]
        if self.coef_complement.size and np.all(np.isfinite(self.complement)):
            ranges.append((self.coef_complement, *self.complement))
        low, high = self.offset.copy(), self.offset.copy()
        for coef, lo, hi in ranges:
            pos, neg = np.clip(coef, 0, None), np.clip(coef, None, 0)
            low += pos @ lo + neg @ hi
            high += pos @ hi + neg @ lo
        return low, high

    def conic_data(self, box: Box, upper_bound: float, envelope: bool = True) -> ConicData | None:
        """The relaxation on ``box`` for points costing at most ``upper_bound``, or None when
        some depth is below EPS_DEPTH on the whole box (no point of the domain is in it)."""
        low, high = self.depth_range(box)
        if np.any(high <= EPS_DEPTH):
            return None
        low = np.maximum(low, EPS_DEPTH)
        high = np.maximum(high, low * (1 + 1e-9) + 1e-15)
        return self.relaxation(box, low, high, self.gamma(upper_bound), upper_bound, envelope)

    def relaxation(self, box: Box, low: np.ndarray, high: np.ndarray, gamma: float, upper_bound: float,
                   envelope: bool = True) -> ConicData:
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
        # Where the lift of a point costing at most upper_bound lies: t = s * term <= min(u, high * ub)
        # (its smallest feasible value), w = s t / u in [0, high], r = term <= ub, epigraphs <= ub.
        lower, upper = np.zeros(n), np.full(n, upper_bound)
        lower[:d], upper[:d] = self.y_bounds(box)
        upper[t_idx] = np.minimum(u, high * upper_bound)
        if envelope:
            upper[w_idx] = high
        return ConicData(q, A, c, ConeSpec(nonneg=n_lin, soc=tuple(socs)), lower, upper, self.transform)




def with_cost_cap(data: ConicData, upper_bound: float) -> ConicData:
    """The same relaxation with ``q'x <= upper_bound`` as one more (first) nonnegative row: the
    feasible set of bound tightening. (Relaxations have no equality rows to keep ahead of it.)"""
    assert data.cones.zero == 0
    A = sp.vstack([sp.csr_matrix(data.q[None, :]), data.A]).tocsc() if sp.issparse(data.A) else np.vstack([data.q[None, :], data.A])
    return ConicData(data.q, A, np.concatenate([[upper_bound], data.b]),
                     ConeSpec(zero=data.cones.zero, nonneg=data.cones.nonneg + 1, soc=data.cones.soc),
                     data.lower, data.upper, data.transform)


def tightening_objective(data: ConicData, functional: np.ndarray, sign: float) -> np.ndarray:
    """``sign * functional . v`` as a linear objective over the relaxation's variables."""
    objective = np.zeros(len(data.q))
    objective[:len(functional)] = sign * functional
    return objective

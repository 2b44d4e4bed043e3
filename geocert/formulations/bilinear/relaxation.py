"""The convex relaxation of one frame's bilinear program over a box of the camera's 2x3 part M
(thesis 8.3): plain numpy, used alike by the solver and the verifier; its constraint matrix is
scipy's CSC for the solver's conic solver, or core.csc's (numpy alone) for the verifier.

Variables, in order: gamma (6K, gamma_rki = M_rk alpha_i), alpha (K), M (6), t (2), then the
epigraph: e (2n, one per residual coordinate) for L1L1 or s (1) for L2L2. Rows (Clarabel's
``A x + s = b``): sum alpha = 1 and, for each (r, k), sum_i gamma_rki = M_rk (exact because the
coefficients sum to 1: an RLT cut that costs nothing); McCormick's four inequalities per gamma
(thesis 8.4/8.5); the box rows of M and alpha; then the cost: L1L1 as -e <= residual <= e (an
LP, 8.6/8.7), L2L2 as one second-order cone ||residual|| <= s (8.9). The cost is sum e, or s^2.

Every bound is the safe bound of a dual vector (core.cones.safe_lower_bound) over the variables'
bounds, which hold for every point of the box costing at most ``cap`` (the incumbent's cost): t
from each observation's residual (at most cap, or sqrt(cap)), the epigraph in [0, cap] (or
[0, sqrt(cap)]), gamma from the corners of its rectangle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from geocert.core.cones import UNIT_ROUNDOFF, ConeSpec, safe_lower_bound
from geocert.core.csc import CscMatrix

if TYPE_CHECKING:  # imported where a scipy matrix is built: the verifier loads numpy alone
    import scipy.sparse as sp

PAD = 1e-9  # relative widening of the translation's derived interval (outward rounding)


@dataclass
class ConicData:
    q: np.ndarray
    A: sp.csc_matrix
    b: np.ndarray
    cones: ConeSpec
    lower: np.ndarray
    upper: np.ndarray


def mccormick_rows(l: np.ndarray, u: np.ndarray, L, U) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """McCormick's envelopes of g = m a for m in [l, u], a in [L, U] as four rows each
    ``c_a a + c_m m + c_g g <= rhs``: returns (c_a, c_m, c_g, rhs), each (..., 4)."""
    l, u = np.asarray(l, float), np.asarray(u, float)
    one = np.ones_like(l)
    c_a = np.stack([l, u, -u, -l], axis=-1)
    L, U = L * one, U * one
    c_m = np.stack([L, U, -L, -U], axis=-1)
    c_g = np.stack([-one, -one, one, one], axis=-1)
    rhs = np.stack([l * L, u * U, -u * L, -l * U], axis=-1)
    return c_a, c_m, c_g, rhs


def product_range(l: np.ndarray, u: np.ndarray, L, U) -> tuple[np.ndarray, np.ndarray]:
    corners = np.stack([l * L, l * U, u * L, u * U])
    return corners.min(axis=0), corners.max(axis=0)


class Relaxation:
    """One frame's relaxation, its sparsity pattern assembled once: per box only the McCormick
    coefficients, the box rows' right-hand sides and the variables' bounds change."""

    def __init__(self, X: np.ndarray, u: np.ndarray, norm: str, coefficients: str, coefficient_bound: float,
                 matrix: type | None = None):
        """``matrix``: the class of the constraint matrices built, called as scipy's csc_matrix
        is; scipy's by default (the conic solver's), core.csc.CscMatrix for the verifier."""
        self.X, self.u, self.norm = np.asarray(X, float), np.asarray(u, float), norm
        K, n, _ = self.X.shape
        self.K, self.n = K, n
        self.alpha_range = (0.0, 1.0) if coefficients == "convex" else (-float(coefficient_bound),
                                                                         float(coefficient_bound))
        L, U = self.alpha_range
        l1 = norm == "L1L1"
        self.ig, self.ia, self.im, self.it = 0, 6 * K, 7 * K, 7 * K + 6
        self.ie = 7 * K + 8
        self.nvar = self.ie + (2 * n if l1 else 1)
        rows, cols, vals = [], [], []

        def add(r, c, v):
            r, c, v = np.broadcast_arrays(np.asarray(r), np.asarray(c), np.asarray(v, float))
            rows.append(r.ravel()), cols.append(c.ravel()), vals.append(v.ravel())

        i = np.arange(K)
        rk = np.arange(6)
        # zero cone: sum alpha = 1; sum_i gamma_rki - M_rk = 0
        add(0, self.ia + i, 1.0)
        add(1 + rk[:, None], self.ig + rk[:, None] * K + i[None, :], 1.0)
        add(1 + rk, self.im + rk, -1.0)
        b = [np.array([1.0]), np.zeros(6)]
        self.zero = 7
        # McCormick: 4 rows per gamma p = rk * K + i; coefficients filled per box
        start = 7
        p = np.arange(6 * K)
        row4 = start + 4 * p[:, None] + np.arange(4)[None, :]
        self._mc_start = sum(len(v) for v in vals)
        add(row4, (self.ia + p % K)[:, None], 0.0)  # c_a
        add(row4, (self.im + p // K)[:, None], 0.0)  # c_m
        add(row4, (self.ig + p)[:, None], 0.0)  # c_g
        self._mc_stop = sum(len(v) for v in vals)
        b.append(np.zeros(24 * K))
        # box rows: M <= hi, -M <= -lo; alpha <= U, -alpha <= -L
        self._box_row = start + 24 * K
        add(self._box_row + 2 * rk, self.im + rk, 1.0)
        add(self._box_row + 2 * rk + 1, self.im + rk, -1.0)
        b.append(np.zeros(12))
        arow = self._box_row + 12
        add(arow + 2 * i, self.ia + i, 1.0)
        add(arow + 2 * i + 1, self.ia + i, -1.0)
        b.append(np.ravel(np.column_stack([np.full(K, U), np.full(K, -L)])))
        rrow = arow + 2 * K
        nonneg = rrow - self.zero
        # the prediction of observation (j, r): sum_{k,i} X^i_jk gamma_rki + t_r
        j = np.arange(n)
        gcols = self.ig + (3 * np.arange(2)[:, None, None] + np.arange(3)[None, :, None]) * K + i[None, None, :]
        gvals = np.transpose(self.X, (1, 2, 0))  # (n, 3, K): X^i_jk at [j, k, i]
        obs = 2 * j[:, None] + np.arange(2)[None, :]  # (n, 2) observation index
        u_flat = self.u.ravel()
        if l1:
            for sign, offset in ((1.0, 0), (-1.0, 1)):
                orow = rrow + 2 * obs + offset  # (n, 2)
                add(orow[:, :, None, None], gcols[None, :, :, :], sign * gvals[:, None, :, :])
                add(orow, self.it + np.arange(2)[None, :], sign)
                add(orow, self.ie + obs, -1.0)
            b.append(np.ravel(np.column_stack([u_flat, -u_flat])))
            nonneg += 4 * n
            self.cones = ConeSpec(zero=self.zero, nonneg=nonneg)
        else:
            add(rrow, self.ie, -1.0)
            orow = rrow + 1 + obs
            add(orow[:, :, None, None], gcols[None, :, :, :], gvals[:, None, :, :])
            add(orow, self.it + np.arange(2)[None, :], 1.0)
            b.append(np.concatenate([[0.0], u_flat]))
            self.cones = ConeSpec(zero=self.zero, nonneg=nonneg, soc=(1 + 2 * n,))
        self.b0 = np.concatenate(b)
        rows, cols, vals = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
        self.nrow = len(self.b0)
        assert self.nrow == self.cones.rows
        pattern, self._perm = CscMatrix.from_triplets(rows, cols, (self.nrow, self.nvar))
        self._indices, self._indptr = pattern.indices, pattern.indptr
        self._vals = vals
        if matrix is None:
            import scipy.sparse as sp

            matrix = sp.csc_matrix
        self._matrix = matrix
        self.q = np.zeros(self.nvar)
        if l1:
            self.q[self.ie:] = 1.0
        else:
            self.q[self.ie] = 1.0
        # per observation, the range of each coordinate of the shape over the coefficient set
        if coefficients == "convex":
            self.shape_lo, self.shape_hi = self.X.min(axis=0), self.X.max(axis=0)  # (n, 3)
        else:  # |sum alpha_i x_i| <= B sum |x_i|
            reach = float(coefficient_bound) * np.abs(self.X).sum(axis=0)
            self.shape_lo, self.shape_hi = -reach, reach

    # --- per box ------------------------------------------------------------------------------
    def residual_bound(self, cap: float) -> float:
        """How large one residual coordinate of a point costing at most ``cap`` can be."""
        return cap if self.norm == "L1L1" else math.sqrt(cap) * (1 + PAD)

    def translation_range(self, lo: np.ndarray, hi: np.ndarray, cap: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Bounds on t holding for every point with M in [lo, hi] costing at most ``cap`` (each
        observation alone bounds t: |u_jr - M_r S_j - t_r| <= g); None when they are
        incompatible, i.e. no such point exists."""
        g = self.residual_bound(cap)
        tlo, thi = np.empty(2), np.empty(2)
        for r in range(2):
            l, h = lo[3 * r:3 * r + 3], hi[3 * r:3 * r + 3]
            corners = np.stack([l * self.shape_lo, l * self.shape_hi, h * self.shape_lo, h * self.shape_hi])
            plo, phi = corners.min(axis=0).sum(axis=1), corners.max(axis=0).sum(axis=1)  # (n,)
            a = self.u[:, r] - phi - g
            c = self.u[:, r] - plo + g
            a, c = a - PAD * (1 + np.abs(a)), c + PAD * (1 + np.abs(c))
            tlo[r], thi[r] = float(np.max(a)), float(np.min(c))
        if not np.all(tlo <= thi):
            return None
        return tlo, thi

    def conic_data(self, lo: np.ndarray, hi: np.ndarray, cap: float, alpha_lo: np.ndarray | None = None,
                   alpha_hi: np.ndarray | None = None) -> ConicData | None:
        """The relaxation on the box (M in [lo, hi], alpha in [alpha_lo, alpha_hi]: by default the
        coefficient set's range), for points costing at most ``cap``; None when the box holds no
        such point (the translation's range is empty)."""
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        t = self.translation_range(lo, hi, cap)
        if t is None:
            return None
        K = self.K
        L = np.full(K, self.alpha_range[0]) if alpha_lo is None else np.asarray(alpha_lo, float)
        U = np.full(K, self.alpha_range[1]) if alpha_hi is None else np.asarray(alpha_hi, float)
        l, u = np.repeat(lo, K), np.repeat(hi, K)  # per gamma p = rk * K + i
        L, U = np.tile(L, 6), np.tile(U, 6)
        c_a, c_m, c_g, rhs = mccormick_rows(l, u, L, U)
        vals = self._vals.copy()
        n_mc = 24 * K
        vals[self._mc_start:self._mc_start + n_mc] = c_a.ravel()
        vals[self._mc_start + n_mc:self._mc_start + 2 * n_mc] = c_m.ravel()
        vals[self._mc_start + 2 * n_mc:self._mc_stop] = c_g.ravel()
        A = self._matrix((vals[self._perm], self._indices.copy(), self._indptr.copy()), shape=(self.nrow, self.nvar))
        b = self.b0.copy()
        b[7:7 + n_mc] = rhs.ravel()
        b[self._box_row:self._box_row + 12] = np.ravel(np.column_stack([hi, -lo]))
        b[self._box_row + 12:self._box_row + 12 + 2 * K] = np.ravel(np.column_stack([U[:K], -L[:K]]))
        glo, ghi = product_range(l, u, L, U)
        g = self.residual_bound(cap)
        e_hi = cap if self.norm == "L1L1" else g
        lower = np.concatenate([glo, L[:K], lo, t[0], np.zeros(self.nvar - self.ie)])
        upper = np.concatenate([ghi, U[:K], hi, t[1], np.full(self.nvar - self.ie, e_hi)])
        return ConicData(self.q, A, b, self.cones, lower, upper)

    def bound(self, data: ConicData, z: np.ndarray) -> float:
        """The safe lower bound on the cost (normalised units) a dual vector proves on the box."""
        value = safe_lower_bound(data.q, data.A, data.b, data.cones, z, data.lower, data.upper)
        if self.norm == "L2L2":  # the square rounded down: it may round up by half a unit in the last place
            return value * value * (1.0 - 2.0 * UNIT_ROUNDOFF) if value > 0 else 0.0
        return max(value, 0.0)

    def split_variables(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M (2x3), alpha, t) of a relaxation point."""
        return x[self.im:self.im + 6].reshape(2, 3), x[self.ia:self.ia + self.K], x[self.it:self.it + 2]


def with_cost_cap(relaxation: Relaxation, data: ConicData, cap: float) -> ConicData:
    """The relaxation with the row "cost at most cap" (sum e <= cap, or s <= sqrt(cap)) appended
    to its orthant rows: the feasible set of bound tightening."""
    at = data.cones.zero + data.cones.nonneg
    A = insert_row(data.A.tocsc(), at, np.arange(relaxation.ie, relaxation.nvar))
    b = np.concatenate([data.b[:at], [relaxation.residual_bound(cap) if relaxation.norm == "L2L2" else cap],
                        data.b[at:]])
    cones = ConeSpec(zero=data.cones.zero, nonneg=data.cones.nonneg + 1, soc=data.cones.soc)
    return ConicData(data.q, A, b, cones, data.lower, data.upper)


def insert_row(A: sp.csc_matrix, at: int, columns: np.ndarray) -> sp.csc_matrix:
    """A with a row of ones in ``columns`` inserted before row ``at`` (the rows from ``at`` on
    move down by one): the same matrix as stacking the three parts, built in place of a
    vstack (which converted the whole relaxation twice per tightening); of A's own class."""
    A = A.copy()
    A.sort_indices()
    nrow, ncol = A.shape
    indices, indptr = A.indices, A.indptr
    before = np.concatenate([[0], np.cumsum(indices < at)])  # entries above the new row, cumulatively
    columns = np.asarray(columns, dtype=np.int64)
    # where each new entry goes: after its column's entries above row ``at``
    positions = indptr[columns] + (before[indptr[columns + 1]] - before[indptr[columns]])
    data = np.insert(A.data, positions, 1.0)
    new_indices = np.insert(np.where(indices >= at, indices + 1, indices), positions, at)
    added = np.zeros(ncol + 1, dtype=np.int64)
    added[columns + 1] = 1
    return type(A)((data, new_indices, indptr + np.cumsum(added)), shape=(nrow + 1, ncol))


def tightening_objective(relaxation: Relaxation, entry: int, sign: float) -> np.ndarray:
    """min sign * (the entry-th tightened variable): M_rk for entry = 3 r + k < 6, then alpha_i
    for entry = 6 + i."""
    q = np.zeros(relaxation.nvar)
    q[relaxation.im + entry if entry < 6 else relaxation.ia + entry - 6] = sign
    return q

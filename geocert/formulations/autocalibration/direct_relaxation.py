"""The moment (Lasserre) relaxation of direct autocalibration (thesis 7.4, 4.4), numpy only: the
verifier rebuilds the same conic program from the raw cameras.

The unknown is the absolute dual quadric Q (symmetric 4x4, trace 1) as x = its 9 free upper-
triangular entries (ENTRIES' order) measured from the centre Q0 = diag(1, 1, 1, 0) / 3, the classic
linear estimate in the program's frame (direct_relaxation.conditioning_frame): x = Q_ab - Q0_ab.
The polynomial program (thesis 7.11 with the objective 7.12):

    min  f(x) = sum_i (w_i11 - w_i22)^2 + w_i12^2 + w_i13^2 + w_i23^2,   w_i = P_i Q P_i^T
    s.t. trace Q = 1 (Q_33 = 1 - Q_00 - Q_11 - Q_22 = -x_0 - x_4 - x_7),  det Q = 0,  Q PSD,
         chirality (optional): R_k' adj(Q) R_l >= 0 for the chosen pairs of rows (k, l),
         each view's focal length within the intrinsics ranges: tr(S_i Q) >= 0, linear in Q
         (direct.focal_rows: without them the objective has a degenerate minimum at f -> 0).

Why centred: a moment relaxation is the same set under an affine change of variables, but not
the same data for the solver. Measured from Q = e_4 e_4' (x = Q's entries themselves) the objective
is a constant near 4 minus a linear term near 4 whose difference, the optimum, is near 1e-3: the
interior-point solver's relative gap then needs 1e-9 to place the bound within 1e-4 of the optimum,
and stalled ("AlmostSolved") on a third of Table 7.1's scenes; from Q0 the constant is the linear
estimate's cost (1e-3 to 1e-1), and the same scenes solve cleanly (measured on five of them).

For Q positive semidefinite of rank 3, adj(Q) = c u u' with c >= 0 and u the plane at infinity (Q's
null vector), so R_k' adj(Q) R_l = c (u.R_k)(u.R_l): two rows on the same side of the plane. The
pairs are signed camera centres with each other, and (with points) every point with every
orientation-signed centre; no sign of u has to be chosen.

Order-d relaxation, variables y_a (the moments of degree 1..2d; y_0 = 1):
- the moment matrix M_d(y) (monomials of degree <= d) positive semidefinite;
- Q's localizing matrix, [Q_ab(x) m_i m_j] over monomials of degree <= d - 1, positive semidefinite
  (Q >= 0 times a square);
- each 2x2 principal minor's localizing matrix (degree <= d - 1) positive semidefinite, each 3x3
  principal minor's moment >= 0, each chirality pair's moment >= 0 and each focal row's >= 0;
- det Q's moment: an equality (trace Q = 1 is substituted, no rows).
Conic form (Clarabel's, geocert.core.cones): minimise q'y s.t. A y + s = b, s in the cones.

Safe bound (safe_bound): for Q PSD with trace 1, Q_aa lies in [0, 1] and |Q_ab| <= sqrt(Q_aa Q_bb)
<= 1/2, so every x_k lies in [-1/3, 2/3] or [-1/2, 1/2], every moment y_a of a feasible Q in [-1, 1],
and in [0, 1] when every exponent is even; and sum_k x_k^2 <= ||Q - Q0||_F^2 = ||Q||_F^2 -
(2/3)(1 - Q_33) + 1/3 <= 4/3 (||Q||_F <= trace Q = 1), so tr M_d(y) = sum over the basis of x^(2 alpha)
<= sum_{j <= d} (4/3)^j (TRACE_RATIO). The dual is projected into the cones but the moment matrix's
block, which is corrected to zero the residual and whose negative eigenvalue is charged against
tr M_d(y): a bound on f over the polynomial program's feasible set, whatever the solver.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from geocert.core.cones import ConeSpec

ENTRIES = tuple((a, b) for a in range(4) for b in range(a, 4))[:-1]  # x's order; Q_33 = 1 - Q_00 - Q_11 - Q_22
CENTRE = np.array([1.0 / 3.0 if a == b else 0.0 for a, b in ENTRIES])  # Q0 = diag(1, 1, 1, 0) / 3's free entries
TRACE_RATIO = 4.0 / 3.0  # sum_k x_k^2 over the feasible set is at most this (module docstring)
N = len(ENTRIES)  # 9
INDEX = {pair: k for k, pair in enumerate(ENTRIES)}
INDEX.update({(b, a): k for (a, b), k in list(INDEX.items())})
MAX_ORDER = 3


def q_of(x: np.ndarray) -> np.ndarray:
    """Q (trace 1) from its 9 free entries' offsets from the centre."""
    entries = np.asarray(x, dtype=float) + CENTRE
    Q = np.empty((4, 4))
    for k, (a, b) in enumerate(ENTRIES):
        Q[a, b] = Q[b, a] = entries[k]
    Q[3, 3] = 1.0 - entries[0] - entries[4] - entries[7]
    return Q


def x_of(Q: np.ndarray) -> np.ndarray:
    """The free entries of Q scaled to trace 1, less the centre's."""
    Q = Q / np.trace(Q)
    return np.array([Q[a, b] for a, b in ENTRIES]) - CENTRE


# --- polynomials: (exponents (t, N) int, coefficients (t,)) ------------------------------------

def poly(terms: dict) -> tuple[np.ndarray, np.ndarray]:
    terms = {e: c for e, c in terms.items() if c != 0}
    if not terms:
        return np.zeros((0, N), dtype=np.int64), np.zeros(0)
    return np.array(list(terms), dtype=np.int64), np.array(list(terms.values()), dtype=float)


def _mul(p: dict, q: dict) -> dict:
    out: dict = {}
    for (e1, c1), (e2, c2) in itertools.product(p.items(), q.items()):
        e = tuple(a + b for a, b in zip(e1, e2))
        out[e] = out.get(e, 0.0) + c1 * c2
    return out


def _entry(a: int, b: int) -> dict:
    """Q_ab as a polynomial in x: Q0_ab + x_k, and Q_33 = 1 - Q_00 - Q_11 - Q_22 = -x_0 - x_4 - x_7
    (Q0's trace is 1)."""
    if (a, b) == (3, 3):
        out = {}
        for k in (0, 4, 7):
            e = [0] * N
            e[k] = 1
            out[tuple(e)] = -1.0
        return out
    e = [0] * N
    k = INDEX[(a, b)]
    e[k] = 1
    out = {tuple(e): 1.0}
    if CENTRE[k]:
        out[tuple([0] * N)] = float(CENTRE[k])
    return out


def _add(p: dict, q: dict, scale: float = 1.0) -> dict:
    out = dict(p)
    for e, c in q.items():
        out[e] = out.get(e, 0.0) + scale * c
    return out


def _det(rows: list[int], cols: list[int]) -> dict:
    """The determinant of Q's submatrix as a polynomial (Leibniz)."""
    out: dict = {}
    for perm in itertools.permutations(range(len(rows))):
        sign = np.linalg.det(np.eye(len(rows))[list(perm)])
        term = {tuple([0] * N): float(round(sign))}
        for i, j in enumerate(perm):
            term = _mul(term, _entry(rows[i], cols[j]))
        for e, c in term.items():
            out[e] = out.get(e, 0.0) + c
    return out


@functools.lru_cache(maxsize=None)
def polynomials() -> dict:
    """det Q, the principal minors, adj(Q)'s entries (dicts)."""
    det = _det([0, 1, 2, 3], [0, 1, 2, 3])
    minors2 = [_det(list(s), list(s)) for s in itertools.combinations(range(4), 2)]
    minors3 = [_det(list(s), list(s)) for s in itertools.combinations(range(4), 3)]
    adj = {}
    for a in range(4):
        for b in range(a, 4):  # adj(Q)_ab = (-1)^(a+b) det(Q without row b, column a)
            rows = [r for r in range(4) if r != b]
            cols = [c for c in range(4) if c != a]
            adj[(a, b)] = {e: (-1) ** (a + b) * c for e, c in _det(rows, cols).items()}
    return {"det": det, "minors2": minors2, "minors3": minors3, "adj": adj}


def evaluate(p: tuple[np.ndarray, np.ndarray], x: np.ndarray) -> float:
    exps, coefs = p
    return float(coefs @ np.prod(x[None, :] ** exps, axis=1))


# --- monomials and moments ------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def monomials(degree: int) -> np.ndarray:
    """All exponent vectors of total degree <= degree, graded (degree 0 first)."""
    out = []
    for d in range(degree + 1):
        for combo in itertools.combinations_with_replacement(range(N), d):
            e = [0] * N
            for k in combo:
                e[k] += 1
            out.append(e)
    return np.array(out, dtype=np.int64)


class Moments:
    """The moments y_a of degree <= 2 order; index() maps exponent vectors to their position."""

    def __init__(self, order: int):
        self.order = order
        self.exps = monomials(2 * order)
        self.base = 2 * order + 1
        self.powers = self.base ** np.arange(N, dtype=np.int64)
        keys = self.exps @ self.powers
        self.sorter = np.argsort(keys)
        self.sorted_keys = keys[self.sorter]

    def index(self, exps: np.ndarray) -> np.ndarray:
        if exps.size and (exps.min() < 0 or exps.sum(axis=-1).max() > 2 * self.order):
            raise ValueError("a monomial beyond the relaxation's degree")
        keys = exps @ self.powers
        pos = np.searchsorted(self.sorted_keys, keys)
        if np.any(pos >= len(self.sorted_keys)) or np.any(self.sorted_keys[np.minimum(pos, len(self.sorted_keys) - 1)] != keys):
            raise ValueError("a monomial beyond the relaxation's degree")
        return self.sorter[pos]

    def vector(self, x: np.ndarray) -> np.ndarray:
        """The moments of the point x (y_0 = 1 included)."""
        return np.prod(x[None, :] ** self.exps, axis=1)


def _svec_pairs(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows, cols = np.triu_indices(n)
    order = np.lexsort((rows, cols))
    rows, cols = rows[order], cols[order]
    return rows, cols, np.where(rows == cols, 1.0, np.sqrt(2.0))


def localizing(moments: Moments, matrix: list[list[dict]], degree: int) -> tuple[sp.coo_matrix, int]:
    """svec of the localizing matrix of a p x p polynomial matrix over monomials of degree <=
    degree, as a sparse (svec rows, moments) coefficient matrix, and its side."""
    basis = monomials(degree)
    p, nb = len(matrix), len(basis)
    size = p * nb
    rows, cols, weights = _svec_pairs(size)
    out_r, out_c, out_v = [], [], []
    for a in range(p):
        for b in range(a, p):
            exps, coefs = poly(matrix[a][b])
            if not len(coefs):
                continue
            # svec rows whose (row block, column block) is (a, b) or (b, a)
            r_block, c_block = rows // nb, cols // nb
            mask = ((r_block == a) & (c_block == b)) | ((r_block == b) & (c_block == a))
            where = np.flatnonzero(mask)
            i, j = rows[where] % nb, cols[where] % nb
            base = basis[i] + basis[j]  # (w, N)
            for e, c in zip(exps, coefs):
                out_r.append(where)
                out_c.append(moments.index(base + e[None, :]))
                out_v.append(c * weights[where])
    shape = (size * (size + 1) // 2, len(moments.exps))
    return sp.coo_matrix((np.concatenate(out_v), (np.concatenate(out_r), np.concatenate(out_c))), shape=shape), size


def scalar_rows(moments: Moments, polys: list[dict], degree: int = 0) -> sp.coo_matrix:
    """Each polynomial times each monomial of degree <= degree, one row each."""
    basis = monomials(degree)
    out_r, out_c, out_v = [], [], []
    row = 0
    for p in polys:
        exps, coefs = poly(p)
        for m in basis:
            out_r.append(np.full(len(coefs), row))
            out_c.append(moments.index(exps + m[None, :]))
            out_v.append(coefs)
            row += 1
    return sp.coo_matrix((np.concatenate(out_v), (np.concatenate(out_r), np.concatenate(out_c))),
                         shape=(row, len(moments.exps)))


def linear_rows(moments: Moments, coefficients: np.ndarray) -> sp.coo_matrix:
    """Rows of cubic forms given by (k, 4, 4) symmetric matrices S_k: sum_ab S_k,ab adj(Q)_ab:
    the weights (S_ab, or S_ab + S_ba off the diagonal) of adj(Q)'s ten upper entries times their
    polynomials' coefficients, summed in that order (one sparse product for all k rows: a row
    costs about a hundred nonzeros, not a polynomial built term by term)."""
    a, b, C = _adjugate_matrix(moments.order)
    weights = coefficients[:, a, b] + np.where(a == b, 0.0, coefficients[:, b, a])
    rows = (sp.csr_matrix(weights) @ C).tocoo()
    keep = rows.data != 0
    return sp.coo_matrix((rows.data[keep], (rows.row[keep], rows.col[keep])), shape=rows.shape)


@functools.lru_cache(maxsize=4)
def _adjugate_matrix(order: int) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix]:
    """adj(Q)'s upper entries (a, b) and the (10, moments) matrix of their polynomials."""
    moments = Moments(order)
    adj = polynomials()["adj"]
    rows, cols, values = [], [], []
    for t, entry in enumerate(adj.values()):
        exps, coefs = poly(entry)
        rows.append(np.full(len(coefs), t))
        cols.append(moments.index(exps))
        values.append(coefs)
    C = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(len(adj), len(moments.exps)))
    keys = np.array(list(adj))
    return keys[:, 0], keys[:, 1], C


# --- the program ----------------------------------------------------------------------------

ALL = tuple((a, b) for a in range(4) for b in range(a, 4))


def forms10(cameras: np.ndarray) -> np.ndarray:
    """(4 m, 10) linear forms l with (w11 - w22, w12, w13, w23) of each view = l . (Q's 10 entries)."""
    forms = []
    for P in cameras:
        def w(j, k):
            M = np.outer(P[j], P[k])
            M = M + M.T
            return np.array([M[a, b] / (2.0 if a == b else 1.0) for a, b in ALL])
        forms += [w(0, 0) - w(1, 1), w(0, 1), w(0, 2), w(1, 2)]
    return np.array(forms)


def objective(cameras: np.ndarray) -> dict:
    """f as a polynomial in x (Q of trace 1)."""
    G = forms10(cameras)
    G = G.T @ G  # f = e' G e over Q's 10 entries e
    entries = [_entry(a, b) for a, b in ALL]
    out: dict = {}
    for i in range(10):
        for j in range(10):
            if G[i, j] != 0:
                out = _add(out, _mul(entries[i], entries[j]), G[i, j])
    return out


def cost(cameras: np.ndarray, Q: np.ndarray) -> float:
    """(7.12) at Q scaled to trace 1."""
    Q = Q / np.trace(Q)
    w = np.einsum("iab,bc,idc->iad", cameras, Q, cameras)
    return float(np.sum((w[:, 0, 0] - w[:, 1, 1]) ** 2 + w[:, 0, 1] ** 2 + w[:, 0, 2] ** 2 + w[:, 1, 2] ** 2))


@dataclass
class Program:
    q: np.ndarray
    constant: float  # the objective is constant + q'y
    A: sp.csc_matrix
    b: np.ndarray
    cones: ConeSpec
    lower: np.ndarray
    upper: np.ndarray
    moments: Moments


def chirality_pairs(rows: np.ndarray, centres: int) -> np.ndarray:
    """(k, 4, 4) symmetrised outer products of the pairs of rows that must lie on one side of the
    plane: the last ``centres`` rows (signed centres) with each other, and every earlier row (a
    point) with every centre."""
    n = len(rows)
    pairs = [(k, l) for k in range(n - centres, n) for l in range(k + 1, n)]
    pairs += [(k, l) for k in range(n - centres) for l in range(n - centres, n)]
    out = np.array([np.outer(rows[k], rows[l]) for k, l in pairs]).reshape(-1, 4, 4)
    return (out + out.transpose(0, 2, 1)) / 2


def cut_polynomial(cut) -> dict:
    """sign (c - x_k) for a cut (k, c, sign): the half of the feasible set a branch keeps."""
    k, c, sign = cut
    e = [0] * N
    e[int(k)] = 1
    return {tuple([0] * N): float(sign) * float(c), tuple(e): -float(sign)}


def trace_polynomial(S: np.ndarray) -> dict:
    """tr(S Q) = sum_ab S_ab Q_ab as a polynomial in x (degree 1)."""
    out: dict = {}
    for a in range(4):
        for b in range(4):
            for e, c in _entry(a, b).items():
                out[e] = out.get(e, 0.0) + float(S[a, b]) * c
    return out


def build(cameras: np.ndarray, pairs: np.ndarray | None, order: int, cuts=(), linear: np.ndarray | None = None
          ) -> Program:
    """The order-``order`` relaxation of the program (module docstring) for the cameras as given,
    with ``linear`` ((k, 4, 4) symmetric S: tr(S Q) >= 0, one moment row each; direct.focal_rows,
    the intrinsics ranges' bound on each view's focal length) and restricted by ``cuts`` ((k, c, sign): sign (c - x_k) >= 0, each with its localizing matrix
    over the monomials of degree <= order - 1, before the moment matrix): a branch of
    direct_solve's splitting, whose leaves' halves cover the feasible set (direct.check_proof)."""
    if order not in range(2, MAX_ORDER + 1):
        raise ValueError(f"relaxation order {order} is not served (2 to {MAX_ORDER})")
    moments = Moments(order)
    polys = polynomials()
    nm = len(moments.exps)
    exps, coefs = poly(objective(cameras))
    q_full = np.zeros(nm)
    np.add.at(q_full, moments.index(exps), coefs)
    zero = [scalar_rows(moments, [polys["det"]])]
    nonneg = [scalar_rows(moments, polys["minors3"])]
    if pairs is not None and len(pairs):
        nonneg.append(linear_rows(moments, pairs))
    if linear is not None and len(linear):
        nonneg.append(scalar_rows(moments, [trace_polynomial(S) for S in linear]))
    psd_blocks, sizes = [], []
    Qmat = [[_entry(a, b) for b in range(4)] for a in range(4)]
    for matrix, degree in [(Qmat, order - 1)] + [([[m]], order - 1) for m in polys["minors2"]] + [
            ([[cut_polynomial(cut)]], order - 1) for cut in cuts] + [([[{tuple([0] * N): 1.0}]], order)]:
        block, size = localizing(moments, matrix, degree)
        psd_blocks.append(block)
        sizes.append(size)
    # s = C y (y_0 included) for every block: A = -C[:, 1:], b = C[:, 0]; the moment matrix last
    C = sp.vstack(zero + nonneg + psd_blocks).tocsc()
    A = sp.csc_matrix(-C[:, 1:])
    b = np.asarray(C[:, 0].todense()).ravel()
    cones = ConeSpec(zero=sum(m.shape[0] for m in zero), nonneg=sum(m.shape[0] for m in nonneg), psd=tuple(sizes))
    even = np.all(moments.exps[1:] % 2 == 0, axis=1)
    lower = np.where(even, 0.0, -1.0)
    upper = np.ones(nm - 1)
    return Program(q_full[1:], float(q_full[0]), A, b, cones, lower, upper, moments)


def moment_matrix(program: Program, y: np.ndarray) -> np.ndarray:
    """M_d(y) for the relaxation's variables y (without y_0)."""
    basis = monomials(program.moments.order)
    full = np.concatenate([[1.0], y])
    idx = program.moments.index(basis[:, None, :] + basis[None, :, :])
    return full[idx]


def safe_bound(program: Program, z: np.ndarray, floor: float = 0.0) -> tuple[float, float]:
    """A lower bound on f over the polynomial program's feasible set from any dual vector z, and
    the smallest eigenvalue of the moment matrix's dual block it charged (numpy only).

    Every cone's part of z but the moment matrix's is projected into its dual cone (exactly:
    cones.project_dual). The moment block Z is then changed, one svec entry per moment, so that
    q + A'z = 0 up to rounding (every moment has an entry in M_d), and only Z's PSD-ness is left
    to pay for: for y the moments of a feasible Q, q'y = -b'z + r'y + sum_cones <z, s> >= -b'z +
    r'y + min(0, lambda_min(Z)) tr M_d(y), with tr M_d(y) = sum over the basis of x^(2 alpha) <=
    sum_{j <= order} TRACE_RATIO^j (each degree j's sum is at most (sum_k x_k^2)^j, module
    docstring), and r'y charged to the box; lambda_min is the computed eigenvalue less its error
    bound (cones.eigenvalue_error), and the sum's rounding is subtracted (cones.rounding_margin,
    plus the products with the constant and the eigenvalue). Never below 0, since f >= 0
    everywhere; ``floor``: that floor (-inf for an objective that is not (7.12): a proven interval's,
    direct_sublevel, where a non-finite bound is then -inf too)."""
    from geocert.core.cones import (UNIT_ROUNDOFF, eigenvalue_error, flush_subnormal, project_dual,
                                    rounding_margin, smat)

    cones = program.cones
    m_size = cones.psd[-1]
    m_rows = m_size * (m_size + 1) // 2
    head = ConeSpec(cones.zero, cones.nonneg, cones.soc, cones.psd[:-1])
    z = flush_subnormal(z)
    if not np.all(np.isfinite(z)):
        return floor, -np.inf
    with np.errstate(over="ignore", invalid="ignore"):
        z[:head.rows] = project_dual(z[:head.rows], head)
        A = program.A
        start = A.shape[0] - m_rows
        r = program.q + np.asarray(A.T @ z).ravel()
        block = A[start:, :].tocsc()
        first = block.indices[block.indptr[:-1]]  # each moment's first entry in the block (csc: sorted)
        coef = block.data[block.indptr[:-1]]
        z[start + first] -= r / coef
        Z = smat(z[start:], m_size)
        lam = float(np.linalg.eigvalsh(Z)[0]) if np.all(np.isfinite(Z)) else -np.inf
        lam_low = lam - eigenvalue_error(Z)
        r = program.q + np.asarray(A.T @ z).ravel()
        terms = np.minimum(r * program.lower, r * program.upper)
        charge = float(np.sum(terms))
        trace = sum(TRACE_RATIO ** j for j in range(program.moments.order + 1))
        bound = program.constant - float(program.b @ z) + charge + min(0.0, lam_low) * trace
        margin = float(rounding_margin(np.abs(program.q)[None], abs(A), np.abs(program.b), z[None],
                                       np.maximum(np.abs(program.lower), np.abs(program.upper)), None, A.nnz,
                                       terms[None])[0])
        margin += 4.0 * UNIT_ROUNDOFF * (abs(program.constant) + abs(lam_low) * trace + abs(bound))
        bound -= margin
    if not bound == bound or not np.isfinite(bound):
        return floor, lam
    # f is a sum of squares (7.12), so 0 bounds it everywhere: where the optimum is 0 (an exact
    # scene) the dual's charges leave its bound a little below (-3.4e-8 measured, make_scene without
    # noise), which would keep a zero-cost quadric from ever certifying at any abs_gap below that
    return max(bound, floor), lam


def conditioning_frame(cameras: np.ndarray) -> np.ndarray:
    """T (4x4) in which the linear estimate of Q (the unit vector of Q's entries minimising f, the
    classic linear method) becomes diag(1, 1, 1, 0): cameras P T, Q_in = T Q T'. Orthogonal freedom
    changes not the optimum but the program, and with it what a recorded dual vector means:
    eigenvector signs are fixed (largest entry positive), so that a verifier whose LAPACK picks
    other signs rebuilds the program the proof's z was solved for."""
    forms = forms10(cameras)
    _, vectors = np.linalg.eigh(forms.T @ forms)
    v = _signed(vectors[:, :1])[:, 0]
    Q = np.empty((4, 4))
    for k, (a, b) in enumerate(ALL):
        Q[a, b] = Q[b, a] = v[k]
    values, V = np.linalg.eigh(Q)
    if np.sum(values > 0) < np.sum(values < 0):  # the sign that makes it nearer PSD
        values, V = -values[::-1], V[:, ::-1]
    order = np.argsort(-values)
    values, V = values[order], _signed(V[:, order])
    top = np.maximum(np.abs(values[:3]), 1e-9 * np.abs(values[0]))
    T = np.empty((4, 4))
    T[:, :3] = V[:, :3] * np.sqrt(top)
    left = np.linalg.norm(np.einsum("iab,bc->iac", cameras, T[:, :3]))
    right = np.linalg.norm(cameras @ V[:, 3])
    T[:, 3] = V[:, 3] * (left / np.sqrt(3.0) / right if right > 0 else 1.0)
    return T


def _signed(V: np.ndarray) -> np.ndarray:
    """The columns of V, each signed so that its entry largest in magnitude is positive."""
    top = V[np.argmax(np.abs(V), axis=0), np.arange(V.shape[1])]
    return V * np.where(top < 0, -1.0, 1.0)


def framed_cameras(cameras: np.ndarray, T: np.ndarray) -> np.ndarray:
    """The cameras in the frame T, each scaled to Frobenius norm sqrt(3) (as a camera [R | 0]):
    the program's data."""
    out = cameras @ T
    return out / (np.linalg.norm(out, axis=(1, 2)) / np.sqrt(3.0))[:, None, None]

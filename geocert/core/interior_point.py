"""A primal-dual interior-point method for the moment relaxation (direct_relaxation.Program),
numpy only, that exploits what Clarabel cannot: the structure of the PSD cones' scaling. Part of
the conic boundary (core.conic maps its statuses to ours).

Why: Clarabel factors the quasi-definite KKT system in which each PSD cone's Nesterov-Todd block
is a dense n(n+1)/2 square (the 55 x 55 moment matrix: 1540 rows), about 3e9 flops an iteration
(0.3 to 0.45 s measured). Eliminating the slacks instead (the Schur complement, as SDPT3, SeDuMi
and CVXOPT do) leaves H = A' (W'W)^-1 A over the 714 moments, where each PSD block's part is
A_b' (G^-1 (x) G^-1) A_b with G the 55 x 55 scaling point: assembled from G^-1's entries and A's
sparse rows, and factored in about 1e8 flops.

The method (Nesterov-Todd scaling, Mehrotra's predictor-corrector, infeasible start, as
Vandenberghe's CVXOPT notes, "The CVXOPT linear and quadratic cone program solvers", 2010):
    minimise q'y  s.t.  A y + s = b,  s in {0}^k x R+^m x S+^n1 x ...  (svec as Clarabel's)
returning (status, y, z).

Measured (Table 7.1's scenes, one BLAS thread): 17 to 38 iterations; with the block operator
assembled as the svec operator kron(Gi) (ASSEMBLY "kron"), 40 to 80 ms an iteration, half of it
the assembly; per moment (_Psd.schur), about 20 ms, of which the assembly 10 ms, the Cholesky
factorisation 5 ms and the refined Newton solves 5 ms (bench.direct_autocalibration --speed).
With OpenBLAS on two threads on the loaded shared machine, each 714 x 714
Cholesky took 0.33 s instead of 5 ms: the service's workers run BLAS on one thread, and so does
the bench.

Nothing here is trusted: the bound is direct_relaxation.safe_bound of the returned z, and only a
solve whose residuals and gap meet the tolerances is "Solved" (ConicStatus.OPTIMAL); anything
else falls back to Clarabel (direct_solve.solve_program).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sl
import scipy.sparse as sp

from geocert.core.conic import ConicStatus, map_interior_point_status

REFINEMENT = 3  # refinement steps per Newton solve (1 left the dual residual at 1e-9 late in some solves; 2-4 at 1e-12)
# ... and up to this many while the equations' error is above a tenth of the tolerance (of |q|, |b|):
# late in some splits' halves H's condition number passes 1e16 and three steps left an error that the
# step carried into the dual residual (seed 1012, varying focal, chirality, one BLAS thread: 1e-15 to
# 7e-7 in five iterations, then "Stalled", the gap 1.6e-7 relative; with up to ten, "Solved" at
# iteration 32). Not a cure: with H that ill-conditioned the refinement need not converge at all
# (with two BLAS threads the same half still stalls; GMRES preconditioned by H's factorisation, with
# or without a shift of 1e-10 of its diagonal, did worse: measured).
MAX_REFINEMENT = 10
STALL = 8  # iterations without progress before giving up


def _svec_index(n: int):
    rows, cols = np.triu_indices(n)
    order = np.lexsort((rows, cols))
    rows, cols = rows[order], cols[order]
    return rows, cols, np.where(rows == cols, 1.0, np.sqrt(2.0))


# How the Schur complement is assembled: "moments" (_Psd.schur, the nonnegative rows' part dense over the
# moments they hold) or "kron" (the former assembly: the svec operator kron(Gi) and sparse products,
# kept as bench.direct_autocalibration --speed's baseline; the same iterates up to rounding, which
# on seed 1008's ill-conditioned programs decides whether the last iterations pass the tolerance).
ASSEMBLY = "moments"
CHUNK = 32 * 55 * 55  # entries of Gi F_l Gi per chunk of the Schur block's assembly (_Psd.schur): 32 moments of the
# 55 x 55 moment matrix, so that its arrays stay in cache; a small block's chunks hold more moments (a 10 x 10
# block's all: 32 at a time, its assembly's Python overhead per chunk was most of its 0.3 ms)


def _chunk(n: int) -> int:
    """Moments per chunk of an n x n block's Schur assembly."""
    return max(1, CHUNK // (n * n))


_STRUCTURES: dict = {}


def _schur_structure(n: int, A: sp.csr_matrix):
    """For _Psd.schur, from the block's rows of A: the moments the block holds (cols), their
    matrices F_l = mat(A[:, l]) (full, symmetric) as (moment, n * n) rows (F), and each F_l's
    nonzero rows: their indices (rows, (moment, r), padded with row 0) and their entries (Fr,
    (moment * r, n), padded with zeros), r the most any F_l has (6 in the moment matrix's block,
    whose F_l are its moment's positions), and the rows of F up to each chunk's last moment (heads:
    F[:last] for _Psd.schur's upper triangle). Kept by the rows' value (a few recent ones): the blocks
    repeat from solve to solve, their rows depending on the order and the cuts only."""
    A = sp.csr_matrix(A)
    A.sort_indices()
    key = (n, A.shape, A.indptr.tobytes(), A.indices.tobytes(), A.data.tobytes())
    if key in _STRUCTURES:
        return _STRUCTURES[key]
    p_index, q_index, w = _svec_index(n)
    coo = A.tocoo()
    cols = np.unique(coo.col)
    m = len(cols)
    local = np.searchsorted(cols, coo.col)
    p, q = p_index[coo.row], q_index[coo.row]
    value = coo.data / w[coo.row]
    off = p != q
    P, Q = np.concatenate([p, q[off]]), np.concatenate([q, p[off]])
    V, L = np.concatenate([value, value[off]]), np.concatenate([local, local[off]])
    F = sp.csr_matrix((V, (L, P * n + Q)), shape=(m, n * n))
    pairs = np.unique(L * n + P)  # (moment, row) of each nonzero row
    counts = np.bincount(pairs // n, minlength=m)
    r = int(counts.max(initial=0))
    slot = np.arange(len(pairs)) - np.repeat(np.cumsum(counts) - counts, counts)
    rows = np.zeros((m, r), dtype=np.intp)
    rows[pairs // n, slot] = pairs % n
    Fr = np.zeros((m, r, n))
    np.add.at(Fr, (L, slot[np.searchsorted(pairs, L * n + P)], Q), V)
    heads = [F[:min(m, first + _chunk(n))] for first in range(0, m, _chunk(n))]
    structure = cols, F, rows, Fr.reshape(m * r, n), heads
    if len(_STRUCTURES) >= 32:
        _STRUCTURES.pop(next(iter(_STRUCTURES)))
    _STRUCTURES[key] = structure
    return structure


class _Psd:
    def __init__(self, n: int, A: sp.csr_matrix, b: np.ndarray):
        self.n = n
        self.p, self.q, self.w = _svec_index(n)
        # (mat's and vec's positions flat: a one-dimensional index measured 2 to 3 times faster than (p, q), a few
        # hundred calls an iteration)
        self.pq, self.qp = self.p * n + self.q, self.q * n + self.p
        self.ww = np.outer(self.w, self.w) / 2.0
        self.AT = sp.csr_matrix(A.T)
        self.A = A
        self.b = b
        self.cols, self.F, self.rows, self.Fr, self.heads = _schur_structure(n, A)
        self._work = None  # schur's work arrays

    def mat(self, v: np.ndarray) -> np.ndarray:
        S = np.zeros((self.n, self.n))
        vals = v / self.w
        flat = S.reshape(-1)
        flat[self.pq] = vals
        flat[self.qp] = vals
        return S

    def vec(self, S: np.ndarray) -> np.ndarray:
        return self.w * S.reshape(-1)[self.pq]

    def kron(self, Gi: np.ndarray) -> np.ndarray:
        """svec form of U -> Gi U Gi (symmetric): entry (pq, rs) is
        w_pq w_rs (Gi_pr Gi_qs + Gi_ps Gi_qr) / 2 (rows gathered first, then columns: measured
        about twice as fast as one two-dimensional gather)."""
        Gp, Gq = Gi[self.p], Gi[self.q]
        out = np.take(Gp, self.p, axis=1)
        out *= np.take(Gq, self.q, axis=1)
        other = np.take(Gp, self.q, axis=1)
        other *= np.take(Gq, self.p, axis=1)
        out += other
        out *= self.ww
        return out

    def schur(self, Gi: np.ndarray, out: np.ndarray | None = None, upper: bool = False) -> np.ndarray:
        """A' kron(Gi) A over the block's moments (self.cols): entry (k, l) is trace(F_k Gi F_l Gi)
        with F_l = mat(A[:, l]). F_l Gi has r nonzero rows at most (its rows R_l: Z_l = F_l[R_l] Gi,
        one product for every l), so Gi F_l Gi = Gi[:, R_l] Z_l (a batch of n x r x n products),
        whose entries are summed over each F_k's positions (sparse), a chunk of moments l at a time
        (its arrays stay in cache). Measured against kron's 1540-square svec operator and its two
        sparse products, one BLAS thread, processor time: the 55 x 55 moment matrix's block 21 ms to
        4.8 ms, the 40 x 40 one 4.1 ms to 0.8 ms. With ``upper``, a chunk's columns l only in the rows k up to its
        last moment (every k <= l), from those rows of F (heads): the same values, about half the sparse products (the factorisation reads only H's
        upper triangle); the others are left as they were in ``out``."""
        n, m = self.n, len(self.cols)
        r = self.rows.shape[1]
        if self._work is None:
            # (the work arrays kept from call to call, with ``out``: fresh megabyte arrays each iteration
            # cost their pages' first touch; the same products into them)
            self._work = np.empty((m * r, n)), np.empty((m, r, n))
        Z = np.matmul(self.Fr, Gi, out=self._work[0]).reshape(m, r, n)
        G = np.take(Gi, self.rows, axis=0, out=self._work[1]).transpose(0, 2, 1)  # (l, n, r): Gi[:, R_l]
        if out is None:
            out = np.empty((m, m))
        for chunk, first in enumerate(range(0, m, _chunk(n))):
            last = min(m, first + _chunk(n))
            Y = np.matmul(G[first:last], Z[first:last])  # (l, a, s): (Gi F_l Gi)[a, s]
            if upper:
                out[:last, first:last] = self.heads[chunk] @ Y.reshape(last - first, n * n).T
            else:
                out[:, first:last] = self.F @ Y.reshape(last - first, n * n).T
        return out


@dataclass
class Result:
    status: ConicStatus  # ours (conic's map of raw_status); FAILED when y or z is not finite
    y: np.ndarray | None
    z: np.ndarray | None
    iterations: int
    primal: float
    dual: float
    raw_status: str  # the method's own: "Solved", "MaxIterations", "NumericalError", "Stalled"


def _factor(S: np.ndarray) -> np.ndarray:
    """L with L L' = S: Cholesky, or (when rounding has made S numerically singular) the
    symmetric root with the eigenvalues clipped to a tiny positive floor."""
    try:
        return np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        values, V = np.linalg.eigh(S)
        floor = 1e-300 + 1e-15 * max(values[-1], 0.0)
        if not values[-1] > 0:
            raise
        return V * np.sqrt(np.maximum(values, floor))


def _scaling_psd(S: np.ndarray, Z: np.ndarray):
    """NT scaling: r with r' Z r = Lambda = r^-1 S r^-T (diagonal), r^-1, lambda (any square
    factors of S and Z serve)."""
    Ls = _factor(S)
    Lz = _factor(Z)
    U, lam, Vt = np.linalg.svd(Lz.T @ Ls)
    root = np.sqrt(lam)
    r = (Ls @ Vt.T) / root
    rinv = (U.T @ Lz.T) / root[:, None]
    return r, rinv, lam


def _schur_complement(n: int, An: sp.csr_matrix, An_used: np.ndarray, flat_n: np.ndarray, weight: np.ndarray,
                      blocks: list, Gis: list, legacy: bool, work: dict | None = None) -> np.ndarray:
    """H = A_K' (W'W)^-1 A_K: the nonnegative rows' part (``weight`` z / s, dense over the moments
    they hold, An_used at the flat positions flat_n of H's transpose) and each PSD block's
    (_Psd.schur, or with ``legacy`` the former assembly through kron, the benchmark's baseline).
    ``work``, when given, keeps H's array and the full blocks' from call to call (the same sums
    into them). H is Fortran-ordered (but with ``legacy``), so that LAPACK factors it in place
    (_cholesky): its flat positions are those of H.T, C-ordered, hence flat_n's transposed order.
    Only H's upper triangle is complete (all the factorisation reads): the PSD blocks' parts below
    it are left out (_Psd.schur's ``upper``)."""
    if legacy:
        H = (sp.csr_matrix(An.T).multiply(weight[None, :]) @ An).toarray()
        for B, Gi in zip(blocks, Gis):
            H += np.asarray(B.AT @ (B.AT @ B.kron(Gi)).T)
        return (H + H.T) / 2
    if work is None:
        work = {}
    if "H" not in work:
        work["H"] = np.empty((n, n), order="F")
    H = work["H"]
    flat = H.T.reshape(-1)  # a view: H[i, j] is flat[j * n + i]
    H.fill(0.0)
    # (the flat positions are distinct, so the indexed sum is np.add.at's: measured 0.5 ms for np.add.at on these
    # values against 0.04 ms)
    flat[flat_n] += ((An_used.T * weight) @ An_used).ravel()
    for B, Gi in zip(blocks, Gis):
        if len(B.cols) == n:
            if id(B) not in work:  # (Fortran-ordered as H: schur's column chunks written contiguous, summed contiguous;
                # zeros, since schur leaves the entries well below the diagonal unwritten)
                work[id(B)] = np.zeros((n, n), order="F")
            H += B.schur(Gi, work[id(B)], upper=True)
        else:  # (np.add.at at the flat positions: measured 3 to 5 times faster than H[np.ix_(cols, cols)] +=;
            # the upper triangle's positions computed once a solve, the block's cols ascending)
            if id(B) not in work:
                k, l = np.triu_indices(len(B.cols))
                work[id(B)] = (np.zeros((len(B.cols), len(B.cols))), k * len(B.cols) + l, B.cols[l] * n + B.cols[k])
            out, upper, positions = work[id(B)]
            np.add.at(flat, positions, np.take(B.schur(Gi, out, upper=True).reshape(-1), upper))
    # (the factorisation reads H's upper triangle only: H is symmetric up to rounding, unsymmetrised, its lower
    # triangle incomplete)
    return H


def _cholesky(H: np.ndarray, legacy: bool):
    """cho_factor(H)'s (c, lower): with ``legacy`` scipy's, which copies H; else LAPACK's dpotrf
    on Fortran-ordered H in place (scipy's cho_factor copies a C-ordered array to Fortran order
    first: measured 1.1 ms of its 5.4 ms at 714 x 714), the same upper factor bit for bit, H
    overwritten by it. LinAlgError when H is not numerically positive definite (H then partly
    overwritten but with ``legacy``)."""
    if legacy:
        return sl.cho_factor(H, check_finite=True)
    c, info = sl.lapack.dpotrf(H, lower=0, clean=0, overwrite_a=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"dpotrf: info {info}")
    return c, False


def solve(q: np.ndarray, A: sp.spmatrix, b: np.ndarray, zero: int, nonneg: int, psd: tuple,
          tolerance: float = 1e-9, max_iter: int = 60, acceptable: float = 1e-8, check=None) -> Result:
    """The solve (_iterate) with its status mapped to ours (conic.map_interior_point_status): only
    "Solved" with a finite y and z is OPTIMAL. Never raises on numerical trouble (FAILED, with the
    exception as its raw status); ``check()``'s exceptions pass through."""
    try:
        raw, y, z, iterations, primal, dual = _iterate(q, A, b, zero, nonneg, psd, tolerance, max_iter, acceptable,
                                                       check)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:
        return Result(ConicStatus.FAILED, None, None, 0, np.nan, np.nan, f"exception: {exc}")
    status = map_interior_point_status(raw)
    if not (np.all(np.isfinite(y)) and np.all(np.isfinite(z))):
        status = ConicStatus.FAILED
    return Result(status, y, z, iterations, primal, dual, raw)


def _iterate(q: np.ndarray, A: sp.spmatrix, b: np.ndarray, zero: int, nonneg: int, psd: tuple,
             tolerance: float, max_iter: int, acceptable: float, check):
    """(raw status, y, z, iterations, primal, dual). Stops when the primal residual (relative to max(1, |b|)), the dual one (to max(1, |q|)) and
    the gap s'z (absolute, or relative to |q'y|) are all within ``tolerance`` ("Solved"); when
    the iterations end otherwise (a limit, a stall: the worst of the three not halved in STALL
    iterations, a numerical failure), the last iterate within ``acceptable`` is returned as
    "Solved", else the last iterate with the reason. ``check()``, when given, is called before
    each iteration and may raise to abandon the solve (a cancel, a time limit)."""
    A = sp.csr_matrix(A)
    n = A.shape[1]
    Ae, be = A[:zero], b[:zero]
    An, bn = A[zero:zero + nonneg], b[zero:zero + nonneg]
    blocks, start = [], zero + nonneg
    for size in psd:
        m = size * (size + 1) // 2
        blocks.append(_Psd(size, A[start:start + m], b[start:start + m]))
        start += m
    nu = nonneg + sum(psd)
    legacy = ASSEMBLY == "kron"
    # the nonnegative rows' part of the Schur complement, over the moments they hold (dense: the
    # chirality rows' cubic forms hold 119 of the 714 at order 2; the sparse product took 6 ms)
    used_n = np.unique(An.indices)
    An_used = An[:, used_n].toarray()
    flat_n = (used_n[None, :] * n + used_n[:, None]).ravel()  # (H's flat positions, H Fortran-ordered)
    bnorm, qnorm = max(1.0, np.linalg.norm(b)), max(1.0, np.linalg.norm(q))

    # start: y minimising ||A y - b||, slacks shifted into the cones; z the least-norm dual, shifted
    AK = sp.vstack([An] + [B.A for B in blocks]).tocsr()
    # the transposes once (each .T builds a new sparse matrix, about 20 times an iteration: measured
    # 70 ms a solve); the same products as before
    AKT, AeT = AK.T, Ae.T
    AeT_dense = AeT.toarray() if zero else None
    bK = np.concatenate([bn] + [B.b for B in blocks])
    AtA = (A.T @ A).toarray()
    AtA[np.diag_indices(n)] += 1e-10 * max(1.0, AtA.diagonal().max())
    factor = sl.cho_factor(AtA)
    y = sl.cho_solve(factor, A.T @ b)
    s = bK - AK @ y
    zK = -(AK @ sl.cho_solve(factor, q))
    lam_e = np.zeros(zero)

    def split(v):
        out, k = [v[:nonneg]], nonneg
        for B in blocks:
            m = len(B.p)
            out.append(v[k:k + m])
            k += m
        return out

    def shift(v):
        parts = split(v)
        deficit = [(-parts[0]).max(initial=-np.inf)] + [-np.linalg.eigvalsh(B.mat(x))[0] for B, x in zip(blocks, parts[1:])]
        a = max(deficit)
        if a >= -1e-8:
            a = 1.0 + max(a, 0.0)
            parts[0] = parts[0] + a
            parts[1:] = [x + a * B.vec(np.eye(B.n)) for B, x in zip(blocks, parts[1:])]
        return np.concatenate(parts)

    s, zK = shift(s), shift(zK)
    e_vecs = [np.ones(nonneg)] + [B.vec(np.eye(B.n)) for B in blocks]

    work: dict = {}  # the Schur complement's arrays, kept from iteration to iteration
    status = "MaxIterations"
    it = 0
    history: list[float] = []
    kept = None
    for it in range(1, max_iter + 1):
        if check is not None:
            check()
        sp_, zp = split(s), split(zK)
        # residuals
        r_p = bK - AK @ y - s
        r_e = be - Ae @ y
        r_d = -(AKT @ zK + AeT @ lam_e + q)
        gap = float(s @ zK)
        mu = gap / nu
        pobj = float(q @ y)
        dobj = float(-bK @ zK - be @ lam_e)
        pres = max(np.linalg.norm(r_p), np.linalg.norm(r_e)) / bnorm
        dres = np.linalg.norm(r_d) / qnorm
        if pres <= tolerance and dres <= tolerance and (gap <= tolerance or gap <= tolerance * abs(pobj)):
            status = "Solved"
            break
        merit = max(pres, dres, min(gap, gap / max(abs(pobj), 1e-300)))
        if merit <= acceptable:
            kept = (y.copy(), zK.copy(), lam_e.copy())
        history.append(merit)
        if len(history) > STALL and min(history[-STALL:]) > 0.5 * min(history[:-STALL]):
            status = "Stalled"  # no halving of the worst residual in STALL iterations
            break
        # scaling
        try:
            wn = np.sqrt(sp_[0] / zp[0])
            lamn = np.sqrt(sp_[0] * zp[0])
            scal = [_scaling_psd(B.mat(x), B.mat(w)) for B, x, w in zip(blocks, sp_[1:], zp[1:])]
        except np.linalg.LinAlgError:
            status = "NumericalError"
            break
        # Schur complement H = A_K' (W'W)^-1 A_K
        Gis = [rinv.T @ rinv for r, rinv, lam in scal]
        H = _schur_complement(n, An, An_used, flat_n, zp[0] / sp_[0], blocks, Gis, legacy, work)
        try:
            Hf = _cholesky(H, legacy)
        except np.linalg.LinAlgError:
            try:
                # (H assembled again: the failed factorisation overwrote part of it)
                H = _schur_complement(n, An, An_used, flat_n, zp[0] / sp_[0], blocks, Gis, legacy, work)
                H[np.diag_indices(n)] += 1e-12 * H.diagonal().max()
                Hf = _cholesky(H, legacy)
            except np.linalg.LinAlgError:
                status = "NumericalError"
                break
        if zero:
            HiAe = sl.cho_solve(Hf, AeT_dense, check_finite=legacy)
            S_e = Ae @ HiAe
            S_e = np.atleast_2d(S_e)

        def schur(rhs, r_eq):
            """(dy, dl) with H dy + Ae' dl = rhs and Ae dy = r_eq."""
            if zero:
                Hr = sl.cho_solve(Hf, rhs, check_finite=legacy)
                dl = np.linalg.solve(S_e, Ae @ Hr - r_eq)
                return Hr - HiAe @ dl, dl
            return sl.cho_solve(Hf, rhs, check_finite=legacy), np.zeros(0)

        def inverse_scale(v):
            """(W'W)^-1 v per block."""
            parts = split(v)
            return np.concatenate([parts[0] * (zp[0] / sp_[0])]
                                  + [B.vec(Gi @ B.mat(x) @ Gi) for B, Gi, x in zip(blocks, Gis, parts[1:])])

        def newton(rc_n, rc_psd):
            """rc: the scaled complementarity right side per block (vector / matrix)."""
            # t = W^-1 (lambda \ rc) - (W'W)^-1 r_p
            tn = (rc_n / lamn) / wn - r_pn * (zp[0] / sp_[0])
            ts = []
            for B, (r, rinv, lam), Gi, rc, rpb in zip(blocks, scal, Gis, rc_psd, r_pb):
                V = 2.0 * rc / (lam[:, None] + lam[None, :])
                T = rinv.T @ V @ rinv - Gi @ B.mat(rpb) @ Gi
                ts.append(B.vec(T))
            t = np.concatenate([tn] + ts)
            rhs = r_d - AKT @ t
            dy, dl = schur(rhs, r_e)
            dz = inverse_scale(AK @ dy) + t
            for step in range(MAX_REFINEMENT):
                # refined against the operator itself (H is its rounded product): the dual
                # equations' and the equalities' residuals, solved for again with no centring part
                e_d = r_d - (AKT @ dz + AeT @ dl)
                e_e = r_e - Ae @ dy
                if (step >= REFINEMENT and np.linalg.norm(e_d) <= 0.1 * tolerance * qnorm
                        and np.linalg.norm(e_e) <= 0.1 * tolerance * bnorm):
                    break
                cy, cl = schur(e_d, e_e)
                dy, dl = dy + cy, dl + cl
                dz = dz + inverse_scale(AK @ cy)
            ds = r_p - AK @ dy
            return dy, ds, dz, dl

        def scaled(ds, dz):
            """(W^-T ds, W dz) per block: vectors for nonneg, matrices for PSD."""
            dsp, dzp = split(ds), split(dz)
            out_s = [dsp[0] / wn] + [rinv @ B.mat(x) @ rinv.T for B, (r, rinv, lam), x in zip(blocks, scal, dsp[1:])]
            out_z = [dzp[0] * wn] + [r.T @ B.mat(x) @ r for B, (r, rinv, lam), x in zip(blocks, scal, dzp[1:])]
            return out_s, out_z

        def max_step(d):
            """Largest a with lambda + a d in the cones (d scaled)."""
            worst = (-(d[0] / lamn)).max(initial=0.0)
            for (r, rinv, lam), D in zip(scal, d[1:]):
                root = 1.0 / np.sqrt(lam)
                worst = max(worst, -np.linalg.eigvalsh(root[:, None] * D * root[None, :])[0])
            return np.inf if worst <= 0 else 1.0 / worst

        r_pn = r_p[:nonneg]
        r_pb = split(r_p)[1:]
        # predictor
        rc_n = -lamn * lamn
        rc_psd = [-np.diag(lam * lam) for _, _, lam in scal]
        dy, ds, dz, dl = newton(rc_n, rc_psd)
        ss, zz = scaled(ds, dz)
        ap = min(1.0, max_step(ss))
        ad = min(1.0, max_step(zz))
        # Mehrotra's centring: the affine step's gap
        gap_aff = float((s + ap * ds) @ (zK + ad * dz))
        # (SDPT3's exponent: 3 after long affine steps, down to 1 after short ones, when the iterates
        # have lost the central path; the cube alone stalled the halves of some splits)
        sigma = min(1.0, max(0.0, gap_aff / gap)) ** max(1.0, 3.0 * min(ap, ad) ** 2)
        # corrector
        rc_n = -lamn * lamn - ss[0] * zz[0] + sigma * mu
        rc_psd = []
        for (r, rinv, lam), S1, Z1 in zip(scal, ss[1:], zz[1:]):
            rc_psd.append(-np.diag(lam * lam) - (S1 @ Z1 + Z1 @ S1) / 2.0 + sigma * mu * np.eye(len(lam)))
        dy, ds, dz, dl = newton(rc_n, rc_psd)
        ss, zz = scaled(ds, dz)
        ap, ad = max_step(ss), max_step(zz)
        fraction = 0.9 + 0.09 * min(1.0, ap, ad)  # SDPT3's step fraction: shorter after short steps
        ap, ad = min(1.0, fraction * ap), min(1.0, fraction * ad)
        if ap < 1e-10 and ad < 1e-10:
            status = "Stalled"
            break
        y = y + ap * dy
        s = s + ap * ds
        zK = zK + ad * dz
        lam_e = lam_e + ad * dl
    if status != "Solved" and kept is not None:
        # the last iterate that met the acceptable tolerance (Clarabel's first attempt's)
        y, zK, lam_e = kept
        status = "Solved"
    z = np.concatenate([lam_e, zK])
    return status, y, z, it, float(q @ y), float(-bK @ zK - be @ lam_e)

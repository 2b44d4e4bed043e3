"""Cone layouts and safe bounds from dual vectors: plain numpy, no conic solver.

A conic program here is ``min q'x`` subject to ``A x + s = b``, ``s`` in a product of a zero
cone, a nonnegative orthant and second-order cones (Clarabel's form). Its dual asks for ``z`` in
the dual cone with ``A'z + q = 0``. A solver's ``z`` satisfies that only approximately, so
bounds are taken the safe way (docs/algorithms.md section 6; Neumaier & Shcherbina 2004): project
``z`` into the dual cone, then for every feasible ``x`` with ``lower <= x <= upper``

    q'x = (q + A'z)'x + z's - b'z >= -b'z + sum_j min(r_j lower_j, r_j upper_j),  r = q + A'z,

because ``z's >= 0``. The solver and the certificate verifier both call these functions, so the
bound a certificate claims is exactly the one a verifier recomputes.

The right-hand side is evaluated in IEEE double arithmetic, so each bound here is that value less
an upper bound on its rounding (``rounding_margin``): ``gamma_N`` (Higham's ``N u / (1 - N u)``,
N the longest sum involved) times the magnitudes of every product it adds up, plus what products
that underflow can lose. The projection is made exact: a projected second-order block's ``t`` is
raised to an upper bound of ``|x|`` and a projected positive semidefinite block is shifted by an
upper bound of its eigenvalues' error, so that ``z's >= 0`` holds for the vector actually used.
What remains assumed is IEEE rounding to nearest (numpy's sums and products, in any order) and,
for semidefinite blocks, that LAPACK's symmetric eigenvalues are within ``EIGEN_ERROR n u |Z|_F``
of the exact ones (a backward-stable solver's). docs/certificate.md lists every proof test and
what it assumes.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
from dataclasses import dataclass

import numpy as np

UNIT_ROUNDOFF = 2.0 ** -53  # u: one rounding to nearest changes a result by at most this, relatively
SMALLEST_SUBNORMAL = 2.0 ** -1074  # a product that underflows loses at most half of this
SMALLEST_NORMAL = 2.0 ** -1022
# A backward-stable symmetric eigensolver returns the eigenvalues of Z + E with |E|_2 below a
# modest multiple of n u |Z|; this multiple is assumed, far above LAPACK's (about n u |Z|).
EIGEN_ERROR = 64.0


# Whether bounds count their rounding (the default, always in a solver or a verification). Turned
# off only by ``rounding_uncounted``, for one thread or task: to tell whether a stored certificate
# written before bounds counted it is short of its claim by that rounding alone (verify.py).
_COUNTED = contextvars.ContextVar("rounding_counted", default=True)


@contextlib.contextmanager
def rounding_uncounted():
    """Bounds computed as they were before they counted their rounding (no margin, projections
    as computed), in this thread or task only."""
    token = _COUNTED.set(False)
    try:
        yield
    finally:
        _COUNTED.reset(token)


def rounding_counted() -> bool:
    """Whether bounds count their rounding here (always, but within rounding_uncounted)."""
    return _COUNTED.get()


def gamma(n: int) -> float:
    """Higham's gamma_n: a sum of n products in floating point (any order) differs from the
    exact sum by at most gamma_n times the sum of the products' magnitudes, plus underflow."""
    return n * UNIT_ROUNDOFF / (1.0 - n * UNIT_ROUNDOFF)


def subnormal(z: np.ndarray) -> np.ndarray:
    """Entries that are neither 0 nor normal numbers (whose products underflow)."""
    return (z != 0) & (np.abs(z) < SMALLEST_NORMAL)


def flush_subnormal(z: np.ndarray) -> np.ndarray:
    """A copy with subnormal entries set to 0: what the solver records (a certificate's dual
    vectors hold none, and the verifier refuses one that does)."""
    z = np.array(z, dtype=float)
    z[subnormal(z)] = 0.0
    return z


@dataclass(frozen=True)
class ConeSpec:
    """Cone layout of the rows of ``A``: ``zero`` equalities, ``nonneg`` inequalities, SOCs, then
    positive semidefinite cones of n x n matrices, each as its svec (svec below: n(n+1)/2 rows)."""

    zero: int = 0
    nonneg: int = 0
    soc: tuple[int, ...] = ()
    psd: tuple[int, ...] = ()

    @property
    def rows(self) -> int:
        return self.zero + self.nonneg + sum(self.soc) + sum(n * (n + 1) // 2 for n in self.psd)


def project_dual(z: np.ndarray, cones: ConeSpec) -> np.ndarray:
    """A point of the dual cone near ``z`` (free on the zero cone; the orthant and second-order
    cones are self-dual), exactly in the cone although computed in floating point; of each row
    when ``z`` is a matrix of dual vectors."""
    z = np.array(z, dtype=float)
    if z.ndim == 2:
        return np.array([project_dual(row, cones) for row in z]) if cones.psd else _project_rows(z, cones)
    start = cones.zero
    z[start:start + cones.nonneg] = np.maximum(z[start:start + cones.nonneg], 0.0)
    start += cones.nonneg
    if cones.soc:
        for rows in _soc_rows(start, cones.soc):  # all cones of one size at once
            z[rows] = _project_soc(z[rows])
        start += sum(cones.soc)
    for n in cones.psd:  # the PSD cone is self-dual under svec's inner product
        size = n * (n + 1) // 2
        z[start:start + size] = svec_psd(_project_psd(smat(z[start:start + size], n)))
        start += size
    return z


def _project_rows(Z: np.ndarray, cones: ConeSpec) -> np.ndarray:
    """project_dual of every row of ``Z`` (a copy) without PSD cones: each cone size's blocks of
    every row projected at once."""
    start = cones.zero
    Z[:, start:start + cones.nonneg] = np.maximum(Z[:, start:start + cones.nonneg], 0.0)
    start += cones.nonneg
    if cones.soc:
        for rows in _soc_rows(start, cones.soc):  # (cones, size)
            block = Z[:, rows]
            Z[:, rows] = _project_soc(block.reshape(-1, rows.shape[1])).reshape(block.shape)
    return Z


def svec(S: np.ndarray) -> np.ndarray:
    """A symmetric matrix as Clarabel's PSDTriangleConeT vector: the upper triangle column by
    column, off-diagonal entries times sqrt(2), so that svec(A) . svec(B) = trace(A B)."""
    rows, cols = np.triu_indices(S.shape[0])
    order = np.lexsort((rows, cols))  # column-major: by column, then row
    rows, cols = rows[order], cols[order]
    return np.where(rows == cols, 1.0, np.sqrt(2.0)) * S[rows, cols]


def smat(v: np.ndarray, n: int) -> np.ndarray:
    """svec's inverse."""
    rows, cols = np.triu_indices(n)
    order = np.lexsort((rows, cols))
    rows, cols = rows[order], cols[order]
    values = v / np.where(rows == cols, 1.0, np.sqrt(2.0))
    S = np.zeros((n, n))
    S[rows, cols] = values
    S[cols, rows] = values
    return S


def eigenvalue_error(S: np.ndarray) -> float:
    """An upper bound on how far the computed eigenvalues of symmetric S (as read from its svec,
    off-diagonal entries divided by sqrt(2) with rounding) lie from those of the exact matrix:
    EIGEN_ERROR n u |S|_F, plus what the division changed and any underflow."""
    if not _COUNTED.get():
        return 0.0
    n = len(S)
    frobenius = float(np.sqrt(np.sum(S * S))) * (1.0 + 4.0 * UNIT_ROUNDOFF) + n * SMALLEST_NORMAL
    return (EIGEN_ERROR * n + 2.0) * UNIT_ROUNDOFF * frobenius + n * n * SMALLEST_SUBNORMAL


def svec_psd(S: np.ndarray) -> np.ndarray:
    """svec of S (positive semidefinite up to rounding) shifted by a multiple of the identity so
    that the vector returned is exactly in the PSD cone: its matrix's smallest eigenvalue, less
    its error bound, is at least 0 after the shift (which is rounded upwards)."""
    if not _COUNTED.get():
        return svec(S)
    lowest = float(np.linalg.eigvalsh(S)[0])
    shift = max(0.0, -lowest) + 2.0 * eigenvalue_error(S)
    if not np.isfinite(shift):
        return np.full(len(S) * (len(S) + 1) // 2, np.nan)
    return svec(S + shift * (1.0 + 4.0 * UNIT_ROUNDOFF) * np.eye(len(S)))


def _project_psd(S: np.ndarray) -> np.ndarray:
    """The nearest positive semidefinite matrix (Frobenius): negative eigenvalues clipped to 0."""
    values, vectors = np.linalg.eigh(S)
    return (vectors * np.maximum(values, 0.0)) @ vectors.T


@functools.lru_cache(maxsize=256)
def _soc_rows(start: int, soc: tuple[int, ...]) -> tuple[np.ndarray, ...]:
    """Per cone size, the (cones, size) matrix of the rows those cones occupy."""
    sizes = np.asarray(soc)
    offsets = start + np.concatenate([[0], np.cumsum(sizes)[:-1]])
    return tuple(offsets[sizes == size][:, None] + np.arange(size) for size in np.unique(sizes))


def norm_above(x: np.ndarray) -> np.ndarray:
    """For rows x, an upper bound of each row's exact 2-norm: computed on the row scaled by a
    power of two (no square underflows or overflows), inflated by its rounding."""
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        largest = np.max(np.abs(x), axis=1) if x.shape[1] else np.zeros(len(x))
        exponent = np.frexp(largest)[1]
        scaled = np.ldexp(x, -exponent[:, None])  # entries within [-1, 1]; exact unless subnormal
        k = x.shape[1]
        root = np.sqrt(np.sum(scaled * scaled, axis=1)) * (1.0 + (k + 4) * UNIT_ROUNDOFF) + k * SMALLEST_NORMAL
        return np.ldexp(root, exponent) + (k + 1) * SMALLEST_SUBNORMAL


def _project_soc(block: np.ndarray) -> np.ndarray:
    """Rows (t, x) projected onto {t >= |x|}, with t then raised to an upper bound of |x| (the
    projection's rounding may leave a row just outside the cone)."""
    t, x = block[:, 0], block[:, 1:]
    norm = np.linalg.norm(x, axis=1)
    out = block.copy()
    below = norm <= -t  # in the polar cone: projects to 0
    out[below] = 0.0
    middle = (norm > np.abs(t)) & ~below
    alpha = 0.5 * (t[middle] + norm[middle])
    out[middle, 0] = alpha
    out[middle, 1:] = x[middle] * (alpha / norm[middle])[:, None]
    if _COUNTED.get():
        out[:, 0] = np.maximum(out[:, 0], norm_above(out[:, 1:]))
    return out


def _reach(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """max(|lower|, |upper|): how far each variable reaches from 0."""
    return np.maximum(np.abs(lower), np.abs(upper))


def rounding_margin(q_abs: np.ndarray, A_abs, b_abs: np.ndarray, z: np.ndarray, reach: np.ndarray,
                    transform_abs: np.ndarray | None, nonzeros: int, terms: np.ndarray) -> np.ndarray:
    """How far the safe bound of ``z`` computed in floating point (as safe_lower_bounds computes
    it) can lie above its exact value, for each row of ``z`` (p, rows). Each sum of k products
    rounds by at most gamma_k times their magnitudes (Higham, any order of summation):

    - ``b'z``: gamma_rows |b|'|z|;
    - ``r_j = q_j + (A'z)_j``: gamma_(k_j + 1) m_j, ``m = |q| + |A|'|z|``, k_j the nonzero
      products in column j; through ``transform`` (the first d variables) another gamma_d |T|'m
      plus |T|' times those errors;
    - each ``min(r_j lower_j, r_j upper_j)`` moves by at most its r_j error times the variable's
      reach ``max(|lower_j|, |upper_j|)``, and their sum rounds by gamma_cols of the computed
      terms' magnitudes (``terms``: |min(r_j lower_j, r_j upper_j)| as computed, (p, cols));
    - the final subtraction, u times both magnitudes.

    The magnitudes are themselves computed in floating point (sums of nonnegative terms, within
    a factor 1 + gamma_N, N = rows + columns + d + 2): the total is taken 1 + 8 gamma_N times.
    A product that underflows loses at most half a subnormal, charged at the largest reach. A
    variable without a finite reach that a nonzero product touches makes the margin infinite."""
    if not _COUNTED.get():
        return np.zeros(len(z))
    magnitude = np.abs(z)
    with np.errstate(over="ignore", invalid="ignore"):
        m = q_abs + np.asarray(magnitude @ A_abs)  # (p, cols)
        k = np.asarray((magnitude != 0).astype(float) @ (A_abs != 0).astype(float)) + (q_abs != 0)
        if transform_abs is not None:
            mixed, mixed_k = m[:, :transform_abs.shape[0]] @ transform_abs, k[:, :transform_abs.shape[0]] @ (
                transform_abs != 0)
        else:
            mixed = mixed_k = None
        by_b = magnitude @ b_abs
    return _margin(m, k, mixed, mixed_k, transform_abs, by_b, reach, terms, len(b_abs), nonzeros)


def stacked_rounding_margin(q_abs: np.ndarray, A_abs: np.ndarray, b_abs: np.ndarray, z: np.ndarray, reach: np.ndarray,
                            transform_abs: np.ndarray, terms: np.ndarray) -> np.ndarray:
    """rounding_margin with a leading axis over programs: q_abs (G, p, cols), A_abs (G, rows,
    cols), b_abs (G, rows), z (G, p, rows), reach (G, cols), transform_abs (G, d, d), terms (G, p,
    cols); (G, p)."""
    if not _COUNTED.get():
        return np.zeros(z.shape[:2])
    magnitude = np.abs(z)
    d = transform_abs.shape[1]
    with np.errstate(over="ignore", invalid="ignore"):
        m = q_abs + np.einsum("gpr,grc->gpc", magnitude, A_abs)
        k = np.einsum("gpr,grc->gpc", (magnitude != 0).astype(float), (A_abs != 0).astype(float)) + (q_abs != 0)
        mixed = np.einsum("gpc,gcd->gpd", m[..., :d], transform_abs)
        mixed_k = np.einsum("gpc,gcd->gpd", k[..., :d], (transform_abs != 0).astype(float))
        by_b = np.einsum("gpr,gr->gp", magnitude, b_abs)
    G, p = z.shape[:2]
    nonzeros = np.count_nonzero(A_abs, axis=(1, 2))[:, None]
    margins = _margin(m.reshape(G * p, -1), k.reshape(G * p, -1), mixed.reshape(G * p, d),
                      mixed_k.reshape(G * p, d), transform_abs, by_b.reshape(-1),
                      np.repeat(reach, p, axis=0), terms.reshape(G * p, -1), A_abs.shape[1],
                      np.repeat(nonzeros, p, axis=0)[:, 0])
    return margins.reshape(G, p)


def _margin(m, k, mixed, mixed_k, transform_abs, by_b, reach, terms, rows: int, nonzeros) -> np.ndarray:
    """rounding_margin's sum (module docstring): rows of column magnitudes ``m`` and product
    counts ``k``, their images ``mixed``, ``mixed_k`` through |transform| (None without one)."""
    cols = m.shape[-1]
    with np.errstate(over="ignore", invalid="ignore"):
        error = _gammas(k + 1) * m
        d = 0
        if mixed is not None:
            d = mixed.shape[-1]
            mixed_error = np.einsum("pc,...cd->pd", error[:, :d], transform_abs) if transform_abs.ndim == 2 else \
                np.einsum("pc,pcd->pd", error[:, :d], np.repeat(transform_abs, len(m) // len(transform_abs), axis=0))
            error = np.concatenate([gamma(d) * mixed + mixed_error, error[:, d:]], axis=1)
            k = np.concatenate([mixed_k, k[:, d:]], axis=1)
        touched = k > 0
        charged = np.where(touched, error * reach, 0.0)  # 0 * inf: nothing touches it
        moved = np.abs(terms).sum(axis=1)
        total = gamma(rows) * by_b + charged.sum(axis=1) + gamma(cols + 1) * moved + UNIT_ROUNDOFF * (by_b + moved)
        finite_reach = np.where(np.isfinite(reach), reach, 0.0)
        lost = SMALLEST_SUBNORMAL * ((nonzeros + d * d + 3 * cols) * (1.0 + finite_reach.max(axis=-1, initial=0.0))
                                     + rows + cols + 4)
        margin = (1.0 + 8.0 * gamma(rows + cols + d + 2)) * total + lost
    return np.where(np.isfinite(margin), margin, np.inf)


def _gammas(n: np.ndarray) -> np.ndarray:
    return n * UNIT_ROUNDOFF / (1.0 - n * UNIT_ROUNDOFF)


# A program's A is a numpy array or a scipy.sparse matrix (the solvers' sparse relaxations); told
# apart without importing scipy, so a verifier reading dense programs loads numpy alone.
def _sparse(A) -> bool:
    return hasattr(A, "tocsc") and hasattr(A, "nnz")  # scipy.sparse's matrices and arrays


def _absolute(A):
    return abs(A) if _sparse(A) else np.abs(A)


def _nonzeros(A) -> int:
    return int(A.nnz) if _sparse(A) else int(np.count_nonzero(A))


def safe_lower_bound(q: np.ndarray, A, b: np.ndarray, cones: ConeSpec, z: np.ndarray,
                     lower: np.ndarray, upper: np.ndarray, transform: np.ndarray | None = None) -> float:
    """A lower bound on ``q'x`` over the feasible points with ``lower <= x <= upper``, less its
    rounding (rounding_margin): it holds in exact arithmetic for the projected ``z``.

    ``transform`` (d x d), when given, says the first d variables are ``x[:d] = transform @ y``
    and that ``lower[:d], upper[:d]`` bound ``y`` instead: the residual of those variables is
    charged through it (boxes of branching functionals are boxes in y, not in x).
    """
    return float(safe_lower_bounds(np.asarray(q, dtype=float)[None], A, b, cones, np.asarray(z, dtype=float)[None],
                                   lower, upper, transform)[0])


def safe_lower_bounds(Q: np.ndarray, A, b: np.ndarray, cones: ConeSpec, Z: np.ndarray,
                      lower: np.ndarray, upper: np.ndarray, transform: np.ndarray | None = None) -> np.ndarray:
    """safe_lower_bound for each row of ``Q`` with the dual vector in the same row of ``Z``, over
    one feasible set: one projection and one matrix product for all of them (the root region's
    2d bounds of a track). A row whose dual is not finite, or whose bound is not, bounds nothing
    (-inf); subnormal entries are read as 0 (a certificate holds none: strict.dual_vector)."""
    return safe_lower_bounds_and_margins(Q, A, b, cones, Z, lower, upper, transform)[0]


def safe_lower_bounds_and_margins(Q: np.ndarray, A, b: np.ndarray, cones: ConeSpec, Z: np.ndarray,
                                  lower: np.ndarray, upper: np.ndarray, transform: np.ndarray | None = None
                                  ) -> tuple[np.ndarray, np.ndarray]:
    """safe_lower_bounds, and the rounding margin each bound subtracted (rounding_margin): a
    bound computed in another order (another machine, a sparse matrix) lies within about twice
    it of this one."""
    Z = np.array(Z, dtype=float)
    finite = np.isfinite(Z).all(axis=1)
    Z[~finite] = 0.0  # no bound from them (below), whatever they hold
    Z[subnormal(Z)] = 0.0
    # A dual vector of huge entries (the last iterate of a solve that failed) can overflow:
    # whatever is not a finite number then is no bound at all, never NaN (a NaN compares false
    # with everything, and min() keeps or drops it by position) nor an overflowed +inf.
    with np.errstate(over="ignore", invalid="ignore"):
        Z = project_dual(Z, cones)
        finite &= np.isfinite(Z).all(axis=1)
        Z[~finite] = 0.0
        residual = Q + np.asarray(Z @ A)
        if transform is not None:
            d = transform.shape[0]
            residual = np.hstack([residual[:, :d] @ transform, residual[:, d:]])
        terms = np.minimum(residual * lower, residual * upper)
        terms[residual == 0] = 0.0
        bounds = -(Z @ b) + terms.sum(axis=1)
        margin = rounding_margin(np.abs(Q), _absolute(A), np.abs(b), Z, _reach(lower, upper),
                                 None if transform is None else np.abs(transform), _nonzeros(A), terms)
        bounds = bounds - margin
    return np.where(finite & np.isfinite(bounds), bounds, -np.inf), np.broadcast_to(margin, bounds.shape)


def proves_infeasible(A, b: np.ndarray, cones: ConeSpec, z: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                      transform: np.ndarray | None = None) -> bool:
    """Whether ``z`` (a Farkas vector) proves that no ``x`` within the bounds is feasible:
    ``z's >= 0`` gives ``b'z >= (A'z)'x >= min over the bounds``, impossible when ``b'z`` is
    smaller, by more than the rounding of both sides. The test is homogeneous in z, so z is first
    scaled by a power of two to entries of at most 1, the largest at least 1/2: no product of a
    tiny z underflows to a false certainty."""
    z = flush_subnormal(z)  # as a certificate records it (certificates.pack)
    if not np.all(np.isfinite(z)) or not np.any(z != 0):
        return False
    z = np.ldexp(z, -int(np.frexp(np.max(np.abs(z)))[1]))
    bound = safe_lower_bound(np.zeros(A.shape[1]), A, b, cones, z, lower, upper, transform)
    return bool(bound > 0)  # 0 = q'x >= bound > 0 for any feasible x: there is none

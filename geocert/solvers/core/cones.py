"""Cone layouts and safe bounds from dual vectors: plain numpy, no conic solver.

A conic program here is ``min q'x`` subject to ``A x + s = b``, ``s`` in a product of a zero
cone, a nonnegative orthant and second-order cones (Clarabel's form). Its dual asks for ``z`` in
the dual cone with ``A'z + q = 0``. A solver's ``z`` satisfies that only approximately, so
bounds are taken the safe way (docs/algorithms.md section 6; Neumaier & Shcherbina 2004): project
``z`` into the dual cone, then for every feasible ``x`` with ``lower <= x <= upper``

    q'x = (q + A'z)'x + z's - b'z >= -b'z + sum_j min(r_j lower_j, r_j upper_j),  r = q + A'z,

because ``z's >= 0``. The solver and the certificate verifier both call these functions, so the
bound a certificate claims is exactly the one a verifier recomputes.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


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
    """The nearest point of the dual cone (free on the zero cone; the orthant and second-order
    cones are self-dual); of each row when ``z`` is a matrix of dual vectors."""
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
        z[start:start + size] = svec(_project_psd(smat(z[start:start + size], n)))
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


def _project_soc(block: np.ndarray) -> np.ndarray:
    """Rows (t, x) projected onto {t >= |x|}."""
    t, x = block[:, 0], block[:, 1:]
    norm = np.linalg.norm(x, axis=1)
    out = block.copy()
    below = norm <= -t  # in the polar cone: projects to 0
    out[below] = 0.0
    middle = (norm > np.abs(t)) & ~below
    alpha = 0.5 * (t[middle] + norm[middle])
    out[middle, 0] = alpha
    out[middle, 1:] = x[middle] * (alpha / norm[middle])[:, None]
    return out


def _transposed_product(A, z: np.ndarray) -> np.ndarray:
    return np.asarray(A.T @ z).ravel() if sp.issparse(A) else A.T @ z


def _box_minimum(c: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> float:
    """min of c'x over lower <= x <= upper (zero coefficients cost nothing, even on infinite sides;
    a product past the float range is -inf or inf, as it should be: no bound, or none lost)."""
    with np.errstate(invalid="ignore", over="ignore"):
        terms = np.minimum(c * lower, c * upper)
    terms[c == 0] = 0.0
    return float(np.sum(terms))


def safe_lower_bound(q: np.ndarray, A, b: np.ndarray, cones: ConeSpec, z: np.ndarray,
                     lower: np.ndarray, upper: np.ndarray, transform: np.ndarray | None = None) -> float:
    """A lower bound on ``q'x`` over the feasible points with ``lower <= x <= upper``.

    ``transform`` (d x d), when given, says the first d variables are ``x[:d] = transform @ y``
    and that ``lower[:d], upper[:d]`` bound ``y`` instead: the residual of those variables is
    charged through it (boxes of branching functionals are boxes in y, not in x).
    """
    if not np.all(np.isfinite(z)):
        return -np.inf
    # A dual vector of huge entries (the last iterate of a solve that failed) can overflow:
    # whatever is not a finite number then is no bound at all, never NaN (a NaN compares false
    # with everything, and min() keeps or drops it by position) nor an overflowed +inf.
    with np.errstate(over="ignore", invalid="ignore"):
        z = project_dual(z, cones)
        residual = q + _transposed_product(A, z)
        if transform is not None:
            d = transform.shape[0]
            residual = np.concatenate([transform.T @ residual[:d], residual[d:]])
        bound = float(-b @ z) + _box_minimum(residual, lower, upper)
    return bound if math.isfinite(bound) else -np.inf


def safe_lower_bounds(Q: np.ndarray, A, b: np.ndarray, cones: ConeSpec, Z: np.ndarray,
                      lower: np.ndarray, upper: np.ndarray, transform: np.ndarray | None = None) -> np.ndarray:
    """safe_lower_bound for each row of ``Q`` with the dual vector in the same row of ``Z``, over
    one feasible set: one projection and one matrix product for all of them (the root region's
    2d bounds of a track). A row whose dual is not finite, or whose bound is not, bounds nothing
    (-inf)."""
    Z = np.array(Z, dtype=float)
    finite = np.isfinite(Z).all(axis=1)
    Z[~finite] = 0.0  # no bound from them (below), whatever they hold
    with np.errstate(over="ignore", invalid="ignore"):
        Z = project_dual(Z, cones)
        residual = Q + np.asarray(Z @ A)
        if transform is not None:
            d = transform.shape[0]
            residual = np.hstack([residual[:, :d] @ transform, residual[:, d:]])
        terms = np.minimum(residual * lower, residual * upper)
        terms[residual == 0] = 0.0
        bounds = -(Z @ b) + terms.sum(axis=1)
    return np.where(finite & np.isfinite(bounds), bounds, -np.inf)


def proves_infeasible(A, b: np.ndarray, cones: ConeSpec, z: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                      transform: np.ndarray | None = None) -> bool:
    """Whether ``z`` (a Farkas vector) proves that no ``x`` within the bounds is feasible:
    ``z's >= 0`` gives ``b'z >= (A'z)'x >= min over the bounds``, impossible when ``b'z`` is smaller."""
    if not np.all(np.isfinite(z)):
        return False
    with np.errstate(over="ignore", invalid="ignore"):
        z = project_dual(z, cones)
        a = _transposed_product(A, z)
        if transform is not None:
            d = transform.shape[0]
            a = np.concatenate([transform.T @ a[:d], a[d:]])
        left, right = float(b @ z), _box_minimum(a, lower, upper)
    return math.isfinite(left) and math.isfinite(right) and left < right

"""Small linear algebra in a fixed order of operations: the same floats on every machine.

A proof the verifier recomputes (fractional.resection_sublevel, resection_centre_l1) is refused
when the recomputed bound is wider than the stated one. BLAS and LAPACK (matmul, einsum's
contractions through them, dot, cholesky, inv, svd, eigvalsh) sum in an order of their kernel's
choosing (OpenBLAS's Haswell and Prescott kernels differ), and on ill-conditioned data (a
resection 1e5 from the origin) the whitening T of an 11 x 11 Gauss-Newton matrix differed by
1e-4 between kernels, its centre's bounds by 1e-3 of their half-widths: a genuine proof written
under one kernel was refused under the other. Here each sum runs over its index in order, with
elementwise numpy operations only (each an IEEE operation, correctly rounded, no fused
multiply-add), so writer and verifier compute one float. The round-off bounds of the proofs are
bounds for any order of summation and any Cholesky factorisation in floating point: nothing of
their soundness rests on this order, only the agreement between machines.
"""

from __future__ import annotations

import math

import numpy as np


def mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a (..., n) times b (n, ...): sum_p a[..., p] b[p], p in order (a matrix or vector product)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    n = a.shape[-1]
    if b.ndim == 1:
        out = a[..., 0] * b[0]
        for p in range(1, n):
            out = out + a[..., p] * b[p]
        return out
    out = a[..., 0, None] * b[0]
    for p in range(1, n):
        out = out + a[..., p, None] * b[p]
    return out


def gram(G: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """sum_j weight_j G_j' G_j for G (k, m, n): the products elementwise, summed over j and the
    rows of each G_j by numpy's reduction over the first axis (one order for given shapes)."""
    rows = G.reshape(-1, G.shape[-1])  # (k m, n): each G_j's rows, j by j
    weighted_rows = rows * np.repeat(weight, G.shape[1])[:, None]
    return (weighted_rows[:, :, None] * rows[:, None, :]).sum(axis=0)


def weighted(G: np.ndarray, y: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """sum_j weight_j G_j' y_j for G (k, m, n), y (k, m)."""
    return ((G * y[:, :, None]) * weight[:, None, None]).sum(axis=(0, 1))


def cholesky(M: np.ndarray) -> np.ndarray | None:
    """The lower factor L of M = L L' (M symmetric, its lower triangle read), column by column,
    each inner product summed in one order; None when a pivot is not positive (or not finite)."""
    M = np.asarray(M, dtype=float)
    n = len(M)
    L = np.zeros((n, n))
    for j in range(n):
        # the inner products by numpy's reduction over a row's last axis (a fixed order for a given
        # length): one vector operation a column instead of one a term
        s = M[j:, j] - (L[j:, :j] * L[j, :j]).sum(axis=1)
        pivot = float(s[0])
        if not (pivot > 0 and math.isfinite(pivot)):
            return None
        L[j, j] = math.sqrt(pivot)
        L[j + 1:, j] = s[1:] / L[j, j]
    return L if bool(np.all(np.isfinite(L))) else None


def cholesky_completes(M: np.ndarray) -> np.ndarray:
    """For a stack M (k, n, n): whether ``cholesky`` of each M[i] returns a factor (not None).
    Each matrix's factorisation is cholesky's own operations, elementwise over the stack, so each
    answer is the one cholesky gives alone (one float per entry on every machine). A pivot that
    is not positive or not finite fails its matrix, as in cholesky; the matrix is carried on
    (its entries then not finite, or not read) so that one pass decides the whole stack."""
    M = np.asarray(M, dtype=float)
    k, n = M.shape[0], M.shape[-1]
    L = np.zeros((k, n, n))
    pivots = np.empty((k, n))
    with np.errstate(all="ignore"):
        for j in range(n):
            s = M[:, j:, j] - (L[:, j:, :j] * L[:, j, None, :j]).sum(axis=2)
            pivots[:, j] = s[:, 0]
            root = np.sqrt(s[:, 0])
            L[:, j, j] = root
            L[:, j + 1:, j] = s[:, 1:] / root[:, None]
        return np.all(pivots > 0, axis=1) & np.all(np.isfinite(pivots), axis=1) & np.all(np.isfinite(L), axis=(1, 2))


def lower_inverse(L: np.ndarray) -> np.ndarray:
    """The inverse of a lower triangular L with nonzero diagonal, by forward substitution in order."""
    n = len(L)
    X = np.zeros((n, n))
    for i in range(n):
        row = np.zeros(n)
        row[i] = 1.0
        for p in range(i):
            row = row - L[i, p] * X[p]
        X[i] = row / L[i, i]
    return X


def inverse3(A: np.ndarray) -> np.ndarray | None:
    """The inverse of a 3 x 3 matrix by its adjugate over its determinant (None when that is 0 or
    not finite)."""
    a = np.asarray(A, dtype=float)
    adjugate = np.array([[a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1], a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2],
                          a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]],
                         [a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2], a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0],
                          a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]],
                         [a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0], a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1],
                          a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]]])
    determinant = a[0, 0] * adjugate[0, 0] + a[0, 1] * adjugate[1, 0] + a[0, 2] * adjugate[2, 0]
    if not (determinant != 0 and math.isfinite(determinant)):
        return None
    Z = adjugate / determinant
    return Z if bool(np.all(np.isfinite(Z))) else None


def camera_centres(cameras: np.ndarray) -> np.ndarray:
    """The homogeneous centres of (k, 3, 4) cameras: c_j = (-1)^j det(P without column j), each
    camera first scaled by a power of two (exact) so that its largest entry is about 1 (no
    overflow in the products). A null vector, as an SVD's is, but the same floats on every machine:
    an estimate's depth is a difference of the point and the centre, and a point 2e-9 from a centre
    20 units off the origin read the SVD's centres of two kernels 2.5e-5 of its depth apart."""
    P = np.asarray(cameras, dtype=float)
    largest = np.abs(P).max(axis=(1, 2))
    exponent = np.frexp(np.where((largest > 0) & np.isfinite(largest), largest, 1.0))[1]
    P = np.ldexp(P, -exponent[:, None, None])
    columns = [P[:, :, j] for j in range(4)]

    def det(a, b, c):  # the 3 x 3 determinant of columns a, b, c, in one order
        return (a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1])
                - b[:, 0] * (a[:, 1] * c[:, 2] - a[:, 2] * c[:, 1])
                + c[:, 0] * (a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]))

    a, b, c, d = columns
    return np.stack([det(b, c, d), -det(a, c, d), det(a, b, d), -det(a, b, c)], axis=1)


def norm(v: np.ndarray) -> float:
    """The 2-norm of a vector, its squares summed in order."""
    return math.sqrt(float(mul(v, v)))


def symmetric_eigen(M: np.ndarray, sweeps: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending) and eigenvectors (columns) of a symmetric M (its upper triangle
    read), by cyclic Jacobi rotations in a fixed order on Python floats: np.linalg.eigh's LAPACK
    path differs between kernels. Sweeps stop once every off-diagonal entry is below 1e-18 of the
    matrix's size (rounding's), or after ``sweeps``. ArithmeticError on entries not finite."""
    A = [[float(M[min(i, j)][max(i, j)]) for j in range(len(M))] for i in range(len(M))]
    n = len(A)
    if not all(math.isfinite(x) for row in A for x in row):
        raise ArithmeticError("a matrix entry is not finite")
    V = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    size = math.fsum(x * x for row in A for x in row)
    for _ in range(sweeps):
        if math.fsum(A[i][j] * A[i][j] for i in range(n) for j in range(i + 1, n)) <= 1e-36 * size:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = A[p][q]
                if apq == 0.0:
                    continue
                tau = (A[q][q] - A[p][p]) / (2.0 * apq)
                if abs(tau) > 1e150:  # tau * tau overflows: t is 1 / (2 tau) to rounding
                    t = 0.5 / tau
                else:
                    t = math.copysign(1.0, tau) / (abs(tau) + math.sqrt(1.0 + tau * tau))
                c = 1.0 / math.sqrt(1.0 + t * t)
                s = t * c
                for row in A:  # A J: columns p and q
                    akp, akq = row[p], row[q]
                    row[p], row[q] = c * akp - s * akq, s * akp + c * akq
                Ap, Aq = A[p], A[q]  # J' (A J): rows p and q
                A[p] = [c * x - s * y for x, y in zip(Ap, Aq)]
                A[q] = [s * x + c * y for x, y in zip(Ap, Aq)]
                A[p][q] = A[q][p] = 0.0
                for row in V:
                    vkp, vkq = row[p], row[q]
                    row[p], row[q] = c * vkp - s * vkq, s * vkp + c * vkq
    order = sorted(range(n), key=lambda k: (A[k][k], k))
    return (np.array([A[k][k] for k in order]), np.array([[row[k] for k in order] for row in V]).reshape(n, n))

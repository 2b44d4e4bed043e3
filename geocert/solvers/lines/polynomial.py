"""The polynomial solver (thesis 9.3.4): orthonormality enforced, ending in a univariate polynomial
of degree 11; 2 lines suffice.

What is the thesis's: five quadratic equations in three unknowns (x1, x2, x3), with the monomials
[x1^2, x2^2, x1x2, x1, x2, x1x3, x2x3, x3^2, x3, 1]; x3 hidden, so that the system reads
G(x3) u = 0 with G 5x6 (9.12) and u = [x1^2, x2^2, x1x2, x1, x2, 1]; u from the signed 5x5
minors of G (9.13), degrees 4, 4, 4, 3, 3, 2 in x3; the three relations u4 u5 = u3 u6,
u4^2 = u1 u6, u5^2 = u2 u6 (9.14), each of degree 6; and p = sum p_i p_i' (9.16), of degree 11,
whose real roots are the candidates for x3 (x1 = u4/u6, x2 = u5/u6). Every real root is tried.

What differs: where the five quadratics come from. The thesis writes (R, t) as a combination of
the last k = 4 singular vectors of [A, b] and takes the five scale-free orthonormality conditions
(equal column norms, orthogonal columns) on the coefficients. Here t is eliminated exactly (the
equations are linear in t: project them onto the left null space of t's columns, 4N - 3
equations on R alone) and R is written with the Cayley parametrisation
R = ((1 - c.c) I + 2 c c^T + 2 [c]x) / (1 + c.c), a rotation for every c, so orthonormality holds
by construction; multiplying out the denominator gives quadratics in c = (x1, x2, x3) with exactly
the monomials above. With 2 lines that is 5 equations (the minimal case, exact: no choice of
subspace, where the thesis's k = 4 subspace does not hold the 2-line solution); with more lines
the 4N - 3 equations are compressed to the 5 strongest combinations (SVD), the polynomial's real
roots are all tried and ranked by the residual of every equation. The Cayley form cannot express
rotations by 180 degrees (c at infinity); frame-to-frame motion is far from that.

The 5x5 minors are polynomials of degree <= 4 in x3: they are computed by evaluating the minors
at 5 values of x3 and interpolating (thesis 9.4.2 computes them symbolically)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.solvers.lines.geometry import LineSet, equations
from geocert.solvers.lines.results import Degenerate, Motion

MINIMUM_LINES = 2

# R_num(c) (row-major, 9 entries) over the monomials
# [c1^2, c2^2, c1c2, c1, c2, c1c3, c2c3, c3^2, c3, 1]; R = R_num / (1 + c.c).
_T = np.zeros((9, 10))
_T[0, [0, 1, 7, 9]] = [1, -1, -1, 1]
_T[1, [2, 8]] = [2, -2]
_T[2, [5, 4]] = [2, 2]
_T[3, [2, 8]] = [2, 2]
_T[4, [0, 1, 7, 9]] = [-1, 1, -1, 1]
_T[5, [6, 3]] = [2, -2]
_T[6, [5, 4]] = [2, -2]
_T[7, [6, 3]] = [2, 2]
_T[8, [0, 1, 7, 9]] = [-1, -1, 1, 1]
_DENOMINATOR = np.array([1, 1, 0, 0, 0, 0, 0, 1, 0, 1.0])

_NODES = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])  # where the minors are evaluated (degree <= 4)
_VANDERMONDE_INV = np.linalg.inv(np.vander(_NODES, 5))  # values -> coefficients, highest first
_SIGNS = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
_DERIVATIVE = np.arange(6, 0, -1.0)  # d/dx of a degree-6 polynomial, highest coefficient first
_DELETE = np.array([[j for j in range(6) if j != i] for i in range(6)])


@dataclass
class PolynomialOptions:
    max_candidates: int = 4  # real roots kept, ranked by the residual of every equation
    imaginary_tolerance: float = 1e-4  # |Im x3| <= this * (1 + |x3|) counts as a real root


def cayley(c: np.ndarray) -> np.ndarray:
    monomials = np.array([c[0] ** 2, c[1] ** 2, c[0] * c[1], c[0], c[1], c[0] * c[2], c[1] * c[2], c[2] ** 2,
                          c[2], 1.0])
    return (_T @ monomials).reshape(3, 3) / (monomials @ _DENOMINATOR)


def quadratics(lines: LineSet) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Q, A, b): Q (5, 10) the five quadratics in c (t eliminated), and the equations A v = b."""
    A, b = equations(lines)
    # t eliminated: the equations [A_R, -b] [r; 1] = 0 projected off t's columns (rank <= 4N - 3),
    # then their 5 strongest combinations (all of them for 2 lines).
    H = np.concatenate([A[:, :9], -b[:, None]], axis=1)
    basis = np.linalg.qr(A[:, 9:], mode="complete")[0]
    H = basis[:, 3:].T @ H  # the 4N - 3 equations on R alone
    if len(H) > 5:
        _, s, Vt = np.linalg.svd(H, full_matrices=False)
        H = s[:5, None] * Vt[:5]
    Q = H[:, :9] @ _T + np.outer(H[:, 9], _DENOMINATOR)
    return Q, A, b


def hidden_matrix(Q: np.ndarray, x3: np.ndarray) -> np.ndarray:
    """G(x3) (..., 5, 6) of (9.12) at the values x3 (...,)."""
    x3 = np.asarray(x3, dtype=float)[..., None]
    G = np.empty(x3.shape[:-1] + (Q.shape[0], 6))
    G[..., 0] = Q[:, 0]
    G[..., 1] = Q[:, 1]
    G[..., 2] = Q[:, 2]
    G[..., 3] = Q[:, 3] + Q[:, 5] * x3
    G[..., 4] = Q[:, 4] + Q[:, 6] * x3
    G[..., 5] = Q[:, 9] + Q[:, 8] * x3 + Q[:, 7] * x3 * x3
    return G


def null_vector_polynomials(Q: np.ndarray) -> np.ndarray:
    """(6, 5) the coefficients (highest degree first) of u_i(x3) = (-1)^i det(G without column i)."""
    G = hidden_matrix(Q, _NODES)  # (5 nodes, 5, 6)
    minors = np.linalg.det(G[:, :, _DELETE].transpose(0, 2, 1, 3))  # (5 nodes, 6)
    u = (_VANDERMONDE_INV @ (minors * _SIGNS)).T
    u[3:5, 0] = 0.0  # degree 3 (the interpolation's leading terms are rounding)
    u[5, :2] = 0.0  # degree 2
    return u


def degree_11(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(p, u): p the coefficients of the degree-11 polynomial (9.16) in x3, highest first, and u
    the null vector's polynomials."""
    u = null_vector_polynomials(Q)
    u = [u[0], u[1], u[2], u[3, 1:], u[4, 1:], u[5, 2:]]  # degrees 4, 4, 4, 3, 3, 2
    p = np.zeros(12)
    for q in (np.convolve(u[3], u[4]) - np.convolve(u[2], u[5]),  # (9.14), degree 6 each
              np.convolve(u[3], u[3]) - np.convolve(u[0], u[5]),
              np.convolve(u[4], u[4]) - np.convolve(u[1], u[5])):
        p += np.convolve(q, q[:-1] * _DERIVATIVE)  # q q' (9.16), degree 11
    return p, u


def real_roots(p: np.ndarray, tolerance: float) -> np.ndarray:
    nonzero = np.flatnonzero(np.abs(p) > 1e-14 * np.abs(p).max())
    if len(nonzero) == 0:
        return np.zeros(0)
    p = p[nonzero[0]:]
    if len(p) < 2:
        return np.zeros(0)
    companion = np.diag(np.ones(len(p) - 2), -1)
    companion[0, :] = -p[1:] / p[0]
    roots = np.linalg.eigvals(companion)
    return roots[np.abs(roots.imag) <= tolerance * (1 + np.abs(roots.real))].real


def cayley_many(c: np.ndarray) -> np.ndarray:
    """(K, 3, 3) rotations of the Cayley vectors c (K, 3)."""
    c1, c2, c3 = c[:, 0], c[:, 1], c[:, 2]
    monomials = np.stack([c1 * c1, c2 * c2, c1 * c2, c1, c2, c1 * c3, c2 * c3, c3 * c3, c3, np.ones_like(c1)], axis=1)
    return (monomials @ _T.T).reshape(-1, 3, 3) / (monomials @ _DENOMINATOR)[:, None, None]


def solve(lines: LineSet, options: PolynomialOptions | None = None) -> list[Motion]:
    options = options or PolynomialOptions()
    if len(lines) < MINIMUM_LINES:
        raise Degenerate(f"the polynomial solver needs {MINIMUM_LINES} lines, got {len(lines)}")
    Q, A, b = quadratics(lines)
    scale = np.abs(Q).max()
    if not scale > 0:
        raise Degenerate("the lines give no equation on the rotation")
    p, u = degree_11(Q / scale)
    roots = real_roots(p, options.imaginary_tolerance)
    if len(roots) == 0:
        raise Degenerate("the degree-11 polynomial has no real root")
    powers = roots[:, None] ** np.arange(4, -1, -1.0)  # (K, 5): x^4 .. 1
    values = np.stack([powers[:, 5 - len(ui):] @ ui for ui in u], axis=1)  # (K, 6): u_i(x3)
    usable = np.abs(values[:, 5]) > 1e-14 * np.abs(values).max(axis=1)
    if not usable.any():
        raise Degenerate("the degree-11 polynomial has no usable real root")
    values, roots = values[usable], roots[usable]
    c = np.stack([values[:, 3] / values[:, 5], values[:, 4] / values[:, 5], roots], axis=1)
    rotations = cayley_many(c)
    At = A[:, 9:]
    rhs = b[:, None] - A[:, :9] @ rotations.reshape(-1, 9).T  # (4N, K)
    t, *_ = np.linalg.lstsq(At, rhs, rcond=None)
    residuals = np.linalg.norm(At @ t - rhs, axis=0)
    order = np.argsort(residuals)[:options.max_candidates]
    candidates = [Motion(rotations[k], t[:, k], float(residuals[k])) for k in order]
    return candidates

"""How far two machines' evaluations of one cost may lie apart: the allowance of the objective
checks whose costs are sums of squares computed by BLAS and LAPACK (autocalibration, bilinear).

A claimed cost is compared with the cost the verifier computes from the claimed solution. Both are
floating-point evaluations of the same formula, by kernels that sum in different orders (OpenBLAS
picks its kernels by CPU; numpy its loops), on a normalisation the verifier computes again itself.
A residual computed from terms of magnitude M is off by a few ulps of M, not of the residual: a
near-exact fit's residuals (1e-8 of M, or 1e-15 in an exact synthetic scene) differ between
kernels in their leading digits, and a cost relative test refuses genuine certificates on another
CPU. So each residual r_i gets a rounding delta_i = RELATIVE * M_i, M_i the sum of the magnitudes of
the terms it is computed from, and the cost (a sum of squares) the allowance
sum(2 |r_i| delta_i + delta_i^2) on each side.

RELATIVE is 64 ulps of the terms: the dozens of operations behind a residual (products of up to four
factors, sums of up to sixteen terms) round it by a few ulps each. On the stored certificates the
kernels' costs differ by 1e-6 to 0.05 of this allowance (measured under
the default, Haswell and Prescott kernels). It moves only what a claim may state as its cost, never
the proof's bound, which the verifier recomputes, nor the gap, which the checks read from the
verifier's own cost plus this allowance (docs/certificate.md, "Tolerances")."""

from __future__ import annotations

import math

import numpy as np

RELATIVE = 64 * 2.0 ** -52


def squares_rounding(residuals: np.ndarray, magnitudes: np.ndarray) -> float:
    """The rounding allowance of sum(residuals**2), each residual computed from terms of the
    given magnitudes, for the two evaluations compared (the claim's and the verifier's)."""
    delta = RELATIVE * np.abs(np.asarray(magnitudes, dtype=float))
    r = np.abs(np.asarray(residuals, dtype=float))
    one_side = float(np.sum(2.0 * r * delta + delta * delta))
    return 2.0 * one_side if np.isfinite(one_side) else 0.0


def within(cost: float, claimed: float, relative: float, rounding: float) -> bool:
    """Whether the claimed cost is the computed one, to ``relative`` of it plus the rounding."""
    return math.isfinite(cost) and abs(cost - claimed) <= relative * abs(cost) + rounding + 1e-300


def metric_magnitudes(H: np.ndarray, omega: np.ndarray, weights: np.ndarray, rows: np.ndarray,
                      columns: np.ndarray) -> np.ndarray:
    """The metric stage's residuals omega - H omega H^T / q, weighted, each from terms of the
    magnitudes |omega| + |H| |omega| |H|^T / |q|."""
    images = np.einsum("jka,ab,jlb->jkl", np.abs(H), np.abs(omega), np.abs(H))
    q = np.abs(np.einsum("ja,ab,jb->j", H[:, 2], omega, H[:, 2]))
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = np.abs(omega)[None] + images / q[:, None, None]
    return (weights * terms[:, rows, columns]).ravel()


def direct_residuals(cameras: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The residuals whose squares direct_relaxation.cost sums, in direct_magnitudes' order."""
    Q = Q / np.trace(Q)
    w = np.einsum("iab,bc,idc->iad", cameras, Q, cameras)
    return np.concatenate([w[:, 0, 0] - w[:, 1, 1], w[:, 0, 1], w[:, 0, 2], w[:, 1, 2]])


def direct_magnitudes(cameras: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """The direct method's residuals (w00 - w11, w01, w02, w12 of P Q P^T at trace 1), each from
    terms of the magnitudes of |P| |Q| |P|^T."""
    Q = Q / np.trace(Q)
    w = np.einsum("iab,bc,idc->iad", np.abs(cameras), np.abs(Q), np.abs(cameras))
    return np.concatenate([w[:, 0, 0] + w[:, 1, 1], w[:, 0, 1], w[:, 0, 2], w[:, 1, 2]])


def affine_magnitudes(cameras: np.ndarray, reference: int, p: np.ndarray) -> np.ndarray:
    """The modulus residuals cbrt(gamma) alpha - beta of each view but the reference, H = A - a p^T:
    alpha a sum of 3 entries of H, beta of 6 products of two, gamma (the determinant) of 6 of
    three, each entry of H of magnitude at most max|A| + max|a| sum|p|."""
    views = [i for i in range(len(cameras)) if i != reference]
    A, a = np.abs(cameras[views, :, :3]), np.abs(cameras[views, :, 3])
    h = A.max(axis=(1, 2)) + a.max(axis=1) * float(np.sum(np.abs(p)))
    alpha, beta, gamma = 3.0 * h, 6.0 * h ** 2, 6.0 * h ** 3
    return np.cbrt(gamma) * alpha + beta


def bilinear_magnitudes(basis: np.ndarray, points: np.ndarray, camera: np.ndarray,
                        alpha: np.ndarray) -> np.ndarray:
    """Observed minus imaged, u - (S M^T + t) with S the coefficients' shape: the magnitudes
    |u| + |S| |M|^T + |t|, S's from |basis| |alpha| (NaN where a point is missing, as the
    residuals)."""
    shape = np.tensordot(np.abs(alpha), np.abs(basis), axes=1)
    return np.abs(points) + shape @ np.abs(camera[:, :3]).T + np.abs(camera[:, 3])

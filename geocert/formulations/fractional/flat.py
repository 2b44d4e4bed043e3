"""Many triangulation tracks as flat arrays of observations, and the local L2L2 solve on them:
a linear start and a Levenberg-Marquardt refinement, each a few passes of numpy over every
observation of every track at once (no Python-level work per track).

Observations are stored track after track, component-major so that every product is an
elementwise operation over all observations: ``rows`` (3, 4, m), each observation's camera,
``points`` (2, m) its pixel, and ``starts`` (tracks + 1,) with track t's observations at
``starts[t]:starts[t + 1]``. A sum over each track's observations is one ``np.add.reduceat``.

This is both the floor the certified solvers are measured against (what an uncertified
pipeline pays for a local optimum) and the first stage of the convexity certificate
(fractional.convexity), which certifies the point it ends at.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))  # a symmetric 3x3 matrix's entries, in order
NEAR_DOUBLE = 1e-3  # smallest_eigenvalue3: above 1 - this (the two least within about p / 20), eigvalsh answers


@dataclass
class FlatTracks:
    rows: np.ndarray  # (3, 4, m): every observation's camera, entry by entry
    points: np.ndarray  # (2, m) pixels
    starts: np.ndarray  # (tracks + 1,) offsets of each track's observations
    owner: np.ndarray  # (m,) the track of every observation

    @classmethod
    def build(cls, cameras: np.ndarray, tracks: list[tuple[list[int], np.ndarray]]) -> "FlatTracks":
        """From a scene's cameras (N, 3, 4) and ``(views, points)`` tracks (at least one view each)."""
        sizes = np.fromiter((len(views) for views, _ in tracks), dtype=np.int64, count=len(tracks))
        starts = np.zeros(len(tracks) + 1, dtype=np.int64)
        np.cumsum(sizes, out=starts[1:])
        if tracks:
            views = np.concatenate([np.asarray(v, dtype=np.int64) for v, _ in tracks])
            points = np.concatenate([np.asarray(p, dtype=float).reshape(-1, 2) for _, p in tracks])
        else:
            views, points = np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        rows = np.ascontiguousarray(np.asarray(cameras, dtype=float).transpose(1, 2, 0)[:, :, views])
        owner = np.repeat(np.arange(len(tracks)), sizes)
        return cls(rows, np.ascontiguousarray(points.T), starts, owner)

    @property
    def sizes(self) -> np.ndarray:
        return np.diff(self.starts)

    def per_track(self, values: np.ndarray) -> np.ndarray:
        """Each track's sums of ``values`` (..., m) over its observations: (..., tracks)."""
        return np.add.reduceat(values, self.starts[:-1], axis=-1)

    def project(self, x: np.ndarray) -> np.ndarray:
        """(3, m): each observation's camera times its track's point (x (T, 3), homogeneous 1)."""
        X = x[self.owner].T
        P = self.rows
        return P[:, 0] * X[0] + P[:, 1] * X[1] + P[:, 2] * X[2] + P[:, 3]


def linear(flat: FlatTracks) -> tuple[np.ndarray, np.ndarray]:
    """The linear least-squares triangulation of every track: (x (T, 3), ok). The two equations
    ``(u P3 - P1) . X = 0`` and ``(v P3 - P2) . X = 0`` of each observation, each scaled to unit
    length, with X = (x, 1), solved in the least-squares sense (3x3 normal equations by
    cofactors). ok is false where the system is singular or the point not finite (a point at
    infinity has no such x)."""
    P, p = flat.rows, flat.points
    eqs = np.stack([p[0] * P[2] - P[0], p[1] * P[2] - P[1]])  # (2, 4, m)
    eqs = eqs / np.sqrt((eqs * eqs).sum(axis=1, keepdims=True))
    normal = flat.per_track(np.stack([(eqs[:, a] * eqs[:, b]).sum(axis=0) for a, b in PAIRS]
                                     + [(eqs[:, a] * eqs[:, 3]).sum(axis=0) for a in range(3)]))
    with np.errstate(all="ignore"):
        x = -solve3(normal[:6], normal[6:])
    ok = np.all(np.isfinite(x), axis=0)
    return np.where(ok, x, 0.0).T.copy(), ok


def refine(flat: FlatTracks, x: np.ndarray, iterations: int = 20, tolerance: float = 1e-10):
    """Levenberg-Marquardt on every track's squared reprojection error from ``x`` (T, 3), in
    the caller's Euclidean coordinates, every track a step per pass: (x, cost). A step is taken
    only where it lowers the cost and keeps every depth positive; the damping falls by 3 after
    a taken step and grows by 10 after a refused one. Stops once every track has settled: a step
    lowered its cost, or the Gauss-Newton model says it would lower it, by at most
    ``tolerance`` relative (Gauss-Newton converges quadratically: the next step would change
    the cost in its last digits), or its damping has grown past 1e3 (no step lowers it)."""
    x = np.array(x, dtype=float)
    P, y = flat.rows, flat.points
    proj = flat.project(x)
    cost, behind = _costs(flat, proj)
    cost = np.where(behind, np.inf, cost)
    damping = np.full(len(x), 1e-4)
    settled = ~np.isfinite(cost)
    for _ in range(iterations):
        w = proj[2]
        image = proj[:2] / w
        r = image - y
        J = (P[:2, :3] - image[:, None] * P[2, :3][None]) / w  # (2, 3, m): d r_a / d x_k
        sums = flat.per_track(np.stack([(J[:, a] * J[:, b]).sum(axis=0) for a, b in PAIRS]
                                       + [(J[:, a] * r).sum(axis=0) for a in range(3)]))
        JtJ, Jtr = sums[:6], sums[6:]
        diagonal = JtJ[[0, 3, 5]]
        damped = JtJ.copy()
        damped[[0, 3, 5]] += damping * (diagonal + 1e-12 * diagonal.max(axis=0))
        with np.errstate(all="ignore"):
            step = -solve3(damped, Jtr)
            trial = x + step.T
            trial_proj = flat.project(trial)
            trial_cost, trial_behind = _costs(flat, trial_proj)
        better = ~trial_behind & (trial_cost < cost)
        gained = np.where(better, cost - trial_cost, 0.0)
        x = np.where(better[:, None], trial, x)
        proj = np.where(better[flat.owner], trial_proj, proj)
        cost = np.where(better, trial_cost, cost)
        damping = np.where(better, np.maximum(damping / 3, 1e-12), np.minimum(damping * 10, 1e12))
        # Settled: a step that gained, or by the Gauss-Newton model could gain, next to nothing
        # (what is left is round-off), or damping grown past any useful step. A settled track
        # still steps with the others.
        predicted = -(Jtr * step).sum(axis=0)
        settled |= (better & (gained <= tolerance * cost)) | ~(predicted > tolerance * cost) | (damping > 1e3)
        if settled.all():
            break
    return x, cost


def _costs(flat: FlatTracks, proj: np.ndarray):
    """Each track's sum of squared residuals and whether a depth is not positive (or not finite)."""
    w = proj[2]
    with np.errstate(all="ignore"):
        r = proj[:2] / w - flat.points
        sums = flat.per_track(np.stack([(r * r).sum(axis=0), (~(w > 0)).astype(float)]))
    cost = sums[0]
    return np.where(np.isfinite(cost), cost, np.inf), ~(sums[1] == 0) | ~np.isfinite(cost)


def solve3(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A^-1 b`` for symmetric 3x3 systems given entry by entry: ``A`` (6, T) in PAIRS order,
    ``b`` (3, T); by cofactors: a singular or non-finite system gives a non-finite column,
    never an exception for the batch."""
    a00, a01, a02, a11, a12, a22 = A
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    b0, b1, b2 = b
    return np.stack([c00 * b0 + c01 * b1 + c02 * b2, c01 * b0 + c11 * b1 + c12 * b2,
                     c02 * b0 + c12 * b1 + c22 * b2]) / det


def smallest_eigenvalue3(A: np.ndarray) -> np.ndarray:
    """The least eigenvalue of symmetric 3x3 matrices given entry by entry, ``A`` (6, T) in PAIRS
    order, non-finite entries read as 0: numpy.linalg.eigvalsh(...)[:, 0] to rounding (an error
    of a few units of the last place of the matrix's norm, as LAPACK's), without a LAPACK call
    per matrix. The trigonometric solution of the characteristic cubic: with q the mean
    eigenvalue and p^2 the mean squared deviation from it, the eigenvalues are
    q + 2 p cos(phi + 2 pi k / 3), 3 phi = arccos(det(A - q I) / 2 p^3). Where the two least
    eigenvalues nearly meet (the arccos's argument near 1, where its rounding grows as the
    square root), or where p^3 leaves the range where its products round as in the middle of it
    (p outside [1e-90, 1e90]), eigvalsh answers instead."""
    a00, a01, a02, a11, a12, a22 = (np.where(np.isfinite(a), a, 0.0) for a in np.asarray(A, dtype=float))
    with np.errstate(all="ignore"):
        q = (a00 + a11 + a22) / 3
        b00, b11, b22 = a00 - q, a11 - q, a22 - q
        p = np.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6)
        det = b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02)
        r = det / (2 * p * p * p)
        least = q + 2 * p * np.cos(np.arccos(np.clip(r, -1.0, 1.0)) / 3 + 2 * np.pi / 3)
    identity = (a01 == 0) & (a02 == 0) & (a12 == 0) & (a00 == a11) & (a11 == a22)  # a multiple of it
    least = np.where(identity, a00, least)
    redo = ~identity & ~((r <= 1 - NEAR_DOUBLE) & (p > 1e-90) & (p < 1e90) & np.isfinite(least))
    if redo.any():
        matrices = np.stack([a00, a01, a02, a01, a11, a12, a02, a12, a22], axis=-1)[redo].reshape(-1, 3, 3)
        least[redo] = np.linalg.eigvalsh(matrices)[:, 0]
    return least


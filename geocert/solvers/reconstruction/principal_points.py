"""How precisely the data fix each view's own principal point (the bundle model
"principal_per_view"): its marginal standard deviation in pixels, linearised at the adjusted
cameras and points. The reduced camera system (the points eliminated: the points, the shared
focal length and the other views free) is inverted without the similarity's 7 directions (its
smallest: no principal point moves with them); a principal point moving along a further
direction the data leave free (an eigenvalue below 1e-12 of the largest) is not fixed (an
infinite deviation); the noise's variance is read from the residuals. Near a distant object a principal
point's shift and a small rotation of the view nearly coincide: the per-view chi-square test
then passes on a misfit the principal points absorb while the data fix them to tens of pixels
(templeSparseRing, bench/results/reconstruction_vs_colmap.md), which this measures."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial.transform import Rotation

STEP = 1e-6  # forward differences' step (rotation vectors, translations, pixels, points)
NULL = 1e-12  # eigenvalues of the reduced system below this fraction of the largest: its null space
LOOSE = 1e-6  # a principal point's share of a free direction (unit vector) above this: it moves along it
GAUGE = 7  # the similarity's directions (rotation, translation, scale), which no principal point moves with


def standard_deviations(Ks, rotations, translations, points, view, track, pixels) -> tuple[np.ndarray, float, int]:
    """(each view's principal point's standard deviation, px: the larger axis of its 2x2
    covariance; the noise's sigma, px; the null space's dimension) for views (n) with K each
    (one focal length: the mean of theirs), rotations (n, 3, 3), translations (n, 3), points
    (p, 3) and observations (view, track: indices into them; pixels (m, 2))."""
    sd, _, sigma, null = with_focal_groups(Ks, rotations, translations, points, view, track, pixels)
    return sd, sigma, null


def with_focal_groups(Ks, rotations, translations, points, view, track, pixels,
                      groups=None, linearised_minimum: bool = False) -> tuple[np.ndarray, np.ndarray, float, int]:
    """standard_deviations with the focal lengths of the bundle model "focal_groups": ``groups``
    (n,) each view's group (None: one group), a group's focal length the mean of its views'.
    Returns (each view's principal point's sd, each group's focal length's sd (px), sigma, null).
    ``linearised_minimum``: the noise's variance read from the residuals at the minimum of the
    model linearised here (one Gauss-Newton step, every parameter free but the gauge's), not from
    the residuals here: what the deviations would be after the adjustment, from the cameras
    before it (a principal point per view the cameras here do not have yet)."""
    Ks, X = np.asarray(Ks, dtype=float), np.asarray(points, dtype=float)
    view, track, pixels = np.asarray(view, dtype=int), np.asarray(track, dtype=int), np.asarray(pixels, dtype=float)
    n, m, p = len(Ks), len(view), len(X)
    groups = np.zeros(n, dtype=int) if groups is None else np.asarray(groups, dtype=int)
    g = int(groups.max()) + 1
    focals = np.array([Ks[groups == k, 0, 0].mean() for k in range(g)])
    A = np.hstack([Rotation.from_matrix(np.asarray(rotations, dtype=float)).as_rotvec(),
                   np.asarray(translations, dtype=float), Ks[:, :2, 2]])
    obs_group = groups[view]

    def residual(A, f, X):
        cam = Rotation.from_rotvec(A[view, :3]).apply(X[track]) + A[view, 3:6]
        return f[obs_group, None] * cam[:, :2] / cam[:, 2:3] + A[view, 6:8] - pixels

    r0 = residual(A, focals, X)
    rows, cols, vals, at = [], [], [], np.arange(m)

    def add(d, columns):
        for c in range(2):
            rows.append(2 * at + c)
            cols.append(columns)
            vals.append(d[:, c])

    for j in range(8):
        moved = A.copy()
        moved[:, j] += STEP
        add((residual(moved, focals, X) - r0) / STEP, 8 * view + j)
    for k in range(g):
        moved = focals.copy()
        moved[k] *= 1 + STEP
        add((residual(A, moved, X) - r0) / (focals[k] * STEP), np.full(m, 8 * n + k))
    for j in range(3):
        moved = X.copy()
        moved[:, j] += STEP
        add((residual(A, focals, moved) - r0) / STEP, 8 * n + g + 3 * track + j)
    c = 8 * n + g
    J = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * m, c + 3 * p))
    N = (J.T @ J).tocsr()
    # The points' part is block diagonal (a point's 3 coordinates meet only each other): its 3 x 3
    # blocks gathered at once, pseudo-inverted as one stack, and laid out again as a sparse matrix.
    own = N[c:, c:].tocoo()
    blocks = np.zeros((p, 3, 3))
    np.add.at(blocks, (own.row // 3, own.row % 3, own.col % 3), own.data)
    inverse = sp.csr_matrix((np.linalg.pinv(blocks).ravel(), np.repeat(3 * (np.arange(3 * p) // 3), 3)
                             + np.tile(np.arange(3), 3 * p), np.arange(0, 9 * p + 1, 3)), shape=(3 * p, 3 * p))
    S = N[:c, :c].toarray() - (N[:c, c:] @ inverse @ N[:c, c:].T).toarray()
    # Each parameter scaled to unit diagonal (Jacobi): the null space's threshold does not then
    # depend on the frame's units (the pipeline's, or the result's normalised one).
    scale = 1.0 / np.sqrt(np.maximum(np.diag(S), 1e-300))
    values, vectors = np.linalg.eigh(S * scale[:, None] * scale[None, :])
    vectors = vectors * scale[:, None]  # back to the parameters: covariance = V diag(1 / values) V^T
    free = values <= NULL * values.max()
    null = int(np.count_nonzero(free))
    # The similarity's 7 directions (the smallest) are left out; a principal point moving along any
    # other the data leave free is not fixed at all (an infinite deviation).
    loose = vectors[:, GAUGE:][:, free[GAUGE:]]
    fixed = ~free
    fixed[:GAUGE] = False
    unit = (vectors[:, fixed] / values[fixed]) @ vectors[:, fixed].T  # the covariance for a unit variance
    cost = float((r0 ** 2).sum())
    if linearised_minimum:
        # |r0 + J d|^2 at its minimum: |r0|^2 less g_p' V^-1 g_p (the points, for the cameras
        # held) less the reduced gradient's g' S^+ g (the cameras, the points following them)
        gradient = J.T @ r0.ravel()
        points_part = inverse @ gradient[c:]
        reduced = gradient[:c] - N[:c, c:] @ points_part
        cost = max(cost - float(gradient[c:] @ points_part) - float(reduced @ unit @ reduced), 0.0)
    variance = cost / max(2 * m - (c + 3 * p - GAUGE), 1)
    covariance = unit * variance
    def deviation(block: slice) -> float:
        unfixed = loose.shape[1] > 0 and float(np.abs(loose[block] / scale[block, None]).max()) > LOOSE
        return np.inf if unfixed else float(np.sqrt(max(np.linalg.eigvalsh(covariance[block, block]).max(), 0.0)))

    sd = np.array([deviation(slice(8 * k + 6, 8 * k + 8)) for k in range(n)])
    focal_sd = np.array([deviation(slice(8 * n + k, 8 * n + k + 1)) for k in range(g)])
    return sd, focal_sd, float(np.sqrt(variance)), null

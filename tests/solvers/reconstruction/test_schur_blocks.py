"""schur.solve's reduced camera system, summed block by block (schur._Blocks), against the Schur
complement written out densely from the full Jacobian: U - W V^-1 W^T, and the step it gives
against the full normal equations' step."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.solvers.reconstruction import schur


def _problem(seed: int, c: int, s: int, d: int):
    """Random per-observation Jacobian blocks over 5 views and 30 points, every point seen at
    least twice, some twice by one view, the observations in no particular order."""
    rng = np.random.default_rng(seed)
    n, p = 5, 30
    view, track = [], []
    for j in range(p):
        seen = rng.choice(n, size=rng.integers(2, n + 1), replace=False).tolist()
        if j % 7 == 0:
            seen.append(seen[0])  # one view observing the point twice: a block of a view with itself
        view += seen
        track += [j] * len(seen)
    order = rng.permutation(len(view))
    view, track = np.array(view)[order], np.array(track)[order]
    M = len(view)
    return n, p, view, track, rng.normal(size=(M, 2, c + s)), rng.normal(size=(M, 2, d)), rng.normal(size=(M, 2))


@pytest.mark.parametrize("c, s, d", [(6, 0, 3), (6, 1, 3), (8, 3, 3), (12, 0, 4)])
def test_the_blocked_reduced_system_is_the_dense_schur_complement(c, s, d):
    n, p, view, track, je, jb, r = _problem(c + s + d, c, s, d)
    M, nc = len(view), n * c + s
    # The full Jacobian, two rows per observation: cameras' columns then the points'.
    J = np.zeros((2 * M, nc + p * d))
    for m in range(M):
        J[2 * m:2 * m + 2, c * view[m]:c * view[m] + c] = je[m, :, :c]
        J[2 * m:2 * m + 2, n * c:nc] = je[m, :, c:]
        J[2 * m:2 * m + 2, nc + d * track[m]:nc + d * track[m] + d] = jb[m]
    H = J.T @ J
    U, W, V = H[:nc, :nc], H[:nc, nc:], H[nc:, nc:]
    dense = U - W @ np.linalg.inv(V) @ W.T

    blocks = schur._Blocks(view, track, n, c, s, p)
    Vp = schur._sum_by(track, jb.transpose(0, 2, 1) @ jb, p)
    Vinv = schur._inverse(Vp)
    WmT = jb.transpose(0, 2, 1) @ je
    blocked = blocks.own(je, je) - blocks.reduction(Vinv[track] @ WmT, blocks.gathered(WmT))
    assert np.abs(blocks.own(je, je) - U).max() <= 1e-10 * np.abs(U).max()
    assert np.abs(blocked - dense).max() <= 1e-9 * np.abs(dense).max()

    # The camera step from the reduced system is the full normal equations' (gauge-free here:
    # random blocks make H nonsingular).
    g = J.T @ r.ravel()
    full = -np.linalg.solve(H, g)[:nc]
    gb = schur._sum_by(track, (jb.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0], p)
    cam_cols = np.concatenate([c * view[:, None] + np.arange(c)[None, :],
                               np.broadcast_to(n * c + np.arange(s), (M, s))], axis=1)
    ga = (je.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0]
    VWT = Vinv[track] @ WmT
    rhs = np.bincount(cam_cols.ravel(), weights=(ga - (gb[track][:, None, :] @ VWT)[:, 0, :]).ravel(), minlength=nc)
    assert np.abs(-np.linalg.solve(blocked, rhs) - full).max() <= 1e-8 * np.abs(full).max()


def test_points_seen_once_leave_no_pairs():
    """Every point observed once: no cross blocks, the reduction is each observation's own."""
    rng = np.random.default_rng(3)
    view, track = np.array([0, 1, 2, 0]), np.array([0, 1, 2, 3])
    je, jb = rng.normal(size=(4, 2, 6)), rng.normal(size=(4, 2, 3))
    blocks = schur._Blocks(view, track, 3, 6, 0, 4)
    WmT = jb.transpose(0, 2, 1) @ je
    X = rng.normal(size=WmT.shape)
    expected = np.zeros((18, 18))
    for m in range(4):
        at = slice(6 * view[m], 6 * view[m] + 6)
        expected[at, at] += X[m].T @ WmT[m]
    assert np.allclose(blocks.reduction(X, blocks.gathered(WmT)), expected, rtol=0, atol=1e-12)

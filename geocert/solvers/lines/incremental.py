"""The incremental solver for small motion (thesis 9.3.5): R ~ I + [s]x, so the 4N equations (9.3)
are linear in (s, t), 6 unknowns, solved by least squares (SVD); N >= 2 lines.

The thesis solves once. Here the linearisation is repeated about the current estimate
(R <- exp([s]x) R, a Gauss-Newton step on the same algebraic equations), ``iterations`` times:
with 1 it is the thesis's solver; the default 3 removes the first-order error of the tangent-space
approximation (exact motion on noise-free data for rotations of a few degrees)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.solvers.lines.geometry import LineSet, cross, rodrigues
from geocert.solvers.lines.results import Degenerate, Motion

MINIMUM_LINES = 2


@dataclass
class IncrementalOptions:
    iterations: int = 3
    rcond: float = 1e-10


def solve(lines: LineSet, options: IncrementalOptions | None = None, start: np.ndarray | None = None) -> list[Motion]:
    """With ``start`` (a rotation), the linearisation begins there instead of at the identity:
    RANSAC's local optimisation refits a hypothesis on its inliers this way."""
    options = options or IncrementalOptions()
    if len(lines) < MINIMUM_LINES:
        raise Degenerate(f"the incremental solver needs {MINIMUM_LINES} lines, got {len(lines)}")
    X = lines.points_a  # (N, 2, 4)
    n = lines.planes_b[:, :, :3]
    d = lines.planes_b[:, :, 3]
    R = np.eye(3) if start is None else start
    t = np.zeros(3)
    w = X[:, :, 3]
    # n . (Y + s x Y + t w) + d w = 0  ->  s . (Y x n) + w n . t = -(n . Y + d w); the t columns
    # and d w do not change with R
    rows_t = n[:, :, None, :] * w[:, None, :, None]
    dw = d[:, :, None] * w[:, None, :]
    for _ in range(max(1, options.iterations)):
        Y = X[:, :, :3] @ R.T  # (N, 2, 3): frame a's points rotated by the current R
        rows_s = cross(Y[:, None, :, :], n[:, :, None, :])  # (N, plane, point, 3)
        M = np.concatenate([rows_s, rows_t], axis=3).reshape(-1, 6)
        rhs = -(n @ Y.transpose(0, 2, 1) + dw).reshape(-1)
        scale = np.sqrt((M * M).sum(axis=1))
        scale[scale == 0] = 1.0
        M, rhs = M / scale[:, None], rhs / scale
        U, sv, Vt = np.linalg.svd(M, full_matrices=False)
        if sv[-1] <= options.rcond * sv[0]:
            raise Degenerate("the lines do not fix the motion (rank-deficient incremental system)")
        step = Vt.T @ ((U.T @ rhs) / sv)
        R = rodrigues(step[:3]) @ R
        t = step[3:]
        if np.linalg.norm(step[:3]) < 1e-13:
            break
    residual = float(np.linalg.norm(M @ step - rhs))
    return [Motion(R, t, residual)]

"""The reconstruct-and-align baseline (thesis 9.3.1): each stereo frame reconstructs its 3D lines
(intersecting the two back-projected planes), the rotation aligns the lines' directions (the
orthogonal Procrustes solution over the line directions, which for two lines is the thesis's
"mean direction, then the in-plane rotation"), and the translation aligns the rotated lines
(least squares on (R p_a + t - p_b) x d_b = 0, the closest points' offsets across each line).
A line's direction has no sign: every sign pattern of the sample is tried (2^(N-1)) when N is
small, and for larger N the signs are those agreeing with the best small-sample rotation."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from geocert.solvers.lines.geometry import LineSet, directions_and_points, equations, skew
from geocert.solvers.lines.results import Degenerate, Motion

MINIMUM_LINES = 2


@dataclass
class AlignOptions:
    max_sign_search: int = 4  # lines up to which every sign pattern is tried


def _procrustes(da: np.ndarray, db: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(db.T @ da)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def _translation(R, pa, pb, db) -> tuple[np.ndarray, float]:
    rows = np.concatenate([skew(d) for d in db])  # (3N, 3): d x t
    rhs = np.concatenate([skew(d) @ (q - R @ p) for d, p, q in zip(db, pa, pb)])
    t = np.linalg.lstsq(rows, rhs, rcond=None)[0]
    return t, float(np.linalg.norm(rows @ t - rhs))


def solve(lines: LineSet, options: AlignOptions | None = None) -> list[Motion]:
    options = options or AlignOptions()
    if len(lines) < MINIMUM_LINES:
        raise Degenerate(f"the align solver needs {MINIMUM_LINES} lines, got {len(lines)}")
    da, pa = directions_and_points(lines.planes_a)
    db, pb = directions_and_points(lines.planes_b)
    if np.linalg.matrix_rank(da, tol=1e-3) < 2:
        raise Degenerate("the lines are parallel: their directions do not fix the rotation")
    n = len(lines)
    head = min(n, options.max_sign_search)
    best = None
    A, b = equations(lines.subset(slice(0, head)))
    for signs in itertools.product((1.0, -1.0), repeat=head - 1):  # ranked by the equations (9.3)
        s = np.array((1.0,) + signs)
        R = _procrustes(da[:head] * s[:, None], db[:head])
        t, _ = _translation(R, pa[:head], pb[:head], db[:head])
        spread = float(np.linalg.norm(A @ np.concatenate([R.reshape(9), t]) - b))
        if best is None or spread < best[0]:
            best = (spread, R)
    R = best[1]
    if n > head:  # every line, its sign from the best rotation of the first ones
        s = np.sign(np.einsum("ij,ij->i", da @ R.T, db))
        s[s == 0] = 1.0
        R = _procrustes(da * s[:, None], db)
    t, residual = _translation(R, pa, pb, db)
    return [Motion(R, t, residual)]

"""The linear solver (thesis 9.3.3): the 4N equations (9.3) on the 12 entries of (R, t) solved by
least squares (N >= 3 lines); R is then projected onto the rotations (the thesis leaves it
unprojected: "the solution can be arbitrarily far from a rigid body motion") and t re-solved for
that R, so every candidate returned is a rigid motion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.solvers.lines.geometry import LineSet, equations, nearest_rotation, translation_given_rotation
from geocert.solvers.lines.results import Degenerate, Motion

MINIMUM_LINES = 3


@dataclass
class LinearOptions:
    rcond: float = 1e-10  # relative singular value below which the system is called rank deficient


def solve(lines: LineSet, options: LinearOptions | None = None) -> list[Motion]:
    options = options or LinearOptions()
    if len(lines) < MINIMUM_LINES:
        raise Degenerate(f"the linear solver needs {MINIMUM_LINES} lines, got {len(lines)}")
    A, b = equations(lines)
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    if s[-1] <= options.rcond * s[0]:
        raise Degenerate("the lines do not fix the 12 entries of (R, t) (rank-deficient linear system)")
    v = Vt.T @ ((U.T @ b) / s)
    R = nearest_rotation(v[:9].reshape(3, 3))
    t = translation_given_rotation(lines, R)
    residual = float(np.linalg.norm(A @ np.concatenate([R.reshape(9), t]) - b))
    return [Motion(R, t, residual)]

"""How well a frame pair's inlier lines fix its motion (core/determinacy.py), from the
refinement's own residuals (endpoint distances to the projected lines, refine.py): the Jacobian
of the motion (a rotation vector about the estimate, and t) and of each line's four parameters,
the lines eliminated (Schur complement), so the motion's intervals account for the lines being
estimated too. Quantities: the rotation angle (degrees) and t's entries (the rig's units).

Warnings: ``near_parallel_lines`` when the inlier lines nearly share one vanishing point in the
first view (a translation along them is poorly seen)."""

from __future__ import annotations

import math

import numpy as np

from geocert.core.determinacy import information_intervals
from geocert.solvers.lines.geometry import LineSet, segment_lines
from geocert.solvers.lines.refine import _lateral, _Problem, _start

VANISHING = 0.1


def motion(lines: LineSet, R: np.ndarray, t: np.ndarray) -> dict | None:
    n = len(lines)
    if n < 2:
        return None
    problem = _Problem(lines)
    P, Q = _start(lines, R, t)
    r0, Jm, Jl = problem.jacobian(R, t, P, Q, _lateral(P, Q))  # as the refinement builds it: (N, 8), (N, 8, 6), (N, 8, 4)
    # The motion's t in units of the baseline (t = baseline * tau) and each line's parameters
    # scaled by its own block's diagonal (Jacobi): the information's eigenvalues are then compared
    # (core's relative singular test) and regularised in unit-free terms. In the rig's units, t's
    # information scales as 1/unit^2 against the rotation's, so at 1e4 it fell below the relative
    # test ("unbounded"), and a fixed 1e-12 added to each line's block was a different share of it
    # at every unit.
    largest = float(np.abs(lines.rig.t).max())
    baseline = largest * float(np.linalg.norm(np.asarray(lines.rig.t) / largest))  # its squares may underflow
    Jm = Jm * np.array([1.0, 1.0, 1.0, baseline, baseline, baseline])
    U = Jl.transpose(0, 2, 1) @ Jl
    column = np.sqrt(np.einsum("nii->ni", U))  # (N, 4)
    column = np.where(column > 0, column, 1.0)
    U = U / column[:, :, None] / column[:, None, :] + 1e-12 * np.eye(4)
    Jl = Jl / column[:, None, :]
    W = Jm.transpose(0, 2, 1) @ Jl
    V = Jm.reshape(-1, 6).T @ Jm.reshape(-1, 6)
    U_inv = np.linalg.inv(U)
    schur = V - np.einsum("nab,nbc,ndc->ad", W, U_inv, W)
    # How far the motion is from the optimum of these residuals (the lines re-optimised for it):
    # the reduced gradient's Gauss-Newton decrease, in the cost's units.
    gm = Jm.reshape(-1, 6).T @ r0.reshape(-1)
    gl = (Jl.transpose(0, 2, 1) @ r0[:, :, None])[:, :, 0]
    reduced = gm - np.einsum("nab,nbc,nc->a", W, U_inv, gl)
    step = -np.linalg.lstsq(schur, reduced, rcond=None)[0]  # to that optimum, Gauss-Newton
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(R) - 1) / 2))))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    axis = axis / np.linalg.norm(axis) if np.linalg.norm(axis) > 1e-12 else np.zeros(3)
    gradient = np.zeros(6)
    gradient[:3] = np.degrees(axis)  # d angle / d rotation vector (left perturbation), first order
    quantities = {"rotation_angle_deg": (angle, gradient)}
    length = baseline * float(np.linalg.norm(t / baseline))  # the translation known to a tenth of its length
    for k, name in enumerate(("t_x", "t_y", "t_z")):
        quantities[name] = (float(t[k]), baseline * np.eye(6)[3 + k], length)
    out = information_intervals(schur, float((r0 * r0).sum()), 8 * n - 6 - 4 * n, quantities)
    # The intervals are about the optimum; an estimate short of it (RANSAC's start, a refinement
    # that stopped early) is held to the interval stretched to take in the step to it.
    for found, (_, g, *_) in zip(out.intervals, quantities.values()):
        moved = float(np.asarray(g) @ step)
        if found["lower"] is not None and math.isfinite(moved):
            found["lower"], found["upper"] = found["lower"] + min(moved, 0.0), found["upper"] + max(moved, 0.0)
    # Parallel 3D lines meet at one vanishing point: their image lines (normalised by K) then have
    # a near-null vector (measured, 0.03-0.05 of the next singular value for parallel lines at
    # 0.5 px, 0.25-0.33 for random ones).
    image_lines = segment_lines(lines.segments[:, 0]) @ lines.rig.K_left
    image_lines = image_lines / np.maximum(np.linalg.norm(image_lines, axis=1, keepdims=True), 1e-300)
    singular = np.linalg.svd(image_lines, compute_uv=False)
    ratio = float(singular[2] / max(float(singular[1]), 1e-300))
    if ratio < VANISHING:
        out.warnings.append({"code": "near_parallel_lines",
                             "detail": f"the inlier lines nearly share one vanishing point (fit {ratio:.2g}): they "
                                       "are nearly parallel, and a translation along them is poorly fixed"})
    return out.document()

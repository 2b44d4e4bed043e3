"""The optional within-frame refinement: a two-frame bundle adjustment of a frame pair's inlier
lines. Unknowns: the motion (a rotation vector about the estimate, and t) and each line (two
points, each moving in the plane normal to the line: 4 parameters, the line's own degrees of
freedom); residuals: the distances of the segments' endpoints in the four views to the projected
lines (pixels), Huber-weighted at the RANSAC threshold. Levenberg-Marquardt on the normal
equations with the lines eliminated (Schur complement, 4x4 blocks); the Jacobian by forward
differences, every line's block at once (lines do not interact), so an iteration costs 11 residual
evaluations (one batched call) whatever the number of lines. The lines start from their triangulation from all four
views under the RANSAC motion (geometry.triangulated_lines)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.solvers.lines.geometry import LineSet, cross, rodrigues, segment_lines, triangulated_lines
from geocert.solvers.lines.results import Motion


@dataclass
class RefineOptions:
    max_iterations: int = 12
    loss_scale_px: float = 2.0  # Huber: residuals beyond this are down-weighted
    tolerance: float = 1e-7  # relative decrease of the cost below which the iteration stops


def _points_on_lines(lines: LineSet, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two Euclidean points (N, 3) on each homogeneous line X (N, 2, 4): where the line passes
    nearest to the rays through the left-a segment's endpoints."""
    x, w = X[:, :, :3], X[:, :, 3]
    direction = w[:, 0, None] * x[:, 1] - w[:, 1, None] * x[:, 0]
    norm = np.linalg.norm(direction, axis=1, keepdims=True)
    norm[norm == 0] = 1.0
    direction /= norm
    weight = (w * w).sum(axis=1, keepdims=True)
    weight[weight == 0] = 1e-300
    base = (w[:, 0, None] * x[:, 0] + w[:, 1, None] * x[:, 1]) / weight
    K_inv = np.linalg.inv(lines.rig.K_left)
    ends = []
    for k in (0, 2):
        ray = np.concatenate([lines.segments[:, 0, k:k + 2], np.ones((len(lines), 1))], axis=1) @ K_inv.T
        b = (direction * ray).sum(axis=1)
        c = (ray * ray).sum(axis=1)
        dd = (direction * base).sum(axis=1)
        e = (ray * base).sum(axis=1)
        denominator = c - b * b
        s = np.where(np.abs(denominator) > 1e-12, (b * e - c * dd) / np.where(denominator == 0, 1, denominator), 0.0)
        ends.append(base + s[:, None] * direction)
    P, Q = ends
    degenerate = np.linalg.norm(Q - P, axis=1) < 1e-9
    Q[degenerate] = P[degenerate] + direction[degenerate]
    return P, Q


def _normal_basis(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """(N, 2, 3) two unit vectors normal to each line PQ."""
    d = Q - P
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    helper = np.where(np.abs(d[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = cross(d, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return np.stack([e1, cross(d, e1)], axis=1)


class _Problem:
    """The residuals, evaluated for a batch of states at once (the Jacobian's 10 perturbations in
    one call: the per-call overhead of numpy dominates at a hundred lines)."""

    def __init__(self, lines: LineSet):
        cameras = np.stack(lines.rig.cameras())  # (2, 3, 4): left, right
        self.Mt = cameras[:, None, :, :3].transpose(0, 1, 3, 2)  # (2 cameras, 1, 3, 3): x = X M^T + m
        self.m = cameras[:, None, None, :, 3]  # (2 cameras, 1, 1, 3)
        n = len(lines)
        # views in the order left a, right a, left b, right b -> (frame, camera, N, ...)
        self.segments = lines.segments.transpose(1, 0, 2).reshape(2, 2, n, 4)
        observed = segment_lines(lines.segments.reshape(-1, 4)).reshape(n, 4, 3)
        self.orientation = observed[:, :, :2].transpose(1, 0, 2).reshape(2, 2, n, 2)

    def residuals(self, R: np.ndarray, t: np.ndarray, P: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """(B, N, 8) endpoint distances (left a, right a, left b, right b; 2 endpoints each) for
        states R (B, 3, 3), t (B, 3), P and Q (B, N, 3)."""
        points = np.stack([P, Q], axis=1)  # (B, 2 points, N, 3)
        moved = points @ R[:, None].transpose(0, 1, 3, 2) + t[:, None, None, :]
        X = np.stack([points, moved], axis=1)  # (B, 2 frames, 2 points, N, 3)
        x = X[:, :, None] @ self.Mt + self.m  # (B, 2 frames, 2 cameras, 2 points, N, 3)
        line = cross(x[:, :, :, 0], x[:, :, :, 1])  # (B, 2, 2, N, 3)
        norm = np.hypot(line[..., 0], line[..., 1])
        norm[norm == 0] = 1e-300
        sign = np.where((line[..., :2] * self.orientation).sum(axis=-1) < 0, -1.0, 1.0)
        line = line * (sign / norm)[..., None]
        s = self.segments
        d0 = line[..., 0] * s[..., 0] + line[..., 1] * s[..., 1] + line[..., 2]
        d1 = line[..., 0] * s[..., 2] + line[..., 1] * s[..., 3] + line[..., 2]
        out = np.stack([d0, d1], axis=-1)  # (B, 2, 2, N, 2)
        return out.transpose(0, 3, 1, 2, 4).reshape(len(R), -1, 8)


def refine(lines: LineSet, motion: Motion, options: RefineOptions | None = None) -> Motion:
    options = options or RefineOptions()
    if len(lines) < 2:
        return motion
    problem = _Problem(lines)
    R, t = motion.R.copy(), motion.t.copy()
    P, Q = _points_on_lines(lines, triangulated_lines(lines, R, t))
    basis = _normal_basis(P, Q)  # fixed: small moves stay normal to the line to first order
    scale = max(1e-6, float(np.median(np.linalg.norm(P, axis=1))))

    def states(dm: np.ndarray, dl: np.ndarray):
        """Motions and lines after steps dm (B, 6: rotation vector, t) and dl (B, N, 4)."""
        R1 = np.repeat(R[None], len(dm), axis=0)
        for k in np.flatnonzero(np.any(dm[:, :3] != 0, axis=1)):  # the Jacobian's line rows keep R
            R1[k] = rodrigues(dm[k, :3]) @ R
        P1 = P + dl[..., 0, None] * basis[:, 0] + dl[..., 1, None] * basis[:, 1]
        Q1 = Q + dl[..., 2, None] * basis[:, 0] + dl[..., 3, None] * basis[:, 1]
        return R1, t + dm[:, 3:], P1, Q1

    def weighted(r: np.ndarray) -> tuple[np.ndarray, float]:
        a = np.abs(r)
        w = np.where(a <= options.loss_scale_px, 1.0, options.loss_scale_px / np.maximum(a, 1e-300))
        cost = np.where(a <= options.loss_scale_px, 0.5 * r * r,
                        options.loss_scale_px * (a - 0.5 * options.loss_scale_px)).sum()
        return np.sqrt(w), float(cost)

    n = len(lines)
    h_m = np.array([1e-7] * 3 + [1e-7 * scale] * 3)
    h_l = 1e-7 * scale
    # The Jacobian's perturbations: each motion parameter (all lines fixed), then each line
    # parameter of every line at once.
    dm_fd = np.zeros((10, 6))
    dm_fd[np.arange(6), np.arange(6)] = h_m
    dl_fd = np.zeros((10, n, 4))
    for k in range(4):
        dl_fd[6 + k, :, k] = h_l
    r = problem.residuals(*states(np.zeros((1, 6)), np.zeros((1, n, 4))))[0]
    sw, cost = weighted(r)
    damping = 1e-3
    eye4 = np.eye(4)
    for _ in range(options.max_iterations):
        J = (problem.residuals(*states(dm_fd, dl_fd)) - r) * sw  # (10, N, 8)
        Jm = J[:6].transpose(1, 2, 0) / h_m  # (N, 8, 6)
        Jl = J[6:].transpose(1, 2, 0) / h_l  # (N, 8, 4)
        rw = r * sw
        U = Jl.transpose(0, 2, 1) @ Jl  # (N, 4, 4)
        W = Jm.transpose(0, 2, 1) @ Jl  # (N, 6, 4)
        V = Jm.reshape(-1, 6).T @ Jm.reshape(-1, 6)  # (6, 6)
        gm = Jm.reshape(-1, 6).T @ rw.reshape(-1)
        gl = (Jl.transpose(0, 2, 1) @ rw[:, :, None])[:, :, 0]
        diagonal = np.einsum("nii->ni", U)[:, :, None] * eye4 + 1e-12 * eye4
        improved = converged = False
        for _ in range(8):
            Ui = np.linalg.inv(U + damping * diagonal)
            WUi = W @ Ui  # (N, 6, 4)
            S = V + damping * np.diag(np.diag(V)) - np.tensordot(WUi, W, axes=([0, 2], [0, 2]))  # Schur
            dm = -np.linalg.solve(S, gm - np.tensordot(WUi, gl, axes=([0, 2], [0, 1])))
            dl = -(Ui @ (gl + (dm @ W))[:, :, None])[:, :, 0]
            R1, t1, P1, Q1 = states(dm[None], dl[None])
            r1 = problem.residuals(R1, t1, P1, Q1)[0]
            sw1, cost1 = weighted(r1)
            if np.isfinite(cost1) and cost1 < cost:
                converged = cost - cost1 < options.tolerance * cost
                R, t, P, Q, r, sw, cost = R1[0], t1[0], P1[0], Q1[0], r1, sw1, cost1
                basis = _normal_basis(P, Q)
                damping = max(damping / 10, 1e-9)
                improved = True
                break
            damping *= 10
        if not improved or converged:
            break
    return Motion(R, t, float(np.sqrt(np.mean(r * r))))

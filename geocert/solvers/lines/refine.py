"""The optional within-frame refinement: a two-frame bundle adjustment of a frame pair's inlier
lines. Unknowns: the motion (a rotation vector about the estimate, and t) and each line (two
points, each moving in the plane normal to the line: 4 parameters, the line's own degrees of
freedom); residuals: the distances of the segments' endpoints in the four views to the projected
lines (pixels), Huber-weighted at the RANSAC threshold. Levenberg-Marquardt on the normal
equations with the lines eliminated (Schur complement, 4x4 blocks); the Jacobian exact (the chain
rule through the projected lines, every line's block at once: lines do not interact), at about
the cost of two residual evaluations where forward differences took eleven. The lines start from their triangulation from all four
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
    """The residuals and their Jacobian, every line at once (the per-call overhead of numpy
    dominates at a hundred lines)."""

    def __init__(self, lines: LineSet):
        cameras = np.stack(lines.rig.cameras())  # (2, 3, 4): left, right
        self.Mt = cameras[:, None, :, :3].transpose(0, 1, 3, 2)  # (2 cameras, 1, 3, 3): x = X M^T + m
        self.m = cameras[:, None, None, :, 3]  # (2 cameras, 1, 1, 3)
        n = len(lines)
        # views in the order left a, right a, left b, right b -> (frame, camera, N, ...)
        self.segments = lines.segments.transpose(1, 0, 2).reshape(2, 2, n, 4)
        observed = segment_lines(lines.segments.reshape(-1, 4)).reshape(n, 4, 3)
        self.orientation = observed[:, :, :2].transpose(1, 0, 2).reshape(2, 2, n, 2)
        self._kept = None

    def _projected(self, R: np.ndarray, t: np.ndarray, P: np.ndarray, Q: np.ndarray):
        """The lines' points (2 points, N, 3) rotated by R, their projections (2 frames, 2 cameras,
        2 points, N, 3) and the projected lines (2, 2, N, 3); the last state's kept, since the
        Jacobian is asked for at the state whose residuals were just accepted."""
        kept = self._kept
        if kept is not None and kept[0] is R and kept[1] is t and kept[2] is P and kept[3] is Q:
            return kept[4]
        points = np.stack([P, Q])  # (2 points, N, 3)
        rotated = points @ R.T
        X = np.stack([points, rotated + t])  # (2 frames, 2 points, N, 3)
        x = X[:, None] @ self.Mt[:, None, 0] + self.m[:, None, 0]
        out = rotated, x, cross(x[:, :, 0], x[:, :, 1])
        self._kept = (R, t, P, Q, out)
        return out

    def residuals(self, R: np.ndarray, t: np.ndarray, P: np.ndarray, Q: np.ndarray) -> np.ndarray:
        """(N, 8) endpoint distances (left a, right a, left b, right b; 2 endpoints each) for the
        motion (R, t) and the lines through P and Q (N, 3 each)."""
        return self._distances(self._projected(R, t, P, Q)[2]).transpose(2, 0, 1, 3).reshape(len(P), 8)

    def _distances(self, line: np.ndarray, gradient: bool = False):
        """The endpoint distances (..., 2 frames, 2 cameras, N, 2) to the image lines
        (..., 2, 2, N, 3); with ``gradient``, also their gradients in the lines (..., 2, 2, N, 2, 3)."""
        norm = np.hypot(line[..., 0], line[..., 1])
        norm[norm == 0] = 1e-300
        o = self.orientation
        scale = np.where(line[..., 0] * o[..., 0] + line[..., 1] * o[..., 1] < 0, -1.0, 1.0) / norm
        unit = line * scale[..., None]
        s = self.segments
        d0 = unit[..., 0] * s[..., 0] + unit[..., 1] * s[..., 1] + unit[..., 2]
        d1 = unit[..., 0] * s[..., 2] + unit[..., 1] * s[..., 3] + unit[..., 2]
        d = np.stack([d0, d1], axis=-1)
        if not gradient:
            return d
        # d = sign (line . h) / |line[:2]| for the endpoint h = (x, y, 1): its gradient in the line
        # is (sign / |line[:2]|) (h - d (unit[:2], 0)), unit the signed normalised line.
        g = np.empty(d.shape + (3,))
        g[..., 0, :2] = s[..., 0:2] - unit[..., :2] * d0[..., None]
        g[..., 1, :2] = s[..., 2:4] - unit[..., :2] * d1[..., None]
        g[..., 2] = 1.0
        return d, g * scale[..., None, None]

    def jacobian(self, R: np.ndarray, t: np.ndarray, P: np.ndarray, Q: np.ndarray,
                 basis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The residuals (N, 8) and their exact derivatives: in the motion (N, 8, 6: a rotation
        vector applied on the left, then t) and in each line's own parameters (N, 8, 4: P and Q
        moved along ``basis`` (N, 2, 3))."""
        n = len(P)
        rotated, x, line = self._projected(R, t, P, Q)
        d, g = self._distances(line, gradient=True)  # g: (2, 2, N, 2 endpoints, 3)
        # d(x_P x x_Q) / dx_P = -[x_Q]x, / dx_Q = [x_P]x: gradients in the projected points,
        # then (x = M X + m) in the 3D points of each frame (frame b: the moved ones)
        g = np.stack([cross(x[:, :, 1, :, None], g), cross(g, x[:, :, 0, :, None])])  # (2 points, 2, 2, N, 2, 3)
        G = g @ self.Mt[:, 0].transpose(0, 2, 1)[:, None]
        jm = np.zeros((2, 2, n, 2, 6))
        # frame b: X' = R X + t, dX'/dw = -[R X]x (left perturbation), dX'/dt = I
        jm[1, ..., :3] = cross(rotated[:, None, :, None], G[:, 1]).sum(axis=0)
        jm[1, ..., 3:] = G[0, 1] + G[1, 1]
        G[:, 1] = G[:, 1] @ R  # in frame a's points
        jl = (G @ basis.transpose(0, 2, 1)).transpose(1, 2, 3, 4, 0, 5).reshape(2, 2, n, 2, 4)
        order = (2, 0, 1, 3)  # (frame, camera, N, endpoint) -> (N, frame, camera, endpoint)
        return (d.transpose(order).reshape(n, 8), jm.transpose(*order, 4).reshape(n, 8, 6),
                jl.transpose(*order, 4).reshape(n, 8, 4))


def refine(lines: LineSet, motion: Motion, options: RefineOptions | None = None) -> Motion:
    options = options or RefineOptions()
    if len(lines) < 2:
        return motion
    problem = _Problem(lines)
    R, t = motion.R.copy(), motion.t.copy()
    P, Q = _points_on_lines(lines, triangulated_lines(lines, R, t))
    basis = _normal_basis(P, Q)  # remade after each step: small moves stay normal to the line to first order

    def states(dm: np.ndarray, dl: np.ndarray):
        """The motion and lines after a step dm (6: rotation vector, t) and dl (N, 4)."""
        P1 = P + dl[:, 0, None] * basis[:, 0] + dl[:, 1, None] * basis[:, 1]
        Q1 = Q + dl[:, 2, None] * basis[:, 0] + dl[:, 3, None] * basis[:, 1]
        return rodrigues(dm[:3]) @ R, t + dm[3:], P1, Q1

    def weighted(r: np.ndarray) -> tuple[np.ndarray, float]:
        a = np.abs(r)
        w = np.where(a <= options.loss_scale_px, 1.0, options.loss_scale_px / np.maximum(a, 1e-300))
        cost = np.where(a <= options.loss_scale_px, 0.5 * r * r,
                        options.loss_scale_px * (a - 0.5 * options.loss_scale_px)).sum()
        return np.sqrt(w), float(cost)

    r = problem.residuals(R, t, P, Q)
    sw, cost = weighted(r)
    damping = 1e-3
    eye4 = np.eye(4)
    for _ in range(options.max_iterations):
        _, Jm, Jl = problem.jacobian(R, t, P, Q, basis)  # (N, 8, 6), (N, 8, 4)
        J = np.concatenate([Jm, Jl], axis=2) * sw[:, :, None]  # (N, 8, 10): motion, then the line's own
        H = J.transpose(0, 2, 1) @ J  # (N, 10, 10): each line's share of the normal equations
        g = (J.transpose(0, 2, 1) @ (r * sw)[:, :, None])[:, :, 0]  # (N, 10)
        U, W, V = H[:, 6:, 6:], H[:, :6, 6:], H[:, :6, :6].sum(axis=0)  # (N, 4, 4), (N, 6, 4), (6, 6)
        gm, gl = g[:, :6].sum(axis=0), g[:, 6:]
        diagonal = np.einsum("nii->ni", U)[:, :, None] * eye4 + 1e-12 * eye4
        improved = converged = False
        for _ in range(8):
            Ui = np.linalg.inv(U + damping * diagonal)
            WUi = W @ Ui  # (N, 6, 4)
            S = V + damping * np.diag(np.diag(V)) - np.tensordot(WUi, W, axes=([0, 2], [0, 2]))  # Schur
            dm = -np.linalg.solve(S, gm - np.tensordot(WUi, gl, axes=([0, 2], [0, 1])))
            dl = -(Ui @ (gl + (dm @ W))[:, :, None])[:, :, 0]
            R1, t1, P1, Q1 = states(dm, dl)
            r1 = problem.residuals(R1, t1, P1, Q1)
            sw1, cost1 = weighted(r1)
            if np.isfinite(cost1) and cost1 < cost:
                converged = cost - cost1 < options.tolerance * cost
                R, t, P, Q, r, sw, cost = R1, t1, P1, Q1, r1, sw1, cost1
                basis = _normal_basis(P, Q)
                damping = max(damping / 10, 1e-9)
                improved = True
                break
            damping *= 10
        if not improved or converged:
            break
    return Motion(R, t, float(np.sqrt(np.mean(r * r))))

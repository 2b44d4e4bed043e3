"""The optional within-frame refinement: a two-frame bundle adjustment of a frame pair's inlier
lines. Unknowns: the motion (a rotation vector about the estimate, and t) and each line (two
points, each with its inverse depth and a move across the line in the first image: 4 parameters,
the line's own degrees of freedom); residuals: the distances of the segments' endpoints in the four
views to the projected lines (pixels), Huber-weighted at the RANSAC threshold. Levenberg-Marquardt
on the normal equations with the lines eliminated (Schur complement, 4x4 blocks); the Jacobian
exact (the chain rule through the projected lines, every line's block at once: lines do not
interact). The lines start from their triangulation from all four views under the RANSAC motion
(geometry.triangulated_lines).

Why inverse depth: a point is the homogeneous (x/z, y/z, 1, 1/z), so its projections into all four
views are linear in its parameters (only the line through two projections and the distances to it
are not). With the points moved in Euclidean coordinates, the depths of a 7.4 cm baseline made the
problem curved enough that the adjustment converged linearly (the cost's excess falling by a
factor of about 0.6 to 0.8 an iteration) and stopped at its 12 iterations short of the optimum on
some pairs. A depth chart needs a start in front of the rig instead: the algebraic triangulation
puts some points behind the cameras or tens of metres off (a line's planes nearly coincide at this
baseline), and from there a point would have to pass through infinity, where its projected line
turns over (started there, 7 of the first 11 pairs of the bench's sequence ended at a higher cost
than the Euclidean adjustment's).
Such points start at the scene's typical depth on their ray, and steps keep every inverse depth
within a factor DEPTH_BOUND of the scene's. Measured on bench/stereo_lines.py's sequences: see
docs/benchmarks.md (issue 37)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.solvers.lines.geometry import LineSet, cross, rodrigues, segment_lines, triangulated_lines
from geocert.solvers.lines.results import Motion


@dataclass
class RefineOptions:
    max_iterations: int = 8
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
    degenerate = np.linalg.norm(Q - P, axis=1) < 1e-9 * lines.depth  # coincident, at the scene's scale
    Q[degenerate] = P[degenerate] + direction[degenerate]
    return P, Q


START_RANGE = 5.0  # a start point nearer than the scene's depth over this, or farther than it times this, is reset
DEPTH_BOUND = 100.0  # every inverse depth stays within this factor of the scene's


def _inverse_depth(P: np.ndarray, depth: float) -> np.ndarray:
    """Euclidean points (N, 3) of frame a as homogeneous (N, 4) ones scaled to (x/z, y/z, 1, 1/z):
    a point's projections are linear in these coordinates, and the last is its inverse depth. A
    point behind the camera, or nearer or farther than START_RANGE allows about the scene's
    ``depth``, is put at that depth on its ray."""
    z = P[:, 2:3]
    safe = np.where(z == 0, 1.0, z)
    out = np.concatenate([P / safe, 1.0 / safe], axis=1)
    out[(z[:, 0] < depth / START_RANGE) | (z[:, 0] > START_RANGE * depth), 3] = 1.0 / depth
    return out


def _lateral(P: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """(N, 3) the unit direction, in the left image's normalised coordinates (third entry 0),
    normal to the image line through the points P and Q (N, 4, in _inverse_depth's form)."""
    d = Q[:, :2] - P[:, :2]
    norm = np.hypot(d[:, 0], d[:, 1])
    norm[norm == 0] = 1.0
    out = np.zeros((len(P), 3))
    out[:, 0], out[:, 1] = -d[:, 1] / norm, d[:, 0] / norm
    return out


def _start(lines: LineSet, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each line's two points (N, 4 each; _inverse_depth's form) from its triangulation under the
    motion (R, t)."""
    return tuple(_inverse_depth(X, lines.depth) for X in _points_on_lines(lines, triangulated_lines(lines, R, t)))


class _Problem:
    """The residuals and their Jacobian, every line at once (the per-call overhead of numpy
    dominates at a hundred lines). A line is two homogeneous points P, Q (N, 4) of frame a."""

    def __init__(self, lines: LineSet):
        cameras = np.stack(lines.rig.cameras())  # (2, 3, 4): left, right
        self.M = cameras[:, :, :3]  # (2 cameras, 3, 3)
        self.Mt = self.M.transpose(0, 2, 1)[:, None]  # (2 cameras, 1, 3, 3)
        self.m = cameras[:, :, 3]  # (2 cameras, 3): x = M X + m w
        n = len(lines)
        self.segments = lines.segments.transpose(1, 0, 2).reshape(2, 2, n, 4)
        observed = segment_lines(lines.segments.reshape(-1, 4)).reshape(n, 4, 3)
        self.orientation = observed[:, :, :2].transpose(1, 0, 2).reshape(2, 2, n, 2)
        self._kept = None

    def _projected(self, R: np.ndarray, t: np.ndarray, P: np.ndarray, Q: np.ndarray):
        """The points' Euclidean parts rotated by R (2 points, N, 3), their projections (2 frames,
        2 cameras, 2 points, N, 3) and the projected lines (2, 2, N, 3); the last state's kept."""
        kept = self._kept
        if kept is not None and kept[0] is R and kept[1] is t and kept[2] is P and kept[3] is Q:
            return kept[4]
        points = np.stack([P, Q])  # (2 points, N, 4)
        p, w = points[..., :3], points[..., 3:]
        rotated = p @ R.T
        X = np.stack([p, rotated + w * t])  # (2 frames, 2 points, N, 3)
        x = X[:, None] @ self.Mt[None] + self.m[None, :, None, None, :] * w[None, None]
        out = rotated, x, cross(x[:, :, 0], x[:, :, 1])
        self._kept = (R, t, P, Q, out)
        return out

    def residuals(self, R: np.ndarray, t: np.ndarray, P: np.ndarray, Q: np.ndarray) -> np.ndarray:
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
                 lateral: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The residuals (N, 8) and their exact derivatives: in the motion (N, 8, 6: a rotation
        vector applied on the left, then t) and in each line's own parameters (N, 8, 4: P moved
        along ``lateral`` (N, 3) and in its inverse depth, then Q)."""
        n = len(P)
        rotated, x, line = self._projected(R, t, P, Q)
        d, g = self._distances(line, gradient=True)  # g: (2, 2, N, 2 endpoints, 3)
        gx = np.stack([cross(x[:, :, 1, :, None], g), cross(g, x[:, :, 0, :, None])])  # (2 points, 2, 2, N, 2, 3)
        G = gx @ self.M[:, None]  # in each frame's point (its Euclidean part)
        Gw = gx @ self.m[:, None, :, None]  # (2 points, 2, 2, N, 2, 1): in its last coordinate
        w = np.stack([P[:, 3], Q[:, 3]])[:, None, :, None]  # (2 points, 1, N, 1)
        jm = np.zeros((2, 2, n, 2, 6))
        # frame b: X' = (R p + w t, w): dX'/dw = -[R p]x (left perturbation), dX'/dt = w I
        jm[1, ..., :3] = cross(rotated[:, None, :, None], G[:, 1]).sum(axis=0)
        jm[1, ..., 3:] = (G[:, 1] * w[..., None]).sum(axis=0)
        Gw[:, 1] += G[:, 1] @ t[:, None]
        G[:, 1] = G[:, 1] @ R  # in frame a's points
        jl = np.concatenate([G @ lateral[:, :, None], Gw], axis=5)  # (2 points, 2, 2, N, 2, 2)
        jl = jl.transpose(1, 2, 3, 4, 0, 5).reshape(2, 2, n, 2, 4)
        order = (2, 0, 1, 3)
        return (d.transpose(order).reshape(n, 8), jm.transpose(*order, 4).reshape(n, 8, 6),
                jl.transpose(*order, 4).reshape(n, 8, 4))


def refine(lines: LineSet, motion: Motion, options: RefineOptions | None = None) -> Motion:
    options = options or RefineOptions()
    if len(lines) < 2:
        return motion
    problem = _Problem(lines)
    R, t = motion.R.copy(), motion.t.copy()
    P, Q = _start(lines, R, t)
    lateral = _lateral(P, Q)  # kept: any direction across the line's first image serves

    def states(dm: np.ndarray, dl: np.ndarray):
        """The motion and lines after a step dm (6: rotation vector, t) and dl (N, 4)."""
        P1, Q1 = P.copy(), Q.copy()
        P1[:, :3] += dl[:, 0, None] * lateral
        P1[:, 3] += dl[:, 1]
        Q1[:, :3] += dl[:, 2, None] * lateral
        Q1[:, 3] += dl[:, 3]
        for X in (P1, Q1):  # in front of the rig, not through infinity (a projected line would turn over)
            X[:, 3] = np.clip(X[:, 3], 1 / (DEPTH_BOUND * lines.depth), DEPTH_BOUND / lines.depth)
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
        _, Jm, Jl = problem.jacobian(R, t, P, Q, lateral)  # (N, 8, 6), (N, 8, 4)
        J = np.concatenate([Jm, Jl], axis=2) * sw[:, :, None]  # (N, 8, 10): motion, then the line's own
        H = J.transpose(0, 2, 1) @ J  # (N, 10, 10): each line's share of the normal equations
        g = (J.transpose(0, 2, 1) @ (r * sw)[:, :, None])[:, :, 0]  # (N, 10)
        U, W, V = H[:, 6:, 6:], H[:, :6, 6:], H[:, :6, :6].sum(axis=0)  # (N, 4, 4), (N, 6, 4), (6, 6)
        gm, gl = g[:, :6].sum(axis=0), g[:, 6:]
        entries = np.einsum("nii->ni", U)  # damping floor: a share of each line's largest, not a unit's worth
        diagonal = (entries + 1e-12 * entries.max(axis=1, keepdims=True))[:, :, None] * eye4
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
                damping = max(damping / 10, 1e-9)
                improved = True
                break
            damping *= 10
        if not improved or converged:
            break
    return Motion(R, t, float(np.sqrt(np.mean(r * r))))

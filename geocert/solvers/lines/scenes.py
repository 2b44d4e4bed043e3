"""Synthetic stereo line scenes with known motion: the tests', the benchmark's and the kind's
example. A rig like the thesis's (7.4 cm baseline, wide field of view), lines in front of it, and
their segments in the four views of each frame pair (pixels, optional noise on the endpoints)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.solvers.lines.geometry import Rig, rodrigues

WIDTH, HEIGHT = 640, 480


def thesis_rig(baseline: float = 0.074, focal: float = 320.0) -> Rig:
    """Horizontal baseline, identical cameras, 90 degrees horizontal field of view."""
    K = np.array([[focal, 0, WIDTH / 2], [0, focal, HEIGHT / 2], [0, 0, 1.0]])
    return Rig(K, K.copy(), np.eye(3), np.array([-baseline, 0.0, 0.0]))


def random_lines(rng, count: int, depth=(2.0, 6.0), spread: float = 1.5, length=(0.5, 1.5)) -> np.ndarray:
    """(count, 2, 3) 3D segments (endpoints) in front of the origin."""
    centres = np.column_stack([rng.uniform(-spread, spread, count), rng.uniform(-spread, spread, count) * 0.75,
                               rng.uniform(*depth, count)])
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    half = rng.uniform(*length, count)[:, None] / 2
    return np.stack([centres - half * directions, centres + half * directions], axis=1)


def random_motion(rng, degrees: float = 3.0, metres: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    axis = rng.normal(size=3)
    R = rodrigues(np.radians(degrees) * axis / np.linalg.norm(axis))
    direction = rng.normal(size=3)
    return R, metres * direction / np.linalg.norm(direction)


def project(rig: Rig, X: np.ndarray, R: np.ndarray | None = None, t: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Segments (N, 4) in the left and right images of the 3D segments X (N, 2, 3), after the
    motion (R, t) when given (X_b = R X + t)."""
    if R is not None:
        X = X @ R.T + t
    out = []
    for P in rig.cameras():
        x = np.concatenate([X, np.ones(X.shape[:2] + (1,))], axis=2) @ P.T
        x = x[..., :2] / x[..., 2:]
        out.append(x.reshape(-1, 4))
    return out[0], out[1]


@dataclass
class PairScene:
    rig: Rig
    R: np.ndarray
    t: np.ndarray
    lines3d: np.ndarray  # (N, 2, 3) in frame a
    segments: np.ndarray  # (N, 4, 4): left a, right a, left b, right b (pixels)
    outliers: np.ndarray  # (N,) bool: lines whose frame-b views belong to another line


def pair_scene(rng, count: int, noise_px: float = 0.0, outlier_fraction: float = 0.0, degrees: float = 3.0,
               metres: float = 0.1, rig: Rig | None = None) -> PairScene:
    """Lines matched across a frame pair; an outlier's frame-b views are another 3D line's."""
    rig = rig or thesis_rig()
    R, t = random_motion(rng, degrees, metres)
    X = random_lines(rng, count)
    la, ra = project(rig, X)
    lb, rb = project(rig, X, R, t)
    outliers = np.zeros(count, dtype=bool)
    bad = int(round(outlier_fraction * count))
    if bad:
        outliers[rng.choice(count, bad, replace=False)] = True
        other = random_lines(rng, bad)
        lb[outliers], rb[outliers] = project(rig, other, R, t)
    segments = np.stack([la, ra, lb, rb], axis=1)
    if noise_px:
        segments = segments + rng.normal(scale=noise_px, size=segments.shape)
    return PairScene(rig, R, t, X, segments, outliers)


def sequence(rng, frames: int, count: int, noise_px: float = 0.0, degrees: float = 2.0, metres: float = 0.05,
             rig: Rig | None = None) -> tuple[Rig, list[tuple[np.ndarray, np.ndarray]], list[dict]]:
    """A static scene seen by a moving rig: the poses (X_k = R_k X_0 + t_k) and the segments per
    frame ({"left", "right"}: (N, 4) each, the same line order in every frame, lines behind the
    cameras dropped from no frame: the scene is kept in front)."""
    rig = rig or thesis_rig()
    X = random_lines(rng, count, depth=(3.0, 8.0))
    poses = [(np.eye(3), np.zeros(3))]
    for _ in range(frames - 1):
        R, t = random_motion(rng, degrees, metres)
        R0, t0 = poses[-1]
        poses.append((R @ R0, R @ t0 + t))
    out = []
    for R, t in poses:
        left, right = project(rig, X, R, t)
        if noise_px:
            left = left + rng.normal(scale=noise_px, size=left.shape)
            right = right + rng.normal(scale=noise_px, size=right.shape)
        out.append({"left": left, "right": right})
    return rig, poses, out

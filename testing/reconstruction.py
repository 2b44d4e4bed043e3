"""Reconstruction helpers shared by the tests and bench/reconstruction.py: rotation errors after
the best alignment, the Model House's tracks, and VGG's poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.linalg import rq

from geocert.solvers.datasets import load_house
from geocert.solvers.reconstruction import upgrade
from geocert.solvers.reconstruction.tracks import Observations


def aligned_rotation_errors(estimated: list[np.ndarray], truth: list[np.ndarray]) -> np.ndarray:
    """Degrees between R_i Q and the true R_i, Q the rotation aligning the frames best."""
    M = sum(a.T @ b for a, b in zip(estimated, truth))
    U, _, Vt = np.linalg.svd(M)
    Q = U @ np.diag([1, 1, np.linalg.det(U @ Vt)]) @ Vt
    return np.array([np.degrees(np.arccos(np.clip((np.trace((a @ Q).T @ b) - 1) / 2, -1, 1)))
                     for a, b in zip(estimated, truth)])


def house_tracks(folder: Path):
    """The Oxford Model House (``folder``): VGG's cameras, its points seen twice or more, and
    their tracks (views, pixels)."""
    cameras, points, views = load_house(folder)
    by_point: dict[int, list] = {}
    for v, seen in enumerate(views):
        for index, pixel in zip(seen.point_indices, seen.pixels):
            by_point.setdefault(int(index), []).append((v, pixel))
    keys = [k for k, seen in sorted(by_point.items()) if len(seen) >= 2]
    tracks = [(np.array([v for v, _ in by_point[k]]), np.array([p for _, p in by_point[k]])) for k in keys]
    return cameras, points[keys], tracks


def vgg_pose(P: np.ndarray):
    P = P * np.sign(np.linalg.det(P[:, :3]))
    K, R = rq(P[:, :3])
    D = np.diag(np.sign(np.diag(K)))
    K, R = K @ D, D @ R
    return K / K[2, 2], R, np.linalg.solve(K, P[:, 3])


def vgg_refit(cameras, points, tracks, image_size=(768, 576)):
    """VGG's own House reconstruction adjusted under our camera model (one focal length, square
    pixels, the principal point at the image's centre), started from VGG's mean focal length and
    their cameras' rotations, translations and points: the reference that model can be held to."""
    poses = [vgg_pose(P) for P in cameras]
    f = np.mean([K[0, 0] for K, _, _ in poses])
    cx, cy = image_size[0] / 2, image_size[1] / 2
    start = upgrade.Metric(np.array([[f, 0, cx], [0, f, cy], [0, 0, 1]]), [R for _, R, _ in poses],
                           [t for _, _, t in poses], points.copy(), [], False)
    obs = Observations.from_tracks(tracks, len(cameras))
    return upgrade.adjust(start, obs.view, obs.track, obs.pixel, 2.0)[0]

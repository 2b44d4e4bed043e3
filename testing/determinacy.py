"""Cameras and projections for the determinacy tests and bench/determinacy.py."""

from __future__ import annotations

import numpy as np

from geocert.solvers.autocalibration import scenes


def cameras_looking_at_origin(centres: np.ndarray) -> np.ndarray:
    K = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    rng = np.random.default_rng(0)
    return np.array([K @ np.hstack([R, -(R @ c)[:, None]]) for c in centres
                     for R in [scenes.look_at(c, np.zeros(3), rng, up=np.array([0.0, 1.0, 0.0]))]])


def project(cameras, X):
    x = cameras @ np.append(X, 1.0)
    return x[:, :2] / x[:, 2:3]

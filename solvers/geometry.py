"""Small projective-geometry helpers shared by the solvers and the input checks."""

from __future__ import annotations

import numpy as np


class InputError(ValueError):
    """Bad problem data; ``field`` names where (a JSON-pointer-like path), the message says why."""

    def __init__(self, field: str, reason: str):
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


def check_cameras(cameras: np.ndarray, field: str = "cameras") -> np.ndarray:
    """Return cameras as an (N, 3, 4) float array, or raise InputError naming the bad camera."""
    cams = np.asarray(cameras, dtype=float)
    if cams.ndim != 3 or cams.shape[1:] != (3, 4):
        raise InputError(field, f"expected a list of 3x4 matrices, got shape {list(cams.shape)}")
    if cams.shape[0] == 0:
        raise InputError(field, "at least one camera is required")
    for i, cam in enumerate(cams):
        if not np.all(np.isfinite(cam)):
            raise InputError(f"{field}/{i}", "contains a non-finite number")
        singular = np.linalg.svd(cam, compute_uv=False)
        if singular[0] == 0 or singular[2] <= 1e-12 * singular[0]:
            raise InputError(f"{field}/{i}", "camera matrix is rank-deficient (rank < 3)")
        if np.linalg.norm(cam[2, :3]) == 0 and cam[2, 3] == 0:
            raise InputError(f"{field}/{i}", "camera has a zero depth row")
    return cams


def fundamental_from_cameras(P1: np.ndarray, P2: np.ndarray) -> np.ndarray:
    """F with x2' F x1 = 0 for the two cameras (Hartley & Zisserman, eq. 9.1)."""
    _, _, vt = np.linalg.svd(P1)
    centre = vt[-1]
    epipole = P2 @ centre
    skew = np.array([[0, -epipole[2], epipole[1]], [epipole[2], 0, -epipole[0]], [-epipole[1], epipole[0], 0]])
    return skew @ P2 @ np.linalg.pinv(P1)


def reprojection_residuals(cameras: np.ndarray, X: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(k, 2) residuals of homogeneous X in cameras (k, 3, 4) against points (k, 2), in pixels."""
    proj = cameras @ X
    return proj[:, :2] / proj[:, 2:3] - points


def depths(cameras: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Third coordinate of P X, with X's sign fixed so that its last coordinate is not negative."""
    X = X if X[3] >= 0 else -X
    return cameras[:, 2, :] @ X


def lengths(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """np.linalg.norm(x, axis=axis) for real x (the same sums), without its argument handling:
    the hot paths call it on small arrays."""
    return np.sqrt((x * x).sum(axis=axis))


def norm_cost(residuals: np.ndarray, norm: str) -> float:
    # Method calls rather than np.sum and np.linalg.norm: the same sums, a few microseconds less
    # on the small arrays of a triangulation's inner loop.
    if norm == "L2L2":
        return float((residuals * residuals).sum())
    if norm == "L2L1":
        return float(lengths(residuals, 1).sum())
    if norm == "L1L1":
        return float(np.abs(residuals).sum())
    raise ValueError(f"unknown norm {norm!r}")

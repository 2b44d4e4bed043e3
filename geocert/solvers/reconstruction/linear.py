"""Linear estimates of the projective stage, in Hartley-normalised image coordinates: the
fundamental matrix of the initial pair (OpenCV's RANSAC), the canonical camera pair it
determines, DLT triangulation and DLT resection with RANSAC (Hartley and Zisserman, ch. 9-12)."""

from __future__ import annotations

import numpy as np

from geocert.solvers.reconstruction.tracks import project


def skew(e: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -e[2], e[1]], [e[2], 0.0, -e[0]], [-e[1], e[0], 0.0]])


def fundamental_ransac(x1: np.ndarray, x2: np.ndarray, threshold: float, seed: int = 0):
    """F (x2' F x1 = 0) and the inlier mask, by OpenCV's RANSAC with the 8-point method
    (threshold in the coordinates given)."""
    import cv2

    if len(x1) < 8:
        return None, np.zeros(len(x1), dtype=bool)
    cv2.setRNGSeed(seed)
    F, mask = cv2.findFundamentalMat(x1.astype(np.float64), x2.astype(np.float64), cv2.FM_RANSAC, threshold,
                                     0.999, 5000)
    if F is None or F.shape != (3, 3):
        return None, np.zeros(len(x1), dtype=bool)
    return F, mask.ravel().astype(bool)


def homography_inliers(x1: np.ndarray, x2: np.ndarray, threshold: float) -> int:
    """How many matches one homography explains (a pair a homography explains as well as F is a
    degenerate start: rotation only, or a plane)."""
    import cv2

    if len(x1) < 4:
        return len(x1)
    H, mask = cv2.findHomography(x1.astype(np.float64), x2.astype(np.float64), cv2.RANSAC, threshold)
    return 0 if mask is None else int(mask.sum())


def cameras_from_fundamental(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The canonical pair P1 = [I | 0], P2 = [[e']_x F | e'] (Hartley and Zisserman, result 9.14)."""
    e2 = np.linalg.svd(F.T)[2][-1]
    P2 = np.hstack([skew(e2) @ F, e2[:, None]])
    return np.hstack([np.eye(3), np.zeros((3, 1))]), P2


def triangulate(cameras: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Homogeneous X (unit norm) from k >= 2 views by the DLT (cameras (k, 3, 4), pixels (k, 2))."""
    rows = np.concatenate([pixels[:, 0:1] * cameras[:, 2] - cameras[:, 0],
                           pixels[:, 1:2] * cameras[:, 2] - cameras[:, 1]])
    return np.linalg.svd(rows)[2][-1]


def triangulate_pairs(P1: np.ndarray, P2: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """Many points from two views at once (k, 4)."""
    A = np.stack([x1[:, 0:1] * P1[2] - P1[0], x1[:, 1:2] * P1[2] - P1[1],
                  x2[:, 0:1] * P2[2] - P2[0], x2[:, 1:2] * P2[2] - P2[1]], axis=1)
    return np.linalg.svd(A)[2][:, -1]


def resect(X: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The DLT camera (3x4) from homogeneous X (k, 4) and pixels x (k, 2), k >= 6."""
    k = len(X)
    A = np.zeros((2 * k, 12))
    A[0::2, 0:4] = -X
    A[0::2, 8:12] = x[:, 0:1] * X
    A[1::2, 4:8] = -X
    A[1::2, 8:12] = x[:, 1:2] * X
    # The smallest eigenvector of A^T A (12 x 12): the DLT's answer, cheaper than an SVD of A.
    return np.linalg.eigh(A.T @ A)[1][:, 0].reshape(3, 4)


def reprojection_errors(P: np.ndarray, X: np.ndarray, x: np.ndarray) -> np.ndarray:
    image, _ = project(P, X)
    errors = np.linalg.norm(image - x, axis=1)
    return np.where(np.isfinite(errors), errors, np.inf)


def resect_ransac(X: np.ndarray, x: np.ndarray, threshold: float, iterations: int = 300,
                  seed: int = 0) -> tuple[np.ndarray | None, np.ndarray]:
    """A camera from 3D-2D matches with outliers: 6-point DLT samples, the largest consensus
    refitted by the DLT on its inliers (twice, the second time with the refit's inliers)."""
    k = len(X)
    if k < 6:
        return None, np.zeros(k, dtype=bool)
    rng = np.random.default_rng(seed)
    best = np.zeros(k, dtype=bool)
    for _ in range(iterations):
        sample = rng.choice(k, 6, replace=False)
        P = resect(X[sample], x[sample])
        inliers = reprojection_errors(P, X, x) < threshold
        if inliers.sum() > best.sum():
            best = inliers
            if best.mean() > 0.9:
                break
    if best.sum() < 6:
        return None, best
    for _ in range(2):
        P = resect(X[best], x[best])
        refit = reprojection_errors(P, X, x) < threshold
        if refit.sum() < 6:
            break
        best = refit
    return P, best

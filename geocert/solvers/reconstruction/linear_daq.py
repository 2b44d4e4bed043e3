"""A linear estimate of the absolute dual quadric (Pollefeys, Verbiest and Van Gool, "Surviving
dominant planes in uncalibrated structure and motion recovery", ECCV 2002, section 3; the
weighted linear self-calibration of Hartley and Zisserman, 19.3): with image coordinates centred
and scaled, each view's DIAC P Q P' is nearly diag(f^2, f^2, 1) (square pixels, no skew, the
principal point near the centre), four linear equations in Q's ten entries per view, weighted
by how much each prior may be trusted. Not certified: a second starting point for the metric
bundle adjustment, beside the certified autocalibration's answer, which on near-critical motions
(a turntable) or varying intrinsics (VGG's Model House) can lie far from the cameras' true K."""

from __future__ import annotations

import numpy as np

PAIRS = [(i, j) for i in range(4) for j in range(i, 4)]


def _rows(P: np.ndarray) -> np.ndarray:
    """Each entry (a, b) of P Q P' as a row over Q's ten upper-triangle entries."""
    out = np.zeros((3, 3, 10))
    for k, (i, j) in enumerate(PAIRS):
        E = np.zeros((4, 4))
        E[i, j] = E[j, i] = 1.0
        out[:, :, k] = P @ E @ P.T
    return out


def quadric(cameras: np.ndarray, image_size) -> np.ndarray | None:
    """Q (4x4, rank 3, positive semidefinite, unit norm) in the cameras' frame, or None."""
    w, h = image_size
    s = float(w + h)
    N = np.array([[1 / s, 0.0, -w / (2 * s)], [0.0, 1 / s, -h / (2 * s)], [0.0, 0.0, 1.0]])
    Ps = [N @ P for P in cameras]
    Ps = [P / np.linalg.norm(P) for P in Ps]
    weights = np.ones(len(Ps))
    Q = None
    for _ in range(2):  # the second pass weights each view by its estimated depth scale
        rows = []
        for P, nu in zip(Ps, weights):
            R = _rows(P) / nu
            rows += [(R[0, 0] - R[2, 2]) / 9, (R[1, 1] - R[2, 2]) / 9, (R[0, 0] - R[1, 1]) / 0.2,
                     R[0, 1] / 0.1, R[0, 2] / 0.1, R[1, 2] / 0.01]
        q = np.linalg.svd(np.array(rows))[2][-1]
        Q = np.zeros((4, 4))
        for k, (i, j) in enumerate(PAIRS):
            Q[i, j] = Q[j, i] = q[k]
        values, V = np.linalg.eigh(Q)
        if np.sum(values > 0) < np.sum(values < 0):
            Q, values = -Q, -values[::-1]
            V = V[:, ::-1]
        values = np.maximum(values, 0.0)
        order = np.argsort(values)
        values[order[0]] = 0.0  # rank 3
        Q = (V * values) @ V.T
        depth = np.array([P[2] @ Q @ P[2] for P in Ps])
        if not np.all(depth > 0):
            return None
        weights = depth
    return Q / np.linalg.norm(Q)

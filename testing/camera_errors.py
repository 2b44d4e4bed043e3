"""Estimated cameras against reference cameras, up to the similarity a reconstruction cannot fix
(numpy only, no geocert import).

Rotations: the world rotation A with R_est A closest to R_true over the views compared (chordal L2
mean, projected on SO(3)), then each view's angle between R_est A and R_true; rotations do not see
the world's translation and scale, so this is the rotation part of a similarity alignment.
Centres: the similarity (Umeyama 1991: scale, rotation, shift) taking the estimated centres
closest to the true ones in least squares, then each centre's distance, as a percentage of the
true centres' RMS distance from their mean (the scene's size as the cameras see it).
"""

from __future__ import annotations

import numpy as np


def rotation_angle_deg(R: np.ndarray) -> float:
    """R's angle of rotation in degrees: atan2 of its sine (half the skew part's size) and cosine
    (from the trace). The cosine alone cannot resolve angles below 8.5e-7 degrees (one rounding of
    a trace near 3): rotations right to 1e-16 read 0 or 1.2e-6 degrees by the rounding's path."""
    sine = 0.5 * np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return float(np.degrees(np.arctan2(sine, 0.5 * (np.trace(R) - 1.0))))


def align_rotations(estimated: list[np.ndarray], truth: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(A, degrees per view): see the module's docstring."""
    M = sum(Re.T @ Rt for Re, Rt in zip(estimated, truth))
    U, _, Vt = np.linalg.svd(M)
    A = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    return A, np.array([rotation_angle_deg((Re @ A).T @ Rt) for Re, Rt in zip(estimated, truth)])


def align_centers(estimated: np.ndarray, truth: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Umeyama's similarity (s, Q, shift) with s Q c_est + shift closest to c_true, and each
    centre's distance after it (in the truth's units)."""
    estimated, truth = np.asarray(estimated, float), np.asarray(truth, float)
    mu_e, mu_t = estimated.mean(axis=0), truth.mean(axis=0)
    E, T = estimated - mu_e, truth - mu_t
    U, S, Vt = np.linalg.svd(T.T @ E / len(E))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    Q = U @ D @ Vt
    variance = (E ** 2).sum() / len(E)
    s = float(np.trace(np.diag(S) @ D) / variance) if variance > 0 else 1.0
    shift = mu_t - s * Q @ mu_e
    distances = np.linalg.norm((s * (Q @ estimated.T)).T + shift - truth, axis=1)
    return s, Q, shift, distances


def compare(estimated: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]], truth: dict) -> dict:
    """Figures of the estimated cameras {name: (K, R, t)} against the reference cameras {name:
    photo_sets.Camera (or anything with K, R, t)} on the names both have: rotation errors (median,
    max, how many above 5 degrees), centre errors (median, max, % of the scene's size; 3 views or
    more), focal length error (median over views of f_est / f_true - 1, %, f the mean of fx and
    fy) and principal point error (median, pixels)."""
    names = [n for n in estimated if n in truth]
    out = {"compared": len(names)}
    if not names:
        return out
    if truth[names[0]].R is not None:
        _, errors = align_rotations([estimated[n][1] for n in names], [truth[n].R for n in names])
        out.update(rotation_median_deg=float(np.median(errors)), rotation_max_deg=float(errors.max()),
                   rotation_over_5deg=int(np.sum(errors > 5.0)), rotation_errors_deg=dict(zip(names, errors.tolist())))
        if len(names) >= 3:
            centres = np.array([-estimated[n][1].T @ estimated[n][2] for n in names])
            true_centres = np.array([-truth[n].R.T @ truth[n].t for n in names])
            _, _, _, distances = align_centers(centres, true_centres)
            size = float(np.sqrt(((true_centres - true_centres.mean(axis=0)) ** 2).sum(axis=1).mean()))
            out.update(center_median_pct=float(100 * np.median(distances) / size),
                       center_max_pct=float(100 * distances.max() / size))
    focal = [((estimated[n][0][0, 0] + estimated[n][0][1, 1]) / (truth[n].K[0, 0] + truth[n].K[1, 1]) - 1) * 100
             for n in names]
    principal = [np.linalg.norm(estimated[n][0][:2, 2] - truth[n].K[:2, 2]) for n in names]
    out.update(focal_error_pct=float(np.median(focal)), principal_point_error_px=float(np.median(principal)))
    return out

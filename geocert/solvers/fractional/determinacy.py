"""How well a track or a map is fixed by its data (core/determinacy.py): intervals for what a user
reads off the answer, and the degeneracies recognised.

- A track: the point's coordinates and its distance from the first view's centre (depth along
  that ray); warned when the rays meet at a near-zero angle (parallax), or the point is at
  infinity (no interval then).
- A resection: the camera centre; warned when the 3D points are nearly coplanar, or when the
  points and the centre lie near a critical configuration (the camera is not fixed: a direction
  of the data's curvature is singular).
- A homography: the image of the source points' centroid; warned when the source or the target
  points are nearly collinear (coplanar, for maps of P^3).

The curvature is that of the squared reprojection errors whatever the norm solved for (for the
L1 norms, an estimate of the same kind: the intervals say how flat the fit is, not a confidence).
Maps are fixed up to scale: their parameters are the directions orthogonal to the answer."""

from __future__ import annotations

import numpy as np

from geocert.solvers.core.determinacy import (Determinacy, certified_gap, curvature_intervals, numeric_jacobian,
                                               spread)
from geocert.solvers.fractional.charts import camera_centres

PARALLAX_DEGREES = 1.0  # rays meeting at less than this: near-zero parallax
FLAT = 1e-2  # points whose centred spread along a direction is below this fraction: (nearly) flat


def _centres(cameras: np.ndarray) -> np.ndarray:
    """Euclidean centres (NaN for a camera whose centre is at infinity)."""
    C = camera_centres(cameras)
    finite = np.abs(C[:, 3:4]) > 1e-12 * np.abs(C).max(axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(finite, C[:, :3] / C[:, 3:4], np.nan)


def track(cameras: np.ndarray, points: np.ndarray, point: list[float] | None, at_infinity: bool,
          cost: float | None, lower: float | None) -> dict | None:
    if point is None:
        return None
    cameras = np.asarray(cameras, dtype=float)
    points = np.asarray(points, dtype=float)
    if at_infinity:
        out = Determinacy()
        out.warnings.append({"code": "at_infinity", "detail": "the point is at infinity: its depth is not fixed"})
        return out.document()
    X = np.asarray(point, dtype=float)

    def residuals(x):
        proj = cameras @ np.append(x, 1.0)
        return (proj[:, :2] / proj[:, 2:3] - points).ravel()

    proj = cameras @ np.append(X, 1.0)
    # d(pi)/dX = (P_1:2 - pi P_3) / y3, on the first three columns
    J = ((cameras[:, :2, :3] - (proj[:, :2] / proj[:, 2:3])[:, :, None] * cameras[:, 2:3, :3])
         / proj[:, 2:3, None]).reshape(-1, 3)
    centres = _centres(cameras)
    quantities = {name: (float(X[k]), np.eye(3)[k]) for k, name in enumerate(("x", "y", "z"))}
    if np.all(np.isfinite(centres[0])):
        ray = X - centres[0]
        length = float(np.linalg.norm(ray))
        if length > 0:
            quantities["depth_view0"] = (length, ray / length)
    out = curvature_intervals(J, residuals(X), quantities, certified_gap(cost, lower))
    rays = X[None, :] - centres
    rays = rays[np.all(np.isfinite(rays), axis=1)]
    if len(rays) >= 2:
        unit = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        cosines = np.clip(np.abs(unit @ unit.T), -1.0, 1.0)
        widest = float(np.degrees(np.arccos(cosines.min())))
        if widest < PARALLAX_DEGREES:
            out.warnings.append({"code": "near_zero_parallax",
                                 "detail": f"the rays meet at {widest:.3g} degrees at most (< {PARALLAX_DEGREES:g}): "
                                           "the depth along them is poorly fixed"})
    return out.document()


def _complement(M: np.ndarray) -> np.ndarray:
    """An orthonormal basis (columns) of the directions orthogonal to vec(M)."""
    v = M.ravel() / np.linalg.norm(M)
    return np.linalg.svd(v[None, :])[2][1:].T


def _normaliser(points: np.ndarray) -> np.ndarray:
    centre = points.mean(axis=0)
    scale = np.sqrt(2.0) / max(float(np.linalg.norm(points - centre, axis=1).mean()), 1e-300)
    T = np.eye(points.shape[1] + 1)
    T[:-1, :-1] *= scale
    T[:-1, -1] = -scale * centre
    return T


def map_(source: np.ndarray, target: np.ndarray, matrix: list[list[float]] | None, cost: float | None,
         lower: float | None) -> dict | None:
    if matrix is None:
        return None
    source = np.asarray(source, dtype=float)
    target = np.asarray(target, dtype=float)
    M = np.asarray(matrix, dtype=float)
    m, n1 = M.shape
    # Parameters in normalised coordinates (centroid 0, mean distance sqrt 2 on both sides), where
    # the map's entries are of one size: in pixels they span orders of magnitude, and J'J's
    # smallest eigenvalue would look singular for that reason alone.
    Ts, Tt = _normaliser(source), _normaliser(target)
    Tt_inv = np.linalg.inv(Tt)
    normalised = Tt @ M @ np.linalg.inv(Ts)
    normalised = normalised / np.linalg.norm(normalised)
    basis = _complement(normalised)
    source_h = np.hstack([source, np.ones((len(source), 1))])

    def matrix_of(theta):
        return Tt_inv @ (normalised + (basis @ theta).reshape(M.shape)) @ Ts

    def residuals(theta):
        image = source_h @ matrix_of(theta).T
        return (image[:, :-1] / image[:, -1:] - target).ravel()

    zero = np.zeros(basis.shape[1])
    J = numeric_jacobian(residuals, zero)
    quantities = {}
    if m == 3 and n1 == 4:  # resection: the camera centre
        def centre(theta):
            C = np.linalg.svd(matrix_of(theta))[2][-1]
            return C[:3] / C[3]

        value = centre(zero)
        gradient = numeric_jacobian(centre, zero)
        for k, name in enumerate(("centre_x", "centre_y", "centre_z")):
            quantities[name] = (float(value[k]), gradient[k])
    else:  # a homography: where the source points' centroid goes
        centroid = np.append(source.mean(axis=0), 1.0)

        def transfer(theta):
            image = matrix_of(theta) @ centroid
            return image[:-1] / image[-1]

        value = transfer(zero)
        gradient = numeric_jacobian(transfer, zero)
        names = ("centroid_image_x", "centroid_image_y", "centroid_image_z")
        for k in range(len(value)):
            quantities[names[k]] = (float(value[k]), gradient[k])
    out = curvature_intervals(J, residuals(zero), quantities, certified_gap(cost, lower))
    if m == 3 and n1 == 4:
        flat = spread(source)
        if flat[-1] < FLAT:
            out.warnings.append({"code": "near_coplanar_points",
                                 "detail": f"the 3D points are nearly coplanar (spread {flat[-1]:.2g} of their extent): "
                                           "the camera is poorly fixed off their plane"})
        if any(interval["lower"] is None for interval in out.intervals):  # a direction the data do not fix
            out.warnings.append({"code": "near_critical_configuration",
                                 "detail": "the points and the camera centre are near a configuration that does not fix "
                                           "the camera (coplanar points, or a twisted cubic through the centre)"})
    else:
        dims = source.shape[1]
        for name, pts in (("source", source), ("target", target)):
            flat = spread(pts)
            if flat[dims - 1] < FLAT:
                shape = "collinear" if dims == 2 else "coplanar"
                out.warnings.append({"code": f"near_{shape}_points",
                                     "detail": f"the {name} points are nearly {shape} (spread {flat[dims - 1]:.2g} of "
                                               "their extent): the map is poorly fixed off that line or plane"})
    return out.document()

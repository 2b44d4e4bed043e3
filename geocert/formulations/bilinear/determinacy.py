"""How well a frame's camera and coefficients are fixed by its points (core/determinacy.py):
intervals for each coefficient, and a warning when the basis shapes are nearly dependent on the
points seen (the coefficients are then not fixed by the image, whatever the optimum says).

Parameters: the 2x4 affine camera and the coefficients but the last (which makes their sum 1);
the curvature is that of the squared image residuals whatever the norm solved for. Constraints
(convex coefficients are >= 0) are not part of the curvature: an interval may reach below 0."""

from __future__ import annotations

import numpy as np

from geocert.core.determinacy import certified_gap, curvature_intervals, numeric_jacobian

DEPENDENT = 1e-3  # basis shapes whose differences' smallest singular value is below this fraction: nearly dependent


def frame(basis: np.ndarray, points: np.ndarray, camera, coefficients, cost: float | None,
          lower: float | None) -> dict | None:
    if camera is None or coefficients is None:
        return None
    basis = np.asarray(basis, dtype=float)
    points = np.asarray(points, dtype=float)
    visible = ~np.isnan(points[:, 0])
    X, u = basis[:, visible, :], points[visible]
    camera = np.asarray(camera, dtype=float)
    alpha = np.asarray(coefficients, dtype=float)
    k = len(alpha)

    def unpack(theta):
        free = theta[8:]
        return theta[:8].reshape(2, 4), np.append(free, 1.0 - free.sum())

    def residuals(theta):
        cam, a = unpack(theta)
        shape = np.einsum("i,ijk->jk", a, X)
        return (u - (shape @ cam[:, :3].T + cam[:, 3])).ravel()

    theta = np.concatenate([camera.ravel(), alpha[:-1]])
    J = numeric_jacobian(residuals, theta)
    quantities = {}
    for i in range(k):
        g = np.zeros(len(theta))
        if i < k - 1:
            g[8 + i] = 1.0
        else:
            g[8:] = -1.0
        quantities[f"coefficient[{i}]"] = (float(alpha[i]), g, 1.0)  # they sum to 1: each known to 0.1
    out = curvature_intervals(J, residuals(theta), quantities, certified_gap(cost, lower))
    if k > 1:
        differences = (X[1:] - X[0]).reshape(k - 1, -1)
        s = np.linalg.svd(differences, compute_uv=False)
        if s[-1] <= DEPENDENT * max(float(s[0]), 1e-300):
            out.warnings.append({"code": "near_dependent_basis",
                                 "detail": "the basis shapes are nearly dependent on the points seen: the "
                                           "coefficients are not fixed by the image"})
    return out.document()

"""How well a projective reconstruction fixes its metric upgrade (core/determinacy.py).

Critical motions (Sturm 1997; Kahl, Triggs and Astrom 2000) leave constant intrinsics
undetermined whatever the solver does. They are read off the infinite homographies of the plane
found, H_j ~ K R_j K^-1 (the reference view to view j): the angle of R_j is that of H_j's complex
eigenvalues (K cancels), and R_j's axis is K^-1 times H_j's real eigenvector, so views rotating
about one axis share that eigenvector a: (H_j / det(H_j)^(1/3) - I) a = 0 for every j. Warnings:
``pure_translation`` (the median angle below 3 degrees), ``rotation_about_one_axis`` (the stacked
H_j / det^(1/3) - I have their smallest singular value below 0.15 of the next: measured, 0.004 to
0.08 for turntable rings at 0.1% to 1% noise, 0.6 to 0.96 for cameras all round) and
``orbital_motion`` (one axis, and the camera centres nearly coplanar: a turntable or a ring).

Intervals: the affine stage's plane at infinity (input frame, unit norm) over the planes whose
modulus residuals cost at most ``cost_increase`` more; the metric stage's focal lengths, skew and
principal point (pixels) over the omega doing so for the metric cost."""

from __future__ import annotations

import math

import numpy as np

from geocert.solvers.autocalibration import frames
from geocert.solvers.autocalibration import metric_relaxation as mrelax
from geocert.solvers.core.determinacy import certified_gap, curvature_intervals, numeric_jacobian, spread

STILL_DEGREES = 3.0
AXIS_RATIO = 0.15
FLAT = 1e-2


def rotation_angles(H: np.ndarray) -> np.ndarray:
    """The rotation angle (degrees) of each H_j (m, 3, 3), from its eigenvalues' phases."""
    angles = []
    for Hj in H:
        det = np.linalg.det(Hj)
        values = np.linalg.eigvals(Hj / np.cbrt(det) if det != 0 else Hj)
        angles.append(float(np.degrees(np.abs(np.angle(values)).max())))
    return np.array(angles)


def motion_warnings(H: np.ndarray, centres: np.ndarray | None) -> list[dict]:
    angles = rotation_angles(H)
    if np.median(angles) < STILL_DEGREES:  # the median: noise alone turns a few views by degrees
        return [{"code": "pure_translation",
                 "detail": f"the views rotate by {np.median(angles):.2g} degrees from the reference (median; "
                           f"{angles.max():.2g} at most): the intrinsics are not fixed by a translating camera"}]
    stacked = np.vstack([Hj / np.cbrt(np.linalg.det(Hj)) - np.eye(3) for Hj in H if np.linalg.det(Hj) != 0])
    singular = np.linalg.svd(stacked, compute_uv=False)
    ratio = float(singular[2] / max(float(singular[1]), 1e-300))
    if len(H) < 2 or not ratio < AXIS_RATIO:
        return []
    if centres is not None and len(centres) >= 4 and np.all(np.isfinite(centres)) and spread(centres)[-1] < FLAT:
        return [{"code": "orbital_motion",
                 "detail": f"every rotation shares one axis (fit {ratio:.2g}) and the centres are nearly coplanar "
                           "(a turntable or a ring): a critical motion for constant intrinsics"}]
    return [{"code": "rotation_about_one_axis",
             "detail": f"every rotation shares one axis (fit {ratio:.2g}): a critical motion for constant intrinsics"}]


def affine_stage(problem, p: np.ndarray, cost: float | None, lower: float | None, centres: np.ndarray | None) -> dict:
    from geocert.solvers.autocalibration.problem import plane_in_input

    coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
    plane = plane_in_input(problem, p)  # as the result states it

    def plane_of(q):  # nearby planes with the returned plane's sign
        out = plane_in_input(problem, q)
        return out if out @ plane >= 0 else -out

    J = numeric_jacobian(lambda q: frames.modulus_residuals(coef, q), p)
    gradient = numeric_jacobian(plane_of, p)
    value = plane_of(p)
    quantities = {f"plane_at_infinity[{k}]": (float(value[k]), gradient[k]) for k in range(4)}
    out = curvature_intervals(J, frames.modulus_residuals(coef, p), quantities, certified_gap(cost, lower))
    H = mrelax.homographies(problem.norm.cameras, problem.norm.reference, p)
    out.warnings += motion_warnings(H, centres)
    return out.document()


def metric_stage(problem, p: np.ndarray, K_pixels: np.ndarray, cost: float | None, lower: float | None,
                 centres: np.ndarray | None) -> dict:
    from geocert.solvers.autocalibration.problem import upper_triangular_root, w_of_K

    setup = mrelax.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
    w = w_of_K(problem, K_pixels)

    def intrinsics(x):
        omega = mrelax.omega_of(x)
        if np.linalg.eigvalsh(omega)[0] <= 0:
            return np.full(5, np.nan)
        K = problem.K0 @ upper_triangular_root(omega)
        K = K / K[2, 2]
        return np.array([K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]])

    informative = np.concatenate([np.arange(5) + 6 * j for j in range(len(setup.H))])  # the 33 entry is 0

    def residuals(x, q=p):
        here = setup if q is p else mrelax.setup_for(problem.norm.cameras, problem.norm.reference, q,
                                                     problem.unit_ranges)
        return mrelax.residuals(here, x)[informative]

    J = numeric_jacobian(residuals, w)
    value = intrinsics(w)
    gradient = numeric_jacobian(intrinsics, w)
    names = ("focal_x", "focal_y", "skew", "principal_u", "principal_v")
    quantities = {name: (float(value[k]), gradient[k]) for k, name in enumerate(names)}
    out = curvature_intervals(J, residuals(w), quantities, certified_gap(cost, lower))
    # The plane is an estimate too: its uncertainty moves the optimum, w*(p) ~ w - (J'J)^-1 J' J_p dp
    # (Gauss-Newton), with dp over the affine stage's own ellipsoid; the two added in quadrature.
    coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
    Ja = numeric_jacobian(lambda q: frames.modulus_residuals(coef, q), p)
    ra = frames.modulus_residuals(coef, p)
    plane_part = curvature_intervals(Ja, ra, {}, None)
    Jp = numeric_jacobian(lambda q: residuals(w, q), p)
    try:
        D = -np.linalg.lstsq(J, Jp, rcond=None)[0]  # dw*/dp, 5 x 3
        Sa = np.linalg.pinv(Ja.T @ Ja)
        singular_plane = np.linalg.matrix_rank(Ja.T @ Ja, tol=1e-10 * np.abs(Ja.T @ Ja).max()) < 3
    except np.linalg.LinAlgError:
        D, Sa, singular_plane = None, None, True
    for interval, (name, (val, g)) in zip(out.intervals, quantities.items()):
        if interval["lower"] is None or D is None:
            continue
        moved = D.T @ g
        if singular_plane and np.abs(moved).max() > 0:
            interval["lower"] = interval["upper"] = None
            continue
        extra = float(plane_part.cost_increase or 0.0) * float(moved @ Sa @ moved)
        half = math.hypot(interval["upper"] - val, math.sqrt(max(extra, 0.0)))
        interval["lower"], interval["upper"] = val - half, val + half
    out.warnings += motion_warnings(setup.H, centres)
    return out.document()


def varying_focal_stage(problem, p: np.ndarray, Ks: list, centres: np.ndarray | None) -> dict | None:
    """One focal length per view (zero skew, unit aspect, the principal point at the
    preconditioner's): each view's DIAC diag(a_i^2, a_i^2, 1) (preconditioned, a_i = f_i / f0)
    against the reference view's carried by H_i, with the plane p free too."""
    reference = problem.norm.reference
    if any(K is None for K in Ks):
        return None
    f0 = float(problem.K0[0, 0])
    a = np.array([float(np.asarray(K)[0, 0]) / f0 for K in Ks])
    others = [i for i in range(len(Ks)) if i != reference]
    m = len(Ks)

    def residuals(theta):
        focal, q = theta[:m], theta[m:]
        H = mrelax.homographies(problem.norm.cameras, reference, q)
        omega_ref = np.diag([focal[reference] ** 2, focal[reference] ** 2, 1.0])
        out = []
        for j, i in enumerate(others):
            image = H[j] @ omega_ref @ H[j].T
            diff = np.diag([focal[i] ** 2, focal[i] ** 2, 1.0]) - image / image[2, 2]
            out.append(mrelax.WEIGHTS[:5] * np.array([diff[x, y] for x, y in mrelax.ENTRIES]))
        return np.concatenate(out)

    theta = np.concatenate([a, p])
    J = numeric_jacobian(residuals, theta)
    quantities = {f"focal[{i}]": (f0 * a[i], f0 * np.eye(len(theta))[i]) for i in range(m)}
    out = curvature_intervals(J, residuals(theta), quantities)
    out.warnings += motion_warnings(mrelax.homographies(problem.norm.cameras, reference, p), centres)
    return out.document()

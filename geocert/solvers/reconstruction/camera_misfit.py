"""Why a camera of a reconstruction is beaten by a free 3x4 camera on its own points (issue 35):
refitted locally, the points held, with its pose alone, then with a principal point of its own,
then with a focal length and principal point of its own. On the real photos measured
(bench.camera_certification) every camera beyond its tolerance has its pose at its optimum, and
the camera's K misfits the view: with openMVG's K for Sceaux Castle, each photo wants a principal
point of its own (why was not measured), and with it 10 of the 11 fall within the tolerance a
camera with it would have. A diagnosis for the camera's
reason and the summary's warning, found locally: not a certificate, and no certified claim rests
on it."""

from __future__ import annotations

import numpy as np

from geocert.core.geometry import norm_cost
from geocert.formulations.reconstruction import camera_claim

# camera_misfit's refits, each beside the pose: none, the view's own principal point, its own
# focal length and principal point.
MISFIT_MODELS = {"pose": 0, "principal_point": 2, "focal_and_principal_point": 3}


def camera_misfit(P: np.ndarray, X: np.ndarray, x: np.ndarray, norm: str, free: float) -> dict | None:
    """Why a camera costs more than the free 3x4 camera ``free`` on its points: its excess over
    that cost after refitting it locally (Levenberg-Marquardt, the points held) with its pose
    alone, its pose and a principal point of its own, and its pose, focal length and principal
    point (MISFIT_MODELS), each a fraction of ``free``. A pose refit that removes little of the
    excess says the pose is at its optimum on these points; a principal point or focal length of
    its own that removes it says the camera model (the given or shared K) misfits this view. A
    diagnosis found locally, not a certificate: None when P has no camera decomposition."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    from geocert.solvers.reconstruction.upgrade import decompose

    try:
        with np.errstate(all="ignore"):
            K, R, t = decompose(P)
    except np.linalg.LinAlgError:
        return None
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(t)) and free > 0):
        return None
    scale = float(np.abs(np.diag(K[:2, :2])).mean())

    def project(p, extra):
        cam = X @ (Rotation.from_rotvec(p[:3]).as_matrix() @ R).T + t + p[3:6]
        M, centre = K[:2, :2] * (1 + (p[8] if extra == 3 else 0.0)), K[:2, 2] + (scale * p[6:8] if extra else 0.0)
        return (cam[:, :2] / cam[:, 2:3]) @ M.T + centre

    out = {}
    for name, extra in MISFIT_MODELS.items():
        try:
            found = least_squares(lambda p: (project(p, extra) - x).ravel(), np.zeros(6 + extra), method="lm",
                                  max_nfev=100 * (6 + extra))
            cost = norm_cost(project(found.x, extra) - x, norm)
        except (ValueError, np.linalg.LinAlgError):
            return None
        out[name] = float(cost / free - 1.0) if np.isfinite(cost) else None
    return out


def misfit_cause(misfit: dict | None, excess: float, points: int, dof: int, norm: str, rel_gap: float) -> str | None:
    """What camera_misfit's refits say of a camera ``excess`` above the free camera: "pose" (its
    pose alone removes half of it or more), "principal_point" or "focal_and_principal_point" (its
    pose is at its optimum, and that intrinsic of its own brings it within the tolerance a camera
    with those intrinsics of its own would have: camera_claim.tolerance), "unexplained"; None
    without refits."""
    if not misfit or any(misfit.get(name) is None for name in MISFIT_MODELS):
        return None
    if misfit["pose"] < 0.5 * excess:
        return "pose"
    for name, extra in (("principal_point", 2), ("focal_and_principal_point", 3)):
        # The refit camera's own degrees of freedom: its pose and these intrinsics, or the ones it
        # has already where more (a principal point of its own counts once: a camera already
        # with one, 8, refit with a focal length too has 9, not 11).
        tolerance = camera_claim.tolerance(points, max(dof, camera_claim.POSE_DOF + extra), norm, rel_gap)
        if tolerance is not None and misfit[name] <= tolerance:
            return name
    return "unexplained"


def misfit_words(misfit: dict | None) -> str:
    """camera_misfit's refits and their cause (misfit_cause), in words for a camera's reason."""
    if not misfit or misfit.get("cause") is None:
        return ""
    said = (f"; refitted locally on the same points, it leaves above the free camera {misfit['pose']:.2%} with its "
            f"pose alone, {misfit['principal_point']:.2%} with a principal point of its own, "
            f"{misfit['focal_and_principal_point']:.2%} with a focal length and principal point of its own")
    return said + {"pose": ": its pose was off its optimum on these points",
                   "principal_point": ": its pose is at its optimum; the camera's K misfits this view, its principal "
                                      "point (within the tolerance of a camera with a principal point of its own)",
                   "focal_and_principal_point": ": its pose is at its optimum; the camera's K misfits this view, its "
                                                "focal length and principal point (within the tolerance of a camera "
                                                "with them of its own)",
                   "unexplained": ": its pose is at its optimum; no intrinsic of its own explains the rest "
                                  "(distortion, its points, or an affine misfit)"}[misfit["cause"]]

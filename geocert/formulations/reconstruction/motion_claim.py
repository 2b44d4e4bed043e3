"""Whether the motion of a reconstruction's cameras is critical for constant intrinsics, stated
once for the pipeline and the verifier: both judge the cameras and certified points a result
returns, so the verifier recomputes the judgement behind ``critical_motion`` and ``determined``.

A critical motion (Sturm 1997: a turntable, an orbit, a translating camera) leaves a family of
upgrades the tracks fit equally well, so no certificate fixes K. The judgement is
determinacy.motion_warnings' (the autocalibration kind's): the DIAC's family at no less than
determinacy.ROTATION_NOISE (an adjustment drifts along a critical family by more than its
residuals' noise: the Dinosaur's turntable axes scatter by 3 degrees), and the plane at
infinity's at the noise the residuals give (rotation_noise)."""

from __future__ import annotations

import math

import numpy as np

from geocert.formulations.autocalibration import determinacy


def motion(rotations: list, translations: list, noise: float | None = None, plane_noise: float | None = None
           ) -> tuple[list[dict], str | None]:
    """The autocalibration kind's motion warnings (determinacy.motion_warnings: Sturm's critical
    motions for constant intrinsics, the DIAC's family and the plane at infinity's) for the
    registered views (rotation and translation not None): the rotations relative to a reference
    view (infinite homographies K R_j R_0^T K^-1 less their K) and the camera centres. The reference is the view whose
    rotation is nearest the others' (the least sum of chordal distances), not the first in the
    file: the judgement is the motion's, whatever order the photos came in. ``noise``: the
    rotations' standard error (radians) for the DIAC's family (None: determinacy's default);
    ``plane_noise``: for the plane at infinity's family, which is judged only when given (the
    adjustment's residuals' noise, rotation_noise: at the default ROTATION_NOISE, 0.6 degrees,
    a general motion of exact cameras in a 60-degree cone was judged near-critical). Returns the
    warnings and the code of the critical one (None for a general motion)."""
    views = [v for v, R in enumerate(rotations) if R is not None]
    if len(views) < 3:
        return [], None
    R = np.array([rotations[v] for v in views], dtype=float)
    centres = np.array([-np.asarray(rotations[v], dtype=float).T @ np.asarray(translations[v], dtype=float)
                        for v in views])
    # one view at a time: the n x n x 3 x 3 differences at once asked 72 bytes a pair (5 GB for
    # the 6,000 cameras a 4 MB document can list); row by row, memory linear in the views
    chordal = np.array([np.linalg.norm(R - R[k], axis=(1, 2)).sum() for k in range(len(R))])
    ref = int(np.argmin(chordal))
    others = [k for k in range(len(views)) if k != ref]
    try:
        warnings = determinacy.motion_warnings(R[others] @ R[ref].T, centres[[ref, *others]], noise=noise,
                                               reference=None if plane_noise is None else R[ref],
                                               plane_noise=plane_noise)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError):
        return [], None
    return warnings, next((w["code"] for w in warnings if w["code"] in determinacy.CRITICAL_CODES), None)


def rotation_noise(Ks: list, rotations: list, translations: list, points: np.ndarray, obs_view: np.ndarray,
                   obs_track: np.ndarray, pixels: np.ndarray, keep: np.ndarray) -> float | None:
    """The standard error (radians) of a relative rotation R_j R_0^T of the adjusted
    reconstruction, as its residuals give it: per camera, sigma^2 (J'J)^-1 of its pose with the
    points and K held (J the pixels' derivatives in a small rotation and the translation; sigma
    the residuals' RMS per coordinate), the largest standard deviation of its rotation; the
    median over the cameras, times sqrt(2) (two cameras in each relative rotation). None when
    fewer than 3 cameras have 6 points. It is conditional on the points, an estimate of the noise
    alone: an adjustment drifting along a critical family moves the rotations by more (hence
    determinacy.ROTATION_NOISE as the floor where it is used)."""
    registered = np.array([R is not None for R in rotations])
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    use = keep & registered[obs_view] & np.isfinite(points[obs_track, 0])
    if use.sum() < 12:
        return None
    sigmas, squared, count = [], 0.0, 0
    per_view = []
    for v in np.flatnonzero(registered):
        m = np.flatnonzero(use & (obs_view == v))
        if len(m) < 6:
            continue
        K, R, t = (np.asarray(a, dtype=float) for a in (Ks[v], rotations[v], translations[v]))
        turned = points[obs_track[m]] @ R.T  # R X
        cam = turned + t
        x, y, z = cam[:, 0], cam[:, 1], cam[:, 2]
        image = cam @ K.T
        r = image[:, :2] / image[:, 2:3] - pixels[m]
        squared += float((r * r).sum())
        count += r.size
        # d(x/z, y/z)/d cam, then K's 2x2 block; d cam / d(omega, t) = [-[R X]_x, I].
        dproj = np.zeros((len(m), 2, 3))
        dproj[:, 0, 0] = dproj[:, 1, 1] = 1 / z
        dproj[:, 0, 2], dproj[:, 1, 2] = -x / z ** 2, -y / z ** 2
        skew = np.zeros((len(m), 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -turned[:, 2], turned[:, 1], -turned[:, 0]
        skew -= skew.transpose(0, 2, 1)
        dcam = np.concatenate([-skew, np.broadcast_to(np.eye(3), (len(m), 3, 3))], axis=2)
        J = np.einsum("ab,mbc,mcd->mad", K[:2, :2], dproj, dcam).reshape(-1, 6)
        per_view.append(J.T @ J)
    if len(per_view) < 3 or count <= 6 * len(per_view):
        return None
    sigma2 = squared / (count - 6 * len(per_view))
    for normal in per_view:
        try:
            covariance = sigma2 * np.linalg.inv(normal)
        except np.linalg.LinAlgError:
            continue
        sigmas.append(math.sqrt(max(float(np.linalg.eigvalsh(covariance[:3, :3]).max()), 0.0)))
    return float(math.sqrt(2.0) * np.median(sigmas)) if sigmas else None


def judge(Ks: list, rotations: list, translations: list, points: np.ndarray, obs_view: np.ndarray,
          obs_track: np.ndarray, pixels: np.ndarray) -> dict:
    """The judgement of a reconstruction's motion (module docstring): its warnings, the critical
    code (None for a general motion) and the noise each family was judged at. ``points`` (T, 3),
    NaN for a track not used; every observation (view, track, pixel) of a used track counts."""
    noise = rotation_noise(Ks, rotations, translations, points, obs_view, obs_track, pixels,
                           np.ones(len(obs_view), dtype=bool))
    diac = max(noise, determinacy.ROTATION_NOISE) if noise is not None else determinacy.ROTATION_NOISE
    warnings, critical = motion(rotations, translations, diac, noise)
    return {"motion_warnings": warnings, "critical_motion": critical,
            "rotation_noise_rad": {"estimated": noise, "diac_family": diac, "plane_family": noise}}

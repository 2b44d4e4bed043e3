"""How well a metric reconstruction (upgrade.Metric) explains its observations: per observation its
depth and reprojection error, the RMS over the observations kept, and MSAC's capped cost over all
of them (the figure two reconstructions of the same observations are compared by)."""

from __future__ import annotations

import numpy as np

from geocert.solvers.reconstruction import upgrade
from geocert.solvers.reconstruction.tracks import Observations


def depths_and_errors(metric: upgrade.Metric, obs: Observations, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per observation m: its point's depth in its camera and its reprojection error (pixels)."""
    depth, seen = depths_and_images(metric, obs, m)
    with np.errstate(invalid="ignore"):
        error = np.linalg.norm(seen - obs.pixel[m], axis=1)
    return depth, np.nan_to_num(error, nan=np.inf)


def depths_and_images(metric: upgrade.Metric, obs: Observations, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per observation m: its point's depth in its camera and the pixel its point projects to."""
    eye = np.eye(3)
    R = np.array([eye if r is None else r for r in metric.rotations])
    t = np.array([np.zeros(3) if x is None else x for x in metric.translations])
    K = np.array([eye if r is None else upgrade.K_of(metric, v) for v, r in enumerate(metric.rotations)])
    cam = np.einsum("mij,mj->mi", R[obs.view[m]], metric.points[obs.track[m]]) + t[obs.view[m]]
    seen = cam
    if metric.k1:  # the radial model's pixels (bundle.metric's "radial")
        with np.errstate(divide="ignore", invalid="ignore"):
            n = cam[:, :2] / cam[:, 2:3]
        seen = np.c_[n * (1 + metric.k1 * np.sum(n * n, axis=1))[:, None], np.ones(len(n))]
    image = np.einsum("mij,mj->mi", K[obs.view[m]], seen)
    with np.errstate(divide="ignore", invalid="ignore"):
        return cam[:, 2], image[:, :2] / image[:, 2:3]


def fit_cost(metric: upgrade.Metric, obs: Observations, threshold_px: float) -> float:
    """How well a reconstruction explains every observation, in squared pixels: each observation
    costs its squared reprojection error, capped at threshold_px squared, and the cap when it
    cannot be reprojected (its view not registered, its track not triangulated, its point behind
    the camera); MSAC's score (Torr and Zisserman 2000). Two reconstructions of the same
    observations compare by it whatever each kept: dropping observations costs the cap each."""
    registered = np.array([R is not None for R in metric.rotations])
    use = np.flatnonzero(registered[obs.view] & np.isfinite(metric.points[obs.track, 0]))
    cap = threshold_px ** 2
    if len(use) == 0:
        return float(cap * len(obs.view))
    depth, error = depths_and_errors(metric, obs, use)
    squared = np.where(depth > 0, np.minimum(error ** 2, cap), cap)
    return float(squared.sum() + cap * (len(obs.view) - len(use)))


def rms(metric: upgrade.Metric, obs: Observations, keep: np.ndarray) -> float | None:
    registered = np.array([R is not None for R in metric.rotations])
    m = np.flatnonzero(keep & registered[obs.view] & np.isfinite(metric.points[obs.track, 0]))
    if len(m) == 0:
        return None
    _, errors = depths_and_errors(metric, obs, m)
    return float(np.sqrt(np.mean(errors ** 2)))


SAME_RIG_PX = 1e-6  # two rigs whose every image agrees to this are one rig (in another frame)


def same_images(a: upgrade.Metric, b: upgrade.Metric, obs: Observations) -> bool:
    """Whether two reconstructions of the same observations are one rig up to the frame (a
    similarity): the same views registered and tracks triangulated, the same k1, and every
    observation's point projecting in front of its camera in both or in neither, to the same
    pixel within SAME_RIG_PX. An adjustment from either then goes the same way, so one is enough."""
    registered = np.array([R is not None for R in a.rotations])
    if len(a.rotations) != len(b.rotations) or a.points.shape != b.points.shape or a.k1 != b.k1 \
            or not np.array_equal(registered, [R is not None for R in b.rotations]) \
            or not np.array_equal(np.isfinite(a.points[:, 0]), np.isfinite(b.points[:, 0])):
        return False
    use = np.flatnonzero(registered[obs.view] & np.isfinite(a.points[obs.track, 0]))
    if len(use) == 0:
        return False
    (depth_a, image_a), (depth_b, image_b) = depths_and_images(a, obs, use), depths_and_images(b, obs, use)
    with np.errstate(invalid="ignore"):
        return bool(np.array_equal(depth_a > 0, depth_b > 0) and np.all(np.abs(image_a - image_b) <= SAME_RIG_PX))

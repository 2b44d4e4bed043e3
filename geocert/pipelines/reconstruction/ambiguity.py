"""Whether the observations tell the returned reconstruction from its depth-reversed twin (issue
35: never silently wrong). Under a long lens the cameras are nearly affine and a scene and its
mirror image in depth project nearly alike (solvers/reconstruction/depth_reversal.py): the
adjustment may settle in either, and its own residuals cannot say which is right. So the twin is
built in the frame of the view that sees most, adjusted with the same camera model, and the two
compared by MSAC's capped cost over every observation (fit.fit_cost), in units of the returned
reconstruction's noise variance. Each is compared at its best: the twin, and (for the comparison
only) the returned rig, are adjusted again after every track is triangulated anew in their
cameras, and the returned rig's cost is the lower of its own and that refit's:

- the twin costs more by more than MIRROR_CHI2 variances and by more than MIRROR_MARGIN of the
  cost: the data reject it, the poses stand;
- the twin costs less by as much: the adjustment had stopped in the worse of the two, and the
  twin is returned instead (``adopted``);
- otherwise the observations do not decide between two rigs whose cameras point differently
  (``mirror_rotation_deg`` per camera says by how much): the poses are not determined, and the
  result says so (claims.summarise: a warning and each camera's ``pose_determined``).

The margin is there because real photos are not the model: an unmodelled lens distortion or a
principal point held at the centre shifts costs by a few percent whatever the noise level, so a
difference that small is not taken as evidence. Measured (the twin's cost over the returned one's):
dinoSparseRing 1.22 with K unknown and 1.40 with K known, templeSparseRing 8.2 and 12.5, the Oxford
Corridor 22.1 and 1.40; a synthetic turntable seen from 1000 times its size through a 165,000 px lens
1.02 (0.3 px of noise)."""

from __future__ import annotations

import numpy as np

from geocert.pipelines.reconstruction.fit import fit_cost, rms
from geocert.solvers.reconstruction import depth_reversal, upgrade
from geocert.solvers.reconstruction.tracks import Observations

# The twin is told apart when the costs differ by more than this many noise variances (the
# chi-square with 1 degree of freedom at p = 0.001: a likelihood ratio above e^5.4) and by more
# than this fraction of the smaller cost.
MIRROR_CHI2 = 10.8
MIRROR_MARGIN = 0.10


def check(metric: upgrade.Metric, obs: Observations, keep: np.ndarray, threshold_px: float, model: str,
          should_stop=None) -> tuple[upgrade.Metric, np.ndarray, dict]:
    """The depth-reversal check of ``metric`` (adjusted, its observations ``keep``): returns the
    reconstruction to go on with (the twin when it fits better), its observations kept, and the
    figures. ``model`` is the bundle model the twin is adjusted with (the one ``metric`` was)."""
    registered = [v for v, R in enumerate(metric.rotations) if R is not None]
    if len(registered) < 2:
        return metric, keep, {"checked": False, "reason": "fewer than 2 views registered"}
    seen = np.bincount(obs.view[keep], minlength=len(metric.rotations))
    reference = max(registered, key=lambda v: (seen[v], -v))
    twin = depth_reversal.mirrored(metric, reference)
    adjusted, twin_keep, _ = upgrade.adjust(twin, obs.view, obs.track, obs.pixel, threshold_px, model=model,
                                            should_stop=should_stop)
    # The adjustment drops the observations its start did not fit, for good (a point left with
    # fewer than two is lost): every track is triangulated again in the adjusted twin's cameras
    # and adjusted once more, so the twin is judged on all it can explain, as the returned rig was
    # built (its registration triangulated each track as its views were placed).
    adjusted, twin_keep, _ = upgrade.adjust(retriangulated(adjusted, obs), obs.view, obs.track, obs.pixel,
                                            threshold_px, model=model, should_stop=should_stop)
    # The returned rig gets the same second chance (for the comparison only): the two are
    # compared each at its best, so neither wins by what the other was not offered.
    refit, _, _ = upgrade.adjust(retriangulated(metric, obs), obs.view, obs.track, obs.pixel, threshold_px,
                                 model=model, should_stop=should_stop)
    if should_stop is not None and should_stop():
        return metric, keep, {"checked": False, "reason": "stopped before the twin's adjustment ended"}
    cost = min(fit_cost(metric, obs, threshold_px), fit_cost(refit, obs, threshold_px))
    twin_cost = fit_cost(adjusted, obs, threshold_px)
    kept = int(keep.sum())
    points = int(np.count_nonzero(np.bincount(obs.track[keep], minlength=len(metric.points)) >= 2))
    # Residual degrees of freedom: 2 per observation less the poses (6 each), the points (3 each)
    # and the similarity a metric frame leaves free (7).
    dof = max(2 * kept - 6 * len(registered) - 3 * points + 7, 1)
    spread = rms(metric, obs, keep)
    variance = max((spread or 0.0) ** 2 * kept / dof, 1e-4)  # below 0.01 px is rounding, not noise
    statistic = (twin_cost - cost) / variance
    rejected = statistic > MIRROR_CHI2 and twin_cost > (1 + MIRROR_MARGIN) * cost
    adopted = -statistic > MIRROR_CHI2 and cost > (1 + MIRROR_MARGIN) * twin_cost
    ambiguous = not (rejected or adopted)
    kept_metric, kept_obs = (adjusted, twin_keep) if adopted else (metric, keep)
    other = metric if adopted else adjusted
    R_ref, R_other_ref = kept_metric.rotations[reference], other.rotations[reference]
    angles = {int(v): depth_reversal.rotation_between_deg(kept_metric.rotations[v] @ R_ref.T,
                                                          other.rotations[v] @ R_other_ref.T)
              for v in registered if kept_metric.rotations[v] is not None and other.rotations[v] is not None}
    figures = {
        "checked": True, "reference_view": int(reference), "model": model,
        "cost_px2": cost, "mirror_cost_px2": twin_cost, "cost_ratio": twin_cost / cost if cost > 0 else None,
        "noise_variance_px2": variance, "statistic": float(statistic), "threshold": MIRROR_CHI2,
        "margin": MIRROR_MARGIN,
        "observations": int(len(obs.view)), "observations_fitting": kept,
        "mirror_observations_fitting": int(twin_keep.sum()),
        "focal_px": float(metric.K[0, 0]), "mirror_focal_px": float(adjusted.K[0, 0]),
        "mirror_rotation_deg": angles, "ambiguous": bool(ambiguous), "adopted": bool(adopted)}
    return kept_metric, kept_obs, figures


def retriangulated(metric: upgrade.Metric, obs: Observations) -> upgrade.Metric:
    """``metric`` with every track seen by two or more of its registered views triangulated again
    (linear, calibrated.triangulate) in its cameras; a track that triangulates behind a camera or
    at infinity keeps its point."""
    from dataclasses import replace

    from geocert.solvers.reconstruction.calibrated import triangulate

    registered = np.array([R is not None for R in metric.rotations])
    use = np.flatnonzero(registered[obs.view])
    use = use[np.argsort(obs.track[use], kind="stable")]
    bounds = np.searchsorted(obs.track[use], np.arange(len(metric.points) + 1))
    Kinv = {v: np.linalg.inv(upgrade.K_of(metric, v)) for v in np.flatnonzero(registered)}
    points = metric.points.copy()
    for track in range(len(metric.points)):
        m = use[bounds[track]:bounds[track + 1]]
        if len(m) < 2:
            continue
        views = obs.view[m]
        rays = np.array([(Kinv[v] @ [u, w, 1.0])[:2] for v, (u, w) in zip(views, obs.pixel[m])])
        Rs = np.array([metric.rotations[v] for v in views])
        ts = np.array([metric.translations[v] for v in views])
        X = triangulate(Rs, ts, rays)
        if np.all(np.isfinite(X)) and np.all((Rs @ X + ts)[:, 2] > 0):
            points[track] = X
    return replace(metric, points=points)

"""Whether the observations tell the returned reconstruction from its depth-reversed twin (issue
35: never silently wrong). Under a long lens the cameras are nearly affine and a scene and its
mirror image in depth project nearly alike (formulations/reconstruction/depth_reversal.py): the
adjustment may settle in either, and its own residuals cannot say which is right. So the twin is
built in the frame of the view that sees most, adjusted with the same camera model, and the two
compared by MSAC's capped cost over every observation (fit.fit_cost), in units of the returned
reconstruction's noise variance (depth_reversal_claim.verdict, which the verifier reads too). Each
is compared at its best: the twin is adjusted again after every track is triangulated anew in its
cameras, and judged at the better of its two states; unless that already rejects it, the returned
rig gets the same refit (for the comparison only), and its cost is the lower of its own and the
refit's (``returned_refitted`` says whether it was run):

- the twin costs more by more than MIRROR_CHI2 variances and by more than MIRROR_MARGIN of the
  cost: the data reject it, the poses stand;
- the twin costs less by as much: the adjustment had stopped in the worse of the two, and the
  twin is returned instead (``adopted``);
- otherwise the observations do not decide between two rigs whose cameras point differently
  (claims.summarise states per camera by how much, ``mirror_rotation_deg``, from the returned
  cameras: depth_reversal.mirror_angles_deg): the poses are not determined, and the result says so
  (a warning and each camera's ``pose_determined``).

The margin is there because real photos are not the model: an unmodelled lens distortion or a
principal point held at the centre shifts costs by a few percent whatever the noise level, so a
difference that small is not taken as evidence. Measured (the twin's cost over the returned one's):
dinoSparseRing 1.21 with K unknown and 1.38 with K known, templeSparseRing 1.21 and 1.80, the Oxford
Corridor 4.10 and 1.40; a synthetic turntable seen from 1000 times its size through a 165,000 px lens
1.02 (0.3 px of noise). The twin's adjustments mostly stop at their iteration cap (the record's
``mirror_capped``); run to convergence they left every verdict measured as it was
(bench/results/reconstruction_vs_colmap.md, "The twin's adjustments at their cap")."""

from __future__ import annotations

import numpy as np

from geocert.pipelines.reconstruction.fit import fit_cost, rms
from geocert.solvers.reconstruction import upgrade
from geocert.formulations.reconstruction import depth_reversal
from geocert.formulations.reconstruction.depth_reversal_claim import (FEWER_THAN_2_VIEWS, MIRROR_CHI2, MIRROR_MARGIN,
                                                                 STOPPED, verdict)
from geocert.solvers.reconstruction.tracks import Observations


def check(metric: upgrade.Metric, obs: Observations, keep: np.ndarray, threshold_px: float, model: str,
          should_stop=None) -> tuple[upgrade.Metric, np.ndarray, dict]:
    """The depth-reversal check of ``metric`` (adjusted, its observations ``keep``): returns the
    reconstruction to go on with (the twin when it fits better), its observations kept, and the
    figures. ``model`` is the bundle model the twin is adjusted with (the one ``metric`` was).
    ``should_stop()`` is asked between its adjustments."""
    registered = [v for v, R in enumerate(metric.rotations) if R is not None]
    if len(registered) < 2:
        return metric, keep, {"checked": False, "reason": FEWER_THAN_2_VIEWS}
    stopped = (metric, keep, {"checked": False, "reason": STOPPED})
    seen = np.bincount(obs.view[keep], minlength=len(metric.rotations))
    reference = max(registered, key=lambda v: (seen[v], -v))
    twin = depth_reversal.mirrored(metric, reference)
    first, first_keep, first_figures = upgrade.adjust(twin, obs.view, obs.track, obs.pixel, threshold_px,
                                                      model=model, should_stop=should_stop)
    if should_stop is not None and should_stop():
        return stopped
    # The adjustment drops the observations its start did not fit, for good (a point left with
    # fewer than two is lost): every track is triangulated again in the adjusted twin's cameras
    # and adjusted once more, so the twin is judged on all it can explain, as the returned rig was
    # built (its registration triangulated each track as its views were placed). The twin is
    # judged at the better of its two adjusted states.
    second, second_keep, second_figures = upgrade.adjust(retriangulated(first, obs), obs.view, obs.track,
                                                         obs.pixel, threshold_px, model=model,
                                                         should_stop=should_stop)
    if should_stop is not None and should_stop():
        return stopped
    twin_cost, adjusted, twin_keep = min((fit_cost(first, obs, threshold_px), first, first_keep),
                                         (fit_cost(second, obs, threshold_px), second, second_keep),
                                         key=lambda state: state[0])
    kept = int(keep.sum())
    points = int(np.count_nonzero(np.bincount(obs.track[keep], minlength=len(metric.points)) >= 2))
    # Residual degrees of freedom: 2 per observation less the poses (6 each), the points (3 each)
    # and the similarity a metric frame leaves free (7).
    dof = max(2 * kept - 6 * len(registered) - 3 * points + 7, 1)
    spread = rms(metric, obs, keep)
    variance = max((spread or 0.0) ** 2 * kept / dof, 1e-4)  # below 0.01 px is rounding, not noise
    cost = fit_cost(metric, obs, threshold_px)
    statistic, rejected, adopted = verdict(cost, twin_cost, variance)
    refitted = False
    if not rejected:
        # The returned rig gets the twin's second chance too before the twin is called as good or
        # better (each compared at its best, so neither wins by what the other was not offered);
        # it cannot change a rejection (a lower cost only widens the difference), so it is not run
        # for one.
        refit, _, _ = upgrade.adjust(retriangulated(metric, obs), obs.view, obs.track, obs.pixel, threshold_px,
                                     model=model, should_stop=should_stop)
        if should_stop is not None and should_stop():
            return stopped
        cost, refitted = min(cost, fit_cost(refit, obs, threshold_px)), True
        statistic, rejected, adopted = verdict(cost, twin_cost, variance)
    ambiguous = not (rejected or adopted)
    kept_metric, kept_obs = (adjusted, twin_keep) if adopted else (metric, keep)
    figures = {
        "checked": True, "reference_view": int(reference), "model": model,
        "cost_px2": cost, "mirror_cost_px2": twin_cost, "cost_ratio": twin_cost / cost if cost > 0 else None,
        "noise_variance_px2": variance, "statistic": float(statistic), "threshold": MIRROR_CHI2,
        "margin": MIRROR_MARGIN, "returned_refitted": refitted,
        "observations": int(len(obs.view)), "observations_fitting": kept,
        "mirror_observations_fitting": int(twin_keep.sum()),
        "focal_px": float(metric.K[0, 0]), "mirror_focal_px": float(adjusted.K[0, 0]),
        # A twin's adjustment at its iteration cap states an upper bound of its cost, not its
        # minimum (the long-lens twin's focal length runs off toward the affine camera's and its
        # cost falls for hundreds of iterations): said, so a rejection read at the cap is known as one.
        "mirror_capped": bool(first_figures["capped"] or second_figures["capped"]),
        "ambiguous": bool(ambiguous), "adopted": bool(adopted)}
    return kept_metric, kept_obs, figures


def retriangulated(metric: upgrade.Metric, obs: Observations) -> upgrade.Metric:
    """``metric`` with every track seen by two or more of its registered views triangulated again
    (linear, calibrated.triangulate) in its cameras; a track that triangulates behind a camera or
    at infinity keeps its point."""
    from dataclasses import replace

    registered = np.array([R is not None for R in metric.rotations])
    use = np.flatnonzero(registered[obs.view])
    use = use[np.argsort(obs.track[use], kind="stable")]
    bounds = np.searchsorted(obs.track[use], np.arange(len(metric.points) + 1))
    eye = np.eye(3)
    Kinv = np.array([np.linalg.inv(upgrade.K_of(metric, v)) if r else eye for v, r in enumerate(registered)])
    R = np.array([eye if r is None else r for r in metric.rotations])
    t = np.array([np.zeros(3) if x is None else x for x in metric.translations])
    P = np.concatenate([R, t[:, :, None]], axis=2)
    rays = np.einsum("mij,mj->mi", Kinv[obs.view[use]], np.c_[obs.pixel[use], np.ones(len(use))])[:, :2]
    points = metric.points.copy()
    counts = np.diff(bounds)
    # calibrated.triangulate's DLT, the tracks with as many observations at once (one stacked SVD).
    for k in np.unique(counts[counts >= 2]):
        tracks = np.flatnonzero(counts == k)
        m = bounds[tracks][:, None] + np.arange(k)[None, :]  # (tracks, k) into use
        Pm, x = P[obs.view[use[m]]], rays[m]
        A = np.concatenate([x[:, :, 0:1] * Pm[:, :, 2] - Pm[:, :, 0], x[:, :, 1:2] * Pm[:, :, 2] - Pm[:, :, 1]], axis=1)
        A /= np.linalg.norm(A, axis=2, keepdims=True)
        X = np.linalg.svd(A)[2][:, -1]
        with np.errstate(divide="ignore", invalid="ignore"):
            X = np.where(np.abs(X[:, 3:4]) < 1e-12, np.nan, X[:, :3] / X[:, 3:4])
            ahead = np.all(np.einsum("tkij,tj->tki", Pm[:, :, :, :3], X)[:, :, 2] + Pm[:, :, 2, 3] > 0, axis=1)
        good = np.all(np.isfinite(X), axis=1) & ahead
        points[tracks[good]] = X[good]
    return replace(metric, points=points)

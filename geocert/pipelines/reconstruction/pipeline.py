"""From tracks to a certified metric reconstruction (issue 14), stage by stage:

1. projective: a projective reconstruction from the tracks alone (projective.py);
2. autocalibration: the metric upgrade by the certified autocalibration solver (upgrade.py);
3. bundle_adjustment: optionally, a metric bundle adjustment with one shared K (upgrade.py);
4. structure: every kept track triangulated, and cameras: every camera resected, by the
   certified solvers in the metric frame (structure.py).

A stage that fails keeps what the earlier stages found and says why. ``report(stage, done,
total, progress=None)`` sees each stage's progress; when it returns True the run stops (the
stage running and those after it are marked cancelled, ``Reconstruction.cancelled`` is True)
and keeps what is done: the views the projective stage registered so far (finished as usual),
the metric cameras once an upgrade was found, the points triangulated and the cameras resected
before the cancel (structure and cameras are cancellable between chunks of tracks and between
cameras)."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field, replace

import numpy as np

from geocert.formulations.fractional.options import MapOptions, TriangulationOptions
from geocert.solvers.reconstruction import bundle, projective, structure, upgrade
from geocert.formulations.reconstruction import calibration_claim, calibration_tie, camera_claim, depth_reversal_claim
from geocert.pipelines.reconstruction import ambiguity, claims
from geocert.pipelines.reconstruction.fit import (depths_and_errors as _depths_and_errors, fit_cost, rms as _rms,
                                                  same_images)
from geocert.pipelines.reconstruction.options import ReconstructionOptions
from geocert.formulations.reconstruction.camera_claim import FOCAL_P, PRINCIPAL_POINT_CHI2, PRINCIPAL_POINT_P, RADIAL_CHI2
from geocert.solvers.reconstruction.tracks import Observations
from geocert.core.strict import Invalid

STAGES = ("projective", "autocalibration", "bundle_adjustment", "structure", "cameras")


class Cancelled(Exception):
    pass


@dataclass
class Camera:
    view: int
    registered: bool
    reason: str | None = None
    K: np.ndarray | None = None
    R: np.ndarray | None = None
    t: np.ndarray | None = None
    P: np.ndarray | None = None  # 3x4 pixels: K [R | t], or the projective camera when no upgrade was found
    bound: structure.CameraBound | None = None
    # The radial term of the pixels this camera saw (Reconstruction.distortion), at this camera's
    # focal length: a point at normalised coordinates n (of K [R | t]) is seen at K's pixel of
    # n (1 + k1 |n|^2) about distortion_centre; None when no radial term was estimated.
    k1: float | None = None
    distortion_centre: list | None = None
    # Whether the observations fix this camera's pose against the depth-reversed twin's (ambiguity.py):
    # False when the twin fits about as well, None when not checked; and by how much the twin's
    # rotation (relative to the reference view) differs from this one's, degrees.
    pose_determined: bool | None = None
    mirror_rotation_deg: float | None = None

    @property
    def center(self) -> np.ndarray | None:
        return None if self.R is None else -self.R.T @ self.t


@dataclass
class Point:
    track: int
    result: object  # fractional.results.TrackResult
    observations: list[list[float]]  # [[view, u, v], ...] the triangulation used


@dataclass
class Reconstruction:
    cameras: list[Camera]
    points: list[Point]
    stages: list[dict]
    summary: dict = field(default_factory=dict)
    metric: upgrade.Metric | None = None
    cancelled: bool = False  # the run was stopped (report returned True); what was done is kept
    checks: dict = field(default_factory=dict)  # the sanity layer's figures (_check_cameras, _drop_outlier_points)
    # The certified metric upgrade's solve, from which the kind builds the calibration certificate
    proven: upgrade.Proven | None = None
    # The radial term the observations were undistorted with before the metric stages (None: none):
    # {"model", "k1", "k1_at_focal_px", "centres", "test"}; every certificate is conditional on it.
    distortion: dict | None = None


def _stage(name: str) -> dict:
    return {"name": name, "status": "not_run", "elapsed_s": 0.0, "reason": None}


def reconstruct(tracks: list[tuple[np.ndarray, np.ndarray]], image_sizes: list, options: ReconstructionOptions,
                report=None, names: list | None = None) -> Reconstruction:
    """``names``: the views' names as the request gave them (None: none given), for the summary's
    warnings that name views (claims.summarise)."""
    n_views = len(image_sizes)
    stages = {name: _stage(name) for name in STAGES}
    cameras = [Camera(v, False, "not registered") for v in range(n_views)]
    out = Reconstruction(cameras, [], list(stages.values()))

    def asks(stage: str, done: int, total: int, progress=None) -> bool:
        """Progress; True when the run is to stop (a cancel)."""
        return bool(report is not None and report(stage, done, total, progress))

    def tell(stage: str, done: int, total: int, progress=None) -> None:
        if asks(stage, done, total, progress):
            raise Cancelled(stage.split()[0])

    tell.asks = asks
    try:
        _run(tracks, image_sizes, options, stages, out, tell)
    except Cancelled as stop:
        _cancel(stages, str(stop))
    out.cancelled = any(stage["status"] == "cancelled" for stage in out.stages)
    _untie_dropped_views(out, stages["autocalibration"])
    _untie_centred_misfit(out, stages, options, image_sizes)
    claims.summarise(out, len(tracks), n_views, names)
    return out


def _untie_dropped_views(out: Reconstruction, stage: dict) -> None:
    """The calibration certificate proves its K optimal for the projective cameras of the views it
    holds; a view the result no longer registers (dropped after the calibration) has no returned
    camera to tie its certificate camera to the result (calibration_tie), so that K is not
    claimed for the returned cameras: the certificate is not carried, and the stage says why."""
    if out.proven is None:
        return
    dropped = [int(v) for v in out.proven.views if not out.cameras[int(v)].registered]
    if dropped:
        out.proven = None
        stage.update(certified=False, certificate_views=None, certificate_tracks=None, reason=(
            f"the certified calibration's reconstruction holds view(s) {dropped} that the result does not register "
            "(dropped after the calibration): nothing ties their cameras to the result, so its K is not claimed"))


def _untie_centred_misfit(out: Reconstruction, stages: dict, options: ReconstructionOptions, image_sizes) -> None:
    """With camera_model "full", a registration held at the images' centre (its free fit outside
    the middle half: _registration_principal_point) builds the calibration certificate in a model
    the returned cameras are freer than, and the verifier ties it to them through that model's
    least-squares fit (calibration_tie, CENTRED_REFERENCE), whose tests assume what the model
    misfits on the certificate's tracks it misfits as much on the result's other tracks. Where the
    certificate holds a part of the tracks (autocalibration_points) and the misfit is many times
    the noise, the halves differ by more than that allowance (the synthetic scene's 600 tracks
    shifted by (-200, +20) px: 10,070 px^2 on the other tracks, 8,959 allowed). The pipeline asks
    the tie itself, the verifier's own test on what the result will state, and where it refuses,
    the certificate is not carried and the stage says why (a smaller claim that holds: the K is
    returned, not certified), as for a view dropped after the calibration."""
    stage, record = stages["autocalibration"], stages["projective"].get("principal_point")
    if out.proven is None or options.camera_model != "full" or not isinstance(record, dict) \
            or record.get("estimated") is not False or record.get("inside_middle_half") is not False:
        return
    proven = out.proven
    result = {"cameras": [{"view": c.view, "registered": c.registered, "image_size": list(image_sizes[c.view]),
                           "P": None if c.P is None else np.asarray(c.P, dtype=float).tolist()} for c in out.cameras],
              "points": [{"track": p.track, "point": None if p.result.point is None else list(p.result.point),
                          "at_infinity": bool(p.result.at_infinity), "observations": p.observations}
                         for p in out.points],
              "stages": [stages["projective"]]}
    data = {"cameras": np.asarray(proven.cameras, dtype=float).tolist(),
            "points": np.asarray(proven.points, dtype=float).tolist(),
            "image_size": None if proven.image_size is None else list(proven.image_size)}
    try:
        calibration_tie.tie(result, {"certificate_views": list(proven.views), "certificate_tracks": list(proven.tracks)},
                            data, recorded=False)
    except Invalid as refused:
        out.proven = None
        stage.update(certified=False, certificate_views=None, certificate_tracks=None, reason=(
            "the certified calibration's reconstruction is the registration's, held at the images' centre (the "
            "principal point's free fit lies outside their middle half), and the verifier's tie to the returned "
            f"cameras (camera_model full) refuses it: {refused.detail}; its K is not claimed"))


def not_reconstructed(n_views: int, status: str, reason: str, camera_reason: str,
                      names: list | None = None) -> Reconstruction:
    """The reconstruction when no tracks reach it (photos: the matches stage failed, or was
    cancelled): every stage ``status`` ("skipped" or "cancelled") with ``reason``, every view not
    registered with ``camera_reason``, the summary filled (0 views registered, 0 points; ``names``
    as reconstruct's)."""
    stages = [{**_stage(name), "status": status, "reason": reason} for name in STAGES]
    out = Reconstruction([Camera(v, False, camera_reason) for v in range(n_views)], [], stages,
                         cancelled=status == "cancelled")
    claims.summarise(out, 0, n_views, names)
    return out


def _none_kept(out: Reconstruction, stages: dict, stage: dict, name: str, threshold_px: float, what: str) -> None:
    """The stage ``name`` failed: no observation reprojects within the outlier threshold of
    ``what`` (a threshold below the data's noise, or a reconstruction fitting none of them), so
    nothing is left to calibrate, adjust or triangulate; no view is returned registered."""
    reason = (f"no observation reprojects within options.threshold_px ({threshold_px:g} px) of {what}: every "
              "observation is an outlier at that threshold (is it below the noise of the data?)")
    stage.update(status="failed", reason=reason)
    for camera in out.cameras:
        if camera.registered:
            camera.registered, camera.P, camera.reason = False, None, reason
    _skip(stages, name, f"the {name.replace('_', ' ')} stage kept no observation")


def _cancel(stages: dict, at: str) -> None:
    hit = False
    for name in STAGES:
        hit = hit or name == at
        if hit and stages[name]["status"] in ("not_run", "running"):
            stages[name].update(status="cancelled", reason="the job was cancelled")


def _timed(stages: dict, name: str):
    class Timer:
        def __enter__(self):
            stages[name]["status"] = "running"
            self.start, self.cpu = time.perf_counter(), time.process_time()
            return stages[name]

        def __exit__(self, *exc):
            stages[name]["elapsed_s"] = time.perf_counter() - self.start
            stages[name]["cpu_s"] = time.process_time() - self.cpu  # this process's CPU time (wall is shared)
            if stages[name]["status"] == "running" and exc[0] is None:
                stages[name]["status"] = "done"
            return False

    return Timer()


def _skip(stages: dict, after: str, reason: str) -> None:
    later = False
    for name in STAGES:
        if later and stages[name]["status"] == "not_run":
            stages[name].update(status="skipped", reason=reason)
        later = later or name == after


def _calibrated(tracks, n_views: int, K: np.ndarray, options: ReconstructionOptions, stages, out: Reconstruction,
                tell, obs: Observations):
    """K known: the calibrated path (calibrated.py: essential matrices, PnP, a metric bundle
    adjustment with K fixed) replaces the projective reconstruction and its upgrade. Returns the
    metric reconstruction and the observations kept, or None when it failed."""
    from geocert.solvers.reconstruction.calibrated import CalibratedOptions, calibrated_reconstruction

    stages["autocalibration"].update(status="skipped", reason="K is known: no metric upgrade is needed")
    with _timed(stages, "projective") as stage:
        stage["method"] = "calibrated (K known: essential matrices, PnP, metric bundle adjustment)"
        tell("projective", 0, n_views)
        found = calibrated_reconstruction(
            tracks, [K] * n_views, CalibratedOptions(max_reprojection_px=2 * options.threshold_px,
                                                      pnp_min_inliers=options.min_inliers, seed=options.seed,
                                                      merge_components=options.merge_components),
            lambda progress: tell.asks("projective", progress.get("done", 0), progress.get("total", 1)))
        stage.update(_plain(found.stats))
        for v in range(n_views):
            out.cameras[v].registered = found.rotations[v] is not None
            out.cameras[v].reason = found.reasons[v]
        if found.status == "cancelled":  # the views registered so far are kept, with their metric cameras
            stage.update(status="cancelled", reason="the job was cancelled: the views registered before it are kept")
            if sum(R is not None for R in found.rotations) >= 2:
                out.metric = _normalise_frame(upgrade.Metric(
                    K, list(found.rotations), [None if t is None else np.asarray(t, dtype=float)
                                               for t in found.translations],
                    np.asarray(found.points, dtype=float), [], False))
                _metric_cameras(out, out.metric, n_views)
            raise Cancelled("bundle_adjustment")
        if sum(R is not None for R in found.rotations) < 2:
            stage.update(status="failed", reason=found.stats.get("reason") or "fewer than 2 views registered")
            _skip(stages, "projective", "the calibrated reconstruction failed")
            return None
    keep = np.concatenate(found.inliers) if found.inliers else np.zeros(0, dtype=bool)
    metric = upgrade.Metric(K, list(found.rotations), [None if t is None else np.asarray(t, dtype=float)
                                                       for t in found.translations],
                            np.asarray(found.points, dtype=float), [], False)
    return metric, keep


def _undistorted_tracks(tracks, centres: np.ndarray, focal: float, k1: float) -> list:
    """The tracks with their pixels undistorted (bundle.undistort about each view's principal point
    ``centres[view]``), every observation at once: each pixel's undistortion is its own (Newton's
    method point by point), so the same as track by track, without a call per track."""
    if not tracks:
        return []
    views = [np.asarray(v, dtype=int) for v, _ in tracks]
    pixels = np.concatenate([np.asarray(p, dtype=float).reshape(-1, 2) for _, p in tracks])
    every_view = np.concatenate(views)
    undistorted = bundle.undistort(pixels, centres[every_view], focal, k1)
    ends = np.cumsum([len(v) for v in views])[:-1]
    return [(original, part) for (original, _), part in zip(tracks, np.split(undistorted, ends))]


def _incremental(tracks, image_sizes, options: ReconstructionOptions, obs: Observations, asks):
    """K unknown, COLMAP's way: the K-known path (calibrated.py) from a prior K (focal length
    ``focal_prior_factor`` times the larger image side, or ``focal_prior_px``; the principal point
    at the image's centre) refining one shared focal length in its adjustments as it places the
    views (CalibratedOptions.refine_focal), then a metric adjustment refining it (and, with
    ``radial_distortion`` "auto" or "on", one radial term k1, bundle model "radial"); when it moves
    the focal length by more than 2% or k1 by more than RADIAL_STEP_PX at the image's corner, the
    K-known path again from the refined K on the observations undistorted with the refined k1,
    resumed from the adjusted cameras (its views kept, those it lacks registered, the final
    adjustments run again: not every view registered again from a new initial pair) (at most
    ``focal_prior_rounds`` times); when only k1 moved (the focal length by 2% or less) from 0
    (the first term found), every view the tracks see is registered and ``radial_distortion``
    is "auto", the radial term is tested (_radial_test) before that round, and a term rejected
    ends the rounds. Returns the
    reconstruction as a projective.Projective (P = K [R | t] and the points, for the certified
    upgrade), the upgrade.Metric the adjustment found (its k1 that of the pixels given) and the
    radial term's figures."""
    from geocert.solvers.reconstruction.calibrated import CalibratedOptions, calibrated_reconstruction

    n_views = len(image_sizes)
    side = max(max(size) for size in image_sizes)
    focal = options.focal_prior_px or options.focal_prior_factor * side
    centres = np.array([[(w - 1) / 2, (h - 1) / 2] for w, h in image_sizes])
    corner = max(np.hypot(w, h) / 2 for w, h in image_sizes)
    model = "simple" if options.radial_distortion == "off" else "radial"
    history, metric, found, k1, resume, first = [], None, None, 0.0, None, {}
    radial = {"model": options.radial_distortion, "estimated": False, "k1": 0.0}
    unadjusted = False  # the cameras kept are the last round's, at its focal length, not adjusted (a stop)
    seen = len({int(v) for views, _ in tracks for v in views})  # the views the tracks see

    def register(focal: float, k1: float, resume):
        """One round: the K-known path at this focal length (resumed from cameras, or from a new
        initial pair), then the adjustment; returns (found, its metric start, the adjusted metric
        or None when it stopped or found fewer than 2 views, the round's figures)."""
        Ks = [np.array([[focal, 0.0, c[0]], [0.0, focal, c[1]], [0.0, 0.0, 1.0]]) for c in centres]
        used = tracks if k1 == 0.0 else _undistorted_tracks(tracks, centres, focal, k1)
        found = calibrated_reconstruction(used, Ks, CalibratedOptions(
            max_reprojection_px=2 * options.threshold_px, pnp_min_inliers=options.min_inliers, seed=options.seed,
            merge_components=options.merge_components, refine_focal=True), lambda progress: asks(progress.get("done", 0),
                                                                               progress.get("total", 1)),
            start_from=resume)
        first.update({key: found.stats[key] for key in ("initial_pair", "initial_pair_search")
                      if key in found.stats and key not in first})
        found.stats.update(first)  # a resumed round's initial pair is the first round's
        registered = sum(R is not None for R in found.rotations)
        # the focal length the registration refined as it went (Ks[0]'s when it did not: "lsmr")
        K = found.Ks[0] if found.Ks else Ks[0]
        step = {"focal_px": float(focal), "registration_focal_px": float(K[0, 0]), "k1": k1,
                "registered": int(registered), "resumed": resume is not None}
        if registered < 2:
            return found, None, None, step
        start = upgrade.Metric(K, list(found.rotations), [None if t is None else np.asarray(t, dtype=float)
                                                               for t in found.translations],
                               np.asarray(found.points, dtype=float), [], False, k1=k1)
        if found.status == "cancelled":
            return found, start, None, step
        adjusted, _, _ = upgrade.adjust(start, obs.view, obs.track, obs.pixel, options.threshold_px, model=model,
                                        should_stop=lambda: asks(0, 1))  # stopped: the next round's stops too
        step.update(refined_focal_px=float(adjusted.K[0, 0]), refined_k1=adjusted.k1)
        return found, start, adjusted, step

    for _ in range(options.focal_prior_rounds):
        found, start, metric, step = register(focal, k1, resume)
        history.append(step)
        if start is None:
            break
        if metric is None:  # cancelled: the views registered so far are kept, at the focal length they had
            metric = start
            unadjusted = True
            break
        focal = step["registration_focal_px"]  # what this round's views were registered at
        refined = float(metric.K[0, 0])
        moved = abs(metric.k1 * (corner / refined) ** 3 * refined - k1 * (corner / focal) ** 3 * focal)
        if not (refined > 0 and np.isfinite(refined) and np.isfinite(metric.k1)) or (
                abs(refined / focal - 1) <= 0.02 and moved <= RADIAL_STEP_PX):
            break
        if abs(refined / focal - 1) <= 0.02 and options.radial_distortion == "auto" and k1 == 0.0 \
                and step["registered"] == seen:
            # Only a new k1 asks for another round (this round's pixels were not undistorted), and
            # no view is left to place: the radial term is tested first, and a term the data do
            # not support is not worth a registration on pixels undistorted with it (on every 2nd
            # templeRing photo k1 asked for a second round, and the test rejects the term). A
            # term already registered with (Sceaux: the second round's) is refined, not tested
            # again until the end. With views missing the rounds go on as they were: a resumed
            # round, or a new registration after it, may place them (the dinoSparseRing's sixth
            # view).
            metric, early = _radial_test(metric, obs, options, dict(radial))
            step["radial_tested"] = True
            if not early["estimated"]:
                radial = early
                break
        focal, k1 = refined, metric.k1
        resume = (metric.rotations, metric.translations)
    # A resumed round keeps the views a wrong prior focal length placed and adds those PnP finds;
    # when views are still missing, one new registration at the refined K may place more (on the
    # dinoSparseRing: 6 of 14 against 5 resumed); the one registering more views is kept.
    if history and history[-1]["resumed"] and found.status != "cancelled" and metric is not None \
            and history[-1]["registered"] < seen:
        again, again_start, again_metric, step = register(float(metric.K[0, 0]), metric.k1, None)
        step["again_from_a_new_pair"] = True
        if again_metric is not None:
            # Kept by how well each explains every observation (fit_cost), not by views alone: on
            # the dinoSparseRing both place 6 views, the resumed one with a camera 45 degrees off
            # and 523 observations fitting, the new one within 0.4 degrees and 730 fitting.
            resumed_cost, again_cost = (fit_cost(m, obs, options.threshold_px) for m in (metric, again_metric))
            step.update(fit_cost=again_cost, resumed_fit_cost=resumed_cost)
            if again_cost < resumed_cost:
                found, metric = again, again_metric
        history.append(step)
    if metric is not None and model == "radial" and found.status != "cancelled":  # (a term rejected early: k1 is 0)
        metric, radial = _radial_test(metric, obs, options, radial)
    principal = None
    if metric is not None and found.status != "cancelled" and not unadjusted:
        metric, principal = _registration_principal_point(metric, obs, options, image_sizes, radial)
    registered = [v for v in range(n_views) if found is not None and found.rotations[v] is not None]
    cameras: list = [None] * n_views
    points = np.full((len(tracks), 4), np.nan)
    inlier = np.zeros(len(obs.view), dtype=bool)
    stats = {"focal_rounds": history, "views_registered": len(registered)}
    if metric is not None:
        for v in registered:
            cameras[v] = structure.camera_matrix(upgrade.K_of(metric, v), metric.rotations[v], metric.translations[v])
        finite = np.isfinite(metric.points[:, 0])
        points[finite] = np.c_[metric.points[finite], np.ones(int(finite.sum()))]
        inlier = np.concatenate(found.inliers) if found.inliers else inlier
        finite = np.isfinite(points[obs.track, 0])
        inlier &= finite
        seen_by = np.isin(obs.view, registered)
        # Every observation counted once, as the projective path counts them.
        stats.update({"observations": int(len(obs.view)), "observations_kept": int(inlier.sum()),
                      "outliers_removed": int((seen_by & finite & ~inlier).sum()),
                      "observations_of_dropped_tracks": int((seen_by & ~finite).sum()),
                      "observations_of_unregistered_views": int((~seen_by).sum())})
        stats.update({key: value for key, value in found.stats.items()
                      if key in ("initial_pair", "initial_pair_search", "points", "rms_reprojection_px",
                                 "merged")})
    elif found is not None and found.stats.get("reason"):
        stats["reason"] = found.stats["reason"]
    if found is not None and found.status == "cancelled":
        stats["cancelled"] = True
        stats["stopped_before_adjustment"] = unadjusted
    reasons = [None if cameras[v] is not None else (found.reasons[v] if found is not None else "not reached")
               for v in range(n_views)]
    stats["radial_distortion"] = radial
    if principal is not None:
        stats["principal_point"] = principal
    out = projective.Projective(cameras, reasons, points, inlier,
                                None if found is None else found.stats.get("initial_pair"), stats)
    return out, metric, radial


# The registration's cameras (the certificate's) are built at the principal point the data fix
# when the returned cameras estimate it (False: always at the image's centre, as before; for tests
# of results built so).
REGISTER_AT_PRINCIPAL_POINT = True


def _registration_principal_point(metric: upgrade.Metric, obs: Observations, options: ReconstructionOptions,
                                  image_sizes, radial: dict):
    """The registration's adjusted cameras again with the principal point free (bundle model
    "principal"), kept by _principal_point's test, when the returned cameras will estimate it (the
    adjustment run, camera_model "simple" with principal_point "auto" or "per_view", or "full"),
    the views share
    one image size and no radial term (about the image's centre) was kept. The cameras K [R | t]
    built from the reconstruction kept are the projective reconstruction the certified upgrade
    starts from, and the calibration certificate's: held at the image's centre while the tracks'
    principal point lies elsewhere, that model fits them worse than the returned cameras by what
    holding it costs, and the adjustment's robust rounds (the observations beyond the threshold in
    that model dropped) put its fit farther from the model's least-squares fit than the verifier's
    tie allows (114 px off centre on the synthetic scene: 3,323 px^2 against 2,899). Built at the
    estimated principal point, they fit the tracks as the returned cameras do, and the tie holds
    them to those. Where the free fit lies outside the middle half the cameras stay at the centre,
    and with camera_model "full" (whose adjustment keeps the observations the centred model
    misfits) they are that model's least-squares fit (_centred_least_squares). Returns the
    reconstruction kept and the test's figures (None: not tested). The "principal" fit goes with
    the radial figures (RIVAL_FIT) for the adjustment's own test to reuse."""
    sizes = {tuple(size) for size in image_sizes}
    # (without the adjustment the returned cameras are the certified upgrade's with the model's K,
    # the principal point at the centre when "simple": poses found at another would not fit it)
    estimates = options.bundle_adjustment and (options.camera_model == "full" or (
        options.camera_model == "simple" and options.principal_point in ("auto", "per_view")))
    if not (REGISTER_AT_PRINCIPAL_POINT and estimates and len(sizes) == 1 and not radial["estimated"]):
        return metric, None
    keep = _kept(metric, obs, options.threshold_px)
    prefit = radial.get(RIVAL_FIT)
    if prefit is None or not _same_registration(prefit[0], metric):
        trial, trial_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, options.threshold_px,
                                              model="principal")
        prefit = radial[RIVAL_FIT] = (trial, trial_keep)
    kept, _, figures = _principal_point(metric, obs, keep, options.threshold_px, next(iter(sizes)), prefit)
    if options.camera_model == "full" and not figures["estimated"] and figures.get("inside_middle_half") is False:
        kept = _centred_least_squares(kept, obs, prefit[1])
    return kept, figures


def _centred_least_squares(metric: upgrade.Metric, obs: Observations, keep: np.ndarray) -> upgrade.Metric:
    """The registration held at the images' centre (its free fit outside the middle half) with
    camera_model "full": its cameras and points adjusted again in the same model (one focal
    length, square pixels, no skew, the principal point at the centre) by plain least squares on
    the observations the free fit keeps (``keep``: those the full model's adjustment, which frees
    the principal point, keeps too), from the robust fit; the calibration certificate is built on
    the result. The verifier holds a certificate built at the centre to the returned reconstruction
    re-adjusted in that model by least squares over the observations it shares with the result
    (calibration_tie._centred_reference, CENTRED_REFERENCE), and the robust fit (the observations
    the centred model misfits beyond the threshold dropped, which the full model keeps) lay 4.2 to
    7.1 px from it on the synthetic scene's off-centre runs, against 3.8 allowed; this fit lies
    within 0.001 px of it there. The verifier is unchanged: a certificate gets no more room than
    before. A point the free fit keeps fewer than 2 observations of is not moved (one observation
    leaves it free), and the robust fit is kept where this one is not finite."""
    views = np.array([v for v, R in enumerate(metric.rotations) if R is not None])
    vindex = -np.ones(len(metric.rotations), dtype=int)
    vindex[views] = np.arange(len(views))
    seen = keep & (vindex[obs.view] >= 0) & np.isfinite(metric.points[obs.track, 0])
    points = np.flatnonzero(np.bincount(obs.track[seen], minlength=len(metric.points)) >= 2)
    pindex = -np.ones(len(metric.points), dtype=int)
    pindex[points] = np.arange(len(points))
    use = np.flatnonzero(seen & (pindex[obs.track] >= 0))
    if len(use) == 0:
        return metric
    K, R, t, X, _, _ = bundle.metric(metric.K, np.array([metric.rotations[v] for v in views]),
                                     np.array([metric.translations[v] for v in views]), metric.points[points],
                                     vindex[obs.view[use]], pindex[obs.track[use]], obs.pixel[use], model="simple")
    if not all(np.all(np.isfinite(a)) for a in (K, R, t, X)):
        return metric
    rotations, translations, placed = list(metric.rotations), list(metric.translations), metric.points.copy()
    for k, v in enumerate(views):
        rotations[v], translations[v] = R[k], t[k]
    placed[points] = X
    return replace(metric, K=K, rotations=rotations, translations=translations, points=placed)


RADIAL_STEP_PX = 0.5  # k1 moved by less than this at the image's corner: no further registration round


def _radial_test(metric: upgrade.Metric, obs: Observations, options: ReconstructionOptions, radial: dict):
    """Whether the radial term is kept: "on" always; "auto" when the adjustment without it (k1 = 0;
    bundle model "principal", the principal point free, when options.principal_point is "auto",
    else "simple") costs more, on the observations both keep, than RADIAL_CHI2 noise variances
    (the residuals' own, from the fit with it): a principal point off the image's centre, which a
    radial term about the centre partly fits, is left to the principal point's own test. Returns
    the reconstruction kept (the one without the term is adjusted again with the principal point
    held, as the pipeline's later stages expect) and the figures."""
    if metric.k1 == 0.0:
        return metric, radial
    if options.radial_distortion == "auto":
        with_keep = _kept(metric, obs, options.threshold_px)
        rival = "principal" if options.principal_point in ("auto", "per_view") else "simple"
        trial, trial_keep, _ = upgrade.adjust(replace(metric, k1=0.0), obs.view, obs.track, obs.pixel,
                                              options.threshold_px, model=rival)
        common = with_keep & trial_keep
        # the free fit's intrinsics: f and k1 (bundle model "radial")
        statistic, _ = _saved_variances(trial, metric, obs, common, 2)
        if np.isnan(statistic):
            trial, _, _ = upgrade.adjust(replace(metric, k1=0.0), obs.view, obs.track, obs.pixel,
                                         options.threshold_px, model="simple")
            return trial, {**radial, "reason": "too few observations to test"}
        radial.update(chi2=float(statistic), threshold=RADIAL_CHI2, k1_tested=metric.k1, against=rival)
        if not statistic > RADIAL_CHI2:
            if rival != "simple":
                # The "principal" fit is what _principal_point would fit again from nearly the same
                # start: it goes with the figures (RIVAL_FIT, taken out before they are reported).
                radial[RIVAL_FIT] = (trial, trial_keep)
                trial, _, _ = upgrade.adjust(replace(metric, k1=0.0), obs.view, obs.track, obs.pixel,
                                             options.threshold_px, model="simple")
            return trial, radial
    return metric, {**radial, "estimated": True, "k1": float(metric.k1)}


RIVAL_FIT = "_rival_fit"  # the radial figures' key of the rival's (Metric, keep), never reported


def _fixed_radial_test(metric: upgrade.Metric, obs: Observations, keep: np.ndarray, options: ReconstructionOptions,
                       should_stop=None):
    """K known: whether one radial term k1 about K's principal point is kept, K held as given (the
    adjustment again with it, bundle model "fixed_radial", from the "fixed" one): "off" never
    (None: no figures); "on" always; "auto" when it lowers the cost on the observations both keep
    by more than RADIAL_CHI2 noise variances (the residuals' own, from the fit with it, over their
    degrees of freedom), as _radial_test judges the K-unknown term. A real lens's distortion that
    K does not model (Sceaux Castle's, with openMVG's K) otherwise adds to every camera's misfit.
    Returns the reconstruction kept (its k1 that of the pixels given), the observations kept and
    the test's figures."""
    if options.radial_distortion == "off":
        return metric, keep, None
    figures = {"model": options.radial_distortion, "estimated": False}
    trial, trial_keep, _ = upgrade.adjust(replace(metric, k1=0.0), obs.view, obs.track, obs.pixel,
                                          options.threshold_px, model="fixed_radial", should_stop=should_stop)
    if not (np.isfinite(trial.k1) and trial.k1 != 0.0 and trial_keep.any()):
        return metric, keep, {**figures, "reason": "the adjustment found no finite radial term"}
    figures["k1_tested"] = float(trial.k1)
    common = keep & trial_keep
    n = int(common.sum())
    # the free fit's intrinsics: k1 alone (K held; templeSparseRing's 1 px term, 16 of 16 cameras
    # certified without it and 15 with it, fails with its residual degrees of freedom counted)
    statistic, dof = _saved_variances(metric, trial, obs, common, 1)
    if not np.isnan(statistic):
        figures.update(chi2=statistic, threshold=RADIAL_CHI2, observations=n, residual_dof=int(dof))
    elif options.radial_distortion == "auto":
        return metric, keep, {**figures, "reason": "too few observations to test"}
    if options.radial_distortion == "on" or figures["chi2"] > RADIAL_CHI2:
        figures.update(estimated=True, k1=float(trial.k1))
        return trial, trial_keep, figures
    return metric, keep, figures


def _undistorted_K(out: Reconstruction, obs: Observations, metric: upgrade.Metric, n_views: int,
                   radial: dict) -> Observations:
    """K known: every observation undistorted with the radial term _fixed_radial_test kept (about
    K's principal point, bundle.undistort_K): from here on the reconstruction is a pinhole one on
    these pixels (metric.k1 0), and every certificate after it is about them, so conditional on
    that k1 (out.distortion says so, and the points return the undistorted observations)."""
    K = metric.K
    out.distortion = {"model": "radial_k1", "k1_at_focal_px": float(K[0, 0]), "k1": float(metric.k1),
                      "centres": [K[:2, 2].tolist()] * n_views, "test": radial, "about": "principal_point"}
    pixels = bundle.undistort_K(obs.pixel, K, metric.k1)
    metric.k1 = 0.0
    return replace(obs, pixel=pixels)


def _kept(metric: upgrade.Metric, obs: Observations, threshold_px: float) -> np.ndarray:
    """The observations within threshold_px of their points' images in front of their cameras."""
    registered = np.array([R is not None for R in metric.rotations])
    use = np.flatnonzero(registered[obs.view] & np.isfinite(metric.points[obs.track, 0]))
    keep = np.zeros(len(obs.view), dtype=bool)
    depth, error = _depths_and_errors(metric, obs, use)
    keep[use] = (depth > 0) & (error <= threshold_px)
    return keep


MIN_TEST_OBSERVATIONS = 20  # a model test on fewer observations (both fits keep) is not made
# The per-view principal points' trial is run only when their deviations, predicted before it
# (_principal_points_per_view), are within this many times camera_claim.MAX_PRINCIPAL_POINT_SD_PX:
# the prediction takes the noise at the linearised fit's minimum, and the trial's own deviations
# would have to come out this many times smaller to pass.
PRECISE_MARGIN = 3.0


def _residual_dof(obs: Observations, common: np.ndarray, intrinsics: int) -> int:
    """The residual degrees of freedom of a fit on the observations ``common``: 2 per observation
    less every parameter the fit spends on them: 6 per view's pose and 3 per point they see (less
    the 7 of the similarity cameras and points are fixed up to) and the fit's ``intrinsics``."""
    n = int(common.sum())
    views, points = len(np.unique(obs.view[common])), len(np.unique(obs.track[common]))
    return 2 * n - (6 * views + 3 * points - 7) - int(intrinsics)


def _saved_variances(held: upgrade.Metric, free: upgrade.Metric, obs: Observations, common: np.ndarray,
                     intrinsics: int) -> tuple[float, int]:
    """What freeing parameters saves, in noise variances, for every model test (read against the
    chi-square quantile for the parameters freed): the cost of the fit holding them less that of
    the fit freeing them, on the observations both keep, over the noise variance: the free fit's
    cost over its residual degrees of freedom (_residual_dof, ``intrinsics`` the free fit's
    calibration parameters), at least 1e-4 px^2 (residuals below 0.01 px are rounding, not
    noise). Over 2 per observation alone (the poses and points not counted) the variance of
    tracks seen in 2 to 3 views is 0.4 to 0.6 times the noise's and the statistic as much too
    large: templeSparseRing's K-known radial term (1 px at the image's corner) passed at 11.1
    against 10.8 and fails at 4.4. Returns the statistic (NaN, too few observations to test, below
    MIN_TEST_OBSERVATIONS or without residual degrees of freedom) and the degrees of freedom."""
    n = int(common.sum())
    dof = _residual_dof(obs, common, intrinsics)
    if n < MIN_TEST_OBSERVATIONS or dof < 1:
        return float("nan"), dof
    held_cost, free_cost = _rms(held, obs, common) ** 2 * n, _rms(free, obs, common) ** 2 * n
    return float((held_cost - free_cost) / max(free_cost / dof, 1e-4)), dof


def _principal_point(metric: upgrade.Metric, obs: Observations, keep: np.ndarray, threshold_px: float, image_size,
                     prefit: tuple | None = None):
    """The principal point estimated when the data fix it: the adjustment again with it free
    (bundle model "principal"), kept when it lowers the cost on the observations both keep by
    more than PRINCIPAL_POINT_CHI2 noise variances (the residuals' own, from the freer fit) and
    lands in the middle half of the image; else the image centre stays. Returns the
    reconstruction, the observations kept and the test's figures. ``prefit``: a "principal" fit
    of the same observations already made (the radial test's rival, (Metric, keep)), used instead
    of a new one when it registers the same views and tracks as ``metric`` and explains every
    observation at least as well (fit_cost): the adjustment from ``metric`` would end where it did."""
    trial = None
    if prefit is not None and _same_registration(prefit[0], metric) and \
            fit_cost(prefit[0], obs, threshold_px) <= fit_cost(metric, obs, threshold_px):
        trial, trial_keep = prefit
    if trial is None:
        trial, trial_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, threshold_px, model="principal")
    common = keep & trial_keep
    n = int(common.sum())
    figures = {"estimated": False, "observations": n, "K_free": trial.K.tolist()}
    statistic, _ = _saved_variances(metric, trial, obs, common, 3)  # the free fit's f and principal point
    if np.isnan(statistic):
        return metric, keep, {**figures, "reason": "too few observations to test"}
    # The free model nests the held one: a local fit ending above it on the common observations
    # saved nothing (0, never a negative or subnormal statistic, which the verifier refuses as
    # written by no fit). The decision is unchanged: the threshold is positive.
    statistic = statistic if statistic >= sys.float_info.min else 0.0
    u, v = trial.K[0, 2], trial.K[1, 2]
    inside = camera_claim.in_middle_half(u, v, image_size[0], image_size[1])
    figures.update(chi2=float(statistic), threshold=PRINCIPAL_POINT_CHI2, inside_middle_half=bool(inside))
    if statistic > PRINCIPAL_POINT_CHI2 and inside:
        figures["estimated"] = True
        return trial, trial_keep, figures
    return metric, keep, figures


def _same_registration(a: upgrade.Metric, b: upgrade.Metric) -> bool:
    """The same views registered and the same tracks reconstructed."""
    return len(a.rotations) == len(b.rotations) and a.points.shape == b.points.shape and \
        [R is None for R in a.rotations] == [R is None for R in b.rotations] and \
        bool(np.array_equal(np.isfinite(a.points[:, 0]), np.isfinite(b.points[:, 0])))


def _principal_points_per_view(metric: upgrade.Metric, obs: Observations, keep: np.ndarray, threshold_px: float,
                               image_size):
    """A principal point per view, estimated when the data fix them (options.principal_point
    "per_view"): the adjustment again with each view's own (bundle model "principal_per_view", from
    the one the views share), kept when it lowers the cost on the observations both keep by more
    than the chi-square quantile at 1 - PRINCIPAL_POINT_P for the 2 (views - 1) parameters it adds
    (2 views more when the shared one is held at the centre) in noise variances (the residuals'
    own, from the freer fit), every view's lies in the middle half of the image and the data fix
    each to camera_claim.MAX_PRINCIPAL_POINT_SD_PX (_principal_point_sd); else the shared one stays.
    Returns the reconstruction, the observations kept and the test's figures."""
    from scipy.special import chdtri  # chi2.ppf(1 - p, k), without scipy.stats' import (about 0.4 s of CPU)

    views = [v for v, R in enumerate(metric.rotations) if R is not None]
    centre = np.array([image_size[0] / 2, image_size[1] / 2])
    added = 2 * (len(views) - 1) + (2 if np.allclose(metric.K[:2, 2], centre) else 0)
    # The trial adjustment (two rounds at their cap, the slowest of the job's) only when the data
    # could fix each view's principal point: their deviations from the shared fit, each view given
    # the shared one, at the noise of the linearised per-view fit's minimum (the misfit a shift of
    # its own would absorb taken off). Beyond PRECISE_MARGIN times the limit the trial could not
    # pass its precision test: the shared principal point stays, the trial not run.
    if len(views) >= 2 and int(keep.sum()) >= MIN_TEST_OBSERVATIONS:
        shared = replace(metric, Ks=[None if R is None else upgrade.K_of(metric, v).copy()
                                     for v, R in enumerate(metric.rotations)])
        predicted = _principal_point_sd(shared, obs, keep, views, linearised_minimum=True)
        if not np.all(predicted <= PRECISE_MARGIN * camera_claim.MAX_PRINCIPAL_POINT_SD_PX):
            finite = predicted[np.isfinite(predicted)]
            return metric, keep, {
                "estimated": False, "observations": int(keep.sum()), "parameters_added": added,
                "sd_px": [float(finite.min()), float(np.median(finite)), float(finite.max())] if len(finite) else [],
                "max_sd_px": camera_claim.MAX_PRINCIPAL_POINT_SD_PX, "precise": False,
                "reason": f"the data do not fix each view's principal point: predicted from the shared fit, "
                          f"deviations beyond {PRECISE_MARGIN:g} times max_sd_px (the trial not run)"}
    trial, trial_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, threshold_px,
                                          model="principal_per_view")
    common = keep & trial_keep
    n = int(common.sum())
    figures = {"estimated": False, "observations": n, "parameters_added": added}
    if n < MIN_TEST_OBSERVATIONS or len(views) < 2 or trial.Ks is None:
        return metric, keep, {**figures, "reason": "too few observations to test"}
    # the free fit's intrinsics: the focal length and each view's principal point
    statistic, _ = _saved_variances(metric, trial, obs, common, 1 + 2 * len(views))
    if np.isnan(statistic):
        return metric, keep, {**figures, "reason": "too few observations to test"}
    threshold = float(chdtri(added, PRINCIPAL_POINT_P))
    sd = _principal_point_sd(trial, obs, trial_keep, views)
    offsets = np.array([trial.Ks[v][:2, 2] - centre for v in views])
    inside = bool(np.all(np.abs(offsets) <= np.array(image_size, dtype=float) / 4))
    spread = np.linalg.norm(np.array([trial.Ks[v][:2, 2] for v in views]) - trial.K[:2, 2], axis=1)
    precise = bool(np.all(sd <= camera_claim.MAX_PRINCIPAL_POINT_SD_PX))
    figures.update(chi2=float(statistic), threshold=threshold, inside_middle_half=inside,
                   spread_px=[float(spread.min()), float(np.median(spread)), float(spread.max())],
                   sd_px=[float(sd.min()), float(np.median(sd)), float(sd.max())],
                   max_sd_px=camera_claim.MAX_PRINCIPAL_POINT_SD_PX, precise=precise)
    if statistic > threshold and inside and precise:
        figures["estimated"] = True
        return trial, trial_keep, figures
    return metric, keep, figures


def _focals_per_view(metric: upgrade.Metric, obs: Observations, keep: np.ndarray, threshold_px: float):
    """A focal length of its own for each view whose focal length the data set apart from the
    others' (options.principal_point "per_view", after a principal point per view was kept), as
    the principal points are tested: every view given its own (bundle model "focal_groups", a group
    each) screens them, a view standing apart when its focal length lies more than the normal
    quantile at 1 - FOCAL_P / (2 views) (Bonferroni's) of its standard deviation from the others'
    median; those views are then given their own (the others sharing one), kept when that lowers
    the cost on the observations both keep by more than the chi-square quantile at 1 - FOCAL_P
    for the parameters it adds, in noise variances (the residuals' own, from the freer fit), and
    the data fix each focal length to camera_claim.MAX_FOCAL_SD_FRACTION of it and each view's
    principal point to camera_claim.MAX_PRINCIPAL_POINT_SD_PX. EXIF states one focal length for
    every photo of Sceaux Castle, yet one of its 11 views is 2% shorter than the others (a focus
    or stabiliser change EXIF does not record): the shared one fit no view well enough to certify
    two of them. Returns the reconstruction, the observations kept and the test's figures."""
    from scipy.special import chdtri, ndtri  # the quantiles without scipy.stats' import (as the per-view test)

    views = [v for v, R in enumerate(metric.rotations) if R is not None]
    figures = {"estimated": False, "views": []}
    if len(views) < 3 or metric.Ks is None:
        return metric, keep, {**figures, "reason": "fewer than 3 views to compare"}
    each = {v: k for k, v in enumerate(views)}
    screen, screen_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, threshold_px,
                                            model="focal_groups", groups=each)
    _, focal_sd = _intrinsics_sd(screen, obs, screen_keep, views, np.arange(len(views)))
    focals = np.array([screen.Ks[v][0, 0] for v in views])
    z = np.array([(focals[k] - np.median(np.delete(focals, k))) / focal_sd[k] for k in range(len(views))])
    z_threshold = float(-ndtri(FOCAL_P / (2 * len(views))))
    own = [v for k, v in enumerate(views) if np.isfinite(z[k]) and abs(z[k]) > z_threshold]
    figures.update(z=[float(value) for value in z], z_threshold=z_threshold, views=own)
    if not own or len(own) > len(views) - 2:
        figures["views"] = []
        return metric, keep, {**figures, "reason": "no view's focal length stands apart from the others'" if not own
                              else "the focal lengths stand apart in most views: no one focal length to share"}
    groups = {v: 0 for v in views}
    groups.update({v: k + 1 for k, v in enumerate(own)})
    trial, trial_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, threshold_px, model="focal_groups",
                                          groups=groups)
    common = keep & trial_keep
    n = int(common.sum())
    added = len(own)
    figures.update(observations=n, parameters_added=added)
    # the free fit's intrinsics: a focal length per group (the shared one and each own) and each
    # view's principal point
    statistic, _ = _saved_variances(metric, trial, obs, common, 1 + added + 2 * len(views))
    if np.isnan(statistic):
        return metric, keep, {**figures, "reason": "too few observations to test"}
    threshold = float(chdtri(added, FOCAL_P))
    sd, focal_sd = _intrinsics_sd(trial, obs, trial_keep, views, np.array([groups[v] for v in views]))
    relative = [float(focal_sd[groups[v]] / trial.Ks[v][0, 0]) for v in own]
    precise = bool(np.all(sd <= camera_claim.MAX_PRINCIPAL_POINT_SD_PX)
                   and all(r <= camera_claim.MAX_FOCAL_SD_FRACTION for r in relative))
    figures.update(chi2=float(statistic), threshold=threshold, focal_sd=relative,
                   max_focal_sd=camera_claim.MAX_FOCAL_SD_FRACTION,
                   sd_px=[float(sd.min()), float(np.median(sd)), float(sd.max())],
                   max_sd_px=camera_claim.MAX_PRINCIPAL_POINT_SD_PX, precise=precise)
    if statistic > threshold and precise:
        figures["estimated"] = True
        return trial, trial_keep, figures
    return metric, keep, figures


def _intrinsics_sd(metric: upgrade.Metric, obs: Observations, keep: np.ndarray, views: list,
                   groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """principal_points.with_focal_groups in ``metric`` (each view's principal point's sd and each
    group's focal length's, px), on the observations ``keep`` of points it holds (infinite where
    they cannot be computed)."""
    from geocert.solvers.reconstruction import principal_points

    vindex = -np.ones(len(metric.rotations), dtype=int)
    vindex[views] = np.arange(len(views))
    use = keep & (vindex[obs.view] >= 0) & np.isfinite(metric.points[obs.track, 0])
    tracks, track = np.unique(obs.track[use], return_inverse=True)
    try:
        sd, focal_sd, _, _ = principal_points.with_focal_groups(
            [metric.Ks[v] for v in views], [metric.rotations[v] for v in views],
            [metric.translations[v] for v in views], metric.points[tracks], vindex[obs.view[use]], track,
            obs.pixel[use], groups)
    except (np.linalg.LinAlgError, ValueError):
        return np.full(len(views), np.inf), np.full(int(np.max(groups)) + 1, np.inf)
    return np.where(np.isfinite(sd), sd, np.inf), np.where(np.isfinite(focal_sd), focal_sd, np.inf)


def _principal_point_sd(metric: upgrade.Metric, obs: Observations, keep: np.ndarray, views: list,
                        linearised_minimum: bool = False) -> np.ndarray:
    """principal_points.with_focal_groups' deviation of each view's principal point (px) in
    ``metric`` (one focal group), on the observations ``keep`` of points it holds (infinite where
    they cannot be computed); ``linearised_minimum``: at the noise of the linearised fit's minimum."""
    from geocert.solvers.reconstruction import principal_points

    vindex = -np.ones(len(metric.rotations), dtype=int)
    vindex[views] = np.arange(len(views))
    use = keep & (vindex[obs.view] >= 0) & np.isfinite(metric.points[obs.track, 0])
    tracks, track = np.unique(obs.track[use], return_inverse=True)
    try:
        sd, _, _, _ = principal_points.with_focal_groups(
            [metric.Ks[v] for v in views], [metric.rotations[v] for v in views],
            [metric.translations[v] for v in views], metric.points[tracks], vindex[obs.view[use]], track,
            obs.pixel[use], linearised_minimum=linearised_minimum)
    except (np.linalg.LinAlgError, ValueError):
        return np.full(len(views), np.inf)
    return np.where(np.isfinite(sd), sd, np.inf)


def _plain(stats: dict) -> dict:
    return {key: value for key, value in stats.items() if key not in ("ba_nfev",)}


def _run(tracks, image_sizes, options: ReconstructionOptions, stages, out: Reconstruction, tell) -> None:
    n_views = len(image_sizes)
    obs = Observations.from_tracks(tracks, n_views)
    known = options.known_K()
    if known is not None:
        found = _calibrated(tracks, n_views, known, options, stages, out, tell, obs)
        if found is None:
            return
        metric, keep = found
        with _timed(stages, "bundle_adjustment") as stage:
            if options.bundle_adjustment:
                if tell.asks("bundle_adjustment", 0, 1):
                    _keep_metric(out, metric, n_views, stage)
                before = _rms(metric, obs, keep)
                stop, stopping = _stop_check(tell, "bundle_adjustment")
                metric, keep, figures = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, options.threshold_px,
                                                       model="fixed", should_stop=stopping)
                if stop["asked"]:
                    _keep_metric(out, metric, n_views, stage, "adjusted as far as the adjustment went")
                stage.update(started_from="calibrated", model="fixed", rms_px_before=before,
                             rms_px_after=_rms(metric, obs, keep), K=metric.K.tolist(),
                             observations_kept=figures["observations_kept"])
                tested, tested_keep, radial = _fixed_radial_test(metric, obs, keep, options, stopping)
                if stop["asked"]:  # the test's adjustment stopped: the adjusted cameras, without a term
                    _keep_metric(out, metric, n_views, stage, "adjusted, the radial term's test not finished")
                if radial is not None:
                    stage["radial_distortion"] = radial
                    if radial["estimated"]:
                        metric, keep = tested, tested_keep
                        obs = _undistorted_K(out, obs, metric, n_views, radial)
                        stage.update(rms_px_after=_rms(metric, obs, keep), observations_kept=int(keep.sum()))
                metric, keep = _depth_reversal(out, metric, obs, keep, options.threshold_px, "fixed", stage, tell,
                                               n_views)
                if not keep.any():
                    _none_kept(out, stages, stage, "bundle_adjustment", options.threshold_px,
                               "the adjusted reconstruction")
                    return
            else:
                stage.update(status="skipped", reason="options.bundle_adjustment is false")
                _depth_reversal_not_checked(out)
        out.metric = metric = _normalise_frame(metric)
        keep = _check_cameras(out, metric, obs, keep, options.threshold_px)
        _structure(tracks, n_views, options, stages, out, tell, obs, metric, keep)
        return
    incremental = rival_fit = None
    with _timed(stages, "projective") as stage:
        tell("projective", 0, n_views)
        if options.registration == "incremental":
            stage["method"] = ("incremental (K unknown: a focal prior, essential matrices, PnP, the focal length "
                               "refined by bundle adjustment; the cameras P = K [R | t] are the projective "
                               "reconstruction the certified upgrade starts from)")
            proj, incremental, radial = _incremental(tracks, image_sizes, options, obs,
                                                     lambda d, t: tell.asks("projective", d, t))
            rival_fit = radial.pop(RIVAL_FIT, None)
            if radial["estimated"]:
                obs = _undistorted(out, obs, incremental, image_sizes, radial)
        else:
            proj = projective.reconstruct(tracks, n_views, projective.ProjectiveOptions(
                options.threshold_px, options.min_inliers, seed=options.seed),
                lambda s, d, t: tell.asks("projective", d, t))
        stage.update({key: value for key, value in proj.stats.items() if key not in ("reason", "cancelled")})
        for v, P in enumerate(proj.cameras):
            out.cameras[v].registered = P is not None
            out.cameras[v].reason = proj.reasons[v]
            out.cameras[v].P = P
        registered = sum(P is not None for P in proj.cameras)
        if proj.stats.get("cancelled"):  # the views registered so far are kept (projective cameras)
            stage.update(status="cancelled", reason="the job was cancelled: the views registered before it are kept")
            if incremental is not None:
                _keep_registration(out, incremental, obs, proj.inlier, options.threshold_px, n_views, stage)
            raise Cancelled("autocalibration")
        if registered < 2:
            stage.update(status="failed", reason=proj.stats.get("reason") or "fewer than 2 views registered")
            _skip(stages, "projective", "the projective reconstruction failed")
            return
        if not np.any(proj.inlier & np.isfinite(proj.points[obs.track, 0])):
            _none_kept(out, stages, stage, "projective", options.threshold_px, "the registered views' reconstruction")
            return
    sizes = {tuple(image_sizes[v]) for v, P in enumerate(proj.cameras) if P is not None}
    image_size = next(iter(sizes)) if len(sizes) == 1 else None
    with _timed(stages, "autocalibration") as stage:
        method = options.autocalibration
        try:
            tell("autocalibration", 0, 1)
            metric = upgrade.autocalibrate(proj.cameras, proj.points, image_size, options.ranges(image_size),
                                           options.autocalibration_options(image_size),
                                           options.autocalibration_points, method,
                                           lambda p: tell(f"autocalibration {getattr(p, 'stage', '')}".strip(),
                                                          0, 1, p),
                                           skip_critical=options.autocalibration_on_critical_motion == "skip",
                                           observed=(obs.view[proj.inlier], obs.track[proj.inlier]),
                                           per_view=calibration_tie.TIE_POINTS_PER_CAMERA)
        except Cancelled:
            if incremental is not None:
                stage.update(status="cancelled", reason="the job was cancelled: no certified upgrade was found")
                _keep_registration(out, incremental, obs, proj.inlier, options.threshold_px, n_views, stage)
            raise
        stage.update(method=method, stages=metric.stages, certified=metric.certified, intrinsics=metric.ranges,
                     points_used=metric.autocalibration_points, K=None if metric.K is None else metric.K.tolist(),
                     cameras_built_with_one_K=calibration_claim.built_with_one_K(
                         [P for P in proj.cameras if P is not None]))
        if metric.stratified_not_run is not None:  # "auto" went straight to the direct method: said where
            stage["reason"] = metric.stratified_not_run  # the page shows the upgrade's status
        if metric.certified and options.certificate == "full":
            if metric.proven is None:  # the direct method's upgrade: no certificate of it is carried here
                said = ("the direct method certified this upgrade, but a reconstruction carries only the stratified "
                        "method's certificate: not claimed")
                stage.update(certified=False, reason=said if not stage.get("reason") else f"{stage['reason']}; {said}")
            else:  # which views and tracks the calibration certificate's cameras and points are
                out.proven = metric.proven
                stage.update(certificate_views=metric.proven.views, certificate_tracks=metric.proven.tracks)
        starts = []
        if metric.K is not None:
            starts.append(("autocalibration", metric))
        if incremental is not None:
            starts.append(("incremental", incremental))
        if metric.alternative is not None:
            alternative = upgrade.metric_from(proj.cameras, proj.points, *metric.alternative)
            starts.append(("linear", alternative))
            stage["linear_K"] = alternative.K.tolist()
        if metric.skipped is not None:
            stage.update(status="skipped", reason=metric.skipped + "; the adjustment starts from the linear estimate")
        elif metric.K is None:
            stage.update(status="failed", reason=metric.reason + (
                "; the adjustment starts from the linear estimate" if starts else ""))
        if not starts:
            _skip(stages, "autocalibration", "no metric upgrade was found")
            return
    keep = proj.inlier.copy()
    with _timed(stages, "bundle_adjustment") as stage:
        model = options.camera_model
        if model in ("simple", "varying") and image_size is not None:  # the principal point at the image centre
            # Copies, not the starts changed in place: the incremental start is the registration's
            # principal-point fit when its test kept one (rival_fit's reconstruction), and that fit,
            # its K left as the test found it, is what _principal_point reuses below instead of
            # adjusting again (with its K set to the centre, it fitted worse and was not reused).
            starts = [(name, replace(start, K=np.array([[f, 0.0, image_size[0] / 2], [0.0, f, image_size[1] / 2],
                                                         [0.0, 0.0, 1.0]])))
                      for name, start in starts for f in [float(np.sqrt(abs(start.K[0, 0] * start.K[1, 1])))]]
        if options.bundle_adjustment:
            if tell.asks("bundle_adjustment", 0, 1):
                _keep_metric(out, starts[0][1], n_views, stage)
            stop, stopping = _stop_check(tell, "bundle_adjustment")
            name, metric, keep, before, trials = adjust_best(starts, obs, keep, options.threshold_px, model, stopping)
            if stop["asked"]:
                _keep_metric(out, metric, n_views, stage, "adjusted as far as the adjustment went")
            stage["starts"] = trials
            if model == "simple" and options.principal_point in ("auto", "per_view") and image_size is not None:
                metric, keep, stage["principal_point"] = _principal_point(metric, obs, keep, options.threshold_px,
                                                                          image_size, rival_fit)
            if model == "simple" and options.principal_point == "per_view" and image_size is not None:
                metric, keep, stage["principal_point_per_view"] = _principal_points_per_view(
                    metric, obs, keep, options.threshold_px, image_size)
                if stage["principal_point_per_view"].get("estimated"):
                    metric, keep, stage["focal_per_view"] = _focals_per_view(metric, obs, keep, options.threshold_px)
            stage.update(started_from=name, model=model, rms_px_before=before, rms_px_after=_rms(metric, obs, keep),
                         K=metric.K.tolist(), observations_kept=int(keep.sum()))
            adjusted_with = ("focal_groups" if (stage.get("focal_per_view") or {}).get("estimated")
                             else "principal_per_view" if (stage.get("principal_point_per_view") or {}).get("estimated")
                             else "principal" if (stage.get("principal_point") or {}).get("estimated") else model)
            metric, keep = _depth_reversal(out, metric, obs, keep, options.threshold_px, adjusted_with, stage, tell,
                                           n_views)
            if not keep.any():
                _none_kept(out, stages, stage, "bundle_adjustment", options.threshold_px, "the adjusted reconstruction")
                return
        else:
            name, metric = starts[0]
            stage.update(status="skipped", reason="options.bundle_adjustment is false", started_from=name)
            _depth_reversal_not_checked(out)
        out.metric = metric = _normalise_frame(metric)
    keep = _check_cameras(out, metric, obs, keep, options.threshold_px)
    _structure(tracks, n_views, options, stages, out, tell, obs, metric, keep)


def _depth_reversal(out: Reconstruction, metric: upgrade.Metric, obs: Observations, keep: np.ndarray,
                    threshold_px: float, model: str, stage: dict, tell, n_views: int):
    """ambiguity.check on the adjusted reconstruction, its figures in out.checks (the summary's);
    returns the reconstruction to go on with (the depth-reversed twin when it fits better) and its
    observations kept. A stop during the twin's adjustment keeps the adjusted cameras, unchecked."""
    stop, stopping = _stop_check(tell, "bundle_adjustment")
    metric, keep, figures = ambiguity.check(metric, obs, keep, threshold_px, model, stopping)
    out.checks["depth_reversal"] = figures  # stated once, as summary.depth_reversal (claims.summarise)
    if figures.get("adopted"):  # the stage's figures are the returned rig's, the twin's now
        stage.update(rms_px_after=_rms(metric, obs, keep), K=metric.K.tolist(), observations_kept=int(keep.sum()))
    if stop["asked"]:
        _keep_metric(out, metric, n_views, stage, "adjusted, the depth-reversal check not finished")
    return metric, keep


def _depth_reversal_not_checked(out: Reconstruction) -> None:
    out.checks["depth_reversal"] = {"checked": False, "reason": depth_reversal_claim.NOT_ADJUSTED}


def _stop_check(tell, name: str):
    """An adjustment's ``should_stop`` in stage ``name``: asks ``tell`` (a cancel, or the job's
    clock: the kind's report) each iteration, and a stop ends it where it is; the dict returned
    says whether one was asked."""
    stop = {"asked": False}

    def stopping() -> bool:
        stop["asked"] = stop["asked"] or tell.asks(name, 0, 1)
        return stop["asked"]

    return stop, stopping


def _undistorted(out: Reconstruction, obs: Observations, metric: upgrade.Metric, image_sizes,
                 radial: dict) -> Observations:
    """Every observation undistorted with the radial term the registration estimated (about the
    image's centre, at the focal length it was estimated with): from here on the reconstruction is
    a pinhole one on these pixels, and every certificate after it is about them, so conditional on
    that k1 (out.distortion says so, and the points return the undistorted observations)."""
    centres = np.array([[(w - 1) / 2, (h - 1) / 2] for w, h in image_sizes])
    focal = float(metric.K[0, 0])
    out.distortion = {"model": "radial_k1", "k1_at_focal_px": focal, "k1": float(metric.k1),
                      "centres": centres.tolist(), "test": radial}
    pixels = bundle.undistort(obs.pixel, centres[obs.view], focal, metric.k1)
    metric.k1 = 0.0
    return replace(obs, pixel=pixels)


MIN_CAMERA_POINTS = 6  # a camera is checked (and certified) on at least this many points


def _check_cameras(out: Reconstruction, metric: upgrade.Metric, obs: Observations, keep: np.ndarray,
                   threshold_px: float) -> np.ndarray:
    """The sanity layer between the adjustment and the certified structure: every returned camera
    must agree with its own observations. Each observation behind its camera or farther than
    ``threshold_px`` from its point's image is removed (an outlier: a track is certified only on
    the observations that fit); a camera with most of its points behind it (flipped), or left with
    fewer than MIN_CAMERA_POINTS that fit, is dropped: not registered, with the reason, and counted
    in ``out.checks``; then a track left with fewer than two observations is dropped. Repeated
    until nothing changes (a dropped camera takes its observations with it). Returns the
    observations kept."""
    keep = keep.copy()
    dropped, removed = [], 0
    for _ in range(5):
        registered = np.array([R is not None for R in metric.rotations])
        finite = np.isfinite(metric.points[:, 0])
        use = np.flatnonzero(keep & registered[obs.view] & finite[obs.track])
        depth, error = _depths_and_errors(metric, obs, use)
        changed = False
        for v in np.flatnonzero(registered):
            mine = obs.view[use] == v
            n, behind = int(mine.sum()), int((depth[mine] <= 0).sum())
            fit = int((mine & (depth > 0) & (error <= threshold_px)).sum())
            reason = None
            if n and behind > n / 2:
                reason = (f"dropped: {behind} of the {n} points it sees lie behind it (a flipped camera), so no "
                          "pose it is given can be trusted")
            elif fit < MIN_CAMERA_POINTS:
                reason = (f"dropped: {fit} of the {n} points it sees reproject within {threshold_px:g} px in front "
                          f"of it; at least {MIN_CAMERA_POINTS} are needed (a camera contradicting its own "
                          "observations)")
            if reason is not None:
                dropped.append({"view": int(v), "reason": reason, "points": n, "behind": behind, "fit": fit})
                metric.rotations[v] = metric.translations[v] = None
                camera = out.cameras[int(v)]
                camera.registered, camera.reason, camera.K, camera.R, camera.t, camera.P = \
                    False, reason, None, None, None, None
                camera.k1 = camera.distortion_centre = None  # no camera returned: no pixels of it undistorted
                changed = True
        bad = use[(depth <= 0) | ~(error <= threshold_px)]
        if len(bad):
            keep[bad] = False
            removed += len(bad)
            changed = True
        registered = np.array([R is not None for R in metric.rotations])
        keep &= registered[obs.view]
        counts = np.bincount(obs.track[keep], minlength=len(metric.points))
        keep &= counts[obs.track] >= 2
        if not changed:
            break
    out.checks.update(cameras_dropped=dropped, observations_removed=int(removed), threshold_px=threshold_px)
    _stated_K(out, metric)
    return keep


def _stated_K(out: Reconstruction, metric: upgrade.Metric) -> None:
    """With a K per camera, metric.K (summary.calibration.K) is one camera's K picked among the
    cameras returned (calibration_claim.stated_camera, which the verifier recomputes from them):
    the adjustment picked it among the views it adjusted, and a camera the sanity layer dropped
    since may have been that one, or moved the middle. The records stating the adjustment's K (its
    stage's K, the depth-reversal record's focal length of the rig returned) move with it: each is
    the returned K (the verifier reads them against summary.calibration.K)."""
    views = [v for v, R in enumerate(metric.rotations) if R is not None]
    if metric.Ks is None or metric.K is None or not views:
        return
    picked = metric.Ks[views[calibration_claim.stated_camera([metric.Ks[v] for v in views])]]
    if np.array_equal(picked, metric.K):
        return
    was, metric.K = metric.K, picked.copy()
    stage = next((s for s in out.stages if s.get("name") == "bundle_adjustment"), {})
    if stage.get("K") is not None and np.array_equal(np.asarray(stage["K"], dtype=float), was):
        stage["K"] = metric.K.tolist()
    depth = out.checks.get("depth_reversal") or {}
    focal = "mirror_focal_px" if depth.get("adopted") else "focal_px"
    if depth.get("checked") and depth.get(focal) == float(was[0, 0]):
        depth[focal] = float(metric.K[0, 0])


def _metric_cameras(out: Reconstruction, metric: upgrade.Metric, n_views: int) -> dict[int, np.ndarray]:
    """The metric cameras (K, R, t, P) on out.cameras; returns P per registered view."""
    P = {}
    for v in range(n_views):
        cam = out.cameras[v]
        if metric.rotations[v] is not None:
            cam.K, cam.R, cam.t = upgrade.K_of(metric, v), metric.rotations[v], metric.translations[v]
            cam.P = structure.camera_matrix(cam.K, cam.R, cam.t)
            P[v] = cam.P
            if out.distortion is not None:  # the same mapping of pixels, stated at this camera's focal length
                cam.k1 = out.distortion["k1"] * (float(cam.K[0, 0]) / out.distortion["k1_at_focal_px"]) ** 2
                cam.distortion_centre = out.distortion["centres"][v]
    return P


def _keep_registration(out: Reconstruction, metric: upgrade.Metric, obs: Observations, keep: np.ndarray,
                       threshold_px: float, n_views: int, stage: dict) -> None:
    """A stop (a cancel, or the job's clock) after the K-unknown registration placed views and
    before the adjustment: its metric cameras (K [R | t] at the focal length its last round had,
    refined by that round's adjustment when it ran) are kept rather than only their projective
    P, after the sanity layer (_check_cameras), and the stage says they are the registration's,
    not upgraded by the certified autocalibration and not certified."""
    out.metric = metric = _normalise_frame(metric)
    _check_cameras(out, metric, obs, keep, threshold_px)
    _metric_cameras(out, metric, n_views)
    how = ("its last round's, not adjusted" if stage.get("stopped_before_adjustment")
           else "refined by the registration's bundle adjustment")
    stage["reason"] = (f"{stage['reason']}; the cameras returned are the registration's metric cameras (focal length "
                       f"{float(metric.K[0, 0]):.1f} px, {how}), not upgraded by the certified autocalibration, "
                       "adjusted again or certified")


def _keep_metric(out: Reconstruction, metric: upgrade.Metric, n_views: int, stage: dict,
                 how: str = "not adjusted") -> None:
    """A cancel before (or during) the metric adjustment: the upgrade found is kept (its cameras
    returned, ``how``), and the run stops."""
    out.metric = metric = _normalise_frame(metric)
    _metric_cameras(out, metric, n_views)
    stage.update(status="cancelled", reason=f"the job was cancelled: the cameras returned are the upgrade's, {how}")
    raise Cancelled("bundle_adjustment")


def _structure(tracks, n_views, options, stages, out: Reconstruction, tell, obs, metric, keep) -> None:
    P = _metric_cameras(out, metric, n_views)
    stop = {"asked": False, "timed_out": False}
    deadline = time.perf_counter() + options.structure_time_limit_s

    def seen(name: str, done: int, total: int) -> bool:  # progress; a cancel is kept until the next check
        stop["asked"] = stop["asked"] or tell.asks(name, done, total)
        return stop["asked"]

    def should_stop() -> bool:  # a cancel, or past structure_time_limit_s (the points and cameras together)
        stop["timed_out"] = stop["timed_out"] or time.perf_counter() > deadline
        return stop["asked"] or stop["timed_out"]

    def timed_out(what: str, kept: int, not_started: int) -> str:
        return (f"time_limit: stopped at options.structure_time_limit_s ({options.structure_time_limit_s:g} s): "
                f"{kept} {what} done before it are kept, {not_started} were not started")

    with _timed(stages, "structure") as stage:
        if len(P) < 2:  # (a tiny options.threshold_px: the sanity layer drops every camera fitting none)
            stage.update(status="failed", reason=f"{len(P)} view(s) left registered after the cameras' checks (each "
                                                 "camera's reason says why): no point can be triangulated")
            _skip(stages, "structure", "fewer than 2 views left registered")
            return
        kept_tracks = []
        usable = np.flatnonzero(keep & np.isin(obs.view, list(P)))
        usable = usable[np.argsort(obs.track[usable], kind="stable")]  # grouped by track, in observation order
        bounds = np.searchsorted(obs.track[usable], np.arange(len(tracks) + 1))
        for t in range(len(tracks)):
            m = usable[bounds[t]:bounds[t + 1]]
            if len(m) >= 2 and np.isfinite(metric.points[t, 0]):
                kept_tracks.append((t, obs.view[m], obs.pixel[m]))
        tri_options = TriangulationOptions(norm=options.norm, rel_gap=options.rel_gap, abs_gap=options.abs_gap,
                                           max_nodes=options.max_nodes, time_limit_s=options.time_limit_s,
                                           max_residual=options.max_residual, certificate=options.certificate)
        seen("structure", 0, len(kept_tracks))
        results = structure.triangulate_tracks(P, [(v, x) for _, v, x in kept_tracks], tri_options,
                                               lambda d, total: seen("structure", d, total),
                                               should_stop=should_stop)
        not_started = 0
        for (t, views, pixels), result in zip(kept_tracks, results):
            if result.status == "cancelled" and result.point is None:  # a cancel came first: not solved
                not_started += 1
                continue
            if result.status == "cancelled" and not stop["asked"]:  # a search stopped by the stage's clock
                result.status = "time_limit"
            out.points.append(Point(t, result, [[int(v), float(x[0]), float(x[1])] for v, x in zip(views, pixels)]))
        out.points, dropped = _drop_outlier_points(out.points, P, options.threshold_px)
        out.checks["points_dropped"] = dropped
        stage.update(tracks=len(tracks), points=len(out.points), points_dropped=dropped,
                     observations_removed=out.checks.get("observations_removed", 0),
                     certified=sum(1 for p in out.points if p.result.certified))
        if not_started and not stop["asked"]:
            stage.update(status="time_limit", tracks_not_started=not_started,
                         reason=timed_out("points", len(out.points), not_started))
        elif not_started:
            stage.update(status="cancelled", tracks_not_started=not_started,
                         reason=f"the job was cancelled: {len(out.points)} points solved before it are kept, "
                                f"{not_started} tracks were not started")
    if not_started and stop["asked"]:
        raise Cancelled("cameras")
    with _timed(stages, "cameras") as stage:
        if not options.resect_cameras:
            stage.update(status="skipped", reason="options.resect_cameras is false")
            return
        views = sorted(P)
        found = camera_claim.sources(point_entries(out.points), views)
        arrays = {v: (np.array(X, dtype=float).reshape(-1, 3), np.array(x, dtype=float).reshape(-1, 2))
                  for v, (X, x) in zip(views, found) if X}
        map_options = MapOptions(norm=options.norm, rel_gap=options.camera_rel_gap, abs_gap=options.abs_gap,
                                 max_nodes=options.max_nodes, time_limit_s=options.time_limit_s,
                                 max_residual=options.max_residual, certificate=options.certificate)
        if seen("cameras", 0, len(P)):
            raise Cancelled("cameras")
        if should_stop():
            stage.update(status="time_limit", cameras_not_started=len(P), reason=timed_out("cameras", 0, len(P)))
            return
        # Each camera's own degrees of freedom (its pose, and the intrinsics the cameras do not
        # share) set the allowance its tolerance gives it over a 3x4 camera (camera_claim).
        dof = camera_claim.degrees_of_freedom([out.cameras[v].K for v in P])
        stage.update(degrees_of_freedom=dof,
                     claim=camera_claim.statement(options.norm, options.camera_rel_gap, set_aside=True))
        bounds = structure.resect_cameras(P, arrays, map_options, lambda d, total: seen("cameras", d, total),
                                          should_stop=should_stop,
                                          bound_every_camera=options.bound_every_camera, dof=dof)
        for v, bound in bounds.items():
            out.cameras[v].bound = bound
        not_started = sum(1 for b in bounds.values() if b.status == "cancelled")
        stage.update(cameras=len(bounds), certified=sum(1 for b in bounds.values() if b.certified),
                     searched=sum(1 for b in bounds.values() if b.result is not None))
        if not_started and not stop["asked"]:  # stopped by the stage's clock, not by a cancel
            reason = timed_out("cameras", len(bounds) - not_started, not_started)
            for bound in bounds.values():
                if bound.status == "cancelled":
                    bound.status, bound.reason = "time_limit", reason
            stage.update(status="time_limit", cameras_not_started=not_started, reason=reason)
        elif not_started:
            stage.update(status="cancelled", cameras_not_started=not_started,
                         reason=f"the job was cancelled: the {len(bounds) - not_started} cameras resected before it "
                                f"are kept, {not_started} were not started")


def point_entries(points: list[Point]) -> list[tuple]:
    """The returned points as camera_claim.sources reads them (the cameras are resected on the
    certified points only)."""
    return [(p.result.point, p.result.at_infinity, p.result.certified, p.observations) for p in points]


def _drop_outlier_points(points: list[Point], P: dict[int, np.ndarray], threshold_px: float) -> tuple[list, int]:
    """The safety net after the certified triangulation: a point is dropped when it lies behind a
    camera that sees it or reprojects farther than threshold_px * sqrt(its observations) from one
    (each observation it was solved from fit within threshold_px at the adjusted point, so its
    optimum cannot be farther unless something is wrong). Returns the points kept and the count
    dropped; a point not solved (no point) is kept as it is, with its status."""
    solved = [point for point in points if point.result.point is not None]
    if not solved:
        return list(points), 0
    # Every solved point's observations at once (rows point by point, each its own camera @ X and
    # error, the same arithmetic as one point at a time), then a verdict per point.
    counts = np.array([len(point.observations) for point in solved])
    owner = np.repeat(np.arange(len(solved)), counts)
    X = np.array([r.point if r.at_infinity else [*r.point, 1.0] for r in (point.result for point in solved)],
                 dtype=float)
    observed = np.array([o for point in solved for o in point.observations], dtype=float).reshape(-1, 3)
    cams = np.array([P[int(v)] for v in observed[:, 0]]).reshape(-1, 3, 4)
    image = (cams @ X[owner][:, :, None])[:, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        error = np.linalg.norm(image[:, :2] / image[:, 2:3] - observed[:, 1:], axis=1)
    at_infinity = np.array([point.result.at_infinity for point in solved], dtype=bool)
    fits = np.nan_to_num(error, nan=np.inf) <= threshold_px * np.sqrt(counts[owner])
    behind = (image[:, 2] <= 0) & ~at_infinity[owner]
    bad = np.bincount(owner, weights=(~fits | behind).astype(float), minlength=len(solved)) > 0
    verdict = dict(zip(map(id, solved), bad.tolist()))
    kept = [point for point in points if not verdict.get(id(point), False)]
    return kept, len(points) - len(kept)


def adjust_best(starts: list, obs: Observations, keep: np.ndarray, threshold_px: float, model: str,
                should_stop=None):
    """A short adjustment (8 iterations) from each upgrade (name, Metric); the one explaining every
    observation best (fit.fit_cost, MSAC's capped cost) goes on to a full adjustment. A start that
    is an earlier start's rig in another frame (fit.same_images) is not adjusted (its figures say
    ``same_rig_as``). Returns its name, the adjusted reconstruction, the
    observations kept, the RMS before, and each start's figures. ``should_stop()`` (asked each
    iteration) ends the adjustments where they are."""
    if len(starts) == 1:  # nothing to choose between: straight to the full adjustment
        name, start = starts[0]
        before = _rms(start, obs, keep)
        metric, keep, _ = upgrade.adjust(start, obs.view, obs.track, obs.pixel, threshold_px, model=model,
                                         should_stop=should_stop)
        return name, metric, keep, before, [{"from": name, "rms_px_before": before}]
    tried, trials = [], []
    for k, (name, start) in enumerate(starts):
        before = _rms(start, obs, keep)
        # Two starts are often one rig (the certified upgrade of the registration's cameras is
        # those cameras again, in another frame): the later one is not adjusted again, as its
        # adjustment would go where the earlier one's went (the earlier is kept on a tie anyway).
        same = next((earlier for earlier, other in starts[:k] if same_images(start, other, obs)), None)
        if same is not None:
            trials.append({"from": name, "rms_px_before": before, "same_rig_as": same})
            continue
        adjusted, kept, _ = upgrade.adjust(start, obs.view, obs.track, obs.pixel, threshold_px, max_iterations=8,
                                           model=model, should_stop=should_stop)
        cost = fit_cost(adjusted, obs, threshold_px)
        tried.append((cost, name, adjusted, before))
        trials.append({"from": name, "rms_px_before": before, "rms_px_after_8_iterations": _rms(adjusted, obs, kept),
                       "observations_fitting": int(kept.sum()), "fit_cost": cost})
    # The start whose adjustment explains the observations best over all of them (fit_cost), not the
    # smaller RMS over the observations each kept: on the dinoSparseRing the linear start's 0.31 px
    # (against 0.48) led to rotations 21 degrees off fitting 289 of the 1,323 observations, where
    # the right rig fits 730.
    cost, name, metric, before = min(tried, key=lambda item: item[0])
    metric, keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, threshold_px, model=model,
                                     should_stop=should_stop)
    return name, metric, keep, before, trials


def _normalise_frame(metric: upgrade.Metric) -> upgrade.Metric:
    """The similarity that puts the points' centroid at the origin and their RMS distance from it
    at 1 (a metric reconstruction's frame and scale are arbitrary; these keep the numbers near 1)."""
    finite = np.isfinite(metric.points[:, 0])
    if finite.sum() < 2:
        return metric
    c = metric.points[finite].mean(axis=0)
    spread = np.sqrt(np.mean(np.sum((metric.points[finite] - c) ** 2, axis=1)))
    if not spread > 0:
        return metric
    s = 1.0 / spread
    metric.points = s * (metric.points - c)
    metric.translations = [None if t is None else s * (R @ c + t) for R, t in zip(metric.rotations,
                                                                                  metric.translations)]
    return metric

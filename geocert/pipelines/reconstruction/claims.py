"""What a reconstruction's summary claims about what it returns (issue 35: never silently
wrong): its counts, the calibration claim (every statement about K is about a K the result
returns), and the warnings a user reads first: cameras dropped, points dropped, cameras whose fit
is beyond their tolerance, a K moved from the certified one, a certified K on its range's edge, a
critical motion, no metric upgrade."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geocert.formulations.reconstruction import depth_reversal, motion_claim
from geocert.formulations.reconstruction.camera_claim import DOUBTFUL_DROPPED, DOUBTFUL_FRACTION, DOUBTFUL_REMOVED
from geocert.formulations.reconstruction.calibration_claim import (CALIBRATED_CAMERAS_WARNING, K_given, critical_warning,
                                                              difference as k_difference, edge_warning,
                                                              moved_warning, on_range_edge, same)



def summarise(out, n_tracks: int, n_views: int, names: list | None = None) -> None:
    """out.summary (a pipeline.Reconstruction's) from its cameras, points, stages and checks.
    ``names``: the views' names as the request gave them (None where it gave none), for the
    warnings that name views."""
    judge_motion(out)
    squared, count = 0.0, 0
    for point in out.points:
        r = point.result
        if r.point is None:
            continue
        X = np.array(r.point if r.at_infinity else [*r.point, 1.0])
        for v, u, w in point.observations:
            proj = out.cameras[int(v)].P @ X
            squared += (proj[0] / proj[2] - u) ** 2 + (proj[1] / proj[2] - w) ** 2
            count += 1
    registered = [c for c in out.cameras if c.registered]
    bounded = [c for c in out.cameras if c.bound is not None and c.bound.status != "cancelled"]
    out.summary = {
        "views": n_views, "views_registered": len(registered), "tracks": n_tracks, "points": len(out.points),
        "observations": count, "rms_reprojection_px": float(np.sqrt(squared / count)) if count else None,
        "points_certified": sum(1 for p in out.points if p.result.certified),
        "points_certified_fraction": (sum(1 for p in out.points if p.result.certified) / len(out.points)
                                      if out.points else None),
        "cameras_certified": sum(1 for c in bounded if c.bound.certified),
        # of the cameras returned (a camera not bounded is not certified)
        "cameras_certified_fraction": (sum(1 for c in bounded if c.bound.certified) / len(registered)
                                       if registered else None),
        # What "certified" says of a camera (camera_claim.statement), when the cameras were bounded.
        "camera_claim": out.stages[4].get("claim") if len(out.stages) > 4 else None,
        "critical_motion": out.stages[1].get("critical_motion"),
        "cameras_dropped": len(out.checks.get("cameras_dropped", [])),
        "observations_removed": out.checks.get("observations_removed", 0),
        "points_dropped": out.checks.get("points_dropped", 0),
        "time_s": {stage["name"]: stage["elapsed_s"] for stage in out.stages},
        "cpu_s": {stage["name"]: stage.get("cpu_s", 0.0) for stage in out.stages},
    }
    claim = calibration_claim(out)
    out.summary.update(calibration=claim.as_dict(),
                       # the claims about K, as the calibration object states them (about its certified_K)
                       autocalibration_certified=claim.certified, autocalibration_determined=claim.determined)
    warnings = []
    missing = [c for c in out.cameras if not c.registered]
    if missing:  # first: how much of what was sent the result covers
        warnings.append(unregistered_warning(missing, n_views, names))
    warnings += list(claim.warnings)
    reversal = _depth_reversal(out, registered)
    if reversal is not None:
        warnings.append(reversal)
    distortion = getattr(out, "distortion", None)
    if distortion is not None:
        out.summary["distortion"] = _distortion(out, distortion)
        warnings.append({"code": "certificates_conditional_on_k1", "detail": out.summary["distortion"]["statement"]})
    if out.metric is None and registered:
        warnings.append({"code": "no_metric_upgrade", "detail": (
            f"no metric reconstruction was found: the {len(registered)} cameras returned are projective (P only, "
            "no K, R, t), known up to a 3D projective transformation, and no point is returned")})
    for dropped in out.checks.get("cameras_dropped", []):
        warnings.append({"code": "camera_dropped", "detail": f"view {view_said(dropped['view'], names)}: {dropped['reason']}"})
    beyond = [c for c in bounded if c.bound.beyond_tolerance]
    if beyond:
        warnings.append({"code": "camera_fit_beyond_tolerance", "detail": (
            f"views {', '.join(view_said(c.view, names) for c in beyond)}: each costs more above a 3x4 camera on its "
            "own points than its fewer degrees of freedom explain (its bound_reason says by how much): "
            + _misfit_said(beyond, names))})
    if out.checks.get("points_dropped"):
        warnings.append({"code": "points_dropped", "detail": f"{out.checks['points_dropped']} certified points lay "
                                                             "behind a camera or far from an observation: dropped"})
    # Every camera the cameras stage took up, a stopped one too: a stop never makes the rig look
    # sounder (a camera a cancel left unbounded counts as not certified; the verifier's reading).
    doubts = _doubts(out, registered, [c for c in out.cameras if c.bound is not None], count)
    if reversal is not None and reversal["code"] == "poses_not_determined":
        doubts.insert(0, "the poses are not determined: " + reversal["detail"])
    out.summary["doubtful"] = bool(doubts)
    if doubts:  # the first thing a user reads: a certified camera here may still be degrees off
        warnings.insert(0, {"code": "reconstruction_doubtful", "detail": (
            "the reconstruction as a whole is doubtful, whatever its single cameras and points certify (each "
            "certificate is about the returned cameras and points fitting their own observations, not about the "
            "rig being right): " + "; ".join(doubts))})
    out.summary["warnings"] = warnings


# How many views the views_not_registered warning names; the rest it counts (each camera's
# ``reason`` still says why it is not registered).
VIEWS_NAMED = 10


def unregistered_warning(missing: list, n_views: int, names: list | None = None) -> dict:
    """The views_not_registered warning: how many of the views sent have no camera returned, and
    the first VIEWS_NAMED of them by reason, each by its index and, where the request named it,
    its name ("views 2 (IMG_0003.jpg), 5 (IMG_0006.jpg): <reason>"); the rest counted ("and 40
    more"), so the text stays short for a large job. The verifier reads only its code."""
    why: dict[str, list[str]] = {}
    for c in missing[:VIEWS_NAMED]:
        why.setdefault(c.reason or "no reason recorded", []).append(view_said(c.view, names))
    said = "; ".join(f"view{'s' if len(views) > 1 else ''} {', '.join(views)}: {reason}"
                     for reason, views in why.items())
    if len(missing) > VIEWS_NAMED:
        said += f"; and {len(missing) - VIEWS_NAMED} more (each camera's reason says why)"
    return {"code": "views_not_registered",
            "detail": f"{len(missing)} of {n_views} views not registered (no camera returned for them): {said}"}


def view_said(view: int, names: list | None) -> str:
    """A view as a warning names it: its index, and its name in brackets when the request gave one."""
    name = names[view] if names is not None and 0 <= view < len(names) else None
    return f"{view} ({name})" if isinstance(name, str) and name else str(view)


def _misfit_said(beyond: list, names: list | None = None) -> str:
    """What the refits of the cameras beyond their tolerance found (camera_misfit.camera_misfit), in
    words: whether their poses or the camera's K misfit them."""
    causes: dict[str, list[str]] = {}
    for c in beyond:
        causes.setdefault((c.bound.misfit or {}).get("cause") or "not refitted", []).append(view_said(c.view, names))
    if set(causes) == {"not refitted"}:
        return "its pose, or the camera's K, may be off"
    said = {"pose": "refitting its pose alone removes most of it: the pose was off its optimum",
            "principal_point": "the pose is at its optimum and a principal point of its own brings it within tolerance: "
                               "the camera's K (given, or shared by every view) misfits it, not its pose",
            "focal_and_principal_point": "the pose is at its optimum and a focal length and principal point of its own "
                                         "bring it within tolerance: the camera's K misfits it, not its pose",
            "unexplained": "the pose is at its optimum and no intrinsic of its own explains the rest (distortion, "
                           "its points, or an affine misfit)",
            "not refitted": "not refitted (its pose, or the camera's K, may be off)"}
    return "; ".join(f"view{'s' if len(views) > 1 else ''} {', '.join(views)}: {said[cause]}"
                     for cause, views in causes.items())


def judge_motion(out) -> None:
    """The motion of what the result returns, judged (motion_claim.judge) on its registered
    cameras and its certified points, as the verifier recomputes it, and recorded on the
    autocalibration stage (out.stages[1]). On a critical motion (a turntable, an orbit, a
    translating camera) the tracks do not determine constant intrinsics: whatever the stage
    certified, it is said plainly that the upgrade is not determined by these data. Fewer than
    3 metric cameras: not judged (and K not determined)."""
    stage = out.stages[1]
    cameras = [c if c.registered and c.K is not None and c.R is not None else None for c in out.cameras]
    if sum(c is not None for c in cameras) < 3:
        return
    placed = [p for p in out.points if p.result.certified and p.result.point is not None and not p.result.at_infinity]
    observations = [(int(v), k, u, w) for k, p in enumerate(placed) for v, u, w in p.observations]
    judged = motion_claim.judge([None if c is None else c.K for c in cameras],
                                [None if c is None else c.R for c in cameras],
                                [None if c is None else c.t for c in cameras],
                                np.array([p.result.point for p in placed], dtype=float).reshape(-1, 3),
                                np.array([o[0] for o in observations], dtype=int),
                                np.array([o[1] for o in observations], dtype=int),
                                np.array([o[2:] for o in observations], dtype=float).reshape(-1, 2))
    critical = judged["critical_motion"]
    # determined only by a full judgement: the plane at infinity's family is judged only when the
    # residuals give the rotations' noise
    stage.update(judged, determined=critical is None and judged["rotation_noise_rad"]["estimated"] is not None)
    if critical is None:
        return
    detail = next((w["detail"] for w in judged["motion_warnings"] if w["code"] == critical), "")
    if K_given(stage):
        said = (f"critical motion ({critical}): {detail}. The tracks alone would not determine a constant K "
                "(Sturm 1997); K was given, so the metric reconstruction does not depend on them for it")
        stage["reason"] = said if not stage.get("reason") else f"{stage['reason']}; {said}"
        return
    if stage.get("certified"):
        proved = ("both stages certified their optimum, but it is one of many upgrades these tracks fit equally well, "
                  "so the certificate fixes no calibration")
    else:
        proved = "no certificate can separate the upgrades the motion leaves open (the cost is flat along them)"
    said = (f"critical motion ({critical}): {detail}. The tracks do not determine a constant K (Sturm 1997): {proved}; "
            "K comes from the bundle adjustment's camera model, not from a certificate")
    stage["reason"] = said if not stage.get("reason") else f"{stage['reason']}; {said}"


def _depth_reversal(out, registered: list) -> dict | None:
    """The depth-reversal check's claim (ambiguity.check): each registered camera's
    ``pose_determined`` and ``mirror_rotation_deg``, ``summary.poses_determined`` (None when not
    checked) and ``summary.depth_reversal`` (its figures); returns the warning to give, if any: the
    twin fits about as well (the poses are not determined), or it fitted better and was returned."""
    figures = out.checks.get("depth_reversal")
    checked = bool(figures and figures.get("checked"))
    out.summary["depth_reversal"] = figures
    out.summary["poses_determined"] = (not figures["ambiguous"]) if checked else None
    posed = {c.view: c.R for c in out.cameras if c.registered and c.R is not None}
    if checked:  # from the returned rotations, so that the verifier recomputes them
        figures["mirror_rotation_deg"] = (depth_reversal.mirror_angles_deg(posed, figures["reference_view"])
                                          if figures["reference_view"] in posed else {})
    for camera in out.cameras:
        camera.pose_determined = camera.mirror_rotation_deg = None
        if checked and camera.view in posed:
            camera.pose_determined = not figures["ambiguous"]
            camera.mirror_rotation_deg = figures["mirror_rotation_deg"].get(camera.view)
    if not checked:
        return None
    turned = [a for c in registered if (a := figures["mirror_rotation_deg"].get(c.view)) is not None]
    most = max(turned, default=0.0)
    if figures["ambiguous"]:
        return {"code": "poses_not_determined", "detail": (
            f"the depth-reversed twin of the returned rig (every point mirrored in depth in view "
            f"{figures['reference_view']}'s frame, each relative rotation's axis mirrored, then adjusted: focal "
            f"{figures['mirror_focal_px']:.1f} px against {figures['focal_px']:.1f}) fits the observations about as well "
            f"(its capped cost {figures['mirror_cost_px2']:.1f} against {figures['cost_px2']:.1f} px^2, "
            f"{figures['statistic']:+.1f} noise variances, ratio {figures['cost_ratio'] or 0:.3f}: not more than "
            f"{figures['threshold']:g} variances and {100 * figures['margin']:g}% apart), and its cameras point up to "
            f"{most:.1f} degrees differently: the observations do not say which is right (a long lens sees nearly "
            "affinely), so no camera's pose is determined, certified or not (each camera's pose_determined is false)")}
    if figures["adopted"]:
        return {"code": "depth_reversed_twin_returned", "detail": (
            f"the adjustment had settled in the depth-reversed twin of a rig that fits better "
            f"({-figures['statistic']:.1f} noise variances better): that rig is returned, its cameras up to "
            f"{most:.1f} degrees from the adjustment's")}
    return None


def _doubts(out, registered: list, bounded: list, observations: int) -> list[str]:
    """Why the reconstruction as a whole is doubtful (empty when it is not): most cameras taken up
    (``bounded``: every camera the cameras stage judged, or stopped before judging) are not
    certified or fit their points worse than their tolerance allows (the shared K or the rig, not one pose, is
    off), a large share of the observations contradicts the returned rig, or the sanity layer
    dropped many of the cameras registered."""
    doubts = []
    beyond = [c for c in bounded if c.bound.beyond_tolerance or not c.bound.certified]
    if len(bounded) >= 2 and len(beyond) > DOUBTFUL_FRACTION * len(bounded):
        doubts.append(f"{len(beyond)} of the {len(bounded)} cameras taken up are not certified or fit beyond their "
                      "tolerance: the rig does not fit its own observations as its camera model should")
    removed = out.checks.get("observations_removed", 0)
    if removed and removed > DOUBTFUL_REMOVED * (removed + observations):
        doubts.append(f"{removed} observations contradicted the returned cameras and were removed, against "
                      f"{observations} kept: the rig is inconsistent with its tracks")
    dropped = len(out.checks.get("cameras_dropped", []))
    if dropped and dropped > DOUBTFUL_DROPPED * (dropped + len(registered)):
        doubts.append(f"{dropped} cameras were dropped as contradicting their own observations, against "
                      f"{len(registered)} kept")
    return doubts


def _distortion(out, distortion: dict) -> dict:
    """The radial term the observations were undistorted with, at the returned K's focal length
    (each camera carries its own k1 at its own focal length), and what it means for the claims."""
    K = out.metric.K if out.metric is not None and out.metric.K is not None else None
    focal = float(K[0, 0]) if K is not None else distortion["k1_at_focal_px"]
    k1 = distortion["k1"] * (focal / distortion["k1_at_focal_px"]) ** 2
    about = "K's principal point" if distortion.get("about") == "principal_point" else "each image's centre"
    return {"model": distortion["model"], "k1": k1, "focal_px": focal, "estimated_by": "bundle_adjustment",
            "certified": False, "test": distortion.get("test"),
            "statement": (f"the observations were undistorted with the radial term k1 = {k1:.4g} (at focal length "
                          f"{focal:.1f} px, about {about}) that the bundle adjustment estimated, before any "
                          "point or camera was certified: every certificate is about the undistorted observations "
                          "the points return, so it is conditional on that k1, which is estimated, not certified")}


@dataclass(frozen=True)
class CalibrationClaim:
    """What the result says about K, built so that every claim is about a K it returns.

    ``K`` is the calibration the returned cameras use (every registered camera's, unless
    ``model`` is "varying": then one camera's among those returned, each camera carrying its own
    (calibration_claim.stated_camera: the middle focal length's, or with a principal point per
    view the middle principal point's); None when no metric reconstruction was found);
    ``certified_K`` the K the certified autocalibration proved optimal for its upgrade (None when
    none was certified). ``certified`` is about ``certified_K`` only, and cannot be True without
    it; ``returned_is_certified`` says whether the cameras use it (then K is certified_K), and
    ``difference`` how far the returned K moved from it (the adjustment's work). ``determined`` is
    True only when the tracks fix K: certified, no critical motion, and no certified intrinsic on
    its range's edge (an optimum on the edge is the range's, not the data's)."""

    K: list | None
    # "given", "autocalibration", "bundle_adjustment" (it moved K), "camera_model" (no adjustment:
    # the model's constraints, square pixels and the principal point at the image centre, moved
    # the certified K) or "none"
    source: str
    certified_K: list | None
    certified: bool
    returned_is_certified: bool
    difference: dict | None
    on_range_edge: tuple
    determined: bool | None
    warnings: tuple
    model: str = "shared"  # "shared" (one K, every registered camera's) or "varying" (one focal length per view)

    def __post_init__(self):
        if self.certified and self.certified_K is None:
            raise ValueError("a certified calibration claim needs the certified K it is about")
        if self.returned_is_certified and (self.K is None or self.certified_K is None or not self.certified):
            raise ValueError("the returned K can be called certified only when a certified K was returned")
        if self.returned_is_certified and (self.model != "shared" or not same(self.K, self.certified_K)):
            raise ValueError("the returned K is called certified only when every camera uses the certified K")
        if (self.source == "autocalibration") != self.returned_is_certified:
            raise ValueError("K comes from the autocalibration exactly when the returned K is the certified one")
        if (self.difference is not None) != (self.K is not None and self.certified_K is not None):
            raise ValueError("the difference is stated exactly when both a returned and a certified K are")
        if self.determined and (not self.certified or self.on_range_edge):
            raise ValueError("K is determined only when certified, and not on its range's edge")

    def as_dict(self) -> dict:
        return {"K": self.K, "model": self.model, "source": self.source, "certified_K": self.certified_K,
                "certified": self.certified, "returned_is_certified": self.returned_is_certified,
                "difference": self.difference, "on_range_edge": list(self.on_range_edge), "determined": self.determined}


def calibration_claim(out) -> CalibrationClaim:
    """The calibration claim of a pipeline.Reconstruction: its metric K, the autocalibration
    stage's (out.stages[1]) certified K, and the motion judged there."""
    stage = out.stages[1]
    K = None if out.metric is None or out.metric.K is None else np.asarray(out.metric.K, dtype=float)
    varying = out.metric is not None and out.metric.Ks is not None
    known = K_given(stage)
    certified = bool(stage.get("certified")) and stage.get("K") is not None and K is not None
    cert = np.asarray(stage["K"], dtype=float) if certified else None
    warnings, edges, difference, same_K = [], [], None, False
    adjusted = any(s.get("name") == "bundle_adjustment" and s.get("status") != "skipped" for s in out.stages)
    if cert is not None:
        same_K = bool(same(K, cert) and not varying)
        difference = k_difference(K, cert)
        if not same_K:
            per_view = varying and len({tuple(np.round(k[:2, 2], 9)) for k in out.metric.Ks if k is not None}) > 1
            which = "per_view" if per_view else "varying" if varying else "shared"
            warnings.append({"code": "returned_K_not_certified", "detail": moved_warning(adjusted, which, difference)})
        if stage.get("cameras_built_with_one_K"):
            warnings.append({"code": "certified_K_of_calibrated_cameras", "detail": CALIBRATED_CAMERAS_WARNING})
        edges = on_range_edge(cert, stage.get("intrinsics") or {})
        if edges:
            warnings.append({"code": "certified_K_on_range_edge", "detail": edge_warning(edges)})
    critical = stage.get("critical_motion")
    if critical:
        warnings.append({"code": "critical_motion", "detail": critical_warning(critical, known)})
    determined = None if known or K is None else bool(certified and not critical and not edges
                                                      and stage.get("determined") is True)
    source = ("none" if K is None else "given" if known else "autocalibration" if same_K
              else "bundle_adjustment" if adjusted else "camera_model")
    return CalibrationClaim(None if K is None else K.tolist(), source, None if cert is None else cert.tolist(),
                            certified, same_K, difference, tuple(edges), determined, tuple(warnings),
                            "varying" if varying else "shared")

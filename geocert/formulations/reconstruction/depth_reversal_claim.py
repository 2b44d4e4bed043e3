"""The depth-reversal check's record, as the verifier reads it (numpy only).

The check (pipelines/reconstruction/ambiguity.py) compares the returned rig with its adjusted
depth-reversed twin; the verifier cannot run that adjustment, so the verdict's figures are taken
as stated, but they must be the verdict's: ``summary.poses_determined`` is null exactly when the
check did not run, and then only for a reason the result shows (fewer than 2 views registered, a
stop, the adjustment switched off); when it ran, the statistic, the cost ratio and the three
outcomes (rejected, adopted, ambiguous) are recomputed from the stated costs and noise at the
pipeline's thresholds, and each registered camera's ``mirror_rotation_deg`` is recomputed: the
angle between it and the twin's camera as constructed in the reference view's frame, before its
adjustment (depth_reversal.mirror_angles_deg). What stays unchecked is stated in
docs/certificate.md: the costs themselves, which need the adjusted twin."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from geocert.core.geometry import is_number
from geocert.core.strict import Invalid
from geocert.formulations.reconstruction import depth_reversal

# The twin is told apart when the costs differ by more than this many noise variances (the
# chi-square with 1 degree of freedom at p = 0.001: a likelihood ratio above e^5.4) and by more
# than this fraction of the smaller cost. The pipeline's check (ambiguity.py) judges by verdict()
# and writes the reasons below; the verifier reads them from here too.
MIRROR_CHI2 = 10.8
MIRROR_MARGIN = 0.10
ROUNDING = 1e-9
ANGLE_ROUNDING_DEG = 1e-7  # the angles' arctan2 is well conditioned: rotations to 1e-15 move it by far less
FEWER_THAN_2_VIEWS = "fewer than 2 views registered"
STOPPED = "stopped before the twin's adjustment ended"
NOT_ADJUSTED = "options.bundle_adjustment is false: the twin could only be compared adjusted"
NOT_CHECKED = {FEWER_THAN_2_VIEWS: "registered", STOPPED: "stopped", NOT_ADJUSTED: "not_adjusted"}
# The record's members as the pipeline writes them (ambiguity.check; mirror_rotation_deg by
# claims.summarise), when the check ran and when it did not: a member beyond them is refused.
MEMBERS = frozenset(("checked", "reference_view", "model", "cost_px2", "mirror_cost_px2", "cost_ratio",
                     "noise_variance_px2", "statistic", "threshold", "margin", "returned_refitted", "observations",
                     "observations_fitting", "mirror_observations_fitting", "focal_px", "mirror_focal_px",
                     "mirror_rotation_deg", "ambiguous", "adopted", "mirror_capped"))
NOT_CHECKED_MEMBERS = frozenset(("checked", "reason"))
# The bundle models the twin may be adjusted with (bundle.MODELS, which imports scipy; a test
# asserts the two agree).
MODELS = ("simple", "full", "fixed", "varying", "principal", "radial", "principal_per_view", "focal_groups",
          "fixed_radial")


def verdict(cost: float, twin: float, variance: float) -> tuple[float, bool, bool]:
    """(statistic, rejected, adopted) of a twin costing ``twin`` against ``cost``, in units of
    the noise ``variance``: rejected when it costs more by MIRROR_CHI2 variances and by
    MIRROR_MARGIN of the cost, adopted when it costs less by as much; neither: ambiguous."""
    statistic = (twin - cost) / variance
    return (statistic, statistic > MIRROR_CHI2 and twin > (1 + MIRROR_MARGIN) * cost,
            -statistic > MIRROR_CHI2 and cost > (1 + MIRROR_MARGIN) * twin)


def _close(value: Any, expected: float) -> bool:
    """``value`` is a number within rounding of ``expected``, itself finite: a figure recomputed
    from stated ones overflows to inf where they are extreme (a subnormal noise variance: the
    statistic 15 / 5e-324), and |value - inf| <= ROUNDING * inf held for every stated value."""
    return (is_number(value) and math.isfinite(expected)
            and abs(value - expected) <= ROUNDING * max(abs(expected), 1e-300))


def check(summary: dict, cameras: list[dict], stages: list, current_form: bool = False,
          points: list | None = None) -> None:
    """Refuse a depth-reversal record that is not its verdict's (module docstring). ``current_form``:
    the document's hash is in the form every result since the check is written in, so a missing
    record is one removed, unless fewer than two cameras are posed or a stage shows a stop."""
    figures, poses = summary.get("depth_reversal"), summary.get("poses_determined")
    registered = [c for c in cameras if c.get("registered") is True]
    if any(c.get("mirror_rotation_deg") is not None for c in cameras if c.get("registered") is not True):
        raise Invalid("returned", "a camera not registered states a mirror_rotation_deg")
    if figures is None:  # a result from before the check: nothing stated of it
        posed = sum(1 for c in registered if c.get("R") is not None)
        if current_form and posed >= 2 and not _stopped(stages):
            raise Invalid("returned", "summary/depth_reversal is missing: a result in the current form states the "
                                      "depth-reversal check's record whenever two cameras are posed, unless a stage "
                                      "shows the stop that prevented it")
        if poses is not None or any(c.get("mirror_rotation_deg") is not None for c in registered):
            raise Invalid("returned", "summary/poses_determined or a camera's mirror_rotation_deg is stated without "
                                      "summary/depth_reversal")
        return
    # by type: 1 in (True, False) and 1.0 == True in Python, and a number is never a boolean here
    if not isinstance(figures, dict) or type(figures.get("checked")) is not bool:
        raise Invalid("returned", "summary/depth_reversal must be an object saying whether the check ran (checked)")
    extra = sorted(str(name) for name in set(figures) - (MEMBERS if figures["checked"] else NOT_CHECKED_MEMBERS))
    if extra:
        raise Invalid("returned", f"summary/depth_reversal has no member {extra[0]!r:.40}")
    if figures["checked"] is False:
        why = NOT_CHECKED.get(figures.get("reason"))
        shown = {"registered": len(registered) < 2,
                 "stopped": _stopped(stages),
                 "not_adjusted": any(isinstance(s, dict) and s.get("name") == "bundle_adjustment"
                                     and s.get("status") == "skipped" for s in stages)}.get(why, False)
        if not shown or poses is not None or any(c.get("mirror_rotation_deg") is not None for c in registered):
            raise Invalid("returned", f"summary/depth_reversal says the check did not run ({figures.get('reason')!r:.80}), "
                                      "which the result does not show, or poses_determined or a camera's "
                                      "mirror_rotation_deg is stated beside it")
        return
    names = ("cost_px2", "mirror_cost_px2", "noise_variance_px2", "statistic")
    if not all(is_number(figures.get(n)) for n in names) or not (figures["cost_px2"] >= 0
                                                                   and figures["mirror_cost_px2"] >= 0
                                                                   and figures["noise_variance_px2"] > 0):
        raise Invalid("returned", f"summary/depth_reversal must state {', '.join(names)} as numbers, the costs not "
                                  "negative and the noise positive")
    cost, twin, variance = figures["cost_px2"], figures["mirror_cost_px2"], figures["noise_variance_px2"]
    statistic, rejected, adopted = verdict(cost, twin, variance)
    ambiguous = not (rejected or adopted)
    ratio = figures.get("cost_ratio")
    if not (_close(figures["statistic"], statistic) and (_close(ratio, twin / cost) if cost > 0 else ratio is None)
            and figures.get("threshold") == MIRROR_CHI2 and figures.get("margin") == MIRROR_MARGIN
            and figures.get("ambiguous") is ambiguous and figures.get("adopted") is adopted
            and poses is (not ambiguous)):
        raise Invalid("returned", "summary/depth_reversal's verdict (ambiguous, adopted, poses_determined) or its "
                                  "statistic and cost ratio are not what its costs and noise give at the check's "
                                  f"thresholds ({MIRROR_CHI2:g} variances, {100 * MIRROR_MARGIN:g}%)")
    _check_figures(figures, ambiguous, adopted, stages, registered)
    if points is not None:
        _check_observations(figures["observations"], summary, points)
    # Each angle is the constructed twin's (depth_reversal.mirror_angles_deg), recomputed here from
    # the returned rotations (checked against P elsewhere) about the stated reference view.
    reference, angles = figures.get("reference_view"), figures.get("mirror_rotation_deg")
    posed = {c["view"]: np.asarray(c["R"], dtype=float) for c in registered if c.get("R") is not None}
    if not (isinstance(reference, int) and not isinstance(reference, bool) and isinstance(angles, dict)):
        raise Invalid("returned", "summary/depth_reversal must state its reference_view and mirror_rotation_deg")
    # The check builds the twin in a registered view's frame (ambiguity.check); the angles are
    # stated only while that view is still posed, so a reference the result shows neither posed
    # nor dropped afterwards (the sanity layer's reason) would state none for any camera.
    if reference not in posed and not any(
            c.get("view") == reference and c.get("registered") is False and str(c.get("reason") or "").startswith(
                "dropped") for c in cameras):
        raise Invalid("returned", f"summary/depth_reversal/reference_view {reference!r:.20} is not a registered view "
                                  "of the result (nor one dropped after the check): the twin is built in a registered "
                                  "view's frame")
    expected = depth_reversal.mirror_angles_deg(posed, reference) if reference in posed else {}
    if set(angles) != {str(view) for view in expected} or not all(
            _near(angles[str(view)], angle) for view, angle in expected.items()):
        raise Invalid("returned", "summary/depth_reversal/mirror_rotation_deg is not, for each registered view, the "
                                  f"angle between its camera and the twin's mirrored in view {reference}'s frame "
                                  "(depth_reversal.mirror_angles_deg of the returned rotations)")
    for camera in registered:
        stated, angle = camera.get("mirror_rotation_deg"), expected.get(camera.get("view"))
        if not (stated is None if angle is None else _near(stated, angle)):
            raise Invalid("returned", f"cameras/{camera.get('view')}/mirror_rotation_deg {stated!r:.40} is not the "
                                      f"twin's angle for its view ({angle!r})")


def _check_figures(figures: dict, ambiguous: bool, adopted: bool, stages: list, registered: list[dict]) -> None:
    """The record's other figures are of their types and ranges, and those the result shows are
    its: the rig returned (the twin's figures where it was adopted) fits the observations the
    bundle_adjustment stage kept, at the focal length of its K; every observation sent is the
    projective stage's count where that stage counts each once (the projective and incremental
    paths; a K-known registration counts its inliers). The returned rig is refitted whenever the
    twin is not rejected (ambiguity.check: a refit only lowers its cost, so cannot undo a rejection)."""
    counts = ("observations", "observations_fitting", "mirror_observations_fitting")
    if not all(type(figures.get(n)) is int and figures[n] >= 0 for n in counts) or not (
            figures["observations_fitting"] <= figures["observations"]
            and figures["mirror_observations_fitting"] <= figures["observations"]):
        raise Invalid("returned", "summary/depth_reversal must state its observations and those each rig fits as "
                                  "counts (integers >= 0), the fitting ones at most the observations")
    if not all(is_number(figures.get(n)) and figures[n] > 0 for n in ("focal_px", "mirror_focal_px")):
        raise Invalid("returned", "summary/depth_reversal must state focal_px and mirror_focal_px as positive numbers")
    if figures.get("model") not in MODELS or type(figures.get("returned_refitted")) is not bool:
        raise Invalid("returned", f"summary/depth_reversal's model is one of {', '.join(MODELS)} and "
                                  "returned_refitted true or false")
    # mirror_capped: whether a twin's adjustment stopped at its iteration cap (its cost then an
    # upper bound); taken as stated with the costs, a boolean where stated (results from before it
    # was written have none).
    if "mirror_capped" in figures and type(figures["mirror_capped"]) is not bool:
        raise Invalid("returned", "summary/depth_reversal/mirror_capped must be true or false")
    if (ambiguous or adopted) and figures["returned_refitted"] is not True:
        raise Invalid("returned", "summary/depth_reversal/returned_refitted must be true: the returned rig is refitted "
                                  "whenever the twin is not rejected")
    named = {s.get("name"): s for s in stages if isinstance(s, dict)}
    fitting, focal = ("mirror_observations_fitting", "mirror_focal_px") if adopted else ("observations_fitting",
                                                                                         "focal_px")
    adjustment, projective = named.get("bundle_adjustment") or {}, named.get("projective") or {}
    if "observations_kept" in adjustment and adjustment["observations_kept"] != figures[fitting]:
        raise Invalid("returned", f"summary/depth_reversal/{fitting} is {figures[fitting]!r}, the rig returned fits "
                                  f"{adjustment['observations_kept']!r:.40} "
                                  "(stages/bundle_adjustment/observations_kept)")
    K = adjustment.get("K")
    shown = K[0][0] if isinstance(K, list) and K and isinstance(K[0], list) and K[0] else None
    if shown is not None and not _close(figures[focal], shown):
        raise Invalid("returned", f"summary/depth_reversal/{focal} is {figures[focal]!r}, the rig returned has focal "
                                  f"length {shown!r:.40} (stages/bundle_adjustment/K)")
    _check_returned_K(K, registered)
    if "observations_of_unregistered_views" in projective and projective.get("observations") != figures["observations"]:
        raise Invalid("returned", f"summary/depth_reversal/observations is {figures['observations']!r}, the projective "
                                  f"stage counts {projective.get('observations')!r:.40}")


def _check_returned_K(K: Any, registered: list[dict]) -> None:
    """The bundle_adjustment stage's K, which the record's focal length is read against, is the K
    of the cameras returned when they share one (every registered camera's K the same: the shared
    models; summary.calibration.K is checked to be it elsewhere), so the record is about the rig
    returned, not a K the stage alone states. (Cameras with a focal length each, the "varying"
    model, share none: the stage's K is then not tied here.)"""
    Ks = [_matrix(c.get("K")) for c in registered if c.get("K") is not None]
    if K is None or not Ks or any(k is None or not np.array_equal(k, Ks[0]) for k in Ks):
        return
    stated = _matrix(K)
    if stated is None or not np.all(
            np.abs(stated - Ks[0]) <= ROUNDING * max(float(np.abs(Ks[0]).max()), 1e-300)):
        raise Invalid("returned", "stages/bundle_adjustment/K is not the K of the cameras returned (every registered "
                                  "camera's), which the depth-reversal record's focal length is read against")


def _check_observations(observations: int, summary: dict, points: list) -> None:
    """The observations the check was sent (every observation of every track, pipeline._run) are
    tied to the data on every path (on the K-known one no stage counts them): at least those the
    points returned hold (each point's track, checked against the certificate's data elsewhere)
    and 2 for each track not returned (a track has 2 views at least), at most one a view for each
    track (summary.tracks and views, checked against the stages and the points)."""
    held = sum(len(p["observations"]) for p in points if isinstance(p, dict) and isinstance(p.get("observations"), list))
    tracks, views = summary.get("tracks"), summary.get("views")
    if not all(type(n) is int and n >= 0 for n in (tracks, views)):
        return  # refused where the summary's counts are read
    least, most = held + 2 * max(tracks - len(points), 0), tracks * views
    if not least <= observations <= most:
        raise Invalid("returned", f"summary/depth_reversal/observations is {observations!r}: the tracks sent hold from "
                                  f"{least} (the points returned's observations, and 2 for each track not returned) "
                                  f"to {most} (one a view for each track)")


def _matrix(value: Any) -> np.ndarray | None:
    """A 3x3 matrix of finite numbers, or None."""
    if not (isinstance(value, list) and len(value) == 3 and all(
            isinstance(row, list) and len(row) == 3 and all(is_number(x) for x in row) for row in value)):
        return None
    return np.array(value, dtype=float)


def _stopped(stages: list) -> bool:
    return any(isinstance(s, dict) and s.get("status") in ("cancelled", "time_limit") for s in stages)


def _near(value: Any, angle: float) -> bool:
    return is_number(value) and abs(value - angle) <= ANGLE_ROUNDING_DEG

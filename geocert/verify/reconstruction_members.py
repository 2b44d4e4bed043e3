"""The members of a reconstruction's stage records that are neither figures (reconstruction_stages
.FIGURES types those) nor read by another check: words, switches, lists of views and tracks, maps
keyed by view, each of the type its writer gives it, and tied to what the result holds where its
data allow (the verifier's, numpy free). A member no check types could state what no run
produces (a start "the same rig as" one that never was, a principal point "estimated": "yes"),
which a reader takes for the run's word.

Writers: pipelines.reconstruction.pipeline (the stages, adjust_best's starts, _principal_point,
_radial_test), solvers.reconstruction.calibrated (registered_by, per_view, resumed_from),
pipelines.reconstruction.features (the photos' matching figures: ``images`` and the matches
stage). Each may be null where the stage has none, as a figure may."""

from __future__ import annotations

import json
import math
import sys
from typing import Any

import numpy as np

from geocert.core.geometry import is_number
from geocert.core.strict import Invalid
from geocert.formulations.reconstruction.camera_claim import (FOCAL_P, MAX_FOCAL_SD_FRACTION, MAX_PRINCIPAL_POINT_SD_PX,
                                                          PRINCIPAL_POINT_CHI2, PRINCIPAL_POINT_P, in_middle_half)
from geocert.verify.reconstruction_stages import MAX_FIGURE, _values

# How calibrated.py registers a view (registered_by's words); adjust_best's starts; the models the
# adjustment is run with (options.camera_model, or "fixed" with K known).
REGISTRATION_STEPS = ("initial pair", "pnp", "essential", "merged", "given")
STARTS = ("autocalibration", "incremental", "linear")
STARTED_FROM = STARTS + ("calibrated",)
ADJUSTMENT_MODELS = ("simple", "varying", "full", "fixed")
AUTOCALIBRATION_METHODS = ("stratified", "direct", "auto")

# (stage, path) -> its type: "boolean" true or false; "text" a string; a tuple one of those words;
# "views" / "tracks" distinct view / track numbers of those the summary counts; "view_map" an
# object keyed by view number, each one of REGISTRATION_STEPS; "measures" an object of numbers >= 0
# (times keyed by step); "object" an object; "counts" a list of counts; "pairs" a list of
# objects, each naming two views. A path's "*" is any entry of a list.
MEMBERS = {
    "*": {"reason": "text"},
    "matches": {"stopped": "text", "pairs_chosen_by": "text", "time_s": "measures", "features_per_image": "counts",
                "verified_pairs": "pairs", "focal_prior_from_exif": "object"},
    "projective": {
        "method": "text", "registered_by": "view_map", "cancelled": "boolean", "time_s": "measures",
        "focal_rounds/*/resumed": "boolean", "focal_rounds/*/radial_tested": "boolean",
        "focal_rounds/*/again_from_a_new_pair": "boolean", "per_view/*/registered_by": REGISTRATION_STEPS,
        "radial_distortion/model": ("auto", "on", "off"), "radial_distortion/estimated": "boolean",
        "radial_distortion/against": ("principal", "simple"), "radial_distortion/reason": "text",
        "principal_point/estimated": "boolean", "principal_point/inside_middle_half": "boolean",
        "principal_point/reason": "text",
        "initial_pair_search/reason": "text"},
    "autocalibration": {
        "method": AUTOCALIBRATION_METHODS, "certified": "boolean", "determined": "boolean",
        "critical_motion": "text", "cameras_built_with_one_K": "boolean", "certificate_views": "views",
        "certificate_tracks": "tracks", "stages/*/name": "text", "stages/*/status": "text",
        "stages/*/certified": "boolean", "stages/*/reason": "text"},
    "bundle_adjustment": {
        "model": ADJUSTMENT_MODELS, "started_from": STARTED_FROM, "starts/*/from": STARTS,
        "starts/*/same_rig_as": STARTS, "principal_point/estimated": "boolean",
        "principal_point/inside_middle_half": "boolean", "principal_point/reason": "text",
        "principal_point_per_view/estimated": "boolean", "principal_point_per_view/inside_middle_half": "boolean",
        "principal_point_per_view/precise": "boolean", "principal_point_per_view/reason": "text",
        "focal_per_view/estimated": "boolean", "focal_per_view/views": "views", "focal_per_view/precise": "boolean",
        "focal_per_view/reason": "text", "radial_distortion/model": ("auto", "on", "off"),
        "radial_distortion/estimated": "boolean", "radial_distortion/reason": "text"},
    "cameras": {"claim": "text"},
}
# The members counted (each a count, at most its total): (stage, path) -> what bounds it.
COUNTS = {("projective", "resumed_from"): "views", ("structure", "tracks_not_started"): "tracks",
          ("cameras", "cameras_not_started"): "views", ("matches", "images"): "views",
          ("matches", "candidate_pairs"): "pairs", ("matches", "tracks_built"): None,
          ("matches", "dropped_inconsistent"): None, ("matches", "dropped_short"): None,
          ("matches", "tracks_kept"): None}


def _fail(where: str, what: str, value: Any) -> None:
    raise Invalid("returned", f"{where} must be null or {what}, got {value!r:.60}")


def _numbers(value: Any, total: int) -> bool:
    return isinstance(value, list) and all(type(v) is int and 0 <= v < total for v in value) \
        and len(set(value)) == len(value)


def _typed(value: Any, where: str, kind: Any, views: int, tracks: int) -> None:
    if value is None:
        return
    if isinstance(kind, tuple):
        if not (isinstance(value, str) and value in kind):
            _fail(where, f"one of {', '.join(kind)}", value)
    elif kind == "boolean" and not isinstance(value, bool):
        _fail(where, "true or false", value)
    elif kind == "text" and not isinstance(value, str):
        _fail(where, "a string", value)
    elif kind == "object" and not isinstance(value, dict):
        _fail(where, "an object", value)
    elif kind == "views" and not _numbers(value, views):
        _fail(where, f"distinct view numbers (of the {views} views)", value)
    elif kind == "tracks" and not _numbers(value, tracks):
        _fail(where, f"distinct track numbers (of the {tracks} tracks)", value)
    elif kind == "counts" and not (isinstance(value, list) and all(type(v) is int and 0 <= v <= MAX_FIGURE
                                                                     for v in value)):
        _fail(where, "a list of counts (integers >= 0)", value)
    elif kind == "measures" and not (isinstance(value, dict) and all(
            is_number(v) and 0 <= v <= MAX_FIGURE for v in value.values())):
        _fail(where, "an object of numbers >= 0 (times)", value)
    elif kind == "view_map" and not (isinstance(value, dict) and all(
            isinstance(key, str) and key.isdigit() and int(key) < views and key == str(int(key))
            and step in REGISTRATION_STEPS for key, step in value.items())):
        _fail(where, f"an object keyed by view number (of the {views} views), each one of "
                     f"{', '.join(REGISTRATION_STEPS)}", value)
    elif kind == "pairs" and not (isinstance(value, list) and all(
            isinstance(entry, dict) and _numbers(entry.get("views"), views) and len(entry["views"]) == 2
            for entry in value)):
        _fail(where, "a list of objects, each naming two views", value)


def check_members(result: dict) -> None:
    """Every typed member of every stage (MEMBERS, COUNTS), ``images`` and its ties to the
    matches stage, and the members tied to what the result holds (_check_ties)."""
    summary = result.get("summary") or {}
    views, tracks = summary["views"], summary["tracks"]  # counts (check_stages)
    totals = {"views": views, "tracks": tracks, "pairs": views * (views - 1) // 2, None: MAX_FIGURE}
    stages = {stage["name"]: stage for stage in result["stages"]}
    for name, stage in stages.items():
        for path, kind in {**MEMBERS["*"], **MEMBERS.get(name, {})}.items():
            for where, value in _values(stage, path.split("/"), f"stages/{name}"):
                _typed(value, where, kind, views, tracks)
    for (name, path), total in COUNTS.items():
        value = stages.get(name, {}).get(path)
        if value is not None and not (type(value) is int and 0 <= value <= totals[total]):
            _fail(f"stages/{name}/{path}", f"a count (an integer from 0 to {totals[total]:g})", value)
    _check_images(result, stages.get("matches"), views)
    _check_ties(result, stages, views, tracks)


def _check_images(result: dict, matches: dict | None, views: int) -> None:
    """``images`` (the photos' matching figures) is an object exactly when the result has a
    matches stage (photos sent: kinds.reconstruction), and that stage restates its figures (but
    focal_prior_from_exif, added after it); it counts the views sent, and its figures bound the
    points' observations (_check_image_points)."""
    images = result.get("images")
    if images is not None and not isinstance(images, dict):
        raise Invalid("returned", f"images must be null or an object, got {type(images).__name__}")
    if (images is None) != (matches is None):
        raise Invalid("returned", "images is stated exactly when the result has a matches stage (photos sent), "
                                  f"this result {'has' if matches is not None else 'has no'} matches stage")
    if images is None:
        return
    for name, value in images.items():
        # the same JSON (review 59: 1268.0 or a pair's views [0.0, 1.0] compared equal to the stage's
        # counts, typed there only, and an index of a float stopped the check with a TypeError)
        if name != "focal_prior_from_exif" and name in matches and not _same(matches[name], value):
            raise Invalid("returned", f"images/{name} is not the matches stage's {name}")
        if name == "focal_prior_from_exif" or name in matches:
            continue
        raise Invalid("returned", f"images/{name} is not restated by the matches stage (which states the figures "
                                  "it matched with)")
    _typed(images.get("focal_prior_from_exif"), "images/focal_prior_from_exif", "object", views, 0)
    if "images" in images and images["images"] != views:
        raise Invalid("returned", f"images/images is {images['images']!r:.20}, the summary's views {views}")
    counted = images.get("features_per_image")
    if counted is not None and (not isinstance(counted, list) or len(counted) != views):
        raise Invalid("returned", f"images/features_per_image must count each of the {views} images")
    _check_image_counts(result, images, matches)
    _check_image_points(result, images)


# The images record's counts its writer states wherever matching ran (features.tracks_from_images).
COUNTED = ("images", "features_per_image", "candidate_pairs", "verified_pairs", "tracks_built",
           "dropped_inconsistent", "dropped_short", "tracks_kept")


def _same(one: Any, other: Any) -> bool:
    """One JSON value and another written alike (a count and its float, true and 1, differ)."""
    return json.dumps(one, sort_keys=True) == json.dumps(other, sort_keys=True)


def _check_image_counts(result: dict, images: dict, matches: dict) -> None:
    """The matching figures' counts agree with each other and with the result, as their writer
    (pipelines.reconstruction.features.tracks_from_images) states them: the tracks built are those
    kept and those dropped; where matching ran to its end or its clock (the stage done or
    time_limit), the tracks kept are the tracks the result reconstructs from (summary/tracks);
    each verified pair is a candidate pair (i < j, none twice, no more than candidate_pairs).
    Stated otherwise (both records alike, review 58: 0 tracks kept beside 1,268 reconstructed,
    1,270,000 built, a pair verified twice), the figures were read as typed counts only."""
    ran = matches.get("status") in ("done", "time_limit", "failed")
    # matching that ran to its end, its clock or too few matched images states every count (kinds.
    # reconstruction: all but a cancel keep the figures); a count null or deleted skipped the ties
    # below (review 59: tracks_kept null beside 10^9 tracks built), and "stopped" is said of a clock
    missing = [name for name in COUNTED if images.get(name) is None]
    if ran and missing:
        raise Invalid("returned", f"images/{missing[0]} is not stated where matching ran (the matches stage "
                                  f"{matches.get('status')}): its writer states each of {', '.join(COUNTED)}")
    if images.get("stopped") is not None and matches.get("status") == "done":
        raise Invalid("returned", "images/stopped is stated beside matching that ran to its end (the matches stage "
                                  "done): it says where the matching's clock stopped it")
    kept = images.get("tracks_kept")
    parts = [images.get(name) for name in ("tracks_kept", "dropped_inconsistent", "dropped_short")]
    tracks = (result.get("summary") or {}).get("tracks")
    if kept is not None and matches.get("status") in ("done", "time_limit") and kept != tracks:
        raise Invalid("returned", f"images/tracks_kept is {kept!r:.20}, and the result reconstructs from "
                                  f"{tracks!r:.20} tracks (summary/tracks)")
    built = images.get("tracks_built")
    if built is not None and all(part is not None for part in parts) and built != sum(parts):
        raise Invalid("returned", f"images/tracks_built is {built!r:.20}: the tracks kept and dropped number "
                                  f"{sum(parts)!r:.20}")
    pairs = images.get("verified_pairs")
    if isinstance(pairs, list):
        seen = [tuple(pair["views"]) for pair in pairs]  # two distinct views each (typed: "pairs")
        candidates = images.get("candidate_pairs")
        if any(i > j for i, j in seen) or len(set(seen)) != len(seen) or (
                candidates is not None and len(seen) > candidates):
            raise Invalid("returned", "images/verified_pairs are candidate pairs (i < j), none twice, at most "
                                      f"candidate_pairs ({candidates!r:.20}) of them")
        for number, pair in enumerate(pairs):  # its matches and inliers (and guided inliers) counted
            if not all(type(pair.get(name)) is int and 0 <= pair[name] <= MAX_FIGURE for name in ("matches", "inliers")
                       ) or not (pair.get("guided") is None or type(pair["guided"]) is int and pair["guided"] >= 0):
                raise Invalid("returned", f"images/verified_pairs/{number}: matches and inliers (and guided) are "
                                          "counts (integers >= 0)")
        _check_pair_figures(images, pairs)


PAIR_FIGURES = {"views", "matches", "inliers", "guided"}  # features.match_pair's figures and the pair


def _check_pair_figures(images: dict, pairs: list) -> None:
    """Each verified pair's figures as features.match_pair states them, and the tracks they make:
    its matches are the first image's features matched once each at most (the ratio test keeps a
    row's nearest column), and so are its guided matches, whose inliers replace the pair's only
    when more (so inliers exceed matches only as the guided count, and never fall below it); a
    track is a connected group of the pairs' inlying matches (build_tracks), so there are at most
    as many tracks built as inliers. Review 59: matches 2,000 beside an image of 1,027 features, an
    image of 0 features in a verified pair, inliers above matches with no guided count, 10^6 tracks
    dropped as short (tracks_built restated to match) beside 1,268 tracks from some 2,000 inliers,
    all verified."""
    counted = images.get("features_per_image")
    for number, pair in enumerate(pairs):
        if not set(pair) <= PAIR_FIGURES:  # review 59: a member no writer states ("extra": 1) verified
            extra = sorted(set(pair) - PAIR_FIGURES)
            raise Invalid("returned", f"images/verified_pairs/{number} states {extra!r:.60}: a pair states "
                                      f"{', '.join(sorted(PAIR_FIGURES))} only")
        first = pair["views"][0]
        figures = [pair[name] for name in ("matches", "inliers", "guided") if pair.get(name) is not None]
        guided = pair.get("guided")
        features = counted[first] if isinstance(counted, list) else None
        if isinstance(counted, list) and type(counted[first]) is int and max(figures) > counted[first] or (
                pair["inliers"] > pair["matches"] and pair["inliers"] != guided) or (
                guided is not None and guided > pair["inliers"]):
            raise Invalid("returned", f"images/verified_pairs/{number}: its figures are not a pair's its writer "
                                      f"states (matches {pair['matches']!r:.20}, inliers {pair['inliers']!r:.20}, "
                                      f"guided {guided!r:.20}, of view {first}'s {features!r:.20} features)")
    built = images.get("tracks_built")
    if built is not None and built > sum(pair["inliers"] for pair in pairs):
        raise Invalid("returned", f"images/tracks_built is {built!r:.20}, more than the verified pairs' inliers "
                                  f"({sum(pair['inliers'] for pair in pairs)}): each track holds one at least")


def _check_image_points(result: dict, images: dict) -> None:
    """The points' observations against the images record they were matched from (features.
    tracks_from_images: a track is a connected group of the verified pairs' inlying matches,
    build_tracks, holding one feature of each of its images): in each view, the points observe at
    most that image's features (features_per_image; each observation is a feature of one track)
    and at most the inliers of that image's verified pairs (each such feature is joined to its
    track by an inlying match of its own), and each point's views lie in one connected component of
    the verified pairs (a track joins no images that no chain of verified pairs joins). Review 60:
    a record stating 10 features, or 5 inliers in each pair, of an image the points observe 443
    times, and a record whose pairs split the images in two beside tracks joining both halves,
    verified. Read where the record states the figures (typed by _check_image_counts), the
    observations' views the cameras' (_check_points)."""
    counted, pairs = images.get("features_per_image"), images.get("verified_pairs")
    points = [point for point in result.get("points") or [] if isinstance(point, dict)]
    observed: dict[int, int] = {}
    for point in points:
        for view, _, _ in point.get("observations") or []:
            observed[view] = observed.get(view, 0) + 1
    for view, number in sorted(observed.items()):
        if isinstance(counted, list) and view < len(counted) and type(counted[view]) is int \
                and number > counted[view]:
            raise Invalid("returned", f"images/features_per_image/{view} is {counted[view]}, and the points observe "
                                      f"view {view} {number} times (each observation one feature of its image)")
        if isinstance(pairs, list):
            inliers = sum(pair["inliers"] for pair in pairs if view in pair["views"])
            if number > inliers:
                raise Invalid("returned", f"images/verified_pairs: the pairs of view {view} hold {inliers} inliers, "
                                          f"and the points observe view {view} {number} times (each observation "
                                          "joined to its track by an inlying match of its own)")
    if not isinstance(pairs, list):
        return
    parent: dict[int, int] = {}

    def root(view: int) -> int:
        while parent.get(view, view) != view:
            view = parent[view]
        return view

    for pair in pairs:
        first, second = (root(view) for view in pair["views"])
        if first != second:
            parent[max(first, second)] = min(first, second)
    for index, point in enumerate(points):
        joined = {root(view) for view, _, _ in point.get("observations") or []}
        if len(joined) > 1:
            raise Invalid("returned", f"images/verified_pairs: points/{index} observes views "
                                      f"{sorted(view for view, _, _ in point['observations'])} that no chain of "
                                      "verified pairs joins (a track is a connected group of the pairs' matches)")


def _check_ties(result: dict, stages: dict, views: int, tracks: int) -> None:
    projective = stages.get("projective", {})
    if projective.get("cancelled") is True and projective.get("status") not in ("cancelled", "time_limit"):
        raise Invalid("returned", f"stages/projective/cancelled is true, and the stage's status is "
                                  f"{projective.get('status')!r:.20} (a stop says it was stopped)")
    per_view = projective.get("per_view")
    if per_view is not None:
        if not (isinstance(per_view, list) and len(per_view) == views and all(isinstance(e, dict) for e in per_view)):
            raise Invalid("returned", f"stages/projective/per_view must hold one entry for each of the {views} views, "
                                      "in view order")
        for k, entry in enumerate(per_view):
            where = f"stages/projective/per_view/{k}"
            if entry.get("view") != k or type(entry.get("view")) is not int:
                raise Invalid("returned", f"{where}/view is {entry.get('view')!r:.20}: the entries are in view order")
            through = entry.get("tracks")
            if not (type(through) is int and 0 <= through <= tracks):
                _fail(f"{where}/tracks", f"a count of at most {tracks} (the tracks)", through)
            for name in ("linked", "points"):
                if entry.get(name) is not None and not (type(entry[name]) is int and 0 <= entry[name] <= through):
                    _fail(f"{where}/{name}", f"a count of at most its tracks ({through})", entry[name])
    _check_starts(result, stages)
    _check_principal_point(stages.get("bundle_adjustment", {}), result=result)
    _check_principal_point(stages.get("projective", {}), "projective", result)
    _check_principal_points_per_view(result, stages.get("bundle_adjustment", {}))
    _check_estimated_off_centre(result, stages.get("bundle_adjustment", {}))
    _check_focals_per_view(result, stages.get("bundle_adjustment", {}))
    _check_adjustment_model(result, stages.get("bundle_adjustment", {}))
    structure, summary = stages.get("structure", {}), result.get("summary") or {}
    left = structure.get("tracks_not_started")
    returned, dropped = len(result.get("points") or []), summary.get("points_dropped")
    if left is not None and type(dropped) is int and left > tracks - returned - dropped:
        raise Invalid("returned", f"stages/structure/tracks_not_started is {left}: the {tracks} tracks less the "
                                  f"{returned} points returned and {dropped} dropped leave {tracks - returned - dropped}")
    cameras = stages.get("cameras", {})
    registered = sum(1 for c in result.get("cameras") or [] if isinstance(c, dict) and c.get("registered") is True)
    if cameras.get("cameras_not_started") is not None and cameras["cameras_not_started"] > registered:
        raise Invalid("returned", f"stages/cameras/cameras_not_started is {cameras['cameras_not_started']}, more than "
                                  f"the {registered} cameras registered")


def _check_starts(result: dict, stages: dict) -> None:
    """adjust_best's starts: each named once, in the order the pipeline makes them, each one the
    result had (the certified upgrade's K, the registration's cameras, the linear estimate); one
    the same rig as an earlier start names that start and was not adjusted; the start adjusted is
    one that was (the first of least fit_cost where each states it), and a known K starts from
    the calibrated reconstruction alone."""
    stage, calibration = stages.get("bundle_adjustment", {}), stages.get("autocalibration", {})
    starts = stage.get("starts") or []
    names = [s.get("from") for s in starts]
    if len(set(names)) != len(names) or names != [n for n in STARTS if n in names]:
        raise Invalid("returned", f"stages/bundle_adjustment/starts/*/from are {names!r:.80}: each start once, in the "
                                  f"pipeline's order ({', '.join(STARTS)})")
    had = {"autocalibration": calibration.get("K") is not None, "linear": calibration.get("linear_K") is not None,
           "incremental": str(stages.get("projective", {}).get("method") or "").startswith("incremental")}
    for k, start in enumerate(starts):
        where = f"stages/bundle_adjustment/starts/{k}"
        if not had[start["from"]]:
            raise Invalid("returned", f"{where}/from is {start['from']!r}, a start this result never had (no "
                                      + {"autocalibration": "K in the autocalibration stage",
                                         "linear": "linear_K in the autocalibration stage",
                                         "incremental": "incremental registration"}[start["from"]] + ")")
        same = start.get("same_rig_as")
        if same is not None:
            if same not in names[:k]:
                raise Invalid("returned", f"{where}/same_rig_as is {same!r}: not an earlier start ({names[:k]!r})")
            adjusted = [n for n in ("rms_px_after_8_iterations", "fit_cost", "observations_fitting")
                        if start.get(n) is not None]
            if adjusted:
                raise Invalid("returned", f"{where}: the same rig as an earlier start is not adjusted, and it states "
                                          f"{adjusted[0]}")
    started = stage.get("started_from")
    tried = [s for s in starts if s.get("same_rig_as") is None]
    if starts and started is not None and started not in [s["from"] for s in tried]:
        raise Invalid("returned", f"stages/bundle_adjustment/started_from is {started!r:.40}, not a start it adjusted "
                                  f"({[s['from'] for s in tried]!r})")
    costs = [s.get("fit_cost") for s in tried]
    if len(tried) > 1 and started is not None and all(is_number(c) for c in costs):
        best = tried[costs.index(min(costs))]["from"]
        if started != best:
            raise Invalid("returned", f"stages/bundle_adjustment/started_from is {started!r}, and the start of least "
                                      f"fit_cost is {best!r} (the one adjust_best goes on with)")
    intrinsics = ((result.get("certificate") or {}).get("options") or {}).get("intrinsics")
    known = isinstance(intrinsics, dict) and intrinsics.get("K") is not None
    if started is not None and (started == "calibrated") != known:
        raise Invalid("returned", f"stages/bundle_adjustment/started_from is {started!r}: the calibrated "
                                  "reconstruction is the start exactly when K is given (options.intrinsics.K)")


def _check_principal_point(stage: dict, name: str = "bundle_adjustment", result: dict | None = None) -> None:
    """_principal_point's test: the principal point is estimated exactly when its chi-square
    passes the threshold and it lies in the image's middle half, and (in the adjustment) only in
    the simple camera model. The registration's test (the projective stage's record,
    pipeline._registration_principal_point) is the same test.

    Both ways: a record saying ``estimated: false`` beside a chi2 above the threshold and a free
    fit inside the middle half contradicts itself (the pipeline writes ``estimated`` exactly when
    both hold), and on the projective record it chose the centred reading of the calibration
    tie (its cameras at the images' centre, with that reference's room). A test that ran (a chi2
    stated) states the pipeline's threshold, and ``inside_middle_half`` is what the free fit's
    principal point (K_free) gives in the registered views' one image size, so neither can be
    edited to make the contradiction disappear. The chi2 itself the verifier cannot recompute (the
    adjustment's fits): a record whose chi2 is edited below the threshold is read as written (a
    limit docs/certificate.md states). A record with no chi2 says the test did not run ("too few
    observations to test"): estimated false."""
    test = stage.get("principal_point")
    if test is None:
        return
    where = f"stages/{name}/principal_point"
    _check_record_shape(test, where, result)
    chi2, threshold = test.get("chi2"), test.get("threshold")
    if test.get("estimated") is True:
        if not (is_number(chi2) and threshold == PRINCIPAL_POINT_CHI2 and chi2 > threshold
                and test.get("inside_middle_half") is True and (name == "projective" or stage.get("model") == "simple")):
            raise Invalid("returned", f"{where}/estimated is true, and its test does not "
                                      f"pass (chi2 above its threshold {PRINCIPAL_POINT_CHI2}, inside the middle half"
                                      + ("" if name == "projective" else ", the simple model") + ")")
    if chi2 is None:
        return
    if threshold != PRINCIPAL_POINT_CHI2:
        raise Invalid("returned", f"{where}/threshold is {threshold!r:.30}: the test's threshold is "
                                  f"{PRINCIPAL_POINT_CHI2} (camera_claim.PRINCIPAL_POINT_CHI2)")
    inside = _inside_middle_half(test.get("K_free"), result)
    if inside is not None and test.get("inside_middle_half") is not inside:
        raise Invalid("returned", f"{where}/inside_middle_half is {test.get('inside_middle_half')!r:.20}, and the free "
                                  f"fit's principal point (K_free) lies {'inside' if inside else 'outside'} the middle "
                                  "half of the views' image")
    if name == "bundle_adjustment" and test.get("estimated") is True:
        _check_estimated_inside(result, where)
    if test.get("estimated") is not True and is_number(chi2) and chi2 > threshold \
            and test.get("inside_middle_half") is True:
        raise Invalid("returned", f"{where}/estimated is {test.get('estimated')!r:.20}, and its test passes (chi2 "
                                  f"{chi2!r:.20} above its threshold {PRINCIPAL_POINT_CHI2}, inside the middle half): "
                                  "the pipeline estimates the principal point exactly then")


# The two shapes _principal_point writes its record in (pipeline._principal_point): the test ran
# (its chi2, threshold and inside_middle_half stated), or it did not, for too few observations.
RECORD_RAN = frozenset({"estimated", "observations", "K_free", "chi2", "threshold", "inside_middle_half"})
RECORD_NOT_RUN = frozenset({"estimated", "observations", "K_free", "reason"})
NOT_RUN_REASON = "too few observations to test"
# pipeline.MIN_TEST_OBSERVATIONS: the test is made on at least this many observations (both fits keep)
MIN_TEST_OBSERVATIONS = 20


def _check_record_shape(test: Any, where: str, result: dict | None) -> None:
    """A principal-point record is one of its writer's two shapes, every member of the type it
    writes: the test ran (RECORD_RAN: at least MIN_TEST_OBSERVATIONS observations, K_free a 3x3 of
    numbers, the chi2 a number, the threshold, inside_middle_half) or it did not (RECORD_NOT_RUN:
    estimated false, the reason "too few observations to test", which holds only below
    MIN_TEST_OBSERVATIONS or without residual degrees of freedom: 2 per observation less 6 per view
    and 3 per point (at most the summary's views and tracks, and the observations) less the 7 of a
    similarity and the free fit's 3). A member left out switched a check off: K_free deleted or
    null, inside_middle_half was read as written; the chi2 deleted beside 1,596 observations, the
    record said the test never ran; either chose the calibration tie's centred reading."""
    if not isinstance(test, dict):
        _fail(where, "an object (the principal point's test)", test)
    members = frozenset(test)
    if members not in (RECORD_RAN, RECORD_NOT_RUN):
        raise Invalid("returned", f"{where} has members {sorted(members)!r:.160}: its writer states "
                                  f"{sorted(RECORD_RAN)} (the test ran) or {sorted(RECORD_NOT_RUN)} (too few "
                                  "observations to test)")
    K_free, observations = test["K_free"], test["observations"]
    if not (isinstance(K_free, list) and len(K_free) == 3 and all(
            isinstance(row, list) and len(row) == 3 and all(is_number(x) and abs(x) <= MAX_FIGURE for x in row)
            for row in K_free)):
        _fail(f"{where}/K_free", "a 3x3 matrix of numbers (the free fit's K)", K_free)
    if not (type(observations) is int and 0 <= observations <= MAX_FIGURE):
        _fail(f"{where}/observations", "a count", observations)
    if not isinstance(test["estimated"], bool):
        _fail(f"{where}/estimated", "true or false", test["estimated"])
    _check_free_K(K_free, f"{where}/K_free", result)
    if members == RECORD_RAN:
        if not (is_number(test["chi2"]) and isinstance(test["inside_middle_half"], bool)):
            raise Invalid("returned", f"{where}: a test that ran states its chi2 (a number) and inside_middle_half "
                                      "(true or false)")
        chi2 = test["chi2"]
        if chi2 < 0 or 0 < chi2 < sys.float_info.min:
            raise Invalid("returned", f"{where}/chi2 is {chi2!r:.30}: the test's statistic is what freeing the "
                                      "principal point saves, at least 0 (pipeline._saved_variances), and a normal "
                                      "float where it is not 0")
        if observations < MIN_TEST_OBSERVATIONS:
            raise Invalid("returned", f"{where}/observations is {observations}: the test is made on at least "
                                      f"{MIN_TEST_OBSERVATIONS} observations, and this record says it ran")
        return
    if test["estimated"] is not False or test["reason"] != NOT_RUN_REASON:
        raise Invalid("returned", f"{where}: a record without the test's figures says estimated false and "
                                  f"{NOT_RUN_REASON!r}")
    summary = (result or {}).get("summary") or {}
    views, tracks = summary.get("views"), summary.get("tracks")
    if observations >= MIN_TEST_OBSERVATIONS and type(views) is int and type(tracks) is int:
        fewest_dof = 2 * observations - (6 * min(views, observations) + 3 * min(tracks, observations) - 7) - 3
        if fewest_dof >= 1:
            raise Invalid("returned", f"{where} says {NOT_RUN_REASON!r} on {observations} observations: at least "
                                      f"{MIN_TEST_OBSERVATIONS}, and with at most {views} views and {tracks} points "
                                      f"the free fit leaves at least {fewest_dof} residual degrees of freedom (the "
                                      "test runs then)")


# The free fit's focal lengths (pixels), relative to the larger side of the views' one image size:
# from a field of view of about 180 degrees to about 0.06 degrees. No adjustment of a registration
# the pipeline accepts ends outside (calibrated.MAX_FOCAL_SCALE holds the registration's focal
# length within 10 times its prior, the image's size); a K_free outside states no fit.
K_FREE_FOCAL = (1e-2, 1e3)


def _check_free_K(K_free: list, where: str, result: dict | None) -> None:
    """K_free is a calibration matrix (reconstruction_stages.FIGURES: 3x3, upper triangular, bottom
    row [0, 0, 1]) whose focal lengths are normal floats within K_FREE_FOCAL of the larger side
    of the views' one image size (where the result states one)."""
    focals = (K_free[0][0], K_free[1][1])
    if not (K_free[1][0] == K_free[2][0] == K_free[2][1] == 0 and K_free[2][2] == 1
            and all(f >= sys.float_info.min for f in focals)):
        _fail(where, "a calibration matrix (upper triangular, bottom row [0, 0, 1], focal lengths normal floats "
                     "above 0)", K_free)
    size = _one_image_size(result)
    if size is not None:
        side = max(size)
        low, high = K_FREE_FOCAL[0] * side, K_FREE_FOCAL[1] * side
        if not all(low <= f <= high for f in focals):
            raise Invalid("returned", f"{where} has focal lengths {[float(f) for f in focals]!r:.60}: a free fit of "
                                      f"views {size[0]:g} x {size[1]:g} px ends within {low:g} to {high:g} px")


def _one_image_size(result: dict | None) -> tuple | None:
    """The one image size (width, height) the registered cameras state, None where they state
    several or none."""
    sizes = {tuple(camera["image_size"]) for camera in (result or {}).get("cameras") or []
             if isinstance(camera, dict) and camera.get("registered") is True
             and isinstance(camera.get("image_size"), list) and len(camera["image_size"]) == 2
             and all(is_number(x) and x > 0 for x in camera["image_size"])}
    return next(iter(sizes)) if len(sizes) == 1 else None


def _returned_outside_middle_half(result: dict) -> list:
    """The registered cameras whose principal point (the K their P fixes: intrinsics_of) lies
    outside the middle half of their own image (image_size): (view, [u, v], image_size) each."""
    outside = []
    for camera in result.get("cameras") or []:
        if not (isinstance(camera, dict) and camera.get("registered") is True and camera.get("P") is not None):
            continue
        size = camera.get("image_size")
        if not (isinstance(size, list) and len(size) == 2 and all(is_number(x) for x in size)):
            continue
        K = intrinsics_of(camera["P"])
        if not in_middle_half(float(K[0, 2]), float(K[1, 2]), size[0], size[1]):
            outside.append((camera.get("view"), [round(float(K[0, 2]), 3), round(float(K[1, 2]), 3)], size))
    return outside


def _check_estimated_inside(result: dict | None, where: str) -> None:
    """A principal point the adjustment estimated (its record says so) is the returned cameras':
    each lies in the middle half of its image, as its test asked of the fit it kept. Judged from
    the cameras (each P's K), not from the record's own figures (K_free, inside_middle_half), which
    the verifier does not replay: a K_free moved inside the middle half beside images restated
    smaller stood for cameras whose principal point lay outside it."""
    if not isinstance(result, dict):
        return
    outside = _returned_outside_middle_half(result)
    if outside:
        view, point, size = outside[0]
        raise Invalid("returned", f"{where}/estimated is true, and camera {view}'s principal point {point} (the K its "
                                  f"P fixes) lies outside the middle half of its {size[0]:g} x {size[1]:g} px image: "
                                  "the test keeps an estimate only inside it")


def _inside_middle_half(K_free: Any, result: dict | None) -> bool | None:
    """Whether K_free's principal point lies in the middle half of the registered views' one image
    size, as _principal_point judges it (|u - w/2| <= w/4 and |v - h/2| <= h/4, the same float
    operations on the same numbers); None where the record or the result states no such size."""
    if not isinstance(result, dict) or not isinstance(K_free, list) or len(K_free) != 3 or not all(
            isinstance(row, list) and len(row) == 3 and all(is_number(x) for x in row) for row in K_free):
        return None
    sizes = {tuple(camera["image_size"]) for camera in result.get("cameras") or []
             if isinstance(camera, dict) and camera.get("registered") is True
             and isinstance(camera.get("image_size"), list) and len(camera["image_size"]) == 2
             and all(is_number(x) for x in camera["image_size"])}
    if len(sizes) != 1:
        return None
    (width, height), = sizes
    return in_middle_half(K_free[0][2], K_free[1][2], width, height)


def intrinsics_of(P: Any) -> np.ndarray:
    """The K a camera's P fixes (K [R | t] = P, K upper triangular with a positive diagonal and
    K[2][2] = 1: the RQ decomposition of P's left 3x3). The degrees of freedom are counted from
    these, not from the K stated: a stated K is checked against P only to P's rounding (1e-9 of
    its largest entry, about 1e-6 px), which would let a K moved by 1e-6 px in each intrinsic,
    its P unchanged, count every intrinsic as not shared (11 degrees of freedom, the allowance
    withdrawn) and so judge cameras that fit within their true tolerance uncertifiable."""
    M = np.asarray(P, dtype=float)[:, :3]
    Q, U = np.linalg.qr(np.flipud(M).T)
    K = np.flipud(np.fliplr(U.T))
    K = K * np.sign(np.diag(K))[None, :]  # a positive diagonal (the rotation's rows flipped to match)
    return K / K[2, 2]


# relative to the focal length: principal points further apart than this are each a view's own
# (genuine ones differ by pixels; a K is tied to its P only to about 1e-9 of P, so the verifier
# reads them off P: intrinsics_of)
PER_VIEW_APART = 1e-6


def _check_adjustment_model(result: dict, stage: dict) -> None:
    """The adjustment's model is the one the options ask for (options.camera_model with K unknown,
    "simple" when absent; "fixed" exactly when K is given), and the cameras returned (the K each P
    fixes: intrinsics_of) have that model's calibration: one K ("fixed", "full"); square pixels,
    no skew and one principal point ("varying", each view its own focal length); the same and one
    focal length ("simple"; a principal point per view only as its test says: _check_principal_
    points_per_view). The hash covers camera_model, so a document restating it beside another
    model's cameras would be about a request its adjustment did not follow."""
    model = stage.get("model")
    options = (result.get("certificate") or {}).get("options") or {}
    intrinsics = options.get("intrinsics")
    known = isinstance(intrinsics, dict) and intrinsics.get("K") is not None
    asked = "fixed" if known else options.get("camera_model", "simple")
    if model is None:  # the adjustment did not run (one that ran states its model)
        if stage.get("status") == "done":
            raise Invalid("returned", "stages/bundle_adjustment/model: an adjustment that ran states its model")
        if stage.get("status") == "skipped" and options.get("bundle_adjustment") is False:
            # the cameras are the start's, put in the model asked for (the pipeline does so before
            # it asks whether to adjust): its calibration, and no test of the principal point
            for name in PRINCIPAL_POINT_TESTS:
                if stage.get(name) is not None:
                    raise Invalid("returned", f"stages/bundle_adjustment/{name} is stated, and the adjustment after "
                                              "which its test runs was skipped (options.bundle_adjustment false)")
            _check_calibration(result, stage, asked, f"the cameras of the model asked for, {asked!r:.20} (the "
                                                     "adjustment skipped: options.bundle_adjustment false),")
        return
    where = "stages/bundle_adjustment/model"
    if model != asked:
        raise Invalid("returned", f"{where} is {model!r:.20}, and the options ask for {asked!r:.20} ("
                                  + ("K given" if known else "options.camera_model") + ")")
    if model != "simple" and (stage.get("principal_point") is not None
                              or stage.get("principal_point_per_view") is not None):
        raise Invalid("returned", f"{where} is {model!r:.20}, and the principal point's tests "
                                  "it states run after the simple model's adjustment only")
    # absent: a document of the second hash form, written while the default was "auto"
    # (hashed_options.SECOND_DEFAULTS; today's documents state it)
    chosen = options.get("principal_point", "auto")
    for name, runs in PRINCIPAL_POINT_TESTS.items():
        if stage.get(name) is not None and chosen not in runs:
            raise Invalid("returned", f"stages/bundle_adjustment/{name} is stated, and options.principal_point "
                                      f"{chosen!r:.20} runs no such test (it runs with {' or '.join(runs)})")
    _check_calibration(result, stage, model, f"{where} is {model!r:.20}, and")


def _check_calibration(result: dict, stage: dict, model: str, said: str) -> None:
    """The cameras returned have ``model``'s calibration (_check_adjustment_model); ``said``
    begins a refusal's words."""
    registered = [camera for camera in result.get("cameras") or []
                  if isinstance(camera, dict) and camera.get("registered") is True and camera.get("P") is not None]
    Ks = [intrinsics_of(camera["P"]) for camera in registered]
    if not Ks:
        return
    tolerance = PER_VIEW_APART * max(abs(K[0, 0]) for K in Ks)
    _check_centred(result, stage, model, Ks, tolerance, said)
    first = Ks[0]

    def shared(entries: tuple) -> bool:
        return all(abs(K[i, j] - first[i, j]) <= tolerance for K in Ks for i, j in entries)

    if model in ("fixed", "full"):
        fits, what = shared(((0, 0), (0, 1), (0, 2), (1, 1), (1, 2))), "one K"
    else:
        # a model without skew: each camera's K its writer builds with a skew of 0, exactly (bundle:
        # the model's K; the start put in the model). Read off P within the tolerance only, a K's
        # skew of 5e-324 or 1e-300 verified (review 53): a skew the model does not have, claimed.
        for number, camera in enumerate(registered):
            K = camera.get("K")
            if isinstance(K, list) and len(K) == 3 and isinstance(K[0], list) and len(K[0]) == 3 \
                    and not (is_number(K[0][1]) and K[0][1] == 0):
                raise Invalid("returned", f"{said} camera {camera.get('view')!r:.10}'s K states a skew of "
                                          f"{K[0][1]!r:.30}: the model has none (exactly 0)")
        square = all(abs(K[0, 1]) <= tolerance and abs(K[0, 0] - K[1, 1]) <= tolerance for K in Ks)
        fits, what = square and shared(((0, 2), (1, 2))), "square pixels, no skew and one principal point"
        if model == "simple":
            per_view = (stage.get("principal_point_per_view") or {}).get("estimated") is True
            focal_per_view = (stage.get("focal_per_view") or {}).get("estimated") is True  # _check_focals_per_view
            fits = square and (focal_per_view or shared(((0, 0),))) and (per_view or shared(((0, 2), (1, 2))))
            what = ("square pixels, no skew, one focal length and one principal point (or one each, as their tests "
                    "say)")
    if not fits:
        raise Invalid("returned", f"{said} the cameras returned do not have its calibration ({what})")


# The principal point's tests (the bundle_adjustment stage's records) and the options.principal_point
# values each runs under (pipeline: _principal_point with "auto" or "per_view", _principal_points_per_view
# with "per_view").
PRINCIPAL_POINT_TESTS = {"principal_point": ("auto", "per_view"), "principal_point_per_view": ("per_view",)}


def _check_centred(result: dict, stage: dict, model: str, Ks: list, tolerance: float, said: str) -> None:
    """The simple and varying models hold the principal point at the image's centre (width / 2,
    height / 2: the pipeline sets every start's there when the views registered share one image
    size) unless a test of it estimated it (``principal_point`` or ``principal_point_per_view``
    estimated, the simple model only). Read where every view of the data has one image size (its
    input_labels; with views of several sizes the pipeline may leave it where the start had it):
    a camera whose P puts it elsewhere was not adjusted in the model stated, or its test's record
    was edited to say it was not estimated (options.principal_point "centre" restated included)."""
    if model not in ("simple", "varying"):
        return
    if any(isinstance(stage.get(name), dict) and stage[name].get("estimated") is True for name in PRINCIPAL_POINT_TESTS):
        return
    centre = _one_image_centre(result)
    if centre is None:
        return
    worst = max(Ks, key=lambda K: float(np.abs(K[:2, 2] - centre).max()))
    if float(np.abs(worst[:2, 2] - centre).max()) > tolerance:
        raise Invalid("returned", f"{said} the {model!r:.20} model holds the principal point at the image's centre "
                                  f"{centre.tolist()} unless its test estimated it, and a camera returned has it at "
                                  f"{worst[:2, 2].round(6).tolist()} with no test saying estimated")


def _one_image_centre(result: dict) -> np.ndarray | None:
    """(width / 2, height / 2) of the one image size every view of the data has (the certificate
    data's input_labels), where the pipeline sets the simple and varying models' principal point;
    None where the views have several sizes or the labels state none."""
    labels = ((result.get("certificate") or {}).get("data") or {}).get("input_labels")
    sizes = labels.get("image_sizes") if isinstance(labels, dict) else None
    if not (isinstance(sizes, list) and sizes and all(isinstance(size, list) and len(size) == 2
                                                      and all(is_number(v) for v in size) for size in sizes)
            and all(size == sizes[0] for size in sizes)):
        return None
    return np.array(sizes[0], dtype=float) / 2


def _check_estimated_off_centre(result: dict, stage: dict) -> None:
    """The adjustment's principal_point record saying ``estimated`` (and no principal point per
    view kept): the simple model's cameras then share the free fit's principal point, which the
    pipeline otherwise holds at the image's centre (_check_centred); a free fit landing exactly
    there (to PER_VIEW_APART of the focal length, about 1e-3 px) is not a fit, so cameras
    returned with it there were not adjusted with it free. Found: with the chi2 raised above the
    threshold (not recomputed), ``estimated: true`` beside every camera at the centre verified."""
    test = stage.get("principal_point")
    if stage.get("model") != "simple" or not (isinstance(test, dict) and test.get("estimated") is True) \
            or (stage.get("principal_point_per_view") or {}).get("estimated") is True:
        return
    registered = [camera for camera in result.get("cameras") or []
                  if isinstance(camera, dict) and camera.get("registered") is True and camera.get("P") is not None]
    centre = _one_image_centre(result)
    sizes = {tuple(camera["image_size"]) for camera in registered if isinstance(camera.get("image_size"), list)
             and len(camera["image_size"]) == 2 and all(is_number(x) for x in camera["image_size"])}
    if centre is None and len(sizes) == 1:  # (a document of a form without input_labels: the cameras' one size)
        centre = np.array(next(iter(sizes)), dtype=float) / 2
    Ks = [intrinsics_of(camera["P"]) for camera in registered]
    if centre is None or not Ks:
        return
    tolerance = PER_VIEW_APART * max(abs(K[0, 0]) for K in Ks)
    if all(float(np.abs(K[:2, 2] - centre).max()) <= tolerance for K in Ks):
        raise Invalid("returned", "stages/bundle_adjustment/principal_point/estimated is true, and every camera "
                                  f"returned has its principal point at the image's centre {centre.tolist()}, where "
                                  "the simple model holds it unless its test estimated it")


def _normal_quantile(p: float) -> float:
    """The standard normal quantile at ``p`` (0.5 < p < 1), by bisection on math.erfc."""
    low, high = 0.0, 40.0
    for _ in range(200):
        middle = (low + high) / 2
        if 0.5 * math.erfc(middle / math.sqrt(2.0)) > 1 - p:
            low = middle
        else:
            high = middle
    return (low + high) / 2


def _chi2_survival(x: float, k: int) -> float:
    """P(chi-square with ``k`` (>= 1) degrees of freedom > x), its closed form for whole k, each
    term taken from its logarithm (no power or factorial overflowing, however many views)."""
    if x <= 0:
        return 1.0
    if k % 2 == 0:
        return sum(math.exp(-x / 2 + j * math.log(x / 2) - math.lgamma(j + 1)) for j in range(k // 2))
    # erfc(sqrt(x / 2)) + sqrt(2x / pi) e^(-x/2) sum_j x^j / (1 3 5 ... (2j + 1)), j < (k - 1) / 2
    return math.erfc(math.sqrt(x / 2)) + sum(
        math.exp(0.5 * math.log(2 * x / math.pi) - x / 2 + j * math.log(x)
                 - (math.lgamma(2 * j + 2) - j * math.log(2.0) - math.lgamma(j + 1)))
        for j in range((k - 1) // 2))


def _chi2_quantile(p: float, k: int) -> float:
    """The chi-square quantile at ``p`` with ``k`` degrees of freedom, by bisection."""
    low, high = 0.0, 10.0 * k + 200.0
    for _ in range(200):
        middle = (low + high) / 2
        if _chi2_survival(middle, k) > 1 - p:
            low = middle
        else:
            high = middle
    return (low + high) / 2


def _focal_test_levels(result: dict, test: dict) -> bool:
    """The kept focal length test's own figures agree with one another and with FOCAL_P: one z a
    view registered at the test (in view order: those returned registered, and those the sanity
    layer dropped after the adjustment, _views_at_adjustment), at least the 20 observations the
    test needs, z_threshold the normal quantile at 1 - FOCAL_P / (2 views), the views named the
    very views whose z exceed it (a dropped one too), at most all but two, one parameter added
    each, and threshold the chi-square quantile at 1 - FOCAL_P for them. A document choosing its
    own quantiles (a threshold of 0, a z_threshold below every z) states a test that never ran."""
    views = _views_at_adjustment(result)
    z, z_threshold, named = test.get("z"), test.get("z_threshold"), test.get("views")
    added, threshold = test.get("parameters_added"), test.get("threshold")
    if not (isinstance(z, list) and 3 <= len(z) == len(views)
            and all(is_number(v) for v in z) and is_number(z_threshold) and is_number(threshold)
            and isinstance(named, list) and type(added) is int and added == len(named) and 1 <= added <= len(z) - 2
            and type(test.get("observations")) is int and test["observations"] >= 20):
        return False
    if not _close_quantile(z_threshold, _normal_quantile(1 - FOCAL_P / (2 * len(z)))):
        return False
    if named != [view for view, value in zip(views, z) if abs(value) > z_threshold]:
        return False
    return _close_quantile(threshold, _chi2_quantile(1 - FOCAL_P, added))


def _views_at_adjustment(result: dict) -> list:
    """The views registered when the adjustment's tests ran, in view order: those returned
    registered and those the sanity layer dropped after it (pipeline._check_cameras: not
    registered, their reason "dropped: ...", as the summary's cameras_dropped counts them), which
    no other step unregisters."""
    return sorted(camera.get("view") for camera in result.get("cameras") or []
                  if isinstance(camera, dict) and type(camera.get("view")) is int
                  and (camera.get("registered") is True
                       or (camera.get("registered") is False and str(camera.get("reason") or "").startswith("dropped"))))


def _close_quantile(stated: float, recomputed: float) -> bool:
    return abs(stated - recomputed) <= 1e-9 * max(1.0, abs(recomputed))


def _check_focals_per_view(result: dict, stage: dict) -> None:
    """_focals_per_view's test (after a principal point per view was kept): a focal length of
    their own for the views it names is kept (``estimated``) only when its chi-square passes its
    threshold and the data fix each such focal length to MAX_FOCAL_SD_FRACTION of it and each
    principal point to MAX_PRINCIPAL_POINT_SD_PX (``precise``), a principal point per view was
    kept, in the simple model; and the registered cameras returned (their P) share one focal
    length but for the views it names, each of which has its own, exactly when it was kept."""
    test = stage.get("focal_per_view")
    where = "stages/bundle_adjustment/focal_per_view"
    estimated = isinstance(test, dict) and test.get("estimated") is True
    named = test.get("views") if isinstance(test, dict) else None
    if estimated:
        chi2, threshold, sd, focal_sd = test.get("chi2"), test.get("threshold"), test.get("sd_px"), test.get("focal_sd")
        options = (result.get("certificate") or {}).get("options") or {}
        if not (is_number(chi2) and is_number(threshold) and chi2 > threshold and test.get("precise") is True
                and test.get("max_sd_px") == MAX_PRINCIPAL_POINT_SD_PX
                and test.get("max_focal_sd") == MAX_FOCAL_SD_FRACTION
                and isinstance(sd, list) and sd and all(is_number(s) and s <= MAX_PRINCIPAL_POINT_SD_PX for s in sd)
                and isinstance(named, list) and named and isinstance(focal_sd, list) and len(focal_sd) == len(named)
                and all(is_number(s) and s <= MAX_FOCAL_SD_FRACTION for s in focal_sd)
                and (stage.get("principal_point_per_view") or {}).get("estimated") is True
                and stage.get("model") == "simple" and options.get("principal_point") == "per_view"
                and _focal_test_levels(result, test)):
            raise Invalid("returned", f"{where}/estimated is true, and its test does not pass (chi2 above its "
                                      f"threshold, a focal_sd for each view named, each at most max_focal_sd "
                                      f"{MAX_FOCAL_SD_FRACTION}, every sd_px at most max_sd_px "
                                      f"{MAX_PRINCIPAL_POINT_SD_PX}, precise, a principal point per view kept, the "
                                      "simple model, options.principal_point per_view, a z for each registered view, "
                                      "the views named those whose focal length's z exceeds z_threshold, one "
                                      "parameter added each, and "
                                      f"z_threshold and threshold the quantiles of level {FOCAL_P} they set)")
    if stage.get("model") != "simple":
        if test is not None:
            raise Invalid("returned", f"{where}: the focal length's test runs after the simple model's adjustment only")
        return
    if test is not None and (stage.get("principal_point_per_view") or {}).get("estimated") is not True:
        # the pipeline runs it only once a principal point per view was kept (options.principal_point
        # per_view): a record beside any other run states a test that never ran, kept or not
        raise Invalid("returned", f"{where} is stated, and its test runs only after a principal point per view "
                                  "was kept (principal_point_per_view estimated)")
    cameras = [camera for camera in result.get("cameras") or []
               if isinstance(camera, dict) and camera.get("registered") is True and camera.get("P") is not None]
    if len(cameras) < 2:
        return
    focals = {camera.get("view"): float(intrinsics_of(camera["P"])[0, 0]) for camera in cameras}
    apart = PER_VIEW_APART * max(abs(f) for f in focals.values())
    own = set(named) if estimated and isinstance(named, list) else set()
    shared = [f for view, f in focals.items() if view not in own]
    if not shared or any(abs(f - shared[0]) > apart for f in shared):
        raise Invalid("returned", f"{where}: the cameras returned have focal lengths of their own beyond the views "
                                  "its test names" if estimated else
                                  f"{where}: the cameras returned have focal lengths of their own, and no test says "
                                  "they were estimated")
    # a named view the sanity layer dropped since has no camera to hold its own focal length (the
    # test's levels above ask that it be a view registered at the test, dropped since)
    if estimated and not all(abs(focals[view] - shared[0]) > apart for view in own if view in focals):
        raise Invalid("returned", f"{where}: a view its test names has the focal length the others share")


def _check_principal_points_per_view(result: dict, stage: dict) -> None:
    """_principal_points_per_view's test (options.principal_point "per_view"): a principal point
    per view is kept (``estimated``) only when its chi-square passes its threshold, every view's
    lies in the middle half of its image (judged from each returned camera's, the K its P fixes,
    not read from inside_middle_half), and the data fix each to MAX_PRINCIPAL_POINT_SD_PX
    (``precise``, every sd_px at most it), in the simple model; and the cameras returned (their
    P) have principal points of their own exactly when it was kept, after a simple-model
    adjustment (the other models share theirs, or set them from the image: "varying")."""
    test = stage.get("principal_point_per_view")
    estimated = isinstance(test, dict) and test.get("estimated") is True
    where = "stages/bundle_adjustment/principal_point_per_view"
    if estimated:
        chi2, threshold, sd = test.get("chi2"), test.get("threshold"), test.get("sd_px")
        added = test.get("parameters_added")
        options = (result.get("certificate") or {}).get("options") or {}
        cameras = [camera for camera in result.get("cameras") or [] if isinstance(camera, dict)]
        registered = sum(1 for camera in cameras if camera.get("registered") is True)
        if not (is_number(chi2) and is_number(threshold) and chi2 > threshold and test.get("inside_middle_half") is True
                # 2 (views - 1) parameters, 2 views with the shared one held at the centre, the views
                # those registered at the test (those returned registered and any the sanity layer
                # dropped since, at most every view); its quantile at 1 - PRINCIPAL_POINT_P
                and type(added) is int and added % 2 == 0
                and max(2, 2 * (registered - 1)) <= added <= 2 * len(cameras)
                and _close_quantile(threshold, _chi2_quantile(1 - PRINCIPAL_POINT_P, added))
                and type(test.get("observations")) is int and test["observations"] >= 20
                and test.get("precise") is True and test.get("max_sd_px") == MAX_PRINCIPAL_POINT_SD_PX
                and isinstance(sd, list) and sd and all(is_number(s) and s <= MAX_PRINCIPAL_POINT_SD_PX for s in sd)
                and stage.get("model") == "simple" and options.get("principal_point") == "per_view"):
            raise Invalid("returned", f"{where}/estimated is true, and its test does not pass (chi2 above its "
                                      f"threshold, the chi-square quantile at {1 - PRINCIPAL_POINT_P:g} for the "
                                      "parameters added (2 a view, less 2), inside the middle half, every sd_px at "
                                      f"most max_sd_px {MAX_PRINCIPAL_POINT_SD_PX}, precise, the simple model, "
                                      "options.principal_point "
                                      "per_view)")
        _check_estimated_inside(result, where)
    if isinstance(test, dict) and test.get("precise") is True:
        # ``precise`` restates its sd_px (every view's at most max_sd_px), and a test whose every
        # condition passed kept the principal points (pipeline._principal_points_per_view): beside
        # ``estimated`` false, precise true says the test failed on its chi-square or the middle half
        sd = test.get("sd_px")
        if not (test.get("max_sd_px") == MAX_PRINCIPAL_POINT_SD_PX and isinstance(sd, list) and sd
                and all(is_number(s) and s <= MAX_PRINCIPAL_POINT_SD_PX for s in sd)):
            raise Invalid("returned", f"{where}/precise is true, and its sd_px are not every one at most max_sd_px "
                                      f"{MAX_PRINCIPAL_POINT_SD_PX}")
        chi2, threshold = test.get("chi2"), test.get("threshold")
        if not estimated and is_number(chi2) and is_number(threshold) and chi2 > threshold \
                and test.get("inside_middle_half") is True:
            raise Invalid("returned", f"{where}/estimated is false, and its test states every condition for keeping "
                                      "a principal point per view passed (chi2 above its threshold, inside the middle "
                                      "half, precise)")
    if stage.get("model") != "simple":
        return
    Ks = [intrinsics_of(camera["P"]) for camera in result.get("cameras") or []
          if isinstance(camera, dict) and camera.get("registered") is True and camera.get("P") is not None]
    if len(Ks) < 2:
        return
    points = [K[:2, 2] for K in Ks]
    apart = max(float(abs(p - points[0]).max()) for p in points) > PER_VIEW_APART * max(abs(K[0, 0]) for K in Ks)
    if apart != estimated:
        raise Invalid("returned", f"{where}: the cameras returned have "
                                  + ("principal points of their own, and the test does not say they were estimated"
                                     if apart else "one principal point, and the test says one each was estimated"))

"""The reconstruction kind's verification adapter (numpy only).

Its claims are the points, each a triangulation in the cameras the certificate's data state, so
they are checked as the triangulation kind's are (TrackItems). ``check_result`` ties the rest of
a result to them (docs/certificate.md, "Reconstruction"):

- the cameras: one per view in view order (each view its index, compared as JSON: true and 1.0
  are not 1); the registered ones (the views the certificate's data
  list) return the P the points are certified in, and K, R, t and the centre that P gives
  (P = K [R | t], K upper triangular with K[2][2] = 1 and a positive diagonal, R a rotation,
  centre -R' t); the others return none of them and claim nothing; a certified camera's reason
  and bound_reason, and a certified point's reason, are null, and a certified point states its
  proof's summary;
- each point's observations are the track the certificate's data hold for it (as JSON), and
  the labels (each camera's name and image size, each point's input track number) those the
  data's input_labels state (a document without them: unchecked, and the report's scope says so);
- every camera the result calls certified, or gives a lower bound, is backed by the camera
  certificate beside it: a valid resection document solved with the result's norm, max_residual,
  abs_gap and camera_rel_gap, one map per searched camera built from the returned points, in
  view order; a certified camera's cost is recomputed from its P, every point lies in front of
  it (the resection bound's scope), its lower bound is at most the proven one and its cost, its
  gap is cost - lower_bound, and its cost at most (1 + tolerance) times the proven bound plus
  abs_gap, the tolerance recomputed (camera_claim) from its points, the norm, camera_rel_gap and
  its degrees of freedom, which the K each returned camera's P fixes give (intrinsics_of);
- the summary's counts and RMS are recomputed from the items (a count an integer, as everywhere
  in the document); each warning is stated once;
- summary.calibration is about the K returned: its K the cameras', its certified_K the one the
  calibration certificate beside it proves (a valid stratified autocalibration certificate of
  the projective reconstruction the pipeline upgraded), the difference, the range edges (the
  ranges that certificate searched) and ``determined`` recomputed, the critical motion judged
  again from the cameras and certified points returned (motion_claim), the summary's
  autocalibration_certified and autocalibration_determined its own, and each of its warnings
  (and views not registered) said;
- the summary's counts of what the pipeline was given and set aside agree with the stages and
  items that record them (the input is not in this document), and its camera claim is the
  words camera_claim gives for the result's norm and camera_rel_gap;
- every registered camera's figures (cost, points, degrees of freedom, tolerance, status) are
  recomputed, whatever it claims, its status a word the kind writes that its figures give (a
  stop word only as its search, or a stop before it started, gave it); the cameras are resected
  on the certified points only.

A camera no bound could certify is not searched (structure.resect_cameras) and claims no bound.
(A result without ``searched`` on its cameras, from before it was stated, is read as every
registered camera searched.) The calibration certificate proves K optimal for the projective
reconstruction in its data, which the pipeline made from the same tracks before the bundle
adjustment; calibration_tie ties it to the result by its images of every shared observation, and
the report's scope states how close they are.
"""

from __future__ import annotations

import json
import math
from typing import Any, Callable

import numpy as np

from geocert.core.geometry import is_number, norm_cost
from geocert.core.strict import Invalid, number, numbers, same, same_counts
from geocert.verify import residual_claims
from geocert.verify.fractional import TRACKS, TrackItems, _check_scope_words, refuse_unknown_members
from geocert.verify.reconstruction_members import intrinsics_of
from geocert.verify.verification import Verification
from geocert.formulations.fractional.options import TriangulationOptions
from geocert.formulations.reconstruction import calibration_claim, calibration_tie, camera_claim, depth_reversal_claim, motion_claim, run_control
from geocert.verify import hashed_options
from geocert.formulations.reconstruction.camera_claim import DOUBTFUL_DROPPED, DOUBTFUL_FRACTION, DOUBTFUL_REMOVED

ROUNDING = 1e-9  # relative: what JSON round trips and a recomputed cost may differ by
MAX_CALIBRATION_ABS_GAP = 1e-9  # the autocalibration's costs are of order 1e-3 on real tracks (the pipeline's: 1e-12)
CAMERA_FIELDS = ("K", "R", "t", "center", "P")


def _views_of(cameras: list[dict]) -> list[dict]:
    """The registered cameras, in view order: the cameras the certificates' data list."""
    return [camera for camera in cameras if camera.get("P") is not None and camera.get("K") is not None]


def camera_maps(points: list[dict], cameras: list[dict]) -> list[dict]:
    """Each camera's resection data from the returned points (camera_claim.sources: every
    observation in that view of a certified finite point), as (source point, target pixel), less
    the outliers the camera says it set aside (camera_claim.kept: the rule recomputed from its P;
    refused when its set_aside is not the rule's count)."""
    return maps_less_set_aside(camera_sources(points, cameras), cameras)


def camera_sources(points: list[dict], cameras: list[dict]) -> list[tuple[list, list]]:
    """Each camera's observations of certified finite points (camera_claim.sources), all of them."""
    return camera_claim.sources([(p.get("point"), p.get("at_infinity"), p.get("certified"), p.get("observations"))
                                 for p in points if isinstance(p, dict)], [int(camera["view"]) for camera in cameras])


def maps_less_set_aside(found: list[tuple[list, list]], cameras: list[dict]) -> list[dict]:
    """``found`` (camera_sources) less what each camera says it set aside (see camera_maps)."""
    out = []
    for camera, (source, target) in zip(cameras, found):
        set_aside = camera.get("set_aside")
        if set_aside is not None and not (type(set_aside) is int and set_aside >= 0):
            raise Invalid("returned", f"cameras/{camera['view']}: set_aside must be a count, got {set_aside!r:.40}")
        if set_aside:
            if camera.get("status") == "not_run" or camera.get("P") is None:
                raise Invalid("returned", f"cameras/{camera['view']}: a camera not judged sets nothing aside")
            source_target = camera_claim.kept(source, target, np.asarray(camera["P"], dtype=float), set_aside)
            if source_target is None:
                raise Invalid("returned", f"cameras/{camera['view']}: set_aside {set_aside}, but the returned camera "
                                          "sets aside none or another number of its observations as outliers "
                                          "(camera_claim.outliers)")
            source, target = source_target
        out.append({"source": source, "target": target})
    return out


def _close(value: Any, expected: float, scale: float) -> bool:
    """``value`` is a number within rounding of ``expected``, read at the magnitude ``scale`` or
    its own, whichever is larger (0: a copy or a recomputation of the same sum, at its own).
    ``expected`` must be finite: against a recomputation that overflowed, |value - inf| <= inf
    would hold for every stated value (depth_reversal_claim._close's class)."""
    return is_number(value) and math.isfinite(expected) and abs(value - expected) <= ROUNDING * max(scale,
                                                                                                       abs(expected))


def _check_camera_fields(camera: dict, where: str) -> None:
    """K, R, t and the centre are what the camera's P gives (they fix each other: P's third row is
    R's, of unit norm, so K [R | t] = P with K[2][2] = 1 leaves no scale free)."""
    P = numbers(camera.get("P"), f"{where}/P", (3, 4), "returned")
    K = numbers(camera.get("K"), f"{where}/K", (3, 3), "returned")
    R = numbers(camera.get("R"), f"{where}/R", (3, 3), "returned")
    t = numbers(camera.get("t"), f"{where}/t", (3,), "returned")
    centre = numbers(camera.get("center"), f"{where}/center", (3,), "returned")
    if not (K[1, 0] == K[2, 0] == K[2, 1] == 0 and K[2, 2] == 1 and K[0, 0] > 0 and K[1, 1] > 0):
        raise Invalid("returned", f"{where}/K must be upper triangular with K[2][2] = 1 and a positive diagonal")
    if not (np.abs(R @ R.T - np.eye(3)).max() <= ROUNDING and np.linalg.det(R) > 0):
        raise Invalid("returned", f"{where}/R is not a rotation")
    scale = np.abs(P).max()
    if not np.abs(K @ np.column_stack([R, t]) - P).max() <= ROUNDING * scale:
        raise Invalid("returned", f"{where}: K [R | t] is not its P")
    if not np.abs(centre + R.T @ t).max() <= ROUNDING * max(1.0, np.abs(t).max()):
        raise Invalid("returned", f"{where}/center is not -R' t")


# The members every form of the writers (kinds.reconstruction: _camera, and triangulation.track_document
# with the track and its observations) has stated of each camera and point, null where it has
# nothing (later forms add k1, distortion_centre, pose_determined, mirror_rotation_deg, set_aside
# and free_camera to a camera, which the stored documents of earlier forms lack, and a result from
# before a camera's judgement was stated has no searched, degrees_of_freedom or tolerance, read
# as such: _check_camera_figures): a record missing one is not its writer's (an uncertified camera's
# cost deleted read as "no cost found").
JUDGED_STATUSES = ("optimal", "not_certified")  # a camera whose cost its writer always states (when finite)
CAMERA_WRITTEN = ("view", "name", "registered", "reason", "image_size", "K", "R", "t", "center", "P", "cost",
                  "lower_bound", "gap", "optimal_cost", "certified", "status", "bound_reason", "points")
# The camera's judgement (kinds.reconstruction._camera writes each on every camera, null or false
# where it has none): each member on every camera or, in a result from before it was stated, on
# none (searched came first, degrees_of_freedom and tolerance later). One left out on one camera
# was read as that earlier form: a camera not searched read as searched.
CAMERA_JUDGEMENT = ("searched", "degrees_of_freedom", "tolerance")
POINT_WRITTEN = ("track", "observations", "point", "at_infinity", "cost", "lower_bound", "gap", "status", "certified",
                 "nodes", "elapsed_s", "reason", "certificate")


def _complete(records: list, written: tuple, key: str) -> None:
    for index, record in enumerate(records):
        missing = [name for name in written if name not in record]
        if missing:
            raise Invalid("returned", f"{key}/{index} leaves out {missing[0]!r}: its writer states "
                                      f"{', '.join(written)} (null where it has none)")


def _all_or_none(records: list, members: tuple, key: str) -> None:
    """Each of ``members`` stated on every record or on none (a form that states it, on all)."""
    for name in members:
        stated = [name in record for record in records]
        if any(stated) and not all(stated):
            raise Invalid("returned", f"{key}/{stated.index(False)} leaves out {name!r}, which the others state: its "
                                      "writer states it on every camera (a result from before it was, on none)")


def _check_cameras(cameras: Any, stated: list) -> tuple[list[dict], list[int]]:
    """The cameras in view order, the registered ones those the certificate's data state."""
    if not isinstance(cameras, list) or not all(isinstance(c, dict) for c in cameras):
        raise Invalid("returned", "the result's cameras must be a list of objects")
    _complete(cameras, CAMERA_WRITTEN, "cameras")
    _all_or_none(cameras, CAMERA_JUDGEMENT, "cameras")
    # a view is an integer (same_counts): in Python true == 1 and 1.0 == 1, so a view stated as true
    # or 1.0 (review 60) passed ==, and was read as that view by every check after
    if not same_counts([camera.get("view") for camera in cameras], list(range(len(cameras)))):
        raise Invalid("returned", "the result's cameras must be one per view, in view order (each view its index, "
                                  "an integer)")
    registered = _views_of(cameras)
    views = [camera["view"] for camera in registered]
    if stated.get("cameras") != [camera["P"] for camera in registered] or \
            not same_counts(stated.get("views", views), views):
        raise Invalid("returned", "the cameras the points are certified in are not the cameras returned")
    chosen = {id(camera) for camera in registered}
    for camera in cameras:
        where = f"cameras/{camera['view']}"
        if id(camera) in chosen:
            _check_camera_fields(camera, where)
            if camera.get("registered") is not True:
                raise Invalid("returned", f"{where}: a camera with a P is registered")
            _check_certified_words(camera, ("reason", "bound_reason"), where, "camera")
            continue
        if any(camera.get(name) is not None for name in CAMERA_FIELDS + ("cost", "lower_bound", "gap")) or \
                camera.get("certified") is not False or camera.get("registered") is not False or \
                camera.get("searched", False) is not False or camera.get("status", "not_run") != "not_run":
            raise Invalid("returned", f"{where}: a camera not registered returns no camera and claims nothing (status "
                                      "not_run)")
    return registered, views


def _check_certified_words(record: dict, names: tuple, where: str, what: str) -> None:
    """A certified camera's or point's reason words are null: its writer states why an item is not
    registered, bounded or certified (kinds.reconstruction._camera: the registration's reason and
    the bound's, null when certified; track_document: the track's, null when optimal), so words
    beside a certified claim ("not proven", review 60) would say of it what its proof denies."""
    if record.get("certified") is not True:
        return
    for name in names:
        if record.get(name) is not None:
            raise Invalid("returned", f"{where}/{name} is {record[name]!r:.60}, beside a certified {what}: its writer "
                                      f"states {name} only of a {what} not certified (null when certified)")


def _check_points(points: Any, tracks: Any, views: list[int]) -> None:
    """Each point's observations are its track in the certificate's data (views by position)."""
    if not isinstance(points, list) or not isinstance(tracks, list) or len(points) != len(tracks):
        raise Invalid("returned", "the result's points are not the certificate's tracks")
    if not all(isinstance(point, dict) for point in points):
        raise Invalid("returned", "the result's points must be a list of objects")
    _complete(points, POINT_WRITTEN, "points")
    for index, (point, track) in enumerate(zip(points, tracks)):
        observations = point.get("observations") if isinstance(point, dict) else None
        if not isinstance(observations, list) or not all(isinstance(o, list) and len(o) == 3 for o in observations):
            raise Invalid("returned", f"points/{index}/observations must be [view, u, v] triples")
        stated = [[views[k], u, v] for k, (u, v) in zip(track["views"], track["points"])]
        if not same_counts(observations, stated):  # a view true or 1.0 is not view 1 (review 60)
            raise Invalid("returned", f"points/{index}/observations are not the track its certificate is about")


LABEL_MEMBERS = ("view_names", "image_sizes", "track_numbers")
LABELS_UNSTATED = ("unchecked: the certificate's data state no input_labels (a document written before they were), so "
                   "which input track each point is, and each camera's name and image size, are the result's word only")
LABELS_STATED = ("each point's track number and each camera's name and image size are the certificate's "
                 "input_labels, hashed with the observations and cameras its claims are about (a holder of the input "
                 "checks data_sha256's data against it: data.tracks[i] is input track input_labels.track_numbers[i])")


def _check_labels(result: dict, data: dict, recorded: bool = True) -> str:
    """The result's labels tied to the input the certificate's data state (input_labels, hashed
    with them): each camera's name and image size are its view's, each point's track number its
    track's. Without input_labels (a document from before they were stated) they are unchecked,
    and the report's scope says so (the returned words); a document of the current form
    (``recorded``: hashed_options.states_records) states them, so without them it is refused
    (leaving them out chose the unchecked reading: the points' track numbers or the cameras' names
    swapped verified then)."""
    labels = data.get("input_labels")
    if labels is None and recorded:
        raise Invalid("data", "data/input_labels is absent: a document of this form (its problem_sha256 covers "
                              "registration) states the input's labels, and without them the result's labels would "
                              "go unchecked")
    if labels is None:
        return LABELS_UNSTATED
    cameras, points = result["cameras"], result["points"]
    names, sizes, tracks = (labels.get(name) if isinstance(labels, dict) else None
                            for name in ("view_names", "image_sizes", "track_numbers"))
    if not (isinstance(labels, dict) and set(labels) == {"view_names", "image_sizes", "track_numbers"}
            and isinstance(names, list) and isinstance(sizes, list) and isinstance(tracks, list)
            and len(names) == len(sizes) == len(cameras) and len(tracks) == len(data.get("tracks") or [])):
        raise Invalid("data", "data/input_labels must be {view_names, image_sizes, track_numbers}: one name and one "
                              "image size for each view, one track number for each track of the data")
    for view, (name, size) in enumerate(zip(names, sizes)):
        if not (name is None or isinstance(name, str)) or not (
                isinstance(size, list) and len(size) == 2 and all(is_number(v) and v > 0 for v in size)):
            raise Invalid("data", f"data/input_labels/{view}: a name (a string or null) and an image size [width, "
                                  "height], both positive")
    if not (all(type(t) is int and t >= 0 for t in tracks) and len(set(tracks)) == len(tracks)):
        raise Invalid("data", "data/input_labels/track_numbers must be distinct track numbers (integers >= 0)")
    for camera, name, size in zip(cameras, names, sizes):
        given = camera.get("image_size")  # numbers, not booleans (True == 1 in Python)
        if camera.get("name") != name or not (isinstance(given, list) and all(is_number(v) for v in given)
                                              and given == size):
            raise Invalid("returned", f"cameras/{camera['view']}: name {camera.get('name')!r:.40} and image_size "
                                      f"{camera.get('image_size')!r:.40} are not its view's in the certificate's "
                                      f"data ({name!r:.40}, {size!r:.40})")
    for index, (point, track) in enumerate(zip(points, tracks)):
        if point.get("track") != track or type(point.get("track")) is not int:
            raise Invalid("returned", f"points/{index}/track is {point.get('track')!r:.40}: the certificate's data "
                                      f"say its observations are input track {track}")
    return LABELS_STATED


def _check_summary(result: dict, registered: list[dict]) -> None:
    """The summary's counts and RMS, recomputed from the items (pipeline._summarise's)."""
    summary = result.get("summary")
    if not isinstance(summary, dict):
        raise Invalid("returned", "the result's summary must be an object")
    cameras, points = result["cameras"], result["points"]
    placed = [p for p in points if p.get("point") is not None]
    count, squared = 0, 0.0
    by_view = {camera["view"]: np.asarray(camera["P"], dtype=float) for camera in registered}
    for point in placed:
        X = np.asarray(point["point"] if point.get("at_infinity") else [*point["point"], 1.0], dtype=float)
        for view, u, v in point["observations"]:
            proj = by_view[int(view)] @ X
            squared += (proj[0] / proj[2] - u) ** 2 + (proj[1] / proj[2] - v) ** 2
            count += 1
    certified_points = sum(1 for p in points if p.get("certified") is True)
    certified_cameras = sum(1 for c in cameras if c.get("certified") is True)
    expected = {"views": len(cameras), "views_registered": len(registered), "points": len(points),
                "observations": count, "points_certified": certified_points,
                "points_certified_fraction": certified_points / len(points) if points else None,
                "cameras_certified": certified_cameras,
                "cameras_certified_fraction": certified_cameras / len(registered) if registered else None}
    for name, value in expected.items():
        given = summary.get(name)
        # a count is the items' number itself, an integer (same_counts: 12.0 is none); only a
        # fraction, a quotient, may differ from the recomputed one by its rounding
        fraction = name.endswith("_fraction")
        if not (same_counts(given, value) if not fraction else
                same(given, value) or (value is not None and _close(given, value, 0.0))):
            raise Invalid("returned", f"summary/{name} is {given!r}, the items give {value!r}"
                                      + ("" if fraction else " (a count: exactly that number)"))
    rms = math.sqrt(squared / count) if count else None
    given = summary.get("rms_reprojection_px")
    if not (given is rms or (rms is not None and _close(given, rms, 1e-6))):
        raise Invalid("returned", f"summary/rms_reprojection_px is {given!r}, the cameras and points give {rms!r}")
    for stage in result.get("stages") or []:  # the stages' counts of the same items
        if not isinstance(stage, dict):
            continue
        counts = {"structure": {"points": len(points), "certified": certified_points},
                  "cameras": {"cameras": len(registered), "certified": certified_cameras,
                              "searched": sum(1 for c in cameras if c.get("searched") is True)}}.get(stage.get("name"))
        for name, value in (counts or {}).items():
            if name in stage and not same_counts(stage[name], value):
                raise Invalid("returned", f"stages/{stage['name']}/{name} is {stage[name]!r}, the items give {value!r} "
                                          "(a count: that integer)")


def _check_pipeline_counts(result: dict, rel_gap: float, states_depth_reversal: bool) -> None:
    """The summary's counts of what the pipeline was given and set aside (tracks, points_dropped,
    cameras_dropped, observations_removed) and its camera claim: each agrees with the stage that
    records it and with the items (the points' track numbers, the cameras dropped with their
    reason, the warnings). The input itself is not in this document: a count of it is checked for
    agreement, not against the input (the scope says so). The camera claim is the words
    camera_claim.statement gives for the result's norm and camera_rel_gap. ``states_depth_reversal``:
    the document's hash form is one whose results state the depth-reversal record (hashed_options)."""
    summary, points, cameras = result["summary"], result["points"], result["cameras"]
    stages = {stage.get("name"): stage for stage in result.get("stages") or [] if isinstance(stage, dict)}
    structure = stages.get("structure", {})
    for name in ("tracks", "points_dropped", "observations_removed"):
        given = summary.get(name)
        if not (isinstance(given, int) and not isinstance(given, bool) and given >= 0):
            raise Invalid("returned", f"summary/{name} must be a count, got {given!r}")
        if name in structure and not same_counts(structure[name], given):
            raise Invalid("returned", f"summary/{name} is {given!r}, the structure stage's {structure[name]!r}")
    numbers_ = [point.get("track") for point in points]
    if not all(isinstance(t, int) and not isinstance(t, bool) and 0 <= t < summary["tracks"] for t in numbers_) \
            or len(set(numbers_)) != len(numbers_) or summary["tracks"] < len(points) + summary["points_dropped"]:
        raise Invalid("returned", f"summary/tracks {summary['tracks']!r}: the points' track numbers must be distinct, "
                                  "below it, and it must count the points returned and dropped")
    if bool(summary["points_dropped"]) != _warned(summary, "points_dropped") or (
            summary["points_dropped"] and not any(str(w.get("detail", "")).startswith(f"{summary['points_dropped']} ")
                                                  for w in summary["warnings"] if w.get("code") == "points_dropped")):
        raise Invalid("returned", f"summary/points_dropped {summary['points_dropped']!r}: its warning must say it")
    dropped = sum(1 for c in cameras if c.get("registered") is False and str(c.get("reason") or "").startswith("dropped"))
    warned = sum(1 for w in summary.get("warnings") or [] if isinstance(w, dict) and w.get("code") == "camera_dropped")
    if not (same_counts(summary.get("cameras_dropped"), dropped) and dropped == warned):
        raise Invalid("returned", f"summary/cameras_dropped is {summary.get('cameras_dropped')!r}: {dropped} views are "
                                  f"dropped by their reason, {warned} by the warnings")
    # claims._doubts, recomputed: the cameras bounded, the counts above. A result from before the
    # key was stated lacks it and its warning (they came together): read as "not doubtful", which
    # it must then be, so a forger gains nothing by dropping them.
    # every camera the stage took up, a stopped one too (a stop never makes the rig look sounder)
    bounded = [c for c in cameras if c.get("registered") and c.get("status") != "not_run"]
    beyond = sum(1 for c in bounded if c.get("certified") is not True)
    removed, kept = summary["observations_removed"], summary.get("observations") or 0
    registered = sum(1 for c in cameras if c.get("registered") is True)
    # The depth-reversal check (pipelines/reconstruction/ambiguity.py) needs an adjustment this
    # verifier does not run: its verdict is taken as stated, but stated consistently (the summary,
    # its warning and every registered camera), and poses not determined make the rig doubtful.
    poses = summary.get("poses_determined")
    if poses not in (True, False, None) or (poses is False) != _warned(summary, "poses_not_determined") or any(
            c.get("pose_determined") != poses for c in cameras if c.get("registered") is True and "pose_determined" in c):
        raise Invalid("returned", f"summary/poses_determined is {poses!r}: its warning (poses_not_determined) and "
                                  "every registered camera's pose_determined must say the same")
    depth_reversal_claim.check(summary, cameras, result.get("stages") or [], states_depth_reversal, points)
    doubtful = bool((len(bounded) >= 2 and beyond > DOUBTFUL_FRACTION * len(bounded))
                    or (removed and removed > DOUBTFUL_REMOVED * (removed + kept))
                    or (dropped and dropped > DOUBTFUL_DROPPED * (dropped + registered))
                    or poses is False)
    if summary.get("doubtful", False) is not doubtful or doubtful != _warned(summary, "reconstruction_doubtful"):
        raise Invalid("returned", f"summary/doubtful is {summary.get('doubtful')!r}: its cameras and counts make the "
                                  f"reconstruction {'' if doubtful else 'not '}doubtful, and the warning must say "
                                  "so exactly then")
    judged = any(c.get("degrees_of_freedom") is not None or c.get("searched") is True for c in cameras)
    # the words before the outlier rule, for a result no camera of which states set_aside (so none
    # set any aside: each is held to all its points)
    claim = camera_claim.statement(result.get("norm"), rel_gap,
                                   any(c.get("set_aside") is not None for c in cameras if isinstance(c, dict)))
    for where, given in (("summary/camera_claim", summary.get("camera_claim")),
                         ("stages/cameras/claim", stages.get("cameras", {}).get("claim"))):
        if not (given == claim or (given is None and not judged)):
            raise Invalid("returned", f"{where} is {given!r:.80}, not what the result's norm and camera_rel_gap say "
                                      f"a certified camera is: {claim!r}")


def _check_projective_counts(result: dict) -> None:
    """The projective stage's counts of what it was given and kept are at most the totals the
    summary states (each track holds at most one observation a view): the stage saw the views
    and tracks sent, before any was dropped, so it may count more than is returned, never more
    than was sent."""
    summary = result["summary"]
    stage = _stage(result, "projective")
    observations = summary["tracks"] * (summary.get("views") or 0)
    # each count, under each name the registration paths state it by (the projective path's, the
    # incremental one's, the K-known one's)
    totals = {"views_registered": summary.get("views"), "registered": summary.get("views"),
              "views": summary.get("views"), "points": summary["tracks"], "tracks": summary["tracks"],
              "observations": observations, "observations_kept": observations,
              "outliers_removed": observations, "observations_of_dropped_tracks": observations,
              "observations_of_unregistered_views": observations}
    for name, total in totals.items():
        given = stage.get(name)
        if name in stage and not (isinstance(given, int) and not isinstance(given, bool) and 0 <= given <= total):
            raise Invalid("returned", f"stages/projective/{name} is {given!r}: at most {total} (the summary's views "
                                      "and tracks, each track one observation a view)")
    given = [stage.get(name) for name in ("observations_kept", "outliers_removed", "observations_of_dropped_tracks",
                                          "observations_of_unregistered_views")]
    if all(isinstance(g, int) for g in given) and "observations" in stage and sum(given) > stage["observations"]:
        raise Invalid("returned", "stages/projective: the observations kept, removed, of dropped tracks and of "
                                  "unregistered views add up to more than its observations")
    _check_nested_counts(stage, summary.get("views") or 0, summary["tracks"])


def _count(value: Any, where: str, total: int) -> None:
    if not (isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= total):
        raise Invalid("returned", f"stages/projective/{where} is {value!r:.40}: at most {total}")


def _view_numbers(value: Any, where: str, views: int) -> None:
    if not (isinstance(value, list) and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v < views
                                            for v in value)):
        raise Invalid("returned", f"stages/projective/{where} is {value!r:.60}: not views of the {views} sent")


def _check_nested_counts(stage: dict, views: int, tracks: int) -> None:
    """The counts and view numbers the stage states inside its records: each focal round's views
    registered, the initial pair's views, shared tracks and inliers (inliers <= shared <= the
    tracks: a track is shared by a pair at most once), and the views each merge added."""
    for k, round_ in enumerate(stage.get("focal_rounds") or []):
        if isinstance(round_, dict) and "registered" in round_:
            _count(round_["registered"], f"focal_rounds/{k}/registered", views)
    if "initial_pair" in stage and stage["initial_pair"] is not None:
        _view_numbers(stage["initial_pair"], "initial_pair", views)
    search = stage.get("initial_pair_search")
    pair = search.get("pair") if isinstance(search, dict) else None
    if isinstance(pair, dict):
        if "views" in pair:
            _view_numbers(pair["views"], "initial_pair_search/pair/views", views)
        if "shared" in pair:
            _count(pair["shared"], "initial_pair_search/pair/shared", tracks)
        if "inliers" in pair:
            _count(pair["inliers"], "initial_pair_search/pair/inliers",
                   pair["shared"] if isinstance(pair.get("shared"), int) else tracks)
    for k, merge in enumerate(stage.get("merged") or []):
        if isinstance(merge, dict) and "views_added" in merge:
            _view_numbers(merge["views_added"], f"merged/{k}/views_added", views)


def _check_distortion(result: dict, registered: list[dict], options: dict) -> None:
    """The radial term (pipelines.reconstruction.claims._distortion): with one kept, every
    certificate is about the observations undistorted with an estimated k1, and the result says
    so. summary.distortion and the certificates_conditional_on_k1 warning (its words the
    statement, which names k1) are stated exactly when a camera states a k1, or the stage that
    tests the term says it was estimated (K unknown: the projective stage's radial_distortion;
    K known: the bundle adjustment's, _check_known_K_distortion); then every registered camera
    states one term (k1 / focal^2 the summary's, at a focal length one of theirs) and its centre,
    the summary calls it not certified, the stage's k1 has its sign, and options radial_distortion
    is not "off"; a camera not registered states none, nor does any camera without the term."""
    summary, cameras = result["summary"], result["cameras"]
    distortion = summary.get("distortion")
    warned = [w for w in summary.get("warnings") or [] if isinstance(w, dict)
              and w.get("code") == "certificates_conditional_on_k1"]
    intrinsics = options.get("intrinsics")
    known = isinstance(intrinsics, dict) and intrinsics.get("K") is not None
    # the stage whose test estimates the term, and the one that never states it
    testing, other = ("bundle_adjustment", "projective") if known else ("projective", "bundle_adjustment")
    if _stage(result, other).get("radial_distortion") is not None:
        raise Invalid("returned", f"stages/{other}/radial_distortion is stated, and with K "
                                  + ("known" if known else "unknown") + f" the term is tested in the {testing} stage")
    stage = _stage(result, testing)
    radial = stage.get("radial_distortion")
    estimated = isinstance(radial, dict) and radial.get("estimated") is True
    stated = [c for c in cameras if c.get("k1") is not None or c.get("distortion_centre") is not None]
    if not (stated or warned or estimated or distortion is not None):
        return
    chosen = {id(camera) for camera in registered}
    if options.get("radial_distortion", "off") == "off" or not registered or any(id(c) not in chosen for c in stated):
        raise Invalid("returned", "a radial term is stated on a camera not registered, or with options "
                                  "radial_distortion off (or absent)")
    if not (isinstance(distortion, dict) and distortion.get("certified") is False
            and distortion.get("model") == "radial_k1" and is_number(distortion.get("k1"))
            and distortion["k1"] != 0 and is_number(distortion.get("focal_px")) and distortion["focal_px"] > 0):
        raise Invalid("returned", "summary/distortion must state the radial term the cameras use (model radial_k1, a "
                                  "nonzero k1 at a positive focal_px), not certified")
    k1, focal, statement = distortion["k1"], distortion["focal_px"], distortion.get("statement")
    if not (len(warned) == 1 and warned[0].get("detail") == statement and f"k1 = {k1:.4g}" in str(statement)):
        raise Invalid("returned", "the certificates_conditional_on_k1 warning must state summary/distortion's "
                                  "statement, naming its k1")
    if not (estimated and is_number(radial.get("k1")) and radial["k1"] * k1 > 0):
        raise Invalid("returned", f"stages/{testing}/radial_distortion must say the term was estimated, with the "
                                  "summary's k1's sign")
    focals = [float(camera["K"][0][0]) for camera in registered]
    if not any(_close(focal, f, 0.0) for f in focals):
        raise Invalid("returned", f"summary/distortion/focal_px {focal!r} is not a registered camera's focal length")
    if known:
        given = numbers(intrinsics["K"], "certificate/options/intrinsics/K", (3, 3), "returned")
        _check_known_K_distortion(radial, k1, focal, given, options)
    for camera, f in zip(registered, focals):
        centre = camera.get("distortion_centre")
        if not (_close(camera.get("k1"), k1 * (f / focal) ** 2, abs(k1)) and isinstance(centre, list)
                and len(centre) == 2 and all(is_number(c) for c in centre)):
            raise Invalid("returned", f"cameras/{camera['view']}: k1 {camera.get('k1')!r} is not summary/distortion's "
                                      f"term at its focal length, or it states no distortion_centre")
        if known:  # the term is about K's principal point, as the pipeline undistorts (bundle.undistort_K)
            if all(_close(c, float(e), 0.0) for c, e in zip(centre, given[:2, 2])):
                continue
            raise Invalid("returned", f"cameras/{camera['view']}/distortion_centre {centre!r} is not the given K's "
                                      "principal point")
        # the term is about the image's centre, as the pipeline undistorts ((w - 1) / 2, (h - 1) / 2)
        size = camera.get("image_size")
        if not (isinstance(size, list) and len(size) == 2 and all(is_number(v) for v in size)
                and all(_close(c, (v - 1) / 2, 1.0) for c, v in zip(centre, size))):
            raise Invalid("returned", f"cameras/{camera['view']}/distortion_centre {centre!r} is not its image's "
                                      "centre")


def _check_known_K_distortion(radial: dict, k1: float, focal: float, K: np.ndarray, options: dict) -> None:
    """K known (pipeline._fixed_radial_test): the term is the bundle adjustment's test's, K held
    as given, so its k1 is the summary's at the given K's focal length; the test ran with the
    options' radial_distortion, and an "auto" term passed it: its chi-square above
    camera_claim.RADIAL_CHI2 (the threshold recomputed, not read), the threshold stated that one."""
    where = "stages/bundle_adjustment/radial_distortion"
    if not _close(focal, float(K[0, 0]), 0.0):
        raise Invalid("returned", f"summary/distortion/focal_px {focal!r} is not the given K's focal length")
    if not _close(radial.get("k1"), k1, 0.0):
        raise Invalid("returned", f"{where}/k1 {radial.get('k1')!r:.40} is not summary/distortion's k1 {k1!r}")
    chosen = options.get("radial_distortion")
    if radial.get("model") != chosen:
        raise Invalid("returned", f"{where}/model {radial.get('model')!r:.20} is not options.radial_distortion "
                                  f"{chosen!r:.20}")
    if chosen == "auto" and not (is_number(radial.get("chi2")) and radial["chi2"] > camera_claim.RADIAL_CHI2
                                 and radial.get("threshold") == camera_claim.RADIAL_CHI2):
        raise Invalid("returned", f"{where}: a term kept by the test (options.radial_distortion \"auto\") has its "
                                  f"chi2 above the threshold {camera_claim.RADIAL_CHI2:g} it states")


def _warned(summary: dict, code: str) -> bool:
    warnings = summary.get("warnings")
    return isinstance(warnings, list) and any(isinstance(w, dict) and w.get("code") == code for w in warnings)


# The one warning its writer states once an item: camera_dropped, once for each camera dropped
# (claims.summarise); every other code once at most.
WARNED_EACH = ("camera_dropped",)


def _check_warnings_once(summary: dict) -> None:
    """Each warning is stated once: no warning twice (the same code and detail), and no code but
    camera_dropped (one a camera dropped, each naming its view) twice. The checks that read a
    warning ask whether one of its code is there, so a second copy of it (review 60: the
    critical_motion warning twice verified), or a second one of its code saying something else,
    would be read by none of them."""
    warnings = [w for w in summary.get("warnings") or [] if isinstance(w, dict)]
    seen: set[str] = set()
    codes: set = set()
    for warning in warnings:
        code, written = warning.get("code"), json.dumps(warning, sort_keys=True)
        if written in seen or (code in codes and code not in WARNED_EACH):
            raise Invalid("returned", f"summary/warnings states the {code!r:.40} warning twice: its writer states "
                                      "each warning once (camera_dropped once for each camera dropped)")
        seen.add(written)
        codes.add(code)


def _check_calibration(result: dict, registered: list[dict], verify: Callable[[dict], object],
                       recorded: bool = True) -> None:
    """summary.calibration is about the K the cameras return (claims.CalibrationClaim): its K is
    every registered camera's (model "shared") or the one camera's K the writer picks among them
    (calibration_claim.stated_camera) ("varying"); certified_K is stated exactly when certified,
    and is the returned K exactly when returned_is_certified (then source "autocalibration"); the
    difference and the certified intrinsics on their range's edge (the autocalibration stage's
    ranges) are recomputed; determined only when certified, off the edge and with no critical
    motion; the summary's autocalibration_certified and autocalibration_determined are its own;
    a returned K not the certified one, a certified K on the edge, a critical motion and views
    not registered each have their warning. That the certified K is the autocalibration's
    optimum is the pipeline's statement (the scope says so): no proof of it is carried here. A
    result without summary.calibration (from before it was stated) is read by
    _check_unstated_calibration. ``recorded``: the document's form states every record
    (hashed_options.states_records; _built_with_one_K)."""
    stage = _stage(result, "autocalibration")
    if recorded and result.get("calibration_certificate") is not None and "cameras_built_with_one_K" not in stage:
        raise Invalid("returned", "stages/autocalibration/cameras_built_with_one_K is absent beside a calibration "
                                  "certificate: a document of this form (its problem_sha256 covers registration) "
                                  "states it, and without it the certified_K_of_calibrated_cameras warning would not "
                                  "be asked for")
    summary = result["summary"]
    missing = sum(1 for camera in result["cameras"] if camera.get("registered") is not True)
    if missing and not _warned(summary, "views_not_registered"):
        raise Invalid("returned", f"summary: {missing} views not registered, and no views_not_registered warning "
                                  "says so")
    claim = summary.get("calibration")
    if claim is None:
        return _check_unstated_calibration(result, registered, summary, verify)
    if not isinstance(claim, dict):
        raise Invalid("returned", "summary/calibration must be an object")
    where = "summary/calibration"
    if recorded and "model" not in claim:  # the first form of the claim (before the varying model) had none: read as shared
        raise Invalid("returned", f"{where} leaves out its member 'model', which a document of this form states "
                                  "(claims.summarise)")
    Ks = [numbers(camera["K"], f"cameras/{camera['view']}/K", (3, 3), "returned") for camera in registered]
    K = None if claim.get("K") is None else numbers(claim["K"], f"{where}/K", (3, 3), "returned")
    certified, model = claim.get("certified"), claim.get("model", "shared")
    if (K is None) != (not Ks):
        raise Invalid("returned", f"{where}/K must be stated exactly when cameras with a K are returned")
    if K is not None and model == "shared" and not all(calibration_claim.same(k, K) for k in Ks):
        raise Invalid("returned", f"{where}/K is not every registered camera's K (model shared)")
    if K is not None and model == "varying":
        # The writer's K is one camera's it returns, picked by calibration_claim.stated_camera: the
        # middle focal length's with shared intrinsics (a focal length merely within the cameras'
        # range is one no camera has: review 45; an end camera's is not the one stated: review 46),
        # the middle principal point's among the cameras sharing the most common focal length with a
        # principal point each (any other camera's would say no more than it: issue 33).
        if not calibration_claim.same(K, Ks[calibration_claim.stated_camera(Ks)]):
            raise Invalid("returned", f"{where}/K is not the K of the registered camera the writer states (the "
                                      "middle focal length's with their shared intrinsics; with a principal point "
                                      "per view, the middle principal point's among those sharing the most common "
                                      "focal length) (model varying)")
    if model not in ("shared", "varying") or certified not in (True, False):
        raise Invalid("returned", f"{where}: model must be shared or varying, certified a boolean")
    if K is not None and "model" in claim and model not in _calibration_models(result, Ks):
        # "varying" says each camera carries its own K: the writer says so exactly when the
        # adjustment returned a K a view (claims.calibration_claim); beside cameras sharing one K
        # it verified, the K still every camera's (review 51).
        raise Invalid("returned", f"{where}/model is {model!r:.20}, and the adjustment returned "
                                  + ("a K a view (varying)" if model == "shared" else "one K every camera shares "
                                     "(shared)") + " (stages/bundle_adjustment: its model and principal point tests)")
    cert = claim.get("certified_K")
    if (cert is not None) != (certified is True) or (certified and K is None):
        raise Invalid("returned", f"{where}/certified_K is stated exactly when a certified K is claimed beside a "
                                  "returned one")
    cert = None if cert is None else numbers(cert, f"{where}/certified_K", (3, 3), "returned")
    for name, value in (("K", K), ("certified_K", cert)):  # compared to the cameras' within rounding: its form exact
        if value is not None and not (value[1, 0] == value[2, 0] == value[2, 1] == 0 and value[2, 2] == 1):
            raise Invalid("returned", f"{where}/{name} must be upper triangular with K[2][2] = 1 (its entries below "
                                      "the diagonal exactly 0)")
    stage = _stage(result, "autocalibration")
    ranges = _stage_calibration(result, stage, cert, verify)
    returned = bool(cert is not None and model == "shared" and calibration_claim.same(K, cert))
    if claim.get("returned_is_certified") is not returned:
        raise Invalid("returned", f"{where}/returned_is_certified is {claim.get('returned_is_certified')!r}: the "
                                  f"returned K is {'' if returned else 'not '}the certified one")
    source = claim.get("source")
    intrinsics = ((result.get("certificate") or {}).get("options") or {}).get("intrinsics")
    # adjusted: the adjustment ran (claims.calibration reads "not skipped" of the statuses the
    # pipeline writes: done, or stopped in it; a stage not run or failed adjusted nothing)
    adjusted = _stage(result, "bundle_adjustment").get("status") in ("done", "cancelled", "time_limit")
    expected_source = ("none" if K is None else "given" if isinstance(intrinsics, dict) and "K" in intrinsics
                       else "autocalibration" if returned else "bundle_adjustment" if adjusted else "camera_model")
    if source != expected_source:
        raise Invalid("returned", f"{where}/source {source!r} is not where the returned K comes from "
                                  f"({expected_source!r})")
    if expected_source == "given":  # the K asked for is the cameras' K, and nothing calibrated it
        given_K = numbers(intrinsics["K"], "certificate/options/intrinsics/K", (3, 3), "returned")
        if not (calibration_claim.same(K, given_K) and all(calibration_claim.same(k, given_K) for k in Ks)):
            raise Invalid("returned", f"{where}: source \"given\", but the returned cameras' K is not the options' "
                                      "intrinsics/K")
        if certified or result.get("calibration_certificate") is not None:
            raise Invalid("returned", f"{where}: K was given, so no autocalibration runs: no calibration "
                                      "certificate or certified K may be stated")
    expected = None if cert is None else calibration_claim.difference(K, cert)
    given = claim.get("difference")
    if (expected is None) != (given is None) or (expected is not None and not (
            isinstance(given, dict) and all(_close(given.get(name), value, 1.0) for name, value in expected.items()))):
        raise Invalid("returned", f"{where}/difference is {given!r}, the returned and certified K give {expected!r}")
    edges = [] if cert is None else calibration_claim.on_range_edge(cert, ranges)
    if claim.get("on_range_edge") != edges:
        raise Invalid("returned", f"{where}/on_range_edge is {claim.get('on_range_edge')!r}, the certified K and "
                                  f"the autocalibration's ranges give {edges!r}")
    critical, judged = _stage_motion(result, registered, summary, stage)
    determined = claim.get("determined")
    if determined is True and (not certified or edges or critical or not judged):
        raise Invalid("returned", f"{where}/determined is true, but K is "
                                  + ("not certified" if not certified else "on its range's edge" if edges
                                     else f"under a critical motion ({critical})" if critical else
                                     "not judged: too few cameras or certified points to judge its motion"))
    if K is not None and "certified" in stage and (stage["certified"] is True and stage.get("K") is not None) \
            is not certified:
        raise Invalid("returned", f"stages/autocalibration/certified is {stage['certified']!r}, "
                                  f"summary/calibration/certified {certified!r}")
    if summary.get("autocalibration_certified") is not certified or summary.get("autocalibration_determined") \
            is not determined:
        raise Invalid("returned", "summary: autocalibration_certified and autocalibration_determined must be "
                                  "summary/calibration's certified and determined")
    _require_warnings(result, stage, certified and not returned, cert, edges, critical)
    _check_moved_warning(summary, certified and not returned, [] if expected is None else [expected])


def _check_moved_warning(summary: dict, due: bool, differences: list[dict]) -> None:
    """The returned_K_not_certified warning says how far the returned K moved from the certified
    one, in the figures summary/calibration/difference states (recomputed from the two K above;
    without summary/calibration, from each registered camera's K, one of which calibration.K
    would be): one such warning, only when the returned K is not the certified one, in one of the
    forms the pipeline writes (calibration_claim.moved_warning). Unchecked, the warning's words
    were the document's: on the stored reconstruction it verified saying "focal +0.00%, principal
    point 0.0 px" (the cameras' K 0.05% and 0.7 px from the certified one), saying the returned K
    is the certified one, or twice; holding the figures, it said anything else beside them; and
    with summary/calibration removed, anything at all (reviews 24 and 25)."""
    warned = [w for w in summary.get("warnings") or [] if isinstance(w, dict)
              and w.get("code") == "returned_K_not_certified"]
    if not warned:
        return  # _require_warnings asks for it where due
    if not due or not differences or len(warned) != 1:
        raise Invalid("returned", "summary: a returned_K_not_certified warning is given "
                                  + ("twice" if due and differences else
                                     "though the returned K is the certified one (or none is certified)"))
    said = " or ".join(sorted({calibration_claim.moved_figures(moved) for moved in differences}))
    if not any(warned[0].get("detail") == calibration_claim.moved_warning(adjusted, which, moved)
               for moved in differences for adjusted in calibration_claim.MOVED_BY
               for which in calibration_claim.MOVED_WHICH):
        raise Invalid("returned", f"summary: the returned_K_not_certified warning must state how far the returned K "
                                  f"moved from the certified one, as summary/calibration/difference gives it "
                                  f"({said!r}), in the pipeline's words and nothing else")


def _calibration_models(result: dict, Ks: list) -> tuple[str, ...]:
    """The calibration models the writer may state (claims.calibration_claim: "varying" exactly when
    the adjustment returned a K a view, upgrade.Metric.Ks): an adjustment that ran to its end
    states its model (_check_adjustment_model ties it to the options and the cameras), and returns
    a K a view with the varying model, or with a principal point per view its test estimated (and
    a focal length per view after it); one not run or stopped before it states its model returns
    its start's (one K) or, stopped within a varying adjustment, a K a view. Those Ks differ once
    the adjustment has stepped; stopped before its first step they are its start's, one K every
    camera shares, and either word is true of them."""
    stage = _stage(result, "bundle_adjustment")
    if stage.get("model") is not None:
        test = stage.get("principal_point_per_view")
        per_view = stage["model"] == "varying" or (isinstance(test, dict) and test.get("estimated") is True)
        return ("varying",) if per_view else ("shared",)
    return ("shared", "varying") if all(calibration_claim.same(k, Ks[0]) for k in Ks) else ("varying",)


def _stage(result: dict, name: str) -> dict:
    """The result's stage of that name ({} when it has none)."""
    return next((s for s in result.get("stages") or [] if isinstance(s, dict) and s.get("name") == name), {})


def _stage_calibration(result: dict, stage: dict, cert: np.ndarray | None, verify: Callable[[dict], object],
                       where: str = "summary/calibration/certified_K") -> dict:
    """A certified K (``cert``) is the one the calibration certificate proves (_proven_calibration),
    and the autocalibration stage's K and ranges are its; returns those ranges ({} with no
    certified K)."""
    ranges = {} if cert is None else _proven_calibration(result, cert, verify, where)
    if cert is not None and stage.get("K") is not None and not calibration_claim.same(
            numbers(stage["K"], "stages/autocalibration/K", (3, 3), "returned"), cert):
        raise Invalid("returned", "stages/autocalibration/K is not the certified K")
    if cert is not None and stage.get("intrinsics") is not None and stage["intrinsics"] != _plain(ranges):
        raise Invalid("returned", "stages/autocalibration/intrinsics are not the ranges the calibration certificate "
                                  "searched")
    return ranges


def _stage_motion(result: dict, registered: list[dict], summary: dict, stage: dict) -> tuple[str | None, bool]:
    """_judged_motion, and the autocalibration stage's ``determined`` only where it allows."""
    critical, judged = _judged_motion(result, registered, summary, stage)
    if stage.get("determined") is True and (critical or not judged):
        raise Invalid("returned", "stages/autocalibration/determined is true, but its motion is "
                                  + (f"critical ({critical})" if critical else "not judged"))
    return critical, judged


def _require_warnings(result: dict, stage: dict, not_returned: bool, cert: np.ndarray | None, edges: list,
                      critical: str | None) -> None:
    """The summary's warnings about K, wherever they apply: a certified K not the one returned,
    on its range's edge, of cameras built with it, and a critical motion."""
    for code, due in (("returned_K_not_certified", not_returned), ("certified_K_on_range_edge", edges),
                      ("critical_motion", critical),
                      ("certified_K_of_calibrated_cameras", cert is not None and _built_with_one_K(result, stage))):
        if due and not _warned(result["summary"], code):
            raise Invalid("returned", f"summary: no {code} warning, though the calibration calls for it")
    # Their words are the pipeline's (calibration_claim), wherever given: unchecked, the stored
    # reconstruction verified with its critical_motion (or certified_K_of_calibrated_cameras)
    # warning saying "none: the tracks determine K" (review 25). returned_K_not_certified's are
    # read by _check_moved_warning.
    summary = result["summary"]
    given = calibration_claim.K_given(stage)
    motions = {str(motion) for motion in (summary.get("critical_motion"), stage.get("critical_motion"), critical)
               if motion}
    forms = {"certified_K_on_range_edge": {calibration_claim.edge_warning(edges)} if edges else set(),
             "critical_motion": {calibration_claim.critical_warning(motion, given) for motion in motions},
             "certified_K_of_calibrated_cameras": {calibration_claim.CALIBRATED_CAMERAS_WARNING}}
    for warning in summary.get("warnings") or []:
        code = warning.get("code") if isinstance(warning, dict) else None
        if code in forms and warning.get("detail") not in forms[code]:
            raise Invalid("returned", f"summary: the {code} warning's words are not the pipeline's for this "
                                      "calibration (" + (" or ".join(repr(f) for f in sorted(forms[code])) or
                                                         "none is due") + ")")


def _check_unstated_calibration(result: dict, registered: list[dict], summary: dict,
                                verify: Callable[[dict], object]) -> None:
    """A result without summary.calibration (from before it was stated) states no K in its
    summary (autocalibration_certified and autocalibration_determined are refused), but its
    autocalibration stage still may, and each of its claims is checked as in _check_calibration:
    a stage stating a certified K, or a calibration certificate carried, makes that K the
    certified one (the certificate must prove it; the stage's ranges are the certificate's); the
    motion is judged again (the summary's and the stage's critical_motion, the stage's
    determined); and every warning due is asked for (returned_K_not_certified when the cameras
    do not all use the certified K)."""
    if summary.get("autocalibration_certified") or summary.get("autocalibration_determined"):
        raise Invalid("returned", "summary: autocalibration_certified or autocalibration_determined is claimed "
                                  "with no summary/calibration to say which K it is about")
    stage = _stage(result, "autocalibration")
    cert = None
    if result.get("calibration_certificate") is not None or (stage.get("certified") is True
                                                              and stage.get("K") is not None):
        if stage.get("K") is None:
            raise Invalid("returned", "a calibration certificate is carried, and stages/autocalibration states no K "
                                      "it proves")
        cert = numbers(stage["K"], "stages/autocalibration/K", (3, 3), "returned")
    ranges = _stage_calibration(result, stage, cert, verify, "stages/autocalibration/K")
    edges = [] if cert is None else calibration_claim.on_range_edge(cert, ranges)
    critical, _ = _stage_motion(result, registered, summary, stage)
    Ks = [numbers(camera["K"], f"cameras/{camera['view']}/K", (3, 3), "returned") for camera in registered]
    not_returned = cert is not None and bool(Ks) and not all(calibration_claim.same(k, cert) for k in Ks)
    _require_warnings(result, stage, not_returned, cert, edges, critical)
    # the warning's words, as beside summary/calibration, where calibration.K would be one of the
    # cameras' (unchecked, the stored reconstruction with summary/calibration removed verified
    # saying "focal +0.00%", "+25.00%", the returned K is the certified one, or twice: review 25)
    _check_moved_warning(summary, not_returned, [] if cert is None else [calibration_claim.difference(k, cert)
                                                                          for k in Ks])


def _check_adjusted_K(result: dict, registered: list[dict]) -> None:
    """The adjustment stage's K is the K it returns (pipeline: metric.K when the stage ends, which
    the summary's calibration K restates, claims.calibration_claim): where the registered cameras
    share one K (the K each P fixes, which their K is: _check_camera_fields), the stage's K is it;
    where they do not (a focal length or principal point per view), it is summary/calibration's K,
    which _check_calibration ties to theirs. A stage not done (stopped, skipped) is held to it
    where it states one (what the stop kept is what it had adjusted). A result without
    summary/calibration (an earlier form) is held to the cameras' shared K only."""
    stage = _stage(result, "bundle_adjustment")
    if stage.get("K") is None:
        return
    where = "stages/bundle_adjustment/K"
    K = numbers(stage["K"], where, (3, 3), "returned")
    Ks = [numbers(camera["K"], f"cameras/{camera['view']}/K", (3, 3), "returned") for camera in registered]
    if Ks and all(calibration_claim.same(k, Ks[0]) for k in Ks[1:]):
        if not calibration_claim.same(K, Ks[0]):
            raise Invalid("returned", f"{where} is not the K the registered cameras share (each camera's P fixes "
                                      "it): the stage's K is the one it returned")
        return
    claim = result["summary"].get("calibration")
    stated = claim.get("K") if isinstance(claim, dict) else None
    if stated is not None and not calibration_claim.same(K, numbers(stated, "summary/calibration/K", (3, 3),
                                                                      "returned")):
        raise Invalid("returned", f"{where} is not summary/calibration/K, the K the adjustment returned (the "
                                  "registered cameras do not share one)")


def _built_with_one_K(result: dict, stage: dict) -> bool:
    """Whether the calibration certificate's projective cameras (read and checked by
    _proven_calibration) are all K [R | t] for one K, as the autocalibration stage's
    ``cameras_built_with_one_K`` must say. A result written before the stage said so (a stored
    document, of an earlier hash form) lacks the field, and is not asked for the warning; one of
    the current form lacking it is refused (_check_calibration)."""
    cameras = result["calibration_certificate"]["data"]["cameras"]
    built = calibration_claim.built_with_one_K(numbers(cameras, "calibration_certificate/data/cameras",
                                                       (None, 3, 4), "returned"))
    if "cameras_built_with_one_K" not in stage:
        return False
    if stage["cameras_built_with_one_K"] is not built:
        raise Invalid("returned", f"stages/autocalibration/cameras_built_with_one_K is "
                                  f"{stage['cameras_built_with_one_K']!r}: the calibration certificate's cameras "
                                  f"are {'' if built else 'not '}all K [R | t] for one K")
    return built


def _plain(value: Any) -> Any:
    """``value`` as JSON states it (tuples as lists)."""
    if isinstance(value, dict):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    return float(value) if isinstance(value, (np.floating, np.integer)) else value


def _proven_calibration(result: dict, cert: np.ndarray, verify: Callable[[dict], object],
                        where: str = "summary/calibration/certified_K") -> dict:
    """The certified K is the one the calibration certificate proves: a valid autocalibration
    certificate (stratified: both stages certified) whose metric stage states that K. Returns the
    intrinsics ranges it was proven over (its options', completed from its image size), against
    which the certified K's range edges are judged. The certificate's data is the projective
    reconstruction the pipeline upgraded: it proves K optimal for that reconstruction, which
    calibration_tie ties to the result (ReconstructionItems.check_result, once for any result
    carrying a calibration certificate; the scope states how closely)."""
    from geocert.formulations.autocalibration import problem

    document = result.get("calibration_certificate")
    if not isinstance(document, dict) or document.get("kind") != "autocalibration":
        raise Invalid("returned", f"{where} is claimed without a calibration certificate (an "
                                  "autocalibration certificate proving it)")
    report = verify(document)
    if not getattr(report, "valid", False):
        raise Invalid("returned", f"the calibration certificate is invalid: {getattr(report, 'first_failure', None)}")
    claims = document.get("items")
    if not (isinstance(claims, list) and len(claims) == 2 and all(isinstance(c, dict) and c.get("certified") is True
                                                                  for c in claims)):
        raise Invalid("returned", "the calibration certificate must certify both stratified stages")
    proven = numbers(claims[1].get("K"), "calibration_certificate/items/1/K", (3, 3), "returned")
    if not calibration_claim.same(proven, cert):
        raise Invalid("returned", f"{where} is not the K the calibration certificate proves")
    options, data = document.get("options") or {}, document.get("data") or {}
    for name, cap in (("rel_gap", camera_claim.MAX_REL_GAP), ("metric_rel_gap", camera_claim.MAX_REL_GAP),
                      ("abs_gap", MAX_CALIBRATION_ABS_GAP)):
        if not (is_number(options.get(name)) and 0 <= options[name] <= cap):
            raise Invalid("returned", f"the calibration certificate's {name} {options.get(name)!r} is beyond {cap}: "
                                      "it would certify a K whatever it costs")
    hashed_options.check_calibration_options(options, (result.get("certificate") or {}).get("options") or {})
    stage = _stage(result, "autocalibration")
    # The stage states the option's word, the certificate the method the pipeline ran: "auto" runs
    # the stratified method first, and only its upgrade is carried with a certificate
    # (upgrade.autocalibrate); the option is hashed, so the stage's word is the echo's when stated.
    method, asked = options.get("method", "stratified"), stage.get("method")
    echoed = ((result.get("certificate") or {}).get("options") or {}).get("autocalibration")
    if not (asked == method or (asked == "auto" and method == "stratified")):
        raise Invalid("returned", f"stages/autocalibration/method is {asked!r:.40}, the calibration "
                                  f"certificate's is {method!r:.40}")
    if echoed is not None and asked != echoed:
        raise Invalid("returned", f"stages/autocalibration/method is {asked!r:.40}, the options' autocalibration "
                                  f"{echoed!r:.40}")
    restated = stage.get("stages")
    if not (isinstance(restated, list) and len(restated) == len(claims)):
        raise Invalid("returned", "stages/autocalibration/stages must restate the calibration certificate's two stages")
    for k, (given, claim) in enumerate(zip(restated, claims)):
        # every figure the stage restates, its name by position (as the autocalibration kind's own)
        if not isinstance(given, dict) or given.get("certified") is not True or not all(
                (given.get(name) is None and claim.get(name) is None) or _close(given.get(name), claim.get(name), 0.0)
                for name in ("cost", "lower_bound", "gap")) or given.get("status") != claim.get("status") \
                or given.get("name") != ("affine", "metric")[k] or not (is_number(given.get("gap"))
                                                                        and given["gap"] >= 0
                                                                        and given["lower_bound"] <= given["cost"]):
            raise Invalid("returned", f"stages/autocalibration/stages/{k} is not the calibration certificate's claim")
    size = data.get("image_size")
    return problem.resolve_ranges(dict(options.get("intrinsics") or {}), None if size is None else tuple(size))


def _judged_motion(result: dict, registered: list[dict], summary: dict, stage: dict) -> tuple[str | None, bool]:
    """The critical motion, recomputed (motion_claim.judge) from the registered cameras' K, R, t
    and the certified points with their observations, as the pipeline judged it: when it finds
    one, the summary's critical_motion, and the autocalibration stage's when it states one, must
    be it. Returns (the critical motion, stated or found; whether the motion was fully judged:
    3 cameras and enough certified observations to estimate the rotations' noise, without which
    the plane at infinity's family is not judged, and nothing may be called determined)."""
    given = summary.get("critical_motion")
    if given is not None and not (isinstance(given, str) and given):
        # the judgement's name or null: false, 0 or [] read as "no critical motion" by a reader
        # and as none by the truthiness below, a type no writer gives
        raise Invalid("returned", f"summary/critical_motion is {given!r:.40}: a critical motion's name, or null")
    if len(registered) < 3:
        return summary.get("critical_motion"), False
    by_view = {int(camera["view"]): camera for camera in registered}
    n = len(result["cameras"])
    cameras = [by_view.get(view) for view in range(n)]
    placed = [p for p in result["points"] if p.get("certified") is True and p.get("point") is not None
              and not p.get("at_infinity")]
    observations = [(int(o[0]), k, o[1], o[2]) for k, p in enumerate(placed) for o in p["observations"]]
    judged = motion_claim.judge(
        [None if c is None else np.asarray(c["K"], dtype=float) for c in cameras],
        [None if c is None else np.asarray(c["R"], dtype=float) for c in cameras],
        [None if c is None else np.asarray(c["t"], dtype=float) for c in cameras],
        np.array([p["point"] for p in placed], dtype=float).reshape(-1, 3),
        np.array([o[0] for o in observations], dtype=int), np.array([o[1] for o in observations], dtype=int),
        np.array([o[2:] for o in observations], dtype=float).reshape(-1, 2))
    critical = judged["critical_motion"]
    stated = summary.get("critical_motion")
    if critical is not None and (stated != critical or stage.get("critical_motion", critical) != critical):
        raise Invalid("returned", f"summary/critical_motion is {stated!r}, the returned cameras' motion gives "
                                  f"{critical!r} (motion_claim)")
    # a critical motion stated where none is found is a cautious claim; "none" needs a full judgement
    return stated or critical, judged["rotation_noise_rad"]["estimated"] is not None


def _check_camera_certificate(result: dict, certificate: dict, searched: list[dict], certified: list[int],
                              verify: Callable[[dict], object], expected_maps: list[dict]) -> None:
    """The camera certificate backs the certified cameras, and is about this result: the
    resection kind, the result's norm, max_residual, abs_gap and camera tolerance, and one map
    per searched camera built from the returned points."""
    document = result.get("camera_certificate")
    stopped = [c.get("view") for c in searched if c.get("status") in CAMERA_STOPS]
    if not certified and document is None:
        if stopped:
            raise Invalid("returned", f"cameras/{stopped[0]}: says its search stopped, and no camera certificate "
                                      "holds its resection")
        return
    if not isinstance(document, dict):
        raise Invalid("returned", "cameras are called certified without a camera certificate")
    options, own = document.get("options"), certificate["options"]
    if document.get("kind") != "resection" or not isinstance(options, dict):
        raise Invalid("returned", "the camera certificate must be a resection certificate")
    tolerance = own.get("camera_rel_gap", own.get("rel_gap"))  # the raw options: as the pipeline passed them
    expected = {"norm": result.get("norm"), "max_residual": own.get("max_residual"), "abs_gap": own.get("abs_gap"),
                "rel_gap": tolerance}
    for name, value in expected.items():
        given = options.get(name)
        if not (given == value and type(given) is type(value)) and not (is_number(given) and is_number(value)
                                                                        and float(given) == float(value)):
            raise Invalid("returned", f"the camera certificate's {name} is {given!r}, the result's is {value!r}")
    report = verify(document)
    if not getattr(report, "valid", False):
        raise Invalid("returned", f"the camera certificate is invalid: {getattr(report, 'first_failure', None)}")
    discounted = {entry["item"]: entry["proven"] for entry in (report.scope or {}).get("discounted", [])}
    claims, maps = document.get("items"), document.get("data", {}).get("maps")
    if not isinstance(claims, list) or not isinstance(maps, list) or len(claims) != len(searched) \
            or len(maps) != len(searched):
        raise Invalid("returned", f"the camera certificate must hold one map per searched camera ({len(searched)}, "
                                  "in view order)")
    for k, camera in enumerate(searched):
        if maps[k] != expected_maps[k]:
            raise Invalid("returned", f"cameras/{camera.get('view')}: the camera certificate's map is not the "
                                      "returned points")
    norm = result.get("norm")
    for k, camera in enumerate(searched):
        claim, where = claims[k], f"cameras/{camera.get('view')}"
        proven = discounted.get(k, claim.get("lower_bound"))
        lower, cost = camera.get("lower_bound"), camera.get("cost")
        if not _close(camera.get("optimal_cost"), claim.get("cost"), 0.0) and not (
                camera.get("optimal_cost") is None and claim.get("cost") is None):
            raise Invalid("returned", f"{where}: optimal_cost {camera.get('optimal_cost')!r} is not its resection's "
                                      f"{claim.get('cost')!r}")
        if camera.get("status") in CAMERA_STOPS and claim.get("status") != camera.get("status"):
            raise Invalid("returned", f"{where}: status {camera.get('status')!r} says its search stopped so; its "
                                      f"resection's status is {claim.get('status')!r:.40}")
        if claim.get("certified") is not True:  # no bound is proven: none may be stated
            if lower is not None or camera.get("gap") is not None or camera.get("certified") is not False:
                raise Invalid("returned", f"{where}: its resection is not certified, so it states no lower bound or "
                                          "gap and is not certified")
            continue
        if lower is not None and not (is_number(lower) and lower <= proven and is_number(cost)
                                      and lower <= cost * (1 + ROUNDING)):
            raise Invalid("returned", f"{where}: lower bound {lower!r} above the proven {proven!r} or its cost "
                                      f"{cost!r}")
        if lower is not None and not _close(camera.get("gap"), cost - lower, abs(cost)):
            raise Invalid("returned", f"{where}: gap {camera.get('gap')!r} is not its cost less its lower bound")
        if k not in certified:
            continue
        source = np.asarray(maps[k]["source"], dtype=float).reshape(-1, 3)
        P = np.asarray(camera["P"], dtype=float)
        projected = np.hstack([source, np.ones((len(source), 1))]) @ P.T
        if not np.all(projected[:, 2] > 0):
            raise Invalid("returned", f"{where}: a point is behind the camera returned, outside the bound's scope")
        if lower is None:
            raise Invalid("returned", f"{where}: called certified with no lower bound")
        # its degrees of freedom were checked (_check_camera_figures); none stated: a 3x4 camera's
        dof = camera.get("degrees_of_freedom") or camera_claim.PROJECTIVE_DOF
        tolerance = camera_claim.tolerance(len(source), dof, norm, float(options["rel_gap"]))
        if tolerance is None:
            raise Invalid("returned", f"{where}: {len(source)} points and camera_rel_gap {options['rel_gap']!r} allow "
                                      "no tolerance")
        allowed = (1.0 + tolerance) * proven + float(options["abs_gap"])
        if not cost <= allowed * (1 + ROUNDING) + ROUNDING * max(1.0, abs(cost)):
            raise Invalid("returned", f"{where}: costs {cost:.6g}, beyond (1 + tolerance {tolerance:.3g}) times the "
                                      f"proven bound {proven:.6g} plus abs_gap")


def _check_camera_figures(result: dict, registered: list[dict], rel_gap: float, maps: list[dict],
                          states_free: bool = True) -> list[int]:
    """Every registered camera's own figures, whatever it claims: its points (its map from the
    certified points), its cost recomputed from its P, its degrees of freedom (the K each
    returned camera's P fixes give them: intrinsics_of) and tolerance (camera_claim), its status (``optimal`` exactly when
    certified), no bound unless searched, and a judgement that no bound can certify it recomputed
    (_check_judgement). A camera the cameras stage did not judge (``not_run``) states no figures.
    Returns the views whose judgement is unchecked (a document of an earlier form, ``states_free``
    false, stating no free camera)."""
    norm = result.get("norm")
    unchecked: list[int] = []
    dof = camera_claim.degrees_of_freedom([intrinsics_of(camera["P"]) for camera in registered])
    stage = next((s for s in result.get("stages") or [] if isinstance(s, dict) and s.get("name") == "cameras"), None)
    if stage is not None and "degrees_of_freedom" in stage and not same_counts(stage["degrees_of_freedom"], dof):
        raise Invalid("returned", f"stages/cameras/degrees_of_freedom is {stage['degrees_of_freedom']!r:.40}, the "
                                  f"K the returned cameras' P fix give {dof}")
    for camera, entry in zip(registered, maps):
        where = f"cameras/{camera['view']}"
        certified, status = camera.get("certified"), camera.get("status")
        if certified not in (True, False) or (status == "optimal") != (certified is True):
            raise Invalid("returned", f"{where}: status {status!r} with certified {certified!r} (optimal exactly "
                                      "when certified)")
        if camera.get("searched", True) is not True and any(
                camera.get(name) is not None for name in ("lower_bound", "gap", "optimal_cost")):
            raise Invalid("returned", f"{where}: a camera not searched states no bound")
        _check_camera_status(result, camera, where)
        if status == "not_run":
            if any(camera.get(name) is not None for name in ("cost", "lower_bound", "gap", "optimal_cost",
                                                              "degrees_of_freedom", "tolerance")) \
                    or camera.get("searched", False) is not False \
                    or not (camera.get("points") is None or same_counts(camera["points"], 0)):
                raise Invalid("returned", f"{where}: a camera not judged (not_run) states no figures")
            continue
        source = np.asarray(entry["source"], dtype=float).reshape(-1, 3)
        target = np.asarray(entry["target"], dtype=float).reshape(-1, 2)
        # every judged camera states its certified points' number, as its writer does (null read as
        # "no count" let a forger leave it unstated: review 41)
        if not same_counts(camera.get("points"), len(source)):
            raise Invalid("returned", f"{where}: points {camera['points']!r}, its certified points number "
                                      f"{len(source)}")
        if status == "degenerate" and not len(source) < camera_claim.MIN_POINTS:
            raise Invalid("returned", f"{where}: status degenerate, and its {len(source)} certified points are enough "
                                      f"for a camera (degenerate: fewer than {camera_claim.MIN_POINTS})")
        # A camera judged (optimal or not_certified, never one stopped before its bound: cancelled,
        # not started) on enough points to be one states its cost, as its writer does (null only
        # where the cost is not finite): read only when stated, a cost nulled hid an uncertified
        # camera's misfit (4.72 on the stored reconstruction, review 41).
        if camera.get("cost") is not None or camera.get("certified") is True or (
                status in JUDGED_STATUSES and len(source) >= camera_claim.MIN_POINTS):
            P = np.asarray(camera["P"], dtype=float)
            projected = np.hstack([source, np.ones((len(source), 1))]) @ P.T
            with np.errstate(divide="ignore", invalid="ignore"):
                cost = norm_cost(target - projected[:, :2] / projected[:, 2:3], norm) if len(source) else 0.0
            # Two machines' sums differ by the residuals' round-off (about 1e-13 of the pixels'
            # size each), which a sum of absolute residuals (the L1 norms) keeps whatever the cost:
            # read at the points' number times their pixels' size, 1e-3 of it (1e-12 absolute a point).
            terms = len(source) * 1e-3 * float(np.abs(target).max()) if len(source) else 0.0
            if not math.isfinite(cost) and camera.get("cost") is None and camera.get("certified") is not True:
                pass  # its writer states no cost that is not a number
            elif not (math.isfinite(cost) and _close(camera.get("cost"), cost, terms)):
                raise Invalid("returned", f"{where}: cost {camera.get('cost')!r}, but the returned camera costs "
                                          f"{cost!r} on its certified points")
        tolerance = camera_claim.tolerance(len(source), dof, norm, rel_gap)
        if not _check_judgement(result, camera, where, source, target, tolerance, states_free):
            unchecked.append(camera["view"])
        stated = camera.get("degrees_of_freedom")
        if stated is None and camera.get("tolerance") is None:
            continue  # a result from before they were stated: held to a 3x4 camera's (no allowance)
        if not same_counts(stated, dof):
            raise Invalid("returned", f"{where}: degrees_of_freedom {stated!r}, the K the returned cameras' P fix give {dof}")
        given = camera.get("tolerance")
        if not (given is None and tolerance is None) and not (tolerance is not None and _close(given, tolerance, 0.0)):
            raise Invalid("returned", f"{where}: tolerance {given!r}, its points and degrees of freedom give "
                                      f"{tolerance!r}")
    return unchecked


def _check_judgement(result: dict, camera: dict, where: str, source: np.ndarray, target: np.ndarray,
                     tolerance: float | None, states_free: bool) -> bool:
    """A camera not searched and not certified was judged so by its own figures (no tolerance, or
    a point behind it) or because a free 3x4 camera found locally beats it by more than its
    tolerance (structure._bound_on): no bound, at most that camera's cost, can then certify it.
    The latter judgement is recomputed: the free camera it states (free_camera, its 12 numbers)
    puts every certified point in front, and the returned camera's cost on them exceeds (1 +
    tolerance) times the free camera's plus abs_gap (the tolerance its points, the norm,
    camera_rel_gap and the K returned give). Without it the judgement would be the result's word
    alone, and a camera a stop left unstarted could be called judged: a document stating no free
    camera is refused, but one of an earlier hash form (``states_free`` false, written before the
    kind stated it), whose judgement is then unchecked (returns False; the report's scope names
    the camera). Only such a camera states a free camera."""
    free = camera.get("free_camera")
    if not (camera.get("searched", True) is not True and camera.get("status") == "not_certified"):
        if free is not None:
            raise Invalid("returned", f"{where}: states a free_camera, which only a camera judged uncertifiable by "
                                      "one (not searched, not certified) states")
        return True
    P = np.asarray(camera["P"], dtype=float)
    ones = np.hstack([source, np.ones((len(source), 1))])
    if tolerance is None or not np.all(ones @ P[2] > 0):  # its own figures leave it uncertified
        if free is not None:
            raise Invalid("returned", f"{where}: states a free_camera, though its own figures (no tolerance, or a "
                                      "point behind it) leave it uncertified, no free camera judging it")
        return True
    if free is None:
        if states_free:
            raise Invalid("returned", f"{where}: not searched and not certified, with every certified point in front "
                                      "of it and a tolerance, and no free_camera stated: only a free 3x4 camera "
                                      "beating it by more than its tolerance leaves such a camera unsearched "
                                      "(structure.resect_cameras), and the judgement is recomputed from it")
        return False
    M = numbers(free, f"{where}/free_camera", (3, 4), "returned")
    # A camera is its matrix up to a positive scale: read at its largest entry 1, so that no
    # projection is computed in subnormal arithmetic (a camera scaled by 1e-320 cost 2% less there
    # than it does: rounding, not a camera, beating the one returned).
    largest = float(np.max(np.abs(M)))
    if largest > 0:
        M = M / largest
    options = result["certificate"]["options"]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        projected, own = ones @ M.T, ones @ P.T
        cost = norm_cost(target - own[:, :2] / own[:, 2:3], result.get("norm"))
        beats = norm_cost(target - projected[:, :2] / projected[:, 2:3], result.get("norm"))
    if not (np.all(np.isfinite(projected)) and np.all(projected[:, 2] > 0) and math.isfinite(beats)):
        raise Invalid("returned", f"{where}: its free_camera does not put every certified point in front of it: it "
                                  "is no camera the resection's bound is about")
    # judged beaten only beyond rounding (the kind judges with camera_claim.JUDGED_MARGIN to spare)
    if camera_claim.within(cost, beats * (1 + ROUNDING), tolerance, float(options["abs_gap"])):
        raise Invalid("returned", f"{where}: judged not certifiable by a free 3x4 camera (not searched), but on its "
                                  f"certified points the camera returned costs {cost:.6g} and its free_camera "
                                  f"{beats:.6g}: within its tolerance {tolerance:.3g} (plus abs_gap), so a bound "
                                  "could certify it")
    return True


# A camera's status, as the kind writes it (structure.resect_cameras): "optimal" when certified;
# "not_certified" when judged and not certified; "not_run" when not judged; "degenerate" when its
# certified points are too few for a camera; a stop word only for a camera whose search stopped
# so (its resection claim in the camera certificate says the same) or that was never started
# (not searched, no figures, the cameras stage stopped with that word).
CAMERA_STOPS = ("cancelled", "time_limit", "node_limit")
CAMERA_STATUSES = ("optimal", "not_certified", "not_run", "degenerate") + CAMERA_STOPS


def _check_camera_status(result: dict, camera: dict, where: str) -> None:
    """A registered camera's status is a word the kind writes, and one its figures give (the
    stop words of a search are read against the camera certificate in _check_camera_certificate)."""
    status = camera.get("status")
    if status not in CAMERA_STATUSES:
        raise Invalid("returned", f"{where}: status {status!r:.40} is not a camera's ({', '.join(CAMERA_STATUSES)})")
    searched = camera.get("searched", True) is True
    unfigured = all(camera.get(name) is None for name in ("cost", "lower_bound", "gap", "optimal_cost"))
    if status == "degenerate" and (searched or not unfigured):
        raise Invalid("returned", f"{where}: a degenerate camera (too few points) is not searched and states no cost")
    if status in CAMERA_STOPS and not searched:
        stage = _stage(result, "cameras").get("status")
        if not (status in ("cancelled", "time_limit") and unfigured and stage == status):
            raise Invalid("returned", f"{where}: status {status!r} for a camera not searched says it was never started: "
                                      f"then it states no cost and the cameras stage stopped so (its status: "
                                      f"{stage!r:.40})")


def _check_unstarted(result: dict, registered: list[dict], seen: list[int]) -> None:
    """A camera not judged (``not_run``) is one the cameras stage never reached: then none was
    judged, and the stage did not end "done" (a camera it judged cannot be called not judged,
    which would also take it out of the doubtful rule's count). The cameras a stop left unstarted
    are the last in the order the cameras stage starts them (structure.resect_cameras: most
    certified points first, counted from the returned points, not as stated; then by view; every
    camera started finishes); the stage counts them; and a cancel is the job's too (its stats say
    it was cancelled)."""
    stage = next((s for s in result.get("stages") or [] if isinstance(s, dict) and s.get("name") == "cameras"), None)
    not_judged = [c for c in registered if c.get("status") == "not_run"]
    if not_judged and (len(not_judged) != len(registered) or (stage is not None and stage.get("status") == "done")):
        raise Invalid("returned", f"cameras/{not_judged[0]['view']}: called not judged (not_run), but the cameras "
                                  "stage judged cameras (a camera is not judged only when the stage never ran)")
    judged = [c for c in registered if c.get("status") != "not_run"]
    unstarted = [c for c in judged if c.get("status") in CAMERA_STOPS and c.get("searched", True) is not True]
    if not unstarted:
        return
    if stage is not None and "cameras_not_started" in stage \
            and not same_counts(stage["cameras_not_started"], len(unstarted)):
        raise Invalid("returned", f"cameras/{unstarted[0]['view']}: called never started, with "
                                  f"{len(unstarted)} cameras so, but the cameras stage counts "
                                  f"{stage['cameras_not_started']!r:.20} not started")
    count = {id(camera): n for camera, n in zip(registered, seen)}
    order = sorted(judged, key=lambda c: (-count[id(c)], c["view"]))
    if {id(c) for c in order[len(order) - len(unstarted):]} != {id(c) for c in unstarted}:
        raise Invalid("returned", f"cameras/{unstarted[0]['view']}: called never started ({unstarted[0]['status']!r}), "
                                  "but a camera the cameras stage starts after it (fewer points, or as many and a "
                                  "later view) finished")
    stats = result.get("stats")
    if any(c.get("status") == "cancelled" for c in unstarted) and not (
            isinstance(stats, dict) and stats.get("statuses") == {"cancelled": 1}):
        raise Invalid("returned", f"cameras/{unstarted[0]['view']}: called cancelled, and the job's stats do not say "
                                  "it was cancelled")


class ReconstructionItems(TrackItems, Verification):
    """Points as triangulations (TrackItems), plus ``check_result``: the rest of the result."""

    # problem_sha256 covers every option a claim or check reads, and those deciding whether a
    # stage runs; the earlier forms (the points' options only; then not the latter) are read as
    # hashed_options says
    claim_options = hashed_options.CLAIM_OPTIONS
    earlier_forms = hashed_options.EARLIER_FORMS
    option_names = run_control.OPTION_NAMES

    def check_data(self, data) -> None:
        """The pipeline's data (kinds.reconstruction's certificate_data): the cameras, their
        views, the tracks (each its views and points) and the input's labels (a document written
        before the labels were stated has none): nothing else, as for a triangulation (review 48)."""
        refuse_unknown_members(data, ("cameras", "views", "tracks", "input_labels"), "tracks", ("views", "points"))
        labels = data.get("input_labels")
        if isinstance(labels, dict):
            for name in labels:
                if name not in LABEL_MEMBERS:
                    raise Invalid("data", f"data/input_labels/{name}: unknown field (known: {', '.join(LABEL_MEMBERS)})")

    @staticmethod
    def job_outcomes(result: dict) -> list:
        """One item, certified when it has points and every one is; its status "optimal" then,
        "not_certified" otherwise, as the kind writes it, or "cancelled" or "time_limit" when the
        job's statistics say it was stopped, by a cancel or by its clock in all (a stopped run
        keeps what it finished: a weaker claim)."""
        points = result.get("points") or []
        certified = bool(points) and all(isinstance(p, dict) and p.get("certified") is True for p in points)
        stats = result.get("stats")
        for stop in ("cancelled", "time_limit"):
            if isinstance(stats, dict) and stats.get("statuses") == {stop: 1}:
                return [(stop, certified)]
        return [("optimal" if certified else "not_certified", certified)]

    def check_returned(self, result: dict, certificate: dict, earlier_estimates: bool = True) -> None:
        """A certified point's summary states its proof's root box and scope in the solver's words,
        as a triangulation track's must (TrackItems: the same writer makes both). Its determinacy
        is null: the kind runs no analysis for a point (kinds.reconstruction writes null), so a
        point stating one states an estimate no writer made and no check recomputes (review 49)."""
        points = result.get("points")
        if not isinstance(points, list):
            return
        for index, point in enumerate(points):
            if isinstance(point, dict) and point.get("determinacy") is not None:
                raise Invalid("returned", f"points/{index}/determinacy is stated, and a reconstruction's writer states "
                                          "none for a point (null: no analysis of it is run)")
        for index, point in enumerate(points):
            if not (isinstance(point, dict) and point.get("certified") is True):
                continue
            _check_certified_words(point, ("reason",), f"points/{index}", "point")
            # a reconstruction takes no options.detail (its points' summaries are always written:
            # track_document, certificate_summary states one for every certified item), so a
            # certified point stating none (null, review 60) claims an optimum without saying what
            # its proof covers
            if not isinstance(point.get("certificate"), dict):
                raise Invalid("returned", f"points/{index}/certificate is {point.get('certificate')!r:.40}, beside a "
                                          "certified point: its writer states the summary of its proof (scope, "
                                          "tolerance, root region, leaves) for every certified point")
        for index, (point, claim) in enumerate(zip(points, certificate["items"])):
            summary = point.get("certificate") if isinstance(point, dict) else None
            self._check_root_region(f"points/{index}", summary, claim, certificate, index)
            _check_scope_words(f"points/{index}", summary, claim, certificate["options"],
                               "every point in front of every camera")

    def checked_options(self, options: dict) -> dict:
        """The points' options (a triangulation's), and the cameras' tolerance (stated in the
        scope; the camera certificate hashes it as its rel_gap)."""
        checked = residual_claims.checked_options(TriangulationOptions, options)
        # the reconstruction's options cap the points' gaps too: at rel_gap 0.999 "certified"
        # would hold whatever a point costs
        for name, cap in (("rel_gap", camera_claim.MAX_REL_GAP), ("abs_gap", camera_claim.MAX_ABS_GAP)):
            if not checked[name] <= cap:
                raise Invalid("options", f"options/{name}: must be a finite number at most {cap!r}")
        if options.get("camera_rel_gap") is not None:
            checked["camera_rel_gap"] = number(options["camera_rel_gap"], "options/camera_rel_gap", "options")
            if not 0 <= checked["camera_rel_gap"] <= camera_claim.MAX_REL_GAP:
                raise Invalid("options", f"options/camera_rel_gap {checked['camera_rel_gap']!r} is beyond "
                                         f"{camera_claim.MAX_REL_GAP}: a camera would be certified whatever it costs")
        checked.update(hashed_options.checked(options))
        run_control.check(options)  # not hashed: refused when the solver would refuse it
        return checked

    def scope_statement(self, options: dict) -> dict:
        statement = residual_claims.scope("triangulation", TRACKS.domain, options)
        statement["kind"] = "reconstruction"
        statement["camera_rel_gap"] = options.get("camera_rel_gap")
        statement["statement"] = (
            "for each certified point, in the cameras returned (the certificate's data): " + statement["statement"]
            + "; for each certified camera, by the camera certificate (a resection document over the returned points, "
              "with the result's norm, max_residual, abs_gap and camera_rel_gap): no 3x4 camera in front of every point "
              "costs less than its lower_bound, and the camera returned costs cost, at most (1 + tolerance) lower_bound "
              "+ abs_gap, its tolerance the allowance for its fewer degrees of freedom than a 3x4 camera's (what they "
              "cost at the 99.9% level under Gaussian noise: a statistical allowance, not a bound) and camera_rel_gap; "
              "the summary's counts of what the pipeline was given and set aside (tracks, points_dropped, "
              "cameras_dropped, observations_removed) are checked against the stages and items that record them, not "
              "against the input, which this document does not hold; "
              "summary.calibration is checked to be about the K returned; a certified K (calibration.certified_K) "
              "is the one the calibration certificate beside it proves optimal for the projective reconstruction in "
              "that certificate's data (the pipeline's, from the same tracks, before the bundle adjustment: it images every "
              "observation it shares with the returned points within calibration_tie.allowed_px of where the returned "
              "cameras do, TIE_RATIO times their RMS error there, calibration_tie.largest_px at most, and fits those "
              "observations at a cost calibration_tie.shared_cost_px2 of at most calibration_tie.allowed_cost_px2, the "
              "returned cameras' plus 3 standard deviations of a chi-square over the coordinates shared (a certificate "
              "built with the principal point at the images' centre, or with one K elsewhere, is held to the returned "
              "reconstruction re-adjusted in that model instead (the principal point then one and free), "
              "calibration_tie.reference, and allowed what that model costs beyond the returned "
              "cameras, calibration_tie.model_cost_px2, and a quarter of it again, at most their cost: room that lets a "
              "certificate at the centre be re-posed with another focal length, measured from 0.96 to 1.05 times the "
              "returned one when the tracks' principal point is 36 px off, 1.00 to 1.15 times at 75 px, where the "
              "genuine centred certificate certifies 1.002 and 1.07 times: such a certified K is known to that "
              "tolerance only), and its cameras fit the result's other placed points, each "
              "triangulated in them, at calibration_tie.other_cost_px2, at most calibration_tie.other_allowed_cost_px2; so K is "
              "proven optimal for a reconstruction that close to the result's, not for the result's own); the critical motion behind `determined` is judged again from the cameras and "
              "certified points returned")
        return statement

    def check_result(self, result: dict, certificate: dict, verify: Callable[[dict], object],
                     hashed: tuple[str, ...] = ()) -> dict:
        """Every check of the result beyond its points' claims; returns what the report's scope
        adds (whether the labels are tied to the input the data state). ``hashed``: the options the
        certificate's problem_sha256 covers (verify._check_hashes found it so), which tell the
        form, and so what a document of that form states (hashed_options.states_...)."""
        from geocert.verify.reconstruction_stages import check_stages
        from geocert.verify import reconstruction_members
        from geocert.verify.reconstruction_members import check_members
        from geocert.verify.reconstruction_statuses import check_statuses

        registered, views = _check_cameras(result.get("cameras"), certificate.get("data", {}))
        _check_points(result.get("points"), certificate.get("data", {}).get("tracks"), views)
        # what a document of the current form states (hashed_options.states_records): absent, refused
        recorded = hashed_options.states_records(hashed)
        labels = _check_labels(result, certificate["data"], recorded)
        if any("searched" in camera for camera in registered):
            for camera in registered:
                if camera.get("searched") is not True and (camera.get("certified") is not False
                                                           or camera.get("lower_bound") is not None):
                    raise Invalid("returned", f"cameras/{camera.get('view')}: claims a bound (certified or a lower "
                                              "bound) but was not searched: no map of the camera certificate backs it")
            searched = [camera for camera in registered if camera.get("searched") is True]
        else:  # a result from before ``searched`` was stated: every registered camera has a map
            searched = registered
        certified = [k for k, camera in enumerate(searched) if camera.get("certified") is True]
        own = certificate["options"]
        rel_gap = float(own.get("camera_rel_gap", own.get("rel_gap")))  # as the pipeline passed it
        # Each registered camera's map from the returned points, built once for the checks below
        found = camera_sources(result.get("points") or [], registered)
        maps = maps_less_set_aside(found, registered)
        unchecked = _check_camera_figures(result, registered, rel_gap, maps,
                                          hashed_options.states_free_cameras(hashed))
        _check_unstarted(result, registered, [len(source) for source, _ in found])
        by_camera = {id(camera): entry for camera, entry in zip(registered, maps)}
        _check_camera_certificate(result, certificate, searched, certified, verify,
                                  [by_camera[id(camera)] for camera in searched])
        _check_summary(result, registered)
        _check_pipeline_counts(result, rel_gap, hashed_options.states_depth_reversal(hashed))
        _check_projective_counts(result)
        check_stages(result)  # (stage_checks: the stage records' shape and counts)
        check_members(result)  # the stages' words, switches and lists, typed and tied
        check_statuses(result)  # each stage's status against what it produced, and the job's stop
        _check_distortion(result, registered, own)
        _check_calibration(result, registered, verify, recorded)
        _check_adjusted_K(result, registered)
        scoped = {"labels": labels}
        records = [name for name in ("projective", "bundle_adjustment")
                   if isinstance(_stage(result, name).get("principal_point"), dict)]
        if records:  # the test's fits are the pipeline's: the calibration tie reads none of their figures
            scoped["principal_point_records"] = (
                f"unchecked: the principal-point records of the {' and '.join(records)} stage(s) state the "
                "pipeline's figures (observations, chi2, and K_free, the free fit's K, with the inside_middle_half "
                "read off it), which the verifier does not replay: the count is what both of the test's fits kept, "
                "and its free fit rejects its own outliers; their shape, their ranges (a chi2 at least 0, K_free a "
                "calibration matrix whose focal lengths lie within "
                f"{reconstruction_members.K_FREE_FOCAL[0]:g} to {reconstruction_members.K_FREE_FOCAL[1]:g} times the "
                "images' larger side) and their agreement with themselves are checked; where the adjustment's "
                "record says estimated, the middle half is judged from the returned cameras' principal points (the "
                "K each P fixes), not from K_free; and no room the verifier grants follows from them")
        posed = sum(1 for camera in registered if camera.get("R") is not None)
        if result["summary"].get("depth_reversal") is None and posed >= 2 \
                and not hashed_options.states_depth_reversal(hashed):
            scoped["depth_reversal"] = ("unchecked: the summary states no depth-reversal record, which a document of "
                                        "the earliest hash form (written before the check) lacks, so whether the "
                                        "depth-reversed twin of the rig fits as well (poses not determined) is not "
                                        "said")
        elif isinstance(result["summary"].get("depth_reversal"), dict) \
                and result["summary"]["depth_reversal"].get("checked") is not False:
            # what the record's checks cannot derive without the twin's adjustment run again (review 53)
            scoped["depth_reversal"] = (
                "taken as stated: the depth-reversal record's two costs, its noise, the twin's own counts and focal "
                "length, and mirror_capped (whether a twin's adjustment stopped at its iteration cap, its cost then "
                "an upper bound) need the twin's adjustment run again, which the verifier does not do; a rejection "
                "stated with mirror_capped false is read as one at the twin's minimum on the record's word. The "
                "record's angles, its returned rig's counts and focal length, and its verdict's agreement with its "
                "figures are checked; the verdict only ever adds doubt")
        if unchecked:
            scoped["camera_judgements"] = (
                f"unchecked for cameras {', '.join(map(str, unchecked))}: each is called not certified, not searched, "
                "as beaten by more than its tolerance by a free 3x4 camera found locally, which the document (of an "
                "earlier hash form, written before the free camera was stated) does not state; so that judgement is "
                "the result's word, and such a camera may be one a stop left unstarted (then the cameras stage's "
                "status and the job's stop are the result's word too)")
        calibration = result.get("calibration_certificate")
        claim = result["summary"].get("calibration")
        # a certified K claimed: _check_calibration verified the calibration certificate proving it
        proven = isinstance(calibration, dict) and (
            claim.get("certified") if isinstance(claim, dict)
            else _stage(result, "autocalibration").get("K") is not None) is True
        if proven:  # a certified claim checked beyond the points (a result may place none)
            scoped["result_claims_checked"] = 1
        if isinstance(calibration, dict) and not proven and not any(
                isinstance(p, dict) and p.get("point") is not None for p in result.get("points") or []):
            # No point placed: nothing ties the certificate to the result's tracks (calibration_tie.without_points),
            # so it is carried only as the proof of the certified K claimed beside it, never unverified; that
            # K claims nothing the points would judge (determined and the motion need certified points:
            # _judged_motion).
            raise Invalid("returned", "a calibration certificate is carried beside no placed point, and no "
                                      "certified K it proves is claimed: nothing ties it to the result")
        if isinstance(calibration, dict):  # carried (a certified K proven by it): tied to the result, once
            from geocert.verify.autocalibration import AutocalibrationVerification

            # the frame its claims are posed in, as its own report would name it (a reader of this
            # report sees whether an earlier writer's proofs name none)
            scoped["calibration_reference"] = AutocalibrationVerification.data_scope(
                calibration.get("data") or {}, calibration.get("options") or {}, calibration.get("items") or [])
            scoped["calibration_tie"] = calibration_tie.tie(result, _stage(result, "autocalibration"),
                                                            calibration.get("data") or {},
                                                            recorded)
        _check_warnings_once(result["summary"])  # last: a check reading one warning names its own
        return scoped


RECONSTRUCTION = ReconstructionItems()

"""The shape of a reconstruction's stage records, and the counts they state, checked against what
each count counts from (the verifier's, numpy free). A stage's figures (times, thresholds, RMS
values) are informational; its status, the records it nests and its counts are not: a status
"failed" beside the points it certified, a record held in another container than the pipeline's
(which a check reading records would pass over), or a count beyond its total would each tell a
reader something no stage did.

What each count counts from (the summary states the views sent and the tracks; each track holds
at most one observation a view, so tracks * views bounds every count of observations):

- projective: initial_pair_search.candidates <= views * (views - 1) / 2 (the pairs of views),
  principal_point.observations <= tracks * views;
- bundle_adjustment: observations_kept, principal_point.observations and
  radial_distortion.observations <= tracks * views;
- autocalibration: points_used <= tracks.

(The projective stage's own counts, and the structure and cameras stages' counts of the items,
are checked where they are read: verification._check_projective_counts, _check_summary.)"""

from __future__ import annotations

from typing import Any

from geocert.core.records import INTRINSIC_RANGES, NESTED_STAGE, WARNING, ByName, record
from geocert.core.geometry import is_number
from geocert.core.strict import Invalid, same

# The statuses a stage ends with (pipeline._stage, _timed, _skip, _cancel; "running" is never
# returned), and those of a stage that produced nothing (no point or camera it certifies).
STATUSES = ("done", "failed", "skipped", "cancelled", "time_limit", "not_run")
PRODUCED_NOTHING = ("failed", "skipped", "not_run")
STAGE_NAMES = ("matches", "projective", "autocalibration", "bundle_adjustment", "structure", "cameras")

# The records each stage nests, with their containers: "list" a list of objects, "object" an
# object, "pair" a list of two view numbers; each may be absent or null.
CONTAINERS = {
    "projective": {"focal_rounds": "list", "merged": "list", "initial_pair_search": "object",
                   "initial_pair": "pair", "radial_distortion": "object", "principal_point": "object"},
    "autocalibration": {"stages": "list", "intrinsics": "object", "rotation_noise_rad": "object"},
    "bundle_adjustment": {"starts": "list", "principal_point": "object", "radial_distortion": "object"},
}
NESTED = {("projective", "initial_pair_search"): {"pair": "object", "thresholds": "object"}}


# Each stage record's members, by its name, as the pipeline writes them (pipelines.reconstruction:
# pipeline, claims; the registrations' statistics, solvers.reconstruction.calibrated and
# projective; kinds.reconstruction's matches stage, from pipelines.reconstruction.features). The
# kind writes a stage through records.keep_declared (a member not declared here is not returned,
# so a genuine result never holds one), and the verifier refuses one (records.check);
# tests/verify/test_records.py runs the pipeline and checks it declares all it writes. A record
# nested in a stage is closed where listed; the maps keyed by data (registered_by, time_s) and the
# lists of merges and verified pairs are figures kept as written.
COMMON = ("name", "status", "reason", "elapsed_s", "cpu_s")
# The photos' matching figures (pipelines.reconstruction.features.tracks_from_images' statistics):
# the result's ``images`` and its matches stage.
IMAGES = record("images", "time_s", "stopped", "features_per_image", "candidate_pairs", "pairs_chosen_by",
                "verified_pairs", "tracks_built", "dropped_inconsistent", "dropped_short", "tracks_kept",
                "focal_prior_from_exif")
STAGE_RECORDS = ByName({
    "matches": record(*COMMON, *IMAGES.members),
    "projective": record(
        *COMMON, "method", "views", "tracks", "time_s", "registered_by", "resumed_from", "initial_pair",
        "initial_inliers", "bundle_adjustments", "ba_iterations", "focal_scale", "registered", "views_registered",
        "points", "observations", "observations_kept", "outliers_removed", "observations_of_dropped_tracks",
        "observations_of_unregistered_views", "rms_reprojection_px", "merged", "cancelled",
        adjustments=record("whole", "local"),
        initial_pair_search=record(
            "candidates", "reason",
            pair=record("views", "inliers", "shared", "median_angle_deg", "forward_motion"),
            thresholds=record("min_inliers", "min_median_angle_deg", "max_forward_motion", "relaxations")),
        focal_rounds=record("focal_px", "registration_focal_px", "k1", "registered", "resumed", "refined_focal_px",
                            "refined_k1", "again_from_a_new_pair", "fit_cost", "resumed_fit_cost", "radial_tested"),
        per_view=record("view", "registered_by", "tracks", "linked", "points"),
        radial_distortion=record("model", "estimated", "k1", "chi2", "threshold", "k1_tested", "against", "reason"),
        principal_point=record("estimated", "observations", "K_free", "chi2", "threshold", "inside_middle_half",
                               "reason")),
    "autocalibration": record(
        *COMMON, "method", "K", "linear_K", "certified", "determined", "critical_motion", "cameras_built_with_one_K",
        "points_used", "certificate_views", "certificate_tracks",
        intrinsics=INTRINSIC_RANGES, stages=NESTED_STAGE, motion_warnings=WARNING,
        rotation_noise_rad=record("estimated", "diac_family", "plane_family")),
    "bundle_adjustment": record(
        *COMMON, "K", "model", "started_from", "observations_kept", "rms_px_before", "rms_px_after",
        starts=record("from", "rms_px_before", "rms_px_after_8_iterations", "fit_cost", "observations_fitting",
                      "same_rig_as"),
        principal_point=record("estimated", "observations", "K_free", "chi2", "threshold", "inside_middle_half",
                               "reason"),
        principal_point_per_view=record("estimated", "observations", "parameters_added", "chi2", "threshold",
                                        "inside_middle_half", "spread_px", "sd_px", "max_sd_px", "precise",
                                        "reason"),
        focal_per_view=record("estimated", "views", "z", "z_threshold", "observations", "parameters_added", "chi2",
                              "threshold", "focal_sd", "max_focal_sd", "sd_px", "max_sd_px", "precise", "reason"),
        # K known: the radial term's test (pipeline._fixed_radial_test)
        radial_distortion=record("model", "estimated", "k1", "k1_tested", "chi2", "threshold", "observations",
                                 "residual_dof", "reason")),
    "structure": record(*COMMON, "tracks", "points", "certified", "points_dropped", "observations_removed",
                        "tracks_not_started"),
    "cameras": record(*COMMON, "cameras", "certified", "searched", "claim", "degrees_of_freedom",
                      "cameras_not_started"),
})


# The members each stage's writer (pipelines.reconstruction.pipeline, claims.judge_motion) writes on
# every path that reaches them, so that a record leaving one out is not its writer's (a deleted
# critical-motion warning read as "none"; a cameras stage without ``searched`` read as an earlier
# form's). Every stage starts as pipeline._stage (name, status, elapsed_s, reason). A stage that
# ran (status "done": _timed, left without a failure, a stop or a skip) states its CPU time and
# what its every path writes: the projective stage's figures are its registration path's (the
# incremental one's counts where its method says it ran); the adjustment's trials on every start
# but the calibrated path's (K known: one adjustment), and its principal point's test where the
# options and image sizes ask for it; the cameras stage's judgement figures (searched,
# degrees_of_freedom) where the cameras state theirs (a result from before they were stated,
# reconstruction.CAMERA_JUDGEMENT, has the stage's neither). The motion's judgement
# (critical_motion, motion_warnings, rotation_noise_rad, determined) is on the autocalibration
# stage, whatever its status, wherever the verifier judges the motion again (3 registered cameras:
# reconstruction._judged_motion, as claims.judge_motion). Every stored format-2 document
# (tests/data/certificates) states all of these; members a path writes only sometimes (the
# registration's initial pair, its radial term) or an earlier form did not
# (cameras_built_with_one_K) are not asked for.
STARTED = ("name", "status", "reason", "elapsed_s")
WRITTEN_WHEN_DONE = {
    "projective": ("cpu_s",),
    "autocalibration": ("cpu_s", "method", "stages", "certified", "intrinsics", "points_used", "K"),
    "bundle_adjustment": ("cpu_s", "started_from", "model", "rms_px_before", "rms_px_after", "K", "observations_kept"),
    "structure": ("cpu_s", "tracks", "points", "points_dropped", "observations_removed", "certified"),
    "cameras": ("cpu_s", "cameras", "certified", "claim"),
}
# the incremental registration's counts (pipeline._incremental: every run that registered two views)
INCREMENTAL_WRITTEN = ("focal_rounds", "views_registered", "observations", "observations_kept", "outliers_removed",
                       "observations_of_dropped_tracks", "observations_of_unregistered_views")
MOTION_JUDGED = ("critical_motion", "motion_warnings", "rotation_noise_rad", "determined")
CAMERAS_JUDGED = ("searched", "degrees_of_freedom")
MOTION_CAMERAS = 3


def _principal_point_tested(options: dict, cameras: list) -> bool:
    """Whether the adjustment's writer tests the principal point (pipeline: the simple model, the
    principal point "auto" or "per_view", one image size: here every view's, a narrower test)."""
    sizes = {str(camera.get("image_size")) for camera in cameras if isinstance(camera, dict)}
    return options.get("camera_model") == "simple" and options.get("principal_point") in ("auto", "per_view") \
        and len(sizes) == 1


def _written(stage: dict, cameras: list, options: dict) -> tuple[str, ...]:
    """The members the stage's writer has written (the note above)."""
    name, done = stage["name"], stage.get("status") == "done"
    names = STARTED + (WRITTEN_WHEN_DONE.get(name, ()) if done else ())
    registered = sum(1 for camera in cameras if isinstance(camera, dict) and camera.get("registered") is True)
    if name == "autocalibration" and registered >= MOTION_CAMERAS:
        names += MOTION_JUDGED
    if name == "projective" and done and str(stage.get("method")).startswith("incremental"):
        names += INCREMENTAL_WRITTEN
    if name == "bundle_adjustment" and done and stage.get("started_from") != "calibrated":
        names += ("starts",) + (("principal_point",) if _principal_point_tested(options, cameras) else ())
    if name == "cameras" and done:
        names += tuple(member for member in CAMERAS_JUDGED
                       if any(isinstance(camera, dict) and member in camera for camera in cameras))
    return names


def _check_written(stage: dict, cameras: list, options: dict) -> None:
    written = _written(stage, cameras, options)
    missing = [member for member in written if member not in stage]
    if missing:
        raise Invalid("returned", f"{_where(stage['name'], missing[0])} is left out: the stage's writer states it on "
                                  f"a stage {stage.get('status')!r:.20} (null where it has none), so a record "
                                  "without it is not its writer's")
    _check_written_content(stage, written)


# What a done stage's writer writes on its path, not only that it writes it (present but null or
# emptied, each verified: review 30): the adjustment's figures (pipeline: stage.update after
# adjust_best, or the calibrated path's one adjustment: each a number or a K), its trials (one a
# start, adjust_best) and its principal point's record where the options ask for the test; the
# incremental registration's focal rounds (a list, pipeline._incremental) and its RMS; the motion's
# judgement: a critical motion named beside its warning (claims.judge_motion: judged["motion_warnings"]
# holds it, the stage's reason says it).
DONE_NOT_NULL = {
    "bundle_adjustment": ("started_from", "model", "rms_px_before", "rms_px_after", "K", "observations_kept"),
    "autocalibration": ("method", "stages", "certified", "intrinsics", "points_used"),
    "structure": ("tracks", "points", "points_dropped", "observations_removed", "certified"),
    "cameras": ("cameras", "certified", "claim"),
}
INCREMENTAL_NOT_NULL = ("focal_rounds", "views_registered", "observations", "observations_kept", "rms_reprojection_px")


def _check_written_content(stage: dict, written: tuple) -> None:
    name, done = stage["name"], stage.get("status") == "done"
    if done:
        must = DONE_NOT_NULL.get(name, ())
        if name == "projective" and "focal_rounds" in written:  # the incremental path (INCREMENTAL_WRITTEN)
            must = INCREMENTAL_NOT_NULL
        nulled = [member for member in must if member in stage and stage[member] is None]
        if nulled:
            raise Invalid("returned", f"{_where(name, nulled[0])} is null on a stage done: its writer states it on "
                                      "that path")
        if name == "bundle_adjustment" and "starts" in written and not stage.get("starts"):
            raise Invalid("returned", f"{_where(name, 'starts')} is {stage.get('starts')!r:.20}: the adjustment "
                                      "states a trial for every start it had (adjust_best), at least one")
        if name == "bundle_adjustment" and "principal_point" in written and not isinstance(stage["principal_point"],
                                                                                            dict):
            raise Invalid("returned", f"{_where(name, 'principal_point')} is null: the options and the views' one "
                                      "image size ask for the principal point's test, and its writer states its record")
    if name == "autocalibration":
        _check_motion_judgement(stage)
    if name == "autocalibration" and stage.get("critical_motion") is not None and "critical_motion" in written:
        critical, warnings = stage["critical_motion"], stage.get("motion_warnings")
        if not (isinstance(warnings, list) and any(isinstance(w, dict) and w.get("code") == critical
                                                   for w in warnings)):
            raise Invalid("returned", f"{_where(name, 'motion_warnings')} holds no {critical!r:.40} warning beside "
                                      "the critical_motion stated: the motion's judgement writes both")
        if not (isinstance(stage.get("reason"), str) and stage["reason"]):
            raise Invalid("returned", f"{_where(name, 'reason')} is {stage.get('reason')!r:.20} beside the critical "
                                      "motion stated: the motion's judgement says it in the stage's reason")


# The motion's judgement as its writer writes it (claims.judge_motion, motion_claim.judge), wherever
# stated: ``determined`` true or false, ``rotation_noise_rad`` an object of its three figures (each
# a number >= 0, FIGURES; the estimate and the plane's family null where the residuals give no
# noise, the DIAC's family never: at least motion_claim's default). Review 31: a string, true, -1
# or a list in its place, and ``determined`` null, verified.
NOISE_FIGURES = ("estimated", "diac_family", "plane_family")


def _check_motion_judgement(stage: dict) -> None:
    if "determined" in stage and not isinstance(stage["determined"], bool):
        raise Invalid("returned", f"{_where('autocalibration', 'determined')} must be true or false (the motion's "
                                  f"judgement writes one), got {stage['determined']!r:.40}")
    if "rotation_noise_rad" in stage:
        noise = stage["rotation_noise_rad"]
        if not (isinstance(noise, dict) and all(member in noise for member in NOISE_FIGURES)
                and noise["diac_family"] is not None):
            raise Invalid("returned", f"{_where('autocalibration', 'rotation_noise_rad')} must be an object stating "
                                      f"{', '.join(NOISE_FIGURES)} (diac_family a number), as the motion's judgement "
                                      f"writes it, got {noise!r:.80}")


# The stages' figures the verifier reads nowhere else: informational (they describe the run, a
# check reads none of them: docs/certificate.md), but each of its type, so that no figure states
# what no run produces: "count" a whole number >= 0, "measure" a number >= 0 (a time, an RMS, a
# chi-square, a threshold, an angle), "number" any finite number (a distortion term, a motion
# ratio), "calibration" a calibration matrix (3x3, upper triangular, bottom row [0, 0, 1], positive
# focal lengths), and each at most MAX_FIGURE in magnitude; null where the stage has none. Keyed
# (stage, path), a path's "*" any entry of a list. (A stage's K, and the summary's times, are
# tied to what the verifier reads: _check_summary_times and verification._stage_calibration.)
MAX_FIGURE = 1e12
FIGURES = {
    "projective": {
        "views": "count", "tracks": "count", "initial_inliers": "count", "bundle_adjustments": "count",
        "ba_iterations": "count", "focal_scale": "measure", "views_registered": "count", "points": "count",
        "observations": "count", "observations_kept": "count", "outliers_removed": "count",
        "observations_of_dropped_tracks": "count", "observations_of_unregistered_views": "count",
        "rms_reprojection_px": "measure", "adjustments/whole": "count", "adjustments/local": "count",
        "focal_rounds/*/focal_px": "measure", "focal_rounds/*/registration_focal_px": "measure",
        "focal_rounds/*/k1": "number", "focal_rounds/*/refined_focal_px": "measure",
        "focal_rounds/*/refined_k1": "number", "focal_rounds/*/fit_cost": "measure",
        "focal_rounds/*/resumed_fit_cost": "measure", "focal_rounds/*/registered": "count",
        "initial_pair_search/candidates": "count", "initial_pair_search/pair/inliers": "count",
        "initial_pair_search/pair/shared": "count", "initial_pair_search/pair/median_angle_deg": "measure",
        "initial_pair_search/pair/forward_motion": "number",
        "initial_pair_search/thresholds/min_inliers": "count",
        "initial_pair_search/thresholds/min_median_angle_deg": "measure",
        "initial_pair_search/thresholds/max_forward_motion": "number",
        "initial_pair_search/thresholds/relaxations": "count",
        "radial_distortion/k1": "number", "radial_distortion/chi2": "number", "radial_distortion/threshold": "measure",
        "radial_distortion/k1_tested": "number", "principal_point/observations": "count",
        "principal_point/K_free": "calibration", "principal_point/chi2": "number",
        "principal_point/threshold": "measure"},
    "autocalibration": {
        "K": "calibration", "linear_K": "calibration", "points_used": "count",
        "rotation_noise_rad/estimated": "measure", "rotation_noise_rad/diac_family": "measure",
        "rotation_noise_rad/plane_family": "measure", "stages/*/nodes": "count", "stages/*/elapsed_s": "measure"},
    "bundle_adjustment": {
        "K": "calibration", "observations_kept": "count", "rms_px_before": "measure", "rms_px_after": "measure",
        "starts/*/rms_px_before": "measure", "starts/*/rms_px_after_8_iterations": "measure",
        "starts/*/fit_cost": "measure", "starts/*/observations_fitting": "count",
        "principal_point/observations": "count", "principal_point/K_free": "calibration",
        "principal_point/chi2": "number", "principal_point/threshold": "measure",
        "principal_point_per_view/observations": "count", "principal_point_per_view/parameters_added": "count",
        "principal_point_per_view/chi2": "number", "principal_point_per_view/threshold": "measure",
        "principal_point_per_view/spread_px/*": "measure", "principal_point_per_view/sd_px/*": "measure",
        "principal_point_per_view/max_sd_px": "measure", "focal_per_view/z/*": "number",
        "focal_per_view/z_threshold": "measure", "focal_per_view/observations": "count",
        "focal_per_view/parameters_added": "count", "focal_per_view/chi2": "number",
        "focal_per_view/threshold": "measure", "focal_per_view/focal_sd/*": "measure",
        "focal_per_view/max_focal_sd": "measure", "focal_per_view/sd_px/*": "measure",
        "focal_per_view/max_sd_px": "measure", "radial_distortion/k1": "number",
        "radial_distortion/k1_tested": "number", "radial_distortion/chi2": "number",
        "radial_distortion/threshold": "measure", "radial_distortion/observations": "count",
        "radial_distortion/residual_dof": "count"},
}
COMMON_FIGURES = {"elapsed_s": "measure", "cpu_s": "measure"}


def _values(record: Any, path: list[str], where: str):
    """(where, value) of each value at ``path`` in ``record`` ("*": each entry of a list)."""
    if not path:
        yield where, record
        return
    head, rest = path[0], path[1:]
    if head == "*":
        for index, entry in enumerate(record if isinstance(record, list) else []):
            yield from _values(entry, rest, f"{where}/{index}")
    elif isinstance(record, dict) and head in record:
        yield from _values(record[head], rest, f"{where}/{head}")


def _figure(value: Any, where: str, kind: str) -> None:
    if value is None:
        return
    if kind == "calibration":
        K = value
        rows = isinstance(K, list) and len(K) == 3 and all(isinstance(r, list) and len(r) == 3 for r in K)
        entries = [x for r in K for x in r] if rows else []
        if not (rows and all(is_number(x) and abs(x) <= MAX_FIGURE for x in entries)
                and K[1][0] == K[2][0] == K[2][1] == 0 and K[2][2] == 1 and K[0][0] > 0 and K[1][1] > 0):
            raise Invalid("returned", f"{where} must be null or a calibration matrix (3x3, upper triangular, bottom row "
                                      f"[0, 0, 1], positive focal lengths, entries at most {MAX_FIGURE:g}), got "
                                      f"{value!r:.80}")
        return
    ok = is_number(value) and abs(value) <= MAX_FIGURE and (kind == "number" or value >= 0) \
        and (kind != "count" or type(value) is int)
    if not ok:
        what = {"count": "a count (an integer >= 0)", "measure": "a number >= 0", "number": "a finite number"}[kind]
        raise Invalid("returned", f"{where} must be null or {what} at most {MAX_FIGURE:g} (informational: it describes "
                                  f"the run), got {value!r:.40}")


def _check_figures(stage: dict) -> None:
    """A stage's figures of their types (FIGURES)."""
    name = stage["name"]
    for path, kind in {**COMMON_FIGURES, **FIGURES.get(name, {})}.items():
        for where, value in _values(stage, path.split("/"), f"stages/{name}"):
            _figure(value, where, kind)


# The summary's times restate the stages' own (claims.summarise; kinds.reconstruction puts the
# matches stage's first): time_s each stage's elapsed_s (every stage states one, pipeline._stage),
# cpu_s each stage's cpu_s, 0.0 for a stage that states none (one not timed: skipped, cancelled,
# not run). Each an object with an entry for every stage and no other, so that none is left out,
# added, or stated of another type (review 31: a string, null or {} verified, the tie read only
# where the object named the stage). Both stored reconstructions' forms state them so.
SUMMARY_TIMES = (("time_s", "elapsed_s", None), ("cpu_s", "cpu_s", 0.0))


def _check_summary_times(stages: list[dict], summary: dict) -> None:
    names = [stage["name"] for stage in stages]
    for total, own, unstated in SUMMARY_TIMES:
        stated = summary.get(total)
        if not (isinstance(stated, dict) and set(stated) == set(names)):
            raise Invalid("returned", f"summary/{total} must be an object with an entry for each stage "
                                      f"({', '.join(names)}) and no other, got {stated!r:.120}")
        for stage in stages:
            name, value = stage["name"], stated[stage["name"]]
            expected = stage.get(own, unstated)
            if not (is_number(value) and 0 <= value <= MAX_FIGURE) or not same(value, expected):
                raise Invalid("returned", f"summary/{total}/{name} is {value!r:.40}, the stage's {own} "
                                          f"{expected!r:.40}: the summary restates the stage's own")


def _where(stage: str, path: str) -> str:
    return f"stages/{stage}/{path}"


def _container(value: Any, kind: str, where: str) -> None:
    if value is None:
        return
    if kind == "object" and not isinstance(value, dict):
        raise Invalid("returned", f"{where} must be an object, got {type(value).__name__}")
    if kind == "list" and not (isinstance(value, list) and all(isinstance(entry, dict) for entry in value)):
        raise Invalid("returned", f"{where} must be a list of objects")
    if kind == "pair" and not (isinstance(value, list) and len(value) == 2):
        raise Invalid("returned", f"{where} must be a pair of views, got {value!r:.60}")


def _bounded(value: Any, where: str, total: int, counts_from: str) -> None:
    if not (isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= total):
        raise Invalid("returned", f"{where} is {value!r:.40}: a count of at most {total} ({counts_from})")


def check_stages(result: dict) -> None:
    """Every stage record: an object with a known name (once each) and status, its nested records
    in the pipeline's containers, its counts within their totals, and a structure or cameras stage
    that certified an item not saying it produced nothing."""
    stages, summary = result.get("stages"), result.get("summary") or {}
    if not (isinstance(stages, list) and all(isinstance(stage, dict) for stage in stages)):
        raise Invalid("returned", "stages must be a list of objects")
    names = [stage.get("name") for stage in stages]
    if any(name not in STAGE_NAMES for name in names) or len(set(names)) != len(names):
        raise Invalid("returned", f"stages are named {names!r:.120}: each once, of {', '.join(STAGE_NAMES)}")
    views, tracks = summary.get("views"), summary.get("tracks")
    if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in (views, tracks)):
        raise Invalid("returned", "summary/views and summary/tracks must be counts")
    certified = {"structure": any(p.get("certified") is True for p in result.get("points") or [] if isinstance(p, dict)),
                 "cameras": any(c.get("certified") is True for c in result.get("cameras") or [] if isinstance(c, dict))}
    cameras = result.get("cameras") if isinstance(result.get("cameras"), list) else []
    options = (result.get("certificate") or {}).get("options") if isinstance(result.get("certificate"), dict) else None
    options = options if isinstance(options, dict) else {}  # (hashed: a forged option is refused with its hash)
    for stage in stages:
        name = stage["name"]
        if stage.get("status") not in STATUSES:
            raise Invalid("returned", f"{_where(name, 'status')} is {stage.get('status')!r:.40}: one of "
                                      f"{', '.join(STATUSES)}")
        if certified.get(name) and stage["status"] in PRODUCED_NOTHING:
            raise Invalid("returned", f"{_where(name, 'status')} is {stage['status']!r} beside the items it "
                                      "certified")
        for member, kind in CONTAINERS.get(name, {}).items():
            _container(stage.get(member), kind, _where(name, member))
            for inner, inner_kind in NESTED.get((name, member), {}).items():
                if isinstance(stage.get(member), dict):
                    _container(stage[member].get(inner), inner_kind, _where(name, f"{member}/{inner}"))
        _check_figures(stage)
        _check_written(stage, cameras, options)
    _check_counts({stage["name"]: stage for stage in stages}, views, tracks)
    _check_summary_times(stages, summary)


def _check_counts(stages: dict, views: int, tracks: int) -> None:
    observations = tracks * views
    search = (stages.get("projective") or {}).get("initial_pair_search")
    if isinstance(search, dict) and "candidates" in search:
        _bounded(search["candidates"], _where("projective", "initial_pair_search/candidates"), views * (views - 1) // 2,
                 f"the pairs of the {views} views")
    registration = (stages.get("projective") or {}).get("principal_point")
    if isinstance(registration, dict) and "observations" in registration:
        _bounded(registration["observations"], _where("projective", "principal_point/observations"), observations,
                 f"{tracks} tracks, one observation a view of {views}")
    adjustment = stages.get("bundle_adjustment") or {}
    if "observations_kept" in adjustment:
        _bounded(adjustment["observations_kept"], _where("bundle_adjustment", "observations_kept"), observations,
                 f"{tracks} tracks, one observation a view of {views}")
    for name in ("principal_point", "radial_distortion"):
        test = adjustment.get(name)
        if isinstance(test, dict) and "observations" in test:
            _bounded(test["observations"], _where("bundle_adjustment", f"{name}/observations"), observations,
                     f"{tracks} tracks, one observation a view of {views}")
    calibration = stages.get("autocalibration") or {}
    if "points_used" in calibration:
        _bounded(calibration["points_used"], _where("autocalibration", "points_used"), tracks, "the tracks")


# A reconstruction's summary (pipelines.reconstruction.claims.summarise) and its records; its
# depth-reversal record is closed by its own check (depth_reversal_claim.MEMBERS).
RECONSTRUCTION_SUMMARY = record(
    "views", "views_registered", "tracks", "points", "observations", "rms_reprojection_px", "points_certified",
    "points_certified_fraction", "cameras_certified", "cameras_certified_fraction", "camera_claim",
    "critical_motion", "cameras_dropped", "observations_removed", "points_dropped",
    "autocalibration_certified", "autocalibration_determined", "doubtful", "depth_reversal", "poses_determined",
    time_s=record(*STAGE_NAMES), cpu_s=record(*STAGE_NAMES),
    calibration=record("K", "model", "source", "certified_K", "certified", "returned_is_certified", "on_range_edge",
                       "determined",
                       difference=record("focal_percent", "aspect", "skew_px", "principal_point_px")),
    distortion=record("model", "k1", "focal_px", "estimated_by", "certified", "test", "statement"),
    warnings=WARNING)

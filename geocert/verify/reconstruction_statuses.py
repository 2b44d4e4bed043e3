"""A reconstruction's stage statuses tied to what each stage produced, and the job's stop (its
``stats.statuses``) tied to the stages, points and cameras that carry it (the verifier's, numpy
free). A status is a word about the run; each word is one the pipeline writes beside what the
result holds (pipelines.reconstruction.pipeline: _timed, _skip, _cancel, _structure;
kinds.reconstruction: the matches stage and _stopped_by_clock), so that no status tells a reader
the run did less, or more, than its products show.

How the pipeline sets them (every stage starts "not_run", which no finished run keeps):

- a stage that ran ends "done"; "failed" (projective: fewer than 2 views registered;
  autocalibration: no upgrade found) and "skipped" (an option, K known, a critical motion, or
  an earlier stage that failed) say it produced nothing the later stages use, but that
  autocalibration "failed" or "skipped" may leave the linear estimate to the adjustment;
- a cancel (``Cancelled``) marks the stage it reached and every later one not yet run
  "cancelled", the earlier ones keeping theirs (K known: autocalibration "skipped" before it);
  the job's clock in all is seen as a cancel, and _stopped_by_clock then restates every
  "cancelled" as "time_limit" (the stages, points and cameras alike) and warns "time_limit"
  first in the summary;
- the structure and cameras stages have a clock of their own (structure_time_limit_s): "time_limit"
  with the tracks or cameras it did not start counted (tracks_not_started, cameras_not_started),
  or, the cameras stage reached past it, every camera not started; a cancel there likewise says
  "cancelled" with those counts; the matches stage's own clock (features.time_limit_s) says
  "time_limit" and the run goes on with the tracks matched.

So the result's points are the structure stage's, and there only when every stage before it ran
to its end (projective "done"; autocalibration "done", "failed" or "skipped"; the adjustment
"done" or "skipped"; the matches "done" or "time_limit"); the item's stop (the job's statistics)
is "cancelled" exactly when a stage is, and "time_limit" exactly when the summary's first warning
says the job's clock passed."""

from __future__ import annotations

from typing import Any

from geocert.core.strict import Invalid

STOPS = ("cancelled", "time_limit")
# What each stage ends with where the result returns points (the structure stage ran).
WITH_POINTS = {"matches": ("done", "time_limit"), "projective": ("done",),
               "autocalibration": ("done", "failed", "skipped"), "bundle_adjustment": ("done", "skipped"),
               "structure": ("done",) + STOPS}
PIPELINE = ("projective", "autocalibration", "bundle_adjustment", "structure", "cameras")
# An adjustment's own figures: a stage stating one ran the adjustment (done, or stopped in it).
ADJUSTED = ("K", "model", "rms_px_after", "observations_kept", "starts", "principal_point")
CALIBRATED = ("K", "certificate_views", "certificate_tracks")


def _refuse(where: str, why: str) -> None:
    raise Invalid("returned", f"stages/{where}: {why}")


def check_statuses(result: dict) -> None:
    """Each stage's status one the pipeline writes beside what the result holds, and the job's
    stop the one its stages, points and cameras carry. (check_stages has read the stages' shape.)"""
    stages = result["stages"]
    names = [stage["name"] for stage in stages]
    expected = (["matches"] if "matches" in names else []) + list(PIPELINE)
    if names != expected:
        raise Invalid("returned", f"stages are {names!r:.120}: every stage of the pipeline, once, in its order "
                                  f"({', '.join(expected)})")
    by_name = {stage["name"]: stage for stage in stages}
    status = {name: stage["status"] for name, stage in by_name.items()}
    points = [p for p in result.get("points") or [] if isinstance(p, dict)]
    cameras = [c for c in result.get("cameras") or [] if isinstance(c, dict)]
    registered = [c for c in cameras if c.get("registered") is True]
    judged = [c for c in registered if c.get("status") != "not_run"]
    if points:
        for name, allowed in WITH_POINTS.items():
            if name in status and status[name] not in allowed:
                _refuse(f"{name}/status", f"{status[name]!r} beside the points the structure stage returned (it "
                                          f"ran only after this stage ended {' or '.join(allowed)})")
    _check_sequence(names, status)
    _check_cameras_word(result, status)
    _check_products(by_name, status, points, registered, judged)
    _check_job_stop(result, status, points, cameras)


def _check_sequence(names: list[str], status: dict) -> None:
    """What follows a stop or a failure: a cancel (or the job's clock) ends every later stage with
    the same word (K known: autocalibration skipped before it); a stage that failed leaves the
    later ones skipped (projective, matches); the structure stage stopped leaves the cameras
    stage stopped or skipped."""
    for k, name in enumerate(names):
        word, later = status[name], names[k + 1:]
        if name == "structure" and word in STOPS:
            allowed = ("cancelled",) if word == "cancelled" else STOPS + ("skipped",)
        elif name != "cameras" and word in STOPS and not (name == "matches" and word == "time_limit"):
            allowed = (word,)  # (the matches stage's own clock: the run goes on)
        elif word == "failed" and name in ("matches", "projective"):
            allowed = ("skipped",)
        else:
            continue
        for other in later:
            # K known, autocalibration is skipped before the registration starts
            before = name == "projective" and word in STOPS and other == "autocalibration" and status[other] == "skipped"
            if status[other] not in allowed and not before:
                _refuse(f"{other}/status", f"{status[other]!r} after the {name} stage ended {word!r} (the pipeline "
                                           f"ends every later stage {' or '.join(allowed)})")


def _check_cameras_word(result: dict, status: dict) -> None:
    """The cameras stage's word is one the pipeline writes for it (pipeline._structure, _skip):
    never "failed"; "not_run" in no run whose structure stage ended done (the cameras stage is
    entered then, and ends done, stopped or skipped); "skipped" beside a structure stage that ran
    (done, or stopped by its own clock) only when options.resect_cameras is false (an earlier
    stage that failed skips the structure stage too); and the adjustment "skipped" beside a
    structure stage that was entered (not skipped) only when options.bundle_adjustment is false (a
    stage that failed before it skips the structure stage too). The options are read from the
    options' echo, absent read as its default, true (as the report's scope reads it: an earlier
    form's hash does not cover its absence); problem_sha256 covers them (hashed_options.CLAIM_OPTIONS),
    and the report's scope states them for a document of an earlier form, whose hash does not."""
    word, structure = status["cameras"], status["structure"]
    if word == "failed":
        _refuse("cameras/status", "'failed': the pipeline never calls the cameras stage failed (it is done, stopped, "
                                  "or skipped)")
    if word == "not_run" and structure == "done":
        _refuse("cameras/status", "'not_run' after the structure stage ended done: the cameras stage was entered "
                                  "(no finished run keeps not_run)")
    options = (result.get("certificate") or {}).get("options")
    if not isinstance(options, dict):
        return  # no options' echo to read them from (check_result reads a result beside its certificate)
    if word == "skipped" and structure in ("done",) + STOPS and options.get("resect_cameras") is not False:
        _refuse("cameras/status", f"'skipped' after the structure stage ended {structure!r}, with "
                                  "options.resect_cameras true (or absent): the pipeline skips the cameras stage only "
                                  "when that option is false or an earlier stage failed")
    if status["bundle_adjustment"] == "skipped" and structure not in ("skipped", "not_run") \
            and options.get("bundle_adjustment") is not False:
        _refuse("bundle_adjustment/status", f"'skipped' before a structure stage that ended {structure!r}, with "
                                            "options.bundle_adjustment true (or absent): the pipeline skips the "
                                            "adjustment only when that option is false or an earlier stage failed "
                                            "(which skips the structure stage too)")


def _stated(stage: dict, members: tuple) -> list[str]:
    return [name for name in members if stage.get(name) is not None]


def _check_products(by_name: dict, status: dict, points: list, registered: list, judged: list) -> None:
    """Each stage's status against what it produced."""
    if registered and status["projective"] in ("skipped", "not_run"):
        _refuse("projective/status", f"{status['projective']!r} beside {len(registered)} registered cameras (the "
                                     "registration placed them)")
    if status["projective"] == "failed" and len(registered) >= 2:
        _refuse("projective/status", f"'failed' (fewer than 2 views registered) beside {len(registered)} registered "
                                     "cameras")
    calibration = by_name["autocalibration"]
    if status["autocalibration"] != "done" and (_stated(calibration, CALIBRATED)
                                                or calibration.get("certified") is True):
        _refuse("autocalibration/status", f"{status['autocalibration']!r} beside the upgrade it states "
                                          f"({', '.join(_stated(calibration, CALIBRATED)) or 'certified'}): a stage "
                                          "that found a K ends done")
    if status["autocalibration"] == "done" and calibration.get("K") is None:
        _refuse("autocalibration/status", "'done' with no K: a stage that found no upgrade failed or was skipped")
    adjustment = by_name["bundle_adjustment"]
    if status["bundle_adjustment"] not in ("done",) + STOPS and _stated(adjustment, ADJUSTED):
        _refuse("bundle_adjustment/status", f"{status['bundle_adjustment']!r} beside the adjustment's figures "
                                            f"({', '.join(_stated(adjustment, ADJUSTED))}): a stage that adjusted "
                                            "ends done (or stopped)")
    if status["bundle_adjustment"] == "done" and (adjustment.get("K") is None or adjustment.get("started_from") is None):
        _refuse("bundle_adjustment/status", "'done' with no K or started_from: an adjustment states what it "
                                            "started from and the K it found")
    if status["bundle_adjustment"] in ("failed", "not_run") and adjustment.get("started_from") is not None:
        _refuse("bundle_adjustment/status", f"{status['bundle_adjustment']!r} beside a start it took "
                                            "(started_from)")
    structure = by_name["structure"]
    not_started = structure.get("tracks_not_started")
    if status["structure"] == "done" and not_started is not None:
        _refuse("structure/tracks_not_started", f"{not_started!r:.20} in a stage that ended done (it counts the "
                                                "tracks a stop left unstarted)")
    if status["structure"] in STOPS and points and not (type(not_started) is int and not_started >= 1):
        _refuse("structure/status", f"{status['structure']!r} beside the points it returned, and no track it did not "
                                    f"start (tracks_not_started {not_started!r:.20}): a stage that finished every "
                                    "track ended done")
    _check_cameras_stage(by_name["cameras"], registered, judged)


def _check_cameras_stage(stage: dict, registered: list, judged: list) -> None:
    """The cameras stage: "done" only when it judged every registered camera and left none
    unstarted; stopped only when it left cameras unstarted (each called so, their count
    cameras_not_started) or never started one (then every camera not judged, and
    cameras_not_started, when stated, all of them); skipped (or not run) only when it judged none."""
    word, count = stage["status"], stage.get("cameras_not_started")
    unstarted = [c for c in judged if c.get("status") in STOPS and c.get("searched", True) is not True]
    if word == "done" and count is not None:
        _refuse("cameras/cameras_not_started", f"{count!r:.20} in a stage that ended done")
    if word in STOPS and judged and not unstarted:
        _refuse("cameras/status", f"{word!r}, and every camera it took up finished (none was left unstarted): a "
                                  "stage that judged every camera ended done")
    if word in STOPS and not judged and count is not None and count != len(registered):
        _refuse("cameras/cameras_not_started", f"{count!r:.20}, and the stage started no camera of the "
                                               f"{len(registered)} registered")
    if word not in ("done",) + STOPS:
        if judged:
            _refuse("cameras/status", f"{word!r} beside the cameras it judged (cameras/{judged[0]['view']})")
        stated = [name for name in ("claim", "degrees_of_freedom", "cameras_not_started") if stage.get(name) is not None]
        if stated:
            _refuse("cameras/status", f"{word!r} beside its {stated[0]} (a stage that did not run states none)")


def _check_job_stop(result: dict, status: dict, points: list, cameras: list) -> None:
    """The job's stop (stats.statuses: the one item's outcome) is the one its parts carry: a cancel
    exactly when a stage says "cancelled" (pipeline.reconstruct: out.cancelled), the job's clock
    exactly when the summary's warnings say so (kinds.reconstruction._stopped_by_clock, which also
    restates every "cancelled" stage, point and camera as "time_limit"); only those stop the
    registration, the upgrade and the adjustment, which have no clock of their own; a point or
    camera stopped by a cancel is in a cancelled job (but for a point of a run whose cameras stage
    was skipped: the cancel then came after every track started, and no later stage saw it)."""
    stats = result.get("stats")
    statuses = stats.get("statuses") if isinstance(stats, dict) else None
    if not isinstance(statuses, dict):
        return  # a result without the job's statistics states no stop (check_job asks for them)
    stop = next((word for word in STOPS if statuses == {word: 1}), None)
    cancelled = [name for name, word in status.items() if word == "cancelled"]
    if bool(cancelled) != (stop == "cancelled"):
        raise Invalid("returned", f"stats/statuses is {statuses!r:.60}, and "
                      + (f"the {cancelled[0]} stage says it was cancelled" if cancelled
                         else "no stage says it was cancelled") + " (a cancel ends the stage it reaches cancelled)")
    warnings = (result.get("summary") or {}).get("warnings")
    clock = isinstance(warnings, list) and any(isinstance(w, dict) and w.get("code") == "time_limit"
                                                for w in warnings)
    if clock != (stop == "time_limit"):
        raise Invalid("returned", f"stats/statuses is {statuses!r:.60}, and the summary's warnings "
                                  f"{'say' if clock else 'do not say'} the job's time limit in all passed (the "
                                  "time_limit warning is stated exactly when it did)")
    for name in ("projective", "autocalibration", "bundle_adjustment"):
        if status[name] == "time_limit" and stop != "time_limit":
            _refuse(f"{name}/status", f"'time_limit', and the job's statistics do not say its time limit in all "
                                      f"passed ({statuses!r:.60}): this stage has no clock of its own")
    parts = [(f"points/{k}", p.get("status")) for k, p in enumerate(points)] + \
        [(f"cameras/{c.get('view')}", c.get("status")) for c in cameras]
    for where, word in parts:
        if word == "cancelled" and stop != "cancelled" and not (
                where.startswith("points/") and status["cameras"] == "skipped"):
            raise Invalid("returned", f"{where}: status 'cancelled', and the job's statistics do not say it was "
                                      f"cancelled ({statuses!r:.60})")

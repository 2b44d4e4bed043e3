"""A thirteenth hostile review of the verifier (issue 33, review 12's remaining classes): a
reconstruction's words about its run, which no check tied to what the run produced. Each forgery
starts from the stored genuine reconstruction (tests/data/certificates/reconstruction.json: six
views, 16 points all certified, four cameras certified), edits its words (a few fields, kept
consistent with one another where a check reads them together) and asserts the verifier refuses
it; each verified before its fix (run against the verifier before it: every test here but the
genuine ones fails). The genuine stopped runs (a cancel in the structure and cameras stages; the
job's clock) are solved here and verify.

- F3, stage statuses untied to what each stage produced: a stage's status is now one the
  pipeline writes beside the result's products (reconstruction_statuses: the points need every
  stage before the structure to have ended as the pipeline lets it go on; a stage that found a
  K, adjusted, or left tracks or cameras unstarted says so; a stop ends every later stage with
  the same word).
- F4, nested stage members untyped: each has its type (reconstruction_members.MEMBERS, COUNTS)
  and, where the result allows, its tie (a start "the same rig as" an earlier start, each start
  once and one the result had, started_from the start adjusted, a principal point estimated
  only when its test passes, per_view one entry a view, images the matches stage's figures).
- F5, the job's stop read from stats.statuses alone: "cancelled" now exactly when a stage says
  so, "time_limit" exactly when the summary warns the job's clock passed, and only a stop of the
  job's stops the registration, the upgrade and the adjustment.
- Minor: options.certificate and detail, stats' and progress's times, a job document's own
  members (links, times, webhook, a cancelled job's error), and summary.calibration's K and
  certified_K exactly upper triangular (compared within rounding, their form was not)."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from geocert.verify.checks import verify_any

STORED = Path(__file__).parent.parent / "data" / "certificates"


@pytest.fixture(scope="module")
def genuine() -> dict:
    document = json.loads((STORED / "reconstruction.json").read_text())
    assert verify_any(document).valid
    return document


def _stage(document: dict, name: str) -> dict:
    return next(stage for stage in document["stages"] if stage["name"] == name)


def _refused(document: dict, *words: str) -> str:
    report = verify_any(document)
    assert not report.valid, "the forgery verified"
    detail = report.first_failure["detail"]
    assert report.first_failure["check"] in ("returned", "options"), report.first_failure
    assert all(word in detail for word in words), detail
    return detail


def _forged(genuine: dict, edit) -> dict:
    forged = copy.deepcopy(genuine)
    edit(forged)
    return forged


# --- F3: a stage's status against what it produced ---------------------------------------------

@pytest.mark.parametrize("status", ["failed", "skipped", "not_run"])
def test_an_autocalibration_called_not_done_beside_its_certified_K_is_refused(genuine, status):
    forged = _forged(genuine, lambda d: _stage(d, "autocalibration").update(status=status))
    _refused(forged, "stages/autocalibration/status")


@pytest.mark.parametrize("status", ["skipped", "not_run", "failed"])
def test_a_registration_called_not_run_beside_registered_cameras_is_refused(genuine, status):
    forged = _forged(genuine, lambda d: _stage(d, "projective").update(status=status))
    _refused(forged, "stages/projective/status")


@pytest.mark.parametrize("status", ["not_run", "failed"])
def test_an_adjustment_not_run_beside_a_K_it_adjusted_is_refused(genuine, status):
    forged = _forged(genuine, lambda d: _stage(d, "bundle_adjustment").update(status=status))
    assert forged["summary"]["calibration"]["source"] == "bundle_adjustment"
    _refused(forged, "stages/bundle_adjustment/status")


def test_the_calibrations_source_reads_the_adjustment_run_not_only_not_skipped():
    """_check_calibration's source: "bundle_adjustment" only where the adjustment ran (done, or
    stopped in it), as claims.calibration writes it: a stage not run adjusted nothing."""
    document = json.loads((STORED / "reconstruction.json").read_text())
    stage = _stage(document, "bundle_adjustment")
    stage["status"] = "not_run"
    for name in ("K", "model", "rms_px_after", "observations_kept", "starts", "principal_point", "started_from"):
        stage.pop(name, None)
    _refused(document, "bundle_adjustment")


@pytest.mark.parametrize("stop", ["cancelled", "time_limit"])
def test_a_structure_stage_called_stopped_when_every_track_finished_is_refused(genuine, stop):
    def edit(d):
        _stage(d, "structure")["status"] = stop
        _stage(d, "cameras")["status"] = stop  # (as a stop leaves it)
        if stop == "cancelled":
            d["stats"]["statuses"] = {"cancelled": 1}
    _refused(_forged(genuine, edit), "stages/")


@pytest.mark.parametrize("stop", ["cancelled", "time_limit"])
def test_a_cameras_stage_called_stopped_when_every_camera_finished_is_refused(genuine, stop):
    def edit(d):
        _stage(d, "cameras")["status"] = stop
        if stop == "cancelled":
            d["stats"]["statuses"] = {"cancelled": 1}
    _refused(_forged(genuine, edit), "stages/cameras/status", "finished")


def test_stages_after_a_cancel_called_done_are_refused(genuine):
    """A cancel ends the stage it reaches and every later one cancelled (pipeline._cancel)."""
    def edit(d):
        _stage(d, "bundle_adjustment")["status"] = "cancelled"
        d["stats"]["statuses"] = {"cancelled": 1}
    _refused(_forged(genuine, edit), "status")


def test_stages_out_of_the_pipelines_order_are_refused(genuine):
    def edit(d):
        d["stages"][3], d["stages"][4] = d["stages"][4], d["stages"][3]
    _refused(_forged(genuine, edit), "order")


def test_a_structure_stage_done_counting_tracks_not_started_is_refused(genuine):
    forged = _forged(genuine, lambda d: _stage(d, "structure").update(tracks_not_started=0))
    _refused(forged, "stages/structure/tracks_not_started")


# --- F4: nested stage members typed and tied ---------------------------------------------------

def _starts(d: dict) -> list:
    return _stage(d, "bundle_adjustment")["starts"]


FORGED_MEMBERS = {
    "same_rig_as a number": (lambda d: _starts(d)[1].update(same_rig_as=5), "same_rig_as"),
    "same_rig_as a later start": (lambda d: _starts(d)[0].update(same_rig_as="linear"), "same_rig_as"),
    "same_rig_as itself": (lambda d: _starts(d)[1].update(same_rig_as="incremental"), "same_rig_as"),
    "same_rig_as, adjusted": (lambda d: _starts(d)[1].update(same_rig_as="autocalibration"), "same rig"),
    "a start named twice": (lambda d: _starts(d)[1].update({"from": "autocalibration"}), "from"),
    "a start it never had": (lambda d: _stage(d, "autocalibration").pop("linear_K"), "linear"),
    "started_from a list": (lambda d: _stage(d, "bundle_adjustment").update(started_from=["linear"]), "started_from"),
    "started_from no start": (lambda d: _stage(d, "bundle_adjustment").update(started_from="calibrated"),
                              "started_from"),
    "principal_point estimated a word": (
        lambda d: _stage(d, "bundle_adjustment")["principal_point"].update(estimated="yes"), "principal_point/estimated"),
    "principal_point estimated, its test failed": (
        lambda d: _stage(d, "bundle_adjustment")["principal_point"].update(estimated=True), "principal_point/estimated"),
    "radial_tested a number": (
        lambda d: _stage(d, "projective")["focal_rounds"][0].update(radial_tested=1), "radial_tested"),
    "resumed a word": (lambda d: _stage(d, "projective")["focal_rounds"][0].update(resumed="no"), "resumed"),
    "per_view one entry": (lambda d: _stage(d, "projective").update(per_view=[{"view": 0, "tracks": 5}]), "per_view"),
    "per_view out of order": (lambda d: _stage(d, "projective").update(per_view=[
        {"view": 5 - v, "tracks": 16, "linked": 16, "points": 16, "registered_by": "pnp"} for v in range(6)]),
        "per_view/0/view"),
    "per_view counting beyond its tracks": (lambda d: _stage(d, "projective").update(per_view=[
        {"view": v, "tracks": 16, "linked": 17, "points": 16, "registered_by": "pnp"} for v in range(6)]),
        "per_view/0/linked"),
    "per_view registered by a word no step is": (lambda d: _stage(d, "projective").update(per_view=[
        {"view": v, "tracks": 16, "linked": 16, "points": 16, "registered_by": "magic"} for v in range(6)]),
        "registered_by"),
    "registered_by a view not sent": (lambda d: _stage(d, "projective").update(registered_by={"9": "pnp"}),
                                      "registered_by"),
    "tracks_not_started a string": (lambda d: _stage(d, "structure").update(tracks_not_started="2"),
                                    "tracks_not_started"),
    "tracks_not_started beyond the tracks": (lambda d: _stage(d, "structure").update(tracks_not_started=99),
                                             "tracks_not_started"),
    "cameras_not_started a float": (lambda d: _stage(d, "cameras").update(cameras_not_started=1.5),
                                    "cameras_not_started"),
    "projective.cancelled on a finished stage": (lambda d: _stage(d, "projective").update(cancelled=True),
                                                 "projective/cancelled"),
    "projective.cancelled a word": (lambda d: _stage(d, "projective").update(cancelled="no"), "projective/cancelled"),
    "a stage's reason a number": (lambda d: _stage(d, "structure").update(reason=3), "reason"),
    "autocalibration determined a word": (lambda d: _stage(d, "autocalibration").update(determined="yes"),
                                          "determined"),
    "the adjustment's model no model": (lambda d: _stage(d, "bundle_adjustment").update(model="magic"), "model"),
    "images a number": (lambda d: d.update(images=5), "images"),
    "images with no matches stage": (lambda d: d.update(images={"images": 6}), "images"),
}


@pytest.mark.parametrize("name", list(FORGED_MEMBERS))
def test_a_nested_stage_member_of_another_type_or_untied_is_refused(genuine, name):
    edit, field = FORGED_MEMBERS[name]
    _refused(_forged(genuine, edit), field)


# --- F5: the job's stop tied to the stages, points and cameras ----------------------------------

def test_a_finished_job_called_cancelled_is_refused(genuine):
    forged = _forged(genuine, lambda d: d["stats"].update(statuses={"cancelled": 1}))
    _refused(forged, "stats/statuses", "cancelled")


def test_a_finished_job_called_stopped_by_its_clock_is_refused(genuine):
    forged = _forged(genuine, lambda d: d["stats"].update(statuses={"time_limit": 1}))
    _refused(forged, "stats/statuses", "time limit")


def test_a_job_its_clock_stopped_called_finished_is_refused(genuine):
    """The time_limit warning (kinds.reconstruction._stopped_by_clock) says the run did not
    finish; the job's statistics calling it finished are refused."""
    def edit(d):
        d["summary"]["warnings"].insert(0, {"code": "time_limit", "detail": "the job's time limit in all passed"})
    _refused(_forged(genuine, edit), "stats/statuses")


def _cameras_never_judged(d: dict) -> None:
    """The result as a cancel at the cameras stage's start leaves it: no camera judged, no camera
    certificate, the stage cancelled (pipeline._structure: Cancelled("cameras"))."""
    for camera in d["cameras"]:
        camera.update(status="not_run", certified=False, searched=False, points=0, **dict.fromkeys(
            ("cost", "lower_bound", "gap", "optimal_cost", "degrees_of_freedom", "tolerance", "bound_reason",
             "set_aside")))
    d.pop("camera_certificate")
    stage = _stage(d, "cameras")
    for name in ("degrees_of_freedom", "claim", "cameras", "certified", "searched"):
        stage.pop(name)
    stage.update(status="cancelled", reason="the job was cancelled")
    d["summary"].update(cameras_certified=0, cameras_certified_fraction=0.0, camera_claim=None)


def test_a_stage_cancelled_in_a_job_called_finished_is_refused(genuine):
    """A run cancelled as its cameras stage started, restated as finished (stats "optimal"): a
    stronger claim than the run's. Its consistent form (stats "cancelled") verifies."""
    cancelled = _forged(genuine, _cameras_never_judged)
    cancelled["stats"]["statuses"] = {"cancelled": 1}
    report = verify_any(cancelled)
    assert report.valid, report.first_failure
    _refused(_forged(genuine, _cameras_never_judged), "stats/statuses", "cameras stage")


@pytest.mark.parametrize("name", ["projective", "autocalibration", "bundle_adjustment"])
def test_a_stage_without_a_clock_stopped_by_time_in_a_job_not_stopped_is_refused(genuine, name):
    """Only the job's clock in all stops the registration, the upgrade and the adjustment."""
    def edit(d):
        later = [s["name"] for s in d["stages"]]
        for stage in later[later.index(name):]:
            _stage(d, stage)["status"] = "time_limit"
    _refused(_forged(genuine, edit), "status")


# --- minor: options' words, times, job documents, K's form --------------------------------------

@pytest.mark.parametrize("name, value", [("certificate", "bogus"), ("detail", "everything"), ("detail", 1)])
def test_an_options_echo_with_a_word_no_solver_takes_is_refused(genuine, name, value):
    forged = _forged(genuine, lambda d: d["certificate"]["options"].update({name: value}))
    report = verify_any(forged)
    assert not report.valid and f"options/{name}" in report.first_failure["detail"], report.first_failure


@pytest.mark.parametrize("name", ["solve_s", "elapsed_s"])
def test_a_negative_time_in_the_stats_is_refused(genuine, name):
    _refused(_forged(genuine, lambda d: d["stats"].update({name: -1.0})), f"stats/{name}")


@pytest.mark.parametrize("name", ["K", "certified_K"])
def test_a_calibration_not_exactly_upper_triangular_is_refused(genuine, name):
    forged = _forged(genuine, lambda d: d["summary"]["calibration"][name][1].__setitem__(0, 1e-300))
    _refused(forged, f"summary/calibration/{name}")


def _job(result: dict, **members) -> dict:
    stats = result["stats"]
    progress = {"items_total": 1, "items_done": 1, "items_certified": stats["certified"], "nodes": stats["nodes"],
                "open_boxes": 0, "elapsed_s": stats["elapsed_s"]}
    job_id = "0" * 32
    base = f"/v1/jobs/{job_id}"
    return {"id": job_id, "kind": "reconstruction", "status": "succeeded", "created_at": 1.0, "started_at": 2.0,
            "finished_at": 3.0, "progress": progress, "result": result, "error": None,
            "links": {"self": base, "events": f"{base}/events", "cancel": f"{base}/cancel"}, "webhook": None,
            **members}


def test_a_genuine_job_document_verifies(genuine):
    assert verify_any(_job(genuine)).valid
    webhook = {"url": "https://example.org/hook", "state": "delivered", "attempts": 1, "last_error": None,
               "delivered_at": 4.0}
    assert verify_any(_job(genuine, webhook=webhook)).valid


JOB_EDITS = {
    "progress elapsed_s negative": lambda j: j["progress"].update(elapsed_s=-1.0),
    "progress stage a number": lambda j: j["progress"].update(stage=3),
    "created_at a word": lambda j: j.update(created_at="yesterday"),
    "created_at negative": lambda j: j.update(created_at=-5.0),
    "finished_at a word": lambda j: j.update(finished_at="now"),
    "webhook a string": lambda j: j.update(webhook="https://example.org/hook"),
    "webhook of a state none is": lambda j: j.update(webhook={"url": "https://example.org", "state": "certified",
                                                              "attempts": 1}),
    "links to another job": lambda j: j["links"].update(self="/v1/jobs/another"),
    "links not an object": lambda j: j.update(links="/v1/jobs/x"),
    "a cancelled job with an error": lambda j: j.update(status="cancelled", error={"title": "boom"}),
    "an id a number": lambda j: j.update(id=7),
}


@pytest.mark.parametrize("name", list(JOB_EDITS))
def test_a_job_documents_members_of_another_type_are_refused(genuine, name):
    job = _job(genuine)
    JOB_EDITS[name](job)
    report = verify_any(job)
    assert not report.valid, "the forgery verified"


# --- genuine stopped runs still verify ---------------------------------------------------------

def _stopped_run(when) -> dict:
    """The reconstruction kind's example (six views, K unknown), full certificate, cancelled once
    ``when(labels)`` holds of the progress labels published so far (the cancel is seen at the
    next check and stays asked, as the worker's should_stop does)."""
    from geocert.jobs.runner import solve_job
    from geocert.kinds.reconstruction import KIND

    body = copy.deepcopy(KIND.example)
    body["options"]["certificate"] = "full"
    labels: list[str] = []
    return solve_job(body, sink=lambda p: labels.append(p.get("stage", "")), should_stop=lambda: when(labels))


@pytest.mark.parametrize("at", ["cameras 0/", "cameras 2/"])
def test_a_run_cancelled_in_the_cameras_stage_verifies(at):
    """Cancelled as the stage starts (no camera judged) or part way (the cameras it had not
    started called cancelled, counted in cameras_not_started): the points certified before it,
    and the cameras judged, verify; the job's stop is the stage's."""
    result = _stopped_run(lambda labels: any(label.startswith(at) for label in labels))
    statuses = {stage["name"]: stage["status"] for stage in result["stages"]}
    assert statuses["cameras"] == "cancelled" and statuses["structure"] == "done", statuses
    assert result["stats"]["statuses"] == {"cancelled": 1}
    assert any(point["certified"] for point in result["points"])
    report = verify_any(result)
    assert report.valid, report.first_failure


def test_a_run_cancelled_during_the_structure_stage_verifies():
    """A cancel asked as the structure stage starts: its tracks are solved in one batch (every one
    started), so the stage ends done and the cameras stage, next to ask, ends cancelled; the job's
    stop is that stage's, and the result verifies."""
    result = _stopped_run(lambda labels: any(label.startswith("structure") for label in labels))
    statuses = {stage["name"]: stage["status"] for stage in result["stages"]}
    assert statuses["structure"] == "done" and statuses["cameras"] == "cancelled", statuses
    assert result["stats"]["statuses"] == {"cancelled": 1} and result["points"]
    report = verify_any(result)
    assert report.valid, report.first_failure


@pytest.fixture(scope="module")
def photographed() -> dict:
    """A reconstruction from photos (a rendered textured box, 4 views over 45 degrees, 400
    features each, K given):
    its matching figures in ``images`` and in the matches stage, full certificate."""
    import base64

    import cv2

    from geocert.jobs.runner import solve_job
    from geocert.solvers.reconstruction import render

    scene = render.box_scene(n_views=4, arc_deg=45, seed=1)
    images = [{"name": f"v{k}", "content": base64.b64encode(cv2.imencode(".png", scene.render(c))[1]).decode()}
              for k, c in enumerate(scene.cameras)]
    return solve_job({"kind": "reconstruction", "data": {"images": images},
                      "options": {"intrinsics": {"K": scene.cameras[0].K.tolist()}, "certificate": "full",
                                  "resect_cameras": False, "features": {"max_features": 400}}})


def test_a_reconstruction_from_photos_verifies_and_its_matching_figures_are_the_stages(photographed):
    statuses = {stage["name"]: stage["status"] for stage in photographed["stages"]}
    assert statuses == {"matches": "done", "projective": "done", "autocalibration": "skipped",
                        "bundle_adjustment": "done", "structure": "done", "cameras": "skipped"}, statuses
    report = verify_any(photographed)
    assert report.valid, report.first_failure
    forged = copy.deepcopy(photographed)
    forged["images"]["tracks_kept"] += 1
    _refused(forged, "images/tracks_kept")
    forged = copy.deepcopy(photographed)
    forged["images"]["images"] = 5
    _stage(forged, "matches")["images"] = 5
    _refused(forged, "images")
    forged = copy.deepcopy(photographed)
    forged["images"] = None
    _refused(forged, "matches stage")

"""A fourteenth hostile review of the verifier (issue 33): review 13's ties of a reconstruction's
stage statuses, nested members and job stop, attacked both ways. Forgeries start from genuine
runs (the reconstruction kind's example, six views, K unknown, full certificate, or the stored
genuine document) and edit them as a forger would; genuine runs are solved in pipeline outcomes
review 13 did not try. Each test here failed on the verifier as it stood before its fix: a
forgery that verified, or a genuine result refused.

- A stop hidden as an option: a cameras stage stopped before it judged a camera (a cancel, or
  the structure stage's own clock) restated "skipped" with its reason "options.resect_cameras is
  false", every camera "not_run" and the job's stop "optimal", while the certificate's options
  echo ``resect_cameras: true``. Nothing tied the cameras stage's "skipped" to the option (the
  pipeline skips it only when the option is false or an earlier stage failed), so the job's
  cancel disappeared. The option was outside problem_sha256, so the echo itself could be restated
  false with the stage (fixed: the hash covers it, hashed_options.CLAIM_OPTIONS).
- A stop hidden as a judgement: cameras a cancel left unstarted restated as judged and "not
  certified" (not searched, "no bound can certify it"), the stage done and the job "optimal":
  nothing recomputed that judgement (they fit their points to 1e-12 px^2; fixed: a judged
  camera states the free camera that beats it, from which the verifier recomputes it).
- Genuine runs refused: (a) a run stopped after the certified upgrade and before the structure
  stage returned a point (a cancel in the adjustment; the structure stage's own clock before its
  first track), carrying its calibration certificate and no point, is refused by the calibration
  tie ("images 0 of the result's placed points"); (b) ``autocalibration: "auto"`` (the
  pipeline picks stratified and the stage states method "auto") is refused because the stage's
  method is not the calibration certificate's "stratified"."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from geocert.verify.checks import verify_any

STORED = Path(__file__).parent.parent / "data" / "certificates"


def _stage(document: dict, name: str) -> dict:
    return next(stage for stage in document["stages"] if stage["name"] == name)


def _run(when=None, **options) -> dict:
    """The reconstruction kind's example (six views, K unknown), full certificate, ``options``
    added, cancelled once ``when(labels)`` holds of the progress labels published so far."""
    from geocert.jobs.runner import solve_job
    from geocert.kinds.reconstruction import KIND

    body = copy.deepcopy(KIND.example)
    body["options"].update(certificate="full", **options)
    labels: list[str] = []
    stop = (lambda: when(labels)) if when is not None else (lambda: False)
    return solve_job(body, sink=lambda p: labels.append(p.get("stage", "")), should_stop=stop)


def _refused(document: dict) -> None:
    report = verify_any(document)
    assert not report.valid, "the forgery verified"


def _verifies(document: dict) -> None:
    report = verify_any(document)
    assert report.valid, report.first_failure


# --- a stop hidden as the resect_cameras option --------------------------------------------------

def _as_skipped(document: dict, word: str = "skipped") -> None:
    """The cameras stage restated as never run (options.resect_cameras false skips it:
    pipeline._structure), its cameras not judged, the job finished."""
    stage = _stage(document, "cameras")
    for name in ("cameras_not_started", "degrees_of_freedom", "claim", "cameras", "certified", "searched"):
        stage.pop(name, None)
    stage.update(status=word, reason="options.resect_cameras is false")
    for camera in document["cameras"]:
        if camera["status"] in ("cancelled", "time_limit"):
            camera.update(status="not_run", points=0)
    document["stats"]["statuses"] = {"optimal": 1}


@pytest.fixture(scope="module")
def cancelled_before_the_cameras() -> dict:
    """Cancelled as the structure stage starts: its tracks are solved in one batch, the cameras
    stage, next to ask, ends cancelled with no camera judged."""
    result = _run(lambda labels: any(label.startswith("structure") for label in labels))
    statuses = {stage["name"]: stage["status"] for stage in result["stages"]}
    assert statuses["structure"] == "done" and statuses["cameras"] == "cancelled", statuses
    assert {camera["status"] for camera in result["cameras"]} == {"not_run"}
    assert result["stats"]["statuses"] == {"cancelled": 1}
    _verifies(result)
    return result


@pytest.mark.parametrize("word", ["skipped", "not_run", "failed"])
def test_a_cancel_restated_as_the_cameras_stage_never_run_is_refused(cancelled_before_the_cameras, word):
    """With the options' echo saying resect_cameras true, the pipeline never skips the cameras
    stage in a run whose structure stage ended done; no finished run keeps "not_run"; the
    pipeline never calls the cameras stage "failed"."""
    forged = copy.deepcopy(cancelled_before_the_cameras)
    _as_skipped(forged, word)
    assert forged["certificate"]["options"]["resect_cameras"] is True
    _refused(forged)


def test_a_cancel_restated_as_resect_cameras_false_is_refused(cancelled_before_the_cameras):
    """The same forgery made consistent with the options' echo: resect_cameras is not among the
    options problem_sha256 covers, so the echo can be restated false and the document stays
    hashed as before; a user hashing their request (resect_cameras true) cannot see the change."""
    forged = copy.deepcopy(cancelled_before_the_cameras)
    _as_skipped(forged)
    forged["certificate"]["options"]["resect_cameras"] = False
    _refused(forged)


def test_the_structure_clock_restated_as_the_cameras_stage_skipped_is_refused():
    """The stored genuine run as the structure stage's own clock (structure_time_limit_s) leaves
    it when it passes before the cameras stage starts a camera (every camera time_limit, not
    started, counted in cameras_not_started; the job not stopped): it verifies; restated as the
    stage skipped by the option, it must not."""
    document = json.loads((STORED / "reconstruction.json").read_text())
    for camera in document["cameras"]:
        camera.update(status="time_limit", certified=False, searched=False, **dict.fromkeys(
            ("cost", "lower_bound", "gap", "optimal_cost", "degrees_of_freedom", "tolerance", "bound_reason",
             "set_aside")))
    document.pop("camera_certificate")
    stage = _stage(document, "cameras")
    for name in ("degrees_of_freedom", "claim", "cameras", "certified", "searched"):
        stage.pop(name)
    stage.update(status="time_limit", reason="structure_time_limit_s passed", cameras_not_started=6)
    document["summary"].update(cameras_certified=0, cameras_certified_fraction=0.0, camera_claim=None, doubtful=True)
    # every camera a stop left unbounded counts as not certified: the rig is doubtful
    document["summary"]["warnings"].append({"code": "reconstruction_doubtful", "detail": "the reconstruction as a "
                                            "whole is doubtful: 6 of the 6 cameras taken up are not certified"})
    _verifies(document)
    assert document["certificate"]["options"]["resect_cameras"] is True
    _as_skipped(document)
    # not judged, the cameras leave the doubtful rule's count: the warning goes too
    document["summary"]["doubtful"] = False
    document["summary"]["warnings"] = [w for w in document["summary"]["warnings"]
                                       if w["code"] != "reconstruction_doubtful"]
    _refused(document)


def _cost(result: dict, view: int) -> float:
    """A camera's L2L2 cost over its certified points (the squared reprojection errors summed)."""
    P = np.array(result["cameras"][view]["P"])
    total = 0.0
    for point in result["points"]:
        for seen, u, v in point["observations"] if point["certified"] else []:
            if seen == view:
                x = P @ np.append(point["point"], 1.0)
                total += float(np.sum((x[:2] / x[2] - (u, v)) ** 2))
    return total


def test_cameras_a_cancel_left_unstarted_restated_as_judged_uncertifiable_are_refused():
    """A cancel part way through the cameras stage (the cameras not started called cancelled,
    counted in cameras_not_started, the job cancelled) restated as a finished run whose last
    cameras were judged and not certified, "no bound can certify it" (not searched): the stage
    done, the job "optimal". Those cameras fit their points to 1e-12 px^2, and nothing recomputes
    the judgement that a free 3x4 camera beats them beyond their tolerance; a not-searched camera
    called not certified is taken as judged."""
    result = _run(lambda labels: any(label.startswith("cameras 2/") for label in labels))
    unstarted = [c["view"] for c in result["cameras"] if c["status"] == "cancelled" and not c["searched"]]
    judged = next(c for c in result["cameras"] if c["searched"])
    assert unstarted and result["stats"]["statuses"] == {"cancelled": 1}
    _verifies(result)
    forged = copy.deepcopy(result)
    for view in unstarted:
        forged["cameras"][view].update(
            status="not_certified", cost=_cost(forged, view), degrees_of_freedom=judged["degrees_of_freedom"],
            tolerance=judged["tolerance"], set_aside=0,
            bound_reason="the camera returned costs more than a free 3x4 camera found locally, more than its "
                         "tolerance: no bound can certify it, so the certified resection was not run")
    stage = _stage(forged, "cameras")
    stage.pop("cameras_not_started")
    stage.update(status="done", reason=None)
    forged["stats"]["statuses"] = {"optimal": 1}
    _refused(forged)


# --- genuine runs refused ----------------------------------------------------------------------

def test_a_run_cancelled_in_the_adjustment_verifies():
    """A cancel asked as the adjustment starts: the certified upgrade is kept with its
    certificate, the adjustment, structure and cameras stages end cancelled, no point returned."""
    result = _run(lambda labels: any(label.startswith("bundle") for label in labels))
    statuses = {stage["name"]: stage["status"] for stage in result["stages"]}
    assert statuses == {"projective": "done", "autocalibration": "done", "bundle_adjustment": "cancelled",
                        "structure": "cancelled", "cameras": "cancelled"}, statuses
    assert result["calibration_certificate"] is not None and not result["points"]
    _verifies(result)


def test_a_run_whose_structure_clock_passed_before_its_first_track_verifies():
    """structure_time_limit_s below the time a first track takes: the structure stage ends
    time_limit with every track not started (no point), the cameras stage time_limit with every
    camera not started; the certified upgrade is kept with its certificate."""
    result = _run(structure_time_limit_s=1e-6)
    statuses = {stage["name"]: stage["status"] for stage in result["stages"]}
    assert statuses["structure"] == "time_limit" and statuses["autocalibration"] == "done", statuses
    assert not result["points"] and result["calibration_certificate"] is not None
    _verifies(result)


def test_a_run_with_autocalibration_auto_verifies():
    result = _run(autocalibration="auto")
    assert _stage(result, "autocalibration")["status"] == "done"
    _verifies(result)


@pytest.mark.parametrize("method", ["stratified", "direct"])
def test_autocalibration_auto_restated_as_another_method_is_refused(method):
    """The stage states the option's word (hashed: the options' echo says "auto"): restated
    "stratified" it is the certificate's method and verified before the stage was tied to the
    echo; "direct" is not what the certificate ran."""
    result = _run(autocalibration="auto")
    forged = copy.deepcopy(result)
    _stage(forged, "autocalibration")["method"] = method
    _refused(forged)


def test_a_calibration_certificate_beside_no_point_and_no_certified_K_is_refused():
    """A run with no placed point carries its calibration certificate untied (nothing to tie it
    to), so only as the proof of the certified K claimed beside it, which verifies it: restated
    as claiming no certified K, the certificate would be carried unverified. (A guard: the tie
    refused it before, as it refused the genuine run.)"""
    result = _run(lambda labels: any(label.startswith("bundle") for label in labels))
    assert result["calibration_certificate"] is not None and not result["points"]
    forged = copy.deepcopy(result)
    forged["summary"]["calibration"].update(certified=False, certified_K=None, returned_is_certified=False,
                                            difference=None, on_range_edge=[], determined=False)
    forged["summary"]["autocalibration_certified"] = False
    _stage(forged, "autocalibration")["certified"] = False
    forged["summary"]["warnings"] = [w for w in forged["summary"]["warnings"] if w["code"] != "returned_K_not_certified"]
    report = verify_any(forged)
    assert not report.valid and "calibration certificate" in report.first_failure["detail"], report.first_failure

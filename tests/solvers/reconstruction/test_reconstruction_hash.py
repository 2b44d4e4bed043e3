"""A reconstruction's problem_sha256 covers every option a claim or check reads, and those deciding
whether a stage runs (reconstruction.hashed_options), and documents hashed an earlier way (the
points' four options only; then every option but resect_cameras and bundle_adjustment) still
verify, their report's scope stating the options that form does not cover, as the document
states them."""

from __future__ import annotations

import copy
import dataclasses

import pytest

from geocert.core.certificates import problem_hash
from geocert.verify import hashed_options
from geocert.verify.checks import checked_options, verify_any
from tests.verify.test_forgeries import stored


def _earlier_form(result: dict) -> dict:
    """The result with its certificate's problem_sha256 computed the earlier way."""
    result = copy.deepcopy(result)
    document = result["certificate"]
    options = checked_options("reconstruction", document["options"])
    document["problem_sha256"] = problem_hash("reconstruction", document["data"], options,
                                              hashed_options.EARLIER_CLAIM_OPTIONS)
    return result


@pytest.fixture(scope="module")
def at_defaults() -> dict:
    """A genuine reconstruction of the kind's example scene, every option at its default."""
    from geocert.jobs.runner import solve_job
    from geocert.kinds import get_kind

    return solve_job({"kind": "reconstruction", "data": get_kind("reconstruction").example["data"],
                      "options": {"certificate": "full"}})


def test_the_earlier_forms_defaults_are_the_options_defaults_it_was_written_with():
    """Every default the earlier form left out is today's, but radial_distortion's: "off" while that
    form was written (so an earlier-form document without it is read as off), "auto" since."""
    from geocert.pipelines.reconstruction.options import ReconstructionOptions

    defaults = dataclasses.asdict(ReconstructionOptions())
    assert {name: defaults[name] for name in hashed_options.EARLIER_DEFAULTS} == {
        **hashed_options.EARLIER_DEFAULTS, "radial_distortion": "auto"}
    assert hashed_options.EARLIER_DEFAULTS["radial_distortion"] == "off"


def test_the_hash_covers_every_option_a_claim_reads():
    document = stored("reconstruction")["certificate"]
    options = checked_options("reconstruction", document["options"])
    for name, value in (("camera_rel_gap", 0.5), ("radial_distortion", "on"), ("intrinsics", "unknown"),
                        ("metric_rel_gap", 0.5), ("autocalibration_rel_gap", 0.5), ("resect_cameras", False),
                        ("bundle_adjustment", False), ("camera_model", "varying"), ("principal_point", "centre"),
                        ("registration", "projective")):
        changed = checked_options("reconstruction", {**document["options"], name: value})
        assert problem_hash("reconstruction", document["data"], changed, hashed_options.CLAIM_OPTIONS) \
            != problem_hash("reconstruction", document["data"], options, hashed_options.CLAIM_OPTIONS), name


def test_an_earlier_form_at_the_defaults_verifies_and_says_so(at_defaults):
    assert verify_any(at_defaults).valid
    report = verify_any(_earlier_form(at_defaults))
    assert report.valid, report.first_failure
    assert "earlier form" in report.scope["problem_sha256"]


@pytest.mark.parametrize("name, value", [("camera_rel_gap", 0.25), ("radial_distortion", "on"),
                                         ("metric_rel_gap", 1e-3)])
def test_an_earlier_form_states_the_options_it_does_not_cover(at_defaults, name, value):
    result = copy.deepcopy(at_defaults)
    result["certificate"]["options"][name] = value
    assert not verify_any(result).valid  # the current form covers it: changed, the hash is refused
    report = verify_any(_earlier_form(result))
    scope = report.scope["problem_sha256"]
    assert "earlier form" in scope and f"{name} {value!r} (not its default)" in scope


def test_the_stored_reconstruction_in_the_earlier_form_verifies_stating_its_camera_rel_gap():
    """A third party's stored version-2 document still verifies; its scope says that the hash does
    not cover camera_rel_gap, and states the 0.25 the document was asked for with (a forger's 0.5
    would be stated too: test_forgeries_review5.TestCameraToleranceUnhashed)."""
    report = verify_any(stored("reconstruction"))
    assert report.valid, report.first_failure
    assert "camera_rel_gap 0.25 (not its default)" in report.scope["problem_sha256"]


def test_a_calibration_certificate_at_other_gaps_than_the_options_is_refused():
    """The stored reconstruction carrying a genuine calibration certificate of its own projective
    reconstruction solved at metric_rel_gap 0.5 (the options ask for 1e-4)."""
    from geocert.jobs.runner import solve_job

    result = stored("reconstruction")
    calibration = result["calibration_certificate"]
    other = solve_job({"kind": "autocalibration", "data": calibration["data"],
                       "options": {**calibration["options"], "metric_rel_gap": 0.5}})
    assert all(stage["certified"] for stage in other["stages"])
    assert verify_any(other).valid
    result["calibration_certificate"] = other["certificate"]
    report = verify_any(result)
    assert not report.valid and "metric_rel_gap" in report.first_failure["detail"]


def test_an_earlier_form_without_the_calibration_gaps_is_held_to_their_defaults(at_defaults):
    """The earlier form's hash does not cover whether metric_rel_gap is stated: removed, it is
    read as its default, so a calibration certificate at another gap is still refused."""
    from geocert.jobs.runner import solve_job

    result = copy.deepcopy(at_defaults)
    calibration = result["calibration_certificate"]
    other = solve_job({"kind": "autocalibration", "data": calibration["data"],
                       "options": {**calibration["options"], "metric_rel_gap": 0.5}})
    assert all(stage["certified"] for stage in other["stages"])
    result["calibration_certificate"] = other["certificate"]
    del result["certificate"]["options"]["metric_rel_gap"]
    report = verify_any(_earlier_form(result))
    assert not report.valid and "metric_rel_gap" in report.first_failure["detail"]


def test_an_earlier_form_without_camera_rel_gap_states_that_rel_gap_is_read(at_defaults):
    """camera_rel_gap absent is read as rel_gap (documents from before it was an option); the
    earlier form's hash does not cover its absence, so the scope says so. (rel_gap made the
    cameras' own gap, so that every claim holds read at it.)"""
    result = copy.deepcopy(at_defaults)
    options = result["certificate"]["options"]
    options["rel_gap"] = options.pop("camera_rel_gap")
    report = verify_any(_earlier_form(result))
    assert report.valid, report.first_failure
    assert f"camera_rel_gap absent, read as rel_gap {options['rel_gap']!r}" in report.scope["problem_sha256"]


# --- the second form: every option but those deciding whether a stage runs --------------------

def _second_form(result: dict) -> dict:
    """The result as the kind wrote it in the second form: problem_sha256 over
    SECOND_CLAIM_OPTIONS, and no camera's free_camera (stated since)."""
    result = copy.deepcopy(result)
    for camera in result["cameras"]:
        camera.pop("free_camera", None)
    document = result["certificate"]
    options = checked_options("reconstruction", document["options"])
    document["problem_sha256"] = problem_hash("reconstruction", document["data"], options,
                                              hashed_options.SECOND_CLAIM_OPTIONS)
    return result


def test_the_second_forms_defaults_are_the_options_defaults():
    from geocert.pipelines.reconstruction.options import ReconstructionOptions

    defaults = dataclasses.asdict(ReconstructionOptions())
    # principal_point's default was "auto" while the second form was written ("per_view" since)
    assert {**{name: defaults[name] for name in hashed_options.SECOND_DEFAULTS}, "principal_point": "auto"} \
        == hashed_options.SECOND_DEFAULTS
    assert hashed_options.THIRD_CLAIM_OPTIONS == hashed_options.SECOND_CLAIM_OPTIONS + (
        "resect_cameras", "bundle_adjustment", "camera_model", "principal_point")


def test_the_third_forms_defaults_are_the_options_defaults():
    """The fourth form (today's) covers registration beside the third form's options, at the
    default a request naming none gets."""
    from geocert.pipelines.reconstruction.options import ReconstructionOptions

    defaults = dataclasses.asdict(ReconstructionOptions())
    assert {name: defaults[name] for name in hashed_options.THIRD_DEFAULTS} == hashed_options.THIRD_DEFAULTS
    assert hashed_options.CLAIM_OPTIONS == hashed_options.THIRD_CLAIM_OPTIONS + ("registration",)


def test_a_second_form_at_the_defaults_verifies_and_says_so(at_defaults):
    report = verify_any(_second_form(at_defaults))
    assert report.valid, report.first_failure
    scope = report.scope["problem_sha256"]
    assert scope.startswith("the second form") and "resect_cameras True; bundle_adjustment True" in scope
    # the camera model the tolerances count: principal_point's default then was "auto", "per_view" now
    assert "camera_model 'simple'; principal_point 'per_view' (not its default)" in scope


@pytest.mark.parametrize("name, value", [("principal_point", "auto"), ("camera_model", "varying")])
def test_the_camera_model_restated_is_refused_by_the_hash(at_defaults, name, value):
    """Review 16: the options choosing the camera model (whose intrinsics each camera's tolerance
    counts) were outside problem_sha256; the current form covers them, so a document restating
    them no longer hashes to the request's."""
    result = copy.deepcopy(at_defaults)
    assert result["certificate"]["options"][name] != value
    result["certificate"]["options"][name] = value
    report = verify_any(result)
    assert not report.valid and report.first_failure["check"] == "data_hash" and \
        "problem_sha256" in report.first_failure["detail"], report.first_failure


def test_the_earliest_form_states_the_options_deciding_whether_a_stage_runs_too(at_defaults):
    report = verify_any(_earlier_form(at_defaults))
    assert report.valid, report.first_failure
    assert "resect_cameras True; bundle_adjustment True" in report.scope["problem_sha256"]


@pytest.fixture(scope="module")
def cancelled_before_the_cameras() -> dict:
    from tests.verify.test_forgeries_review14 import _run

    result = _run(lambda labels: any(label.startswith("structure") for label in labels))
    assert {stage["name"]: stage["status"] for stage in result["stages"]}["cameras"] == "cancelled"
    return result


def test_a_cancel_restated_as_resect_cameras_false_in_the_second_form_says_so(cancelled_before_the_cameras):
    """Review 14's forgery (the cancel restated as the cameras stage skipped by resect_cameras false)
    rehashed in the second form, which does not cover the option: a document of that form cannot be
    told from it, so it verifies, and the report's scope states resect_cameras false, not its
    default, for the user to compare with their request (true). In the current form it is refused
    (test_forgeries_review14)."""
    from tests.verify.test_forgeries_review14 import _as_skipped

    forged = copy.deepcopy(cancelled_before_the_cameras)
    _as_skipped(forged)
    forged["certificate"]["options"]["resect_cameras"] = False
    assert not verify_any(forged).valid
    report = verify_any(_second_form(forged))
    assert report.valid, report.first_failure
    assert "resect_cameras False (not its default)" in report.scope["problem_sha256"]


def test_the_adjustment_skipped_is_tied_to_its_option(at_defaults):
    """A run with bundle_adjustment false verifies; its echo restated true (rehashed: the hash
    covers it) beside the adjustment skipped is refused: the pipeline skips the adjustment only
    when the option is false or an earlier stage failed, which skips the structure stage too."""
    from geocert.jobs.runner import solve_job
    from geocert.kinds import get_kind
    from tests.verify.test_forgeries import rehash

    result = solve_job({"kind": "reconstruction", "data": get_kind("reconstruction").example["data"],
                        "options": {"certificate": "full", "bundle_adjustment": False}})
    assert next(s for s in result["stages"] if s["name"] == "bundle_adjustment")["status"] == "skipped"
    assert verify_any(result).valid
    result["certificate"]["options"]["bundle_adjustment"] = True
    rehash(result["certificate"])
    report = verify_any(result)
    assert not report.valid and "bundle_adjustment/status" in report.first_failure["detail"], report.first_failure


def test_a_cancel_restated_as_skipped_with_resect_cameras_absent_is_refused(cancelled_before_the_cameras):
    """The second form's hash does not cover whether resect_cameras is stated either: removed from
    the echo, it is read as its default (true), as the scope says, so the cameras stage restated
    skipped is refused."""
    from tests.verify.test_forgeries_review14 import _as_skipped

    forged = copy.deepcopy(cancelled_before_the_cameras)
    _as_skipped(forged)
    del forged["certificate"]["options"]["resect_cameras"]
    report = verify_any(_second_form(forged))
    assert not report.valid and "cameras/status" in report.first_failure["detail"], report.first_failure

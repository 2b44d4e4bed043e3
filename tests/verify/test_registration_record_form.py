"""Issue 33, downgrade by omission: a reconstruction whose projective stage states no
principal-point record (stages.projective.principal_point) had its calibration certificate read as
a registration at the images' centre, held to the centred reference with its room (a quarter of
that model's misfit), as documents written before the pipeline stated the record are. A forger
holding a genuine off-centre run (its registration at the estimated principal point) could swap in
a certificate built at the centre with another focal length and delete the record. The form is
now declared: the problem hash covers ``registration`` (hashed_options' fourth form), and a
document of that form states the record wherever its registration tests the principal point
(calibration_tie.registration_tests); an earlier form may lack it, and the report says so. The
same form states the certificate data's input_labels and the autocalibration stage's
cameras_built_with_one_K (hashed_options.states_records), whose absence gave the same choice."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.core.certificates import problem_hash
from geocert.formulations.reconstruction import calibration_tie
from geocert.verify import hashed_options
from geocert.verify.checks import checked_options, verify_any
from tests.support import stage as _stage
from tests.verify.test_forgeries_review18 import SHIFTS, _centred_registration, _reposed, _scene_job


def _verify(result: dict):
    return verify_any(json.loads(json.dumps(result)))


def _in_form(result: dict, names: tuple) -> dict:
    """The result's certificate hashed over ``names`` (as a document of that form was)."""
    result = copy.deepcopy(result)
    document = result["certificate"]
    document["problem_sha256"] = problem_hash("reconstruction", document["data"],
                                              checked_options("reconstruction", document["options"]), names)
    return result


@pytest.fixture(scope="module")
def off_centre() -> dict:
    """The (+30, -20)-shifted scene, registered at the principal point its test estimates."""
    result = solve_job(_scene_job({}, points=200, shift=np.tile(SHIFTS["(+30, -20)"], (8, 1))))
    assert _stage(result, "projective")["principal_point"]["estimated"] is True
    return result


@pytest.fixture(scope="module")
def centred_forgery(off_centre) -> dict:
    """The run carrying a genuine calibration certificate of its reconstruction re-posed at the
    images' centre with 1.03 times the returned focal length (within the centred reference's room),
    its registration record deleted, as a forger would."""
    from tests.verify.test_calibration_tie import carrying

    K = np.array(next(c for c in off_centre["cameras"] if c.get("registered"))["K"], dtype=float)
    size = next(c["image_size"] for c in off_centre["cameras"] if c.get("registered"))
    K[0, 0] *= 1.03
    K[1, 1] = K[0, 0]
    K[0, 1], K[:2, 2] = 0.0, [(size[0] - 1) / 2, (size[1] - 1) / 2]
    forged = carrying(off_centre, _reposed(off_centre, K))
    _stage(forged, "projective").pop("principal_point", None)
    return forged


def test_the_genuine_run_is_of_the_form_stating_the_record(off_centre):
    report = _verify(off_centre)
    assert report.valid, report.first_failure
    assert "problem_sha256" not in report.scope  # the current form
    assert report.scope["calibration_tie"]["registration_record"] == "stated"


def test_a_centred_certificate_with_the_record_deleted_is_refused(centred_forgery):
    """Found: verified on main (the certificate held to the centred reference, its 1.03 times the
    focal length within that reference's room)."""
    report = _verify(centred_forgery)
    assert not report.valid
    assert "stages/projective/principal_point is absent" in report.first_failure["detail"], report.first_failure


def test_restated_in_an_earlier_form_it_verifies_only_saying_so(centred_forgery):
    """The known limit: the same forgery hashed in the third form (before the hash covered
    registration) is read as a document written before the record, held to the centred reference
    with its room as a stored document is, and verifies; the report's scope says the hash is of
    that form (a user hashing their request in today's form finds another hash) and that the record
    is absent for that reason."""
    report = _verify(_in_form(centred_forgery, hashed_options.THIRD_CLAIM_OPTIONS))
    assert report.valid, report.first_failure
    assert report.scope["problem_sha256"].startswith("the third form")
    assert report.scope["calibration_tie"]["registration_record"].startswith("absent: the document is of an "
                                                                           "earlier form")


def test_a_run_registered_at_the_centre_of_todays_form_is_refused_without_the_record():
    """A run the pipeline made before it registered at the estimated principal point, restated in
    today's form (no record, its hash covering registration): refused; hashed in the form such a
    run was written in, it verifies, the scope saying the record is absent."""
    result = _centred_registration({}, SHIFTS["(+30, -20)"])  # (hashed in the third form, as written then)
    report = _verify(result)
    assert report.valid, report.first_failure
    assert report.scope["problem_sha256"].startswith("the third form")
    assert report.scope["calibration_tie"]["registration_record"].startswith("absent: the document is of an earlier")
    today = _verify(_in_form(result, hashed_options.CLAIM_OPTIONS))
    assert not today.valid and "stages/projective/principal_point is absent" in today.first_failure["detail"]


def test_no_record_is_asked_where_the_registration_does_not_test(off_centre):
    """registration_tests: the test runs only with the adjustment estimating the principal point,
    views of one size, no radial term kept, the registration not stopped."""
    assert calibration_tie.registration_tests(off_centre)
    for edit in (lambda r: r["certificate"]["options"].update(principal_point="centre"),
                 lambda r: r["certificate"]["options"].update(bundle_adjustment=False),
                 lambda r: r["certificate"]["options"].update(registration="projective"),
                 lambda r: r["certificate"]["options"].update(camera_model="varying"),
                 lambda r: _stage(r, "projective")["radial_distortion"].update(estimated=True),
                 lambda r: r["certificate"]["data"]["input_labels"]["image_sizes"][0].__setitem__(0, 641.0)):
        edited = copy.deepcopy(off_centre)
        edit(edited)
        assert not calibration_tie.registration_tests(edited)


# The same class elsewhere: records a document of an earlier form lacks, which the verifier reads
# such a document without more loosely; a document of today's form states them (states_records).

def test_todays_form_without_its_input_labels_is_refused(off_centre):
    """Found: the run with data/input_labels deleted (rehashed) verified on main, its report
    saying the labels are unchecked, so a forger could swap the points' track numbers or the
    cameras' names by leaving the labels out."""
    from tests.verify.test_forgeries import rehash

    forged = copy.deepcopy(off_centre)
    del forged["certificate"]["data"]["input_labels"]
    rehash(forged["certificate"])
    report = _verify(forged)
    assert not report.valid and "data/input_labels is absent" in report.first_failure["detail"], report.first_failure
    # in the form written before the hash covered registration: read without them, and said so
    earlier = _verify(_in_form(forged, hashed_options.THIRD_CLAIM_OPTIONS))
    assert earlier.valid, earlier.first_failure
    assert earlier.scope["labels"].startswith("unchecked")


def test_todays_form_without_cameras_built_with_one_K_is_refused(off_centre):
    """Found: the run's autocalibration stage without cameras_built_with_one_K, and its summary
    without the certified_K_of_calibrated_cameras warning that finding calls for, verified on
    main (the field was read as a stored document's that predates it)."""
    stage = _stage(off_centre, "autocalibration")
    assert stage["cameras_built_with_one_K"] is True
    forged = copy.deepcopy(off_centre)
    del _stage(forged, "autocalibration")["cameras_built_with_one_K"]
    forged["summary"]["warnings"] = [w for w in forged["summary"]["warnings"]
                                     if w["code"] != "certified_K_of_calibrated_cameras"]
    report = _verify(forged)
    assert not report.valid and "cameras_built_with_one_K is absent" in report.first_failure["detail"], \
        report.first_failure

"""K known with a radial term kept (pipeline._fixed_radial_test): the observations were undistorted
with k1 about the given K's principal point, at its focal length, before any certificate, and the
result says so (each camera's k1 and distortion_centre, summary.distortion, the
certificates_conditional_on_k1 warning, the bundle adjustment stage's test). The verifier ties
them together and to the given K and the test's threshold (reconstruction._check_distortion,
_check_known_K_distortion): each forgery below is refused, the genuine result verifies."""

from __future__ import annotations

import copy

import pytest

from geocert.formulations.reconstruction.camera_claim import RADIAL_CHI2
from geocert.verify.checks import verify_any
from tests.pipelines.reconstruction.test_radial_known_K import K1, distorted_scene
from tests.support import reconstruction_data


@pytest.fixture(scope="module")
def known_K_with_k1():
    from geocert.jobs.runner import solve_job

    scene, tracks = distorted_scene(K1)
    data = reconstruction_data(tracks, scene.image_size, 10)
    result = solve_job({"kind": "reconstruction", "data": data, "options": {
        "certificate": "full", "camera_rel_gap": 0.05, "intrinsics": {"K": scene.K.tolist()}}})
    assert result["summary"]["cameras_certified"] == 10
    assert all(camera["k1"] for camera in result["cameras"])
    return result


def refused(result: dict) -> None:
    report = verify_any(result)
    assert not report.valid


def _stage(result: dict, name: str) -> dict:
    return next(stage for stage in result["stages"] if stage["name"] == name)


def _restated(result: dict, k1: float) -> dict:
    """The summary's k1 (its statement and warning too) restated as ``k1``."""
    distortion = result["summary"]["distortion"]
    old = distortion["statement"]
    distortion["statement"] = old.replace(f"k1 = {distortion['k1']:.4g}", f"k1 = {k1:.4g}")
    distortion["k1"] = k1
    for warning in result["summary"]["warnings"]:
        if warning["code"] == "certificates_conditional_on_k1":
            warning["detail"] = distortion["statement"]
    return result


def test_the_genuine_result_verifies(known_K_with_k1):
    report = verify_any(known_K_with_k1)
    assert report.valid, report.first_failure
    test = _stage(known_K_with_k1, "bundle_adjustment")["radial_distortion"]
    assert test["estimated"] is True and test["k1"] == pytest.approx(K1, abs=0.01)


def test_a_cameras_k1_forged_is_refused(known_K_with_k1):
    forged = copy.deepcopy(known_K_with_k1)
    forged["cameras"][3]["k1"] *= 0.5
    refused(forged)


def test_the_summarys_k1_forged_is_refused(known_K_with_k1):
    refused(_restated(copy.deepcopy(known_K_with_k1), known_K_with_k1["summary"]["distortion"]["k1"] * 0.5))


def test_every_k1_but_the_tests_forged_is_refused(known_K_with_k1):
    """The cameras' and the summary's k1 restated together: the bundle adjustment's test is not theirs."""
    forged = copy.deepcopy(known_K_with_k1)
    k1 = forged["summary"]["distortion"]["k1"] * 0.5
    for camera in forged["cameras"]:
        camera["k1"] = k1
    refused(_restated(forged, k1))


def test_the_tests_k1_forged_is_refused(known_K_with_k1):
    forged = copy.deepcopy(known_K_with_k1)
    _stage(forged, "bundle_adjustment")["radial_distortion"]["k1"] *= 0.5
    refused(forged)


def test_a_term_the_test_rejects_is_refused(known_K_with_k1):
    forged = copy.deepcopy(known_K_with_k1)
    _stage(forged, "bundle_adjustment")["radial_distortion"]["chi2"] = RADIAL_CHI2 / 2
    refused(forged)


def test_a_centre_not_Ks_principal_point_is_refused(known_K_with_k1):
    forged = copy.deepcopy(known_K_with_k1)
    forged["cameras"][0]["distortion_centre"] = [forged["cameras"][0]["distortion_centre"][0] + 5.0,
                                                 forged["cameras"][0]["distortion_centre"][1]]
    refused(forged)


@pytest.mark.parametrize("moved", [False, True])
def test_the_test_recorded_in_the_projective_stage_is_refused(known_K_with_k1, moved):
    """With K known the term is tested in the bundle adjustment, never in the registration."""
    forged = copy.deepcopy(known_K_with_k1)
    adjustment = _stage(forged, "bundle_adjustment")
    # the members the K-unknown test's record has (it states no observations)
    _stage(forged, "projective")["radial_distortion"] = {key: value for key, value in
                                                         adjustment["radial_distortion"].items()
                                                         if key != "observations"}
    if moved:
        adjustment.pop("radial_distortion")
    refused(forged)


def test_the_term_removed_from_the_summary_is_refused(known_K_with_k1):
    forged = copy.deepcopy(known_K_with_k1)
    forged["summary"].pop("distortion")
    forged["summary"]["warnings"] = [w for w in forged["summary"]["warnings"]
                                     if w["code"] != "certificates_conditional_on_k1"]
    refused(forged)

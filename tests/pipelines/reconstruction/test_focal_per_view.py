"""A focal length of its own for a view whose focal length differs from the others' (options.
principal_point "per_view", K unknown, after a principal point per view was kept): Sceaux
Castle's 11 photos state one focal length in their EXIF, yet one view's is 2% shorter than the
others', and the shared one fit two views too badly to certify them. The views are screened with
a focal length each, those standing apart (Bonferroni at 0.001) are given their own when the
chi-square test at 0.999 passes and the data fix them; the verifier accepts the genuine document
and refuses one that hides the test or gives a camera a focal length the test did not free.

Before the calibration tie's centred fit (main's), the genuine result of a view 15% longer was
refused by the tie (8% verified): the certificate's projective cameras are the registration's,
built with one focal length, and the adjustment moved that view's images further than the
returned cameras' tie allowed. Both verify now."""

from __future__ import annotations

import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.reconstruction import synthetic
from geocert.verify.checks import verify_any

VIEWS = 8
LONGER = 3  # the view whose focal length is longer
FACTOR = 1.15
SMALLER_FACTOR = 1.08  # what the calibration tie accepted before its centred fit (module docstring)


def _job(tracks, image_size) -> dict:
    return solve_job({"kind": "reconstruction", "options": {"certificate": "full", "principal_point": "per_view"},
                      "data": {"views": [{"image_size": list(image_size)}] * VIEWS,
                               "tracks": [{"views": [int(v) for v in views], "points": pixels.tolist()}
                                          for views, pixels in tracks]}})


def _scene(longer: bool, factor: float = FACTOR):
    """Eight general views, 0.3 px noise, each view's principal point moved by its own offset (up
    to 15 px each way: the per-view principal points are kept); ``longer``: view LONGER seen with
    a focal length FACTOR times the others' (its pixels scaled about its principal point)."""
    scene = synthetic.scene(views=VIEWS, points=200, seed=6, noise_px=0.3, spread_degrees=50.0)
    shift = np.random.default_rng(1).uniform(-15, 15, (VIEWS, 2))
    centre = scene.K[:2, 2]
    factor = np.where(np.arange(VIEWS) == LONGER, factor if longer else 1.0, 1.0)
    tracks = [(views, centre + (pixels - centre) * factor[np.asarray(views), None] + shift[np.asarray(views)])
              for views, pixels in scene.tracks]
    return scene, tracks


def _adjustment(result: dict) -> dict:
    return next(stage for stage in result["stages"] if stage["name"] == "bundle_adjustment")


@pytest.fixture(scope="module")
def longer():
    scene, tracks = _scene(True)
    return scene, _job(tracks, scene.image_size)


@pytest.fixture(scope="module")
def verified():
    scene, tracks = _scene(True, SMALLER_FACTOR)
    return scene, _job(tracks, scene.image_size)


def test_a_view_with_a_longer_focal_length_gets_its_own_and_is_certified(longer):
    scene, result = longer
    # One focal length for all (the code before this test): 2 of the 8 cameras certified.
    assert result["summary"]["views_registered"] == VIEWS and result["summary"]["cameras_certified"] == VIEWS
    stage = _adjustment(result)
    assert stage["principal_point_per_view"]["estimated"] is True
    test = stage["focal_per_view"]
    assert test["estimated"] is True and test["views"] == [LONGER], test
    assert test["chi2"] > test["threshold"] and test["parameters_added"] == 1
    assert abs(test["z"][LONGER]) > test["z_threshold"] and all(
        abs(z) < test["z_threshold"] for k, z in enumerate(test["z"]) if k != LONGER)
    # Focal lengths relative to the others' (the scale of a K-unknown reconstruction's focal is
    # the data's): the longer view's is FACTOR times theirs to 1%, the others share one.
    focals = {c["view"]: c["K"][0][0] for c in result["cameras"]}
    shared = {f for v, f in focals.items() if v != LONGER}
    assert len(shared) == 1
    assert abs(focals[LONGER] / shared.pop() / FACTOR - 1) < 0.01, focals
    assert all(c["certified"] and c["degrees_of_freedom"] == 9 for c in result["cameras"])


def test_the_genuine_result_verifies(verified):
    _, result = verified
    assert _adjustment(result)["focal_per_view"]["views"] == [LONGER]
    report = verify_any(json.loads(json.dumps(result)))
    assert report.valid, report.first_failure


def test_the_genuine_result_of_a_view_15_percent_longer_verifies(longer):
    _, result = longer
    report = verify_any(json.loads(json.dumps(result)))
    assert report.valid, report.first_failure


def test_a_focal_length_no_test_freed_is_refused(verified):
    """The test's record removed, or saying it kept nothing: the cameras' own focal lengths are
    then a model the adjustment did not state."""
    _, result = verified
    for change in ("drop", "not_estimated"):
        forged = json.loads(json.dumps(result))
        stage = _adjustment(forged)
        if change == "drop":
            del stage["focal_per_view"]
        else:
            stage["focal_per_view"]["estimated"] = False
        report = verify_any(forged)
        assert not report.valid and report.first_failure["check"] == "returned", (change, report.first_failure)


def test_a_focal_length_beyond_the_views_named_is_refused(verified):
    """The test names view LONGER: a camera of another view with a focal length of its own (its P
    rewritten to match), or the test naming another view, is refused by the test's check."""
    from geocert.core.strict import Invalid
    from geocert.verify.reconstruction_members import _check_focals_per_view

    _, result = verified
    _check_focals_per_view(result, _adjustment(result))  # the genuine one passes
    forged = json.loads(json.dumps(result))
    camera = next(c for c in forged["cameras"] if c["view"] != LONGER)
    K = np.array(camera["K"])
    K[0, 0] *= 1.001
    K[1, 1] *= 1.001
    camera["K"] = K.tolist()
    camera["P"] = (K @ np.column_stack([np.array(camera["R"]), np.array(camera["t"])])).tolist()
    with pytest.raises(Invalid, match="focal lengths of their own beyond"):
        _check_focals_per_view(forged, _adjustment(forged))
    forged = json.loads(json.dumps(result))
    _adjustment(forged)["focal_per_view"]["views"] = [(LONGER + 1) % VIEWS]
    with pytest.raises(Invalid, match="focal length"):
        _check_focals_per_view(forged, _adjustment(forged))
    report = verify_any(forged)
    assert not report.valid and report.first_failure["check"] == "returned", report.first_failure


def test_views_sharing_their_focal_length_keep_one():
    """The test does not free what the data do not ask for: with one focal length for all (each
    view's principal point its own), no view stands apart in the screen and one focal length stays."""
    scene, tracks = _scene(False)
    result = _job(tracks, scene.image_size)
    stage = _adjustment(result)
    assert stage["principal_point_per_view"]["estimated"] is True
    test = stage["focal_per_view"]
    assert test["estimated"] is False and test["views"] == [], test
    assert all(abs(z) < test["z_threshold"] for z in test["z"])
    focals = {c["K"][0][0] for c in result["cameras"] if c["registered"]}
    assert len(focals) == 1
    assert all(c["degrees_of_freedom"] == 8 for c in result["cameras"])


def test_the_misfit_of_a_camera_with_its_own_principal_point_counts_it_once():
    """Sceaux Castle's 100_7110 with a principal point each (8 degrees of freedom, 530 points):
    4.22% above the free 3x4 camera, 1.88% refit with a focal length and principal point of its
    own. Such a camera has 9 degrees of freedom (tolerance 2.34%), not 8 + 3 = 11 (1.01%, where
    the diagnosis said no intrinsic of its own explained it): its own focal length does."""
    from geocert.solvers.reconstruction.camera_misfit import misfit_cause

    refits = {"pose": 0.0422, "principal_point": 0.0422, "focal_and_principal_point": 0.0188}
    assert misfit_cause(refits, 0.0422, 530, 8, "L2L2", 1e-2) == "focal_and_principal_point"


# --- a view the sanity layer drops after the test (review 21's open finding) ------------------------------
#
# The z of the focal length's test are one a view registered at the test; the sanity layer
# (pipeline._check_cameras) may drop a view after it, not registered then, its reason "dropped:
# ...". Main checked such a document's named views by count only, and refused a genuine one whose
# dropped view was the named one ("a view its test names has the focal length the others share":
# it has no camera). A view is dropped here by the sanity layer's own rule with its level raised
# (MIN_CAMERA_POINTS: the view sees fewer points than that, the others more; the verifier does
# not read the level), the dropped view seeing SEEN of the 200 points.

SEEN = {LONGER: 60, 6: 130}  # the view dropped: the named one, or another (seeing enough for the test to run)


def _dropped(view: int) -> dict:
    from geocert.pipelines.reconstruction import pipeline

    scene, tracks = _scene(True)
    kept = []
    for k, (views, pixels) in enumerate(tracks):
        views, pixels = np.asarray(views), np.asarray(pixels)
        if k >= SEEN[view]:
            views, pixels = views[views != view], pixels[views != view]
        if len(views) >= 2:
            kept.append((views, pixels))
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(pipeline, "MIN_CAMERA_POINTS", SEEN[view] + 20)
        result = _job(kept, scene.image_size)
    test = _adjustment(result)["focal_per_view"]
    assert test["estimated"] is True and test["views"] == [LONGER] and len(test["z"]) == VIEWS
    assert [c["view"] for c in result["cameras"] if not c["registered"]] == [view]
    assert next(c for c in result["cameras"] if c["view"] == view)["reason"].startswith("dropped")
    return result


@pytest.fixture(scope="module")
def named_dropped() -> dict:
    return _dropped(LONGER)


@pytest.fixture(scope="module")
def other_dropped() -> dict:
    return _dropped(6)


def test_the_genuine_result_whose_named_view_was_dropped_after_the_test_verifies(named_dropped):
    report = verify_any(json.loads(json.dumps(named_dropped)))
    assert report.valid, report.first_failure


def test_the_genuine_result_with_another_view_dropped_after_the_test_verifies(other_dropped):
    report = verify_any(json.loads(json.dumps(other_dropped)))
    assert report.valid, report.first_failure


@pytest.mark.parametrize("which", ["named_dropped", "other_dropped"])
@pytest.mark.parametrize("edit", ["another view named", "z of the named view and the next swapped",
                                  "one z fewer", "the dropped camera's reason not a drop"])
def test_named_views_not_those_past_the_test_beside_a_dropped_view_are_refused(request, which, edit):
    """The views named must be those whose z exceed the threshold, the z one a view registered at
    the test (those returned registered and those dropped since): naming another view, swapping
    the named view's z with the next one's (the named view then within the screen; the count of
    z above it unchanged, all main read), stating one z fewer, or the dropped camera no longer
    said dropped, is refused."""
    forged = json.loads(json.dumps(request.getfixturevalue(which)))
    test = _adjustment(forged)["focal_per_view"]
    if edit == "another view named":
        test["views"] = [LONGER + 1]
    elif edit == "z of the named view and the next swapped":
        test["z"][LONGER], test["z"][LONGER + 1] = test["z"][LONGER + 1], test["z"][LONGER]
    elif edit == "one z fewer":
        test["z"] = [z for k, z in enumerate(test["z"]) if k != LONGER + 1]
    else:
        camera = next(c for c in forged["cameras"] if not c["registered"])
        camera["reason"] = "not registered"
    report = verify_any(forged)
    assert not report.valid and report.first_failure["check"] == "returned", report.first_failure

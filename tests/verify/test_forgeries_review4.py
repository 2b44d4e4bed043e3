"""A fourth hostile review of the verifier (issue 33): each class below is a false claim (or a
document the docs say is refused) that ``verify_any`` accepts today, built from a genuine stored
certificate (tests/data/certificates). Each forgery test asserts the sound outcome, so it xfails
(strict) until the verifier gives it; beside it, where it matters, the true claim the forgery
starts from verifies. Each class's docstring says what is accepted, how false it is, and a fix."""

from __future__ import annotations

import copy

import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored
from tests.verify.test_forgeries_review3 import _uncertified
from tests.support import reconstruction_data

ACCEPTED = "accepted today: see the class's docstring"
XFAIL = {"strict": True, "reason": ACCEPTED, "raises": AssertionError}


def _valid(document: dict) -> bool:
    return verify_any(document).valid


@pytest.fixture(scope="module")
def given_K_reconstruction() -> dict:
    """Six views of 16 points with K given (synthetic.scene seed 3, as make_fixtures'
    reconstruction): a genuine result, every point certified."""
    from geocert.jobs.runner import solve_job
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=6, points=16, seed=3, noise_px=0.5)
    data = reconstruction_data(scene.tracks, scene.image_size, 6)
    K = [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]
    result = solve_job({"kind": "reconstruction", "data": data,
                        "options": {"certificate": "full", "intrinsics": {"K": K}}})
    assert verify_any(result).valid and result["summary"]["calibration"]["source"] == "given"
    return result


class TestUncertifiedStatusUnread:
    """uncertified_claim asks only that an uncertified item's status is not "optimal": any other
    word verifies, with no proof. docs/kinds.md says "`infeasible` is said only when proven" (no
    point in front of every camera, or every box proven empty within max_residual), yet a
    certified track (optimum 13.83, its point in front of every camera) verifies restated as
    uncertified with status "infeasible", point null and the reason "no solution has every
    residual within max_residual (proven by the search)", in a document with no max_residual at
    all; likewise "degenerate" (a claim about the data), and words no kind writes ("garbage"). The
    genuine solver's infeasible tracks carry no proof either (proof null), so the word is only
    the solver's. Suggested fix: an uncertified item's status is one of the kind's statuses
    (kinds.schema.ItemStatus); "infeasible" is stated only with a proof the verifier checks (the
    search's leaves, each closed by a Farkas or depth proof over the root region: the same
    records a branch-and-bound proof carries) and only where the scope allows it (max_residual
    set, or a depth proof), and "degenerate" only where the verifier's own reading of the data
    finds the degeneracy; otherwise the word is refused (or the report states that an
    uncertified item's status is unchecked)."""

    @staticmethod
    def restated(status: str) -> dict:
        result = stored("triangulation_l2l2")
        assert result["tracks"][0]["certified"] is True
        forged = _uncertified(result, "tracks", 0, status=status, point=None, cost=None, lower_bound=None,
                              gap=None)
        forged["tracks"][0]["reason"] = "no solution has every residual within max_residual (proven by the search)"
        forged["tracks"][0]["determinacy"] = None
        return forged

    def test_the_genuine_document_verifies(self):
        assert _valid(stored("triangulation_l2l2"))

    def test_the_wire_contract_states_the_words_the_verifier_takes(self):
        from typing import get_args

        from geocert.kinds.schema import ItemStatus
        from geocert.verify.checks import UNCERTIFIED_STATUSES

        assert set(get_args(ItemStatus)) == {"optimal", "infeasible", *UNCERTIFIED_STATUSES}

    def test_a_track_behind_a_camera_is_infeasible_and_verifies(self):
        """The one "infeasible" the verifier proves from the data: a camera whose depth row is
        the reference's negated (no point in front of both), beside a certified track."""
        from geocert.jobs.runner import solve_job

        cameras = [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]],
                   [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]],
                   [[-800, 0, -320, 800], [0, -800, -240, 0], [0, 0, -1, 0]]]
        result = solve_job({"kind": "triangulation", "options": {"certificate": "full"}, "data": {
            "cameras": cameras, "tracks": [{"views": [0, 1], "points": [[330, 250], [250, 251]]},
                                           {"views": [0, 2], "points": [[330, 250], [250, 251]]}]}})
        assert [t["status"] for t in result["tracks"]] == ["optimal", "infeasible"]
        assert _valid(result)

    @pytest.mark.parametrize("status", ["infeasible", "degenerate", "garbage"])
    def test_a_solvable_track_called_infeasible_is_refused(self, status):
        assert not _valid(self.restated(status))

    def test_a_frame_called_infeasible_is_refused(self):
        result = stored("bilinear_l2l2")
        forged = _uncertified(result, "frames", 0, status="infeasible", camera=None, coefficients=None, cost=None,
                              lower_bound=None, gap=None)
        for name in ("shape", "residuals", "baseline", "determinacy"):
            forged["frames"][0][name] = None
        assert not _valid(forged)

    def test_a_map_and_a_metric_stage_called_infeasible_are_refused(self):
        result = stored("resection_l1l1")
        forged = _uncertified(result, "maps", 0, status="infeasible", matrix=None, cost=None, lower_bound=None,
                              gap=None)
        forged["maps"][0]["residuals"] = None
        assert not _valid(forged)
        result = stored("autocalibration_stratified")
        metric = _uncertified(result, "stages", 1, status="infeasible", cost=result["stages"][1]["cost"],
                              lower_bound=None, gap=None)
        assert not _valid(metric)


LINEAR_ESTIMATE = {"method": "linear", "K": [[1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [0.0, 0.0, 1.0]], "psd": True,
                   "cost": 0.0}


class TestDirectBaselineUnread:
    """A stratified result's baseline is recomputed (autocalibration.verification._check_baseline:
    the thesis's linear estimate 6.30, 6.31), and docs/certificate.md says a result's baseline is
    not informational: a result may be judged against it. A direct-method result's baseline is
    read by no check (check_returned returns through _check_returned_direct before
    _check_baseline): the genuine direct results state none, and one stating a made-up linear
    estimate (K = [[1, 0, .5], [0, 1, .5], [0, 0, 1]], psd, cost 0: a linear method that fits
    exactly) verifies, as does any other value (1.0). Suggested fix: a direct result's baseline
    is null (the kind writes none), or, if one is ever stated, recomputed as the stratified one
    is for the plane at infinity the quadric gives."""

    @pytest.mark.parametrize("name", ["autocalibration_direct", "autocalibration_direct_points"])
    def test_the_genuine_result_states_no_baseline_and_verifies(self, name):
        result = stored(name)
        assert result["baseline"] is None
        assert _valid(result)

    @pytest.mark.parametrize("name", ["autocalibration_direct", "autocalibration_direct_points"])
    @pytest.mark.parametrize("baseline", [LINEAR_ESTIMATE, 1.0])
    def test_a_baseline_no_linear_method_gave_is_refused(self, name, baseline):
        result = stored(name)
        result["baseline"] = baseline
        assert not _valid(result)


class TestStageNamesUnread:
    """An autocalibration result's stages are an affine and a metric stage (stratified) or one
    direct stage, and each stage's ``name`` says which figures a user reads; no check reads it
    (it is neither a claim field nor in RETURNED_FIELDS). The stratified result with its stages
    renamed (stage 0 "metric", stage 1 "affine": the affine stage's cost and bound now read as the
    metric one's), or a stage called "x", verifies. Suggested fix: AutocalibrationVerification.
    check_returned asks each stage's name to be its position's (STAGES' names for the method)."""

    def test_stages_renamed_are_refused(self):
        result = stored("autocalibration_stratified")
        assert [stage["name"] for stage in result["stages"]] == ["affine", "metric"]
        result["stages"][0]["name"], result["stages"][1]["name"] = "metric", "affine"
        assert not _valid(result)

    @pytest.mark.parametrize("name", ["autocalibration_stratified", "autocalibration_direct"])
    def test_a_stage_named_otherwise_is_refused(self, name):
        result = stored(name)
        result["stages"][0]["name"] = "x"
        assert not _valid(result)


class TestInformationalResultFieldsUntyped:
    """docs/certificate.md: fields no check reads are informational, "and each must be null or of
    its type (a finite number, an integer, a string)", naming every item's ``nodes`` and
    ``reason``. A result's items are not held to it: a track's ``reason`` 1.0 (a number where
    the words are), its ``nodes`` -1 or 2.5 (no count), a stage's or frame's likewise, and
    ``stats.nodes`` -2, all verify (a job document's progress/nodes is then checked against that
    -2). Suggested fix: _check_returned types each item's nodes (a non-negative integer), reason
    (null or a string) and elapsed_s (null or a finite non-negative number), and stats' nodes,
    as _check_summaries types SUMMARY_NOTES; or the docs say results are not typed."""

    CASES = [("triangulation_l2l2", "tracks", "reason", 1.0), ("triangulation_l2l2", "tracks", "nodes", -1),
             ("resection_l2l2", "maps", "nodes", 2.5), ("bilinear_l2l2", "frames", "reason", 1.0),
             ("autocalibration_stratified", "stages", "nodes", -1)]

    @pytest.mark.parametrize("name, key, field, value", CASES)
    def test_an_item_field_not_of_its_type_is_refused(self, name, key, field, value):
        result = stored(name)
        result[key][0][field] = value
        assert not _valid(result)

    def test_a_negative_node_count_is_refused(self):
        result = stored("triangulation_l2l2")
        result["stats"]["nodes"] = -2
        assert not _valid(result)


class TestGenuineUnregisteredReconstructionMisread:
    """A genuine reconstruction with K given that registers no view (14 tracks: no pair of views
    shares the 15 the initial pair needs) returns summary.calibration {"K": null, "source":
    "given"}; the verifier's calibration check (reconstruction.verification, ``source == "none"``
    exactly when K is null) refuses it with check "returned" ("source 'given' is not where the
    returned K comes from"): the solver's own honest output is reported as a tampered field. The
    document is refused anyway (nothing is certified), but its first failure should say that, as
    a K-unknown run's does. Suggested fix: with K given, source "given" is the sound word whether
    or not a camera was returned (K null when no view is registered), or the kind writes "none"
    when it returns no K; either way solver and verifier agree, and a test solves the case."""

    @staticmethod
    def unregistered(**options) -> dict:
        from geocert.jobs.runner import solve_job
        from geocert.solvers.reconstruction import synthetic

        scene = synthetic.scene(views=5, points=14, seed=7, noise_px=0.5)
        data = reconstruction_data(scene.tracks, scene.image_size, 5)
        result = solve_job({"kind": "reconstruction", "data": data, "options": {"certificate": "full", **options}})
        assert result["summary"]["views_registered"] == 0
        return result

    def test_k_unknown_says_nothing_is_certified(self):
        report = verify_any(self.unregistered())
        assert report.first_failure["detail"] == "no certified item to check", report.first_failure

    def test_k_given_says_nothing_is_certified(self):
        K = [[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]
        report = verify_any(self.unregistered(intrinsics={"K": K}))
        assert report.first_failure["detail"] == "no certified item to check", report.first_failure


class TestCalibrationSourceUnread:
    """summary.calibration.source says where the returned K comes from ("given", "autocalibration",
    "bundle_adjustment", "none"). reconstruction.verification checks only that it is
    "autocalibration" exactly when the returned K is the certified one and "none" exactly when
    no K is returned: any other word passes. The stored reconstruction (K unknown: options
    intrinsics {}, K refined by the bundle adjustment, not the certified one) verifies stating
    source "given" (a user reads: the calibration was known, not estimated; the critical-motion
    warning's "K was not certified" then reads as moot) or "x". The same check refuses the
    genuine K-given run that registers no view (TestGenuineUnregisteredReconstructionMisread).
    Suggested fix: source is "given" exactly when options.intrinsics gives K, "autocalibration"
    when the returned K is the certified one, "bundle_adjustment" otherwise when a K is returned,
    "none" when none is (or whatever the kind writes, stated once and checked for every word)."""

    def test_the_genuine_result_says_bundle_adjustment(self):
        result = stored("reconstruction")
        assert result["certificate"]["options"]["intrinsics"] == {}
        assert result["summary"]["calibration"]["source"] == "bundle_adjustment"
        assert _valid(result)

    @pytest.mark.parametrize("source", ["given", "x"])
    def test_an_estimated_K_called_given_is_refused(self, source):
        result = stored("reconstruction")
        result["summary"]["calibration"]["source"] = source
        assert not _valid(result)


class TestProjectiveStageCountsPartlyRead:
    """_check_projective_counts bounds the projective stage's views_registered, points and
    observations by the summary's totals; its other counts are read by no check, though
    docs/certificate.md makes only a reconstruction's stage figures "other than its counts"
    informational. The stored reconstruction (96 observations, none removed) verifies with its
    projective stage stating observations_kept 200 (more than were sent) and outliers_removed 7
    (the summary says 0 observations removed), or observations_kept -96. Suggested fix: every
    count the stage states (observations_kept, outliers_removed, observations_of_dropped_tracks,
    observations_of_unregistered_views, focal_rounds' registered, the initial pair's shared and
    inliers) is a non-negative integer at most the total it counts from, and outliers_removed is
    the summary's observations_removed where both say the same thing (or each is documented as
    an informational figure)."""

    @pytest.mark.parametrize("counts", [{"observations_kept": 200, "outliers_removed": 7},
                                        {"observations_kept": -96}])
    def test_counts_beyond_the_data_are_refused(self, counts):
        result = stored("reconstruction")
        stage = next(stage for stage in result["stages"] if stage["name"] == "projective")
        assert stage["observations_kept"] == 96 and stage["outliers_removed"] == 0
        stage.update(counts)
        assert not _valid(result)

    @pytest.mark.parametrize("counts", [{"views": 10, "registered": 10}, {"tracks": -16}])
    def test_a_calibrated_runs_counts_beyond_the_data_are_refused(self, given_K_reconstruction, counts):
        """With K given the projective stage states views, tracks and registered (not the names
        _check_projective_counts reads): 10 of 6 views registered verifies."""
        result = copy.deepcopy(given_K_reconstruction)
        stage = next(stage for stage in result["stages"] if stage["name"] == "projective")
        assert (stage["views"], stage["registered"], stage["tracks"]) == (6, 6, 16)
        stage.update(counts)
        assert not _valid(result)


class TestImageSizeWithKGiven:
    """A camera's image_size is checked against the calibration certificate's (K unknown); with
    K given there is none, and no check reads it: a camera of the K-given reconstruction (image
    640 x 480) verifies stating 961 x 480 or -640 x 480. Suggested fix: the certificate's data
    carries each view's image size (it is input, hashed) and every camera's image_size is
    compared with it whatever the calibration path."""

    @pytest.mark.parametrize("width", [961.0, -640.0])
    def test_an_image_size_not_the_views_is_refused(self, given_K_reconstruction, width):
        result = copy.deepcopy(given_K_reconstruction)
        assert result["cameras"][0]["image_size"] == [640.0, 480.0]
        result["cameras"][0]["image_size"][0] = width
        assert not _valid(result)


class TestCameraStatusWordsUnread:
    """A reconstruction camera's status is checked to be "optimal" exactly when certified and
    "not_run" only without figures; any other word passes. The stored reconstruction's cameras 1
    and 2 (resection not run: each costs 45-48% above a free 3x4 camera, beyond its tolerance, so
    no bound can certify it; the job ran to its end, stats {"optimal": 1}) verify restated as
    "cancelled" (a user reads: the run was stopped before them, not that they fail the camera
    claim) or "node_limit" or "x". The word also counts: the summary's doubtful test
    (reconstruction.verification, claims._doubts) leaves cameras "cancelled" out of the cameras
    bounded, so in a result where more than half the bounded cameras are not certified, calling
    them "cancelled" makes "doubtful" false required (and its warning forbidden). Suggested fix:
    a camera's status is the one its figures give, as the kind writes it (optimal when
    certified; not_certified when judged and not certified; not_run when not judged; cancelled,
    or a search's own stop, only for a camera whose bound search ran and was stopped: searched
    true, as pipelines.reconstruction.claims reads c.bound.status)."""

    @pytest.mark.parametrize("status", ["cancelled", "node_limit", "x"])
    def test_a_camera_not_certifiable_called_otherwise_is_refused(self, status):
        result = stored("reconstruction")
        assert result["stats"]["statuses"] == {"optimal": 1}
        for view in (1, 2):
            assert result["cameras"][view]["status"] == "not_certified"
            result["cameras"][view]["status"] = status
        assert not _valid(result)


class TestDerivedFieldsWithoutTheirSolution:
    """A map's residuals (MapItems.check_returned) and a bilinear frame's shape and residuals
    (FRAMES.check_returned) are recomputed only beside the solution they derive from: a map with
    matrix null, or a frame with coefficients null, has them read by no check. Restated as
    uncertified with that solution withheld (cost, lower_bound, gap null), a certified homography
    verifies returning all-zero residuals (a perfect fit, which no matrix gives on its noisy
    points), and a bilinear frame its camera, a shape 3 times the true one plus 1 and all-zero
    residuals. Suggested fix: residuals and shape are null (or absent) when the solution they
    derive from is not returned; a frame returning a camera without coefficients (or the
    reverse) states neither."""

    @staticmethod
    def zeros(rows: list) -> list:
        return [[0.0] * len(rows[0])] * len(rows)

    def test_a_maps_residuals_without_its_matrix_are_refused(self):
        result = stored("homography3_l2l1")
        forged = _uncertified(result, "maps", 0, cost=None, lower_bound=None, gap=None, matrix=None)
        forged["maps"][0]["residuals"] = self.zeros(forged["maps"][0]["residuals"])
        assert not _valid(forged)

    def test_a_frames_shape_and_residuals_without_its_coefficients_are_refused(self):
        import numpy as np

        result = stored("bilinear_l2l2")
        forged = _uncertified(result, "frames", 0, cost=None, lower_bound=None, gap=None, coefficients=None)
        frame = forged["frames"][0]
        frame["shape"] = (np.array(frame["shape"]) * 3 + 1).tolist()
        frame["residuals"] = self.zeros(frame["residuals"])
        assert not _valid(forged)

    def test_the_same_residuals_beside_the_solution_are_refused(self):
        result = stored("bilinear_l2l2")
        forged = _uncertified(result, "frames", 0, cost=None, lower_bound=None, gap=None)
        forged["frames"][0]["residuals"] = self.zeros(forged["frames"][0]["residuals"])
        assert not _valid(forged)


class TestReconstructionLabelsUntied:
    """What ties a reconstruction's returned point or camera to the caller's input is unchecked
    where the certificate does not carry it. A point's ``track`` (the input track it
    triangulates) is checked only to be distinct and below summary.tracks: points 0 and 1 of the
    stored reconstruction verify with their track numbers swapped (a caller joining points to its
    tracks by that number gets each the other's 3D point; the certificate's own track is the
    point's position, and its observations are checked against that). Likewise a camera's
    ``name`` (the input view's name): cameras 0 and 1 verify with their names swapped (the
    certificate's data has the views' indices, not their names). Suggested fix: the certificate
    data carries each kept track's input index and each view's name (covered by data_sha256),
    and check_result compares points[i].track and cameras[v].name with them.

    Fixed so: the certificate's data carry input_labels (reconstruction_labelled, written by the
    same scene and options as reconstruction once they were stated). A document written before
    (reconstruction) stays checkable, and its report's scope says the labels are unchecked."""

    def test_points_track_numbers_swapped_are_refused(self):
        result = stored("reconstruction_labelled")
        points = result["points"]
        assert [points[0]["track"], points[1]["track"]] == [0, 1]
        points[0]["track"], points[1]["track"] = 1, 0
        assert not _valid(result)

    def test_camera_names_swapped_are_refused(self):
        result = stored("reconstruction_labelled")
        cameras = result["cameras"]
        cameras[0]["name"], cameras[1]["name"] = cameras[1]["name"], cameras[0]["name"]
        assert not _valid(result)

    def test_the_labelled_document_verifies_and_says_its_labels_are_tied(self):
        report = verify_any(stored("reconstruction_labelled"))
        assert report.valid and report.scope["labels"].startswith("each point's track number")

    def test_a_document_without_labels_says_they_are_unchecked(self):
        report = verify_any(stored("reconstruction"))
        assert report.valid and report.scope["labels"].startswith("unchecked")


@pytest.fixture(scope="module")
def radial_reconstruction() -> dict:
    """make_fixtures' six-view scene solved with radial_distortion "on" (K unknown): a genuine
    result whose cameras state k1 and its centre, each image's centre."""
    from geocert.jobs.runner import solve_job
    from geocert.solvers.reconstruction import synthetic

    scene = synthetic.scene(views=6, points=16, seed=3, noise_px=0.5)
    data = reconstruction_data(scene.tracks, scene.image_size, 6)
    result = solve_job({"kind": "reconstruction", "data": data,
                        "options": {"certificate": "full", "radial_distortion": "on"}})
    assert verify_any(result).valid and result["cameras"][0]["k1"] is not None
    return result


class TestDistortionCentreUnread:
    """_check_distortion asks every registered camera to state its radial term k1 (the summary's
    at the camera's focal length) "and its centre", and reads the centre only for presence: the
    summary's statement says the observations were undistorted "about each image's centre"
    ((639/2, 479/2) = (319.5, 239.5) for a 640 x 480 view), yet camera 0 verifies stating the
    centre (324.5, 244.5), a model that undistorts its pixels otherwise than the certificates
    assume. Suggested fix: each camera's distortion_centre is its view's image centre
    ((width - 1) / 2, (height - 1) / 2), the one the points were undistorted about."""

    def test_a_centre_not_the_images_is_refused(self, radial_reconstruction):
        result = copy.deepcopy(radial_reconstruction)
        camera = result["cameras"][0]
        assert camera["distortion_centre"] == [319.5, 239.5]
        camera["distortion_centre"] = [324.5, 244.5]
        assert not _valid(result)


class TestLabelsAndCameraWordsDodged:
    """Attacks on the checks that fixed TestReconstructionLabelsUntied, TestImageSizeWithKGiven and
    TestCameraStatusWordsUnread, as a hostile user would dodge them; each is refused (or, for a
    document without labels, its report says they are unchecked)."""

    @staticmethod
    def rehashed(result: dict) -> dict:
        """Hashed again in the stored document's earlier form (a current-form one would also owe
        the depth-reversal record the stored result predates)."""
        from tests.verify.test_forgeries import rehash

        rehash(result["certificate"], earlier=True)
        return result

    def test_labels_stripped_from_the_data_are_said_unchecked(self):
        result = stored("reconstruction_labelled")
        del result["certificate"]["data"]["input_labels"]
        points = result["points"]
        points[0]["track"], points[1]["track"] = 1, 0
        # the autocalibration stage names the calibration certificate's points by the same labels
        # (calibration_tie holds each to the point so labelled): relabelled alike
        stage = next(stage for stage in result["stages"] if stage["name"] == "autocalibration")
        stage["certificate_tracks"] = [{0: 1, 1: 0}.get(track, track) for track in stage["certificate_tracks"]]
        report = verify_any(self.rehashed(result))
        assert report.scope["labels"].startswith("unchecked")  # valid, and says what it did not check

    @pytest.mark.parametrize("change", [
        lambda labels: labels.pop("track_numbers"),  # one label left out, the others kept
        lambda labels: labels["track_numbers"].__setitem__(1, labels["track_numbers"][0]),  # a duplicate
        lambda labels: labels["view_names"].pop(),  # a view short
        lambda labels: labels["image_sizes"].__setitem__(0, [True, 480.0]),  # a boolean width
        lambda labels: labels.__setitem__("extra", 1)])
    def test_malformed_labels_are_refused(self, change):
        result = stored("reconstruction_labelled")
        change(result["certificate"]["data"]["input_labels"])
        assert not _valid(self.rehashed(result))

    def test_a_track_number_as_a_boolean_is_refused(self):
        result = stored("reconstruction_labelled")
        assert result["points"][1]["track"] == 1
        result["points"][1]["track"] = True
        assert not _valid(result)

    def test_an_image_size_as_booleans_is_refused(self):
        result = stored("reconstruction_labelled")
        labels = result["certificate"]["data"]["input_labels"]
        labels["image_sizes"][0] = [1.0, 1.0]
        result["cameras"][0]["image_size"] = [True, True]
        assert not _valid(self.rehashed(result))

    def test_cameras_called_never_started_in_a_finished_stage_are_refused(self):
        result = stored("reconstruction_labelled")
        next(s for s in result["stages"] if s["name"] == "cameras")["status"] = "cancelled"
        for view in (1, 2):  # not certifiable, not searched; cost withheld
            result["cameras"][view].update(status="cancelled", cost=None)
        assert not _valid(result)

    def test_the_last_cameras_called_cancelled_in_a_job_not_cancelled_are_refused(self):
        result = stored("reconstruction_labelled")
        next(s for s in result["stages"] if s["name"] == "cameras")["status"] = "cancelled"
        for view in (4, 5):  # the last the stage starts (16 points each, the latest views)
            result["cameras"][view].update(status="cancelled", certified=False, searched=False, **dict.fromkeys(
                ("cost", "lower_bound", "gap", "optimal_cost")))
        assert not _valid(result)


class TestFinishedRunRestatedAsCancelled:
    """No document proves whether a cancel came. A finished run restated as cancelled (the job's
    stats {"cancelled": 1}, the cameras stage cancelled, its last two cameras (views 4 and 5, the
    last it starts) never started: no figures, their maps dropped from the camera certificate and
    it rehashed, the summary's and stage's counts to match) verified, and the doubtful test left
    cameras called cancelled out of the cameras it counts: in a result whose last cameras are the
    uncertified ones, such a restatement turned a doubtful reconstruction sound. Fixed so: every
    camera the cameras stage took up counts (a stopped one as not certified), in the writer
    (claims._doubts) and the verifier alike; here 4 of the 6 cameras taken up are then not
    certified, so the forged summary's "doubtful": false is refused. (The false history itself
    stays unprovable either way: it only withholds claims.)"""

    def test_a_stop_does_not_make_the_rig_look_sounder(self):
        result = stored("reconstruction_labelled")
        assert result["summary"]["doubtful"] is False
        for view in (4, 5):
            result["cameras"][view].update(status="cancelled", certified=False, searched=False, **dict.fromkeys(
                ("cost", "lower_bound", "gap", "optimal_cost", "degrees_of_freedom", "tolerance")),
                bound_reason="the job was cancelled")
        camera_certificate = result["camera_certificate"]
        camera_certificate["items"] = camera_certificate["items"][:2]
        camera_certificate["data"]["maps"] = camera_certificate["data"]["maps"][:2]
        TestLabelsAndCameraWordsDodged.rehashed({"certificate": camera_certificate})
        stage = next(s for s in result["stages"] if s["name"] == "cameras")
        stage.update(status="cancelled", certified=2, searched=2, cameras_not_started=2)
        result["summary"].update(cameras_certified=2, cameras_certified_fraction=2 / 6)
        result["stats"]["statuses"] = {"cancelled": 1}
        report = verify_any(result)
        assert not report.valid and "doubtful" in report.first_failure["detail"], report.first_failure


class TestFailedStageWithItsSolution:
    """An autocalibration stage may say "failed" (a word about the solver: no plane, K or
    quadric found), and the status rule lets it. A certified metric stage restated as failed,
    its K kept and its cost stated, verified with the rule alone: "failed" over a solution the
    verifier costs is false. Fixed so: a failed item returns no solution."""

    def test_a_failed_stage_returning_its_solution_is_refused(self):
        result = stored("autocalibration_stratified")
        forged = _uncertified(result, "stages", 1, status="failed", cost=result["stages"][1]["cost"],
                              lower_bound=None, gap=None)
        assert not _valid(forged)


class TestUnregisteredCameraStatusUnread:
    """A camera not registered returns no camera and claims nothing, and its status was read by
    no check: one of the K-given run that registers no view verified (as far as its cameras go)
    saying "optimal". Fixed so: its status is not_run, as the kind writes it."""

    def test_an_unregistered_camera_called_optimal_is_refused(self):
        from geocert.verify.reconstruction import _check_cameras
        from geocert.core.strict import Invalid

        result = TestGenuineUnregisteredReconstructionMisread.unregistered()
        cameras = result["cameras"]
        assert all(c["status"] == "not_run" for c in cameras)
        _check_cameras(cameras, result["certificate"]["data"])  # the genuine cameras pass
        cameras[0]["status"] = "optimal"
        with pytest.raises(Invalid):
            _check_cameras(cameras, result["certificate"]["data"])

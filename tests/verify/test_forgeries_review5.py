"""A fifth hostile review of the verifier (issue 33): each class below is a false claim that
``verify_any`` accepts today, built from a genuine stored certificate (tests/data/certificates) or
genuine solver output (geocert.jobs.runner.solve_job with certificate "full"). Each forgery test asserts
the sound outcome, so it xfails (strict) until the verifier gives it; beside it, the true claim the
forgery starts from verifies. Each class's docstring says what is accepted, how false it is, and a
suggested fix."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored

ACCEPTED = "accepted today: see the class's docstring"
XFAIL = {"strict": True, "reason": ACCEPTED, "raises": AssertionError}


def _valid(document: dict) -> bool:
    return verify_any(document).valid


# The stored stratified autocalibration's projective frame with its world shrunk: cameras' fourth
# columns divided by this, points' last coordinates multiplied by it (no projection changes), so
# the metric points, centres and translations the upgrade gives are of order 1e-9. (3e5 did it in
# the frame of the reference as given; the unit reference frame's world is 2^14 times larger
# there, the shrink moving the reference's largest entry off its fourth column: 3e9 now, points
# at about 9e-9 and centres at about 1.3e-8.)
WORLD_SHRINK = 3e9


@pytest.fixture(scope="module")
def small_world() -> dict:
    """A genuine stratified autocalibration of the stored data in a frame whose metric world is
    of order 1e-9 (both stages certified, the result verifies)."""
    from geocert.jobs.runner import solve_job

    certificate = stored("autocalibration_stratified")["certificate"]
    data = certificate["data"]
    shrink = np.diag([1.0, 1.0, 1.0, WORLD_SHRINK])
    cameras = [(np.asarray(P) @ np.linalg.inv(shrink)).tolist() for P in data["cameras"]]
    points = (np.asarray(data["points"]) @ shrink).tolist()
    result = solve_job({"kind": "autocalibration", "data": {"cameras": cameras, "points": points,
                                                            "image_size": data["image_size"]},
                        "options": dict(certificate["options"])})
    assert all(stage["certified"] for stage in result["stages"])
    return result


class TestDerivedFieldsAbsoluteFloor:
    """(Refused now: each array is compared at its own scale, a list of records' fields each at
    its largest over the records, autocalibration.verification._close.) An autocalibration result's `cameras` and `points` (and `upgrade`, `Ks` for the direct
    method) must be what the certified plane and K (or quadric) give, compared by
    autocalibration.verification._close: within 1e-9 of max(|expected entry|, 1.0). The floor 1.0
    makes it an absolute 1e-9 for every entry smaller than 1, and the world's scale is the data's
    choice: a projective frame with the cameras' fourth columns divided by 3e5 and the points'
    last coordinates multiplied by it (same images, same certified K) puts the metric points at
    about 5e-9 and the centres at about 6e-9. There a result with every point pulled 0.9e-9 towards
    the reference camera, its small coordinates mirrored (a relative change of 200%), and every
    camera's centre and translation moved by 0.9e-9 (15% to 50%) verifies: a metric structure
    and camera layout the certified upgrade does not give. Suggested fix: compare each derived
    array relative to its own largest entry (a points list to its largest coordinate, a camera's
    t and centre to its own, as reconstruction ties K [R | t] to P), with no absolute floor a
    document can choose its way under; or state the returned structure's tolerance in the
    report's scope."""

    def test_the_genuine_small_world_verifies(self, small_world):
        """Since the stratified frame brings the world to unit scale (world_scale), the returned
        metric world no longer follows the data's: these data's is of order 1e-2, not 1e-9."""
        assert _valid(small_world)
        assert np.max(np.abs(np.asarray(small_world["points"]))) > 1e-4

    @staticmethod
    def forged(result: dict) -> dict:
        """The review's edit at the returned world's scale (its points' largest coordinate over
        the 5e-9 they had): every point pulled 0.18 of it, small coordinates mirrored."""
        unit = np.max(np.abs(np.asarray(result["points"]))) / 5e-9
        forged = copy.deepcopy(result)
        forged["points"] = [[-x if abs(x) < 5e-10 * unit else x, -y if abs(y) < 5e-10 * unit else y, z - 0.9e-9 * unit]
                            for x, y, z in result["points"]]
        for camera in forged["cameras"]:
            camera["center"] = [c + 0.9e-9 * unit for c in camera["center"]]
            camera["t"] = [c - 0.9e-9 * unit for c in camera["t"]]
        return forged

    def test_the_forgery_is_false(self, small_world):
        given, forged = np.asarray(small_world["points"]), np.asarray(self.forged(small_world)["points"])
        assert np.max(np.abs(forged - given) / np.abs(given)) > 1.0  # some coordinate's sign flipped

    def test_points_and_centres_not_the_upgrades_are_refused(self, small_world):
        assert not _valid(self.forged(small_world))


def _one_track_uncertified() -> dict:
    """The stored L2L2 triangulation with track 0 restated, truly, as not certified (its point
    and cost kept, no bound): a genuine weaker result that verifies."""
    from tests.verify.test_forgeries_review3 import _uncertified

    result = stored("triangulation_l2l2")
    track = result["tracks"][0]
    return _uncertified(result, "tracks", 0, point=track["point"], cost=track["cost"], lower_bound=None, gap=None)


class TestMembersNoKindWrites:
    """A certificate document's members, and every proof record's, are a closed set (verify.
    CERTIFICATE_MEMBERS, strict.record: "a field no check reads is not a place to hide what a
    reader might take for part of the proof"). A result's and its items' are not: any member the
    kind never writes is carried unread. A triangulation result with track 0 not certified
    verifies with a top-level `"status": "optimal"`, `"certified": true` and `"summary":
    {"points": 6, "points_certified": 6}` (5 of 6 are), with track 0 stating `"verified": true`
    and `"proven_lower_bound"` equal to its cost (nothing proves any bound of it); and with a
    `maps` list holding a "certified, optimal" identity homography of cost 0 that no certificate
    item proves; and a job document whose status is "succeeded" with an `error` saying the
    solve failed. Each is the shape of a member other kinds write and the verifier ties there
    (autocalibration's `status`, reconstruction's `summary` and cameras' `certified`), so a reader
    of one kind's results has every reason to trust it in another's. Suggested fix: a result's
    members, and its items', are the kind's (the kinds' result schemas, listed in the verifier's
    registry), any other refused as strict.record refuses one in a proof; or the report lists
    the members it did not read."""

    def test_the_genuine_weaker_result_verifies(self):
        assert _valid(_one_track_uncertified())

    def test_a_headline_no_kind_writes_is_refused(self):
        forged = _one_track_uncertified()
        forged.update(status="optimal", certified=True, summary={"points": 6, "points_certified": 6})
        assert not _valid(forged)

    def test_an_items_proven_bound_no_kind_writes_is_refused(self):
        forged = _one_track_uncertified()
        track = forged["tracks"][0]
        track.update(verified=True, proven_lower_bound=track["cost"])
        assert not _valid(forged)

    def test_a_succeeded_job_stating_an_error_is_refused(self):
        """check_job reads a job document's kind, status and progress; its `error` (the
        service's, null for a job that succeeded) is not read: a succeeded job saying the solver
        failed and the certificate is not valid verifies."""
        job = {"id": "job", "kind": "triangulation", "status": "succeeded", "result": stored("triangulation_l2l2"),
               "error": {"type": "about:blank", "title": "Solver failed", "status": 500,
                         "detail": "the certificate did not verify"}}
        assert not _valid(job)

    def test_items_of_another_kind_beside_the_proven_ones_are_refused(self):
        forged = stored("triangulation_l2l2")
        forged["maps"] = [{"matrix": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "certified": True,
                           "status": "optimal", "cost": 0.0, "lower_bound": 0.0, "gap": 0.0}]
        assert not _valid(forged)


def _track_cost(document: dict, index: int, point: list) -> float:
    """What ``point`` costs on track ``index`` of a triangulation certificate's data (the
    verifier's own recomputation, verify._check_residual_claim's)."""
    from geocert.core.geometry import norm_cost
    from geocert.verify.checks import _adapter

    adapter = _adapter("triangulation")
    item = adapter.item(adapter.read(document["data"], index), document["options"]["norm"])
    residuals, _, _ = item.raw_residuals(item.solution({"point": point, "at_infinity": False}))
    return float(norm_cost(residuals, document["options"]["norm"]))


class TestGapsUncapped:
    """(Refused now: every kind caps rel_gap at 0.5 (fractional.options.MAX_REL_GAP) and abs_gap in
    its cost's units (each options module's MAX_ABS_GAP, after review 6: the shared cap of 1 was as
    large as whole kinds' costs), as input and in the verifier's reading of the options.) A reconstruction's options cap rel_gap at 0.5 and abs_gap at 1 (reconstruction.verification:
    "at rel_gap 0.999 'certified' would hold whatever a point costs"). The other kinds take any
    abs_gap >= 0 and rel_gap up to 1 (fractional.options.OPTION_RANGES, likewise bilinear and
    autocalibration), so a document whose options say abs_gap 1e300 (or rel_gap 1) calls every
    item "optimal" and certified through a trivial proof (lower_bound 0, gap = cost): the stored
    L2L2 triangulation with every point moved 5 units verifies, each track "certified optimal" at
    a cost of 4.9e5 to 1.1e6 where its optimum is about 14 (35,000 to 80,000 times it). What the
    report states is true (no solution costs below 0), and the options are hashed, so a reader
    who compares problem_sha256 with their own request sees the change; but the status word and
    `certified` a user reads first say "optimal" of a point that is not, and nothing in the report
    says the tolerance exceeds the cost. Suggested fix: cap the gaps for every kind as for a
    reconstruction (rel_gap < 1, say at most 0.5; abs_gap at most a bound the kind states in its
    own units), or refuse "optimal" for an item whose tolerance is not below its cost (it is then
    proven nothing beyond 0)."""

    @staticmethod
    def forged(abs_gap: float, rel_gap: float) -> dict:
        result = stored("triangulation_l2l2")
        document = result["certificate"]
        document["options"].update(abs_gap=abs_gap, rel_gap=rel_gap)
        for index, (track, claim) in enumerate(zip(result["tracks"], document["items"])):
            point = [x + 5.0 for x in track["point"]]
            cost = _track_cost(document, index, point)
            for record in (track, claim):
                record.update(point=point, cost=cost, lower_bound=0.0, gap=cost)
            claim["proof"] = {"type": "trivial"}
            track["certificate"] = track["determinacy"] = None
        from tests.verify.test_forgeries import rehash

        rehash(document)
        return result

    def test_the_forgery_is_false(self):
        genuine, forged = stored("triangulation_l2l2"), self.forged(1e300, 1e-3)
        for track, true in zip(forged["tracks"], genuine["tracks"]):
            assert track["cost"] > 1000 * true["cost"]

    @pytest.mark.parametrize("abs_gap, rel_gap", [(1e300, 1e-3), (1e-7, 1.0)])
    def test_optimal_at_any_cost_is_refused(self, abs_gap, rel_gap):
        assert not _valid(self.forged(abs_gap, rel_gap))


class TestRepeatedNames:
    """(Refused now: the CLI and the verify route read the text with strict.load_document, which
    refuses a repeated name.) `geocert verify` (cli.cmd_verify) and POST /v1/certificates/verify parse with json.loads,
    which keeps the last of a repeated member name silently. RFC 8259 (4) leaves a repeated name's
    meaning to each parser ("many implementations report the last name/value pair only", others
    the first or an error), so one text can hold two results: the stored L2L2 triangulation's
    text with a first `tracks` member prepended, each track "certified optimal" at a tenth of its
    true cost and with a lower bound 0, verifies (exit 0): the verifier read the second `tracks`,
    a reader keeping the first reads claims nothing proves. A trust boundary should not depend
    on which of two parsers a reader uses. Suggested fix: parse documents (CLI, API body of the
    verify route) with an object_pairs_hook refusing a repeated name (exit 2; 422 naming it),
    as streamed.split_items already treats a repeated key as unexpected."""

    @staticmethod
    def text() -> str:
        import json

        result = stored("triangulation_l2l2")
        first = copy.deepcopy(result["tracks"])
        for track in first:
            track.update(cost=track["cost"] / 10, lower_bound=0.0, gap=track["cost"] / 10)
        return '{"tracks": ' + json.dumps(first) + ", " + json.dumps(result)[1:]

    def test_the_verifier_reads_the_last(self, tmp_path):
        import json

        document = json.loads(self.text())
        assert document["tracks"] == stored("triangulation_l2l2")["tracks"]

    def test_a_repeated_name_is_refused(self, tmp_path, capsys):
        from geocert.app.cli import main

        path = tmp_path / "repeated.json"
        path.write_text(self.text())
        assert main(["verify", str(path)]) != 0


class TestProjectiveStageNestedCountsUnread:
    """(Refused now: reconstruction.verification._check_nested_counts.) The fourth review's count class (test_forgeries_review4.TestProjectiveStageCountsPartlyRead)
    named, beside the projective stage's top-level counts, its "focal_rounds' registered, the
    initial pair's shared and inliers"; _check_projective_counts now bounds the top-level ones
    only. The stored reconstruction (6 views, 16 tracks) verifies with its last focal round
    stating 7 views registered, the initial pair's search stating 17 inliers of 17 shared
    observations (16 tracks: at most 16 are shared by two views), and the initial pair naming
    views 5 and 6 (there is no view 6). docs/certificate.md calls only the stage figures "other
    than its counts" informational. Suggested fix: bound every count the stage states, nested
    ones included (focal_rounds[].registered at most the views, the pair's inliers <= shared <=
    tracks), and the view numbers it names (initial_pair, initial_pair_search.pair.views, merged)
    to the result's views; or document these as informational."""

    def test_the_genuine_result_verifies(self):
        assert _valid(stored("reconstruction"))

    @staticmethod
    def projective(result: dict) -> dict:
        return next(stage for stage in result["stages"] if stage["name"] == "projective")

    def test_a_focal_round_registering_more_views_than_exist_is_refused(self):
        result = stored("reconstruction")
        rounds = self.projective(result)["focal_rounds"]
        assert rounds[-1]["registered"] == 6 == result["summary"]["views"]
        rounds[-1]["registered"] = 7
        assert not _valid(result)

    def test_an_initial_pair_sharing_more_than_the_tracks_is_refused(self):
        result = stored("reconstruction")
        pair = self.projective(result)["initial_pair_search"]["pair"]
        assert pair["shared"] == 16 == result["summary"]["tracks"]
        pair.update(shared=17, inliers=17)
        assert not _valid(result)

    def test_an_initial_pair_of_a_view_that_does_not_exist_is_refused(self):
        result = stored("reconstruction")
        stage = self.projective(result)
        assert stage["initial_pair"] == [4, 5]
        stage["initial_pair"] = stage["initial_pair_search"]["pair"]["views"] = [5, 6]
        assert not _valid(result)


class TestReconstructionStageRestatementsUnread:
    """(Refused now: _proven_calibration compares every restated figure, the name by position and the method; the cameras stage's degrees_of_freedom is the cameras'.) A reconstruction's autocalibration stage restates the calibration certificate's stages
    (`stages/autocalibration/stages`: name, status, certified, cost, lower_bound, gap) and its
    method; the cameras stage states the degrees of freedom every camera's tolerance comes from.
    _proven_calibration compares each restated stage's `certified`, `cost` and `lower_bound` with
    the certificate's claims, and nothing else: the stored reconstruction verifies with its metric
    stage's gap 0.5 (its cost less its lower bound is 9.6e-29; the certificate's claim says so), or
    -1 (a negative gap), or its status "infeasible" beside `certified: true`, or named "direct";
    with the autocalibration stage's method "direct" (the calibration certificate is stratified,
    and docs/certificate.md says a K the direct method certified is never claimed certified in a
    reconstruction); and with the cameras stage stating 10 degrees of freedom where every camera
    states (and the verifier recomputes) 6. Suggested fix: compare every field a restated stage
    holds with the claim it restates (gap, status, name by position as autocalibration's own
    stages are), the method with the calibration certificate's options, and the cameras stage's
    degrees_of_freedom with the one recomputed for the cameras (or document each as
    informational)."""

    @staticmethod
    def restated(stage: int, **fields) -> dict:
        result = stored("reconstruction")
        calibration = next(s for s in result["stages"] if s["name"] == "autocalibration")
        assert calibration["stages"][1]["gap"] < 1e-20 and calibration["method"] == "stratified"
        if stage is None:
            calibration.update(fields)
        else:
            calibration["stages"][stage].update(fields)
        return result

    def test_the_genuine_result_verifies(self):
        assert _valid(stored("reconstruction"))

    @pytest.mark.parametrize("fields", [{"gap": 0.5}, {"gap": -1.0}, {"status": "infeasible"}, {"name": "direct"}])
    def test_a_restated_metric_stage_not_the_claim_is_refused(self, fields):
        assert not _valid(self.restated(1, **fields))

    def test_a_method_not_the_certificates_is_refused(self):
        assert not _valid(self.restated(None, method="direct"))

    def test_a_cameras_stage_dof_not_the_cameras_is_refused(self):
        result = stored("reconstruction")
        stage = next(s for s in result["stages"] if s["name"] == "cameras")
        assert stage["degrees_of_freedom"] == 6
        assert {c.get("degrees_of_freedom") for c in result["cameras"] if c.get("P") is not None} == {6}
        stage["degrees_of_freedom"] = 10
        assert not _valid(result)


# The focal scale of the forged calibration certificate's cameras, about the image's centre.
FOCAL_SCALE = 1.08


@pytest.fixture(scope="module")
def other_calibration() -> tuple[dict, dict]:
    """(the stored reconstruction, and the same result carrying the genuine calibration
    certificate of another projective reconstruction: its cameras' focal lengths scaled by 8% about
    the principal point, its points the same), the result's calibration fields made the new
    certificate's."""
    from tests.verify.test_calibration_tie import carrying

    result = stored("reconstruction")
    f = FOCAL_SCALE
    scale = np.array([[f, 0.0, 320.0 * (1 - f)], [0.0, f, 240.0 * (1 - f)], [0.0, 0.0, 1.0]])
    data = copy.deepcopy(result["calibration_certificate"]["data"])
    data["cameras"] = [(scale @ np.asarray(P)).tolist() for P in data["cameras"]]
    return result, carrying(result, data)


class TestCalibrationTiedByAMedian:
    """A reconstruction's certified K is the one its calibration certificate proves optimal "for
    the projective reconstruction in that certificate's data (the pipeline's, from the same
    tracks)" (docs/certificate.md); what ties that data to the result is
    reconstruction.verification._tie_calibration_data: the median reprojection error of the
    shared observations within TIE_PX (10 px) or 10 times the returned cameras' own, over at
    least 12 observations. A projective reconstruction the pipeline never made passes it: the
    stored one's calibration data with each camera's focal length scaled by 8% about the image
    centre (S P_i, the same points) reprojects the result's 96 observations at a median of 9.1 px
    (20 px at most; the returned cameras: about 0.5), its own genuine stratified certificate
    certifies a K of focal 860.2 px, and the stored
    reconstruction carrying it (certified_K, the stage's K and stages, the difference recomputed)
    verifies. The pipeline's reconstruction certifies 796.5 px, and on its data (the certified
    plane) the forged K costs 0.21 where the optimum costs 1e-28: the certified K is not
    optimal for the tracks' reconstruction, by 8% of the focal length (the genuine difference from
    the returned K is 0.05%). A median lets half the shared observations lie anywhere, and the
    10 px floor is 20 times these tracks' own error. Suggested fix: tie the calibration data to
    the result exactly where it can be (the pipeline's projective cameras are the registered
    cameras before bundle adjustment: state them, or the transform, in the result and compare), or
    bound every shared observation's error (not the median) by a multiple of the returned
    cameras' own with no pixel floor, and say in the report's scope how far the certified K's
    reconstruction may lie from the result's."""

    def test_the_genuine_result_verifies(self, other_calibration):
        assert _valid(other_calibration[0])

    def test_the_forged_K_is_far_from_the_tracks(self, other_calibration):
        genuine, forged = other_calibration
        true = genuine["summary"]["calibration"]["certified_K"][0][0]
        assert forged["summary"]["calibration"]["certified_K"][0][0] > 1.07 * true

    def test_a_calibration_of_another_reconstruction_is_refused(self, other_calibration):
        assert not _valid(other_calibration[1])


@pytest.fixture(scope="module")
def looser_cameras() -> dict:
    """The stored reconstruction with its certificate's camera_rel_gap 0.5 (was 0.25), its hashes
    untouched, and a genuine camera certificate solved at rel_gap 0.5 over the same maps; each
    searched camera's bound, each camera's tolerance and the camera claim's words made the new
    certificate's."""
    from geocert.jobs.runner import solve_job
    from geocert.formulations.reconstruction import camera_claim

    forged = stored("reconstruction")
    loose = 0.5
    forged["certificate"]["options"]["camera_rel_gap"] = loose
    cameras = forged["camera_certificate"]
    other = solve_job({"kind": "resection", "data": cameras["data"],
                       "options": {**cameras["options"], "rel_gap": loose}})
    forged["camera_certificate"] = other["certificate"]
    searched = [camera for camera in forged["cameras"] if camera.get("searched")]
    for camera, claim in zip(searched, other["certificate"]["items"]):
        assert claim["certified"]
        camera.update(optimal_cost=claim["cost"], lower_bound=claim["lower_bound"],
                      gap=camera["cost"] - claim["lower_bound"])
    for camera in forged["cameras"]:
        if camera.get("tolerance") is not None:
            camera["tolerance"] = camera_claim.tolerance(camera["points"], camera["degrees_of_freedom"], forged["norm"],
                                                         loose)
    statement = camera_claim.statement(forged["norm"], loose)
    forged["summary"]["camera_claim"] = statement
    next(stage for stage in forged["stages"] if stage["name"] == "cameras")["claim"] = statement
    return forged


class TestCameraToleranceUnhashed:
    """problem_sha256 is "everything a claim depends on": "hash your own copy of the problem and
    the options you asked for to confirm that the certificate is about your problem, with your
    scope and tolerance" (docs/certificate.md). A reconstruction's hash covers the points' options
    (norm, max_residual, rel_gap, abs_gap: the reconstruction adapter states no claim_options),
    not camera_rel_gap, which every certified camera's tolerance comes from (1 + tolerance =
    (1 + allowance) / (1 - camera_rel_gap)), nor the other options the verifier reads (intrinsics,
    radial_distortion). The stored reconstruction, asked for with camera_rel_gap 0.25, verifies
    with camera_rel_gap 0.5 and a genuine camera certificate at that gap: each certified camera's
    tolerance is then 1.0 where the request's gives 0.33 (a certified camera may cost twice its
    proven bound, not 1.33 times), and problem_sha256 is still the request's, so a user checking
    the hash against their own request is told the document is about their problem with their
    tolerance. (radial_distortion "on" added to a document without it, read as "off", verifies too, hashes
    unchanged.) Suggested fix: the reconstruction's problem hash covers every option a claim or a
    check reads (camera_rel_gap, intrinsics, radial_distortion, the calibration options), through
    a claim_options of its adapter (read both hashes for stored version 2 documents, or say in
    the report that these options are unhashed)."""

    def test_the_hash_is_the_requests(self, looser_cameras):
        genuine = stored("reconstruction")["certificate"]
        assert looser_cameras["certificate"]["problem_sha256"] == genuine["problem_sha256"]
        tolerances = [c["tolerance"] for c in looser_cameras["cameras"] if c.get("certified")]
        assert tolerances and all(t == pytest.approx(1.0) for t in tolerances)

    def test_a_camera_tolerance_the_hash_does_not_cover_is_stated(self, looser_cameras):
        """The stored document's hash has the earlier form, which cannot tell 0.5 from the 0.25
        asked for: a third party's stored documents must stay checkable, so it verifies, and the
        report's scope says the hash does not cover camera_rel_gap and states the 0.5 every
        certified camera's tolerance is read at (its claim, so read, is true). In the current
        form the hash covers it (tests/solvers/reconstruction/test_reconstruction_hash.py)."""
        report = verify_any(looser_cameras)
        assert report.valid, report.first_failure
        assert "camera_rel_gap 0.5 (not its default)" in report.scope["problem_sha256"]


def _with_cameras(count: int) -> dict:
    """The stored reconstruction with registered cameras added up to ``count`` (the stored K,
    random rotations, translations about 10 units deep, each camera's fields what its P gives;
    none searched, none observing a point) and its summary's counts made theirs: a result that
    verifies (the cameras added claim nothing)."""
    from scipy.spatial.transform import Rotation

    from tests.verify.test_forgeries import rehash

    result = stored("reconstruction")
    K = np.asarray(result["cameras"][0]["K"])
    rng = np.random.default_rng(0)
    for k, R in enumerate(Rotation.random(count - 6, random_state=1).as_matrix()):
        view, t = 6 + k, rng.normal(size=3) + [0.0, 0.0, 10.0]
        P = K @ np.column_stack([R, t])
        result["cameras"].append({"view": view, "name": f"view{view}", "registered": True, "reason": None,
                                  "image_size": [640.0, 480.0], "P": P.tolist(), "K": K.tolist(), "R": R.tolist(),
                                  "t": t.tolist(), "center": (-R.T @ t).tolist(), "cost": None, "lower_bound": None,
                                  "gap": None, "optimal_cost": None, "certified": False, "status": "not_certified", "bound_reason": None,
                                  "points": 0, "searched": False, "degrees_of_freedom": None, "tolerance": None})
        result["certificate"]["data"]["cameras"].append(P.tolist())
        result["certificate"]["data"]["views"].append(view)
    summary = result["summary"]
    summary.update(views=count, views_registered=count, cameras_certified_fraction=4 / count, doubtful=True)
    summary["warnings"].append({"code": "reconstruction_doubtful", "detail": "most bounded cameras are not certified"})
    next(stage for stage in result["stages"] if stage["name"] == "cameras")["cameras"] = count
    rehash(result["certificate"], earlier=True)  # the stored form: it predates the depth-reversal record
    return result


def _peak_bytes(document: dict) -> tuple[bool, int]:
    """Whether the document verifies, and the verification's peak traced memory (numpy's arrays
    included: they report to tracemalloc)."""
    import tracemalloc

    tracemalloc.start()
    try:
        valid = _valid(document)
        return valid, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


class TestMotionJudgedInSquareMemory:
    """(Memory linear now: the reference view is picked one view at a time, the same sums,
    motion_claim.motion. The judgement is still not charged to the budget, and its time is still
    quadratic in the cameras: about 6,000 cameras are 36 million 3 x 3 differences.) docs/certificate.md: "time and memory are linear in [the document]" (every unit of work
    charged to the document's size, strict.charge). A reconstruction's critical motion is judged
    again by motion_claim.motion on every registered camera, uncharged, and it builds the n x n
    array of rotation differences (R[:, None] - R[None, :], 72 bytes a pair) to pick its
    reference view; nothing bounds the number of cameras (a track's views are bounded, the
    cameras list is not). The stored reconstruction with registered cameras added that claim
    nothing verifies, and its peak memory grows with the square of the cameras: 8 MB at 200
    cameras, 27 MB at 400, 100 MB at 800 (tracemalloc; the test's 300 and 900: 14 and 124 MB for
    a document twice the size), so some 6,000 cameras (a 4 MB document) ask for about 5 GB.
    Suggested fix: pick the reference view in linear memory (a loop over the views, each an n x 9
    difference; or squared chordal sums, 6n - 2 tr(R_i' sum_j R_j), a slightly different rule),
    charge the motion judgement to the budget, and bound a reconstruction's cameras (as the
    autocalibration kind bounds its cameras at 1,000)."""

    def test_memory_is_linear_in_the_cameras(self):
        from geocert.core.strict import document_size

        small, large = _with_cameras(300), _with_cameras(900)
        (small_valid, small_peak), (large_valid, large_peak) = _peak_bytes(small), _peak_bytes(large)
        assert small_valid and large_valid
        growth = document_size(large) / document_size(small)
        assert large_peak <= 2 * growth * small_peak

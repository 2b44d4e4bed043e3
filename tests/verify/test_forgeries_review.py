"""Hostile review of the verifier's checks (issue 33): each class below is a false claim
``verify_any`` accepted when the review ran, built from a genuine document (make_fixtures'
reconstruction through test_forgeries' calibrated_reconstruction fixture, or a stored
certificate). Each test asserts the forgery is refused (each failed on the code the review read);
each class's docstring says what was accepted and how false the claim was."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import (  # noqa: F401 (a fixture, used by name)
    _autocalibration_stage, _cameras_stage, _restate_mirror_angles, calibrated_reconstruction, refused, rehash, stored)


def _stage(result: dict, name: str) -> dict:
    return next(stage for stage in result["stages"] if stage["name"] == name)


def _uncertify_points(result: dict, keep: set) -> dict:
    """Every point but those in ``keep`` called uncertified (its claim too, its proof dropped),
    the counts to match: a true, weaker claim."""
    for index, (point, claim) in enumerate(zip(result["points"], result["certificate"]["items"])):
        if index in keep:
            continue
        point.update(certified=False, status="not_certified", lower_bound=None, gap=None, certificate=None)
        claim.update(certified=False, status="not_certified", lower_bound=None, gap=None)
        claim.pop("proof", None)
    count = sum(point["certified"] for point in result["points"])
    result["summary"].update(points_certified=count, points_certified_fraction=count / len(result["points"]))
    _stage(result, "structure")["certified"] = count
    every = count == len(result["points"])
    result["stats"].update(certified=int(every), statuses={"optimal" if every else "not_certified": 1})
    return result


def _unsearch_cameras(result: dict) -> dict:
    """Every registered camera called not searched and not certified, its figures recomputed on
    the certified points left (camera_claim), and no camera certificate: a weaker claim, as a
    document of the second hash form states it (problem_sha256 over SECOND_CLAIM_OPTIONS, no
    free camera: the judgement "no bound can certify it" unchecked and said so in the report's
    scope; the current form's is recomputed from the free camera it states, which a camera that
    a bound could certify has none of)."""
    from geocert.core.certificates import problem_hash
    from geocert.core.geometry import norm_cost
    from geocert.formulations.reconstruction import camera_claim
    from geocert.verify import hashed_options
    from geocert.verify.checks import checked_options
    from geocert.verify.reconstruction import camera_maps

    registered = [camera for camera in result["cameras"] if camera["registered"]]
    maps = camera_maps(result["points"], registered)
    dof = camera_claim.degrees_of_freedom([camera["K"] for camera in registered])
    options = result["certificate"]["options"]
    for camera, entry in zip(registered, maps):
        source = np.array(entry["source"], dtype=float).reshape(-1, 3)
        target = np.array(entry["target"], dtype=float).reshape(-1, 2)
        image = np.hstack([source, np.ones((len(source), 1))]) @ np.array(camera["P"]).T
        cost = norm_cost(target - image[:, :2] / image[:, 2:3], result["norm"]) if len(source) else 0.0
        camera.pop("free_camera", None)
        camera.update(searched=False, certified=False, status="not_certified", lower_bound=None, gap=None,
                      optimal_cost=None, points=len(source), cost=cost, degrees_of_freedom=dof,
                      tolerance=camera_claim.tolerance(len(source), dof, result["norm"], options["camera_rel_gap"]))
    result["camera_certificate"] = None
    document = result["certificate"]
    document["problem_sha256"] = problem_hash("reconstruction", document["data"],
                                              checked_options("reconstruction", document["options"]),
                                              hashed_options.SECOND_CLAIM_OPTIONS)
    result["summary"].update(cameras_certified=0, cameras_certified_fraction=0.0)
    _cameras_stage(result).update(certified=0, searched=0)
    # every camera bounded and none certified: doubtful (claims._doubts), said first
    if not any(c["certified"] for c in result["cameras"]) and not result["summary"].get("doubtful"):
        result["summary"]["doubtful"] = True
        result["summary"]["warnings"].insert(0, {"code": "reconstruction_doubtful", "detail": "none"})
    return result


def _claim_determined(result: dict) -> dict:
    """K called determined: no critical motion, no warning of one."""
    summary = result["summary"]
    summary["calibration"]["determined"] = True
    summary.update(autocalibration_determined=True, critical_motion=None,
                   warnings=[w for w in summary["warnings"] if w["code"] != "critical_motion"])
    _autocalibration_stage(result).update(determined=True, critical_motion=None)
    return result


def _certified_K_from(result: dict, document: dict) -> dict:
    """``document`` (an autocalibration certificate) put in as the calibration certificate, and
    the summary's certified K, its difference from the returned K, its range edges and the
    autocalibration stage's K and ranges made to agree with it."""
    from geocert.formulations.autocalibration import problem as autocalibration_problem
    from geocert.formulations.reconstruction import calibration_claim

    result["calibration_certificate"] = document
    K = document["items"][1]["K"]
    size = document["data"].get("image_size")
    ranges = autocalibration_problem.resolve_ranges(dict(document["options"].get("intrinsics") or {}),
                                                    None if size is None else tuple(size))
    calibration = result["summary"]["calibration"]
    calibration.update(certified_K=K, difference=calibration_claim.difference(calibration["K"], K),
                       on_range_edge=calibration_claim.on_range_edge(K, ranges))
    _autocalibration_stage(result).update(K=K, intrinsics=ranges)
    return result


def _two_views_registered(result: dict) -> dict:
    """``result`` with views 0 and 1 registered only, every certificate genuine: the points
    triangulated anew in those two cameras (their tracks cut to them), the other views returned
    not registered with a warning, the cameras unsearched, the counts to match. The calibration
    (its certificate of the six views' projective reconstruction) is left as it was."""
    from geocert.jobs.runner import solve_job

    keep = [0, 1]
    certificate = result["certificate"]
    certificate["data"]["cameras"] = [result["cameras"][view]["P"] for view in keep]
    certificate["data"]["views"] = keep
    tracks = []
    for point in result["points"]:
        point["observations"] = [o for o in point["observations"] if o[0] in keep]
        tracks.append({"views": [keep.index(o[0]) for o in point["observations"]],
                       "points": [o[1:] for o in point["observations"]]})
    certificate["data"]["tracks"] = tracks
    own = {name: certificate["options"][name] for name in ("norm", "rel_gap", "abs_gap", "max_residual")}
    solved = solve_job({"kind": "triangulation", "options": {**own, "certificate": "full"},
                        "data": {"cameras": certificate["data"]["cameras"], "tracks": tracks}})
    certificate["items"] = solved["certificate"]["items"]
    for point, track in zip(result["points"], solved["tracks"]):
        point.update({name: track[name] for name in ("point", "at_infinity", "cost", "lower_bound", "gap", "status",
                                                     "certified", "certificate")})
    rehash(certificate)
    for camera in result["cameras"][len(keep):]:
        camera.update({name: None for name in ("K", "R", "t", "center", "P", "cost", "lower_bound", "gap",
                                               "optimal_cost", "degrees_of_freedom", "tolerance")})
        camera.update(certified=False, registered=False, searched=False, status="not_run", reason="not registered",
                      points=0, mirror_rotation_deg=None, pose_determined=None)
    _restate_mirror_angles(result)
    result = _unsearch_cameras(result)
    squared = []
    for point in result["points"]:
        X = np.array([*point["point"], 1.0])
        for view, u, v in point["observations"]:
            image = np.array(result["cameras"][view]["P"]) @ X
            squared.append(float(((image[:2] / image[2] - [u, v]) ** 2).sum()))
    count = sum(point["certified"] for point in result["points"])
    result["summary"].update(views_registered=len(keep), observations=len(squared),
                             rms_reprojection_px=float(np.sqrt(np.mean(squared))), points_certified=count,
                             points_certified_fraction=count / len(result["points"]))
    result["summary"]["warnings"].append({"code": "views_not_registered", "detail": "4 views not registered"})
    _stage(result, "structure")["certified"] = count
    _cameras_stage(result)["cameras"] = len(keep)
    # both cameras left are bounded and uncertified: doubtful (claims._doubts), said first
    result["summary"]["doubtful"] = True
    result["summary"]["warnings"].insert(0, {"code": "reconstruction_doubtful", "detail": "2 of 2"})
    return result


class TestCriticalMotionErasedByUncertifiedPoints:
    """The critical motion behind ``determined`` is judged again (_judged_motion,
    motion_claim.judge) on the certified points only, and the plane at infinity's family is judged
    only when rotation_noise can estimate the noise (12 observations, 3 cameras with 6 each).
    Calling all but one point uncertified (a weaker, true claim), and the cameras unsearched to
    match, leaves too few observations: the judgement finds no critical motion, and the result
    verifies with summary.autocalibration_determined true, critical_motion null and no warning,
    while its own autocalibration stage (and the genuine result) finds a near-critical motion
    whose family of planes at infinity moves K by 35.5% of the focal length. (The converse holds
    too: the weaker result that still warns of its critical motion is refused, "the returned
    cameras' motion gives None".) Likewise with every point certified: views 0 and 1 registered
    alone (the points triangulated anew in them, the other four views returned not registered),
    no motion is judged at all (fewer than 3 cameras), and "determined" verifies beside the
    certified K of the six views' reconstruction."""

    def test_determined_after_the_points_are_uncertified_is_refused(self, calibrated_reconstruction):
        genuine = calibrated_reconstruction
        assert genuine["summary"]["critical_motion"] == "critical_motion"
        weaker = _unsearch_cameras(_uncertify_points(copy.deepcopy(genuine), {0}))
        forged = _claim_determined(weaker)
        assert forged["summary"]["calibration"]["certified"] and not forged["summary"]["calibration"]["on_range_edge"]
        assert refused(forged)["check"] == "returned"

    def test_determined_with_two_views_registered_is_refused(self, calibrated_reconstruction):
        # The calibration's other four views no longer registered, its certificate is tied to
        # nothing there (calibration_tie): refused already, and so is a "determined" beside it.
        weaker = _two_views_registered(copy.deepcopy(calibrated_reconstruction))
        assert weaker["summary"]["points_certified"] == 16
        assert "does not register" in refused(weaker)["detail"]
        assert refused(_claim_determined(weaker))["check"] == "returned"


class TestCalibrationCertificateOptionsUntied:
    """_proven_calibration checks that the calibration certificate is a valid stratified
    autocalibration certificate stating certified_K, but not that it was solved with the result's
    options (intrinsics, autocalibration_rel_gap, metric_rel_gap; abs_gap 1e-12 as the pipeline
    passes it). A certificate of the same projective reconstruction solved with every intrinsic
    pinned (focal 1,500 px, principal point (330, 250): zero-width ranges, which on_range_edge
    skips) is genuine, and makes certified_K focal 1,500 px where the optimum over the result's
    ranges is 796 px (88% off; it costs 4.25 where that optimum costs 1e-28), not on any range's
    edge; with the critical motion erased (above) it verifies as "determined". One with
    metric_rel_gap 1 (or abs_gap 1e6) certifies any K in the box: focal 1,500 px, principal point
    (330, 250), at a cost of 40 against 1e-28."""

    @staticmethod
    def pinned(result: dict) -> dict:
        from geocert.jobs.runner import solve_job

        document = result["calibration_certificate"]
        options = {name: document["options"][name] for name in ("rel_gap", "metric_rel_gap", "abs_gap")}
        pinned = {"focal": [1500.0, 1500.0], "principal_point": [[330.0, 330.0], [250.0, 250.0]],
                  "aspect": [1.0, 1.0], "skew": [0.0, 0.0]}
        return solve_job({"kind": "autocalibration", "data": document["data"],
                          "options": {**options, "intrinsics": pinned, "certificate": "full"}})["certificate"]

    def test_a_calibration_certificate_with_pinned_intrinsics_is_refused(self, calibrated_reconstruction):
        """Pinned ranges now count as the certified K's range edges (calibration_claim): the K is
        the range's, not the tracks', and a claim that does not say so is refused."""
        document = self.pinned(calibrated_reconstruction)
        assert verify_any(document).valid and document["items"][1]["K"][0][0] == 1500.0
        forged = _certified_K_from(copy.deepcopy(calibrated_reconstruction), document)
        assert "focal" in forged["summary"]["calibration"]["on_range_edge"]
        assert refused(forged)["check"] == "returned"  # no certified_K_on_range_edge warning
        forged["summary"]["calibration"]["on_range_edge"] = []
        assert refused(forged)["check"] == "returned"

    def test_pinned_and_called_determined_is_refused(self, calibrated_reconstruction):
        document = self.pinned(calibrated_reconstruction)
        forged = _certified_K_from(copy.deepcopy(calibrated_reconstruction), document)
        forged = _claim_determined(_unsearch_cameras(_uncertify_points(forged, {0})))
        assert refused(forged)["check"] == "returned"

    @pytest.mark.parametrize("options", [{"metric_rel_gap": 1.0}, {"abs_gap": 1e6}])
    def test_a_calibration_certificate_with_a_loose_gap_is_refused(self, calibrated_reconstruction, options):
        from geocert.formulations.autocalibration import metric_relaxation
        from geocert.formulations.autocalibration import problem as autocalibration_problem
        from geocert.verify.autocalibration import read_data

        result = copy.deepcopy(calibrated_reconstruction)
        document = copy.deepcopy(result["calibration_certificate"])
        document["options"].update(options)
        claim = document["items"][1]
        cameras, points, size = read_data(document["data"])
        problem = autocalibration_problem.prepare(cameras, points, size, {})
        plane = autocalibration_problem.plane_from_input(problem, np.array(claim["plane_at_infinity"]))
        setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, plane, problem.unit_ranges)
        K = [[1500.0, 0.0, 330.0], [0.0, 1500.0, 250.0], [0.0, 0.0, 1.0]]
        cost = metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, np.array(K)))
        assert cost > 1e20 * claim["cost"]
        # The genuine proof's bound is 0 (exact data): its leaves need no vector; a unit near 1 for the new cost.
        claim.update(K=K, cost=cost, gap=cost - claim["lower_bound"])
        claim["proof"].update(unit=1.0 / cost, tightening=[])
        rehash(document)
        alone = verify_any(document)  # valid on its own, or refused for a gap beyond every kind's cap
        assert alone.valid or alone.first_failure["check"] == "options"
        forged = _certified_K_from(result, document)
        assert refused(forged)["check"] == "returned"


class TestCalibrationCertificateOfAnotherScene:
    """_proven_calibration does not tie the calibration certificate's data (the projective
    reconstruction it proves K for) to the result: the scope says it is "the pipeline's, from the
    same tracks", and nothing checks it. The autocalibration kind's own example (another scene,
    1000 x 1000 px images) verifies as this result's certified K: focal 1,000 px against the
    scene's 796 (+25.6%), principal point (500, 500), outside this scene's default range
    ([160, 480] x [120, 360]) and 276 px from its own."""

    def test_another_scenes_calibration_certificate_is_refused(self, calibrated_reconstruction):
        document = stored("autocalibration_stratified")["certificate"]
        assert verify_any(document).valid
        forged = _certified_K_from(copy.deepcopy(calibrated_reconstruction), document)
        assert abs(forged["summary"]["calibration"]["difference"]["focal_percent"]) > 20
        assert refused(forged)["check"] == "returned"


class TestUncertifiedItemFigures:
    """An item its result calls uncertified (a search stopped at its node limit, say, whose
    lower_bound the solver does state) is skipped by _verify_items, and _check_returned only
    compares the result's cost, lower_bound and gap with the claim's, which no check reads: a
    triangulation track costing 13.8 verifies stating cost 1e-9 and lower_bound 40 (2.9 times its
    minimum, 13.83), or with status "optimal" (certified false), cost 1e-9 and gap 0; a
    reconstruction's point costing 0.86 verifies stating lower_bound 50 (58 times its cost) or
    cost 1e-9."""

    @staticmethod
    def stopped(item: dict, claim: dict, **figures) -> None:
        for record in (item, claim):
            record.update(certified=False, status="node_limit", **figures)
        claim.pop("proof", None)
        item["certificate"] = None

    @pytest.mark.parametrize("figures", [{"cost": 1e-9}, {"lower_bound": 40.0}])
    def test_a_stopped_tracks_figures_are_true(self, figures):
        result = stored("triangulation_l2l2")
        item, claim = result["tracks"][0], result["certificate"]["items"][0]
        assert item["cost"] < 14 and item["lower_bound"] > 13.8
        cost = figures.get("cost", item["cost"])
        lower = figures.get("lower_bound", item["lower_bound"])
        self.stopped(item, claim, cost=cost, lower_bound=lower, gap=cost - lower)
        result["stats"].update(certified=result["stats"]["certified"] - 1,
                               statuses={"optimal": result["stats"]["items"] - 1, "node_limit": 1})
        assert refused(result)["check"] in ("returned", "objective", "claim")

    def test_an_uncertified_track_called_optimal_is_refused(self):
        result = stored("triangulation_l2l2")
        item, claim = result["tracks"][0], result["certificate"]["items"][0]
        for record in (item, claim):
            record.update(certified=False, status="optimal", cost=1e-9, lower_bound=1e-9, gap=0.0)
        claim.pop("proof")
        item["certificate"] = None
        result["stats"]["certified"] -= 1
        assert refused(result)["check"] in ("returned", "objective", "claim")

    @pytest.mark.parametrize("figures", [{"cost": 1e-9}, {"lower_bound": 50.0}])
    def test_an_uncertified_points_figures_are_true(self, calibrated_reconstruction, figures):
        result = _unsearch_cameras(_uncertify_points(copy.deepcopy(calibrated_reconstruction), set(range(1, 16))))
        point, claim = result["points"][0], result["certificate"]["items"][0]
        cost = figures.get("cost", point["cost"])
        lower = figures.get("lower_bound")
        for record in (point, claim):
            record.update(cost=cost, lower_bound=lower, gap=None if lower is None else cost - lower)
        assert verify_any(_unsearch_cameras(_uncertify_points(copy.deepcopy(calibrated_reconstruction),
                                                              set(range(1, 16))))).valid
        assert refused(result)["check"] in ("returned", "objective", "claim")


class TestBaselineUnread:
    """The baseline a result returns beside the certified solution (the linear estimate: its
    camera and coefficients, or its K, and its cost) is read by no check, and docs/certificate.md
    does not list it among the informational fields: a bilinear frame whose certified optimum is
    proven at least 3.86 verifies beside a baseline said to cost 1.0 (3.9 times below the proven
    bound, where the genuine baseline costs 730), and an autocalibration result beside a baseline
    K of focal 5,000 px (the genuine one: 1,000 px) or a baseline cost 1,000 times below the metric
    stage's proven bound."""

    def test_a_bilinear_baseline_below_the_proven_bound_is_refused(self):
        result = stored("bilinear_l1l1")
        frame = result["frames"][0]
        assert frame["baseline"]["cost"] > 100 * frame["lower_bound"]
        frame["baseline"]["cost"] = 1.0
        assert frame["baseline"]["cost"] < frame["lower_bound"] / 3
        assert refused(result)["check"] == "returned"

    @pytest.mark.parametrize("change", ["cost", "K"])
    def test_an_autocalibration_baseline_not_the_linear_estimate_is_refused(self, change):
        result = stored("autocalibration_stratified")
        baseline = result["baseline"]
        if change == "cost":
            baseline["cost"] = result["stages"][1]["lower_bound"] * 1e-3
        else:
            baseline["K"][0][0] = baseline["K"][1][1] = 5000.0
        assert refused(result)["check"] == "returned"


class TestMapResidualsUnread:
    """A resection's or homography's returned ``residuals`` (one per correspondence, what the
    matrix returned leaves) are read by no check (the maps' adapter has no check_returned; the
    bilinear kind's checks its own): all set to 0, a perfect fit, beside a resection costing 72
    and a homography costing 34, verify."""

    @pytest.mark.parametrize("name", ["resection_l2l2", "homography2_l2l2"])
    def test_residuals_not_the_matrixs_are_refused(self, name):
        result = stored(name)
        item = result["maps"][0]
        assert item["cost"] > 30
        item["residuals"] = [[0.0, 0.0] for _ in item["residuals"]]
        assert refused(result)["check"] == "returned"


class TestResultReadAsItsCertificate:
    """find_certificate reads any document with a ``format`` member as a bare certificate document.
    A result with its certificate's members copied to its own top level (format, version, data,
    options, items and the hashes: the certificate's kind is the result's) is therefore verified as
    a certificate, and none of its returned fields are read: a triangulation result whose track 0
    is moved to (100, 100, 100) and said to cost 1e-9 (its optimum costs 13.8) verifies, as does a
    reconstruction result whose summary says 6/6 cameras certified at an RMS of 0.01 px (the
    genuine: 4/6, 0.54 px) with an uncertified camera called certified."""

    @staticmethod
    def merged(result: dict) -> dict:
        for name, value in result["certificate"].items():
            result.setdefault(name, value)
        return result

    def test_a_triangulation_result_with_its_certificates_members_is_refused(self):
        result = self.merged(stored("triangulation_l2l2"))
        result["tracks"][0].update(point=[100.0, 100.0, 100.0], cost=1e-9)
        assert refused(result)["check"] in ("format", "returned")

    def test_a_reconstruction_result_with_its_certificates_members_is_refused(self, calibrated_reconstruction):
        result = self.merged(copy.deepcopy(calibrated_reconstruction))
        camera = next(c for c in result["cameras"] if c["registered"] and not c["certified"])
        camera.update(certified=True, status="optimal", bound_reason=None)
        result["summary"].update(cameras_certified=6, cameras_certified_fraction=1.0, rms_reprojection_px=0.01)
        assert refused(result)["check"] in ("format", "returned")


class TestAutocalibrationStageFlags:
    """The autocalibration stage's critical_motion, K and intrinsics are tied to the summary and
    the calibration certificate (_check_calibration, _judged_motion), but not its ``determined``
    and ``certified`` flags (docs/certificate.md makes a stage's figures other than its counts
    informational; these are claims, not figures): the stage saying determined true beside a
    critical motion its own motion_warnings describe (K moves by 35.5% along the family), or
    certified false beside a certified K, verifies."""

    @pytest.mark.parametrize("flags", [{"determined": True}, {"certified": False}])
    def test_stage_flags_not_the_summarys_are_refused(self, calibrated_reconstruction, flags):
        forged = copy.deepcopy(calibrated_reconstruction)
        assert forged["summary"]["calibration"]["certified"] and not forged["summary"]["calibration"]["determined"]
        _autocalibration_stage(forged).update(flags)
        assert refused(forged)["check"] == "returned"


class TestAutocalibrationStageBounds:
    """A reconstruction's autocalibration stage states its own stages (affine, metric) with their
    status, certified, cost, lower_bound and gap: the claims the calibration certificate proves,
    but compared with them by no check. The metric stage said to cost 5 with a lower bound of 5
    (proven: 0, the calibration costs 1e-28), or the affine stage uncertified, verifies."""

    @pytest.mark.parametrize("stage, changes", [(1, {"cost": 5.0, "lower_bound": 5.0, "gap": 0.0}),
                                                (0, {"certified": False, "status": "node_limit"})])
    def test_stage_bounds_not_the_certificates_are_refused(self, calibrated_reconstruction, stage, changes):
        forged = copy.deepcopy(calibrated_reconstruction)
        claim = forged["calibration_certificate"]["items"][stage]
        assert claim["certified"] and claim["lower_bound"] < 1e-20
        _autocalibration_stage(forged)["stages"][stage].update(changes)
        assert refused(forged)["check"] == "returned"


class TestDeterminacyCalledProven:
    """``determinacy`` is an estimate outside the certificate, which docs/certificate.md says is
    marked ``"proven": false`` (the solver never writes true) and which the verifier neither reads
    nor checks: flipped to ``"proven": true`` with its intervals narrowed a thousandfold (a
    resection's first parameter "proven" within [-0.7882, -0.7860] where the estimate's interval
    is [-2.14, 0.56]), it verifies, on a map and on an autocalibration stage alike."""

    @staticmethod
    def proven(determinacy: dict) -> None:
        determinacy["proven"] = True
        for interval in determinacy["intervals"]:
            if interval.get("lower") is not None and interval.get("upper") is not None:
                half = (interval["upper"] - interval["lower"]) / 2000
                interval.update(lower=interval["value"] - half, upper=interval["value"] + half)

    @pytest.mark.parametrize("name", ["resection_l2l2", "autocalibration_stratified"])
    def test_a_determinacy_called_proven_is_refused(self, name):
        result = stored(name)
        item = result["maps"][0] if name.startswith("resection") else result["stages"][1]
        assert item["determinacy"]["proven"] is False
        self.proven(item["determinacy"])
        assert refused(result)["check"] in ("returned", "format")


class TestJobStatusesOfOneItem:
    """A kind whose job is one item proving several claims (a reconstruction's points, the
    autocalibration stages) states no status per item (job_outcomes gives None), so _check_stats
    leaves stats.statuses unchecked: {"optimal": 7} beside stats.items 1 verifies."""

    @pytest.mark.parametrize("name", ["autocalibration_stratified", "autocalibration_direct"])
    def test_statuses_counting_more_items_than_the_job_has_are_refused(self, name):
        result = stored(name)
        assert result["stats"]["items"] == 1
        result["stats"]["statuses"] = {"optimal": 7}
        assert refused(result)["check"] == "returned"

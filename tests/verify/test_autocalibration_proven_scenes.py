"""The metric stage's proven intervals (autocalibration.metric_sublevel) on the scenes whose
genuine results the first version's intervals failed (review 5's world shrunk to 1e-9, review 6's
point 1e12 away: their stated intervals were narrower than what the verifier reads off their
leaves, by some 1e-6 px), and on real camera layouts (the Dinosaur's projective cameras; the
dinoSparseRing's and the Model House's layouts, skipped without ../shared/data). Every genuine
result with a full certificate verifies, its intervals hold the ground truth where the truth is
known (the stored scene's K; for the real layouts, with the true plane at infinity: the intervals
are proven for the plane the stage states, and these layouts are critical motions, whose stated
plane is one of a family), and intervals narrower than what the leaves prove are refused."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.verify.checks import verify_any
from tests.support import shared_data
from tests.verify.test_forgeries import estimates_form, rehash, stored
from tests.verify.test_forgeries_review5 import WORLD_SHRINK
from tests.verify.test_forgeries_review6 import far_point_data

NAMES = ("focal_x", "focal_y", "skew", "principal_u", "principal_v")


def intrinsics(K: np.ndarray) -> np.ndarray:
    K = np.asarray(K, float) / K[2][2]
    return np.array([K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]])


def proven_bounds(result: dict) -> np.ndarray:
    document = result["stages"][1]["determinacy"]["proven_intervals"]
    assert [i["name"] for i in document["intervals"]] == list(NAMES)
    return np.array([[i["lower"], i["upper"]] for i in document["intervals"]])


def inside(bounds: np.ndarray, k: np.ndarray) -> np.ndarray:
    return (bounds[:, 0] <= k) & (k <= bounds[:, 1])


def review_data(name: str) -> dict:
    """The job of review 5's or review 6's scene (tests/verify/test_forgeries_review5.small_world,
    test_forgeries_review6.far_point_result), or the stored one they start from."""
    genuine = stored("autocalibration_stratified")
    data = copy.deepcopy(genuine["certificate"]["data"])
    if name == "review5_small_world":
        shrink = np.diag([1.0, 1.0, 1.0, WORLD_SHRINK])
        data["cameras"] = [(np.asarray(P) @ np.linalg.inv(shrink)).tolist() for P in data["cameras"]]
        data["points"] = (np.asarray(data["points"]) @ shrink).tolist()
    elif name == "review6_far_point":
        data = far_point_data()
    return {"kind": "autocalibration", "data": data, "options": dict(genuine["certificate"]["options"])}


# The stored scene is the kind's example: scenes.make_scene(6, 0.0, points=12, seed=11), rounded
# to 7 digits (geocert/kinds/autocalibration.py); its K is the scene's.
def true_K() -> np.ndarray:
    from geocert.solvers.autocalibration import scenes

    return scenes.make_scene(6, 0.0, points=12, seed=11).K


@pytest.fixture(scope="module", params=["stored", "review5_small_world", "review6_far_point"])
def review_result(request) -> dict:
    result = solve_job(review_data(request.param))
    assert [stage["certified"] for stage in result["stages"]] == [True, True]
    return result


def narrowed(result: dict, quantity: int, end: int, fraction: float) -> dict:
    """``result`` with one end of one proven interval moved inwards by ``fraction`` of its width,
    in its proof's sublevel and its determinacy alike (the certificate rehashed): a result
    consistent with itself, stating less than its leaves prove."""
    from geocert.verify.autocalibration import proven_metric

    form = estimates_form(result["certificate"])  # the document's own, kept
    forged = copy.deepcopy(result)
    sublevel = forged["certificate"]["items"][1]["proof"]["sublevel"]
    low, high = sublevel["intervals"][quantity]
    sublevel["intervals"][quantity][end] += (1 if end == 0 else -1) * fraction * (high - low)
    forged["stages"][1]["determinacy"]["proven_intervals"] = proven_metric(sublevel)
    rehash(forged["certificate"], form=form)
    return forged


class TestReviewScenes:
    def test_the_genuine_full_result_verifies_with_its_proven_intervals(self, review_result):
        assert review_result["stages"][1]["determinacy"]["proven"] is True
        report = verify_any(review_result)
        assert report.valid, report.first_failure
        assert {"name": "proven_interval", "passed": 1, "failed": 0} in report.checks

    def test_the_truth_and_the_K_returned_lie_inside_intervals_of_a_pixel(self, review_result):
        """The data are exact but for their 7 digits: the true K (focal 1000 px, principal point
        (500, 500)) costs about what the optimum does, and the intervals are some 1e-3 px wide."""
        bounds = proven_bounds(review_result)
        assert np.all(inside(bounds, intrinsics(true_K())))
        assert np.all(inside(bounds, intrinsics(review_result["K"])))
        assert np.all(bounds[:, 1] - bounds[:, 0] < 1e-2)

    def test_the_intervals_hold_the_verifiers_own_hull(self, review_result):
        """What the verifier reads off the proof (proofs.sublevel_hull at the level, every leaf
        as it reads it) lies inside what the result states, within a thousandth of the width:
        the solver states that hull (the first version read the leaves as its search left them,
        up to 7e-7 px narrower on these scenes)."""
        from geocert.formulations.autocalibration import metric_relaxation
        from geocert.formulations.autocalibration import problem as autocalibration_problem
        from geocert.formulations.autocalibration import proofs
        from geocert.verify.autocalibration import read_data

        certificate = review_result["certificate"]
        claim = certificate["items"][1]
        cameras, points, size = read_data(certificate["data"])
        problem = autocalibration_problem.prepare(cameras, points, size,
                                                  dict(certificate["options"].get("intrinsics") or {}))
        p = autocalibration_problem.plane_from_input(problem, np.array(claim["plane_at_infinity"]))
        setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
        setup.unit = claim["proof"]["unit"]
        cost = max(claim["cost"],
                   float(metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, np.array(claim["K"])))))
        hull = proofs.sublevel_hull(problem, setup, claim["proof"]["sublevel"], cost)
        stated = proven_bounds(review_result)
        assert np.all(stated[:, 0] <= hull[:, 0]) and np.all(hull[:, 1] <= stated[:, 1])
        assert np.all(np.abs(stated - hull) <= 1e-3 * (hull[:, 1:] - hull[:, :1]) + 1e-9 * np.abs(hull))

    @pytest.mark.parametrize("quantity", range(5))
    @pytest.mark.parametrize("end", [0, 1])
    def test_an_interval_narrowed_is_refused(self, review_result, quantity, end):
        first = verify_any(narrowed(review_result, quantity, end, 0.01)).first_failure
        assert first is not None and first["check"] == "proven_interval" and "narrower" in first["detail"]

    def test_an_interval_widened_verifies(self, review_result):
        """A wider interval is a weaker statement the leaves prove as well."""
        assert verify_any(narrowed(review_result, 0, 0, -0.5)).valid

    def test_the_result_stating_other_intervals_than_its_proof_is_refused(self, review_result):
        forged = copy.deepcopy(review_result)
        interval = forged["stages"][1]["determinacy"]["proven_intervals"]["intervals"][3]
        interval["lower"] = 0.5 * (interval["lower"] + interval["upper"])
        first = verify_any(forged).first_failure
        assert first is not None and first["check"] == "returned"


# --- real layouts -----------------------------------------------------------------------------

def dinosaur_job() -> dict:
    """The Oxford Dinosaur's projective cameras and the points of its tracks seen 6 times or more
    (tests/kinds/test_autocalibration_kind.TestOxfordDinosaur), with wide ranges."""
    from geocert.solvers.datasets import load_dinosaur

    cameras, tracks = load_dinosaur(shared_data("oxford_dinosaur"))
    points = []
    for track in tracks:
        if len(track.views) >= 6:
            rows = [x * cameras[v][2] - cameras[v][0] for v, (x, y) in zip(track.views, track.points)]
            rows += [y * cameras[v][2] - cameras[v][1] for v, (x, y) in zip(track.views, track.points)]
            points.append(np.linalg.svd(np.array(rows))[2][-1])
    wide = {"focal": [100, 5000], "aspect": [0.2, 5], "skew": [-200, 200], "principal_point": [[0, 720], [0, 576]]}
    return {"kind": "autocalibration", "data": {"cameras": cameras.tolist(), "points": np.array(points).tolist(),
                                                "image_size": [720, 576]},
            "options": {"intrinsics": wide, "certificate": "full"}}


def sparse_ring():
    """dinoSparseRing's 16 cameras (one K), 100 points of its box seen with 0.5 px of noise, in a
    random projective frame (scenes.from_cameras, seed 0); its focal length (3310 px) is beyond
    the default ranges."""
    from geocert.solvers import datasets
    from geocert.solvers.autocalibration import scenes

    views = datasets.load_middlebury(shared_data("middlebury_dinoSparseRing"))
    return scenes.from_cameras(views.cameras, views.box, 0.5, seed=0, image_size=views.image_size), \
        {"focal": [1000.0, 6000.0]}


def model_house():
    """The Model House's 10 views (their rotations and centres) with its first camera's K for all
    (VGG's own Ks differ from view to view), 100 points, 0.5 px, a random projective frame."""
    from geocert.solvers import datasets
    from geocert.solvers.autocalibration import scenes

    views = datasets.load_vgg_cameras(shared_data("oxford_house"), "house", (768, 576))
    cameras = np.array([views.K[0] @ np.hstack([R, t[:, None]]) for R, t in zip(views.R, views.t)])
    return scenes.from_cameras(cameras, views.box, 0.5, seed=0, image_size=views.image_size), {}


@pytest.fixture(scope="module", params=["dinosaur", "dinoSparseRing"])
def real_result(request) -> tuple[dict, np.ndarray | None]:
    if request.param == "dinosaur":
        return solve_job(dinosaur_job()), None
    scene, ranges = sparse_ring()
    return solve_job({"kind": "autocalibration", "data": scene.job_data(),
                      "options": {"intrinsics": ranges, "certificate": "full"}}), scene.K


class TestRealLayouts:
    def test_the_genuine_full_result_verifies_with_its_proven_intervals(self, real_result):
        result, _ = real_result
        assert result["stages"][1]["certified"] and result["stages"][1]["determinacy"]["proven"] is True
        report = verify_any(result)
        assert report.valid, report.first_failure
        assert {"name": "proven_interval", "passed": 1, "failed": 0} in report.checks
        assert np.all(inside(proven_bounds(result), intrinsics(result["K"])))

    def test_a_truth_costing_within_the_level_for_the_plane_stated_lies_inside(self, real_result):
        """What is proven: every K of the ranges costing at most the level for the stated plane.
        On these critical motions the stated plane is one of a family, and the true K costs 11
        times the level for it (dinoSparseRing: the intervals, focal 1000 to 1075 px, miss the
        true 3310): that is the plane's error, not the intervals'."""
        from geocert.formulations.autocalibration import metric_relaxation
        from geocert.formulations.autocalibration import problem as autocalibration_problem
        from geocert.verify.autocalibration import read_data

        result, K = real_result
        if K is None:  # the Dinosaur's cameras are projective (no true K), and a turntable fixes none:
            bounds = proven_bounds(result)  # the intervals span most of the focal range (100 to 5000 px)
            assert bounds[0, 0] < 1000 and bounds[0, 1] > 4000
            return
        certificate = result["certificate"]
        cameras, points, size = read_data(certificate["data"])
        problem = autocalibration_problem.prepare(cameras, points, size, dict(certificate["options"]["intrinsics"]))
        p = autocalibration_problem.plane_from_input(problem, np.array(result["plane_at_infinity"]))
        setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
        stage = result["stages"][1]
        level = stage["cost"] + stage["determinacy"]["proven_intervals"]["cost_increase"]
        if metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, K / K[2, 2])) <= level:
            assert np.all(inside(proven_bounds(result), intrinsics(K)))

    def test_an_interval_narrowed_is_refused(self, real_result):
        result, _ = real_result
        for quantity, end in ((0, 0), (0, 1), (3, 1)):
            first = verify_any(narrowed(result, quantity, end, 0.01)).first_failure
            assert first is not None and first["check"] == "proven_interval"


@pytest.mark.parametrize("layout", [sparse_ring, model_house], ids=["dinoSparseRing", "model_house"])
def test_with_the_true_plane_the_intervals_hold_the_true_K(layout):
    """The metric stage run for the true plane at infinity (the scene's), its intervals proven at
    its determinacy's cost increase (metric_sublevel.prove) and checked by the verifier's
    proofs.check_sublevel: they hold the true K, all five intrinsics (dinoSparseRing: focal
    3134 to 3395 px about the true 3310; the House: 631 to 665 about 666)."""
    from geocert.solvers.autocalibration import metric, metric_sublevel
    from geocert.formulations.autocalibration import determinacy, proofs
    from geocert.formulations.autocalibration import metric_relaxation
    from geocert.formulations.autocalibration import problem as autocalibration_problem

    scene, ranges = layout()
    problem = autocalibration_problem.prepare(scene.cameras, scene.points, scene.image_size, dict(ranges))
    p = autocalibration_problem.plane_from_input(problem, scene.plane_at_infinity)
    setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
    lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
    bnb = autocalibration_problem.bnb_options(autocalibration_problem.AutocalibrationOptions(), 1e-4)
    stage = metric.solve_metric(setup, lo, hi, bnb, True)
    assert stage.certified
    K = problem.K0 @ autocalibration_problem.upper_triangular_root(metric_relaxation.omega_of(stage.w))
    K = K / K[2, 2]
    cost = float(metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, K)))
    increase = determinacy.metric_stage(problem, p, K, cost, stage.lower_bound, None)["cost_increase"]
    sublevel = metric_sublevel.prove(problem, p, stage.unit, cost, increase, 20.0)
    assert sublevel is not None
    setup.unit = stage.unit
    proofs.check_sublevel(problem, setup, sublevel, cost)  # raises Invalid when refused
    bounds = np.array(sublevel["intervals"])
    assert np.all(inside(bounds, intrinsics(scene.K)))
    assert np.all(inside(bounds, intrinsics(K)))
    assert bounds[0, 1] - bounds[0, 0] < 0.1 * scene.K[0, 0]  # and they say something

"""The direct method on a pixel-scale scene whose cameras all look at one point (an outside user's
trial): without the focal rows (direct.focal_rows) the global minimum of (7.12) there
is a degenerate quadric with f -> 0 (7.3 px against 800), and with chirality "points" no rounded
quadric was feasible. Also: the cameras' centres, the focal rows hold for every calibration within the ranges, exact
scenes certify at the default abs_gap, and the verifier's message for a direct document."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import scenes
from geocert.formulations.autocalibration import direct
from geocert.formulations.autocalibration import direct_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.verify.checks import verify_any

K_TRUE = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])


def pixel_scene(seed: int, noise_px: float, views: int = 12, points: int = 20, distance: float = 4.0):
    """The user's protocol: K_TRUE, cameras on a sphere of radius ``distance`` looking at the origin,
    points in [-1, 1]^3, Gaussian noise of ``noise_px`` pixels, each camera DLT-resected, a random
    Gaussian 4x4 projective frame."""
    rng = np.random.default_rng(seed)
    X = rng.uniform(-1, 1, size=(points, 3))
    Xh = np.hstack([X, np.ones((points, 1))])
    cameras = []
    for _ in range(views):
        d = rng.normal(size=3)
        centre = distance * d / np.linalg.norm(d)
        R = scenes.look_at(centre, np.zeros(3), rng)
        P = K_TRUE @ np.hstack([R, -(R @ centre)[:, None]])
        x = Xh @ P.T
        x = x[:, :2] / x[:, 2:] + rng.normal(scale=noise_px, size=(points, 2))
        Pn = scenes.dlt_resection(Xh, x) if noise_px > 0 else P
        if (Xh @ Pn.T)[:, 2].min() < 0:
            Pn = -Pn
        cameras.append(Pn)
    H = rng.normal(size=(4, 4))
    return {"cameras": [(P @ H).tolist() for P in cameras], "points": (Xh @ np.linalg.inv(H).T).tolist(),
            "image_size": [640, 480]}


def job(data, **options):
    # the direct method keeps time_limit_s (60 s by default): outcomes must not depend on the machine's speed
    return {"kind": "autocalibration", "data": copy.deepcopy(data),
            "options": {"method": "direct", "time_limit_s": 3600, **options}}


@pytest.fixture(scope="module")
def noisy():
    document = job(pixel_scene(1, 0.5), chirality="points", certificate="full")
    return document, solve_job(document)


class TestPixelScale:
    def test_certified_near_the_true_focal_length(self, noisy):
        """Mutation: setup_for without the focal rows (focal=None) returned f = 7.3 px, or with
        chirality "points" no quadric at all (measured before the fix)."""
        _, result = noisy
        stage = result["stages"][0]
        assert stage["certified"], stage["reason"]
        K = np.array(result["K"])
        assert abs(K[0, 0] - 800) < 8 and abs(K[1, 1] - 800) < 8
        assert abs(K[0, 2] - 320) < 8 and abs(K[1, 2] - 240) < 8
        assert stage["gap"] <= 1e-4 * stage["cost"]

    def test_the_certificate_verifies(self, noisy):
        _, result = noisy
        report = verify_any(result)
        assert report.valid, report.first_failure

    def test_each_camera_centre_is_its_metric_camera_s_null_vector(self, noisy):
        """problem.metric_cameras divided t by K[2, 2] before K was normalised, moving each centre by
        its camera's scale (here about 21 times too far out, each by its own factor). Mutation: that
        division put back."""
        document, result = noisy
        H = np.array(result["upgrade"])
        for P, camera in zip(np.array(document["data"]["cameras"]), result["cameras"]):
            M = P @ H
            residual = M @ np.append(camera["center"], 1.0)
            assert np.linalg.norm(residual) <= 1e-9 * np.linalg.norm(M) * max(1.0, np.linalg.norm(camera["center"]))

    def test_the_degenerate_quadric_is_outside_the_focal_rows(self, noisy):
        """The quadric the unconstrained program finds (all cameras' principal axes meet at the
        scene's centre X0: Q ~ X0 X0' plus a little of the true Q*) costs less than the truth but
        breaks the lower focal row."""
        document, result = noisy
        data = document["data"]
        cameras, points = np.array(data["cameras"]), np.array(data["points"])
        problem = autocalibration_problem.prepare(cameras, points, tuple(data["image_size"]), {}, unit_reference=False)
        setup = direct.setup_for(problem, "none")
        Q_in = np.array(result["dual_absolute_quadric"])
        # the point nearest every metric camera's principal axis, in the input frame (metric X = H^-1 X_in)
        A, b = np.zeros((3, 3)), np.zeros(3)
        for camera in result["cameras"]:
            axis, centre = np.array(camera["R"])[2], np.array(camera["center"])
            across = np.eye(3) - np.outer(axis, axis)
            A, b = A + across, b + across @ centre
        X0 = np.array(result["upgrade"]) @ np.append(np.linalg.solve(A, b), 1.0)
        degenerate = direct.rank_three_projection(setup.from_input(1e-3 * Q_in / np.trace(Q_in)
                                                                   + np.outer(X0, X0) / (X0 @ X0)))
        assert direct_relaxation.cost(setup.cameras, degenerate) < 0.2 * result["stages"][0]["cost"]
        assert not direct.within_focal(setup, degenerate)
        assert direct.within_focal(setup, setup.from_input(Q_in))


class TestFocalRows:
    def test_every_calibration_within_the_ranges_meets_them_and_a_shorter_focal_does_not(self):
        """The rows' derivation (direct.focal_rows): random K within the ranges at random poses
        (Q* = diag(1, 1, 1, 0)) meet both rows; f just below the range breaks the lower one.
        Mutation: dropping the aspect factor (1 + a_lo^2) in the lower row fails the second part."""
        rng = np.random.default_rng(0)
        ranges = {"focal": [0.5, 2.0], "aspect": [0.9, 1.1], "skew": [-0.02, 0.02], "u": [-0.1, 0.2],
                  "v": [-0.15, 0.1]}
        Q = np.diag([1.0, 1.0, 1.0, 0.0])

        def camera(f, a, s, u, v):
            K = np.array([[f, s, u], [0.0, a * f, v], [0.0, 0.0, 1.0]])
            R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
            return K @ np.hstack([R, rng.normal(size=(3, 1))])

        inside = [camera(*(rng.uniform(*ranges[name]) for name in ("focal", "aspect", "skew", "u", "v")))
                  for _ in range(200)]
        corners = [camera(f, a, s, u, v) for f in ranges["focal"] for a in ranges["aspect"] for s in ranges["skew"]
                   for u in ranges["u"] for v in ranges["v"]]
        for cams in (inside, corners):
            values = np.einsum("kab,ab->k", direct.focal_rows(np.array(cams), ranges), Q)
            assert values.min() >= -1e-12
        below = [camera(0.98 * ranges["focal"][0], ranges["aspect"][0], 0.0, 0.0, 0.0) for _ in range(5)]
        values = np.einsum("kab,ab->k", direct.focal_rows(np.array(below), ranges), Q)
        assert np.all(values[0::2] < 0)
        above = [camera(1.02 * ranges["focal"][1], ranges["aspect"][1], 0.02, 0.2, -0.15) for _ in range(5)]
        values = np.einsum("kab,ab->k", direct.focal_rows(np.array(above), ranges), Q)
        assert np.all(values[1::2] < 0)


class TestExactScene:
    def test_certifies_at_the_default_tolerance(self):
        """A noise-free scene: cost ~0, and the bound (never below 0: f is a sum of squares) within
        abs_gap's default. Mutation: without the clamp at 0 the bound is -3e-8 or so and it fails."""
        result = solve_job(job(pixel_scene(2, 0.0), chirality="points"))
        stage = result["stages"][0]
        assert stage["certified"], stage["reason"]
        assert stage["lower_bound"] >= 0.0
        assert np.abs(np.array(result["K"]) - K_TRUE).max() < 1e-4


class TestDefaultTolerance:
    def test_the_direct_default_abs_gap_and_the_stratified_one(self):
        direct_gap = autocalibration_problem.AutocalibrationOptions(method="direct").abs_gap
        assert direct_gap == autocalibration_problem.DIRECT_ABS_GAP == 1e-9
        stratified_gap = autocalibration_problem.AutocalibrationOptions().abs_gap
        assert stratified_gap == autocalibration_problem.STRATIFIED_ABS_GAP == 1e-12
        assert autocalibration_problem.AutocalibrationOptions(method="direct", abs_gap=1e-12).abs_gap == 1e-12

    def test_a_low_noise_scene_certifies_at_the_default(self):
        """0.02 px: cost 7.7e-8, the bound 2.2e-10 below it at rank one (the interior point's
        accuracy). Mutation: abs_gap 1e-12 (the former default) leaves it not certified, the reason
        naming the gap's tolerance, not the rank (measured before the change)."""
        result = solve_job(job(pixel_scene(1, 0.02), chirality="points"))
        stage = result["stages"][0]
        assert stage["certified"], stage["reason"]
        assert stage["certificate"]["tolerance"] == pytest.approx(1e-9)
        K = np.array(result["K"])
        assert abs(K[0, 0] - 800) < 1 and abs(K[1, 1] - 800) < 1


class TestVerifierMessage:
    def test_a_direct_result_not_certified_is_not_called_two_stages(self, noisy):
        _, result = noisy
        document = copy.deepcopy(result["certificate"])
        claim = document["items"][0]
        claim["certified"], claim["status"], claim["proof"] = False, "not_certified", None
        claim["lower_bound"] = claim["gap"] = None  # an uncertified claim states no bound (verify.uncertified_claim)
        report = verify_any(document)
        assert not report.valid
        assert "affine" not in report.first_failure["detail"]
        assert report.first_failure["detail"] == "no certified item to check"

    def test_a_result_without_a_quadric_says_nothing_was_certified(self, noisy):
        """A not-certified result with no quadric (as the user's scene gave before the focal rows):
        the verifier said "autocalibration certifies two stages", then (with that fixed) failed
        reading the null quadric as returned. Mutation: either fix undone."""
        _, result = noisy
        result = copy.deepcopy(result)
        stage, claim = result["stages"][0], result["certificate"]["items"][0]
        for item in (stage, claim):
            item.update({"status": "not_certified", "certified": False, "cost": None, "lower_bound": None, "gap": None,
                         "plane_at_infinity": None, "K": None, "dual_absolute_quadric": None})
        claim["proof"] = None
        stage["certificate"]["tolerance_met"] = False
        for name in ("plane_at_infinity", "K", "Ks", "dual_absolute_quadric", "upgrade", "cameras", "points"):
            result[name] = None
        result["stats"]["certified"] = 0  # the job's counts as such a result gives them (verify._check_stats)
        result["stats"]["statuses"] = {"not_certified": 1}
        from geocert.verify.autocalibration import outcome

        result.update(outcome(result))  # and its own status, as its stages give it
        report = verify_any(result)
        assert not report.valid
        assert report.first_failure["detail"] == "no certified item to check"
        result["K"] = K_TRUE.tolist()
        assert verify_any(result).first_failure["detail"] == "K is given, but the direct stage claims no quadric"

    def test_two_items_for_the_direct_method(self, noisy):
        _, result = noisy
        document = copy.deepcopy(result["certificate"])
        document["items"].append({**copy.deepcopy(document["items"][0]), "index": 1, "certified": False,
                                  "status": "not_certified", "lower_bound": None, "gap": None, "proof": None})
        report = verify_any(document)
        assert not report.valid
        assert report.first_failure["detail"] == "the direct method certifies one stage: direct"

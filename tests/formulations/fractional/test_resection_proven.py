"""Proven intervals of a resection's camera centre (fractional.resection_sublevel): every camera of
the scope costing at most the optimum plus the stated cost increase has its centre in them.
Checked against cameras sampled about the optimum, against the truth of synthetic scenes with
known noise, and by the verifier, which refuses an interval it does not recompute (narrowed,
widened, or proven at a lower level than stated) and a result saying proven without it."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.formulations.fractional.resection_sublevel import Scene, proven_centre
from geocert.verify.checks import verify_any

from tests.support import map_job, scene, seed, forged_sublevel, refusal


def resection_job(rng, count: int, noise: float, maps: int = 1, **options) -> tuple[dict, list[np.ndarray]]:
    """A resection job of ``maps`` cameras looking at ``count`` points with Gaussian pixel noise,
    and each camera's true centre."""
    entries, centres = [], []
    for _ in range(maps):
        M, source, target = scene(rng, "resection", count)
        entries.append({"source": source.tolist(),
                        "target": (target + rng.normal(size=target.shape) * noise).tolist()})
        centres.append(-np.linalg.solve(M[:, :3], M[:, 3]))
    job = {"kind": "resection", "data": {"maps": entries},
           "options": {"norm": "L2L2", "certificate": "full", **options}}
    return job, centres


def costs_at(source: np.ndarray, target: np.ndarray, cameras: np.ndarray) -> np.ndarray:
    """The L2L2 costs of cameras (s, 3, 4); inf outside the scope (a point at non-positive depth)."""
    proj = np.einsum("sij,kj->ski", cameras, np.hstack([source, np.ones((len(source), 1))]))
    r = proj[..., :2] / proj[..., 2:3] - target
    return np.where(np.all(proj[..., 2] > 0, axis=1), (r * r).sum(axis=(1, 2)), np.inf)


def centres_of(cameras: np.ndarray) -> np.ndarray:
    return -np.linalg.solve(cameras[:, :, :3], cameras[:, :, 3:])[..., 0]


def intervals_of(document: dict) -> tuple[np.ndarray, np.ndarray]:
    found = document["proven_intervals"]["intervals"]
    return np.array([i["lower"] for i in found]), np.array([i["upper"] for i in found])


@pytest.mark.parametrize("count,noise", [(12, 1.0), (30, 1.0), (200, 2.0)])
def test_every_camera_within_the_increase_has_its_centre_in_the_proven_intervals(count, noise):
    """Cameras walked along rays from the optimum (random directions in the 12 entries, and the
    data's least determined directions, where the set is longest): each costing at most the
    optimum plus cost_increase has its centre inside the intervals, and the walks do reach the
    intervals' ends within a factor (the intervals are not vacuous)."""
    rng = np.random.default_rng(seed("resection proven", str(count), str(noise)))
    job, _ = resection_job(rng, count, noise)
    result = solve_job(job)
    item = result["maps"][0]
    document = item["determinacy"]
    assert item["certified"] and document["proven"] is True
    lower, upper = intervals_of(document)
    source, target = (np.array(job["data"]["maps"][0][key]) for key in ("source", "target"))
    P = np.array(item["matrix"])
    assert np.all(lower <= centres_of(P[None])[0]) and np.all(centres_of(P[None])[0] <= upper)
    level = item["cost"] + document["proven_intervals"]["cost_increase"]
    # The least determined directions: the Gauss-Newton information's smallest eigenvectors.
    h = 1e-7
    base = P.ravel()
    J = []
    for k in range(12):
        step = np.zeros(12)
        step[k] = h
        plus, minus = (base + step).reshape(3, 4), (base - step).reshape(3, 4)
        rp = (np.hstack([source, np.ones((count, 1))]) @ plus.T)
        rm = (np.hstack([source, np.ones((count, 1))]) @ minus.T)
        J.append(((rp[:, :2] / rp[:, 2:] - rm[:, :2] / rm[:, 2:]) / (2 * h)).ravel())
    J = np.array(J).T
    _, _, vt = np.linalg.svd(J)
    # ... and each centre coordinate's extreme direction on the curvature's ellipsoid, S g
    gradient = np.array([(centres_of((base + h * e).reshape(1, 3, 4))[0]
                          - centres_of((base - h * e).reshape(1, 3, 4))[0]) / (2 * h) for e in np.eye(12)]).T
    extreme = (np.linalg.pinv(J.T @ J, rcond=1e-12) @ gradient.T).T
    directions = list(vt[-4:-1]) + [u / np.linalg.norm(u) for u in list(extreme) + list(rng.normal(size=(30, 12)))]
    steps = np.geomspace(1e-7, 1.0, 300)
    reached = np.zeros(3)
    inside = 0
    for u in directions:
        for sign in (1.0, -1.0):
            cameras = base[None] + sign * steps[:, None] * u
            cameras = cameras.reshape(-1, 3, 4)
            within = cameras[costs_at(source, target, cameras) <= level]
            if not len(within):
                continue
            inside += len(within)
            centres = centres_of(within)
            assert np.all(lower <= centres) and np.all(centres <= upper)
            reached = np.maximum(reached, np.abs(centres - centres_of(P[None])[0]).max(axis=0))
    assert inside > 100
    half = 0.5 * (upper - lower)
    assert np.all(reached > half / 5), (reached, half)  # the walks get near the ends


def test_the_proven_intervals_hold_the_truth_at_the_stated_rate():
    """40 synthetic cameras (12 to 60 points, 1 px noise): 3 standard errors' level, so each
    coordinate's interval (a superset of the estimate's, to the curvature's accuracy) holds the
    true centre in at least 99.7% of cases in expectation: at least 119 of 120 here (all 120 when
    measured), and each proven interval holds the estimate's."""
    rng = np.random.default_rng(seed("resection proven", "truth"))
    covered = total = 0
    for _ in range(40):
        job, (truth,) = resection_job(rng, int(rng.integers(12, 61)), 1.0)
        item = solve_job(job)["maps"][0]
        document = item["determinacy"]
        assert item["certified"] and document["proven"] is True
        lower, upper = intervals_of(document)
        covered += int(np.sum((lower <= truth) & (truth <= upper)))
        total += 3
        for proven, estimate in zip(document["proven_intervals"]["intervals"], document["intervals"]):
            assert proven["lower"] <= estimate["lower"] and estimate["upper"] <= proven["upper"]
    assert covered >= total - 1


@pytest.fixture(scope="module")
def proven() -> dict:
    """A full result of two certified cameras, each with a proven interval."""
    rng = np.random.default_rng(seed("resection proven", "forged"))
    job, _ = resection_job(rng, 25, 1.0, maps=2)
    result = solve_job(job)
    assert all("sublevel" in item["proof"] for item in result["certificate"]["items"])
    report = verify_any(result)
    assert report.valid and {"name": "proven_interval", "passed": 2, "failed": 0} in report.checks
    return result


class TestForgedIntervals:
    @pytest.mark.parametrize("coordinate", [0, 1, 2])
    @pytest.mark.parametrize("end,change", [(0, 1e-6), (1, -1e-6), (0, 1e-3), (1, -1e-3), (0, -1e-4), (1, 1e-4),
                                            (0, -0.5), (1, 0.5)])
    def test_a_narrowed_or_widened_interval_is_refused(self, proven, coordinate, end, change):
        intervals = copy.deepcopy(proven["certificate"]["items"][1]["proof"]["sublevel"]["intervals"])
        width = intervals[coordinate][1] - intervals[coordinate][0]
        intervals[coordinate][end] += change * width
        first = refusal(forged_sublevel(proven, intervals=intervals))
        assert first["check"] == "proven_interval" and first["item"] == 1

    @pytest.mark.parametrize("factor", [0.5, 0.1])
    def test_intervals_proven_at_a_lower_level_than_stated_are_refused(self, proven, factor):
        """The intervals a lower level proves, stated at the higher one: narrower than what that
        level proves."""
        source, target = (np.array(proven["certificate"]["data"]["maps"][1][key]) for key in ("source", "target"))
        sublevel = proven["certificate"]["items"][1]["proof"]["sublevel"]
        lower = sublevel["cost_increase"] * factor
        scene_ = Scene(source, target, np.array(proven["certificate"]["items"][1]["matrix"]), sublevel["reference"])
        bounds, _ = proven_centre(scene_, lower, sublevel["radius"], sublevel["rounds"])
        assert np.all(bounds[:, 1] - bounds[:, 0] < np.diff(sublevel["intervals"], axis=1)[:, 0])
        first = refusal(forged_sublevel(proven, intervals=bounds.tolist()))
        assert first["check"] == "proven_interval"
        # ... and the result stating them at the lower level beside its estimate's level
        result = copy.deepcopy(proven)
        result["certificate"] = forged_sublevel(proven, intervals=bounds.tolist(), cost_increase=lower)
        assert refusal(result["certificate"]) is None  # true of the lower level
        stated = result["maps"][1]["determinacy"]["proven_intervals"]
        stated["cost_increase"] = lower
        for entry, (lo, hi) in zip(stated["intervals"], bounds.tolist()):
            entry["lower"], entry["upper"] = lo, hi
        first = refusal(result)
        assert first["check"] == "returned" and "below" in first["detail"]

    def test_a_smaller_radius_is_refused(self, proven):
        radius = proven["certificate"]["items"][1]["proof"]["sublevel"]["radius"] * 0.3
        first = refusal(forged_sublevel(proven, radius=radius))
        assert first["check"] == "proven_interval" and "not proven" in first["detail"]

    @pytest.mark.parametrize("rounds", [0, -1, 33, 1.0])
    def test_rounds_other_than_the_proofs_are_refused(self, proven, rounds):
        assert refusal(forged_sublevel(proven, rounds=rounds))["check"] == "proven_interval"

    @pytest.mark.parametrize("increase", [-1.0, 1e300, 5e-324])
    def test_a_negative_huge_or_subnormal_cost_increase_is_refused(self, proven, increase):
        assert refusal(forged_sublevel(proven, cost_increase=increase))["check"] == "proven_interval"

    def test_a_larger_cost_increase_with_the_same_intervals_is_refused(self, proven):
        increase = proven["certificate"]["items"][1]["proof"]["sublevel"]["cost_increase"] * 4
        assert refusal(forged_sublevel(proven, cost_increase=increase))["check"] == "proven_interval"

    def test_a_field_it_does_not_have_is_refused(self, proven):
        assert refusal(forged_sublevel(proven, note=1.0))["check"] == "format"

    def test_a_result_saying_proven_with_other_intervals_is_refused(self, proven):
        result = copy.deepcopy(proven)
        result["maps"][0]["determinacy"]["proven_intervals"]["intervals"][2]["lower"] -= 1.0
        assert refusal(result)["check"] == "returned"

    def test_a_result_saying_proven_without_a_proof_of_it_is_refused(self, proven):
        result = copy.deepcopy(proven)
        del result["certificate"]["items"][0]["proof"]["sublevel"]
        assert verify_any(result["certificate"]).valid  # the certificate alone proves its bound
        assert refusal(result)["check"] == "returned"
        result["maps"][0]["determinacy"]["proven_intervals"] = None
        assert refusal(result)["check"] == "returned"  # proven: true with nothing proven

    def test_a_homography_proof_stating_an_interval_is_refused(self, proven):
        document = solve_job(map_job(np.random.default_rng(5), "homography2", 8, "L2L2", maps=1))["certificate"]
        assert document["items"][0]["proof"]["type"] == "branch_and_bound"
        document["items"][0]["proof"]["sublevel"] = proven["certificate"]["items"][0]["proof"]["sublevel"]
        assert refusal(document)["check"] == "format"


def test_a_noiseless_camera_certified_by_the_trivial_bound_states_none_and_verifies():
    """Its proof ({"type": "trivial"}) has no place for one: a result saying proven beside it
    would be refused."""
    rng = np.random.default_rng(seed("resection proven", "noiseless"))
    job, _ = resection_job(rng, 12, 0.0)
    result = solve_job(job)
    assert result["certificate"]["items"][0]["proof"]["type"] == "trivial"
    assert result["maps"][0]["determinacy"]["proven_intervals"] is None
    assert verify_any(result).valid


# 20 points drawn in the Middlebury dino's box (metres: a 7 cm object), seen by one of its real
# cameras (f = 3310 px, 0.6 m away; Seitz et al., Middlebury multi-view stereo) with 0.5 px of
# noise: the whitening matrix's inverse Cholesky factor had an entry of 2.7e-39, rounding below
# the moderate range, and no interval was proven.
DINO_CAMERA_SOURCE = [[0.020867, 0.020118, 0.014898], [-0.018347, 0.075594, -0.006647], [-0.016014, 0.036506,
                     0.016051], [0.001929, 0.053116, 0.026583], [-0.035725, 0.08142, -0.0108], [-0.035583,
                     0.054244, -0.015551], [0.020858, 0.032804, -0.032208], [-0.025076, 0.059701, 0.008917],
                     [-0.011026, 0.05154, -0.035159], [-0.024007, 0.003496, 0.016202], [0.024472, 0.007508,
                     -0.022547], [-0.003973, 0.033698, 0.008896], [0.014297, 0.013204, 0.015291], [0.009889,
                     0.071894, -0.031134], [-0.033323, 0.083275, -0.012489], [0.019446, 0.001871, 0.016731],
                     [0.022024, 0.018816, 0.004861], [-0.040429, 0.002159, 0.025139], [0.025188, 0.051654,
                     0.021281], [-0.009046, 0.026321, -0.017053]]
DINO_CAMERA_TARGET = [[346.376, 124.992], [152.622, 211.203], [341.142, 103.829], [232.178, 52.171], [152.773,
                     229.715], [288.458, 260.913], [282.5, 352.533], [246.596, 131.415], [252.47, 364.511],
                     [512.152, 110.346], [390.382, 308.572], [330.177, 145.293], [389.594, 124.557], [118.666,
                     340.462], [137.161, 238.253], [430.993, 121.955], [349.224, 173.813], [556.36, 60.381],
                     [198.342, 87.367], [370.206, 277.49]]


def test_a_real_small_scale_camera_is_proven_and_verifies():
    result = solve_job({"kind": "resection", "data": {"maps": [
        {"source": DINO_CAMERA_SOURCE, "target": DINO_CAMERA_TARGET}]}, "options": {"certificate": "full"}})
    assert result["maps"][0]["certified"] and result["maps"][0]["determinacy"]["proven"] is True
    report = verify_any(result)
    assert report.valid and {"name": "proven_interval", "passed": 1, "failed": 0} in report.checks


def test_under_the_l1_norms_the_proven_intervals_are_the_depth_rows_read_off_leaves():
    """The depth row's, read off a search's leaves (fractional.resection_leaves;
    tests/solvers/fractional/test_resection_leaves.py), then the centre's at the same level, from
    this module's enclosure and rounds with the L1 cost's inequalities
    (fractional.resection_centre_l1; tests/solvers/fractional/test_resection_centre_l1.py)."""
    rng = np.random.default_rng(seed("resection proven", "norms"))
    job, _ = resection_job(rng, 12, 1.0, norm="L2L1")
    result = solve_job(job)
    stated = result["maps"][0]["determinacy"]["proven_intervals"]
    assert [i["name"] for i in stated["intervals"]] == ["depth_x", "depth_y", "depth_z", "depth_0",
                                                        "centre_x", "centre_y", "centre_z"]
    assert "search" in result["certificate"]["items"][0]["proof"]["sublevel"]
    assert verify_any(result).valid

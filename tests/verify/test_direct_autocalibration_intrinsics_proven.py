"""The direct stage's proven intervals of its other intrinsics (direct_intrinsics): with
``prove_intrinsics_intervals`` a certified one-K stage's determinacy states, beside the focal
length's, proven intervals of principal_u, principal_v, focal_y, skew and aspect over every quadric
of its scope costing at most cost_increase more than the certified one, each end a dual of the
order-2 relaxation of min sign (N - c D) with the cost row; the verifier recomputes every end and
refuses a narrowed interval, a forged dual, an end stated where none is proven, intervals stated
without their proof and a proof the options did not ask for."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import scenes
from geocert.core.certificates import pack, unpack
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import rehash

UNIT = {"aspect": [0.95, 1.05], "skew": [-0.01, 0.01], "principal_point": [[-0.1, 0.1], [-0.1, 0.1]],
        "focal": [0.5, 2.0]}
NAMES = ["principal_u", "principal_v", "focal_y", "skew", "aspect"]


def test_the_ratios_read_K_off_its_DIAC():
    """Each ratio at a quadric whose views all see K (W = mean P Q P' proportional to K K') is K's
    own: u, v, (a f)^2, s / (a f) and a^2 (fails without direct_intrinsics)."""
    from geocert.formulations.autocalibration import direct_intrinsics

    rng = np.random.default_rng(3)
    K = np.array([[1.1, 0.02, 0.05], [0.0, 1.1 * 0.97, -0.03], [0.0, 0.0, 1.0]])
    H = np.eye(4)
    H[:3, :3] = K
    cameras = []
    for _ in range(5):  # P = [R | t] H^-1 sees Q = H diag(1, 1, 1, 0) H' as K K'
        R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        cameras.append(K @ np.hstack([R, rng.normal(size=(3, 1))]) @ np.linalg.inv(H))
    cameras = np.array([P / np.linalg.norm(P) * np.sqrt(3) for P in cameras])
    Q = H @ np.diag([1.0, 1.0, 1.0, 0.0]) @ H.T
    Q = Q / np.trace(Q)
    forms = direct_intrinsics.ratios(cameras)
    f, s, u, a_f, v = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    expected = {"u": u, "v": v, "fy2": a_f ** 2, "t": s / a_f, "a2": (a_f / f) ** 2}
    for name, value in expected.items():
        assert forms[name].at(Q) == pytest.approx(value, rel=1e-9, abs=1e-12), name


def test_asking_with_varying_focal_is_refused():
    from geocert.formulations.autocalibration.problem import AutocalibrationOptions
    from geocert.core.geometry import InputError

    options = AutocalibrationOptions(method="direct", varying_focal=True, prove_intrinsics_intervals=True)
    with pytest.raises(InputError) as raised:
        options.check()
    assert raised.value.field == "options/prove_intrinsics_intervals" and "varying_focal" in raised.value.reason



@pytest.fixture(scope="module")
def result() -> dict:
    """Table 7.1's seed 5 (12 views, 0.2% noise, K = I: u = v = 0, skew 0, aspect 1), "centers"."""
    scene, _ = scenes.table71_scene(5, 0.2, False)
    return solve_job({"kind": "autocalibration",
                      "data": {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()},
                      "options": {"method": "direct", "intrinsics": UNIT, "chirality": "centers",
                                  "certificate": "full", "prove_intrinsics_intervals": True,
                                  "time_limit_s": 3600}})


def intervals(result: dict) -> dict:
    document = result["stages"][0]["determinacy"]["proven_intervals"]
    return {i["name"]: (i["lower"], i["upper"]) for i in document["intervals"]}


def sublevel_of(result: dict) -> dict:
    return result["certificate"]["items"][0]["proof"]["sublevel"]


def restated(forged: dict) -> dict:
    """``forged``'s determinacy made its proof's again, and its certificate rehashed."""
    from geocert.formulations.autocalibration import direct_intrinsics

    forged["stages"][0]["determinacy"]["proven_intervals"] = direct_intrinsics.proven_document(sublevel_of(forged))
    rehash(forged["certificate"])
    return forged


def refused(forged: dict, check: str, words: str = "") -> None:
    first = verify_any(forged).first_failure
    assert first is not None and first["check"] == check and words in first["detail"], first


@pytest.mark.slow
class TestGenuine:
    def test_certified_proven_and_verified(self, result):
        stage = result["stages"][0]
        assert stage["certified"], stage["reason"]
        assert stage["determinacy"]["proven"] is True
        assert list(intervals(result)) == ["focal"] + NAMES
        report = verify_any(result)
        assert report.valid, report.first_failure
        assert {"name": "proven_interval", "passed": 1, "failed": 0} in report.checks

    def test_the_principal_point_is_bounded_on_both_sides(self, result):
        found = intervals(result)
        for name in ("principal_u", "principal_v"):
            assert None not in found[name], found[name]
            assert found[name][1] - found[name][0] < 0.05  # a few percent of f at most

    def test_the_truth_and_the_K_returned_lie_inside(self, result):
        """Every end stated (null ends claim nothing) holds the truth (K = I) and the K returned."""
        K = np.array(result["K"])
        truth = {"principal_u": 0.0, "principal_v": 0.0, "focal_y": 1.0, "skew": 0.0, "aspect": 1.0}
        returned = {"principal_u": K[0, 2], "principal_v": K[1, 2], "focal_y": K[1, 1], "skew": K[0, 1],
                    "aspect": K[1, 1] / K[0, 0]}
        for name, (lower, upper) in list(intervals(result).items())[1:]:
            for value in (truth[name], returned[name]):
                assert lower is None or lower <= value, (name, lower, value)
                assert upper is None or value <= upper, (name, upper, value)

    def test_a_null_end_states_its_reason(self, result):
        document = result["stages"][0]["determinacy"]["proven_intervals"]
        for entry in document["intervals"]:
            assert ("reason" in entry) == (entry["lower"] is None or entry["upper"] is None)


@pytest.mark.slow
class TestForged:
    @pytest.mark.parametrize("k", range(len(NAMES)))
    def test_a_narrowed_interval_is_refused(self, result, k):
        forged = copy.deepcopy(result)
        pair = sublevel_of(forged)["intrinsics"]["intervals"][k]
        if pair[0] is None and pair[1] is None:
            pytest.skip(f"{NAMES[k]}: neither end proven here")
        side = 0 if pair[0] is not None else 1
        width = (pair[1] - pair[0]) if None not in pair else abs(pair[side]) + 1.0
        pair[side] += (0.01 if side == 0 else -0.01) * width
        refused(restated(forged), "proven_interval", "narrower")

    def test_a_widened_interval_verifies(self, result):
        forged = copy.deepcopy(result)
        for pair in sublevel_of(forged)["intrinsics"]["intervals"]:
            pair[0] = None if pair[0] is None else pair[0] - 0.5
            pair[1] = None if pair[1] is None else pair[1] + 0.5
        assert verify_any(restated(forged)).valid

    def test_an_end_stated_without_its_dual_is_refused(self, result):
        """principal_u's lower end stated with its entries removed (a missing end claimed)."""
        forged = copy.deepcopy(result)
        sublevel_of(forged)["intrinsics"]["u"]["lower"] = None
        refused(restated(forged), "proven_interval", "narrower")

    def test_a_missing_end_stated_null_verifies(self, result):
        forged = copy.deepcopy(result)
        intrinsics = sublevel_of(forged)["intrinsics"]
        intrinsics["u"]["lower"] = None
        intrinsics["intervals"][0][0] = None
        assert verify_any(restated(forged)).valid

    def test_a_forged_dual_is_refused(self, result):
        forged = copy.deepcopy(result)
        entry = sublevel_of(forged)["intrinsics"]["v"]["upper"][0]
        entry["z"] = pack(np.random.default_rng(0).normal(size=unpack(entry["z"]).shape))
        refused(restated(forged), "proven_interval")

    def test_a_c_moved_inward_is_refused(self, result):
        """u's lower end's c raised past the returned K's principal point: its dual proves nothing."""
        forged = copy.deepcopy(result)
        entry = sublevel_of(forged)["intrinsics"]["u"]["lower"][0]
        entry["c"] = float(result["K"][0][2]) + 0.05
        refused(restated(forged), "proven_interval", "not above 0")

    def test_a_determinacy_stating_other_intervals_than_its_proof_is_refused(self, result):
        forged = copy.deepcopy(result)
        entry = forged["stages"][0]["determinacy"]["proven_intervals"]["intervals"][1]
        entry["lower"] += 1e-3
        refused(forged, "returned")

    def test_proven_without_its_proof_is_refused(self, result):
        forged = copy.deepcopy(result)
        del sublevel_of(forged)["intrinsics"]
        rehash(forged["certificate"])  # the determinacy still states the intrinsics' intervals
        refused(forged, "returned")

    def test_a_proof_not_asked_for_is_refused(self, result):
        forged = copy.deepcopy(result)
        forged["certificate"]["options"]["prove_intrinsics_intervals"] = False
        forged["certificate"]["options"]["prove_focal_interval"] = True
        refused(restated(forged), "format", "did not ask")

"""The direct autocalibration stage's proven intervals of each view's focal length (varying_focal,
direct_sublevel.check_views): with a full certificate and prove_focal_interval, a certified stage's
determinacy states focal[0] .. focal[m-1], each the interval of that view's focal length (f0 sqrt
of (w11 + w22) / 2 w33 of its w = P Q P') over every quadric of the scope costing at most
cost_increase more than the certified one, each end proven by a dual of the order-2 relaxation with
the cost row; the verifier recomputes every end, and refuses a narrowed, moved, swapped or
mis-shaped proof and a determinacy stating other intervals than it."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import scenes
from geocert.formulations.autocalibration import direct, direct_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.formulations.autocalibration.proofs import sublevel_level
from geocert.core.certificates import pack, unpack
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import rehash

pytestmark = pytest.mark.slow  # the module's job proves 12 ends of 6 views: about 40 s of CPU

INTRINSICS = {"aspect": [0.95, 1.05], "skew": [-0.01, 0.01], "principal_point": [[-0.1, 0.1], [-0.1, 0.1]],
              "focal": [0.05, 1.0]}
SEED, VIEWS = 2, 6


@pytest.fixture(scope="module")
def scene():
    """Table 7.1's varying-focal protocol (f in [0.05, 1] a view, 0.2% noise, a random projective
    frame), 6 views: the true quadric's cost is below the proof's level here (measured 5.1e-4
    against 7.3e-4), so every view's true focal length must lie inside its interval."""
    return scenes.table71_scene(SEED, 0.2, True, views=VIEWS)


@pytest.fixture(scope="module")
def setup(scene) -> direct.DirectSetup:
    """The program the kind builds for the scene (its frame, its focal rows)."""
    scene, _ = scene
    return direct.setup_for(autocalibration_problem.prepare(scene.cameras, scene.points, None, INTRINSICS,
                                                            unit_reference=False), "centers")


@pytest.fixture(scope="module")
def result(scene) -> dict:
    scene, _ = scene
    return solve_job({"kind": "autocalibration",
                      "data": {"cameras": scene.cameras.tolist(), "points": scene.points.tolist()},
                      "options": {"method": "direct", "varying_focal": True, "intrinsics": INTRINSICS,
                                  "chirality": "centers", "certificate": "full", "prove_focal_interval": True,
                                  "time_limit_s": 3600}})


def sublevel_of(document: dict) -> dict:
    return document["certificate"]["items"][0]["proof"]["sublevel"]


def intervals(result: dict) -> list[tuple[float, float]]:
    document = result["stages"][0]["determinacy"]["proven_intervals"]
    assert [i["name"] for i in document["intervals"]] == [f"focal[{k}]" for k in range(VIEWS)]
    return [(i["lower"], i["upper"]) for i in document["intervals"]]


def quantity(w: np.ndarray) -> float:
    """The interval's quantity of one view's w = P Q P' (input frame, pixels; here K0 has its
    principal point at the ranges' middle, 0): the root of (w11 + w22) / (2 w33)."""
    return math.sqrt((w[0, 0] + w[1, 1]) / (2.0 * w[2, 2]))


def forged(result: dict, edit) -> dict:
    """``result`` with ``edit(sublevel)`` applied to its proof, its determinacy restated from the
    edited proof (so that only the proof's own check can refuse it), rehashed."""
    from geocert.formulations.autocalibration import direct_sublevel

    document = copy.deepcopy(result)
    sublevel = sublevel_of(document)
    edit(sublevel)
    try:
        document["stages"][0]["determinacy"]["proven_intervals"] = direct_sublevel.proven_views_document(sublevel)
    except (KeyError, TypeError):
        pass  # a mis-shaped proof: the determinacy keeps the genuine intervals
    rehash(document["certificate"])
    return document


def refused_by(document: dict) -> dict:
    first = verify_any(document).first_failure
    assert first is not None
    return first


class TestGenuine:
    def test_certified_and_every_views_ends_proven(self, result):
        stage = result["stages"][0]
        assert stage["certified"], stage["reason"]
        assert stage["determinacy"]["proven"] is True
        views = sublevel_of(result)["views"]
        assert len(views) == VIEWS
        assert all(view["lower"] is not None and view["upper"] is not None for view in views)

    def test_verifies(self, result):
        report = verify_any(result)
        assert report.valid, report.first_failure
        assert {"name": "proven_interval", "passed": 1, "failed": 0} in report.checks

    def test_the_true_quadrics_focal_lengths_lie_inside(self, scene, setup, result):
        """Ground truth: the true quadric costs less than the level, so it is in the proven set and
        each view's focal length of it must lie in that view's interval; so must the Ks returned
        (their quadric is the certified one) and here the true Ks themselves."""
        scene, Ks = scene
        Hi = np.linalg.inv(scene.projective)
        true_Q = Hi @ np.diag([1.0, 1.0, 1.0, 0.0]) @ Hi.T
        stage = result["stages"][0]
        level = sublevel_level(stage["cost"], sublevel_of(result)["cost_increase"])
        assert direct_relaxation.cost(setup.cameras, setup.from_input(true_Q)) <= level
        Q_returned = np.array(result["dual_absolute_quadric"])
        for k, (lower, upper) in enumerate(intervals(result)):
            P = scene.cameras[k]
            assert lower <= quantity(P @ true_Q @ P.T) <= upper, k
            assert lower <= quantity(P @ Q_returned @ P.T) <= upper, k
            assert lower <= Ks[k][0, 0] <= upper, k

    def test_each_interval_fixes_its_focal_length(self, result):
        """Each view's interval within 10% of its focal length on either side (the `determined`
        tolerance; measured 3.5% to 5.7% a side), where the estimates' are the curvature's."""
        for (lower, upper), K in zip(intervals(result), result["Ks"]):
            assert upper - lower <= 0.2 * K[0][0]

    def test_quadrics_near_the_certified_one_within_the_level_lie_inside(self, scene, setup, result):
        """Soundness beside the proof: quadrics of the scope (PSD of rank 3, within the focal rows,
        chirality) moved at random from the certified one, whose cost is within the level, have
        every view's focal length inside its interval."""
        scene, _ = scene
        stage = result["stages"][0]
        level = sublevel_level(stage["cost"], sublevel_of(result)["cost_increase"])
        Q0 = setup.from_input(np.array(result["dual_absolute_quadric"]))
        rng = np.random.default_rng(0)
        bounds = intervals(result)
        inside = 0
        for scale in (3e-3, 1e-2, 3e-2):
            for _ in range(200):
                E = rng.normal(size=(4, 4))
                Q = direct.rank_three_projection(Q0 + scale * (E + E.T) / 2)
                if not (direct.in_domain(setup, Q) and direct_relaxation.cost(setup.cameras, Q) <= level):
                    continue
                inside += 1
                Q_in = setup.to_input(Q)
                for k, (lower, upper) in enumerate(bounds):
                    P = scene.cameras[k]
                    assert lower <= quantity(P @ Q_in @ P.T) <= upper, (k, scale)
        assert inside >= 50


class TestForged:
    @pytest.mark.parametrize("end", [0, 1])
    def test_a_narrowed_view_is_refused(self, result, end):
        def narrow(sublevel):
            lower, upper = sublevel["views"][3]["interval"]
            cut = 0.01 * (upper - lower)
            sublevel["views"][3]["interval"] = [lower + cut, upper] if end == 0 else [lower, upper - cut]

        first = refused_by(forged(result, narrow))
        assert first["check"] == "proven_interval" and "views/3" in first["detail"] and "narrower" in first["detail"]

    def test_widened_verifies(self, result):
        def widen(sublevel):
            for view in sublevel["views"]:
                view["interval"] = [view["interval"][0] * 0.9, view["interval"][1] * 1.1]

        report = verify_any(forged(result, widen))
        assert report.valid, report.first_failure

    def test_a_c_moved_inward_is_refused(self, setup, result):
        """View 1's lower end's c raised past the returned quadric's own ratio: that quadric is in
        the set with tr((A - c B) Q) < 0, so no dual proves the end."""
        from geocert.formulations.autocalibration import direct_sublevel

        own = direct_sublevel.ratio(setup.cameras, setup.from_input(np.array(result["dual_absolute_quadric"])), 1)

        def inward(sublevel):
            sublevel["views"][1]["lower"][0]["c"] = own * 1.001

        first = refused_by(forged(result, inward))
        assert first["check"] == "proven_interval" and "not above 0" in first["detail"]

    def test_a_forged_dual_is_refused(self, result):
        def noise(sublevel):
            z = unpack(sublevel["views"][2]["upper"][0]["z"])
            sublevel["views"][2]["upper"][0]["z"] = pack(np.random.default_rng(0).normal(size=z.shape))

        assert refused_by(forged(result, noise))["check"] == "proven_interval"

    def test_two_views_swapped_are_refused(self, result):
        """A view's proof read as another's: the forms are the view's own, so the other view's
        duals prove nothing about it (or less than its stated interval)."""
        def swap(sublevel):
            views = sublevel["views"]
            views[0], views[4] = views[4], views[0]

        assert refused_by(forged(result, swap))["check"] == "proven_interval"

    def test_the_one_focal_length_format_is_refused(self, result):
        """The fixed-focal proof's shape ({lower, upper, interval} at the top) in a varying-focal
        job: refused as mis-shaped, not read as every view's."""
        def flatten(sublevel):
            first = sublevel.pop("views")[0]
            sublevel.update(first)

        assert refused_by(forged(result, flatten))["check"] == "format"

    def test_a_view_left_out_is_refused(self, result):
        assert refused_by(forged(result, lambda sublevel: sublevel["views"].pop()))["check"] == "format"

    def test_the_result_stating_another_interval_than_its_proof_is_refused(self, result):
        document = copy.deepcopy(result)
        document["stages"][0]["determinacy"]["proven_intervals"]["intervals"][5]["lower"] *= 1.001
        assert refused_by(document)["check"] == "returned"

    def test_a_lower_cost_increase_than_the_rule_is_refused(self, result):
        """The proof and its determinacy at a tenth of the rule's level: a smaller set, proven,
        but not the set the kind promises."""
        def lower(sublevel):
            sublevel["cost_increase"] = sublevel["cost_increase"] / 10

        first = refused_by(forged(result, lower))
        assert first["check"] in ("proven_interval", "returned")

    def test_proven_without_its_proof_is_refused(self, result):
        document = copy.deepcopy(result)
        del document["certificate"]["items"][0]["proof"]["sublevel"]
        rehash(document["certificate"])
        assert refused_by(document)["check"] == "returned"

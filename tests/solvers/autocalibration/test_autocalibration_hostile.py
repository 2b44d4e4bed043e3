"""Hostile review of the autocalibration certificates (issue 12): forged and tampered documents.

Every attack is a regression test: the verifier must refuse it. The five at the end succeeded
when this review was written (a NaN leaf bound dropped by min(), an inside-out frame, the metric
stage's plane not tied to the affine stage's, the result's headline fields unchecked, a scope
closed where the exclusions are strict) and were fixed. One solved certificate (the kind's
example, full certificate) is shared by the module.
"""

from __future__ import annotations

import copy
import json
import warnings

import numpy as np
import pytest
from scipy.optimize import linprog

from geocert.jobs.runner import solve_job
from geocert.kinds import get_kind
from geocert.formulations.autocalibration import affine_relaxation as arelax
from geocert.solvers.autocalibration import metric
from geocert.formulations.autocalibration import frames, proofs
from geocert.formulations.autocalibration import metric_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.verify.autocalibration import CLAIM_OPTIONS, read_data
from geocert.core.certificates import data_hash, pack, problem_hash, unpack
from geocert.core.cones import proves_infeasible
from geocert.core.geometry import InputError
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import uncertify

KIND = "autocalibration"


@pytest.fixture(scope="module")
def solved() -> dict:
    kind = get_kind(KIND)
    result = solve_job({**kind.example, "options": {"certificate": "full"}})
    assert verify_any(result).valid
    return result


@pytest.fixture(scope="module")
def problem(solved):
    cameras, points, size = read_data(solved["certificate"]["data"])
    return autocalibration_problem.prepare(cameras, points, size, {})


def check(document) -> tuple[bool, dict | None]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = verify_any(document)
    return report.valid, report.first_failure


def refused(document, check_name: str | None = None, affine_only: bool = False) -> None:
    """The verifier refuses the document. ``affine_only``: the tampering is in the affine item, so
    check the certificate alone with the metric item uncertified (skipped: quicker)."""
    if affine_only:
        document = copy.deepcopy(document["certificate"])
        uncertify(document["items"][1])
    valid, failure = check(document)
    assert not valid
    if check_name is not None:
        assert failure["check"] == check_name, failure


def set_claim(result: dict, index: int, **fields) -> None:
    """The same fields on the certificate's item and the result's stage (so 'returned' agrees)."""
    result["certificate"]["items"][index].update(fields)
    result["stages"][index].update({k: v for k, v in fields.items() if k != "proof"})


def rehash(result: dict) -> None:
    document = result["certificate"]
    document["data_sha256"] = data_hash(KIND, document["data"])
    document["problem_sha256"] = problem_hash(KIND, document["data"], document["options"], CLAIM_OPTIONS)


def metric_setup(problem, claim: dict):
    p = autocalibration_problem.plane_from_input(problem, np.array(claim["plane_at_infinity"]))
    return p, metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)


def suboptimal_K(problem, claim: dict) -> tuple[list, float]:
    """A calibration in the metric domain, far from the optimum (K = [[1000, 0, 500], ...]), and its cost."""
    _, setup = metric_setup(problem, claim)
    lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
    K = np.array([[700.0, 0.0, 450.0], [0.0, 720.0, 560.0], [0.0, 0.0, 1.0]])
    w = autocalibration_problem.w_of_K(problem, K)
    assert metric_relaxation.in_domain(setup, w, lo, hi)
    return K.tolist(), metric_relaxation.cost(setup, w)


def suboptimal_plane(problem, claim: dict, step=(0.02, -0.01, 0.01)) -> tuple[list, float]:
    p0 = autocalibration_problem.plane_from_input(problem, np.array(claim["plane_at_infinity"]))
    plane = autocalibration_problem.plane_in_input(problem, p0 + np.array(step))
    p = autocalibration_problem.plane_from_input(problem, plane)
    assert autocalibration_problem.allowed_by_chirality(problem, p)
    return plane.tolist(), autocalibration_problem.affine_cost(problem, p)


# --- refused attacks --------------------------------------------------------------------------

class TestClaimTamper:
    def test_metric_lower_bound_raised(self, solved):
        r = copy.deepcopy(solved)
        cost = r["certificate"]["items"][1]["cost"]
        set_claim(r, 1, lower_bound=cost, gap=0.0)
        refused(r)  # (its tightening's cap is the incumbent's, a hair below: check tightening)

    def test_affine_lower_bound_raised(self, solved):
        r = copy.deepcopy(solved)
        item = r["certificate"]["items"][0]
        set_claim(r, 0, cost=item["cost"] * 2, lower_bound=item["cost"] * 2, gap=0.0)
        refused(r)

    def test_cost_not_the_solutions(self, solved):
        r = copy.deepcopy(solved)
        item = r["certificate"]["items"][1]
        set_claim(r, 1, cost=item["cost"] * 0.5, lower_bound=item["cost"] * 0.5 - item["gap"])
        refused(r, "objective")

    def test_gap_disagrees(self, solved):
        r = copy.deepcopy(solved)
        set_claim(r, 1, gap=0.0)
        refused(r, "claim")

    def test_negative_gap(self, solved):
        r = copy.deepcopy(solved)
        item = r["certificate"]["items"][1]
        set_claim(r, 1, gap=-item["gap"], lower_bound=item["cost"] + item["gap"])
        refused(r, "claim")

    def test_status_and_certified_types(self, solved):
        for fields in ({"status": "time_limit"}, {"certified": "yes"}, {"certified": 1}):
            r = copy.deepcopy(solved)
            set_claim(r, 1, **fields)
            refused(r)

    def test_returned_stage_differs(self, solved):
        for field, value in (("plane_at_infinity", [0.0, 0.0, 0.0, 1.0]), ("K", np.eye(3).tolist()),
                             ("cost", 1.0), ("lower_bound", 0.0)):
            r = copy.deepcopy(solved)
            r["stages"][1][field] = value
            refused(r, "returned")


class TestSolutionOutOfScope:
    def test_suboptimal_plane_with_its_cost(self, solved, problem):
        """A worse plane, its true cost, lower bound = cost: the proof shows only ~0."""
        r = copy.deepcopy(solved)
        plane, cost = suboptimal_plane(problem, r["certificate"]["items"][0], (0.2, -0.1, 0.1))
        set_claim(r, 0, plane_at_infinity=plane, cost=cost, lower_bound=cost, gap=0.0)
        # Refused for its bound, or sooner: the proof's unit was chosen for the optimum's cost,
        # 1e7 times smaller (proofs.UNIT_RANGE).
        valid, failure = check(copy.deepcopy(r["certificate"]) | {"items": [r["certificate"]["items"][0],
                                                                          {**r["certificate"]["items"][1],
                                                                           "certified": False}]})
        assert not valid and failure["check"] in ("lower_bound", "program"), failure

    def test_plane_through_reference_centre(self, solved, problem):
        r = copy.deepcopy(solved)
        plane = np.linalg.solve(problem.norm.T0.T, np.array([1.0, 0.5, 0.2, 0.0]))
        set_claim(r, 0, plane_at_infinity=plane.tolist())
        refused(r, "objective", affine_only=True)

    def test_plane_not_allowed_by_chirality(self, solved, problem):
        r = copy.deepcopy(solved)
        rows = frames.chirality_rows(problem.norm, 1.0)
        pi = rows[0] - rows[1]  # positive on point 0, negative on point 1
        p = pi[:3] / pi[3]
        assert not autocalibration_problem.allowed_by_chirality(problem, p)
        plane = autocalibration_problem.plane_in_input(problem, p)
        cost = autocalibration_problem.affine_cost(problem, autocalibration_problem.plane_from_input(problem, plane))
        set_claim(r, 0, plane_at_infinity=plane.tolist(), cost=cost, lower_bound=0.0, gap=cost)
        r["certificate"]["options"]["rel_gap"] = 0.5  # the largest allowed (the scope is checked before the gap)
        rehash(r)
        refused(r, "scope", affine_only=True)

    def test_K_not_upper_triangular(self, solved):
        r = copy.deepcopy(solved)
        K = np.array(r["certificate"]["items"][1]["K"])
        K[1, 0] = 1e-3
        set_claim(r, 1, K=K.tolist())
        refused(r, "claim")

    def test_K_outside_the_domain(self, solved, problem):
        r = copy.deepcopy(solved)
        claim = r["certificate"]["items"][1]
        _, setup = metric_setup(problem, claim)
        K = np.array([[1e5, 0.0, 500.0], [0.0, 1e5, 500.0], [0.0, 0.0, 1.0]])  # focal beyond 5000
        cost = metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, K))
        set_claim(r, 1, K=K.tolist(), cost=cost, lower_bound=0.0, gap=cost)
        r["certificate"]["options"]["metric_rel_gap"] = 1.0
        rehash(r)
        refused(r, "scope")

    def test_suboptimal_K_with_its_cost(self, solved, problem):
        r = copy.deepcopy(solved)
        K, cost = suboptimal_K(problem, r["certificate"]["items"][1])
        set_claim(r, 1, K=K, cost=cost, lower_bound=cost, gap=0.0)
        refused(r)


class TestHashTamper:
    def test_data_changed(self, solved):
        r = copy.deepcopy(solved)
        r["certificate"]["data"]["cameras"][1][0][0] *= 1.01
        refused(r, "data_hash")

    def test_data_changed_and_rehashed(self, solved):
        r = copy.deepcopy(solved)
        r["certificate"]["data"]["cameras"][1][0][0] *= 1.01
        rehash(r)
        refused(r)

    @pytest.mark.parametrize("change", [
        {"intrinsics": {"focal": [900.0, 1100.0]}},
        {"metric_rel_gap": 0.5},
        {"rel_gap": 0.5},
        {"abs_gap": 1e-9},  # (within the kind's cap, 1e-8: beyond it the options check refuses first)
    ])
    def test_options_changed_without_rehash(self, solved, change):
        r = copy.deepcopy(solved)
        r["certificate"]["options"].update(change)
        refused(r, "data_hash")

    def test_intrinsics_narrowed_and_rehashed(self, solved):
        """A narrower focal range: the proofs were for the wider box (tightening starts elsewhere)."""
        r = copy.deepcopy(solved)
        r["certificate"]["options"]["intrinsics"] = {"focal": [900.0, 1100.0]}
        rehash(r)
        refused(r)

    def test_image_size_changed_and_rehashed(self, solved):
        r = copy.deepcopy(solved)
        r["certificate"]["data"]["image_size"] = [2000, 2000]
        rehash(r)
        refused(r)

    def test_bad_options(self, solved):
        for change in ({"method": "direct"}, {"rel_gap": -1.0}, {"metric_rel_gap": 2.0},
                       {"intrinsics": {"focal": [2000.0, 1000.0]}}, {"intrinsics": {"nope": [1, 2]}},
                       {"intrinsics": "focal"}, {"rel_gap": "0.1"}, {"rel_gap": True}):
            r = copy.deepcopy(solved)
            r["certificate"]["options"].update(change)
            rehash(r)
            refused(r)


class TestAffineProofTamper:
    def proof(self, r):
        return r["certificate"]["items"][0]["proof"]

    def test_excluded_rows_changed(self, solved):
        r = copy.deepcopy(solved)
        excluded = self.proof(r)["excluded"][0]
        excluded["rows"] = [0, 1, 2, 3, 4]
        refused(r, "root_region", affine_only=True)

    def test_feasible_orientation_excluded(self, solved):
        """The region's orientation claimed excluded by the other's rows."""
        r = copy.deepcopy(solved)
        proof = self.proof(r)
        region, excluded = proof["regions"][0], proof["excluded"][0]
        proof["excluded"].append({"delta": region["delta"], "rows": excluded["rows"]})
        proof["regions"] = []
        refused(r, "root_region", affine_only=True)

    def test_orientation_missing(self, solved):
        for drop in ("regions", "excluded"):
            r = copy.deepcopy(solved)
            self.proof(r)[drop] = []
            refused(r, "root_region", affine_only=True)

    def test_orientation_twice(self, solved):
        r = copy.deepcopy(solved)
        proof = self.proof(r)
        proof["regions"].append(copy.deepcopy(proof["regions"][0]))
        refused(r, "root_region", affine_only=True)

    def test_box_side_shrunk(self, solved):
        r = copy.deepcopy(solved)
        region = self.proof(r)["regions"][0]
        box = region["box"]
        box[0][0] += 0.5 * (box[1][0] - box[0][0])
        for leaf in region["leaves"]:
            leaf[0][0] = max(leaf[0][0], box[0][0])
        for item in region["proofs"]:
            item["box"][0][0] = max(item["box"][0][0], box[0][0])
        refused(r, "root_region", affine_only=True)

    def test_basis_rows_changed(self, solved):
        r = copy.deepcopy(solved)
        region = self.proof(r)["regions"][0]
        region["basis"][0] = region["basis"][1]
        refused(r, "root_region", affine_only=True)

    def test_basis_malformed(self, solved):
        for basis in ([[0, 0, 0]] * 6, [[0, 1]] * 6, [[0, 1, 10 ** 6]] * 6, [[0, 1, -1]] * 6, [[0, 1, 2.0]] * 6,
                      "rows", [[0, 1, 2]] * 5):
            r = copy.deepcopy(solved)
            self.proof(r)["regions"][0]["basis"] = basis
            refused(r, affine_only=True)

    def test_singular_frame(self, solved):
        r = copy.deepcopy(solved)
        frame = np.array(self.proof(r)["regions"][0]["frame"])
        frame[3] = frame[2]
        self.proof(r)["regions"][0]["frame"] = frame.tolist()
        refused(r, "root_region", affine_only=True)

    def test_rows_out_of_range(self, solved):
        for rows in ([], [10 ** 6], [-1], [0.5], "all"):
            r = copy.deepcopy(solved)
            self.proof(r)["regions"][0]["rows"] = rows
            refused(r, affine_only=True)

    def test_unit_not_positive(self, solved):
        for unit in (0.0, -1.0, float("nan"), float("inf"), "1", None):
            r = copy.deepcopy(solved)
            self.proof(r)["regions"][0]["unit"] = unit
            refused(r, affine_only=True)

    def test_leaf_does_not_cover(self, solved):
        r = copy.deepcopy(solved)
        leaf = self.proof(r)["regions"][0]["leaves"][0]
        leaf[1][2] = leaf[0][2] + 0.5 * (leaf[1][2] - leaf[0][2])
        refused(r, "coverage", affine_only=True)

    def test_no_leaves(self, solved):
        r = copy.deepcopy(solved)
        self.proof(r)["regions"][0]["leaves"] = []
        refused(r, "format", affine_only=True)


class TestMetricProofTamper:
    def proof(self, r):
        return r["certificate"]["items"][1]["proof"]

    def test_tightening_cap_below_lower_bound(self, solved):
        r = copy.deepcopy(solved)
        self.proof(r)["tightening"][0]["cap"] = r["certificate"]["items"][1]["lower_bound"] * 0.5
        refused(r, "tightening")

    def test_tightening_cuts_better_points(self, solved):
        """The last round's box shrunk past what its duals prove (and the search box with it)."""
        r = copy.deepcopy(solved)
        proof = self.proof(r)
        last = proof["tightening"][-1]
        lo, hi = np.array(last["box_out"][0]), np.array(last["box_out"][1])
        lo[0] = lo[0] + 0.75 * (hi[0] - lo[0])
        last["box_out"][0] = lo.tolist()
        proof["search_box"][0] = lo.tolist()
        for leaf in proof["leaves"]:
            leaf[0][0] = max(leaf[0][0], lo[0])
        refused(r, "tightening")

    def test_tightening_box_in_not_previous(self, solved):
        r = copy.deepcopy(solved)
        first = self.proof(r)["tightening"][0]
        first["box_in"][0][0] += 1e-6
        refused(r, "tightening")

    def test_tightening_side_moved_without_dual(self, solved):
        r = copy.deepcopy(solved)
        rounds = self.proof(r)["tightening"]
        moved = next((n, s) for n, round_ in enumerate(rounds) for s in range(10)
                     if round_["box_out"][s % 2][s // 2] != round_["box_in"][s % 2][s // 2])
        rounds[moved[0]]["duals"][moved[1]] = None
        refused(r, "tightening")

    def test_tightening_dual_swapped(self, solved):
        r = copy.deepcopy(solved)
        duals = self.proof(r)["tightening"][0]["duals"]
        duals[0], duals[1] = duals[1], duals[0]
        refused(r, "tightening")

    def test_tightening_wrong_dual_count(self, solved):
        r = copy.deepcopy(solved)
        self.proof(r)["tightening"][0]["duals"].pop()
        refused(r, "tightening")

    def test_search_box_not_last_round(self, solved):
        r = copy.deepcopy(solved)
        proof = self.proof(r)
        proof["search_box"][0][3] += 1e-9
        refused(r, "root_region")

    def test_tightening_dropped(self, solved):
        """Without the rounds, the search box must be the root box: the leaves do not cover it."""
        r = copy.deepcopy(solved)
        self.proof(r)["tightening"] = []
        refused(r)

    def test_leaf_outside_its_proof_box(self, solved):
        r = copy.deepcopy(solved)
        self.proof(r)["proofs"][0]["box"][1][1] -= 1e-9
        refused(r, "leaf_bounds")

    def test_leaf_shrunk(self, solved):
        r = copy.deepcopy(solved)
        leaf = self.proof(r)["leaves"][0]
        leaf[1][4] = leaf[0][4] + 0.5 * (leaf[1][4] - leaf[0][4])
        refused(r, "coverage")

    def test_dual_for_another_box(self, solved):
        """The leaf's dual re-filed under a wider proof box (the relaxation it proves is another)."""
        r = copy.deepcopy(solved)
        proof = self.proof(r)
        first = proof["tightening"][0]
        item = proof["proofs"][0]
        item["box"] = copy.deepcopy(first["box_in"])
        proof["tightening"] = []
        proof["search_box"] = copy.deepcopy(first["box_in"])
        proof["leaves"] = [first["box_in"] + [0]]
        refused(r)

    def test_dual_zeroed_or_scaled(self, solved):
        for transform in (lambda z: np.zeros_like(z), lambda z: -z, lambda z: z * 1e-6):
            r = copy.deepcopy(solved)
            item = self.proof(r)["proofs"][0]
            item["z"] = pack(transform(unpack(item["z"])))
            refused(r)

    def test_dual_wrong_length_or_not_base64(self, solved):
        for z in ("not base64!", pack(np.zeros(3)), "", None, 12):
            r = copy.deepcopy(solved)
            self.proof(r)["proofs"][0]["z"] = z
            refused(r)

    def test_dual_not_finite(self, solved):
        r = copy.deepcopy(solved)
        item = self.proof(r)["proofs"][0]
        z = unpack(item["z"])
        z[0] = np.nan
        item["z"] = pack(z)
        refused(r)

    def test_proof_kind_changed(self, solved):
        for kind in ("farkas", "no_domain", "trivial", None):
            r = copy.deepcopy(solved)
            self.proof(r)["proofs"][0]["kind"] = kind
            refused(r)

    def test_unit_changed(self, solved):
        for factor in (1e-3, 10.0):
            r = copy.deepcopy(solved)
            self.proof(r)["unit"] *= factor
            refused(r)

    def test_proof_type_swapped(self, solved):
        r = copy.deepcopy(solved)
        items = r["certificate"]["items"]
        items[0]["proof"], items[1]["proof"] = items[1]["proof"], items[0]["proof"]
        refused(r, "format")

    def test_metric_plane_changed_without_new_proof(self, solved, problem):
        r = copy.deepcopy(solved)
        plane, _ = suboptimal_plane(problem, r["certificate"]["items"][0], (0.05, -0.03, 0.02))
        set_claim(r, 1, plane_at_infinity=plane)
        refused(r)


class TestMalformed:
    @pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf"), 1e308, "0.1", True, None, [1.0]])
    def test_bad_numbers_in_the_claim(self, solved, value):
        for field in ("cost", "lower_bound", "gap"):
            r = copy.deepcopy(solved)
            r["certificate"]["items"][1][field] = value
            refused(r)

    @pytest.mark.parametrize("value", [float("nan"), float("inf"), 1e308, "1", None])
    def test_bad_numbers_in_the_solution(self, solved, value):
        r = copy.deepcopy(solved)
        r["certificate"]["items"][1]["K"][0][0] = value
        refused(r)
        r = copy.deepcopy(solved)
        r["certificate"]["items"][0]["plane_at_infinity"][3] = value
        refused(r, affine_only=True)

    @pytest.mark.parametrize("value", [float("nan"), float("inf"), 1e308, -1e308, "0", None])
    def test_bad_numbers_in_boxes(self, solved, value):
        r = copy.deepcopy(solved)
        r["certificate"]["items"][1]["proof"]["leaves"][0][1][0] = value
        refused(r)
        r = copy.deepcopy(solved)
        r["certificate"]["items"][0]["proof"]["regions"][0]["box"][1][0] = value
        refused(r, affine_only=True)

    def test_wrong_types(self, solved):
        affine = [
            lambda c: c["items"][0].__setitem__("proof", []),
            lambda c: c["items"][0].__setitem__("proof", None),
            lambda c: c["items"][0]["proof"].__setitem__("regions", {}),
            lambda c: c["items"][0]["proof"]["regions"].__setitem__(0, "region"),
            lambda c: c["items"][0]["proof"]["regions"][0].__setitem__("delta", "1"),
            lambda c: c["items"][0]["proof"]["regions"][0].__setitem__("delta", 0.5),
            lambda c: c["items"][0]["proof"]["excluded"].__setitem__(0, [1, 2]),
            lambda c: c["items"][0]["proof"]["excluded"][0].__setitem__("rows", "12345"),
            lambda c: c["items"][0]["proof"]["regions"][0].__setitem__("frame", [[1.0]]),
        ]
        for mutate in affine:
            r = copy.deepcopy(solved)
            mutate(r["certificate"])
            refused(r, affine_only=True)
        mutations = [
            lambda c: c["items"][1]["proof"].__setitem__("leaves", {}),
            lambda c: c["items"][1]["proof"]["leaves"].__setitem__(0, [1, 2, 3]),
            lambda c: c["items"][1]["proof"]["leaves"][0].__setitem__(2, 5),
            lambda c: c["items"][1]["proof"]["leaves"][0].__setitem__(2, True),
            lambda c: c["items"][1]["proof"]["leaves"][0].__setitem__(2, "0"),
            lambda c: c["items"][1]["proof"].__setitem__("tightening", None),
            lambda c: c["items"][1]["proof"]["tightening"].__setitem__(0, []),
            lambda c: c["items"][1]["proof"].__setitem__("search_box", [[0.0] * 5]),
            lambda c: c["items"][1]["proof"]["proofs"].__setitem__(0, "proof"),
            lambda c: c["items"][1].__setitem__("plane_at_infinity", [0.0, 0.0, 0.0]),
            lambda c: c["items"][1].__setitem__("K", [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
            lambda c: c["items"].append(copy.deepcopy(c["items"][1])),
            lambda c: c["items"].__setitem__(1, {**c["items"][1], "index": 0}),
            lambda c: c["data"].__setitem__("cameras", c["data"]["cameras"][:2]),
            lambda c: c["data"].__setitem__("extra", 1),
        ]
        for mutate in mutations:
            r = copy.deepcopy(solved)
            mutate(r["certificate"])
            rehash(r)
            refused(r)

    def test_deeply_nested(self, solved):
        r = copy.deepcopy(solved)
        nest: list = [0.0]
        for _ in range(5000):
            nest = [nest]
        r["certificate"]["items"][1]["proof"]["leaves"][0][0] = nest
        refused(r, "format")
        r = copy.deepcopy(solved)
        r["certificate"]["data"]["points"][0] = nest
        refused(r)

    def test_verifier_never_raises(self, solved):
        for document in (None, [], "x", 1, {"format": "geocert-certificate"},
                         {**solved["certificate"], "kind": "nope"}, {**solved["certificate"], "version": 1},
                         {"result": {"certificate": []}}):
            valid, _ = check(document)
            assert not valid


class TestKindInputs:
    """Bad input is an InputError naming the field, never a crash."""

    def solve(self, data=None, options=None):
        kind = get_kind(KIND)
        return solve_job({"kind": KIND, "data": data if data is not None else kind.example["data"],
                          "options": options or {}})

    def data(self):
        return copy.deepcopy(get_kind(KIND).example["data"])

    @pytest.mark.parametrize("mutate, field", [
        (lambda d: d.__setitem__("cameras", d["cameras"][:2]), "data/cameras"),
        (lambda d: d["cameras"].__setitem__(1, [[1, 0, 0, 0], [0, 1, 0, 0], [1, 1, 0, 0]]), "data/cameras/1"),
        (lambda d: d["cameras"][1][0].__setitem__(0, float("nan")), "data/cameras/1/0/0"),
        (lambda d: d["cameras"][1][0].__setitem__(0, "1"), "data/cameras/1/0/0"),
        (lambda d: d["cameras"].__setitem__(1, d["cameras"][1][:2]), "data/cameras"),
        (lambda d: d.__setitem__("cameras", [[[0, 0, 0, 1], [1, 0, 0, 0], [0, 1, 0, 0]]] * 3), "data/cameras"),
        (lambda d: d.__setitem__("points", [p[:3] for p in d["points"]]), "data/points"),
        (lambda d: d.__setitem__("points", []), "data/points"),
        (lambda d: d.__setitem__("points", d["points"][:-1] + [[0, 0, 0, 0]]), "data/points/11"),
        (lambda d: d["points"][0].__setitem__(2, float("inf")), "data/points/0/2"),
        (lambda d: d.__setitem__("image_size", [-1, 100]), "data/image_size"),
        (lambda d: d.pop("image_size"), "options/intrinsics/focal"),
        (lambda d: d.__setitem__("extra", 1), "data/extra"),
        (lambda d: d.pop("cameras"), "data/cameras"),
    ])
    def test_bad_data(self, mutate, field):
        data = self.data()
        mutate(data)
        with pytest.raises(InputError) as info:
            self.solve(data)
        assert info.value.field == field

    @pytest.mark.parametrize("intrinsics, field", [
        ({"focal": [2000, 1000]}, "options/intrinsics/focal"),
        ({"focal": [0, 1000]}, "options/intrinsics/focal"),
        ({"aspect": [-1, 1]}, "options/intrinsics/aspect"),
        ({"focal": [float("nan"), 1000]}, "options/intrinsics/focal"),
        ({"principal_point": [[600, 400], [0, 1000]]}, "options/intrinsics/principal_point/0"),
        ({"principal_point": [100, 200]}, "options/intrinsics/principal_point/0"),
        ({"foo": [1, 2]}, "options/intrinsics/foo"),
    ])
    def test_bad_intrinsics(self, intrinsics, field):
        with pytest.raises(InputError) as info:
            self.solve(options={"intrinsics": intrinsics})
        assert info.value.field == field

    def test_no_consistent_chirality(self):
        """A point behind half the cameras, given with both signs: no quasi-affine frame. A failed
        stage with its reason, nothing certified, nothing for the verifier to accept."""
        data = self.data()
        cameras = np.array(data["cameras"])
        rng = np.random.default_rng(1)
        while True:
            X = rng.normal(size=4)
            if (cameras[:, 2, :] @ X > 0).sum() == 3:
                break
        data["points"] += [X.tolist(), (-X).tolist()]
        result = solve_job({"kind": KIND, "data": data, "options": {"certificate": "full"}})
        stage = result["stages"][0]
        assert stage["status"] == "failed" and not stage["certified"] and "chirality" in stage["reason"]
        assert not check(result)[0]


# --- attacks that succeeded before their fixes ------------------------------------------------

class TestResultHeadlineUnchecked:
    """verify_any(result) compares only the stages with the certificate's items: the result's
    own plane_at_infinity, K, upgrade, dual_absolute_quadric, cameras and points can be anything."""

    @pytest.mark.parametrize("field, value", [
        ("K", [[500.0, 0.0, 100.0], [0.0, 2000.0, 900.0], [0.0, 0.0, 1.0]]),
        ("plane_at_infinity", [0.0, 0.0, 0.0, 1.0]),
        ("upgrade", np.eye(4).tolist()),
    ])
    def test_headline_changed(self, solved, field, value):
        r = copy.deepcopy(solved)
        r[field] = value
        refused(r)


def nan_dual(n: int) -> str:
    """A finite dual vector whose safe bound overflows to NaN (inf - inf)."""
    return pack(np.full(n, 1e300))


class TestNanBoundSkipped:
    """check_leaves takes min() over the leaves' bounds in Python: a NaN bound that is not first
    never wins, so its leaf counts as proven. A first leaf far outside the box, with no point of the
    domain (build is None), proves its arbitrary upper_bound; the leaf covering the box proves NaN."""

    def test_metric_any_K_certified(self, solved, problem):
        r = copy.deepcopy(solved)
        claim = r["certificate"]["items"][1]
        K, cost = suboptimal_K(problem, claim)  # cost ~3.2, the optimum ~2e-12
        _, setup = metric_setup(problem, claim)
        lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
        rows = len(metric_relaxation.build(setup, lo, hi, 1.0).b)
        far = [[1e8, -1.0, -1.0, 1e8, -1.0], [1e9, 1.0, 1.0, 1e9, 1.0]]
        assert metric_relaxation.build(setup, np.array(far[0]), np.array(far[1]), 1.0) is None
        box = [lo.tolist(), hi.tolist()]
        proof = claim["proof"]
        proof.update(tightening=[], search_box=box,
                     proofs=[{"box": far, "upper_bound": 1e30, "kind": "dual", "z": pack(np.zeros(1)), "bound": None},
                             {"box": box, "upper_bound": 1e30, "kind": "dual", "z": nan_dual(rows), "bound": None}],
                     leaves=[far + [0], box + [1]])
        set_claim(r, 1, K=K, cost=cost, lower_bound=cost, gap=0.0)
        refused(r)

    def test_affine_any_plane_certified(self, solved, problem):
        r = copy.deepcopy(solved)
        claim = r["certificate"]["items"][0]
        plane, cost = suboptimal_plane(problem, claim, (0.2, -0.1, 0.1))
        region = claim["proof"]["regions"][0]
        G = np.array(region["frame"])
        rows = frames.chirality_rows(problem.norm, float(region["delta"]))
        a, b = frames.frame_rows(G, rows)
        coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
        setup = arelax.AffineSetup(coef, frames.plane_map(G, float(region["delta"])), a[region["rows"]],
                                   b[region["rows"]], region["unit"])
        D = setup.functionals()[0]
        far_centre = -1e6 * D[:3] / np.linalg.norm(D[:3])  # d = D . (v, 1) < 0 there
        far = [(far_centre - 1.0).tolist(), (far_centre + 1.0).tolist()]
        assert arelax.build(setup, np.array(far[0]), np.array(far[1]), 1.0) is None
        lo, hi = map(np.array, region["box"])
        n = len(arelax.build(setup, lo, hi, 1.0).b)
        region.update(proofs=[{"box": far, "upper_bound": 1e30, "kind": "dual", "z": pack(np.zeros(1)), "bound": None},
                              {"box": region["box"], "upper_bound": 1e30, "kind": "dual", "z": nan_dual(n),
                               "bound": None}],
                      leaves=[far + [0], region["box"] + [1]])
        set_claim(r, 0, plane_at_infinity=plane, cost=cost, lower_bound=cost, gap=0.0)
        refused(r)


class TestFlippedFrame:
    """check_affine accepts any invertible frame G and proves the box from G's rows; it never
    checks that the polytope {v : a v + b >= 0} is the chirality cone's slice (b > 0, or v = 0 in
    it). With G's last row negated the slice is empty, the relaxation with the chirality rows is
    infeasible (a Farkas vector), and the region "proves" any cap: any allowed plane certified."""

    def test_any_plane_certified(self, solved, problem):
        r = copy.deepcopy(solved)
        claim = r["certificate"]["items"][0]
        region = claim["proof"]["regions"][0]
        delta = float(region["delta"])
        G = np.diag([1.0, 1.0, 1.0, -1.0]) @ np.array(region["frame"])
        a, b = frames.frame_rows(G, frames.chirality_rows(problem.norm, delta))
        assert np.all(b < 0)
        coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
        setup = arelax.AffineSetup(coef, frames.plane_map(G, delta), a, b, 1.0)
        lo, hi = map(np.array, region["box"])  # its six sides are still "proved" by the same bases
        program = arelax.build(setup, lo, hi, 1e30)
        k = len(a)
        lp = linprog(np.zeros(k), A_eq=np.vstack([a.T, np.ones((1, k))]), b_eq=[0, 0, 0, 1],
                     bounds=[(0, None)] * k, method="highs")
        z = np.zeros(len(program.b))
        z[6:6 + k] = lp.x  # the chirality rows follow the six box rows
        assert proves_infeasible(program.A, program.b, program.cones, z, program.lower, program.upper)
        region.update(frame=G.tolist(), rows=list(range(k)), unit=1.0,
                      proofs=[{"box": region["box"], "upper_bound": 1e30, "kind": "farkas", "z": pack(z),
                               "bound": None}],
                      leaves=[region["box"] + [0]])
        plane, cost = suboptimal_plane(problem, claim, (0.2, -0.1, 0.1))
        set_claim(r, 0, plane_at_infinity=plane, cost=cost, lower_bound=cost, gap=0.0)
        refused(r)


class TestMetricPlaneMismatch:
    """Nothing ties the metric item's plane_at_infinity to the affine item's (nor to the result's):
    a metric proof for another plane, with that plane stated, is accepted beside the affine claim."""

    def test_metric_stage_on_another_plane(self, solved, problem):
        r = copy.deepcopy(solved)
        plane, _ = suboptimal_plane(problem, r["certificate"]["items"][0], (0.05, -0.03, 0.02))
        p = autocalibration_problem.plane_from_input(problem, np.array(plane))
        setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
        lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
        options = autocalibration_problem.AutocalibrationOptions(metric_rel_gap=1e-2, time_limit_s=20)
        stage = metric.solve_metric(setup, lo, hi, autocalibration_problem.bnb_options(options, 1e-2), True, None)
        assert stage.certified
        K = problem.K0 @ autocalibration_problem.upper_triangular_root(metric_relaxation.omega_of(stage.w))
        K = K / K[2, 2]
        K[1, 0] = K[2, 0] = K[2, 1] = 0.0
        cost = metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, K))
        gap = max(0.0, cost - stage.lower_bound)
        r["certificate"]["options"]["metric_rel_gap"] = 1e-2
        rehash(r)
        set_claim(r, 1, plane_at_infinity=plane, K=K.tolist(), cost=cost, lower_bound=cost - gap, gap=gap,
                  proof=proofs.encode_metric(stage, problem.norm))
        assert r["stages"][0]["plane_at_infinity"] != plane
        refused(r)


class TestClosedChiralityScope:
    """allowed_by_chirality admits planes with pi . w >= 0 (zero allowed); Gordan's alternative
    excludes only pi . w > 0. Data with a point given with both signs (X, -X: a point behind half
    the cameras) lets both orientations be "excluded" by those two rows (bound: infinity), while a
    plane through X is still "allowed": any such plane is certified optimal, whatever its cost."""

    def test_plane_through_a_point_certified(self, solved):
        data = copy.deepcopy(solved["certificate"]["data"])
        cameras = np.array(data["cameras"])
        rng = np.random.default_rng(1)
        while True:
            X = rng.normal(size=4)
            if (cameras[:, 2, :] @ X > 0).sum() == 3:
                break
        data["points"] += [X.tolist(), (-X).tolist()]
        cams, points, size = read_data(data)
        problem = autocalibration_problem.prepare(cams, points, size, {})
        rows = frames.chirality_rows(problem.norm, 1.0)
        iX, iY = len(points) - 2, len(points) - 1
        assert np.array_equal(rows[iX], -rows[iY])
        others = np.delete(rows, [iX, iY], axis=0)
        lp = linprog([0, 0, 0, 0, -1], A_ub=np.hstack([-others, np.ones((len(others), 1))]), b_ub=np.zeros(len(others)),
                     A_eq=np.append(rows[iX], 0.0)[None], b_eq=[0.0], bounds=[(-1, 1)] * 4 + [(None, 1)], method="highs")
        assert lp.x[4] > 0  # planes through X, positive on every other row
        pi = lp.x[:4]
        plane0 = autocalibration_problem.plane_in_input(problem, pi[:3] / pi[3])
        # The scope is strict, as the exclusions are: no float neighbour of a plane through X is
        # in it (on one of X, -X it is <= 0), so such a claim fails its scope check.
        for _ in range(2000):
            candidate = plane0 * (1 + rng.integers(-8, 9, size=4) * 2.2e-16)
            assert not autocalibration_problem.allowed_by_chirality(
                problem, autocalibration_problem.plane_from_input(problem, candidate))
        plane = plane0
        cost = autocalibration_problem.affine_cost(problem, autocalibration_problem.plane_from_input(problem, plane))
        document = copy.deepcopy(solved["certificate"])
        document["data"] = data
        document["data_sha256"] = data_hash(KIND, data)
        document["problem_sha256"] = problem_hash(KIND, data, document["options"], CLAIM_OPTIONS)
        document["items"][0].update(
            plane_at_infinity=plane.tolist(), cost=cost, lower_bound=cost, gap=0.0,
            proof={"type": "stratified_affine", "regions": [],
                   "excluded": [{"delta": 1.0, "rows": [iX, iY]}, {"delta": -1.0, "rows": [iX, iY]}]})
        uncertify(document["items"][1])
        refused(document)

"""Full certificates: every kind and norm verifies, tampering is caught, and the verifier's bound
agrees with the solver's within the documented tolerance."""

from __future__ import annotations

import copy
import json
import subprocess
import sys

import numpy as np
import pytest

from geocert.core.certificates import data_hash, pack, problem_hash, unpack
from geocert.jobs.runner import solve_job
from geocert.formulations.fractional.relaxation import NORMS
from geocert.core.certificates import BOUND_TOLERANCE
from geocert.core.coverage import uncovered_part
from geocert.verify.checks import verify_arrays, verify_document
from geocert.core.bnb import Box

from tests.support import map_job, seed, triangulation_job


def certified(document: dict) -> list[dict]:
    return [item for item in document["items"] if item["certified"]]


class TestEveryKindVerifies:
    @pytest.mark.parametrize("norm", NORMS)
    def test_triangulation(self, norm):
        result = solve_job(triangulation_job(np.random.default_rng(seed("tri", norm)), 6, 4, norm))
        report = verify_document(result["certificate"])
        assert report.valid, report.first_failure
        assert report.items_checked == result["stats"]["certified"] == 6

    @pytest.mark.parametrize("norm", NORMS)
    @pytest.mark.parametrize("kind, count, noise", [("resection", 8, 1.0), ("homography2", 6, 1.0),
                                                    ("homography3", 8, 0.005)])  # 3D targets are unit-sized
    def test_maps(self, kind, count, noise, norm):
        result = solve_job(map_job(np.random.default_rng(seed(kind, norm)), kind, count, norm, noise=noise))
        report = verify_document(result["certificate"])
        assert report.valid, report.first_failure
        assert report.items_checked == result["stats"]["certified"] == 2

    def test_exact_data_verify_by_the_trivial_bound(self):
        rng = np.random.default_rng(seed("exact"))
        job = triangulation_job(rng, 2, 3, "L2L2", noise=0.0)
        result = solve_job(job)
        assert all(item["proof"]["type"] == "trivial" for item in certified(result["certificate"]))
        assert verify_document(result["certificate"]).valid

    def test_summary_results_carry_no_proof(self):
        job = triangulation_job(np.random.default_rng(seed("summary")), 2, 3, "L2L2")
        job["options"]["certificate"] = "summary"
        result = solve_job(job)
        assert "certificate" not in result
        assert all("proof" not in track["certificate"] for track in result["tracks"])


class TestVerifierBoundMatchesSolver:
    """The verifier recomputes each leaf's bound from its dual vector: it proves what the solver
    claimed, within BOUND_TOLERANCE (scaled units), and never more than that above it."""

    @pytest.mark.parametrize("norm", NORMS)
    def test_bounds_agree(self, norm):
        rng = np.random.default_rng(seed("agree", norm))
        jobs = [triangulation_job(rng, 4, 5, norm), map_job(rng, "resection", 8, norm), map_job(rng, "homography2", 6, norm)]
        compared = 0
        for job in jobs:
            document = solve_job(job)["certificate"]
            for claim in certified(document):
                if claim["proof"]["type"] == "convexity":  # recomputed from the point: the same sums
                    _, proven = verify_arrays(document["kind"], _arrays(document, claim["index"]),
                                              document["options"], claim)
                    assert claim["lower_bound"] <= proven <= claim["lower_bound"] + 1e-9 * abs(claim["lower_bound"])
                    compared += 1
                    continue
                if claim["proof"]["type"] != "branch_and_bound":
                    continue
                arrays = _arrays(document, claim["index"])
                _, proven = verify_arrays(document["kind"], arrays, document["options"], claim)
                scale = claim["proof"]["scale"]
                unit = scale**2 if norm == "L2L2" else scale
                solver = claim["lower_bound"]
                slack = BOUND_TOLERANCE * max(1.0, abs(solver) * unit) / unit
                assert proven >= solver - slack
                assert proven <= solver + slack or claim["cost"] <= proven  # lower_bound is min(bound, cost)
                compared += 1
        assert compared >= 6


def _arrays(document: dict, index: int) -> tuple:
    data = document["data"]
    if document["kind"] == "triangulation":
        track = data["tracks"][index]
        return np.asarray(data["cameras"])[track["views"]], np.asarray(track["points"])
    entry = data["maps"][index]
    return np.asarray(entry["source"]), np.asarray(entry["target"])


@pytest.fixture(scope="module")
def branched() -> dict:
    """A certificate whose first item needed several leaves and a tightening round (a map)."""
    rng = np.random.default_rng(seed("tamper"))
    for _ in range(20):
        document = solve_job(map_job(rng, "resection", 7, "L2L2", maps=1, noise=3.0))["certificate"]
        item = document["items"][0]
        proof = item["proof"]
        if item["certified"] and proof["type"] == "branch_and_bound" and len(proof["leaves"]) >= 3 and proof["tightening"]:
            assert verify_document(document).valid
            return document
    pytest.fail("no instance with several leaves")


def failed_check(document: dict) -> str | None:
    report = verify_document(document)
    return None if report.valid else report.first_failure["check"]


class TestTamperingIsCaught:
    def test_raised_leaf_bound(self, branched):
        doc = copy.deepcopy(branched)
        proofs = doc["items"][0]["proof"]["proofs"]
        target = max((p for p in proofs if p["kind"] == "dual"), key=lambda p: p["bound"])
        target["bound"] = target["bound"] * 1.01 + 1e-3
        assert failed_check(doc) == "leaf_bounds"

    def test_dropped_leaf(self, branched):
        doc = copy.deepcopy(branched)
        doc["items"][0]["proof"]["leaves"].pop(1)
        assert failed_check(doc) == "coverage"

    def test_shrunken_root_region(self, branched):
        doc = copy.deepcopy(branched)
        lower, upper = doc["items"][0]["proof"]["root"]["bounds"]
        lower[0] += 0.25 * (upper[0] - lower[0])
        assert failed_check(doc) == "root_region"

    def test_shrunken_search_box(self, branched):
        doc = copy.deepcopy(branched)
        proof = doc["items"][0]["proof"]
        lo, hi = proof["search_box"]
        lo[0] += 0.25 * (hi[0] - lo[0])
        for leaf in proof["leaves"]:  # leaves clipped to match: coverage holds, the proof chain does not
            leaf[0][0] = max(leaf[0][0], lo[0])
            leaf[1][0] = max(leaf[1][0], lo[0])
        assert failed_check(doc) == "tightening"

    def test_perturbed_solution(self, branched):
        doc = copy.deepcopy(branched)
        matrix = np.asarray(doc["items"][0]["matrix"])
        doc["items"][0]["matrix"] = (matrix + 1e-4 * np.abs(matrix).max()).tolist()
        assert failed_check(doc) == "objective"

    def test_perturbed_dual_vector(self, branched):
        doc = copy.deepcopy(branched)
        proofs = doc["items"][0]["proof"]["proofs"]
        target = max((p for p in proofs if p["kind"] == "dual"), key=lambda p: p["bound"])
        z = unpack(target["z"])
        z = z * (1 + 0.05 * np.random.default_rng(0).standard_normal(z.shape))
        target["z"] = pack(z)
        assert failed_check(doc) == "leaf_bounds"

    def test_edited_problem_data(self, branched):
        doc = copy.deepcopy(branched)
        doc["data"]["maps"][0]["target"][0][0] += 0.5
        assert failed_check(doc) == "data_hash"

    def test_edited_problem_data_with_its_hash_recomputed(self, branched):
        doc = copy.deepcopy(branched)
        doc["data"]["maps"][0]["target"][0][0] += 0.5
        doc["data_sha256"] = data_hash(doc["kind"], doc["data"])
        doc["problem_sha256"] = problem_hash(doc["kind"], doc["data"], doc["options"])
        assert failed_check(doc) in ("objective", "leaf_bounds", "lower_bound")

    def test_understated_gap(self, branched):
        doc = copy.deepcopy(branched)
        item = doc["items"][0]
        item["gap"] = item["gap"] * 0.01  # claims a lower bound the leaves do not reach
        item["lower_bound"] = item["cost"] - item["gap"]
        assert failed_check(doc) == "lower_bound"


@pytest.fixture(scope="module")
def tightened() -> dict:
    """A map certificate whose search cut boxes by node tightening (forced on for a small map)."""
    import geocert.solvers.fractional.maps as maps

    saved, maps.NODE_TIGHTENING_POINTS = maps.NODE_TIGHTENING_POINTS, 0
    try:
        rng = np.random.default_rng(seed("node tightening"))
        for _ in range(20):
            document = solve_job(map_job(rng, "resection", 7, "L2L2", maps=1, noise=3.0))["certificate"]
            item = document["items"][0]
            if item["certified"] and any(p["kind"] == "tightened" for p in item["proof"].get("proofs", [])):
                return document
    finally:
        maps.NODE_TIGHTENING_POINTS = saved
    pytest.fail("no instance with node tightening")


def cut_leaf(document: dict) -> tuple[list, dict]:
    """A leaf closed by a tightened proof, and that proof."""
    proof = document["items"][0]["proof"]
    for leaf in proof["leaves"]:
        if leaf[2] is not None and proof["proofs"][leaf[2]]["kind"] == "tightened":
            return leaf, proof["proofs"][leaf[2]]
    raise AssertionError("no leaf closed by node tightening")


class TestNodeTightening:
    def test_verifies_and_is_strict_json(self, tightened):
        assert verify_document(tightened).valid
        # Infinite bounds (tightened, depth, farkas) are written as null, not as Infinity.
        json.dumps(tightened, allow_nan=False)

    def test_a_cut_part_grown_into_the_proven_range_is_refused(self, tightened):
        doc = copy.deepcopy(tightened)
        leaf, proof = cut_leaf(doc)
        leaf[0], leaf[1] = copy.deepcopy(proof["box"])  # the whole node's box: coverage still holds
        assert failed_check(doc) == "leaf_bounds"

    def test_a_cut_part_without_its_duals_is_refused(self, tightened):
        doc = copy.deepcopy(tightened)
        _, proof = cut_leaf(doc)
        proof["duals"] = [None] * len(proof["duals"])
        assert failed_check(doc) == "leaf_bounds"

    def test_negated_tightening_duals_are_refused(self, tightened):
        doc = copy.deepcopy(tightened)
        _, proof = cut_leaf(doc)
        for i, z in enumerate(proof["duals"]):
            if z is not None:
                proof["duals"][i] = pack(-unpack(z))  # the opposite direction proves nothing useful
        assert failed_check(doc) == "leaf_bounds"


class TestCoverage:
    def test_partition_covers_and_a_missing_sliver_is_found(self):
        root = Box(np.zeros(2), np.ones(2))
        lo = np.array([[0, 0], [0.5, 0], [0.5, 0.25]])
        hi = np.array([[0.5, 1], [1, 0.25], [1, 1]])
        assert uncovered_part(root, lo, hi) is None
        hi_short = hi.copy()
        hi_short[2, 1] = 1 - 1e-12
        gap = uncovered_part(root, lo, hi_short)
        assert gap is not None and gap[0][1] == 1 - 1e-12


class TestVerifierStandsAlone:
    def test_imports_no_conic_solver(self, branched, tmp_path):
        # Reading the registry and checking a whole document, not only importing the module.
        path = tmp_path / "certificate.json"
        path.write_text(json.dumps(branched))
        code = ("import json, sys; from geocert.verify.checks import verify_document; "
                f"valid = verify_document(json.load(open({str(path)!r}))).valid; "
                "bad = [m for m in sys.modules if m.split('.')[0] in "
                "('clarabel', 'cvxpy', 'pyscipopt', 'scs', 'ecos', 'osqp')]; print(json.dumps([valid, bad]))")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
        assert json.loads(out.stdout) == [True, []]


class TestCommandLine:
    def run(self, *args, stdin: str | None = None):
        return subprocess.run([sys.executable, "-m", "geocert.app.cli", *args], input=stdin, capture_output=True, text=True)

    def test_exit_status_valid_invalid_unreadable(self, tmp_path, branched):
        good = tmp_path / "certificate.json"
        good.write_text(json.dumps(branched))
        assert self.run("verify", str(good)).returncode == 0
        bad_doc = copy.deepcopy(branched)
        bad_doc["items"][0]["proof"]["leaves"].pop(0)
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps(bad_doc))
        out = self.run("verify", str(bad))
        assert out.returncode == 1
        assert json.loads(out.stdout)["first_failure"]["check"] == "coverage"
        assert self.run("verify", str(tmp_path / "missing.json")).returncode == 2
        assert self.run("verify", "-", stdin="{not json").returncode == 2
        assert self.run("verify", "-", stdin='{"kind": "triangulation"}').returncode == 2


class TestNodeTighteningHostile:
    """A hostile review of node tightening (3bb336f) and strict JSON for maps' certificates."""

    def test_a_box_closed_before_any_incumbent_is_strict_json_and_verifies(self):
        # max_residual a hair above the smallest largest residual of any camera: no start point
        # is in scope (prepare's region search asks for 1 - 1e-6 of it), the search closes boxes
        # with no cost cap (upper_bound inf), then finds an incumbent and certifies. Those proofs'
        # upper_bound was written as the non-JSON Infinity, and the verifier refused it.
        rng = np.random.default_rng(seed("hrev scope", "L2L2"))
        for _ in range(3):
            job = map_job(rng, "resection", 7, "L2L2", maps=1, noise=3.0)
        job["options"].update(max_residual=4.365090983853207, time_limit_s=10)
        document = solve_job(job)["certificate"]
        item = document["items"][0]
        assert item["certified"]
        assert any(p["upper_bound"] is None for p in item["proof"]["proofs"])  # the path is taken
        json.dumps(document, allow_nan=False)
        assert verify_document(document).valid

    def test_a_tightened_proof_without_its_cost_cap_is_refused(self, tightened):
        doc = copy.deepcopy(tightened)
        _, proof = cut_leaf(doc)
        proof["upper_bound"] = None  # no cap: its duals prove nothing outside the box
        assert failed_check(doc) == "leaf_bounds"

    def test_a_cut_part_reaching_its_proven_side_exactly_is_refused(self, tightened, monkeypatch):
        # A point on a proven side may cost the cap: the leaf must lie strictly outside.
        import geocert.formulations.fractional.proof as proof_module

        ranges, original = {}, proof_module._proven_sides
        monkeypatch.setattr(proof_module, "_proven_sides",
                            lambda *args: ranges.setdefault(args[4], original(*args)))
        assert verify_document(tightened).valid
        leaf, _ = cut_leaf(tightened)
        low, high = ranges[f"proof {leaf[2]}"]
        below = np.flatnonzero(np.asarray(leaf[1]) < low)
        axis, upper = (int(below[0]), 1) if below.size else (int(np.flatnonzero(np.asarray(leaf[0]) > high)[0]), 0)
        side = low[axis] if upper else high[axis]
        results = []
        for value in (float(np.nextafter(side, -np.inf if upper else np.inf)), float(side)):
            doc = copy.deepcopy(tightened)
            cut_leaf(doc)[0][upper][axis] = value  # grown (or shrunk) up to the side
            results.append(failed_check(doc))
        assert results == [None, "leaf_bounds"]  # one float short of the side: accepted

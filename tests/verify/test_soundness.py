"""Certified must mean certified: one class per way a claim could be false or a forged certificate
accepted (issue 11). Each test fails on the code before the soundness work; each says why."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
import scipy.optimize

from geocert.core.certificates import data_hash, pack, problem_hash, unpack
from geocert.core.conic import ConicStatus, solve_conic
from geocert.core.geometry import InputError
from geocert.solvers.fractional.search import root_region
from geocert.jobs.runner import parse_job, solve_job
from geocert.formulations.fractional.relaxation import Relaxation
from geocert.formulations.fractional.charts import Chart
from geocert.core.coverage import uncovered_part
from geocert.verify.checks import verify_any, verify_document
from geocert.core.bnb import Box
from geocert.core.cones import proves_infeasible

from tests.support import every_track_searched, project, random_cameras

CAMERAS = [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]],
           [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]]


def readme_job(u: float = 330.0, mode: str = "summary", norm: str = "L2L2", **options) -> dict:
    """The README's two-view job; its optimum costs 0.5 (L2L2) whatever u, in front of both."""
    return {"kind": "triangulation",
            "data": {"cameras": copy.deepcopy(CAMERAS), "tracks": [{"views": [0, 1], "points": [[u, 250], [250, 251]]}]},
            "options": {"norm": norm, "certificate": mode, **options}}


def failed_check(document) -> str | None:
    report = verify_any(document)
    return None if report.valid else report.first_failure["check"]


def rehash(doc: dict) -> dict:
    """What a forger can always do: make the hashes match whatever the document now says."""
    doc["data_sha256"] = data_hash(doc["kind"], doc["data"])
    doc["problem_sha256"] = problem_hash(doc["kind"], doc["data"], doc["options"])
    return doc


def six_view_job(norm: str, max_residual: float | None, mode: str = "full") -> dict:
    """Six views of one point, exact but for one view off by (3, 3) px."""
    rng = np.random.default_rng(11)
    cameras = random_cameras(rng, 6)
    points = project(cameras, np.array([0.2, -0.1, 0.3, 1.0]))
    points[2] += 3.0
    return {"kind": "triangulation",
            "data": {"cameras": cameras.tolist(), "tracks": [{"views": list(range(6)), "points": points.tolist()}]},
            "options": {"norm": norm, "certificate": mode, "max_residual": max_residual}}


class TestEveryModeIsSafe:
    """Class 1: the summary mode used the solver's own objective where full mode used the safe
    bound; the modes now search alike and differ only in what they return."""

    @pytest.mark.parametrize("norm", ["L2L2", "L2L1", "L1L1"])
    @pytest.mark.parametrize("u", [330.0, 1e6, -1e9, 1e9])
    def test_summary_and_full_prove_the_same_bound(self, u, norm):
        summary = solve_job(readme_job(u, "summary", norm))["tracks"][0]
        full = solve_job(readme_job(u, "full", norm))["tracks"][0]
        assert (summary["status"], summary["cost"]) == (full["status"], full["cost"])
        # The same search; its bounds agree to the verifier's BOUND_TOLERANCE, not to the last bit
        # (pooled conic solvers, conic._Pool, leave differences of about 1e-11 with what the process
        # solved before: one run after the hostile test files gave 0.9999999999461883 against ...624).
        if full["lower_bound"] is None:  # nothing proven (coordinates beyond the limit): in both modes
            assert summary["lower_bound"] is None
        else:
            assert summary["lower_bound"] == pytest.approx(full["lower_bound"], rel=1e-9)

    @pytest.mark.parametrize("u", [1e6, 1e9, -1e9])
    def test_extreme_coordinates_within_the_limit_never_overstate(self, u):
        track = solve_job(readme_job(u))["tracks"][0]
        # 0.5 is attainable in front of both cameras: no true lower bound exceeds it.
        assert track["lower_bound"] is None or track["lower_bound"] <= 0.5 * (1 + 1e-9)
        assert track["status"] in ("optimal", "not_certified", "node_limit")

    @pytest.mark.parametrize("u", [1.0000001e9, 1e15, 1e16, -1e300])
    def test_coordinates_beyond_the_limit_are_refused_with_the_limit(self, u):
        with pytest.raises(InputError) as error:
            parse_job(readme_job(u))
        assert error.value.field == "data/tracks/0/points/0/0"
        assert "1e+09" in error.value.reason


class TestNoFalseInfeasible:
    """Class 2: 'infeasible' was reported when a solver merely failed, and a camera of large
    scale was called rank-deficient."""

    def test_a_camera_of_extreme_scale_is_the_same_camera(self):
        scaled = readme_job()
        scaled["data"]["cameras"][0] = (np.array(CAMERAS[0], float) * 1e300).tolist()
        tiny = readme_job()
        tiny["data"]["cameras"][1] = (np.array(CAMERAS[1], float) * 1e-300).tolist()
        plain = solve_job(readme_job())["tracks"][0]
        for job in (scaled, tiny):
            track = solve_job(job)["tracks"][0]
            assert track["certified"] and track["cost"] == pytest.approx(plain["cost"], rel=1e-12)
            assert np.allclose(track["point"], plain["point"], rtol=1e-9)

    def test_a_rank_deficient_camera_is_named_with_its_singular_values(self):
        job = readme_job()
        job["data"]["cameras"][0] = [[1e300, 0, 0, 0], [2e300, 0, 0, 0], [0, 0, 1e300, 0]]
        with pytest.raises(InputError) as error:
            parse_job(job)
        assert error.value.field == "data/cameras/0" and "singular values" in error.value.reason

    def test_infeasible_only_when_proven(self):
        # Points beyond the coordinate limit never reach the solver; a track whose every box is
        # proven empty of in-scope points (max_residual far below any fit) is not_certified, its
        # reason saying so: the proof is not carried, so "infeasible" would go unchecked.
        job = six_view_job("L2L2", 1e-3, mode="summary")
        track = solve_job(job)["tracks"][0]
        assert track["status"] == "not_certified" and "every box" in track["reason"]


class TestMaxResidualScope:
    """Class 3: incumbents were adopted outside max_residual; under L1L1 the leaves bounded the
    1-norm where the scope is the pixel distance."""

    @pytest.mark.parametrize("norm", ["L2L2", "L2L1", "L1L1"])
    def test_the_solution_is_in_scope_and_its_bound_true(self, norm):
        job = six_view_job(norm, 3.5)
        result = solve_job(job)
        track = result["tracks"][0]
        assert track["status"] == "optimal" and track["certified"]
        cameras = np.array(job["data"]["cameras"])
        points = np.array(job["data"]["tracks"][0]["points"])
        residuals = project(cameras, np.append(track["point"], 1.0)) - points
        assert np.max(np.linalg.norm(residuals, axis=1)) <= 3.5
        assert verify_document(result["certificate"]).valid
        # An independent local optimum of the same problem within the scope is never below the bound.
        cost = {"L2L2": lambda r: float((r**2).sum()), "L2L1": lambda r: float(np.linalg.norm(r, axis=1).sum()),
                "L1L1": lambda r: float(np.abs(r).sum())}[norm]

        def residual_of(x):
            return project(cameras, np.append(x, 1.0)) - points

        best = scipy.optimize.minimize(
            lambda x: cost(residual_of(x)), np.array(track["point"]) + 0.01, method="SLSQP",
            constraints=[{"type": "ineq", "fun": lambda x: 3.5**2 - (residual_of(x) ** 2).sum(axis=1)}])
        if np.max(np.linalg.norm(residual_of(best.x), axis=1)) <= 3.5:
            assert track["lower_bound"] <= cost(residual_of(best.x)) * (1 + 1e-9)

    def test_the_verifier_refuses_a_solution_outside_the_scope(self):
        result = solve_job(six_view_job("L2L2", None))
        doc = rehash(copy.deepcopy(result["certificate"]))
        doc["options"]["max_residual"] = 3.5  # the unbounded optimum has a residual beyond it
        assert failed_check(rehash(doc)) in ("scope", "root_region", "leaf_bounds", "lower_bound")


class TestPointsAtInfinity:
    """Class 4: a point at infinity came back with X[3] = -2.7e-17, which the verifier flipped."""

    def test_zero_disparity_is_at_infinity_and_verifies(self):
        job = readme_job(mode="full")
        job["data"]["tracks"][0]["points"] = [[330, 250], [330, 250]]
        result = solve_job(job)
        track = result["tracks"][0]
        assert track["at_infinity"] and track["point"][3] == 0.0
        depths = np.array(CAMERAS, float)[:, 2] @ np.array(track["point"])
        assert np.all(depths > 0)
        assert verify_document(result["certificate"]).valid


def searched(job: dict) -> dict:
    """solve_job with every track searched (none certified by its convexity, L2L2's usual path)."""
    with every_track_searched():
        return solve_job(job)


@pytest.fixture(scope="module")
def genuine() -> dict:
    """A full certificate of a track that needed a search (README cameras, 3 px of disparity noise)."""
    job = readme_job(mode="full")
    job["data"]["tracks"][0]["points"] = [[330, 250], [251.5, 253]]
    result = searched(job)
    assert result["certificate"]["items"][0]["proof"]["type"] == "branch_and_bound"
    assert verify_document(result["certificate"]).valid
    return result


class TestScaleIsNoLoophole:
    """Class 5: a tiny proof.scale made the absolute slack on cost caps swallow the claim."""

    def test_a_cap_below_the_claim_is_refused_at_any_scale(self, genuine):
        doc = copy.deepcopy(genuine["certificate"])
        item = doc["items"][0]
        proof = item["proof"]
        # Forge: a worse point claimed optimal, with a proof whose leaf is the relaxation at cost
        # cap 0 (infeasible: no point fits exactly), at a scale where the old absolute slack
        # (1e-9, scaled units) exceeded the whole claim.
        bad = [0.5, 0.7, 5.0]
        cams = np.array(CAMERAS, float)
        pts = np.array(doc["data"]["tracks"][0]["points"], float)
        cost = float(((project(cams, np.append(bad, 1.0)) - pts) ** 2).sum())
        scale = 1e-7
        item.update(point=bad, cost=cost, gap=cost * 1e-4, lower_bound=cost - cost * 1e-4)
        chart = Chart.build(cams, pts, "L2L2")
        chart.program.rescale(scale)
        k = len(proof["search_box"][0])
        B = np.array(proof["root"]["functionals"])[:k]
        # The root region proven at the forger's scale, holding the bad point.
        _, _, root = root_region(chart.program, B, math.sqrt(cost) * scale)
        assert root is not None
        proof["root"] = {"gamma": root.gamma, "functionals": root.functionals.tolist(),
                         "claim": [root.claim_lower.tolist(), root.claim_upper.tolist()],
                         "bounds": [root.lower.tolist(), root.upper.tolist()], "duals": [pack(z) for z in root.duals]}
        lower, upper, F = root.lower, root.upper, root.functionals
        relaxation = Relaxation(chart.program, F[:k], (lower[k:], upper[k:]), F)
        box = Box(lower[:k], upper[:k])
        claimed = item["lower_bound"] * scale**2
        for cap in (1e-4 * claimed, 1e-6 * claimed, 1e-8 * claimed):  # all below the old slack of 1e-9
            data = relaxation.conic_data(box, cap)
            res = solve_conic(data.q, data.A, data.b, data.cones)
            if res.status is ConicStatus.INFEASIBLE and proves_infeasible(
                    data.A, data.b, data.cones, res.z, data.lower, data.upper, data.transform):
                break
        else:
            pytest.fail("no cap gave a checkable Farkas vector")
        proof.update(scale=scale, tightening=[], search_box=[box.lo.tolist(), box.hi.tolist()],
                     proofs=[{"box": [box.lo.tolist(), box.hi.tolist()], "upper_bound": cap, "kind": "farkas",
                              "z": pack(res.z), "bound": 1e300}],
                     leaves=[[box.lo.tolist(), box.hi.tolist(), 0]])
        assert failed_check(doc) == "leaf_bounds"

    @pytest.mark.parametrize("scale", [1e-300, 0.0, -1.0, 1e10])
    def test_a_scale_outside_the_solver_range_is_refused(self, genuine, scale):
        doc = copy.deepcopy(genuine["certificate"])
        doc["items"][0]["proof"]["scale"] = scale
        assert failed_check(doc) == "program"


class TestNumbersOnly:
    """Class 6: strings such as "inf" were parsed as numbers, and terms over infinite bounds
    dropped."""

    @pytest.mark.parametrize("value", ["inf", "-inf", "1.5", None, True])
    def test_root_bounds_must_be_finite_json_numbers(self, genuine, value):
        doc = copy.deepcopy(genuine["certificate"])
        doc["items"][0]["proof"]["root"]["bounds"][1][0] = value
        assert failed_check(doc) == "format"

    def test_a_leaf_box_must_be_numbers(self, genuine):
        doc = copy.deepcopy(genuine["certificate"])
        doc["items"][0]["proof"]["leaves"][0][1][0] = "Infinity"
        assert failed_check(doc) == "format"


class TestRelativeTolerances:
    """Class 7: absolute 1e-9 slacks let a trivial proof claim cost 1e-9 where the true cost is
    far smaller."""

    def test_an_exact_track_cannot_claim_a_larger_cost(self):
        cams = np.array(CAMERAS, float) / 800.0  # normalised cameras: residuals of order 1e-12
        X = np.array([0.1, 0.2, 4.0, 1.0])
        points = project(cams, X)
        job = {"kind": "triangulation", "data": {"cameras": cams.tolist(),
               "tracks": [{"views": [0, 1], "points": points.tolist()}]}, "options": {"certificate": "full"}}
        result = solve_job(job)
        item = result["certificate"]["items"][0]
        assert item["proof"]["type"] == "trivial" and item["cost"] < 1e-12
        forged = copy.deepcopy(result["certificate"])
        forged["items"][0].update(cost=1e-9, gap=0.0, lower_bound=1e-9)
        assert failed_check(forged) in ("objective", "lower_bound")


class TestClaimFieldsChecked:
    """Class 8: lower_bound, status, certified and gap were never compared with the proof."""

    @pytest.mark.parametrize("change", [{"lower_bound": 1e6}, {"status": "node_limit"}, {"gap": -1.0},
                                        {"certified": "yes"}, {"lower_bound": "0.1"}])
    def test_a_claim_the_proof_does_not_support_is_refused(self, genuine, change):
        doc = copy.deepcopy(genuine["certificate"])
        doc["items"][0].update(change)
        report = verify_document(doc)
        assert not report.valid


class TestOptionsHashedAndChecked:
    """Class 9: options were neither checked nor hashed: an empty scope made "optimal" vacuous."""

    @pytest.mark.parametrize("max_residual", [-1.0, 0.0, "1"])
    def test_invalid_options_are_an_invalid_certificate(self, genuine, max_residual):
        doc = copy.deepcopy(genuine["certificate"])
        doc["options"]["max_residual"] = max_residual
        assert failed_check(doc) == "options"

    def test_a_narrower_scope_changes_the_hash_and_must_hold_the_solution(self, genuine):
        doc = copy.deepcopy(genuine["certificate"])
        doc["options"]["max_residual"] = 0.001
        assert failed_check(doc) == "data_hash"
        assert failed_check(rehash(doc)) == "scope"

    def test_the_report_states_the_scope(self, genuine):
        report = verify_document(genuine["certificate"]).as_dict()
        assert report["scope"]["norm"] == "L2L2" and report["scope"]["max_residual"] is None
        assert "in front of every camera" in report["scope"]["statement"]


class TestReturnedItemsMatch:
    """Class 10: a result whose numbers differed from its certificate verified."""

    @pytest.mark.parametrize("field, value", [("point", [0.0, 0.0, 5.0]), ("cost", 0.1), ("certified", False)])
    def test_a_result_must_return_what_its_certificate_proves(self, genuine, field, value):
        result = copy.deepcopy(genuine)
        assert verify_any(result).valid and verify_any({"id": "j", "result": result}).valid
        result["tracks"][0][field] = value
        assert failed_check(result) == "returned"
        assert failed_check({"id": "j", "result": result}) == "returned"

    def test_the_command_line_checks_the_result_too(self, genuine, tmp_path):
        result = copy.deepcopy(genuine)
        result["tracks"][0]["point"] = [0.0, 0.0, 5.0]
        path = tmp_path / "result.json"
        path.write_text(json.dumps(result))
        out = subprocess.run([sys.executable, "-m", "geocert.app.cli", "verify", str(path)], capture_output=True, text=True)
        assert out.returncode == 1 and json.loads(out.stdout)["first_failure"]["check"] == "returned"


class TestNoCrashNoExhaustion:
    """Class 11: deep nesting crashed the CLI, and an unserved dimension made the verifier build
    2^18 rows."""

    def test_deep_nesting_is_refused_fast(self, genuine, tmp_path):
        path = tmp_path / "deep.json"
        path.write_text("[" * 100_000 + "]" * 100_000)
        out = subprocess.run([sys.executable, "-m", "geocert.app.cli", "verify", str(path)], capture_output=True, text=True)
        assert out.returncode == 2 and "Traceback" not in out.stderr
        doc = copy.deepcopy(genuine["certificate"])
        nested: list = []
        for _ in range(200):
            nested = [nested]
        doc["data"]["extra"] = nested
        assert failed_check(doc) == "format"

    def test_unserved_dimensions_are_refused_before_any_program_is_built(self, monkeypatch):
        rng = np.random.default_rng(3)
        source = rng.normal(size=(40, 2)).tolist()
        target = rng.normal(size=(40, 18)).tolist()
        doc = {"format": "geocert-certificate", "version": 2, "kind": "homography",
               "options": {"norm": "L1L1", "rel_gap": 1e-3, "abs_gap": 1e-7, "max_residual": None},
               "data": {"maps": [{"source": source, "target": target}]},
               "items": [{"index": 0, "status": "optimal", "certified": True, "cost": 1.0, "gap": 0.0,
                          "lower_bound": 1.0, "matrix": np.eye(19, 3).tolist(), "proof": {"type": "trivial"}}]}
        rehash(doc)
        # The old verifier built this 18-dimensional program (2^18 rows, 18 s and 7 GB); now the
        # data are refused as they are read, and no chart is ever built.
        from geocert.formulations.fractional import items

        def never(*args, **kwargs):
            raise AssertionError("a program was built for a kind or dimension not served")
        monkeypatch.setattr(items.MapChart, "build", never)
        assert failed_check(doc) == "data"

    def test_l1_relaxations_grow_linearly_with_the_dimension(self):
        from geocert.formulations.fractional.charts import MapChart
        rows = {}
        for n in (2, 3):
            rng = np.random.default_rng(n)
            chart = MapChart.build(rng.normal(size=(12, n)), rng.normal(size=(12, n)), "L1L1")
            data = Relaxation(chart.program, np.eye(chart.program.dim)[:n]).conic_data(
                Box(-np.ones(n), np.ones(n)), 10.0)
            rows[n] = data.cones.nonneg
        # Per observation: 2 rows per coordinate, one for the sum, one for the cost cap (and the
        # envelope's five), plus 2 box rows per branched functional: linear in the dimension,
        # where sign enumeration doubled (2 x 4 rows per observation in 2D, 2 x 8 in 3D).
        assert rows[3] - rows[2] == 2 * 12 + 2


class TestStrictTypes:
    """Class 12 (solver side, the CLI's path): strings and booleans are not numbers."""

    @pytest.mark.parametrize("path, value, field", [
        (("data", "tracks", 0, "points", 0, 0), "330", "data/tracks/0/points/0/0"),
        (("data", "tracks", 0, "points", 0, 1), True, "data/tracks/0/points/0/1"),
        (("data", "tracks", 0, "views", 1), 1.0, "data/tracks/0/views"),
        (("data", "cameras", 0, 0, 0), "800", "data/cameras/0/0/0"),
        (("options", "rel_gap"), "1e-3", "options/rel_gap"),
    ])
    def test_loose_types_are_refused(self, path, value, field):
        job = readme_job()
        target = job
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
        with pytest.raises(InputError) as error:
            parse_job(job)
        assert error.value.field == field


# --- property: any perturbation of a genuine certificate is refused, or leaves a true claim ------

def _numbers_in(value, path=()):
    """Paths of every number (and of every dual vector's entries) in a proof or claim."""
    if isinstance(value, dict):
        for key, v in value.items():
            yield from _numbers_in(v, path + (key,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _numbers_in(v, path + (i,))
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield path
    elif isinstance(value, str) and path and path[-1] not in ("kind", "type", "status") and len(value) > 8:
        yield path + ("dual",)


@pytest.fixture(scope="module")
def convexity() -> dict:
    """A full certificate of a track certified by its convexity (the same track as genuine's)."""
    job = readme_job(mode="full")
    job["data"]["tracks"][0]["points"] = [[330, 250], [251.5, 253]]
    result = solve_job(job)
    assert result["certificate"]["items"][0]["proof"]["type"] == "convexity"
    assert verify_document(result["certificate"]).valid
    return result


@pytest.fixture(scope="module")
def genuine_documents(genuine, convexity) -> list[dict]:
    """A branched track, a resection with tightening rounds and several leaves, and a track
    certified by its convexity."""
    from .test_certificates import map_job
    rng = np.random.default_rng(5)
    for _ in range(20):
        document = solve_job(map_job(rng, "resection", 7, "L2L2", maps=1, noise=3.0))["certificate"]
        proof = document["items"][0]["proof"]
        if document["items"][0]["certified"] and proof.get("tightening") and len(proof["leaves"]) >= 3:
            return [genuine["certificate"], document, convexity["certificate"]]
    pytest.fail("no branched resection")


@settings(max_examples=150, deadline=None)
@given(which=st.integers(0, 2), pick=st.integers(0, 10**6), how=st.integers(0, 4),
       amount=st.floats(1e-12, 0.5), section=st.sampled_from(["proof", "claim", "options"]))
def test_a_perturbed_certificate_is_refused_or_still_true(genuine_documents, which, pick, how, amount, section):
    original = genuine_documents[which]
    doc = copy.deepcopy(original)
    item = doc["items"][0]
    if section == "proof":
        paths = [("items", 0, "proof") + p for p in _numbers_in(item["proof"])]
    elif section == "claim":
        paths = [("items", 0, key) for key in ("cost", "lower_bound", "gap")] + \
            [("items", 0) + p for p in _numbers_in({k: item[k] for k in ("point", "matrix") if k in item})]
    else:
        paths = [("options", key) for key in ("rel_gap", "abs_gap")]
    path = paths[pick % len(paths)]
    if path[-1] == "dual":
        *where, _ = path
        target = doc
        for key in where[:-1]:
            target = target[key]
        z = unpack(target[where[-1]]).copy()
        z[pick % len(z)] = z[pick % len(z)] * (1 + amount) if how else -z[pick % len(z)] - amount
        target[where[-1]] = pack(z)
    else:
        target = doc
        for key in path[:-1]:
            target = target[key]
        old = target[path[-1]]
        target[path[-1]] = [old * (1 + amount), old + amount, -old, old * 1e6 + 1, 0.0][how]
    if section == "options":
        rehash(doc)  # a forger recomputes the hashes; the third party compares the scope stated
    report = verify_document(doc)
    if not report.valid:
        return
    # Still valid: the claim must still be true. The optimum lies in [original bound, original
    # cost]; a valid claim's lower bound may not exceed the cost of the original (attainable)
    # solution, and its cost is recomputed from its solution, which must be in scope.
    claim = doc["items"][0]
    assert claim["lower_bound"] <= original["items"][0]["cost"] * (1 + 1e-9)
    assert report.scope["max_residual"] == original["options"].get("max_residual")


class TestConvexityProof:
    """A convexity proof (fractional.convexity) is checked, not trusted: its radius must enclose
    every point costing as little, keep every depth positive and leave the cost convex there;
    it serves L2L2 with no max_residual only."""

    def edited(self, convexity, **changes) -> dict:
        doc = copy.deepcopy(convexity["certificate"])
        doc["items"][0]["proof"].update(changes)
        return doc

    @pytest.mark.parametrize("radius", [1e-12, 1e6, 0.0, -1.0])
    def test_a_radius_that_does_not_prove_is_refused(self, convexity, radius):
        assert failed_check(self.edited(convexity, radius=radius)) == "convexity"

    @pytest.mark.parametrize("field", ["scale", "root"])
    def test_a_field_it_does_not_have_is_refused(self, convexity, field):
        assert failed_check(self.edited(convexity, **{field: 1.0})) == "format"

    @pytest.mark.parametrize("options", [{"norm": "L2L1"}, {"max_residual": 100.0}])
    def test_it_serves_l2l2_over_the_whole_scope_only(self, convexity, options):
        doc = copy.deepcopy(convexity["certificate"])
        doc["options"].update(options)
        rehash(doc)
        assert failed_check(doc) is not None

    def test_a_claimed_bound_above_the_proven_one_is_refused(self, convexity):
        doc = copy.deepcopy(convexity["certificate"])
        item = doc["items"][0]
        item["lower_bound"] = item["cost"] * (1 - 1e-12)
        item["gap"] = item["cost"] - item["lower_bound"]
        assert failed_check(doc) == "lower_bound"

    @staticmethod
    def claimed_at(convexity, point, radius: float) -> tuple[dict, float]:
        """The certificate moved to ``point``: its cost recomputed there, a bound claimed 1e-4
        of it below (within the gap tolerance), the proof's radius ``radius``."""
        doc = copy.deepcopy(convexity["certificate"])
        item = doc["items"][0]
        cameras = np.array(doc["data"]["cameras"], dtype=float)
        proj = cameras @ np.append(point, 1.0)
        cost = float(((proj[:, :2] / proj[:, 2:3] - np.array(doc["data"]["tracks"][0]["points"])) ** 2).sum())
        item.update(point=[float(v) for v in point], cost=cost, lower_bound=cost * (1 - 1e-4), proof={
            "type": "convexity", "radius": radius})
        item["gap"] = cost - item["lower_bound"]
        return doc, item["lower_bound"]

    @pytest.mark.parametrize("along", [1.05, 1.2])
    def test_a_point_off_the_optimum_is_refused(self, convexity, along):
        """The point moved along its ray (to cost 18 and 176, the optimum costing 4.5): no radius
        proves the bound claimed there."""
        point = np.array(convexity["certificate"]["items"][0]["point"]) * along
        for radius in (1e-3, 0.1, 1.0, 5.0, 50.0):
            doc, claimed = self.claimed_at(convexity, point, radius)
            assert claimed > convexity["certificate"]["items"][0]["cost"]  # a false claim
            assert failed_check(doc) in ("convexity", "lower_bound"), radius

    def test_a_point_where_the_cost_is_not_convex_is_refused(self, convexity):
        """Twice as far along the ray the cost's Hessian has a negative eigenvalue (central
        differences): the convexity test refuses every radius."""
        point = np.array(convexity["certificate"]["items"][0]["point"]) * 2
        doc, _ = self.claimed_at(convexity, point, 1.0)
        cameras = np.array(doc["data"]["cameras"], dtype=float)
        observed = np.array(doc["data"]["tracks"][0]["points"])

        def cost(X):
            proj = cameras @ np.append(X, 1.0)
            return ((proj[:, :2] / proj[:, 2:3] - observed) ** 2).sum()

        h, e = 1e-4, np.eye(3) * 1e-4
        hessian = np.array([[(cost(point + e[i] + e[j]) - cost(point + e[i] - e[j]) - cost(point - e[i] + e[j])
                              + cost(point - e[i] - e[j])) / (4 * h * h) for j in range(3)] for i in range(3)])
        assert np.linalg.eigvalsh(hessian)[0] < -1  # not convex there
        for radius in (1e-6, 1e-3, 0.1, 1.0, 10.0, 100.0):
            assert failed_check(self.claimed_at(convexity, point, radius)[0]) == "convexity", radius

    @pytest.mark.parametrize("radius", [5e-324, 2.0 ** -1022, 1e300])
    def test_a_subnormal_or_huge_radius_is_refused(self, convexity, radius):
        assert failed_check(self.edited(convexity, radius=radius)) == "convexity"

    def test_a_subnormal_number_in_the_data_is_refused(self, convexity):
        """A camera's zero entry made the smallest subnormal: the problem is the same to the last
        bit of every residual, but its numbers leave the range the proof's round-off is counted
        for (docs/certificate.md, "Floating point")."""
        doc = copy.deepcopy(convexity["certificate"])
        doc["data"]["cameras"][0][0][1] = 5e-324
        rehash(doc)
        report = verify_any(doc)
        assert report.first_failure["check"] == "convexity" and "subnormal" in report.first_failure["detail"]

    @pytest.mark.parametrize("scale", [2.0 ** 130, 2.0 ** -130])
    def test_huge_or_tiny_data_are_refused(self, convexity, scale):
        """The image plane scaled by a power of two (the cameras' first two rows and the
        observations): exact, the claim scaled with it stays true, but the observations (or the
        cost) leave the proof's range."""
        doc = copy.deepcopy(convexity["certificate"])
        for camera in doc["data"]["cameras"]:
            camera[0] = [v * scale for v in camera[0]]
            camera[1] = [v * scale for v in camera[1]]
        track = doc["data"]["tracks"][0]
        track["points"] = [[v * scale for v in p] for p in track["points"]]
        item = doc["items"][0]
        for name in ("cost", "lower_bound", "gap"):
            item[name] *= scale * scale
        rehash(doc)
        assert failed_check(doc) == "convexity"


class TestHostileReview:
    """What an independent attack on the solver and the verifier found (each reproduced here)."""

    def test_a_barely_varying_depth_is_not_taken_for_a_constant(self):
        # View 1's depth varies by 5e-10 of its row: once taken as constant, far points (x ~ 2e9)
        # were priced wrongly and a bound of 1.25 was certified where 0.8 is attainable.
        eps, f = 5e-10, 1e-3
        cameras = np.array([[[f, 0, 0, 0], [0, f, 0, 0], [0, 0, 1.0, 0]],
                            [[f, 0, 0, -f], [0, f, 0, 0], [eps, 0, 1.0, 0]]])
        points = project(cameras, np.array([1 / eps, 0.0, 1.0, 1.0]))
        points[1, 1] += 1.0
        job = {"kind": "triangulation", "data": {"cameras": cameras.tolist(),
               "tracks": [{"views": [0, 1], "points": points.tolist()}]}}
        track = solve_job(job)["tracks"][0]
        witness = np.array([2000395674.223707, 400.0791355985553, 1.000197837111884, 1.0])
        assert np.all(cameras[:, 2] @ witness > 0)
        witness_cost = float(((project(cameras, witness) - points) ** 2).sum())  # 0.8
        assert track["lower_bound"] <= witness_cost * (1 + 1e-9)

    @pytest.mark.parametrize("f0, z0, norm", [(100.0, 0.1, "L1L1"), (1e3, 1e-2, "L2L2"), (1e5, 1e-4, "L2L2")])
    def test_an_observed_epipole_is_never_certified_above_the_infimum(self, f0, z0, norm):
        # View 0 observes the image of camera 1's centre: points ever closer to that centre, in
        # front of both cameras, cost ever less (infimum 0, not attained). The domain is cut
        # nowhere short of depth 0, so no positive bound can be certified.
        cameras = [[[f0, 0, 0, f0], [0, f0, 0, 0], [0, 0, 1.0, z0]],
                   [[800.0, 0, 320, 0], [0, 800.0, 240, 0], [0, 0, 1.0, 0]]]
        job = {"kind": "triangulation", "data": {"cameras": cameras, "tracks": [
            {"views": [0, 1], "points": [[f0 / z0, 0.0], [330.0, 250.0]]}]}, "options": {"norm": norm}}
        for mode in ("summary", "full"):
            job["options"]["certificate"] = mode
            track = solve_job(job)["tracks"][0]
            assert not track["certified"] or track["lower_bound"] <= 1e-9

    def test_the_solution_as_returned_is_checked_again(self):
        # The point or matrix returned is rounded from the search's variables: its cost and
        # residuals are recomputed from the raw data, and "optimal" survives only when the gap
        # and the scope still hold for them.
        from geocert.formulations.fractional.options import TriangulationOptions
        from geocert.solvers.fractional.search import recomputed_status
        residuals = np.array([[3.0, 0.0], [0.0, 1.0]])
        options = TriangulationOptions(rel_gap=1e-3, max_residual=3.0)
        assert recomputed_status("optimal", residuals, 10.0, 9.995, options) == ("optimal", None)
        status, reason = recomputed_status("optimal", residuals, 10.0, 9.9, options)
        assert status == "not_certified" and "tolerance" in reason
        outside = TriangulationOptions(rel_gap=1e-3, max_residual=3.0 * (1 - 1e-12))
        status, reason = recomputed_status("optimal", residuals, 10.0, 9.995, outside)
        assert status == "not_certified" and "max_residual" in reason
        assert recomputed_status("node_limit", residuals, 10.0, 5.0, options) == ("node_limit", None)

    def test_a_solution_whose_recomputed_cost_misses_the_tolerance_is_not_certified(self):
        cameras = [[[800.0, 0, 0, 0], [0, 800.0, 0, 0], [0, 0, 1.0, 0]],
                   [[800.0, 0, 320, -1120], [0, 800.0, 240, -240], [0, 0, 1.0, -1]]]
        job = {"kind": "triangulation", "data": {"cameras": cameras, "tracks": [
            {"views": [0, 1], "points": [[800.0, 0.0], [330.0, 250.0]]}]}, "options": {"certificate": "full"}}
        result = solve_job(job)
        track = result["tracks"][0]
        if track["certified"]:
            assert track["gap"] <= max(1e-7, 1e-3 * track["cost"])
            assert verify_any(result).valid
        else:
            assert track["status"] == "not_certified" and track["reason"]

    def test_many_views_cost_linear_memory(self):
        import tracemalloc
        rng = np.random.default_rng(2)
        cameras = random_cameras(rng, 1000, spread=20.0)
        points = project(cameras, np.array([0.1, 0.0, 0.2, 1.0]))
        # numpy reports its buffers to tracemalloc. Views^2 arrays of 1000 views held at once
        # (the old reference choice) peak at 72 MB (measured); in blocks, a few MB.
        tracemalloc.start()
        Chart.build(cameras, points, "L2L2")
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        assert peak < 20e6
        job = readme_job()
        job["data"]["cameras"] = [CAMERAS[0]] * 1001
        job["data"]["tracks"][0] = {"views": list(range(1001)), "points": [[1.0, 1.0]] * 1001}
        with pytest.raises(InputError) as error:
            parse_job(job)
        assert "limit of 1000" in error.value.reason

    def test_coverage_needs_no_subtraction_for_a_tree_of_leaves(self, genuine, monkeypatch):
        doc = copy.deepcopy(genuine["certificate"])
        proof = doc["items"][0]["proof"]
        lo, hi = np.array(proof["search_box"][0]), np.array(proof["search_box"][1])
        starts = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.01, 0.99, 8000)[None, :]
        proof["leaves"] = [[starts[:, i].tolist(), (starts[:, i] + 1e-9 * (hi - lo)).tolist(), None]
                           for i in range(8000)]
        # Disjoint leaves are split apart by planes (n log n a level): the quadratic subtraction
        # that took 13 minutes on 8000 leaves is never reached.
        from geocert.core import coverage as proof_module

        def never(*args, **kwargs):
            raise AssertionError("leaves separable by planes were subtracted one by one")
        monkeypatch.setattr(proof_module, "_subtracted", never)
        assert failed_check(doc) == "coverage"
        # A genuine partition into many slabs is still recognised as covering.
        cuts = np.linspace(lo[0], hi[0], 5001)
        cuts[-1] = hi[0]
        leaves_lo = np.tile(lo, (5000, 1))
        leaves_hi = np.tile(hi, (5000, 1))
        leaves_lo[:, 0], leaves_hi[:, 0] = cuts[:-1], cuts[1:]
        assert uncovered_part(Box(lo, hi), leaves_lo, leaves_hi) is None
        leaves_hi[2500, 0] = leaves_lo[2500, 0] + 0.5 * (leaves_hi[2500, 0] - leaves_lo[2500, 0])
        assert uncovered_part(Box(lo, hi), leaves_lo, leaves_hi) is not None


class TestHostileReviewRoundTwo:
    """A second attack, on forged proofs and verifier work."""

    def test_a_root_claim_box_that_misses_the_region_is_refused(self):
        # Dual bounds hold on R ∩ claim. A claim box that R does not meet (one depth -1 there)
        # gets "proven" ranges from a Farkas ray; a depth leaf then "proves" any bound. The
        # solution must be a point of R inside the claim box.
        from geocert.formulations.fractional.relaxation import residual_region, root_bounds, gamma_for
        from geocert.formulations.fractional.items import TrackItem
        from geocert.core.geometry import norm_cost, normalised_cameras
        cameras = copy.deepcopy(CAMERAS) + [[[800, 0, 320, 0], [0, 800, 240, -800], [0.3, 0, 1, 0]]]
        data = {"cameras": cameras, "tracks": [{"views": [0, 1, 2], "points": [[330, 250], [250, 251], [320, 200]]}]}
        options = {"norm": "L2L2", "rel_gap": 0.001, "abs_gap": 1e-07, "max_residual": None}
        cams, pts = np.array(cameras, float), np.array(data["tracks"][0]["points"], float)
        bad = np.array([0.0, 0.0, 100.0, 1.0])  # in front of every camera, a poor fit
        cost = norm_cost(project(cams, bad) - pts, "L2L2")
        program = TrackItem((normalised_cameras(cams), pts), "L2L2").program
        gamma = 2 * gamma_for(cost, "L2L2")
        region = residual_region(program, gamma)
        varying = next(j for j in range(len(program.den)) if not program.exact[j])
        a, c = program.den[varying, :3], program.den[varying, 3]
        y0 = -(c + 1.0) * a / (a @ a)
        lo, hi, F = y0 - 1e-3, y0 + 1e-3, np.eye(3)
        ray = np.zeros(len(region[1]))
        ray[len(program.linear) + varying * 3] = 1.0
        for lam in np.logspace(-8, 3, 200):
            duals = [lam * ray] * 6
            low, high = root_bounds(region, F, duals, lo, hi)
            if np.all(lo < low) and np.all(high < hi):
                break
        box = [lo.tolist(), hi.tolist()]
        proof = {"type": "branch_and_bound", "scale": 1.0,
                 "root": {"gamma": gamma, "functionals": F.tolist(), "claim": box, "bounds": box,
                          "duals": [pack(z) for z in duals]},
                 "tightening": [], "search_box": box,
                 "proofs": [{"box": box, "upper_bound": cost, "kind": "depth", "z": None, "bound": 0.0}],
                 "leaves": [box + [0]]}
        doc = rehash({"format": "geocert-certificate", "version": 2, "kind": "triangulation", "options": options,
                      "data": data, "items": [{"index": 0, "status": "optimal", "certified": True, "cost": cost,
                                               "lower_bound": cost, "gap": 0.0, "point": bad[:3].tolist(),
                                               "at_infinity": False, "proof": proof}]})
        assert failed_check(doc) == "root_region"

    def test_rounds_without_duals_cost_nothing_and_are_capped(self, genuine_documents):
        doc = copy.deepcopy(genuine_documents[1])
        proof = doc["items"][0]["proof"]
        last = proof["tightening"][-1]["box_out"]
        empty = {"upper_bound": proof["tightening"][-1]["upper_bound"], "box_in": last, "box_out": last,
                 "duals": [None] * (2 * len(last[0]))}
        proof["tightening"] += [copy.deepcopy(empty) for _ in range(3)]
        assert verify_document(doc).valid
        proof["tightening"] += [copy.deepcopy(empty) for _ in range(20)]
        assert failed_check(doc) == "tightening"
        moved = copy.deepcopy(genuine_documents[1])
        widened = copy.deepcopy(empty)
        widened["box_out"] = [[x - 1 for x in last[0]], [x + 1 for x in last[1]]]
        moved["items"][0]["proof"]["tightening"].append(widened)
        assert failed_check(moved) == "tightening"

    def test_leaves_no_plane_separates_are_subtracted_within_a_budget(self, monkeypatch):
        # A pinwheel (no separating plane) with many small leaves in its hole, then fillers.
        lo, hi = np.zeros(2), np.ones(2)
        pinwheel = [([0, 0], [0.6, 0.4]), ([0.6, 0], [1, 0.6]), ([0.4, 0.6], [1, 1]), ([0, 0.4], [0.4, 1])]
        boxes = [(np.array(a, float), np.array(b, float)) for a, b in pinwheel]
        for i in range(200):
            x = 0.401 + 0.198 * (i % 20) / 20
            y = 0.401 + 0.198 * (i // 20) / 10
            boxes.append((np.array([x, y]), np.array([x + 0.001, y + 0.001])))
        boxes += [(np.array([0.01, 0.01]), np.array([0.02, 0.02]))] * 5000
        leaves_lo = np.array([b[0] for b in boxes])
        leaves_hi = np.array([b[1] for b in boxes])
        assert uncovered_part(Box(lo, hi), leaves_lo, leaves_hi) is not None
        # The pinwheel with its hole filled covers, and is recognised; with a budget below the
        # work it takes, the same cover is "not shown covered" (refused): the budget is enforced,
        # so the hostile document above stops after MAX_WORK leaf-piece tests (83 s before it).
        from geocert.core import coverage as proof_module
        full = np.array([[0, 0], [0.6, 0], [0.4, 0.6], [0, 0.4], [0.4, 0.4]], float)
        full_hi = np.array([[0.6, 0.4], [1, 0.6], [1, 1], [0.4, 1], [0.6, 0.6]], float)
        assert uncovered_part(Box(lo, hi), full, full_hi) is None
        monkeypatch.setattr(proof_module, "MAX_WORK", 3)
        assert uncovered_part(Box(lo, hi), full, full_hi) is not None


class TestProgramCheck:
    """The verifier compares the program it rebuilds with the raw data at the solution and at
    points around it, all at once: a program differing from the data in one residual, or in one
    depth's sign, is refused (a defect of the chart code could otherwise certify another problem)."""

    @staticmethod
    def altered(monkeypatch, change) -> None:
        from geocert.formulations.fractional.items import TrackItem
        from geocert.verify.fractional import TrackItems

        original = TrackItem.__init__
        # The per-item path is under test: the stacked one (tests/verify/test_stacked_verification.py)
        # proves nothing here.
        monkeypatch.setattr(TrackItems, "proven_together", lambda self, data, options, claims: (set(), ()))

        def init(self, arrays, norm):
            original(self, arrays, norm)
            self.program.num, self.program.den = self.program.num.copy(), self.program.den.copy()
            change(self.program)

        monkeypatch.setattr(TrackItem, "__init__", init)

    def test_the_genuine_program_passes(self, genuine):
        assert failed_check(copy.deepcopy(genuine["certificate"])) is None

    def test_a_residual_differing_from_the_data_is_refused(self, genuine, monkeypatch):
        def change(program):
            program.num[-1, 0, :] *= 1 + 1e-5
        self.altered(monkeypatch, change)
        assert failed_check(copy.deepcopy(genuine["certificate"])) == "program"

    def test_a_depth_of_the_wrong_sign_is_refused(self, monkeypatch):
        document = searched(six_view_job("L2L2", None))["certificate"]  # depths that vary (the README's don't)
        assert failed_check(document) is None

        def change(program):  # numerator and depth both negated: the residuals stay the data's
            varying = np.flatnonzero(~program.exact)[0]  # an exact (constant) depth is not compared
            program.num[varying] *= -1
            program.den[varying] *= -1
        self.altered(monkeypatch, change)
        assert failed_check(document) == "program"


class TestCamerasReadPerDocument:
    """The verifier reads a document's cameras once for all its tracks, and anew for each
    document: cameras changed in place between two verifications are the ones checked."""

    def test_cameras_changed_in_place_are_read_anew(self, genuine):
        doc = copy.deepcopy(genuine["certificate"])
        assert failed_check(doc) is None
        doc["data"]["cameras"][1][0][3] = -700.0  # the same list object, another camera
        rehash(doc)
        assert failed_check(doc) is not None


class TestNestingDepth:
    """The verifier's nesting check walks a document level by level, passing over lists of
    scalars in C: every container is still found, wherever it hides among scalars."""

    def test_depths(self):
        from geocert.core.strict import nesting_depth

        assert nesting_depth(1.0, 64) == 0
        assert nesting_depth({}, 64) == 1
        assert nesting_depth([[1.0, 2]], 64) == 2
        assert nesting_depth({"a": [1, "x", None, True, {"b": []}]}, 64) == 4
        assert nesting_depth([1.0, 2.0, 3.0, [[[]]]], 64) == 4  # behind scalars

    def test_a_deep_document_stops_past_the_limit(self):
        from geocert.core.strict import nesting_depth

        deep: list = [0.0]
        for _ in range(10_000):
            deep = [1.0, deep]
        assert nesting_depth({"items": deep}, 64) == 65

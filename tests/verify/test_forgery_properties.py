"""Whatever numbers a certificate holds, it is refused or its claim is still true (issue 33): a
property over the genuine full certificates of every certified kind (tests/data/certificates).

A forger replaces any float of the document (data, options, claims, proofs, dual vectors'
entries, or the fields the result returns beside them) by a subnormal, 0, -0, a huge or a tiny
normal number, its negative or a nearby number; swaps an embedded certificate, or an item's
proof, for another item's, kind's or option set's; and recomputes the hashes. The verifier then
refuses the result, or every claim it accepts is true by an independent judge: the claimed
solution's cost recomputed from the (perhaps changed) data by the kind's cost function, no
claimed lower bound above the cost of a solution known to exist (the genuine one, where the data
and the scope are unchanged, or one a local search finds), and no claimed cost below a bound
the genuine certificate proved. A field the verifier does not check must be one docs/certificate.md
calls informational."""

from __future__ import annotations

import base64
import copy
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from geocert.core.certificates import unpack
from geocert.verify.checks import verify_any

STORED = Path(__file__).resolve().parents[1] / "data" / "certificates"
NAMES = sorted(path.stem for path in STORED.glob("*.json"))
# What a result returns that proves nothing and says so (docs/certificate.md, "What a certificate
# does not say"): a changed value of these keys, anywhere in a result, is no false claim.
INFORMATIONAL = {"elapsed_s", "solve_s", "cpu_s", "time_s", "nodes", "reason", "bound_reason", "determinacy", "name",
                 "baseline", "linear_K", "starts", "started_from", "rms_px_before", "rms_px_after", "initial_pair",
                 "initial_inliers", "bundle_adjustments", "observations_kept", "outliers_removed", "points_used",
                 "observations_of_dropped_tracks", "observations_of_unregistered_views", "motion_warnings",
                 "critical_motion", "determined", "autocalibration_determined", "root_region", "image_size", "track",
                 "model", "conic_status", "eigenvalue_ratio", "moment_rank", "scope", "note", "meaning", "tracks",
                 "order", "residuals_px", "status", "views_used", "intrinsics_used", "method_used", "images"}
VALUES = ("subnormal", "-subnormal", "zero", "-zero", "huge", "tiny", "negated", "nearby", "far")


@pytest.fixture(scope="module")
def genuine() -> dict:
    """Each stored result, and the bounds its own verification stands behind (item: proven)."""
    out = {}
    for name in NAMES:
        result = json.loads((STORED / f"{name}.json").read_text())
        report = verify_any(result)
        assert report.valid, (name, report.first_failure)
        out[name] = (result, _standing(result["certificate"], report))
    return out


def _standing(document: dict, report) -> dict[int, float]:
    """Each certified claim's lower bound as the report stands behind it."""
    proven = {entry["item"]: entry["proven"] for entry in (report.scope or {}).get("discounted", [])}
    return {claim["index"]: proven.get(claim["index"], claim["lower_bound"]) for claim in document["items"]
            if isinstance(claim, dict) and claim.get("certified") is True}


def _paths(value, path=()):
    """Every float's path, and every dual vector's (a base64 string's, marked "dual")."""
    if isinstance(value, dict):
        for key, v in value.items():
            yield from _paths(v, path + (key,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, path + (i,))
    elif isinstance(value, float):
        yield path
    elif isinstance(value, str) and len(value) >= 12 and path and path[-1] in ("z", "duals") or (
            isinstance(value, str) and len(path) >= 2 and path[-2] == "duals"):
        yield path + ("dual",)


def _new_value(old: float, how: str, nearby: float) -> float:
    return {"subnormal": 5e-324, "-subnormal": -5e-324, "zero": 0.0, "-zero": -0.0, "huge": 1e300, "tiny": 1e-300,
            "negated": -old, "nearby": old * (1 + nearby) + nearby, "far": old * 1e6 + 1.0}[how]


def _rehash(document: dict) -> None:
    """The hashes made again, in the estimates' form the document's hash declares where its data
    and options are unchanged (test_forgeries.rehash), unmarked otherwise."""
    from tests.verify.test_forgeries import rehash

    rehash(document)


def _at(root, path):
    target = root
    for key in path[:-1]:
        target = target[key]
    return target, path[-1]


def _mutate_number(result: dict, path: tuple, how: str, nearby: float, entry: int) -> None:
    if path[-1] == "dual":
        target, key = _at(result, path[:-1])
        z = unpack(target[key]).copy()
        if len(z):
            z[entry % len(z)] = _new_value(float(z[entry % len(z)]), how, nearby)
        target[key] = base64.b64encode(z.astype("<f8").tobytes()).decode("ascii")
    else:
        target, key = _at(result, path)
        target[key] = _new_value(target[key], how, nearby)


def _swap(result: dict, others: dict, pick: int) -> str:
    """Swap an embedded certificate or an item's proof for another's; returns what was swapped."""
    document = result["certificate"]
    certified = [claim for claim in document["items"] if claim.get("certified")]
    names = sorted(others)
    if "camera_certificate" in result and pick % 3 == 0:
        other = others[names[pick % len(names)]][0]["certificate"]
        result["camera_certificate"] = copy.deepcopy(other)
        return "camera_certificate"
    if len(certified) >= 2 and pick % 3 == 1:
        a, b = certified[pick % len(certified)], certified[(pick // 7 + 1) % len(certified)]
        if a is not b:
            a["proof"], b["proof"] = copy.deepcopy(b["proof"]), copy.deepcopy(a["proof"])
            return "proofs swapped between items"
    other = others[names[pick % len(names)]][0]["certificate"]
    claim = certified[pick % len(certified)]
    donors = [c for c in other["items"] if c.get("certified")]
    claim["proof"] = copy.deepcopy(donors[pick % len(donors)]["proof"])
    return "a proof from another document"


# --- the judge: every accepted claim is true ------------------------------------------------------

def _claim_cost(kind: str, data: dict, options: dict, claim: dict) -> float | None:
    """The claim's solution's cost recomputed from the data by the kind's cost function (None
    where its solution is not one of the scope, e.g. behind a camera: then it must be refused)."""
    from geocert.kinds import get_kind
    from geocert.core.geometry import norm_cost

    adapter = get_kind(kind).verification
    if kind in ("triangulation", "reconstruction", "resection", "homography"):
        arrays = adapter.read(data, claim["index"])
        item = adapter.item(arrays, options["norm"])
        solution = item.solution(claim)
        residuals, depths, _ = item.raw_residuals(solution)
        if not item.depths_agree(depths):
            return None
        return norm_cost(residuals, options["norm"])
    if kind == "bilinear":
        from geocert.formulations.bilinear import problem as bilinear_problem

        basis, points = adapter.read(data, claim["index"])
        return bilinear_problem.cost(bilinear_problem.residuals(basis, points, np.array(claim["camera"]),
                                                                np.array(claim["coefficients"])), options["norm"])
    from geocert.formulations.autocalibration import metric_relaxation
    from geocert.formulations.autocalibration import problem as autocalibration_problem
    from geocert.verify.autocalibration import read_data

    cameras, points, size = read_data(data)
    # the frame the claim is posed in: a stratified proof stating reference_scale the unit reference
    # frame, the direct method's and an earlier stratified proof's the reference as given
    unit = options.get("method") != "direct" and "reference_scale" in (claim.get("proof") or {})
    problem = autocalibration_problem.prepare(cameras, points, size, dict(options.get("intrinsics") or {}),
                                              unit_reference=unit)
    if options.get("method") == "direct":
        from geocert.formulations.autocalibration import direct
        from geocert.formulations.autocalibration import direct_relaxation

        setup = direct.setup_for(problem, options["chirality"], exclude=False)
        return direct_relaxation.cost(setup.cameras, setup.from_input(np.array(claim["dual_absolute_quadric"])))
    p = autocalibration_problem.plane_from_input(problem, np.array(claim["plane_at_infinity"]))
    if claim["index"] == 0:
        return autocalibration_problem.affine_cost(problem, p)
    setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
    return metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, np.array(claim["K"])))


SCOPE_OPTIONS = ("max_residual", "intrinsics", "chirality", "coefficients", "coefficient_bound", "camera_bound",
                 "method", "varying_focal", "relaxation_order", "norm")


def _same_problem(kind: str, before: dict, after: dict, index: int) -> bool:
    """Whether the item's data and scope are the genuine ones (its genuine bounds then apply)."""
    from geocert.kinds import get_kind

    adapter = get_kind(kind).verification
    if any(before["options"].get(name) != after["options"].get(name) for name in SCOPE_OPTIONS):
        return False
    if kind in ("autocalibration",):
        return before["data"] == after["data"]
    try:
        old, new = adapter.read(before["data"], index), adapter.read(after["data"], index)
    except Exception:
        return False
    same = all(np.array_equal(np.asarray(a, dtype=float), np.asarray(b, dtype=float), equal_nan=True)
               for a, b in zip(old, new) if a is not None)
    if kind == "bilinear" and same:  # the scope's camera box is the proof's
        box_before = before["items"][index]["proof"].get("camera_box")
        box_after = after["items"][index]["proof"].get("camera_box")
        same = box_before is None or box_before == box_after
    return same


def _judge(name: str, genuine: dict, mutated: dict, report, what: str) -> None:
    original, standing_before = genuine[name]
    document, before = mutated["certificate"], original["certificate"]
    kind = document["kind"]
    standing = _standing(document, report)
    for index, bound in standing.items():
        claim = document["items"][index]
        cost = _claim_cost(kind, document["data"], document["options"], claim)
        assert cost is not None, f"{what}: item {index}'s solution is outside its scope"
        assert abs(cost - claim["cost"]) <= 1e-6 * abs(cost) + 1e-9 * max(1.0, abs(cost)), (what, index, cost, claim)
        assert bound <= cost * (1 + 1e-9) + 1e-300, (what, index, bound, cost)
        if index < len(before["items"]) and _same_problem(kind, before, document, index) \
                and before["items"][index].get("certified"):
            genuine_cost = before["items"][index]["cost"]
            assert bound <= genuine_cost * (1 + 1e-9) + 1e-12 * max(1.0, genuine_cost), (what, index, bound, genuine_cost)
            lower = standing_before.get(index)
            if lower is not None:
                assert claim["cost"] >= lower * (1 - 1e-9) - 1e-12, (what, index, claim["cost"], lower)
    if "camera_certificate" in mutated and mutated.get("camera_certificate") is not None:
        _judge_cameras(original, mutated, what)


def _judge_cameras(original: dict, mutated: dict, what: str) -> None:
    """A certified camera's lower bound is at most its cost and the genuine free camera's."""
    genuine_optimum = {camera["view"]: camera["optimal_cost"] for camera in original["cameras"]
                       if camera.get("optimal_cost") is not None}
    for camera in mutated["cameras"]:
        if camera.get("certified") is True:
            assert camera["lower_bound"] <= camera["cost"] * (1 + 1e-9), (what, camera["view"])
            if camera["view"] in genuine_optimum:
                assert camera["lower_bound"] <= genuine_optimum[camera["view"]] * (1 + 1e-9), (what, camera["view"])


def _informational(path: tuple) -> bool:
    return any(isinstance(key, str) and key in INFORMATIONAL for key in path)


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                   HealthCheck.too_slow])
@given(which=st.sampled_from(NAMES), section=st.sampled_from(["certificate", "proof", "claim", "result", "swap"]),
       pick=st.integers(0, 10**9), how=st.sampled_from(VALUES), nearby=st.floats(1e-12, 1e-2), entry=st.integers(0, 10**6))
def test_a_forged_certificate_is_refused_or_its_claim_still_true(genuine, which, section, pick, how, nearby, entry):
    result = copy.deepcopy(genuine[which][0])
    document = result["certificate"]
    if section == "swap":
        what = _swap(result, genuine, pick)
    else:
        if section == "certificate":  # data, options and claims
            paths = [("certificate",) + p for p in _paths({k: document[k] for k in ("data", "options")})]
        elif section == "proof":
            paths = [("certificate", "items", i, "proof") + p for i, claim in enumerate(document["items"])
                     for p in _paths(claim.get("proof"))]
        elif section == "claim":
            paths = [("certificate", "items", i) + p for i, claim in enumerate(document["items"])
                     for p in _paths({k: v for k, v in claim.items() if k != "proof"})]
        else:
            paths = [p for p in _paths({k: v for k, v in result.items() if k not in ("certificate",)})]
        if not paths:
            return
        path = paths[pick % len(paths)]
        _mutate_number(result, path, how, nearby, entry)
        what = f"{which}: {'/'.join(map(str, path))} {how}"
    _rehash(document)  # a forger recomputes the hashes; the third party compares the scope stated
    report = verify_any(result)
    if not report.valid:
        return
    if section == "result" and _informational(path):
        return
    _judge(which, genuine, result, report, what)


def test_the_judge_catches_a_false_claim(genuine):
    """The judge is no formality: a claim whose lower bound is raised above the genuine cost
    fails it (the verifier refuses it: here it is judged as if it had been accepted)."""
    result = copy.deepcopy(genuine["triangulation_l2l2"][0])
    claim = result["certificate"]["items"][0]
    claim["lower_bound"] = claim["cost"] * 1.5

    class Accepted:
        scope = {}

    with pytest.raises(AssertionError):
        _judge("triangulation_l2l2", genuine, result, Accepted(), "a raised bound")

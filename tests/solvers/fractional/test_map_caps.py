"""Per-term caps of maps (search.BoxProblem.cap_terms, Relaxation.others): proven lower bounds on
the sum of the other terms, which tighten the envelope and residual cone of the costliest
observations (outliers), and their check by the verifier."""

import copy
import dataclasses

import numpy as np
import pytest

from geocert.verify import checks as verify
from geocert.formulations.fractional.results import claim_of
from geocert.core.bnb import Box, BoxStatus
from geocert.core.geometry import norm_terms
from geocert.solvers.fractional import search
from geocert.formulations.fractional.charts import MapChart
from geocert.solvers.fractional.maps import _REASONS, dlt, fit_map
from geocert.formulations.fractional.options import MapOptions
from geocert.solvers.fractional.search import Prepared, prepare
from geocert.solvers.fractional.triangulation import NORMS

from tests.support import scene, seed


def outlier_scene(rng, count: int = 60):
    """A camera seen with 1 px noise and four outlying points (about 30 px off)."""
    _, source, target = scene(rng, "resection", count)
    target = target + rng.normal(size=target.shape)
    target[:4] += rng.normal(size=(4, 2)) * 30.0
    return source, target


def prepared_problem(norm: str, name: str):
    rng = np.random.default_rng(seed("caps", name, norm))
    source, target = outlier_scene(rng)
    chart = MapChart.build(source, target, norm)
    prepared = prepare(chart.program, chart.from_matrix(dlt(source, target)), np.eye(chart.program.dim)[:3],
                       1e-7, None, _REASONS)
    assert isinstance(prepared, Prepared)
    prepared.problem.root = prepared.problem.tighten(prepared.problem.root, prepared.upper, 4)  # as fit_map's rounds
    return rng, chart, prepared


def samples_within(rng, chart, prepared, cap: float, box: Box, count: int = 4000):
    """Maps around the incumbent on every scale, those costing at most ``cap`` with B v in ``box``."""
    problem = prepared.problem
    scales = 10.0 ** rng.uniform(-6, -1, size=(count, 1))
    samples = prepared.incumbent + rng.normal(size=(count, chart.program.dim)) * scales
    costs = np.array([problem.objective(v) for v in samples])
    z = samples @ problem.B.T
    keep = (costs <= cap) & np.all((z >= box.lo) & (z <= box.hi), axis=1)
    return samples[keep], costs[keep]


@pytest.mark.parametrize("norm", NORMS)
def test_caps_bound_the_other_terms_of_every_map_within_the_cap(norm):
    """Every sampled map costing at most the cap has, for each capped observation, the other terms
    summing to at least the proven bound; and the outliers are capped well above 0."""
    rng, chart, prepared = prepared_problem(norm, "others")
    problem = prepared.problem
    cap = 1.05 * prepared.upper
    problem.cap_terms(problem.root, cap, prepared.incumbent)
    assert len(problem.caps) == 2
    chosen = problem.caps[-1].observations
    others = problem.relaxation.others
    assert set(range(4)) <= set(chosen.tolist())  # the four outliers are capped
    # Not vacuous: each outlier's other terms are proven to cost most of the incumbent's cost.
    assert np.all(others[:4] > 0.5 * prepared.upper)
    samples, costs = samples_within(rng, chart, prepared, cap, problem.root)
    assert len(samples) >= 50
    terms = np.array([norm_terms(problem.program.residuals(v), norm) for v in samples])
    rest = costs[:, None] - terms[:, chosen]
    assert np.all(rest >= others[chosen] - 1e-9 * (1 + np.abs(others[chosen])))


@pytest.mark.parametrize("norm", NORMS)
def test_capped_relaxations_stay_below_the_cost_and_tighten_the_bound(norm):
    """With the caps, the bound of boxes around sampled maps stays below their cost, and the
    root's bound rises (the outliers' envelopes and residual cones are tighter)."""
    rng, chart, prepared = prepared_problem(norm, "bounds")
    problem = prepared.problem
    cap = 1.05 * prepared.upper  # caps proven for maps costing up to this, used at the incumbent's cost
    before = problem.bound(problem.root, prepared.upper)
    problem.cap_terms(problem.root, cap, prepared.incumbent)
    after = problem.bound(problem.root, prepared.upper)
    assert before.status == after.status == BoxStatus.BOUNDED
    assert after.lower_bound > before.lower_bound + 0.1 * (prepared.upper - before.lower_bound)
    assert after.lower_bound <= prepared.upper * (1 + 1e-9)
    samples, costs = samples_within(rng, chart, prepared, cap, problem.root)
    z = samples @ problem.B.T
    checked = 0
    for shrink in (0.3, 0.1, 0.03):
        for j in rng.choice(len(samples), size=6, replace=False):
            half = shrink * problem.root.width * rng.uniform(0.2, 1.0, size=3)
            box = Box(np.maximum(problem.root.lo, z[j] - half), np.minimum(problem.root.hi, z[j] + half))
            inside = np.all((z >= box.lo) & (z <= box.hi), axis=1)
            result = problem.bound(box, cap)
            assert result.status != BoxStatus.EMPTY
            if result.status == BoxStatus.BOUNDED:
                assert result.lower_bound <= costs[inside].min() * (1 + 1e-7) + 1e-9
                checked += 1
    assert checked >= 12


@pytest.fixture(scope="module")
def capped_certificate():
    """A 60-point camera with outliers: the search branches, caps its outliers, and certifies.
    (L2L1: under L2L2 the quadratic envelope closes this camera before caps are worth computing.)"""
    rng = np.random.default_rng(seed("caps", "certificate"))
    source, target = outlier_scene(rng)
    options = MapOptions(norm="L2L1", certificate="full")
    result = fit_map(source, target, options)
    assert result.certified, result.reason
    return source, target, options, result


def test_the_verifier_accepts_a_capped_certificate_and_recomputes_its_caps(capped_certificate):
    source, target, options, result = capped_certificate
    proof = result.certificate.proof
    assert len(proof["caps"]) == 2 and any(record.get("caps") == 2 for record in proof["proofs"])
    claim = claim_of(result, matrix=result.matrix)
    verify.verify_arrays("resection", (source, target), dataclasses.asdict(options), claim)

    def refused(change) -> verify.Invalid:
        tampered = copy.deepcopy(claim)
        change(tampered["proof"])
        with pytest.raises(verify.Invalid) as error:
            verify.verify_arrays("resection", (source, target), dataclasses.asdict(options), tampered)
        return error.value

    def without_caps(proof):  # the leaves' duals then face the uncapped relaxations
        del proof["caps"]
        for record in proof["proofs"]:
            record.pop("caps", None)

    assert refused(without_caps).check == "leaf_bounds"

    def lower_cap(proof):  # a round proven only for maps cheaper than the claimed bound
        proof["caps"][0]["upper_bound"] = 0.5 * proof["caps"][0]["upper_bound"]

    assert refused(lower_cap).check == "tightening"

    def swapped(proof):  # each bound attached to another observation: no longer what its dual proves
        observations = proof["caps"][1]["observations"]
        proof["caps"][1]["observations"] = observations[1:] + observations[:1]

    assert refused(swapped).check in ("leaf_bounds", "tightening")

    def no_such_round(proof):
        proof["proofs"][0]["caps"] = 3

    assert refused(no_such_round).check == "format"


def test_caps_wait_for_a_wide_gap_below_the_root():
    """Caps are computed before the box after the root and its two children, and only when one
    of those children left a gap of at least cap_gap times the upper bound."""
    counts = []
    for cap_gap in (1e9, 0.0):
        _, _, prepared = prepared_problem("L2L2", "trigger")
        problem = prepared.problem
        problem.capping, problem.cap_gap = True, cap_gap
        ub = prepared.upper
        root = problem.root
        assert problem.bound(root, ub).status == BoxStatus.BOUNDED
        side = int(np.argmax(root.width))
        middle = 0.5 * (root.lo[side] + root.hi[side])
        left_hi, right_lo = root.hi.copy(), root.lo.copy()
        left_hi[side], right_lo[side] = middle, middle
        for child in (Box(root.lo.copy(), left_hi), Box(right_lo, root.hi.copy())):
            problem.bound(child, ub)
        assert problem.caps == []  # not before the fourth box
        problem.bound(Box(root.lo.copy(), left_hi), ub)
        counts.append(len(problem.caps))
    assert counts == [0, 2]

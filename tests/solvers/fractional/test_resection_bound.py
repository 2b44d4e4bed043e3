"""The resection's bound with no search (fractional.resection_bound): below the optimum the search
finds, certifying well-conditioned cameras, and its forgeries refused by the verifier."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from geocert.core.strict import Invalid
from geocert.solvers.fractional import maps
from geocert.solvers.fractional.maps import fit_map
from geocert.formulations.fractional.options import MapOptions
from geocert.formulations.fractional.resection_bound import resection_bound
from geocert.formulations.fractional.results import claim_of
from geocert.verify.checks import verify_arrays

K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])


def scene(seed: int, k: int, noise: float = 1.0, depth: float = 6.0, spread: float = 1.0, outliers: int = 0):
    rng = np.random.default_rng(seed)
    X = rng.uniform(-spread, spread, (k, 3)) + [0, 0, depth]
    angle = rng.uniform(-0.2, 0.2, 3)
    c, s = np.cos(angle), np.sin(angle)
    R = (np.array([[1, 0, 0], [0, c[0], -s[0]], [0, s[0], c[0]]])
         @ np.array([[c[1], 0, s[1]], [0, 1, 0], [-s[1], 0, c[1]]]))
    P = K @ np.hstack([R, rng.normal(0, 0.2, (3, 1))])
    proj = np.hstack([X, np.ones((k, 1))]) @ P.T
    x = proj[:, :2] / proj[:, 2:] + rng.normal(0, noise, (k, 2))
    x[:outliers] += rng.normal(0, 40 * noise, (outliers, 2))
    return X, x


def searched(X, x, monkeypatch) -> object:
    """The branch and bound's result, the fast path switched off."""
    with monkeypatch.context() as patch:
        patch.setattr(maps, "_sublevel_certified", lambda *args: None)
        return fit_map(X, x, MapOptions(norm="L2L2", rel_gap=1e-6))


CASES = [dict(seed=s, k=k, noise=n, depth=d, outliers=o) for s, (k, n, d, o) in enumerate([
    (7, 1.0, 6.0, 0), (8, 3.0, 3.0, 0), (10, 1.0, 4.0, 2), (12, 2.0, 2.5, 0), (20, 1.0, 6.0, 0), (20, 5.0, 3.0, 4),
    (40, 1.0, 10.0, 0), (60, 2.0, 2.0, 6), (100, 1.0, 6.0, 0)])]


@pytest.mark.parametrize("case", CASES)
def test_bound_is_below_every_cost(case, monkeypatch):
    """Every bound below every cost: the fast bound, at the search's camera and at perturbed ones
    (a proof about any camera of the scope bounds the one optimum), below the search's optimum."""
    X, x = scene(**case)
    result = searched(X, x, monkeypatch)
    assert result.certified and result.nodes > 0
    M = np.array(result.matrix)
    rng = np.random.default_rng(case["seed"])
    for camera in [M] + [M + rng.normal(0, 1e-4 * np.abs(M).max(), M.shape) for _ in range(3)]:
        found = resection_bound(X, x, camera)
        if found is not None:
            assert found[0] <= result.cost * (1 + 1e-9)


def test_most_well_conditioned_cameras_are_certified_with_no_search():
    certified = 0
    total = 0
    for seed in range(20):
        X, x = scene(seed, k=[15, 30, 60, 120][seed % 4], noise=1.0, depth=6.0)
        result = fit_map(X, x, MapOptions(norm="L2L2", certificate="full"))
        total += 1
        if result.certified and result.nodes == 0 and result.certificate.proof["type"] == "sublevel_bound":
            certified += 1
            assert result.gap <= 1e-3 * result.cost
    assert certified >= 0.9 * total


def fast_claim(seed: int = 3, k: int = 40):
    X, x = scene(seed, k)
    options = MapOptions(norm="L2L2", certificate="full")
    result = fit_map(X, x, options)
    assert result.certified and result.certificate.proof["type"] == "sublevel_bound"
    return (X, x), dataclasses.asdict(options), claim_of(result, matrix=result.matrix)


def test_the_verifier_accepts_the_fast_proof():
    arrays, options, claim = fast_claim()
    passed, bound = verify_arrays("resection", arrays, options, claim)
    assert "sublevel_bound" in passed and bound >= claim["lower_bound"]


def refused(arrays, options, claim) -> str:
    with pytest.raises(Invalid) as caught:
        verify_arrays("resection", arrays, options, claim)
    return caught.value.check


def test_a_too_small_radius_is_refused():
    arrays, options, claim = fast_claim()
    claim["proof"]["radius"] *= 0.5
    assert refused(arrays, options, claim) == "sublevel_bound"


def test_a_lower_bound_above_the_proofs_is_refused():
    arrays, options, claim = fast_claim()
    claim["lower_bound"] = claim["cost"]
    claim["gap"] = 0.0
    assert refused(arrays, options, claim) == "lower_bound"


def test_a_gap_the_proof_does_not_give_is_refused():
    arrays, options, claim = fast_claim()
    options["rel_gap"] = 1e-8  # the proof's gap is about 1e-6 of the cost
    assert refused(arrays, options, claim) == "gap"


def test_a_proof_for_another_camera_is_refused():
    """The proof and bound of one camera stated for another (here one 2% costlier): refused."""
    arrays, options, claim = fast_claim()
    X, x = arrays
    other = copy.deepcopy(claim)
    M = np.array(claim["matrix"])
    direction = np.random.default_rng(1).normal(0, np.abs(M).max(), M.shape)
    for scale in 1e-7 * 2.0 ** np.arange(30):
        candidate = M + scale * direction
        proj = np.hstack([X, np.ones((len(X), 1))]) @ candidate.T
        cost = float(((proj[:, :2] / proj[:, 2:] - x) ** 2).sum())
        if cost > 1.02 * claim["cost"]:
            break
    other["matrix"] = candidate.tolist()
    other["cost"] = cost
    other["gap"] = cost - other["lower_bound"]
    options["rel_gap"] = 0.5  # the gap is allowed: only the bound is to refuse
    assert refused(arrays, options, other) in ("sublevel_bound", "lower_bound")


def test_the_proof_is_refused_under_another_norm():
    arrays, options, claim = fast_claim()
    options["norm"] = "L2L1"
    with pytest.raises(Invalid):
        verify_arrays("resection", arrays, options, claim)

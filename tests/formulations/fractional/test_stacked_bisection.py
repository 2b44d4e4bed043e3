"""The resection bound's smallest-eigenvalue bisection (resection_sublevel.least_eigenvalue_below)
tests several midpoints at once by one stacked Cholesky factorisation
(fixed_order.cholesky_completes): each answer, and so the kappa returned, must be the one the
factorisations one at a time give, since writer and verifier must compute one float."""

from __future__ import annotations

import math

import numpy as np
import pytest

from geocert.formulations.fractional import resection_sublevel
from geocert.formulations.fractional.fixed_order import cholesky, cholesky_completes


def one_at_a_time(M: np.ndarray, allowance: float, steps: int) -> float | None:
    """The bisection as written before the stacked tests: one least_eigenvalue_above a midpoint."""
    above = resection_sublevel.least_eigenvalue_above
    hi = float(np.diag(M).min())
    if not (hi > 0 and math.isfinite(hi)):
        return None
    lo = hi
    for _ in range(60):
        lo *= 0.5
        if above(M, lo, allowance):
            break
    else:
        return None
    hi = min(hi, 2 * lo)
    for _ in range(steps):
        middle = 0.5 * (lo + hi)
        if not lo < middle < hi:
            break
        if above(M, middle, allowance):
            lo = middle
        else:
            hi = middle
    return lo


def matrices(count: int, seed: int):
    rng = np.random.default_rng(seed)
    for trial in range(count):
        n = int(rng.integers(1, 13))
        A = rng.normal(size=(n, n)) * 10.0 ** rng.uniform(-5, 5)
        M = A @ A.T + np.diag(rng.uniform(0, 1, n)) * 10.0 ** rng.uniform(-12, 2)
        if trial % 7 == 0:
            M[0, 0] = -1.0  # no positive kappa passes
        if trial % 11 == 0 and n > 1:
            M[-1, 0] = np.inf
        yield rng, M


def test_a_stacked_factorisation_completes_exactly_where_one_alone_does():
    completed = failed = 0
    for rng, M in matrices(400, 3):
        shifts = rng.normal(size=7) * float(np.abs(M[np.isfinite(M)]).max())
        stack = np.stack([M - shift * np.eye(len(M)) for shift in shifts])
        answers = cholesky_completes(stack)
        with np.errstate(all="ignore"):  # an infinite entry's inner products
            alone = [cholesky(m) is not None for m in stack]
        assert answers.tolist() == alone
        completed, failed = completed + sum(alone), failed + len(alone) - sum(alone)
    assert completed > 200 and failed > 200  # both answers are exercised


@pytest.mark.parametrize("steps", [1, 5, 48, 60])
def test_the_stacked_bisection_returns_the_one_at_a_time_kappa_to_the_last_bit(steps):
    found = 0
    for rng, M in matrices(150, steps):
        allowance = float(10.0 ** rng.uniform(-20, 0)) * float(np.abs(np.diag(M)).max())
        kappa = resection_sublevel.least_eigenvalue_below(M, allowance, steps)
        with np.errstate(all="ignore"):
            expected = one_at_a_time(M, allowance, steps)
        assert repr(kappa) == repr(expected)
        found += kappa is not None
    assert found > 50


@pytest.mark.parametrize("guess", ["none", "random", "halved"])
def test_the_predicted_margins_choose_what_is_tested_never_an_answer(monkeypatch, guess):
    """A wrong prediction (nothing, random margins, every margin halved) costs factorisations,
    never the kappa: each answer comes from a factorisation of its own margin."""
    predict = resection_sublevel._predicted_margins

    def wrong(M, allowance, halvings, hi, steps):
        if guess == "none":
            return []
        if guess == "random":
            return list(np.random.default_rng(len(halvings)).uniform(0, hi, 40))
        return [0.5 * margin for margin in predict(M, allowance, halvings, hi, steps)]

    monkeypatch.setattr(resection_sublevel, "_predicted_margins", wrong)
    for rng, M in matrices(60, 17):
        allowance = float(10.0 ** rng.uniform(-20, 0)) * float(np.abs(np.diag(M)).max())
        kappa = resection_sublevel.least_eigenvalue_below(M, allowance, 48)
        with np.errstate(all="ignore"):
            assert repr(kappa) == repr(one_at_a_time(M, allowance, 48))


def test_the_predicted_path_leaves_few_factorisations_on_a_resection_like_matrix(monkeypatch):
    """On well-scaled 11 x 11 matrices the eigenvalue's path is the factorisations' to the last
    steps: the bisection then takes one stack of them and a few more, not one stack every
    BISECTION_LEVELS steps."""
    stacks = []
    shifted = resection_sublevel._shifted
    monkeypatch.setattr(resection_sublevel, "_shifted", lambda M, margins, allowance: (
        stacks.append(len(margins)), shifted(M, margins, allowance))[1])
    rng = np.random.default_rng(5)
    for _ in range(20):
        A = rng.normal(size=(11, 40))
        M = A @ A.T
        stacks.clear()
        kappa = resection_sublevel.least_eigenvalue_below(M, 1e-12 * float(np.trace(M)), 48)
        assert repr(kappa) == repr(one_at_a_time(M, 1e-12 * float(np.trace(M)), 48))
        assert len(stacks) <= 3, stacks

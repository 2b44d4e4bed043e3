"""A map estimate's level reads its squared residuals computed exactly
(fractional.determinacy.exact_squared_residuals): checked against rational arithmetic (Fractions)
on data near and far from the origin, maps of P^2 and P^3, so that the float it returns is the
exact sum rounded at most a few times (each residual once, the sum once), whatever machine."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from geocert.formulations.fractional.determinacy import exact_squared_residuals


def _rational(source, target, matrix) -> Fraction:
    """The squared residuals' sum, each residual rounded to the nearest float (as the function's
    are), in exact arithmetic otherwise."""
    M = [[Fraction(v) for v in row] for row in matrix]
    total = Fraction(0)
    for X, x in zip(source.tolist(), target.tolist()):
        image = [sum(m * Fraction(v) for m, v in zip(row, X + [1.0])) for row in M]
        for k, t in enumerate(x):
            total += Fraction(float(Fraction(t) - image[k] / image[-1])) ** 2
    return total


@pytest.mark.parametrize("offset", [0.0, 1e3, 1e6, 1e8])
@pytest.mark.parametrize("dims", [(3, 2), (2, 2), (3, 3)])
def test_the_sum_is_the_rational_one_rounded_once(offset, dims):
    rng = np.random.default_rng(int(offset) % 97 + dims[0] + 10 * dims[1])
    n = 12
    source = rng.uniform(-1, 1, (n, dims[0])) + offset
    matrix = rng.normal(size=(dims[1] + 1, dims[0] + 1))
    image = np.hstack([source, np.ones((n, 1))]) @ matrix.T
    target = image[:, :-1] / image[:, -1:] + rng.normal(0, 1e-6, (n, dims[1]))
    exact = _rational(source, target, matrix)
    assert exact_squared_residuals(source, target, matrix) == float(exact)


def test_an_exact_fit_costs_its_residuals_rounding_only():
    source = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [0.5, 0.25]])
    matrix = np.array([[2.0, 0.0, 1.0], [0.0, 4.0, -1.0], [0.0, 0.0, 1.0]])  # dyadic: images exact
    target = source * [2.0, 4.0] + [1.0, -1.0]
    assert exact_squared_residuals(source, target, matrix) == 0.0


def test_a_point_on_the_plane_at_infinity_costs_infinity():
    source = np.array([[1.0, 0.0], [0.0, 1.0]])
    matrix = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, -1.0]])  # the first point's depth is 0
    assert exact_squared_residuals(source, np.zeros((2, 2)), matrix) == float("inf")


def test_a_sum_beyond_the_largest_float_is_infinity():
    source = np.array([[0.0, 0.0]])
    matrix = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert exact_squared_residuals(source, np.array([[1e200, 1e200]]), matrix) == float("inf")

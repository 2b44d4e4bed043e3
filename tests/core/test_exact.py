"""core.exact: residuals computed exactly and rounded once, against Fractions, and the cost every
machine computes from them."""

from fractions import Fraction

import numpy as np
import pytest

from geocert.core import exact


def _by_fractions(matrix: np.ndarray, point: np.ndarray, target: np.ndarray) -> list[float]:
    image = [sum(Fraction(m) * Fraction(v) for m, v in zip(row, point)) for row in matrix]
    return [float(Fraction(t) - image[k] / image[-1]) for k, t in enumerate(target)]


@pytest.mark.parametrize("offset", [0.0, 1e3, 1e6, 1e9])
def test_a_maps_residuals_are_the_exact_ones_rounded_once(offset):
    rng = np.random.default_rng(3)
    matrix = rng.normal(size=(3, 4))
    points = np.hstack([rng.normal(size=(40, 3)) + offset, np.ones((40, 1))])
    targets = rng.normal(size=(40, 2)) * 300
    residuals = exact.residuals(matrix, points, targets)
    for i in range(40):
        assert residuals[i].tolist() == _by_fractions(matrix, points[i], targets[i])


def test_a_tracks_residuals_one_matrix_an_observation():
    rng = np.random.default_rng(4)
    cameras = rng.normal(size=(7, 3, 4)) * 10.0 ** rng.integers(-200, 200, size=(7, 1, 1))
    point = np.array([1e6 + 0.1, -2e5, 3.3, 1.0])
    targets = rng.normal(size=(7, 2))
    residuals = exact.residuals(cameras, point, targets)
    for i in range(7):
        assert residuals[i].tolist() == _by_fractions(cameras[i], point, targets[i])


def test_the_float_evaluation_is_off_where_the_exact_one_is_not():
    """The premise: 1e8 from the origin, a float residual is off its exact value by far more than
    its size's rounding, so a cost stated from floats depends on the machine's kernels."""
    rng = np.random.default_rng(5)
    matrix = np.hstack([np.eye(3), -np.array([[1e8], [2e8], [-1e8]])]) * 800.0
    matrix[2] = [0.1, 0.2, 1.0, -(0.1e8 + 0.4e8 - 1e8)]
    points = np.hstack([rng.uniform(-1, 1, (30, 3)) + [1e8, 2e8, -1e8 + 5], np.ones((30, 1))])
    projected = points @ matrix.T
    targets = projected[:, :2] / projected[:, 2:] + rng.normal(0, 1e-6, (30, 2))
    floats = targets - projected[:, :2] / projected[:, 2:]
    exact_residuals = exact.residuals(matrix, points, targets)
    assert np.max(np.abs(floats - exact_residuals)) > 1e3 * np.max(np.spacing(np.abs(exact_residuals)))
    assert exact.needs_exact(floats, np.abs(floats - exact_residuals), float((floats**2).sum()), "L2L2", 1e-9)


def test_a_depth_of_zero_or_a_residual_past_the_largest_float_is_infinite():
    matrix = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 0, 0]])
    assert np.all(np.isinf(exact.residuals(matrix, np.array([1.0, 2.0, 3.0, 1.0]), np.zeros((1, 2)))))
    tiny = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 0, 5e-324]])
    residuals = exact.residuals(tiny, np.array([1e300, -1e300, 3.0, 1.0]), np.zeros((1, 2)))
    assert residuals.tolist() == [[-np.inf, np.inf]]


@pytest.mark.parametrize("norm", ["L2L2", "L2L1", "L1L1"])
def test_the_cost_does_not_depend_on_the_order_of_the_observations(norm):
    rng = np.random.default_rng(6)
    residuals = rng.normal(size=(1001, 2)) * 10.0 ** rng.uniform(-8, 3, size=(1001, 1))
    costs = {exact.cost(residuals[order], norm) for order in (np.arange(1001), rng.permutation(1001),
                                                               np.arange(1001)[::-1])}
    assert len(costs) == 1
    terms = [Fraction(t) for t in exact.norm_terms(residuals, norm)]
    assert costs.pop() == float(sum(terms))

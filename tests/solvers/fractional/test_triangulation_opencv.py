"""Two views: the certified L2L2 optimum is the Hartley-Sturm correction (OpenCV's correctMatches)."""

import cv2
import numpy as np
import pytest

from geocert.core.geometry import fundamental_from_cameras
from geocert.solvers.fractional.triangulation import TriangulationOptions, triangulate

from tests.support import random_cameras


def correct_matches_cost(cameras: np.ndarray, points: np.ndarray) -> float:
    F = fundamental_from_cameras(cameras[0], cameras[1])
    new1, new2 = cv2.correctMatches(F, points[0].reshape(1, 1, 2), points[1].reshape(1, 1, 2))
    return float(np.sum((new1.ravel() - points[0]) ** 2) + np.sum((new2.ravel() - points[1]) ** 2))


class TestTwoViewsAgainstOpenCV:
    @pytest.mark.parametrize("seed", range(4))
    def test_cost_equals_correct_matches(self, seed):
        rng = np.random.default_rng(seed)
        options = TriangulationOptions(norm="L2L2", rel_gap=1e-6)
        for _ in range(30):  # 120 instances over the four seeds
            cameras = random_cameras(rng, 2)
            X = np.append(rng.normal(size=3), 1.0)
            proj = cameras @ X
            points = proj[:, :2] / proj[:, 2:3] + rng.normal(size=(2, 2)) * rng.uniform(0.1, 5.0)
            reference = correct_matches_cost(cameras, points)
            result = triangulate(cameras, points, options)
            assert result.certified, result.reason
            assert result.cost == pytest.approx(reference, rel=1e-6, abs=1e-12)
            assert result.lower_bound <= reference * (1 + 1e-9) + 1e-12
            # the gap really was closed to the stated tolerance
            assert result.gap <= max(options.abs_gap, options.rel_gap * result.cost) * (1 + 1e-9)

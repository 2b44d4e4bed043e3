"""Hostile scenes (bench.hostile_triangulation's: cameras multiplied by -1, 1e-6 or 1e6, points up
to 1e6 away or at infinity, gross outliers, observations clipped at 1e8). Whatever either
triangulation path certifies, the per-item verifier accepts; where it could not, the solver says
so and does not certify. The tracks named here were certified and refused before the solver
checked its own claims as the verifier does."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.hostile_triangulation import refused, scene
from geocert.solvers.core.geometry import normalised_cameras
from geocert.solvers.core.strict import Invalid
from geocert.solvers.fractional.items import TrackItem
from geocert.solvers.fractional.proof import check_program
from geocert.solvers.fractional.batched import triangulate_many
from geocert.solvers.fractional.triangulation import TriangulationOptions, triangulate

from tests.support import noisy_track, random_cameras, seed


@pytest.fixture(scope="module")
def scenes() -> dict:
    return {seed: scene(seed, 400) for seed in (1, 2)}


def options(norm: str) -> TriangulationOptions:
    return TriangulationOptions(norm=norm, certificate="full", max_nodes=300)


def both(scenes, seed: int, index: int, norm: str):
    cameras, tracks = scenes[seed]
    views, points = tracks[index]
    return (cameras, views, points,
            {"batched": triangulate_many(cameras, [tracks[index]], options(norm))[0],
             "track by track": triangulate(cameras[views], points, options(norm))})


# (seed, norm, track): what the verifier refused before. BEHIND: a point returned behind the
# cameras (the chart's point just beyond the plane at infinity, divided by its negative last
# coordinate). SCALED: the program's agreement with the data was judged on depths compared across
# views, so a camera multiplied by 1e-6 next to one multiplied by 1e6 went unchecked, or a point
# near one view's principal plane was compared where its residual is round-off. ILL: a point so
# near a principal plane (relative depth 8e-12, an observation at 8e5 px) that the data determine
# its cost only to within the tolerance.
BEHIND = [(1, "L2L2", 46), (1, "L2L2", 81), (2, "L2L2", 148), (2, "L2L2", 171), (2, "L2L2", 352)]
SCALED = [(1, "L2L2", 131), (1, "L2L1", 90), (1, "L2L1", 106), (1, "L2L1", 394), (1, "L1L1", 227)]
ILL = [(1, "L2L2", 68)]


class TestEveryCertifiedClaimVerifies:
    @pytest.mark.parametrize("seed, norm, index", BEHIND + SCALED + ILL)
    def test_certified_only_what_the_verifier_accepts(self, scenes, seed, norm, index):
        cameras, views, points, results = both(scenes, seed, index, norm)
        for path, result in results.items():
            if result.certified:
                assert refused(cameras, views, points, result, options(norm)) is None, path
            else:
                assert result.cost is not None and result.lower_bound is not None, path


class TestPointsBeyondInfinity:
    @pytest.mark.parametrize("seed, norm, index", BEHIND)
    def test_returned_at_infinity_in_front_of_every_camera(self, scenes, seed, norm, index):
        cameras, views, points, results = both(scenes, seed, index, norm)
        P = normalised_cameras(cameras[views])
        for path, result in results.items():
            X = np.append(result.point, 1.0) if not result.at_infinity else np.array(result.point)
            assert np.all(P[:, 2] @ X > 0), path
            # The optimum is approached towards the plane at infinity: the point is returned on it.
            assert result.at_infinity, path
            assert result.certified, path


class TestCamerasOfAnyScale:
    @pytest.mark.parametrize("seed, norm, index", SCALED)
    def test_certified_and_verified(self, scenes, seed, norm, index):
        cameras, views, points, results = both(scenes, seed, index, norm)
        for path, result in results.items():
            assert result.certified, path
            assert refused(cameras, views, points, result, options(norm)) is None, path

    @pytest.mark.parametrize("seed, norm, index", SCALED)
    @pytest.mark.parametrize("exponent", [-40, 40])
    def test_the_verdict_does_not_depend_on_a_cameras_scale(self, scenes, seed, norm, index, exponent):
        # A camera multiplied by a power of two is the same camera, and every product scales
        # exactly: the same claim must verify.
        cameras, views, points, results = both(scenes, seed, index, norm)
        scaled = cameras.copy()
        scaled[views[0]] *= 2.0 ** exponent
        assert refused(scaled, views, points, results["track by track"], options(norm)) is None


class TestIllConditionedSolutions:
    @pytest.mark.parametrize("seed, norm, index", ILL)
    def test_not_certified_and_the_reason_given(self, scenes, seed, norm, index):
        cameras, views, points, results = both(scenes, seed, index, norm)
        for path, result in results.items():
            assert not result.certified and result.status == "not_certified", path
            assert "determine the solution's cost only to within" in result.reason, path
            assert 0 <= result.lower_bound <= result.cost, path

    @pytest.mark.parametrize("seed, norm, index", ILL)
    def test_the_verifier_refuses_it_as_certified(self, scenes, seed, norm, index):
        cameras, views, points, results = both(scenes, seed, index, norm)
        forged = dataclasses.replace(results["track by track"], status="optimal", certified=True)
        assert forged.certificate.proof is not None
        assert "determine the solution's cost only to within" in refused(cameras, views, points, forged, options(norm))


class TestProgramCheckSeesEveryView:
    """proof.check_program compares the verifier's own program (rebuilt from the data) with the
    data; a chart wrong in one view must be caught, whatever that camera's scale."""

    def item(self, exponent: int, wrong: float):
        rng = np.random.default_rng(seed("program check", str(exponent)))
        cameras = random_cameras(rng, 4)
        X, points = noisy_track(rng, cameras)
        cameras[2] *= 2.0 ** exponent  # the same camera
        item = TrackItem((normalised_cameras(cameras), points), "L2L2")
        item.program.num[2, 0] *= 1 + wrong  # as if the chart were built wrong in view 2
        return item, X

    @pytest.mark.parametrize("exponent", [-60, 0, 60])
    def test_a_wrong_view_is_refused(self, exponent):
        item, X = self.item(exponent, 1e-3)
        with pytest.raises(Invalid, match="residuals differ"):
            check_program(item, X, 1.0)

    @pytest.mark.parametrize("exponent", [-60, 0, 60])
    def test_a_right_program_passes(self, exponent):
        item, X = self.item(exponent, 0.0)
        check_program(item, X, 1.0, strictness=0.5)

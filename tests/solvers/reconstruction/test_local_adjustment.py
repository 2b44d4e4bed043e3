"""The registration's adjustments after each view (geocert.solvers.reconstruction.calibrated): COLMAP's
schedule, a whole adjustment once the registered views have grown by global_adjustment_growth,
a local one in between (the new view and the views sharing most points with it, with the points
they see). Synthetic dense ring (synthetic.ring: the templeRing's layout), exact or noisy tracks."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.solvers.reconstruction import calibrated, synthetic
from geocert.solvers.reconstruction.calibrated import CalibratedOptions, calibrated_reconstruction

from testing.reconstruction import aligned_rotation_errors


@pytest.fixture(scope="module")
def ring():
    return synthetic.ring(views=30, points=500, noise_px=0.3, seed=3)


def _registered_state(ring, views: int):
    """A _State with the first ``views`` views placed at the truth moved by a small error each,
    and every track they see triangulated."""
    state = calibrated._State(ring.tracks, [ring.K] * len(ring.rotations))
    rng = np.random.default_rng(0)
    from scipy.spatial.transform import Rotation
    for v in range(views):
        state.R[v] = ring.rotations[v] if v == 0 else Rotation.from_rotvec(rng.normal(scale=2e-3, size=3)).as_matrix() @ ring.rotations[v]
        state.t[v] = ring.translations[v] + (0 if v == 0 else rng.normal(scale=1e-2, size=3))
    # the gauge: view 0 at R = I, t = 0
    R0, t0 = state.R[0].copy(), state.t[0].copy()
    for v in range(views):
        state.t[v] = state.t[v] - state.R[v] @ R0.T @ t0
        state.R[v] = state.R[v] @ R0.T
    calibrated._triangulate_new(state, CalibratedOptions())
    return state


class TestLocalAdjustment:
    def test_only_the_free_views_and_their_points_move(self, ring):
        state = _registered_state(ring, 12)
        before_R = [None if R is None else R.copy() for R in state.R]
        before_points = state.points.copy()
        free = calibrated._local_views(state, 11, 4)
        assert free[0] == 11 and len(free) == 4
        calibrated._bundle_adjust_schur(state, 0, 10, CalibratedOptions(), free_views=free)
        moved = [v for v in range(12) if not np.allclose(state.R[v], before_R[v], atol=0, rtol=0)]
        assert set(moved) <= set(free.tolist()) - {0} and 11 in moved
        seen_by_free = np.zeros(len(state.points), bool)
        seen_by_free[state.obs_track[np.isin(state.obs_view, free) & state.inlier]] = True
        unchanged = ~seen_by_free & np.isfinite(before_points[:, 0])
        assert np.array_equal(state.points[unchanged], before_points[unchanged])

    def test_a_local_adjustment_lowers_the_cost_of_the_views_it_moves(self, ring):
        state = _registered_state(ring, 12)

        def cost():
            obs = np.flatnonzero(state.inlier & state.registered[state.obs_view]
                                 & np.isfinite(state.points[state.obs_track, 0]))
            errors, _ = state.reprojection(obs)
            return float((errors ** 2).sum())

        before = cost()
        calibrated._bundle_adjust_schur(state, 0, 10, CalibratedOptions(), free_views=calibrated._local_views(state, 11, 6))
        assert cost() < before


@pytest.mark.slow  # two reconstructions of a 30-view ring
class TestSchedule:
    def test_whole_adjustments_follow_the_growth_and_the_result_matches(self, ring):
        truth = ring.rotations
        runs = {}
        for growth in (1.0, 1.1):
            result = calibrated_reconstruction(ring.tracks, [ring.K] * len(truth),
                                               CalibratedOptions(global_adjustment_growth=growth))
            runs[growth] = result
            assert all(R is not None for R in result.rotations)
            assert set(result.stats["registered_by"].values()) == {"initial pair", "pnp"}  # one view at a time
        # the pair's adjustment is whole; then view k + 1 is adjusted whole when k + 1 >= 1.1 x the
        # views at the last whole one
        whole_at, expected = 2, {"whole": 1, "local": 0}
        for count in range(3, len(truth) + 1):
            if count < 1.1 * whole_at:
                expected["local"] += 1
            else:
                expected["whole"] += 1
                whole_at = count
        assert runs[1.1].stats["adjustments"] == expected
        assert runs[1.0].stats["adjustments"] == {"whole": len(truth) - 1, "local": 0}
        errors = {g: float(np.median(aligned_rotation_errors(r.rotations, truth))) for g, r in runs.items()}
        assert errors[1.1] <= max(1.2 * errors[1.0], 0.05), errors

"""Issue 14's K-known path on its hard case, and the final adjustment's parts that make it work.

Middlebury's dinoSparseRing (Seitz, Curless, Diebel, Scharstein and Szeliski, CVPR 2006): 14 photos
of an untextured object on a turntable with ground-truth K, R, t; the views form one open chain
(0007 ... 0016, 0001 ... 0004) that breaks for PnP at 0013|0014. The synthetic tests use the
textured box scene's cameras (geocert.solvers.reconstruction.render) with exact or perturbed tracks.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from geocert.solvers.reconstruction import calibrated
from testing.camera_errors import align_rotations
from geocert.solvers.reconstruction.calibrated import CalibratedOptions, calibrated_reconstruction
from geocert.pipelines.reconstruction.features import FeatureOptions, tracks_from_images
from geocert.solvers.reconstruction.render import box_scene

from tests.support import shared_data

# What the ring needs (bench/reconstruction_images.py uses the same): faint SIFT keypoints, a
# loose ratio test, a 2 px epipolar threshold, guided matching, and a second reconstruction merged.
RING_FEATURES = FeatureOptions(max_features=0, contrast_threshold=0.005, ratio=0.85, ransac_threshold_px=2.0,
                               guided_ratio=0.8)
RING_CALIBRATED = CalibratedOptions(pnp_min_inliers=10, merge_components=True)


@pytest.fixture(scope="module")
def scene():
    return box_scene(n_views=8, arc_deg=150.0, seed=0)


def _tracks_with_two_view_shifts(scene, shift_px: float):
    """300 exact tracks of 3 views or more, and 200 two-view tracks of neighbouring views whose
    second observation is moved ``shift_px`` to the right (within the outlier threshold, so they
    stay inliers, but they fit the cameras only if the cameras move)."""
    rng = np.random.default_rng(7)
    cams = scene.cameras
    tracks = []
    for x in rng.uniform([-0.5, -0.4, 0.0], [0.5, 0.4, 0.6], size=(300, 3)):
        views = np.array([v for v in range(8) if rng.random() < 0.7])
        if len(views) < 3:
            views = np.array([0, 1, 2]) + rng.integers(0, 6)
        tracks.append((views, np.array([cams[v].project(x)[0] for v in views])))
    for x in rng.uniform([-0.5, -0.4, 0.0], [0.5, 0.4, 0.6], size=(200, 3)):
        a = int(rng.integers(0, 7))
        points = np.array([cams[a].project(x)[0], cams[a + 1].project(x)[0] + [shift_px, 0.0]])
        tracks.append((np.array([a, a + 1]), points))
    return tracks


def _centres_error(result, cams) -> float:
    est = np.array([-R.T @ t for R, t in zip(result.rotations, result.translations)])
    true = np.array([-c.R.T @ c.t for c in cams])
    E, T = est - est.mean(0), true - true.mean(0)
    U, S, Vt = np.linalg.svd(T.T @ E)
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    Q = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / (E ** 2).sum()
    return float(np.abs(s * E @ Q.T - T).max() / np.abs(T).max())


class TestFinalAdjustment:
    def test_two_view_tracks_do_not_move_the_cameras(self, scene):
        # The final adjustments use the tracks of 3 views or more (final_min_views): the shifted
        # two-view tracks then leave the exact cameras exact; adjusted with them too
        # (final_min_views=2) the cameras move to fit them.
        tracks = _tracks_with_two_view_shifts(scene, 2.0)
        Ks = [c.K for c in scene.cameras]
        result = calibrated_reconstruction(tracks, Ks)
        assert result.stats["registered"] == 8
        _, errors = align_rotations(result.rotations, [c.R for c in scene.cameras])
        assert errors.max() < 1e-5
        assert _centres_error(result, scene.cameras) < 1e-7
        # the gauge: the initial pair's first view stays at R = I, t = 0 after the Schur adjustment
        first = result.stats["initial_pair"][0]
        assert np.abs(result.rotations[first] - np.eye(3)).max() < 1e-12
        assert np.abs(result.translations[first]).max() < 1e-12
        # the two-view tracks still get points (triangulated in the adjusted cameras)
        assert np.isfinite(result.points[300:, 0]).sum() >= 190
        moved = calibrated_reconstruction(tracks, Ks, CalibratedOptions(final_min_views=2))
        _, errors = align_rotations(moved.rotations, [c.R for c in scene.cameras])
        assert errors.max() > 1e-3

    def test_lsmr_solver_also_keeps_to_long_tracks(self, scene):
        tracks = _tracks_with_two_view_shifts(scene, 2.0)
        result = calibrated_reconstruction(tracks, [c.K for c in scene.cameras],
                                           CalibratedOptions(final_solver="lsmr", final_ba_max_nfev=1000))
        _, errors = align_rotations(result.rotations, [c.R for c in scene.cameras])
        assert errors.max() < 1e-4

    def test_restart_clears_the_marks(self, scene):
        # Exact tracks, exact cameras, a third of the observations marked outliers and the points
        # cleared: _restart marks every observation an inlier again and triangulates every track.
        rng = np.random.default_rng(8)
        cams = scene.cameras
        tracks = []
        X = rng.uniform([-0.5, -0.4, 0.0], [0.5, 0.4, 0.6], size=(50, 3))
        for x in X:
            views = np.array([0, 2, 4, 6])
            tracks.append((views, np.array([cams[v].project(x)[0] for v in views])))
        state = calibrated._State(tracks, [c.K for c in cams])
        for v in range(8):
            state.R[v], state.t[v] = cams[v].R, cams[v].t
        state.inlier[rng.random(len(state.inlier)) < 0.33] = False
        state.outliers_removed = 17
        state.points[:] = np.nan
        calibrated._restart(state, CalibratedOptions(), {"triangulation": 0.0})
        assert state.inlier.all() and state.outliers_removed == 0
        assert np.abs(state.points - X).max() < 1e-9


def load_ring():
    ring = shared_data("middlebury_dinoSparseRing")
    rows = [line.split() for line in (ring / "dinoSR_par.txt").read_text().splitlines()[1:] if line.strip()]
    values = [np.array(r[1:], dtype=float) for r in rows]
    images = [cv2.imread(str(ring / r[0]), cv2.IMREAD_GRAYSCALE) for r in rows]
    return images, [v[:9].reshape(3, 3) for v in values], [v[9:18].reshape(3, 3) for v in values]


@pytest.mark.slow
def test_dino_sparse_ring():
    images, Ks, Rs = load_ring()
    tracks = tracks_from_images(images, RING_FEATURES)
    result = calibrated_reconstruction(tracks.tracks, Ks, RING_CALIBRATED)
    registered = [v for v in range(14) if result.rotations[v] is not None]
    _, errors = align_rotations([result.rotations[v] for v in registered], [Rs[v] for v in registered])
    print(len(registered), np.round(errors, 3))
    # Measured: all 14 registered (0007-0013 by PnP, the rest merged), rotation errors median
    # 0.46, max 0.61 degrees against the ground truth (the target: 12 of 14 within 1).
    # With final_min_views=2 the median is 1.72 and none is within 1 degree. The result is fragile
    # against the options, not the code: the ring's common tilt against the turntable axis is
    # barely determined by these tracks, and the start and the inlier marks decide where it ends.
    # Measured: guided_ratio 0.75, all 14 registered but 2.8 degrees off; 0.85, the merge fails
    # (7 registered); max_reprojection_px 3, 11 within 1 degree; 2, none. Adjusted from the true
    # cameras every one of those ends within 0.74 degrees.
    assert len(registered) == 14
    assert int(np.sum(errors < 1.0)) >= 12
    assert errors.max() < 0.8

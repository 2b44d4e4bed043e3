"""Orienting projective reconstructions (solvers/orientation.py): signs, and the plane at infinity
moved off the scene, so that "in front of every camera" holds for the reconstruction's points."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.orientation import camera_centre, orient

from tests.support import noisy_track, project, random_cameras


def scene(seed: int, cameras: int = 5, points: int = 40):
    rng = np.random.default_rng(seed)
    P = random_cameras(rng, cameras)
    X = np.hstack([rng.normal(size=(points, 3)), np.ones((points, 1))])
    return rng, P, X


def pixels(P: np.ndarray, X: np.ndarray) -> np.ndarray:
    proj = np.einsum("ijk,nk->inj", P, X)
    return proj[..., :2] / proj[..., 2:]


def projective(rng, P, X):
    """The same scene in a random projective frame, with random signs on cameras and points."""
    H = rng.normal(size=(4, 4))
    cameras = np.einsum("ijk,kl->ijl", P, np.linalg.inv(H)) * rng.choice([-1, 1], size=(len(P), 1, 1))
    points = (X @ H.T) * rng.choice([-1, 1], size=(len(X), 1))
    return cameras, points


@pytest.mark.parametrize("seed", range(20))
def test_a_projective_reconstruction_is_oriented_with_the_same_pixels(seed):
    rng, P, X = scene(seed)
    cameras, points = projective(rng, P, X)
    found = orient(cameras, points)
    assert np.all(found.depths() > 0) and found.quasi_affine and found.centres_one_side
    assert not found.negative_depths and not found.undetermined
    assert np.allclose(found.points[:, 3], 1.0)
    assert np.abs(pixels(found.cameras, found.points) - pixels(P, X)).max() < 1e-6
    assert np.allclose(np.linalg.norm(found.cameras, axis=(1, 2)), 1.0)
    # What was applied is what is reported.
    signed = points * found.point_signs[:, None]
    again = signed @ found.transform.T
    assert np.allclose(again / again[:, 3:], found.points)


def test_a_metric_reconstruction_keeps_its_frame_and_only_flipped_signs_change():
    _, P, X = scene(1)
    flips = np.array([1, -1, 1, -1, 1])
    found = orient(P * flips[:, None, None], X[:, :3])
    assert found.camera_signs.tolist() == flips.tolist() and np.all(found.point_signs == 1)
    assert not found.frame_changed and np.allclose(found.transform, np.eye(4))
    assert np.allclose(found.points[:, :3], X[:, :3])
    assert np.allclose(found.cameras, P / np.linalg.norm(P, axis=(1, 2), keepdims=True))


def test_visibility_limits_the_pairs_that_count():
    rng, P, X = scene(2, cameras=4, points=30)
    cameras, points = projective(rng, P, X)
    views = [sorted(rng.choice(4, size=int(rng.integers(2, 5)), replace=False).tolist()) for _ in range(30)]
    found = orient(cameras, points, views)
    depths = found.depths()
    assert all(depths[i, j] > 0 for j, cams in enumerate(views) for i in cams)
    assert found.quasi_affine and not found.negative_depths


def test_pairs_no_signs_can_fix_are_reported():
    # One camera sees a point behind it while it sees the others in front: no choice of signs
    # puts every pair in front; the majority wins and the odd pair is named.
    _, P, X = scene(3, cameras=3, points=10)
    X[4, :3] = camera_centre(P[0])[:3] / camera_centre(P[0])[3] - 3 * P[0][2, :3] / np.linalg.norm(P[0][2, :3])
    found = orient(P, X)
    assert found.negative_depths == [(0, 4)]
    assert found.camera_signs.tolist() == [1, 1, 1]


def test_an_oriented_camera_turns_infeasible_into_certified():
    rng = np.random.default_rng(4)
    P = random_cameras(rng, 3)
    X, observed = noisy_track(rng, P, noise_px=0.5)
    flipped = P * np.array([1, -1, 1])[:, None, None]
    track = {"views": [0, 1, 2], "points": observed.tolist()}
    before = solve_job({"kind": "triangulation", "data": {"cameras": flipped.tolist(), "tracks": [track]},
                        "options": {"max_nodes": 50}})["tracks"][0]
    # The true point is behind the flipped camera: out of scope, so never the certified answer.
    assert not (before["certified"] and np.allclose(before["point"], X[:3], atol=0.05))
    others = np.hstack([rng.normal(size=(8, 3)), np.ones((8, 1))])
    found = orient(flipped, others)
    assert np.allclose(project(found.cameras, X), project(P, X))
    after = solve_job({"kind": "triangulation", "data": {"cameras": found.cameras.tolist(), "tracks": [track]}})
    assert after["tracks"][0]["certified"] and np.allclose(after["tracks"][0]["point"], X[:3], atol=0.05)


@pytest.mark.parametrize("cameras, points, message", [
    (np.zeros((0, 3, 4)), np.ones((1, 3)), "cameras"),
    (np.ones((2, 3, 3)), np.ones((1, 3)), "cameras"),
    (np.ones((2, 3, 4)), np.ones((1, 2)), "points"),
    (np.ones((2, 3, 4)), np.ones((0, 3)), "at least one point"),
])
def test_bad_shapes_are_refused(cameras, points, message):
    with pytest.raises(ValueError, match=message):
        orient(cameras, points)

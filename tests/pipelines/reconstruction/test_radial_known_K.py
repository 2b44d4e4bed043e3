"""K known with a lens's radial distortion K does not model (issue 35: openMVG's K for Sceaux
Castle, whose photos have barrel distortion): the pipeline tests one radial term k1 about K's
principal point, K held as given (_fixed_radial_test), undistorts the observations with the term
the data support and certifies the cameras on them; without it no camera fits its points within
its tolerance. Without distortion no term is kept and nothing changes."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.pipelines.reconstruction import pipeline
from geocert.pipelines.reconstruction.options import ReconstructionOptions
from geocert.solvers.reconstruction import synthetic
from geocert.formulations.reconstruction.camera_claim import RADIAL_CHI2

from testing.reconstruction import aligned_rotation_errors

K1 = -0.25  # barrel distortion: 18 px at the image's corner, f = 800 px


def distorted_scene(k1: float, seed: int = 6):
    scene = synthetic.scene(views=10, points=200, seed=seed, noise_px=0.3, spread_degrees=50.0)
    K = scene.K

    def distort(pixels):
        n = (pixels - K[:2, 2]) / K[0, 0]
        return K[:2, 2] + K[0, 0] * n * (1 + k1 * np.sum(n * n, axis=1))[:, None]

    return scene, [(views, distort(np.asarray(pixels, dtype=float))) for views, pixels in scene.tracks]


def known(scene, **options) -> ReconstructionOptions:
    return ReconstructionOptions(intrinsics={"K": scene.K.tolist()}, camera_rel_gap=0.05, **options)


@pytest.fixture(scope="module")
def with_term():
    scene, tracks = distorted_scene(K1)
    return scene, pipeline.reconstruct(tracks, [scene.image_size] * 10, known(scene))


@pytest.fixture(scope="module")
def without_term():
    scene, tracks = distorted_scene(K1)
    return scene, pipeline.reconstruct(tracks, [scene.image_size] * 10, known(scene, radial_distortion="off"))


def test_without_the_term_no_camera_is_certified(without_term):
    """What the K-known path did before it tested a radial term: every camera beyond its tolerance."""
    _, out = without_term
    assert out.summary["views_registered"] == 10
    assert out.summary["cameras_certified"] == 0
    assert "radial_distortion" not in out.stages[2] and out.distortion is None


def test_the_term_is_estimated_with_K_held_and_every_camera_certified(with_term):
    scene, out = with_term
    stage = out.stages[2]
    test = stage["radial_distortion"]
    assert stage["model"] == "fixed" and test["estimated"] is True and test["chi2"] > RADIAL_CHI2
    assert test["k1"] == pytest.approx(K1, abs=0.01)
    assert out.summary["views_registered"] == 10
    assert out.summary["cameras_certified"] == 10
    for camera in out.cameras:  # K as given; each camera states the term and its centre, K's principal point
        assert np.array_equal(camera.K, scene.K)
        assert camera.k1 == test["k1"] and camera.distortion_centre == scene.K[:2, 2].tolist()
    distortion = out.summary["distortion"]
    assert distortion["k1"] == test["k1"] and distortion["focal_px"] == scene.K[0, 0]
    assert "K's principal point" in distortion["statement"]
    assert "certificates_conditional_on_k1" in [w["code"] for w in out.summary["warnings"]]
    # the points return the undistorted observations their certificates are about
    for point in out.points[:50]:
        X = np.array([*point.result.point, 1.0])
        for v, u, w in point.observations:
            image = out.cameras[int(v)].P @ X
            assert np.hypot(image[0] / image[2] - u, image[1] / image[2] - w) < 2.0
    assert aligned_rotation_errors([c.R for c in out.cameras], list(scene.rotations)).max() < 0.1


def test_no_term_is_kept_without_distortion():
    scene, tracks = distorted_scene(0.0)
    out = pipeline.reconstruct(tracks, [scene.image_size] * 10, known(scene, resect_cameras=False))
    test = out.stages[2]["radial_distortion"]
    assert test["estimated"] is False and test["chi2"] <= RADIAL_CHI2
    assert out.distortion is None and "distortion" not in out.summary
    assert all(camera.k1 is None for camera in out.cameras)

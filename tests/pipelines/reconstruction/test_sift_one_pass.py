"""features.sift_features: one SIFT pass (detectAndCompute) where it gives what detect, then
compute on the keypoints select_keypoints keeps, give (the CPU a scale space costs, saved); the
two passes where it would not (compute's scale space starts at the kept keypoints' lowest octave)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from geocert.pipelines.reconstruction import features
from geocert.solvers.reconstruction.render import box_scene


@pytest.fixture(scope="module")
def images():
    scene = box_scene(n_views=4, arc_deg=90.0, seed=0)
    rng = np.random.default_rng(7)
    out = []
    for image in scene.images():
        gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        out.append(np.ascontiguousarray(gray, dtype=np.uint8))
        noisy = gray.astype(float) + rng.normal(0, 25, gray.shape)  # fine-scale clutter: many keypoints
        out.append(np.clip(noisy, 0, 255).astype(np.uint8))
    return out


def _two_passes(sift, image, max_features):
    return sift.compute(image, features.select_keypoints(sift.detect(image, None), max_features))


@pytest.mark.parametrize("max_features", [0, 4000, 300, 15])
def test_one_pass_gives_the_two_passes_keypoints_and_descriptors(images, max_features):
    """Every keypoint (position, scale, octave) and descriptor the same, bit for bit: all kept
    (0, 4000), the largest-scale few hundred, and a budget so small that no kept keypoint is on
    the doubled image's octave (15: the case needing the second pass)."""
    sift = cv2.SIFT_create(nfeatures=0, contrastThreshold=0.04, edgeThreshold=10)
    lowest = []
    for image in images:
        expected_kps, expected = _two_passes(sift, image, max_features)
        kps, desc = features.sift_features(sift, image, max_features)
        assert len(kps) == len(expected_kps) > 0
        assert [(k.pt, k.size, k.octave) for k in kps] == [(k.pt, k.size, k.octave) for k in expected_kps]
        assert np.array_equal(desc, expected)
        lowest.append(min(features._octave(k) for k in kps))
    if max_features == 15:
        assert max(lowest) >= 0  # the case is there: kept keypoints none on octave -1
    if max_features in (0, 4000):
        assert min(lowest) == -1  # and the one-pass case

"""features.opencv_threads_off: OpenCV's own threads are off during the features stage when the
stage's threads fill the processors (issue 35's CPU), the tracks the same as with them on, and the
setting put back when the stage ends, however it ends."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from geocert.pipelines.reconstruction import features
from geocert.pipelines.reconstruction.features import FeatureOptions, tracks_from_images
from geocert.solvers.reconstruction.render import box_scene
from tests.support import shared_data


@pytest.fixture(scope="module")
def images():
    return box_scene(n_views=4, arc_deg=90.0, seed=0).images()


@pytest.fixture
def opencv_at_two():
    """OpenCV's own threads at 2 (whatever this machine's default) for the test, then as before."""
    before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    yield
    cv2.setNumThreads(before)


def _seen_during(images, monkeypatch, processors: int, callback_extra=None):
    """OpenCV's thread count seen from the stage's progress callbacks, with ``processors``."""
    monkeypatch.setattr(features, "_processors", lambda: processors, raising=False)
    seen = set()

    def callback(progress):
        seen.add(cv2.getNumThreads())
        return callback_extra(progress) if callback_extra else None

    result = tracks_from_images(images, FeatureOptions(), callback)
    return seen, result


def test_off_while_the_stage_threads_fill_the_processors_then_put_back(images, monkeypatch, opencv_at_two):
    seen, result = _seen_during(images, monkeypatch, processors=features.FEATURE_THREADS)
    assert result.status == "ok" and result.tracks
    assert seen == {1}
    assert cv2.getNumThreads() == 2


def test_left_alone_when_processors_are_to_spare(images, monkeypatch, opencv_at_two):
    seen, _ = _seen_during(images, monkeypatch, processors=features.FEATURE_THREADS + 6)
    assert seen == {2}
    assert cv2.getNumThreads() == 2


def test_put_back_after_a_cancel_and_an_error(images, monkeypatch, opencv_at_two):
    seen, result = _seen_during(images, monkeypatch, features.FEATURE_THREADS, lambda p: p["stage"] == "matches")
    assert result.status == "cancelled" and seen == {1}
    assert cv2.getNumThreads() == 2

    def fails(progress):
        raise RuntimeError("the caller's callback failed")

    with pytest.raises(RuntimeError):
        _seen_during(images, monkeypatch, features.FEATURE_THREADS, fails)
    assert cv2.getNumThreads() == 2


def test_overlapping_stages_put_back_the_setting_when_the_last_ends(monkeypatch, opencv_at_two):
    monkeypatch.setattr(features, "_processors", lambda: features.FEATURE_THREADS)
    with features.opencv_threads_off():
        with features.opencv_threads_off():
            assert cv2.getNumThreads() == 1
        assert cv2.getNumThreads() == 1
    assert cv2.getNumThreads() == 2


def _same_tracks(a, b):
    assert len(a.tracks) == len(b.tracks) > 0
    for (views, points), (views2, points2) in zip(a.tracks, b.tracks):
        assert np.array_equal(views, views2) and np.array_equal(points, points2)
    assert a.stats["verified_pairs"] == b.stats["verified_pairs"]
    assert a.stats["features_per_image"] == b.stats["features_per_image"]


def _tracks_with_opencv_threads(images, monkeypatch, threads: int):
    """The stage's tracks with OpenCV's own threads at ``threads`` (left alone: processors to spare)."""
    monkeypatch.setattr(features, "_processors", lambda: features.FEATURE_THREADS + 6, raising=False)
    before = cv2.getNumThreads()
    cv2.setNumThreads(threads)
    try:
        return tracks_from_images(images, FeatureOptions())
    finally:
        cv2.setNumThreads(before)


def test_the_tracks_do_not_depend_on_opencvs_threads(images, monkeypatch):
    """SIFT sorts its keypoints before describing them, so its threads change nothing: the same
    tracks, bit for bit, with OpenCV's threads at 1 and at 4, on the synthetic box."""
    _same_tracks(_tracks_with_opencv_threads(images, monkeypatch, 1),
                 _tracks_with_opencv_threads(images, monkeypatch, 4))


def test_the_tracks_do_not_depend_on_opencvs_threads_on_real_photos(monkeypatch):
    """As above on five of Middlebury's dinoSparseRing photos (shared data)."""
    folder = shared_data("middlebury_dinoSparseRing")
    photos = [cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) for path in sorted(folder.glob("dinoSR*.png"))[:5]]
    _same_tracks(_tracks_with_opencv_threads(photos, monkeypatch, 1),
                 _tracks_with_opencv_threads(photos, monkeypatch, 4))

"""features.ransac_trials: a pair's RANSAC runs TRIALS_MULTIPLIER times the trials that find a
sample free of outliers at the stated confidence when only ``min_inliers`` of its matches are
inliers (RANSAC's stopping rule taken at the least inlier ratio a verified pair can have), at
most ``ransac_max_iters``, so the pairs of a few dozen chance matches stop running to the cap
(issue 35's CPU); a pair that verifies at the cap still does, and on real photos the verified
pairs and their inliers are the same as at the full cap."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from geocert.pipelines.reconstruction import features
from geocert.pipelines.reconstruction.options import FeatureOptions
from testing import photo_sets


def _found(trials: int, ratio: float) -> float:
    """The chance that ``trials`` samples of 7 include one with no outlier at inlier ratio ``ratio``."""
    return 1.0 - (1.0 - ratio ** features.SAMPLE_SIZE) ** trials


@pytest.mark.parametrize("min_inliers,confidence,cap", [(15, 0.999, 5000), (10, 0.999, 5000), (15, 0.99, 20000),
                                                        (30, 0.9999, 2000)])
def test_the_trials_are_the_multiplied_rule_at_the_least_inlier_ratio(min_inliers, confidence, cap):
    """TRIALS_MULTIPLIER times the fewest trials that find a sample free of outliers at the
    confidence when min_inliers of the n matches are inliers (RANSAC's stopping rule), rounded up,
    at least MIN_TRIALS, at most the cap."""
    options = FeatureOptions(min_inliers=min_inliers, ransac_confidence=confidence, ransac_max_iters=cap)
    m = features.TRIALS_MULTIPLIER
    capped = 0
    for n in range(min_inliers, 400):
        trials = features.ransac_trials(n, options)
        assert features.MIN_TRIALS <= trials <= cap
        w = min_inliers / n
        if trials < cap:
            capped += 1
            assert _found(trials / m, w) >= confidence  # enough for a pair with min_inliers inliers
            assert trials == features.MIN_TRIALS or _found((trials - 1) / m, w) < confidence  # and no more
        else:
            assert _found((cap - 1) / m, w) < confidence  # the cap binds: the rule asks as many or more
    assert capped > 0  # the rule binds somewhere in the range
    assert features.ransac_trials(400, options) == cap  # and not on pairs of many matches


def test_no_least_ratio_and_a_low_cap_keep_the_cap():
    """min_inliers 0 sets no least ratio (every pair its cap, no division by zero); a cap below
    MIN_TRIALS is still the most a pair gets."""
    assert features.ransac_trials(50, FeatureOptions(min_inliers=0)) == FeatureOptions().ransac_max_iters
    assert features.ransac_trials(10**9, FeatureOptions()) == FeatureOptions().ransac_max_iters
    assert features.ransac_trials(20, FeatureOptions(ransac_max_iters=50)) == 50
    assert features.ransac_trials(15, FeatureOptions(ransac_max_iters=50)) == 50


def test_fit_fundamental_asks_opencv_for_the_bounded_trials(monkeypatch):
    asked = []
    real = cv2.findFundamentalMat

    def spy(a, b, method, threshold, confidence, iterations):
        asked.append((len(a), iterations))
        return real(a, b, method, threshold, confidence, iterations)

    monkeypatch.setattr(features.cv2, "findFundamentalMat", spy)
    rng = np.random.default_rng(0)
    options = FeatureOptions()
    for n in (16, 25, 30, 60):
        features.fit_fundamental(rng.uniform(0, 640, (n, 2)), rng.uniform(0, 640, (n, 2)), options)
    assert [n for n, _ in asked] == [16, 25, 30, 60]
    assert [t for _, t in asked] == [features.ransac_trials(n, options) for n in (16, 25, 30, 60)]
    assert asked[0][1] == features.MIN_TRIALS and asked[-1][1] == options.ransac_max_iters
    assert all(t < options.ransac_max_iters for _, t in asked[:3])


def _two_views(rng, inliers: int, outliers: int, noise_px: float):
    """Matches between two views of a random scene: ``inliers`` true ones (pixel noise added) and
    ``outliers`` pixel pairs drawn at random, shuffled."""
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    X = np.c_[rng.uniform(-1, 1, (inliers, 2)), rng.uniform(4, 6, inliers)]
    angle = np.deg2rad(10.0)
    R = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    t = np.array([-0.8, 0.05, 0.1])

    def project(P):
        x = P @ K.T
        return x[:, :2] / x[:, 2:]

    a = project(X) + rng.normal(0, noise_px, (inliers, 2))
    b = project(X @ R.T + t) + rng.normal(0, noise_px, (inliers, 2))
    a = np.r_[a, rng.uniform(0, 640, (outliers, 2))]
    b = np.r_[b, rng.uniform(0, 480, (outliers, 2))]
    order = rng.permutation(len(a))
    return a[order], b[order], order < inliers


@pytest.mark.parametrize("inliers,outliers", [(15, 15), (15, 10), (16, 14), (15, 3)])
def test_a_pair_of_few_matches_verifies_as_at_the_full_cap(inliers, outliers):
    """Pairs the bound caps (half their matches or fewer true, at the verified pair's minimum):
    in each of 12 random scenes, verified with the bounded trials whenever at ``ransac_max_iters``
    (deterministic: MAGSAC++ seeds its own generator per call)."""
    options = FeatureOptions()
    assert features.ransac_trials(inliers + outliers, options) < options.ransac_max_iters
    verified = []
    for seed in range(12):
        a, b, _ = _two_views(np.random.default_rng(seed), inliers, outliers, 0.3)
        _, bounded = features.fit_fundamental(a, b, options)
        _, mask = cv2.findFundamentalMat(a, b, cv2.USAC_MAGSAC, options.ransac_threshold_px,
                                         options.ransac_confidence, options.ransac_max_iters)
        at_cap = mask is not None and mask.sum() >= options.min_inliers
        assert bounded.sum() >= options.min_inliers or not at_cap, (seed, int(bounded.sum()), int(mask.sum()))
        verified.append(at_cap)
    assert sum(verified) >= 9  # the scenes hold pairs that verify


@pytest.mark.slow
def test_templeSparseRing_verifies_the_same_pairs_and_inliers_as_at_the_full_cap(monkeypatch):
    """Every pair of the 16 photos matched with the bounded trials and with ``ransac_max_iters``
    on every pair: the same verified pairs, each with the same matches, bit for bit."""
    try:
        temple = photo_sets.load("templeSparseRing")
    except photo_sets.MissingSet as missing:
        pytest.skip(str(missing))
    options = FeatureOptions()
    images = [cv2.imread(str(temple.path(n)), cv2.IMREAD_GRAYSCALE) for n in temple.order("file")]
    found = [features.image_features(options, image) for image in images]
    pairs = [(i, j) for i in range(len(images)) for j in range(i + 1, len(images))]

    def verified():
        out = {}
        for i, j in pairs:
            kept = features.match_pair(found[i][0], found[i][1], found[j][0], found[j][1], options)
            if kept is not None:
                out[(i, j)] = kept[0]
        return out

    bounded = verified()
    trials = features.ransac_trials
    monkeypatch.setattr(features, "ransac_trials", lambda n, o: o.ransac_max_iters)
    full = verified()
    assert len(full) == 35  # the set's verified pairs (bench/results/reconstruction.md)
    assert bounded.keys() == full.keys()
    assert all(np.array_equal(bounded[p], full[p]) for p in full)
    # the bound did bind here: pairs of few matches got fewer trials
    counts = [len(features._match(found[i][1], found[j][1], options)) for i, j in pairs]
    assert sum(trials(n, options) < options.ransac_max_iters for n in counts) >= 20

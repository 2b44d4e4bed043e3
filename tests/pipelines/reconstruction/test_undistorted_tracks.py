"""pipeline._undistorted_tracks: every observation undistorted at once gives, bit for bit, what
bundle.undistort gives track by track (each about its views' principal points)."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.pipelines.reconstruction.pipeline import _undistorted_tracks
from geocert.solvers.reconstruction import bundle


@pytest.mark.parametrize("k1", [-0.3, 0.04, 0.25])
def test_all_at_once_is_track_by_track(k1):
    rng = np.random.default_rng(3)
    centres = rng.uniform(200, 400, (9, 2))
    tracks = [(sorted(rng.choice(9, size=k, replace=False).tolist()), rng.uniform(0, 640, (k, 2)).tolist())
              for k in rng.integers(2, 8, 300)]
    found = _undistorted_tracks(tracks, centres, 650.0, k1)
    assert len(found) == len(tracks)
    for (views, pixels), (got_views, got) in zip(tracks, found):
        assert got_views is views
        expected = bundle.undistort(np.asarray(pixels, dtype=float), centres[np.asarray(views)], 650.0, k1)
        assert np.array_equal(got, expected)
    assert not np.allclose(found[0][1], tracks[0][1])  # the pixels did move
    assert _undistorted_tracks([], centres, 650.0, k1) == []

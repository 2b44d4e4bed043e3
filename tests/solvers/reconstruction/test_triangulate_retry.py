"""calibrated._triangulate_new tries again (calibrated._triangulate_track) only the tracks that can
pass: a track its batch pass finds with a point not finite, or rays clearly narrower than
min_triangulation_angle_deg, would fail _triangulate_track's first pass with nothing changed.
Synthetic dense ring, two neighbouring views about a degree apart (many narrow tracks, some at
the threshold)."""

from __future__ import annotations

import copy

import numpy as np

from geocert.solvers.reconstruction import calibrated, synthetic
from geocert.solvers.reconstruction.calibrated import CalibratedOptions


def test_the_tracks_not_tried_again_would_fail_unchanged(monkeypatch):
    ring = synthetic.ring(views=360, points=400, noise_px=0.3, visible_degrees=80.0, seed=5)
    state = calibrated._State(ring.tracks, [ring.K] * len(ring.rotations))
    for v in (0, 1):
        state.R[v], state.t[v] = ring.rotations[v], ring.translations[v]
    options = CalibratedOptions()
    before = copy.deepcopy(state)
    tried = []
    single = calibrated._triangulate_track
    monkeypatch.setattr(calibrated, "_triangulate_track",
                        lambda s, track, o: tried.append(track) or single(s, track, o))
    calibrated._triangulate_new(state, options)
    monkeypatch.setattr(calibrated, "_triangulate_track", single)
    seen = np.bincount(before.obs_track[before.registered[before.obs_view]], minlength=len(before.points))
    candidates = np.flatnonzero(seen >= 2)
    not_tried = [int(t) for t in candidates if t not in tried and np.isnan(state.points[t, 0])]
    assert len(not_tried) >= 50  # the narrow tracks, left out
    assert np.isfinite(state.points[:, 0]).sum() >= 20  # and some wide enough ones made
    for track in not_tried:
        alone = copy.deepcopy(before)
        assert not single(alone, track, options)
        assert np.array_equal(alone.inlier, before.inlier) and np.isnan(alone.points[track]).all()

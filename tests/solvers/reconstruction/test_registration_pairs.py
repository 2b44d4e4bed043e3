"""The registration's initial-pair search (calibrated._initial_pair) counts the tracks each pair of
views shares without listing every pair's observations: its memory does not grow with the sum over
tracks of C(track length, 2), and the rows it builds for a candidate pair are that pair's."""

from __future__ import annotations

import tracemalloc

import numpy as np

from geocert.solvers.reconstruction import calibrated, synthetic

K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])


def test_a_pairs_rows_are_the_observations_of_the_tracks_both_views_see():
    rng = np.random.default_rng(0)
    tracks = []
    for _ in range(500):
        length = int(rng.integers(2, 9))
        tracks.append((rng.choice(12, size=length, replace=False), rng.uniform(0, 600, (length, 2))))
    state = calibrated._State(tracks, [K] * 12)
    shared = calibrated._SharedTracks(state)
    for i in range(12):
        for j in range(i + 1, 12):
            both = [t for t, (views, _) in enumerate(tracks) if i in views and j in views]
            assert shared.counts.get((i, j), 0) == len(both)
            rows = shared.rows(i, j)
            assert sorted(state.obs_track[rows[:, 0]].tolist()) == both
            assert np.all(state.obs_track[rows[:, 0]] == state.obs_track[rows[:, 1]])
            assert np.all(state.obs_view[rows[:, 0]] == i) and np.all(state.obs_view[rows[:, 1]] == j)


def test_the_initial_pair_search_holds_less_than_one_number_per_pair_of_observations():
    views = 60
    scene = synthetic.scene(views=views, points=3000, seed=3, noise_px=0.3)
    state = calibrated._State([(np.asarray(v), np.asarray(p)) for v, p in scene.tracks], [K] * views)
    pair_rows = sum(len(v) * (len(v) - 1) // 2 for v, _ in scene.tracks)
    assert pair_rows > 4_000_000  # most points seen by most views
    tracemalloc.start()
    try:
        pair = calibrated._initial_pair(state, calibrated.CalibratedOptions(init_candidates=2))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert pair is not None
    assert peak < 8 * pair_rows, f"{peak / 2**20:.0f} MiB for {pair_rows} pairs of observations"

"""Stage 4's cameras (structure.resect_cameras): resected a few at a time on threads, with the
same figures as one at a time, every view reported once, progress counted and a cancel honoured."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.solvers.fractional.options import MapOptions
from geocert.solvers.reconstruction import structure, synthetic


@pytest.fixture(scope="module")
def cameras_and_sources():
    scene = synthetic.scene(views=5, points=40, noise_px=0.5, seed=3)
    cameras, sources = {}, {}
    for view in range(5):
        R, t = scene.rotations[view], scene.translations[view]
        P = structure.camera_matrix(scene.K, R, t)
        proj = np.hstack([scene.points, np.ones((len(scene.points), 1))]) @ P.T
        pixels = proj[:, :2] / proj[:, 2:] + np.random.default_rng(view).normal(scale=0.5, size=(len(proj), 2))
        cameras[view], sources[view] = P, (scene.points, pixels)
    sources[4] = (scene.points[:5], sources[4][1][:5])  # too few points: degenerate
    return cameras, sources


def figures(bounds: dict) -> dict:
    return {v: (b.status, b.cost, b.optimal_cost, b.points, b.result and (b.result.lower_bound, b.result.nodes))
            for v, b in bounds.items()}


class TestResectCameras:
    def test_threads_give_the_figures_of_one_at_a_time(self, cameras_and_sources):
        cameras, sources = cameras_and_sources
        options = MapOptions(rel_gap=1e-3)
        # Every search run (the true cameras are not the optima of noisy pixels, so the default
        # would skip them as beaten by a free camera).
        alone = structure.resect_cameras(cameras, sources, options, threads=1, bound_every_camera=True)
        calls: list = []
        together = structure.resect_cameras(cameras, sources, options, threads=2, bound_every_camera=True,
                                            progress=lambda done, total: calls.append((done, total)))
        assert list(together) == list(alone) == [0, 1, 2, 3, 4]
        assert figures(together) == figures(alone)
        assert all(b.view == v for v, b in together.items())
        assert together[4].status == "degenerate"
        assert sum(b.result is not None and b.result.certified for b in together.values()) == 4
        assert calls == [(done, 5) for done in range(1, 6)]

    def test_cancel_stops_the_cameras_not_started(self, cameras_and_sources):
        cameras, sources = cameras_and_sources
        bounds = structure.resect_cameras(cameras, sources, MapOptions(rel_gap=1e-3), threads=2,
                                          bound_every_camera=True, should_stop=lambda: True)
        statuses = [b.status for b in bounds.values()]
        # The first two were in flight when the cancel was seen: they finish, the rest never start.
        assert statuses.count("cancelled") == 3 and len(statuses) == 5

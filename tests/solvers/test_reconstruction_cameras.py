"""Stage 4's cameras (structure.resect_cameras): resected a few at a time on threads, with the
same figures as one at a time, every view reported once, progress counted and a cancel honoured;
what a certified camera claims (camera_claim): sound cameras with a shared K certified, a wrong
one not, and flagged."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.solvers.fractional.options import MapOptions
from geocert.solvers.reconstruction import camera_claim, structure, synthetic


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


def shared_K_scene(points: int = 120, noise_px: float = 0.5, seed: int = 4):
    """True cameras with one shared K and noisy pixels of true points: every camera is sound."""
    scene = synthetic.scene(views=6, points=points, noise_px=0.0, seed=seed)
    rng = np.random.default_rng(seed)
    cameras, sources = {}, {}
    for view in range(6):
        P = structure.camera_matrix(scene.K, scene.rotations[view], scene.translations[view])
        proj = np.hstack([scene.points, np.ones((len(scene.points), 1))]) @ P.T
        cameras[view] = P
        sources[view] = (scene.points, proj[:, :2] / proj[:, 2:] + rng.normal(scale=noise_px, size=(len(proj), 2)))
    return scene, cameras, sources


def turned(scene, view: int, degrees: float) -> np.ndarray:
    """The view's camera turned by ``degrees`` about its own x axis (a wrong pose)."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec([np.radians(degrees), 0.0, 0.0]).as_matrix() @ scene.rotations[view]
    centre = -scene.rotations[view].T @ scene.translations[view]
    return structure.camera_matrix(scene.K, R, -R @ centre)


class TestCameraClaim:
    """What a certified camera claims (camera_claim): its cost within its tolerance (the allowance
    its 6 degrees of freedom against a 3x4 camera's 11 need, and the search's gap) of the bound
    the certified resection proves for every 3x4 camera."""

    def test_sound_cameras_with_a_shared_K_are_certified(self):
        scene, cameras, sources = shared_K_scene()
        options = MapOptions(rel_gap=1e-2)
        bounds = structure.resect_cameras(cameras, sources, options, dof=6, bound_every_camera=True)
        assert all(b.certified for b in bounds.values())
        for b in bounds.values():
            assert b.dof == 6 and b.tolerance == pytest.approx(camera_claim.tolerance(120, 6, "L2L2", 1e-2))
            assert b.cost <= (1 + b.tolerance) * b.lower_bound + options.abs_gap and b.lower_bound <= b.cost
        # Against the bound alone (the tolerance camera_rel_gap), most of these sound cameras fail:
        # the free camera's 5 extra degrees of freedom fit part of the noise.
        assert sum(b.cost - b.lower_bound <= 1e-2 * b.cost for b in bounds.values()) < 3

    def test_a_wrong_camera_is_not_certified_and_is_flagged(self):
        scene, cameras, sources = shared_K_scene()
        cameras[2] = turned(scene, 2, 0.5)  # about 7 px at f = 800
        for every in (False, True):
            bounds = structure.resect_cameras(cameras, sources, MapOptions(rel_gap=1e-2), dof=6,
                                              bound_every_camera=every)
            assert not bounds[2].certified and bounds[2].beyond_tolerance and "tolerance" in bounds[2].reason
            assert all(b.certified and not b.beyond_tolerance for v, b in bounds.items() if v != 2)

    def test_too_few_points_get_no_allowance(self):
        """20 points (an allowance of 20.5 / 29 = 71% for a shared K, above MAX_ALLOWANCE): held
        to the bound as a 3x4 camera is, so noisy sound cameras are not certified, and not
        flagged; exact ones are."""
        for noise, certified in ((0.5, False), (0.0, True)):
            scene, cameras, sources = shared_K_scene(points=20, noise_px=noise)
            bounds = structure.resect_cameras(cameras, sources, MapOptions(rel_gap=1e-2), dof=6)
            for b in bounds.values():
                assert b.tolerance == pytest.approx(1 / 0.99 - 1) and b.certified == certified
                assert not b.beyond_tolerance
                assert certified or "too few for an allowance" in b.reason
        assert camera_claim.allowance(20, 10, "L2L2") == pytest.approx(10.828 / 29)  # one missing: 37%

    def test_only_uncertifiable_cameras_skip_the_certified_resection(self):
        """A camera is not searched only when a free camera found locally beats it by more than its
        tolerance: the certified cameras are those of the full run, and each skipped camera's
        full-run bound is no higher than the free camera's cost and leaves it beyond its tolerance."""
        scene, cameras, sources = shared_K_scene(points=60, seed=3)
        for view, degrees in ((1, 0.3), (4, -0.4)):
            cameras[view] = turned(scene, view, degrees)
        runs = {every: structure.resect_cameras(cameras, sources, MapOptions(rel_gap=1e-2), dof=6,
                                                bound_every_camera=every) for every in (False, True)}
        quick, full = runs[False], runs[True]
        assert {v for v, b in quick.items() if b.certified} == {v for v, b in full.items() if b.certified} \
            == {0, 2, 3, 5}
        skipped = [v for v, b in quick.items() if b.result is None]
        assert skipped == [1, 4]
        for v in skipped:
            b = quick[v]
            assert not b.certified and b.lower_bound is None and "free 3x4 camera" in b.reason
            assert b.cost == pytest.approx(full[v].cost, rel=1e-9)
            free = float(b.reason.split("found locally (")[1].split(")")[0])
            assert full[v].result.lower_bound <= free * (1 + 1e-3)  # the free camera bounds the optimum
            assert full[v].cost > (1 + full[v].tolerance) * full[v].lower_bound


class TestDegreesOfFreedom:
    K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])

    def test_a_shared_K_leaves_the_pose(self):
        assert camera_claim.degrees_of_freedom([self.K, self.K.copy(), self.K.copy()]) == 6

    def test_each_intrinsic_the_cameras_do_not_share_adds_one(self):
        longer = self.K.copy()
        longer[0, 0] = longer[1, 1] = 820.0  # the "varying" model: one focal length per view
        assert camera_claim.degrees_of_freedom([self.K, longer]) == 7
        moved = longer.copy()
        moved[0, 2] += 3.0
        assert camera_claim.degrees_of_freedom([self.K, longer, moved]) == 8

    def test_the_allowance_follows_the_missing_degrees_of_freedom_and_the_points(self):
        assert camera_claim.allowance(200, 6, "L2L2") == pytest.approx(20.515 / 389)
        assert camera_claim.allowance(200, 6, "L1L1") == pytest.approx(20.515 / 778)
        assert camera_claim.allowance(200, 11, "L2L2") == 0.0
        assert camera_claim.allowance(5, 6, "L2L2") is None
        assert camera_claim.tolerance(200, 6, "L2L2", 0.01) == pytest.approx((1 + 20.515 / 389) / 0.99 - 1)

"""Stage 4's cameras (structure.resect_cameras): resected a few at a time on threads, with the
same figures as one at a time, every view reported once, progress counted and a cancel honoured;
what a certified camera claims (camera_claim): sound cameras with a shared K certified, a wrong
one not, and flagged."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.formulations.fractional.options import MapOptions
from geocert.solvers.reconstruction import structure, synthetic
from geocert.formulations.reconstruction import camera_claim


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


def with_principal_point(scene, view: int, shift_px) -> np.ndarray:
    """The camera the view's pixels come from when its principal point is ``shift_px`` from the
    shared K's (a stabilised lens moves it from shot to shot), its pose the true one."""
    K = scene.K.copy()
    K[:2, 2] += shift_px
    return structure.camera_matrix(K, scene.rotations[view], scene.translations[view])


def pose_fitted(K: np.ndarray, R: np.ndarray, t: np.ndarray, X: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The camera with this K whose pose, refined from (R, t), fits the pixels x of X best (what
    an adjustment with a shared K returns)."""
    from scipy.optimize import least_squares
    from scipy.spatial.transform import Rotation

    def camera(p):
        return structure.camera_matrix(K, Rotation.from_rotvec(p[:3]).as_matrix() @ R, t + p[3:])

    def residual(p):
        proj = np.hstack([X, np.ones((len(X), 1))]) @ camera(p).T
        return (proj[:, :2] / proj[:, 2:] - x).ravel()

    return camera(least_squares(residual, np.zeros(6), method="lm").x)


class TestCameraMisfit:
    """Why a camera is not certified (camera_misfit): refitted locally on its points, is its pose off
    its optimum, or does the camera's K misfit the view? Every camera has the shared K; one view's
    pixels come from another camera."""

    def bounds(self, pixels_from: dict, refit: bool, points: int = 300):
        scene, cameras, sources = shared_K_scene(points=points, noise_px=0.3, seed=5)
        rng = np.random.default_rng(7)
        for view, P in pixels_from.items():
            proj = np.hstack([scene.points, np.ones((len(scene.points), 1))]) @ P(scene).T
            sources[view] = (scene.points, proj[:, :2] / proj[:, 2:] + rng.normal(scale=0.3, size=(len(proj), 2)))
            if refit:
                cameras[view] = pose_fitted(scene.K, scene.rotations[view], scene.translations[view], *sources[view])
        return structure.resect_cameras(cameras, sources, MapOptions(rel_gap=1e-2), dof=6)

    def test_a_principal_point_of_its_own_is_named(self):
        # the pose the adjustment would return with the shared K: at its optimum on these pixels
        bounds = self.bounds({3: lambda scene: with_principal_point(scene, 3, [6.0, -4.0])}, refit=True)
        b = bounds[3]
        assert not b.certified and b.misfit is not None and b.misfit["cause"] == "principal_point"
        assert b.misfit["pose"] > b.tolerance and b.misfit["principal_point"] < 0.5 * b.tolerance
        assert "the camera's K misfits this view, its principal point" in b.reason
        assert all(bounds[v].certified and bounds[v].misfit is None for v in bounds if v != 3)

    def test_a_pose_off_its_optimum_is_named(self):
        # the pixels of the view turned: the returned (true) pose is off their optimum
        bounds = self.bounds({2: lambda scene: turned(scene, 2, 0.3)}, refit=False)
        b = bounds[2]
        assert not b.certified and b.misfit["cause"] == "pose" and b.misfit["pose"] < 0.5 * b.tolerance
        assert "its pose was off its optimum" in b.reason

    def test_the_summary_says_which(self):
        from types import SimpleNamespace

        from geocert.pipelines.reconstruction.claims import _misfit_said

        def camera(view, cause):
            return SimpleNamespace(view=view, bound=SimpleNamespace(misfit=None if cause is None else {"cause": cause}))

        said = _misfit_said([camera(1, "principal_point"), camera(4, "principal_point"), camera(6, "unexplained")])
        assert said.startswith("views 1, 4: the pose is at its optimum and a principal point of its own")
        assert "view 6: the pose is at its optimum and no intrinsic" in said
        assert _misfit_said([camera(2, None)]) == "its pose, or the camera's K, may be off"

    def test_no_tolerance_names_no_intrinsic(self):
        from geocert.solvers.reconstruction.camera_misfit import misfit_cause

        refits = {"pose": 0.2, "principal_point": 0.0, "focal_and_principal_point": 0.0}
        # 5 points leave no tolerance for any camera: the cause is not an intrinsic, and no error
        assert misfit_cause(refits, 0.2, 5, 6, "L2L2", 1e-2) == "unexplained"
        assert misfit_cause(refits, 0.2, 200, 6, "L2L2", 1e-2) == "principal_point"

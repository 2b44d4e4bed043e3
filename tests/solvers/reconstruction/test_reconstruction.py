"""Reconstruction from tracks alone (geocert.solvers.reconstruction): exact recovery of a
synthetic scene with known K, outliers removed and counted, the Oxford Model House against
VGG's cameras, and the Oxford Dinosaur's turntable (Oxford Visual Geometry Group's data)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from geocert.solvers.datasets import load_dinosaur
from geocert.pipelines.reconstruction import claims, pipeline
from geocert.solvers.reconstruction import projective, synthetic, upgrade
from geocert.pipelines.reconstruction.options import ReconstructionOptions
from geocert.solvers.reconstruction.tracks import Observations

from tests.support import shared_data
from testing import reconstruction as shared_scenes
from testing.reconstruction import aligned_rotation_errors, vgg_pose, vgg_refit  # noqa: F401


def house_tracks():
    """The Oxford Model House's tracks (the calling test skips without the shared data)."""
    return shared_scenes.house_tracks(shared_data("oxford_house"))


class TestSynthetic:
    def test_exact_tracks_give_the_scene_exactly(self):
        scene = synthetic.scene(views=8, points=60, seed=5)
        out = pipeline.reconstruct(scene.tracks, [scene.image_size] * 8, ReconstructionOptions(resect_cameras=False))
        assert out.summary["views_registered"] == 8 and out.summary["points"] == 60
        assert out.summary["autocalibration_certified"] and out.summary["points_certified_fraction"] == 1.0
        assert out.stages[1]["stages"][1]["certified"]
        assert abs(out.cameras[0].K[0, 0] / 800 - 1) < 1e-8
        errors = aligned_rotation_errors([c.R for c in out.cameras], list(scene.rotations))
        assert errors.max() < 1e-5  # degrees: arccos near 1 resolves about 1e-6
        assert out.summary["rms_reprojection_px"] < 1e-8
        # A general motion: the upgrade is determined, and the result says so.
        assert out.stages[1]["critical_motion"] is None and out.stages[1]["determined"] is True
        assert out.summary["autocalibration_determined"] is True and out.summary["critical_motion"] is None

    def test_a_turntable_is_reported_as_a_critical_motion(self):
        """Constant intrinsics are not determined by a turntable's tracks (Sturm 1997): whatever
        the certified upgrade does, the result must say plainly that the data cannot fix K."""
        scene = synthetic.turntable(views=10, points=40, seed=3, noise_px=0.3)
        searched = pipeline.reconstruct(scene.tracks, [scene.image_size] * 10, ReconstructionOptions(
            resect_cameras=False, autocalibration_time_limit_s=2, autocalibration_on_critical_motion="search"))
        assert [s["name"] for s in searched.stages[1]["stages"]] == ["affine", "metric"]
        assert searched.stages[1]["critical_motion"] == "orbital_motion"
        assert searched.stages[1]["determined"] is False
        # By default the certified search is not run on a critical motion, and the stage says why.
        out = pipeline.reconstruct(scene.tracks, [scene.image_size] * 10, ReconstructionOptions(
            resect_cameras=False, autocalibration_time_limit_s=2))
        assert out.summary["views_registered"] == 10
        stage = out.stages[1]
        assert stage["status"] == "skipped" and stage["stages"] == [] and not stage["certified"]
        assert stage["reason"].startswith("the linear estimate's motion is critical (")
        assert out.stages[2]["started_from"] in ("linear", "incremental")  # no certified upgrade to start from
        assert stage["critical_motion"] == "orbital_motion" and stage["determined"] is False
        assert stage["motion_warnings"][0]["code"] == "orbital_motion"
        assert stage["reason"].startswith("critical motion (orbital_motion)") or \
            "; critical motion (orbital_motion)" in stage["reason"]
        assert "do not determine a constant K" in stage["reason"] and "not from a certificate" in stage["reason"]
        assert out.summary["critical_motion"] == "orbital_motion"
        assert out.summary["autocalibration_determined"] is False

    def test_a_turntable_with_K_given_says_K_was_given(self):
        """With K given, the motion still cannot fix K from the tracks, but K is the user's: the
        result must not say it came from the adjustment's camera model."""
        scene = synthetic.turntable(views=10, points=40, seed=3, noise_px=0.3)
        out = pipeline.reconstruct(scene.tracks, [scene.image_size] * 10, ReconstructionOptions(
            intrinsics={"K": scene.K.tolist()}, resect_cameras=False))
        stage = out.stages[1]
        assert stage["critical_motion"] == "orbital_motion"
        assert "K was given" in stage["reason"] and "not from a certificate" not in stage["reason"]
        warning = next(w for w in out.summary["warnings"] if w["code"] == "critical_motion")
        assert "K was given" in warning["detail"]
        # The motion itself is recovered: the rotations, against the turntable's, after alignment.
        assert aligned_rotation_errors([c.R for c in out.cameras], list(scene.rotations)).max() < 0.5

    def test_outliers_are_removed_and_counted(self):
        scene = synthetic.scene(views=8, points=120, seed=7, noise_px=0.3)
        rng = np.random.default_rng(0)
        corrupted = set()
        for t, (views, pixels) in enumerate(scene.tracks):
            for k in range(len(views)):
                if rng.uniform() < 0.04:
                    pixels[k] += rng.choice([-1, 1], 2) * rng.uniform(20, 40, 2)
                    corrupted.add((t, int(views[k])))
        out = pipeline.reconstruct(scene.tracks, [scene.image_size] * 8, ReconstructionOptions(
            resect_cameras=False, autocalibration_time_limit_s=5, registration="projective"))
        kept = {(p.track, int(o[0])) for p in out.points for o in p.observations}
        assert not kept & corrupted  # every corrupted observation is out
        assert out.stages[0]["outliers_removed"] >= 0.9 * len(corrupted)
        stage = out.stages[0]  # every observation counted once (the House's 27 outliers were not its 52 dropped)
        assert stage["observations"] == sum(len(v) for v, _ in scene.tracks) == stage["observations_kept"] + stage[
            "outliers_removed"] + stage["observations_of_dropped_tracks"] + stage["observations_of_unregistered_views"]
        assert out.summary["observations"] >= 0.93 * sum(len(v) for v, _ in scene.tracks)
        assert abs(out.cameras[0].K[0, 0] / 800 - 1) < 0.01
        assert aligned_rotation_errors([c.R for c in out.cameras], list(scene.rotations)).max() < 0.3
        assert 0.3 < out.summary["rms_reprojection_px"] < 0.45  # sqrt(2) * 0.3 px, less the fitted part


class TestCameraBounds:
    def test_the_cameras_of_a_sound_reconstruction_are_certified(self):
        """Every camera of a good reconstruction (true tracks, 0.5 px noise, one shared K) is
        certified: its cost within its tolerance (camera_claim: its 6 degrees of freedom against a
        3x4 camera's 11, and the search's gap) of the bound. Held to camera_rel_gap alone, as
        before, most were not: the free camera's 5 extra parameters fit part of the noise."""
        scene = synthetic.scene(views=8, points=60, seed=3, noise_px=0.5)
        out = pipeline.reconstruct(scene.tracks, [scene.image_size] * 8, ReconstructionOptions(
            autocalibration_time_limit_s=5))
        bounds = [c.bound for c in out.cameras]
        assert out.summary["cameras_certified_fraction"] == 1.0 and out.stages[4]["degrees_of_freedom"] == 6
        assert "camera_fit_beyond_tolerance" not in [w["code"] for w in out.summary["warnings"]]
        for b in bounds:
            assert b.certified and b.dof == 6 and b.lower_bound <= b.cost <= (1 + b.tolerance) * b.lower_bound
        assert sum(b.cost - b.lower_bound <= 1e-2 * b.cost for b in bounds) < 4

        assert out.summary["doubtful"] is False
        assert "reconstruction_doubtful" not in [w["code"] for w in out.summary["warnings"]]

    def test_a_rig_built_on_a_wrong_K_is_reported_doubtful_first(self):
        """A K 25% too long given as known: each camera still registers and the points
        triangulate, but the rig cannot fit its tracks as a pinhole camera with that K should; the
        summary's first warning says the reconstruction as a whole is doubtful."""
        scene = synthetic.scene(views=8, points=60, seed=3, noise_px=0.5)
        K = scene.K.copy()
        K[0, 0] = K[1, 1] = 1.25 * K[0, 0]
        out = pipeline.reconstruct(scene.tracks, [scene.image_size] * 8, ReconstructionOptions(
            intrinsics={"K": K.tolist()}, bound_every_camera=True))
        assert out.summary["views_registered"] >= 6
        assert out.summary["doubtful"] is True
        assert out.summary["warnings"][0]["code"] == "reconstruction_doubtful"

@pytest.mark.slow
class TestModelHouse:
    def test_from_tracks_alone_against_vgg(self):
        """Every view registered, sub-pixel; VGG's cameras do not share one K (focal 594-666 px,
        principal point to 480 px, skew to -26 px), so one shared K cannot match them within 2%:
        the adjustment started from VGG's own cameras reaches the same reconstruction as ours."""
        cameras, points, tracks = house_tracks()
        # The reference is refitted with the principal point at the centre and no distortion term:
        # ours too, to compare alike (VGG's differing K per view is partly fit by a radial term:
        # with radial_distortion "auto" one is kept and f lands 3.7% above the pinhole refit).
        out = pipeline.reconstruct(tracks, [(768, 576)] * 10, ReconstructionOptions(
            resect_cameras=False, autocalibration_time_limit_s=5, principal_point="centre",
            radial_distortion="off"))
        assert out.summary["views_registered"] == 10 and out.summary["points"] >= 650
        assert out.summary["rms_reprojection_px"] < 0.5 and out.summary["points_certified_fraction"] == 1.0
        f = np.mean([vgg_pose(P)[0][0, 0] for P in cameras])
        reference = vgg_refit(cameras, points, tracks)
        ours = out.cameras[0].K[0, 0]
        assert abs(ours / reference.K[0, 0] - 1) < 0.01
        rotations = aligned_rotation_errors([c.R for c in out.cameras], reference.rotations)
        assert rotations.max() < 0.5, rotations
        vgg_focal_error = abs(ours / f - 1)  # about 14%: the model's, not the pipeline's (README)
        assert vgg_focal_error < 0.2


@pytest.mark.slow
class TestDinosaur:
    def test_every_view_registers_and_the_turntable_steps_by_ten_degrees(self):
        _, loaded = load_dinosaur(shared_data("oxford_dinosaur"))
        tracks = [(np.array(t.views), t.points) for t in loaded]
        options = ReconstructionOptions(autocalibration_time_limit_s=10)
        proj = projective.reconstruct(tracks, 36, projective.ProjectiveOptions())
        assert proj.stats["views_registered"] == 36 and proj.stats["points"] > 4900
        metric = upgrade.autocalibrate(proj.cameras, proj.points, (720, 576), {}, options.autocalibration_options(),
                                       300)
        starts = ([("autocalibration", metric)] if metric.K is not None else []) + [
            ("linear", upgrade.metric_from(proj.cameras, proj.points, *metric.alternative))]
        for _, start in starts:  # the "simple" model: one focal length, the principal point at the centre
            f = np.sqrt(abs(start.K[0, 0] * start.K[1, 1]))
            start.K = np.array([[f, 0, 360.0], [0, f, 288.0], [0, 0, 1]])
        obs = Observations.from_tracks(tracks, 36)
        _, adjusted, kept, _, _ = pipeline.adjust_best(starts, obs, proj.inlier.copy(), 2.0, "simple")
        assert pipeline._rms(adjusted, obs, kept) < 0.5
        R = adjusted.rotations
        steps = Rotation.from_matrix(np.array([R[i + 1] @ R[i].T for i in range(35)])).as_rotvec()
        angles = np.degrees(np.linalg.norm(steps, axis=1))
        axes = steps / np.linalg.norm(steps, axis=1)[:, None]
        axis = axes.mean(axis=0) / np.linalg.norm(axes.mean(axis=0))
        assert abs(angles.mean() - 10.0) < 0.1 and angles.std() < 0.15
        assert np.degrees(np.arccos(np.clip(axes @ axis, -1, 1))).max() < 3.0
        assert upgrade.motion(adjusted)[1] == "orbital_motion"  # the result says K is not determined


class TestSanityLayer:
    """No returned camera or point may be wrong without the result saying so (issue 35)."""

    def _metric(self, scene):
        return upgrade.Metric(scene.K.copy(), list(scene.rotations.copy()), list(scene.translations.copy()),
                              scene.points.copy(), [], False)

    def test_a_flipped_camera_is_dropped_and_counted(self):
        scene = synthetic.scene(views=6, points=40, seed=2)
        metric = self._metric(scene)
        # View 3 turned half round about its own y axis: its points now lie behind it.
        flip = np.diag([-1.0, 1.0, -1.0])
        centre = -metric.rotations[3].T @ metric.translations[3]
        metric.rotations[3] = flip @ metric.rotations[3]
        metric.translations[3] = -metric.rotations[3] @ centre
        obs = Observations.from_tracks(scene.tracks, 6)
        out = pipeline.Reconstruction([pipeline.Camera(v, True) for v in range(6)], [], [])
        keep = pipeline._check_cameras(out, metric, obs, np.ones(len(obs.view), dtype=bool), 2.0)
        dropped = out.checks["cameras_dropped"]
        assert [d["view"] for d in dropped] == [3] and "flipped" in dropped[0]["reason"]
        assert not out.cameras[3].registered and "flipped" in out.cameras[3].reason
        assert metric.rotations[3] is None and not keep[obs.view == 3].any()
        assert keep[obs.view != 3].all()  # the other cameras' observations all fit

    def test_an_outlier_observation_is_removed_before_the_structure(self):
        scene = synthetic.scene(views=6, points=40, seed=2)
        tracks = [(v, p.copy()) for v, p in scene.tracks]
        tracks[5][1][0] += [60.0, -45.0]
        obs = Observations.from_tracks(tracks, 6)
        out = pipeline.Reconstruction([pipeline.Camera(v, True) for v in range(6)], [], [])
        keep = pipeline._check_cameras(out, self._metric(scene), obs, np.ones(len(obs.view), dtype=bool), 2.0)
        bad = (obs.track == 5) & (obs.view == tracks[5][0][0])
        assert not keep[bad].any() and keep[~bad & (obs.track != 5)].all()
        assert out.checks["observations_removed"] == 1 and out.checks["cameras_dropped"] == []

    def test_an_outlier_track_is_caught_before_the_structure_is_certified(self):
        scene = synthetic.scene(views=6, points=40, seed=2, noise_px=0.2)
        views, pixels = scene.tracks[5]
        pixels[0] += [60.0, -45.0]  # one observation far off: it must not reach the certified point
        out = pipeline.reconstruct(scene.tracks, [scene.image_size] * 6, ReconstructionOptions(
            intrinsics={"K": scene.K.tolist()}, resect_cameras=False))
        assert out.summary["views_registered"] == 6
        point = next((p for p in out.points if p.track == 5), None)
        assert point is None or int(views[0]) not in [int(o[0]) for o in point.observations]
        for p in out.points:  # every returned point reprojects within the threshold where it is seen
            X = np.array([*p.result.point, 1.0])
            for v, u, w in p.observations:
                image = out.cameras[int(v)].P @ X
                assert image[2] > 0 and np.hypot(image[0] / image[2] - u, image[1] / image[2] - w) < 2.0 * np.sqrt(6)


class TestAdjustmentStarts:
    """The adjustment stage's starts (pipeline.adjust_best)."""

    @staticmethod
    def _rig(scene):
        return upgrade.Metric(scene.K.copy(), list(scene.rotations.copy()), list(scene.translations.copy()),
                              scene.points.copy(), [], False)

    def test_a_start_that_is_an_earlier_start_in_another_frame_is_not_adjusted_again(self, monkeypatch):
        # The certified upgrade of the registration's cameras is often those cameras again in
        # another frame (their RMS equal to 1e-11): adjusting both is the same work twice.
        scene = synthetic.scene(views=6, points=40, seed=2, noise_px=0.3)
        obs = Observations.from_tracks(scene.tracks, 6)
        rig = self._rig(scene)
        Q, s, c = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix(), 2.5, np.array([1.0, -2.0, 0.5])
        moved = self._rig(scene)  # X' = s Q X + c, so R' = R Q^T and t' = s t - R' c
        moved.points = s * scene.points @ Q.T + c
        moved.rotations = [R @ Q.T for R in scene.rotations]
        moved.translations = [s * t - R @ Q.T @ c for R, t in zip(scene.rotations, scene.translations)]
        other = self._rig(scene)  # another rig: one camera turned by a degree
        other.rotations[3] = Rotation.from_rotvec([0.0, np.radians(1.0), 0.0]).as_matrix() @ other.rotations[3]
        adjusted = []
        real = upgrade.adjust
        monkeypatch.setattr(upgrade, "adjust", lambda start, *args, **kw: adjusted.append(start) or real(
            start, *args, **kw))
        keep = np.ones(len(obs.view), dtype=bool)
        name, _, _, _, trials = pipeline.adjust_best([("autocalibration", rig), ("incremental", moved),
                                                      ("linear", other)], obs, keep, 2.0, "simple")
        assert trials[1]["same_rig_as"] == "autocalibration" and "fit_cost" not in trials[1]
        assert trials[1]["rms_px_before"] == pytest.approx(trials[0]["rms_px_before"], abs=1e-9)
        assert "same_rig_as" not in trials[2] and "fit_cost" in trials[2]
        assert not any(start is moved for start in adjusted)
        assert len(adjusted) == 3 and name == "autocalibration"  # two short adjustments, then the full one


class TestCalibrationClaim:
    def _out(self, certified_K, returned_K, ranges, critical=None, adjusted=True):
        stage = {"name": "autocalibration", "status": "done", "certified": True, "K": certified_K,
                 "intrinsics": ranges, "critical_motion": critical, "determined": critical is None}
        adjustment = {"name": "bundle_adjustment", "status": "done" if adjusted else "skipped"}
        metric = upgrade.Metric(np.array(returned_K, dtype=float), [np.eye(3)], [np.zeros(3)], np.zeros((0, 3)),
                                [], True)
        return pipeline.Reconstruction([], [], [{"name": "projective"}, stage, adjustment], metric=metric)

    RANGES = {"focal": [192.0, 3200.0], "aspect": [0.95, 1.05], "skew": [-6.4, 6.4],
              "principal_point": [[160.0, 480.0], [120.0, 360.0]]}

    def test_a_certified_K_on_its_range_edge_is_a_warning_and_not_determined(self):
        K = [[3200.0, 0.0, 320.0], [0.0, 3200.0, 240.0], [0.0, 0.0, 1.0]]  # the focal range's upper end
        claim = claims.calibration_claim(self._out(K, K, self.RANGES))
        assert claim.certified and claim.on_range_edge == ("focal",) and claim.determined is False
        assert "certified_K_on_range_edge" in [w["code"] for w in claim.warnings]
        inside = [[1000.0, 0.0, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]]
        claim = claims.calibration_claim(self._out(inside, inside, self.RANGES))
        assert claim.on_range_edge == () and claim.determined is True and claim.returned_is_certified

    def test_a_K_moved_by_the_adjustment_returns_both_and_says_which_is_certified(self):
        certified = [[1000.0, 0.0, 320.0], [0.0, 1000.0, 240.0], [0.0, 0.0, 1.0]]
        adjusted = [[1040.0, 0.0, 322.0], [0.0, 1040.0, 240.0], [0.0, 0.0, 1.0]]
        claim = claims.calibration_claim(self._out(certified, adjusted, self.RANGES))
        assert claim.K == adjusted and claim.certified_K == certified and claim.certified
        assert not claim.returned_is_certified and claim.source == "bundle_adjustment"
        assert abs(claim.difference["focal_percent"] - 4.0) < 1e-9 and abs(claim.difference["principal_point_px"] - 2.0) < 1e-9
        assert "returned_K_not_certified" in [w["code"] for w in claim.warnings]

    def test_without_an_adjustment_the_K_moved_by_the_camera_model_says_so(self):
        # bundle_adjustment false, camera_model "simple": the principal point put at the image
        # centre and the pixels made square moved K; no adjustment did.
        certified = [[1000.0, 0.0, 320.7], [0.0, 1001.0, 240.0], [0.0, 0.0, 1.0]]
        returned = [[1000.5, 0.0, 320.0], [0.0, 1000.5, 240.0], [0.0, 0.0, 1.0]]
        claim = claims.calibration_claim(self._out(certified, returned, self.RANGES, adjusted=False))
        assert claim.source == "camera_model" and not claim.returned_is_certified
        warning = next(w for w in claim.warnings if w["code"] == "returned_K_not_certified")
        assert "camera model" in warning["detail"] and "bundle adjustment" not in warning["detail"]

    def test_a_claim_about_a_K_not_returned_is_impossible(self):
        with pytest.raises(ValueError):
            claims.CalibrationClaim(None, "none", None, True, False, None, (), None, ())
        with pytest.raises(ValueError):  # the returned K called certified with no certified K beside it
            claims.CalibrationClaim([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]], "autocalibration", None, False, True,
                                    None, (), None, ())
        with pytest.raises(ValueError):
            claims.CalibrationClaim(None, "none", None, False, False, None, (), True, ())


class TestUnknownIntrinsics:
    def test_a_long_lens_is_found_from_a_prior_four_times_too_short(self):
        # f = 3000 px on 640 x 480 images (a 12 degree field of view); the prior is COLMAP's 1.2 x 640.
        scene = synthetic.scene(views=8, points=150, focal=3000.0, seed=4, noise_px=0.3, spread_degrees=25.0,
                                distance=20.0)
        out = pipeline.reconstruct(scene.tracks, [scene.image_size] * 8, ReconstructionOptions(resect_cameras=False))
        assert out.summary["views_registered"] == 8
        f = out.summary["calibration"]["K"][0][0]
        assert abs(f / 3000.0 - 1) < 0.03
        assert aligned_rotation_errors([c.R for c in out.cameras], list(scene.rotations)).max() < 0.5
        rounds = out.stages[0]["focal_rounds"]  # the registration refined it as it placed the views
        assert rounds[0]["focal_px"] == pytest.approx(768.0) and abs(rounds[0]["registration_focal_px"] / 3000 - 1) < 0.03

    def test_a_view_pnp_refused_at_the_prior_is_tried_again_at_the_refined_focal_length(self):
        # 6 views of 16 points: at the prior focal length (768 px against 800) PnP places 3, and
        # the others see no more points after the focal length is refined; they are tried again.
        scene = synthetic.scene(views=6, points=16, seed=3, noise_px=0.5)
        out = pipeline.reconstruct(scene.tracks, [scene.image_size] * 6, ReconstructionOptions(resect_cameras=False))
        assert out.summary["views_registered"] == 6
        assert aligned_rotation_errors([c.R for c in out.cameras], list(scene.rotations)).max() < 1.0

    def test_the_principal_point_is_estimated_when_the_data_fix_it(self):
        # The principal point 40 px right of and 25 px above the centre, a general motion: freed
        # by the test, it lands within 3 px; held at the centre ("centre"), the cost is higher.
        scene = synthetic.scene(views=10, points=200, seed=6, noise_px=0.3, spread_degrees=50.0)
        K = scene.K.copy()
        K[0, 2] += 40.0
        K[1, 2] -= 25.0
        tracks = [(views, pixels + np.array([40.0, -25.0])) for views, pixels in scene.tracks]  # the moved centre
        out = pipeline.reconstruct(tracks, [scene.image_size] * 10, ReconstructionOptions(resect_cameras=False))
        test = out.stages[2]["principal_point"]
        assert test["estimated"] and test["chi2"] > 13.8
        pp = np.array(out.summary["calibration"]["K"])[:2, 2]
        assert np.abs(pp - K[:2, 2]).max() < 3.0
        held = pipeline.reconstruct(tracks, [scene.image_size] * 10, ReconstructionOptions(
            resect_cameras=False, principal_point="centre"))
        assert "principal_point" not in held.stages[2]
        assert np.abs(np.array(held.summary["calibration"]["K"])[:2, 2] - [320.0, 240.0]).max() < 1e-9


    @staticmethod
    def _distorted(k1: float, seed: int = 6):
        scene = synthetic.scene(views=10, points=200, seed=seed, noise_px=0.3, spread_degrees=50.0)
        centre = np.array([319.5, 239.5])

        def distort(pixels):
            n = (pixels - centre) / 800.0
            return centre + 800.0 * n * (1 + k1 * np.sum(n * n, axis=1))[:, None]

        return scene, [(views, distort(pixels)) for views, pixels in scene.tracks]

    def test_a_radial_distortion_is_recovered_and_the_certificates_say_they_rest_on_it(self):
        # Barrel distortion k1 = -0.25 (18 px at the image's corner) about the centre, f = 800 px.
        scene, tracks = self._distorted(-0.25)
        out = pipeline.reconstruct(tracks, [scene.image_size] * 10, ReconstructionOptions(radial_distortion="auto"))
        f = out.summary["calibration"]["K"][0][0]
        assert abs(f / 800.0 - 1) < 0.005
        distortion = out.summary["distortion"]
        assert distortion["k1"] == pytest.approx(-0.25, abs=0.01) and distortion["certified"] is False
        assert "certificates_conditional_on_k1" in [w["code"] for w in out.summary["warnings"]]
        for camera in out.cameras:  # each camera carries the k1 its pixels were undistorted with
            assert camera.k1 == pytest.approx(-0.25, abs=0.01) and camera.distortion_centre == [319.5, 239.5]
        # The points return the undistorted observations their certificates are about: the pinhole
        # cameras returned reproject them within the threshold.
        for point in out.points[:50]:
            X = np.array([*point.result.point, 1.0])
            for v, u, w in point.observations:
                image = out.cameras[int(v)].P @ X
                assert np.hypot(image[0] / image[2] - u, image[1] / image[2] - w) < 2.0
        assert aligned_rotation_errors([c.R for c in out.cameras], list(scene.rotations)).max() < 0.2

    def test_no_radial_term_is_kept_when_the_data_do_not_need_one(self):
        scene, tracks = self._distorted(0.0)
        out = pipeline.reconstruct(tracks, [scene.image_size] * 10, ReconstructionOptions(
            resect_cameras=False, radial_distortion="auto"))
        assert "distortion" not in out.summary and all(c.k1 is None for c in out.cameras)
        assert not out.stages[0]["radial_distortion"]["estimated"]

    def test_a_radial_term_the_test_rejects_gets_no_registration_round(self):
        # No distortion, the principal point 40 px right of and 25 px above the centre: the first
        # round's adjustment about the centre fits a k1 that moves the corner by more than
        # RADIAL_STEP_PX with the focal length within 2% (every 2nd templeRing photo's case). The
        # term is tested before a second registration on pixels undistorted with it, rejected
        # against the free principal point, and no second round is run.
        scene = synthetic.scene(views=10, points=200, seed=6, noise_px=0.3, spread_degrees=50.0)
        tracks = [(views, pixels + np.array([40.0, -25.0])) for views, pixels in scene.tracks]
        out = pipeline.reconstruct(tracks, [scene.image_size] * 10, ReconstructionOptions(resect_cameras=False))
        rounds, radial = out.stages[0]["focal_rounds"], out.stages[0]["radial_distortion"]
        first = rounds[0]
        corner = np.hypot(640, 480) / 2
        moved = abs(first["refined_k1"]) * (corner / first["refined_focal_px"]) ** 3 * first["refined_focal_px"]
        assert moved > pipeline.RADIAL_STEP_PX
        assert abs(first["refined_focal_px"] / first["registration_focal_px"] - 1) <= 0.02
        assert len(rounds) == 1 and first["radial_tested"]
        assert not radial["estimated"] and radial["chi2"] <= pipeline.RADIAL_CHI2
        assert radial["k1_tested"] == first["refined_k1"]
        assert "distortion" not in out.summary and out.summary["views_registered"] == 10
        assert aligned_rotation_errors([c.R for c in out.cameras], list(scene.rotations)).max() < 0.5

    def test_a_radial_term_the_test_keeps_still_gets_its_registration_round(self):
        # Barrel distortion k1 = -0.25 about the centre: the early test keeps the term, and the
        # second round registers on the pixels undistorted with it, as before.
        scene, tracks = self._distorted(-0.25)
        out = pipeline.reconstruct(tracks, [scene.image_size] * 10, ReconstructionOptions(resect_cameras=False))
        rounds = out.stages[0]["focal_rounds"]
        assert len(rounds) >= 2 and rounds[1]["k1"] == rounds[0]["refined_k1"]
        assert out.stages[0]["radial_distortion"]["estimated"]


RING_VIEWS = 40


@pytest.fixture(scope="module")
def ring():
    """A dense ring (40 photos 9 degrees apart round an object, each point seen over a stretch of
    the ring, a 1500 px lens: Middlebury's templeRing's shape) in a shuffled file order."""
    scene = synthetic.ring(views=RING_VIEWS, points=300, seed=1, noise_px=0.3)
    order = np.random.default_rng(2).permutation(RING_VIEWS)  # file position -> view round the ring
    position = np.argsort(order)
    return scene, order, [(position[views], pixels) for views, pixels in scene.tracks]


class TestDenseRing:
    VIEWS = RING_VIEWS

    def test_k_known_registers_every_view_in_any_order(self, ring):
        from geocert.solvers.reconstruction.calibrated import calibrated_reconstruction

        scene, order, tracks = ring
        found = calibrated_reconstruction(tracks, [scene.K] * self.VIEWS)
        assert found.stats["registered"] == self.VIEWS
        errors = aligned_rotation_errors(found.rotations, list(scene.rotations[order]))
        assert errors.max() < 0.5

    def test_k_unknown_refines_the_focal_length_as_it_registers(self, ring):
        # The prior (1.2 x 640 = 768 px) is half the true focal length: the registration refines
        # one shared focal length in its adjustments as it places views (COLMAP's way), so the
        # views placed later are resected at the refined focal length, and its first round ends
        # with every view placed near the true focal length: no round registers them again.
        scene, order, tracks = ring
        out = pipeline.reconstruct(tracks, [scene.image_size] * self.VIEWS,
                                   ReconstructionOptions(resect_cameras=False))
        assert out.summary["views_registered"] == self.VIEWS
        assert abs(out.summary["calibration"]["K"][0][0] / 1500.0 - 1) < 0.02
        errors = aligned_rotation_errors([c.R for c in out.cameras], list(scene.rotations[order]))
        assert errors.max() < 0.5
        rounds = out.stages[0]["focal_rounds"]
        assert rounds[0]["focal_px"] == pytest.approx(768.0) and not rounds[0]["resumed"]
        assert rounds[0]["registered"] == self.VIEWS
        assert abs(rounds[0]["registration_focal_px"] / 1500.0 - 1) < 0.02
        assert out.stages[0]["initial_pair"] is not None  # the first round's, kept


class TestMotion:
    """The motion of the returned cameras, judged whatever the order of the photos, and at the
    noise the adjustment's residuals give (upgrade.motion, upgrade.rotation_noise)."""

    @staticmethod
    def _metric(R, centres):
        return upgrade.Metric(np.eye(3), list(R), [-r @ c for r, c in zip(R, centres)], np.zeros((0, 3)), [], False)

    @staticmethod
    def _orders(count: int, seed: int = 0):
        rng = np.random.default_rng(seed)
        return [np.arange(count)] + [rng.permutation(count) for _ in range(7)]

    def test_the_judgement_does_not_follow_the_order_of_the_views(self):
        """An arc round an object: judged "orbital_motion" in every order (the first view as the
        reference judged one order of it general)."""
        from tests.solvers.autocalibration.test_critical_motions import layout

        _, R, centres = layout("arc", seed=1)
        judged = {tuple(w["code"] for w in upgrade.motion(self._metric(R[p], centres[p]))[0])
                  for p in self._orders(len(R))}
        assert judged == {("orbital_motion",)}

    @pytest.mark.parametrize("name", ["corridor", "dinoSparseRing"])
    def test_real_cameras_are_judged_alike_in_any_order(self, name):
        """VGG's Corridor (a forward walk: it was judged "pure_translation", general or "rotation
        about one axis" by the order of its frames) and Middlebury's dinoSparseRing (a ring)."""
        from tests.solvers.autocalibration.test_critical_motions import corridor, dino_sparse_ring

        views = corridor() if name == "corridor" else dino_sparse_ring()
        judged = {tuple(w["code"] for w in upgrade.motion(self._metric(views.R[p], views.centres[p]))[0])
                  for p in self._orders(len(views.R))}
        assert judged == {("pure_translation",) if name == "corridor" else ("orbital_motion",)}

    def test_the_rotation_noise_is_the_poses_scatter(self):
        """rotation_noise against the scatter of each camera's pose refitted to fresh noise (its
        points held): within 30%, and in proportion to the pixels' noise."""
        from scipy.optimize import least_squares

        scene = synthetic.scene(views=6, points=80, seed=11)
        truth = upgrade.Metric(scene.K, list(scene.rotations), list(scene.translations), scene.points, [], False)
        rng = np.random.default_rng(0)
        estimates = {}
        for sigma in (0.5, 1.0):
            tracks = [(v, x + sigma * rng.standard_normal(x.shape)) for v, x in scene.tracks]
            obs = Observations.from_tracks(tracks, 6)
            estimates[sigma] = upgrade.rotation_noise(truth, obs.view, obs.track, obs.pixel,
                                                      np.ones(len(obs.view), dtype=bool))
        assert 1.7 < estimates[1.0] / estimates[0.5] < 2.3
        X, R0, t0 = scene.points, scene.rotations[0], scene.translations[0]
        exact = (X @ R0.T + t0) @ scene.K.T
        exact = exact[:, :2] / exact[:, 2:]

        def pixels(pose):
            R = Rotation.from_rotvec(pose[:3]).as_matrix() @ R0
            image = (X @ R.T + t0 + pose[3:]) @ scene.K.T
            return image[:, :2] / image[:, 2:]

        angles = []
        for _ in range(200):
            seen = exact + rng.standard_normal(exact.shape)
            fit = least_squares(lambda pose: (pixels(pose) - seen).ravel(), np.zeros(6), method="lm")
            angles.append(fit.x[:3])
        scatter = float(np.sqrt(np.linalg.eigvalsh(np.cov(np.array(angles).T)).max()))
        # rotation_noise is a relative rotation's: sqrt(2) times one camera's (the median camera's).
        assert 0.7 < estimates[1.0] / np.sqrt(2) / scatter < 1.3

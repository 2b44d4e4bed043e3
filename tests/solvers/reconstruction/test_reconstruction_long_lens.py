"""Long lenses, K unknown (issue 35: never silently wrong). A narrow field of view makes the
cameras nearly affine: the focal length is weakly fixed by the tracks, a registration from a
prior focal length far from the truth can settle in a distorted rig that fits only some of the
observations, and a scene and its mirror image in depth project nearly alike. The pipeline keeps
what explains every observation best (pipeline.fit_cost) and checks the returned rig against its
depth-reversed twin (ambiguity.check), saying so when the twin fits about as well."""

from __future__ import annotations

import copy

import numpy as np

from geocert.pipelines.reconstruction import pipeline
from geocert.pipelines.reconstruction.options import ReconstructionOptions
from geocert.solvers.reconstruction import synthetic, upgrade
from geocert.formulations.reconstruction import depth_reversal
from geocert.verify.checks import verify_any

from tests.verify.test_forgeries import calibrated_reconstruction, refused  # noqa: F401 (a fixture, used by name)
from testing.reconstruction import aligned_rotation_errors


def reconstruct_cameras(scene):
    """The pipeline's cameras, K unknown, with its defaults; stopped where the certified
    structure starts (the cameras and their checks are what is compared)."""
    return pipeline.reconstruct(scene.tracks, [scene.image_size] * len(scene.rotations),
                                ReconstructionOptions(resect_cameras=False),
                                lambda stage, *progress: stage.startswith("structure"))


def dino_like(focal: float, distance: float, noise_px: float, seed: int = 0):
    """Six views 23.5 degrees apart round a turntable's axis, seen from 16 degrees above (the
    dinoSparseRing's ring, its 11-degree field of view at focal 3300 px on 640x480)."""
    return synthetic.turntable(views=6, points=150, focal=focal, step_degrees=23.5, elevation_degrees=16.0,
                               distance=distance, noise_px=noise_px, seed=seed)


def test_a_long_lens_with_k_unknown_gives_the_right_poses_and_focal_length():
    # From the prior focal length 768 px (1.2 x 640) against the true 3300, the earlier pipeline
    # kept the adjustment start with the smaller RMS over the observations each kept: it
    # returned 5 of the 6 views with the focal length +199% (a camera dropped as contradicting
    # its own observations). Compared over every observation, the right rig wins.
    scene = dino_like(focal=3300.0, distance=20.0, noise_px=0.3)
    out = reconstruct_cameras(scene)
    registered = [c for c in out.cameras if c.registered and c.R is not None]
    assert len(registered) == 6
    errors = aligned_rotation_errors([c.R for c in registered], [scene.rotations[c.view] for c in registered])
    assert errors.max() < 0.5
    assert abs(registered[0].K[0, 0] / 3300.0 - 1) < 0.03
    reversal = out.summary["depth_reversal"]
    assert out.summary["poses_determined"] is True and not reversal["ambiguous"] and not reversal["adopted"]
    assert reversal["cost_ratio"] > 1 + reversal["margin"]
    assert type(reversal["mirror_capped"]) is bool  # whether the twin's cost is its adjustment's at the cap
    assert all(c.pose_determined is True for c in registered)
    assert "poses_not_determined" not in [w["code"] for w in out.summary["warnings"]]


def test_a_nearly_affine_view_says_the_poses_are_not_determined():
    # A 165,000 px lens from 1000 times the object's size: the depth-reversed twin projects within
    # the noise of the scene, so nothing in the observations says which rig is right. Whichever
    # the adjustment returns, the result must say that its poses are not determined.
    scene = dino_like(focal=165_000.0, distance=1000.0, noise_px=1.0)
    out = reconstruct_cameras(scene)
    registered = [c for c in out.cameras if c.registered and c.R is not None]
    assert len(registered) >= 3
    reversal = out.summary["depth_reversal"]
    assert reversal["checked"] and reversal["ambiguous"]
    assert reversal["cost_ratio"] < 1 + reversal["margin"]
    assert out.summary["poses_determined"] is False
    assert all(c.pose_determined is False for c in registered)
    assert max(c.mirror_rotation_deg for c in registered) > 10.0  # the two rigs differ: not a formality
    codes = [w["code"] for w in out.summary["warnings"]]
    assert codes[0] == "reconstruction_doubtful" and "poses_not_determined" in codes
    assert out.summary["doubtful"] is True


def test_the_depth_reversed_twin_keeps_each_view_of_the_points_up_to_perspective():
    scene = dino_like(focal=3300.0, distance=20.0, noise_px=0.0)
    metric = upgrade.Metric(scene.K, list(scene.rotations), list(scene.translations), scene.points.copy(), [], False)
    twin = depth_reversal.mirrored(metric, reference=2)
    assert np.allclose(twin.rotations[2], scene.rotations[2]) and np.allclose(twin.translations[2],
                                                                               scene.translations[2])
    for v in range(6):
        R = twin.rotations[v]
        assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
        # the relative rotation's angle is kept, its axis mirrored: not the same rotation
        angle = depth_reversal.rotation_between_deg(scene.rotations[2], scene.rotations[v])
        assert np.isclose(depth_reversal.rotation_between_deg(twin.rotations[2], R), angle, atol=1e-6)
        if v != 2:
            assert depth_reversal.rotation_between_deg(R @ twin.rotations[2].T,
                                                       scene.rotations[v] @ scene.rotations[2].T) > 10.0
        # each camera sees every point at the same x and y in its own frame, its depth reversed
        # about the centroid's
        seen = scene.points @ scene.rotations[v].T + scene.translations[v]
        mirror = twin.points @ R.T + twin.translations[v]
        assert np.allclose(mirror[:, :2], seen[:, :2])
        centre = seen[:, 2].mean()
        assert np.allclose(mirror[:, 2] - centre, -(seen[:, 2] - centre))


class TestPosesDeterminedTied:
    """The verifier cannot run the twin's adjustment, so it takes the depth-reversal check's costs
    as stated, but its verdict must be theirs and be stated consistently (the summary, its
    warning, every registered camera), and a rig whose poses are not determined must be called
    doubtful."""

    @staticmethod
    def not_determined(result: dict, warn: bool = True, cameras: bool = True, doubtful: bool = True) -> dict:
        result = copy.deepcopy(result)
        summary = result["summary"]
        summary["poses_determined"] = False
        figures = summary["depth_reversal"]  # the figures made the verdict's: the twin fits as well
        figures.update(mirror_cost_px2=figures["cost_px2"], statistic=0.0, cost_ratio=1.0, ambiguous=True,
                       adopted=False, returned_refitted=True)  # the pipeline refits the rig unless the twin is rejected
        if warn:
            summary["warnings"].append({"code": "poses_not_determined", "detail": "stated"})
        if cameras:
            for camera in result["cameras"]:
                if camera["registered"]:
                    camera["pose_determined"] = False
        if doubtful and not summary.get("doubtful"):
            summary["doubtful"] = True
            summary["warnings"].insert(0, {"code": "reconstruction_doubtful", "detail": "stated"})
        return result

    def test_the_genuine_result_states_its_poses_and_verifies(self, calibrated_reconstruction):
        summary = calibrated_reconstruction["summary"]
        assert summary["poses_determined"] is True and summary["depth_reversal"]["checked"]
        assert all(c["pose_determined"] is True for c in calibrated_reconstruction["cameras"] if c["registered"])
        report = verify_any(copy.deepcopy(calibrated_reconstruction))
        assert report.valid, report.first_failure

    def test_poses_said_not_determined_everywhere_verifies(self, calibrated_reconstruction):
        report = verify_any(self.not_determined(calibrated_reconstruction))
        assert report.valid, report.first_failure

    def test_poses_not_determined_without_its_warning_is_refused(self, calibrated_reconstruction):
        assert "poses_determined" in refused(self.not_determined(calibrated_reconstruction, warn=False))["detail"]

    def test_a_camera_claiming_a_determined_pose_against_the_summary_is_refused(self, calibrated_reconstruction):
        assert "poses_determined" in refused(self.not_determined(calibrated_reconstruction, cameras=False))["detail"]

    def test_poses_not_determined_in_a_rig_not_called_doubtful_is_refused(self, calibrated_reconstruction):
        assert "doubtful" in refused(self.not_determined(calibrated_reconstruction, doubtful=False))["detail"]


def test_an_adjustment_settled_in_the_worse_twin_gets_the_better_one_back():
    # The depth-reversed twin of the true rig, adjusted, is a rig that fits worse (its focal
    # length runs off making the view more affine); checked, its own twin is the true rig again,
    # which fits better by far: that one is returned, and the figures say so.
    from geocert.pipelines.reconstruction import ambiguity
    from geocert.solvers.reconstruction.tracks import Observations

    scene = dino_like(focal=3300.0, distance=20.0, noise_px=0.3)
    obs = Observations.from_tracks(scene.tracks, 6)
    truth = upgrade.Metric(scene.K.copy(), list(scene.rotations), list(scene.translations), scene.points.copy(), [],
                           False)
    worse, keep, _ = upgrade.adjust(depth_reversal.mirrored(truth, reference=0), obs.view, obs.track, obs.pixel, 2.0)
    assert aligned_rotation_errors(worse.rotations, list(scene.rotations)).max() > 10.0
    kept, _, figures = ambiguity.check(worse, obs, keep, 2.0, "simple")
    assert figures["adopted"] and not figures["ambiguous"] and figures["cost_ratio"] < 1 / (1 + figures["margin"])
    assert aligned_rotation_errors(kept.rotations, list(scene.rotations)).max() < 0.5
    assert abs(kept.K[0, 0] / 3300.0 - 1) < 0.03

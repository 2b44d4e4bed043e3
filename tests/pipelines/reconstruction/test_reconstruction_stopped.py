"""K unknown: a run stopped (a cancel, or the job's clock) after the registration placed views
keeps their metric cameras, as the registration found them, rather than only their projective P
and "no metric reconstruction was found" (issue 35: on Middlebury's 47-photo templeRing the
job's clock passed before the metric upgrade, and the result returned no metric camera at all).

The scene: a synthetic ring of 12 photos round an object with a 1500 px lens (synthetic.ring),
registered from the default prior focal length (1.2 x 640 = 768 px, half the truth)."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.pipelines.reconstruction import pipeline
from geocert.pipelines.reconstruction.options import ReconstructionOptions
from geocert.solvers.reconstruction import synthetic, upgrade

from testing.reconstruction import aligned_rotation_errors

VIEWS = 12


@pytest.fixture(scope="module")
def ring():
    return synthetic.ring(views=VIEWS, points=250, seed=1, noise_px=0.3)


def stopped(ring, when) -> pipeline.Reconstruction:
    """The pipeline on the ring, stopped at the first progress report for which ``when(stage)``."""
    return pipeline.reconstruct(ring.tracks, [ring.image_size] * VIEWS, ReconstructionOptions(resect_cameras=False),
                                lambda stage, *progress: when(stage))


def assert_metric_cameras_kept(ring, out: pipeline.Reconstruction, at_least: int = VIEWS - 1) -> list:
    kept = [c for c in out.cameras if c.registered]
    assert len(kept) >= at_least and out.metric is not None
    for camera in kept:
        assert camera.K is not None and camera.R is not None and camera.t is not None
        P = camera.K @ np.c_[camera.R, camera.t]
        assert np.allclose(camera.P / np.linalg.norm(camera.P), P / np.linalg.norm(P))
        assert camera.bound is None  # nothing about them is certified
    errors = aligned_rotation_errors([c.R for c in kept], [ring.rotations[c.view] for c in kept])
    assert errors.max() < 2.0, errors
    assert out.summary["calibration"]["certified"] is False
    assert out.summary["calibration"]["returned_is_certified"] is False
    assert not any(w["code"] == "no_metric_upgrade" for w in out.summary["warnings"])
    return kept


def test_a_stop_at_the_certified_upgrade_keeps_the_registrations_metric_cameras(ring):
    out = stopped(ring, lambda stage: stage.startswith("autocalibration"))
    kept = assert_metric_cameras_kept(ring, out)
    # the registration's focal length was refined from the prior by its adjustment
    assert abs(kept[0].K[0, 0] / 1500.0 - 1) < 0.05
    stage = out.stages[1]
    assert stage["status"] == "cancelled" and "registration's metric cameras" in stage["reason"]
    assert "refined by the registration's bundle adjustment" in stage["reason"]


def test_a_stop_during_the_registration_keeps_the_views_placed_so_far(ring):
    out = pipeline.reconstruct(ring.tracks, [ring.image_size] * VIEWS, ReconstructionOptions(resect_cameras=False),
                               lambda stage, done, total, *progress: stage.startswith("projective") and done >= 6)
    assert_metric_cameras_kept(ring, out, at_least=6)
    stage = out.stages[0]
    assert stage["status"] == "cancelled" and "registration's metric cameras" in stage["reason"]
    assert "not adjusted" in stage["reason"]


def test_the_clock_passing_after_registration_says_time_limit_first_and_keeps_the_cameras(ring, monkeypatch):
    """The job's path (batch.solve_job): its clock (the kind's time_bound_s) passes once the
    certified upgrade starts, a fake clock standing in for a slow machine."""
    import time
    from types import SimpleNamespace

    from geocert.jobs.runner import solve_job
    from geocert.kinds import reconstruction as kind

    late = {"s": 0.0}
    monkeypatch.setattr(kind, "time", SimpleNamespace(perf_counter=lambda: time.perf_counter() + late["s"],
                                                      process_time=time.process_time))
    autocalibrate = upgrade.autocalibrate

    def past_the_clock(*args, **kwargs):
        late["s"] = 1e6
        return autocalibrate(*args, **kwargs)

    monkeypatch.setattr(upgrade, "autocalibrate", past_the_clock)
    result = solve_job({"kind": "reconstruction", "options": {"resect_cameras": False},
                        "data": {"views": [{"image_size": list(ring.image_size)}] * VIEWS,
                                 "tracks": [{"views": [int(v) for v in views],
                                             "points": [[float(u), float(w)] for u, w in pixels]}
                                            for views, pixels in ring.tracks]}})
    assert result["stats"]["statuses"] == {"time_limit": 1}
    warnings = result["summary"]["warnings"]
    assert warnings[0]["code"] == "time_limit" and "autocalibration" in warnings[0]["detail"]
    assert not any(w["code"] == "no_metric_upgrade" for w in warnings)
    stages = {stage["name"]: stage for stage in result["stages"]}
    assert stages["autocalibration"]["status"] == "time_limit"
    assert "registration's metric cameras" in stages["autocalibration"]["reason"]
    kept = [c for c in result["cameras"] if c["registered"]]
    assert len(kept) >= VIEWS - 1 and all(c["K"] is not None and c["R"] is not None for c in kept)
    assert not any(c["certified"] for c in kept) and not result["points"]
    errors = aligned_rotation_errors([np.array(c["R"]) for c in kept], [ring.rotations[c["view"]] for c in kept])
    assert errors.max() < 2.0, errors
    calibration = result["summary"]["calibration"]
    assert calibration["certified"] is False and calibration["returned_is_certified"] is False
    assert abs(calibration["K"][0][0] / 1500.0 - 1) < 0.05

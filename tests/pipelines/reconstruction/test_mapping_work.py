"""The mapping's work where its answer does not need it (issue 35: total CPU at most COLMAP's):
the per-view principal points' trial adjustment (two rounds at their iteration cap on the
Middlebury rings) runs only when the data could fix each view's principal point. Their
deviations are predicted from the shared fit at the noise of the linearised per-view fit's
minimum. Where the data fix them (each view's principal point shifted), the prediction is near
the trial's own deviations; where they do not (a long lens), the trial is not run, and the shared
principal point stays, as the trial would have left it."""

from __future__ import annotations

import numpy as np

from geocert.pipelines.reconstruction import pipeline
from geocert.solvers.reconstruction import synthetic, upgrade
from geocert.solvers.reconstruction.tracks import Observations


def _truth(scene) -> upgrade.Metric:
    return upgrade.Metric(scene.K.copy(), list(scene.rotations), list(scene.translations), scene.points.copy(), [],
                          False)


def _adjusted(scene, model: str = "simple"):
    obs = Observations.from_tracks(scene.tracks, len(scene.rotations))
    metric, keep, _ = upgrade.adjust(_truth(scene), obs.view, obs.track, obs.pixel, 2.0, model=model)
    return metric, keep, obs


def _shifted_scene():
    """pipeline's per-view test scene (tests/pipelines/reconstruction/test_principal_point_per_view.py):
    eight general views, each principal point moved by up to 15 px."""
    scene = synthetic.scene(views=8, points=200, seed=6, noise_px=0.3, spread_degrees=50.0)
    shift = np.random.default_rng(1).uniform(-15, 15, (8, 2))
    tracks = [(views, pixels + shift[np.asarray(views)]) for views, pixels in scene.tracks]
    return scene, tracks


def _shared_fit(scene, tracks):
    obs = Observations.from_tracks(tracks, len(scene.rotations))
    metric, keep, _ = upgrade.adjust(_truth(scene), obs.view, obs.track, obs.pixel, 2.0, model="principal")
    return metric, keep, obs


def _with_shared_Ks(metric):
    from dataclasses import replace

    return replace(metric, Ks=[None if R is None else upgrade.K_of(metric, v).copy()
                               for v, R in enumerate(metric.rotations)])


def test_the_predicted_deviations_are_the_per_view_fits_own():
    # From the shared fit (whose residuals carry each view's shift), at the noise of the
    # linearised per-view fit's minimum, the deviations are within 30% of the per-view fit's own.
    scene, tracks = _shifted_scene()
    metric, keep, obs = _shared_fit(scene, tracks)
    views = list(range(8))
    shared = _with_shared_Ks(metric)
    predicted = pipeline._principal_point_sd(shared, obs, keep, views, linearised_minimum=True)
    trial, trial_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, 2.0, model="principal_per_view")
    own = pipeline._principal_point_sd(trial, obs, trial_keep, views)
    assert np.all(own < 5.0)
    assert np.all(np.abs(predicted / own - 1) < 0.3), (predicted, own)


def test_a_per_view_trial_the_data_cannot_pass_is_not_run(monkeypatch):
    # A long lens (the dinoSparseRing's ring at 3300 px): a principal point's shift and a small
    # rotation nearly coincide, and no view's is fixed to 5 px. The test says so without the trial,
    # and the trial, forced, decides the same.
    scene = synthetic.turntable(views=6, points=150, focal=3300.0, step_degrees=23.5, elevation_degrees=16.0,
                                distance=20.0, noise_px=0.3, seed=0)
    metric, keep, obs = _adjusted(scene, model="principal")
    image_size = scene.image_size
    calls = []
    adjust = upgrade.adjust

    def counted(*args, **kwargs):
        calls.append(kwargs.get("model"))
        return adjust(*args, **kwargs)

    monkeypatch.setattr(pipeline.upgrade, "adjust", counted)
    kept, kept_obs, figures = pipeline._principal_points_per_view(metric, obs, keep, 2.0, image_size)
    assert calls == [] and kept is metric and figures["estimated"] is False and figures["precise"] is False
    # every deviation beyond the margin (none finite: the data leave them free)
    assert all(sd > pipeline.PRECISE_MARGIN * figures["max_sd_px"] for sd in figures["sd_px"])
    monkeypatch.setattr(pipeline, "PRECISE_MARGIN", np.inf)
    _, _, forced = pipeline._principal_points_per_view(metric, obs, keep, 2.0, image_size)
    assert calls == ["principal_per_view"]
    assert forced["estimated"] is False and forced["precise"] is False

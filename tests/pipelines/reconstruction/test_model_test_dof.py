"""The camera model's tests (pipeline._saved_variances: the radial term with K unknown, the shared
principal point, the per-view principal points and focal lengths, and the K-known radial term)
read what freeing parameters saves in noise variances, the noise variance the free fit's cost
over its residual degrees of freedom: 2 per observation less every parameter it spends (6 per
pose, 3 per point, less the similarity's 7, and its intrinsics). On a synthetic scene of short
tracks (2 to 3 views each, as a sparse ring's) with Gaussian noise of known sigma, the variance
each test implies ((held cost - free cost) / chi2) is the noise's, and the chi2 is the one
computed here by hand from the two fits. Over 2 per observation less the parameters added (the
poses and points not counted, as main's radial, principal point and per-view tests divided) that
variance is about half the noise's and every statistic about twice too large."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from geocert.pipelines.reconstruction import pipeline
from geocert.pipelines.reconstruction.options import ReconstructionOptions
from geocert.solvers.reconstruction import synthetic, upgrade
from geocert.solvers.reconstruction.tracks import Observations

SIGMA = 0.5  # px
THRESHOLD = 2.5  # px: beyond 5 sigma, so that the robust rounds drop nothing
SEEDS = (1, 2, 3)


def _scene(seed: int):
    """10 general views of 300 points, each point seen by each view with probability 0.3 (tracks of
    2 to 3 views mostly), no distortion, the principal point at the image's centre; the
    reconstruction starts from the ground truth."""
    scene = synthetic.scene(views=10, points=300, seed=seed, noise_px=SIGMA, spread_degrees=50.0, visibility=0.3)
    obs = Observations.from_tracks(scene.tracks, 10)
    metric = upgrade.Metric(scene.K.copy(), list(scene.rotations), list(scene.translations), scene.points.copy(),
                            [], False)
    return scene, obs, metric


def _cost(metric: upgrade.Metric, obs: Observations, use: np.ndarray) -> float:
    """The sum of squared reprojection errors of the observations ``use`` (px^2), by hand: each
    view's K (its own where the fit has one), the radial term k1 on normalised coordinates."""
    total = 0.0
    for m in np.flatnonzero(use):
        v, j = obs.view[m], obs.track[m]
        K = metric.Ks[v] if metric.Ks is not None and metric.Ks[v] is not None else metric.K
        cam = metric.rotations[v] @ metric.points[j] + metric.translations[v]
        n = cam[:2] / cam[2]
        n = n * (1.0 + metric.k1 * float(n @ n))
        pixel = K[:2, :2] @ n + K[:2, 2]
        total += float(np.sum((pixel - obs.pixel[m]) ** 2))
    return total


def _dof(obs: Observations, use: np.ndarray, intrinsics: int) -> int:
    n = int(use.sum())
    return 2 * n - (6 * len(np.unique(obs.view[use])) + 3 * len(np.unique(obs.track[use])) - 7) - intrinsics


def _recording(monkeypatch) -> list:
    """upgrade.adjust's fits made from here on: (model, Metric, keep)."""
    fits, adjust = [], upgrade.adjust

    def recorded(*args, **kwargs):
        out = adjust(*args, **kwargs)
        fits.append((kwargs.get("model", "simple"), out[0], out[1]))
        return out

    monkeypatch.setattr(upgrade, "adjust", recorded)
    return fits


def _check(chi2: float, held, free, obs, common, intrinsics: int):
    """The test's chi2 is the one computed by hand, and the noise variance it implies the noise's."""
    held_cost, free_cost = _cost(held, obs, common), _cost(free, obs, common)
    dof = _dof(obs, common, intrinsics)
    assert 2 * int(common.sum()) > 1.6 * dof  # short tracks: the poses and points spend a good share
    assert chi2 == pytest.approx((held_cost - free_cost) / (free_cost / dof), rel=1e-6, abs=1e-9)
    implied = (held_cost - free_cost) / chi2
    assert implied == pytest.approx(SIGMA ** 2, rel=0.15)


@pytest.mark.parametrize("seed", SEEDS)
def test_the_principal_point_test_reads_the_noise_variance(monkeypatch, seed):
    _, obs, metric = _scene(seed)
    held, held_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, THRESHOLD, model="simple")
    fits = _recording(monkeypatch)
    kept, _, figures = pipeline._principal_point(held, obs, held_keep, THRESHOLD, (640, 480))
    (model, free, free_keep), = fits
    assert model == "principal" and figures["estimated"] is False and kept is held  # it is at the centre
    _check(figures["chi2"], held, free, obs, held_keep & free_keep, intrinsics=3)


@pytest.mark.parametrize("seed", SEEDS)
def test_the_per_view_principal_point_test_reads_the_noise_variance(monkeypatch, seed):
    _, obs, metric = _scene(seed)
    held, held_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, THRESHOLD, model="simple")
    fits = _recording(monkeypatch)
    kept, _, figures = pipeline._principal_points_per_view(held, obs, held_keep, THRESHOLD, (640, 480))
    (model, free, free_keep), = fits
    assert model == "principal_per_view" and figures["estimated"] is False and kept is held
    assert figures["parameters_added"] == 20
    _check(figures["chi2"], held, free, obs, held_keep & free_keep, intrinsics=1 + 2 * 10)


@pytest.mark.parametrize("seed", SEEDS)
def test_the_radial_test_reads_the_noise_variance(monkeypatch, seed):
    """K unknown: the fit with k1 (f and k1 free) against the one without it (the principal point
    free instead, options.principal_point "per_view")."""
    _, obs, metric = _scene(seed)
    free, _, _ = upgrade.adjust(replace(metric, k1=1e-3), obs.view, obs.track, obs.pixel, THRESHOLD, model="radial")
    assert free.k1 != 0.0
    options = ReconstructionOptions(radial_distortion="auto", principal_point="per_view", threshold_px=THRESHOLD)
    with_keep = pipeline._kept(free, obs, THRESHOLD)
    fits = _recording(monkeypatch)
    _, figures = pipeline._radial_test(free, obs, options, {"model": "auto", "estimated": False})
    model, held, held_keep = fits[0]
    assert model == "principal" and figures["against"] == "principal" and "k1" not in figures
    _check(figures["chi2"], held, free, obs, with_keep & held_keep, intrinsics=2)


@pytest.mark.parametrize("seed", SEEDS)
def test_the_known_K_radial_test_reads_the_noise_variance(seed):
    """K known (as it did before the others were made alike): k1 alone free, K held."""
    scene, obs, metric = _scene(seed)
    held, held_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, THRESHOLD, model="fixed")
    options = ReconstructionOptions(intrinsics={"K": scene.K.tolist()}, radial_distortion="auto",
                                    threshold_px=THRESHOLD)
    kept, _, figures = pipeline._fixed_radial_test(held, obs, held_keep, options)
    free, free_keep, _ = upgrade.adjust(replace(held, k1=0.0), obs.view, obs.track, obs.pixel, THRESHOLD,
                                        model="fixed_radial")
    assert figures["estimated"] is False and kept is held and free.k1 == figures["k1_tested"]
    common = held_keep & free_keep
    assert figures["residual_dof"] == _dof(obs, common, 1)
    _check(figures["chi2"], held, free, obs, common, intrinsics=1)


@pytest.mark.parametrize("seed", SEEDS)
def test_the_per_view_focal_test_reads_the_noise_variance(monkeypatch, seed):
    """View 3 seen with a focal length 10% longer than the others' (its pixels scaled about the
    principal point): the screen sets it apart and the fit giving it its own focal length is tested
    against the per-view principal points' fit."""
    scene, _, metric = _scene(seed)
    centre = scene.K[:2, 2]
    tracks = [(views, np.where((np.asarray(views) == 3)[:, None], centre + 1.10 * (pixels - centre), pixels))
              for views, pixels in scene.tracks]
    obs = Observations.from_tracks(tracks, 10)
    held, held_keep, _ = upgrade.adjust(metric, obs.view, obs.track, obs.pixel, THRESHOLD, model="principal_per_view")
    fits = _recording(monkeypatch)
    _, _, figures = pipeline._focals_per_view(held, obs, held_keep, THRESHOLD)
    assert figures["views"] == [3] and figures["parameters_added"] == 1
    model, free, free_keep = fits[-1]
    assert model == "focal_groups"
    _check(figures["chi2"], held, free, obs, held_keep & free_keep, intrinsics=1 + 1 + 2 * 10)


def test_no_residual_degrees_of_freedom_make_no_test():
    """2 views of 10 points, a principal point per view free: 40 residuals, 40 parameters (12 for
    the poses, 30 for the points, 5 for the intrinsics, less the similarity's 7). The free fit's
    cost is then nothing but rounding: no statistic (main's divided it by 2 per observation less
    the parameters added, and kept whatever was freed)."""
    scene = synthetic.scene(views=2, points=10, seed=4, noise_px=SIGMA, spread_degrees=50.0)
    obs = Observations.from_tracks(scene.tracks, 2)
    metric = upgrade.Metric(scene.K.copy(), list(scene.rotations), list(scene.translations), scene.points.copy(),
                            [], False)
    common = np.ones(len(obs.view), dtype=bool)
    assert int(common.sum()) == 20
    statistic, dof = pipeline._saved_variances(metric, metric, obs, common, 1 + 2 * 2)
    assert dof == 0 and np.isnan(statistic)
    statistic, dof = pipeline._saved_variances(metric, metric, obs, common, 1)
    assert dof == 4 and statistic == 0.0

"""K unknown, a principal point off the image's centre: the registration's test frees it
(pipeline._registration_principal_point, bundle model "principal"), and the adjustment stage's
test (pipeline._principal_point) takes that fit as it is, not adjusted again, when it registers
the same views and tracks and explains the observations at least as well as the adjusted rig
with the principal point at the centre. The adjustment's starts are copies with the principal
point at the centre: the registration's fit keeps the K its test found."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.reconstruction import synthetic

VIEWS = 8
SHIFT = np.array([14.0, -9.0])  # the principal point, off the image's centre (every view the same)


@pytest.fixture(scope="module")
def solved():
    scene = synthetic.scene(views=VIEWS, points=200, seed=6, noise_px=0.3, spread_degrees=50.0)
    result = solve_job({"kind": "reconstruction", "options": {"principal_point": "auto"},
                        "data": {"views": [{"image_size": list(scene.image_size)}] * VIEWS,
                                 "tracks": [{"views": [int(v) for v in views], "points": (pixels + SHIFT).tolist()}
                                            for views, pixels in scene.tracks]}})
    return scene, result


def _stage(result: dict, name: str) -> dict:
    return next(stage for stage in result["stages"] if stage["name"] == name)


def test_the_adjustment_reuses_the_registrations_principal_point_fit(solved):
    scene, result = solved
    registration = _stage(result, "projective")["principal_point"]
    adjustment = _stage(result, "bundle_adjustment")["principal_point"]
    assert registration["estimated"] and adjustment["estimated"]
    # the same fit: its K to the last digit
    assert adjustment["K_free"] == registration["K_free"]
    assert np.abs(np.array(adjustment["K_free"])[:2, 2] - (scene.K[:2, 2] + SHIFT)).max() < 3.0
    assert result["summary"]["views_registered"] == VIEWS

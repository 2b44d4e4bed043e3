"""What a stratified autocalibration's intervals promise on real cameras (issue 37): 20 of the
Middlebury dino's 363 ground-truth cameras over a hemisphere (f = 3310 px), moved to a random
projective frame with 0.1 px of noise, autocalibrated with the defaults (the focal range widened
to hold the truth), 12 such subsets (seeds 10 to 21). Every modulus and DIAC residual is written in
the reference view's frame, so that view's noise is common to them all and invisible to a level
from the residuals' own variance: the estimate's spread over noise draws was twice what the
intervals stated, and 3 of 55 bounded metric intervals missed the truth, two of them in a
`determined` stage (seed 16: f = 3347 px, missed by 1.59 half-widths, u by 1.23). The metric
stage's intervals now hold the delete-one-view jackknife at the level's quantile
(determinacy.view_jackknife; docs/kinds.md has the measurement)."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import scenes
from tests.support import dino_hemisphere_cameras


@pytest.mark.slow
def test_every_bounded_metric_interval_holds_the_truth():
    views = dino_hemisphere_cameras()
    K = views.K[0] / views.K[0][2, 2]
    truth = {"focal_x": K[0, 0], "focal_y": K[1, 1], "skew": K[0, 1], "principal_u": K[0, 2], "principal_v": K[1, 2]}
    determined, bounded, missed = 0, 0, []
    for seed in range(10, 22):
        chosen = views.subset(np.random.default_rng(seed).choice(363, 20, replace=False))
        scene = scenes.from_cameras(chosen.cameras, chosen.box, 0.1, seed=seed, image_size=chosen.image_size)
        result = solve_job({"kind": "autocalibration", "data": scene.job_data(),
                            "options": {"time_limit_s": 10, "intrinsics": {"focal": [1000.0, 6000.0]}}})
        document = result["stages"][1]["determinacy"]
        determined += document["determined"]
        for found in document["intervals"]:
            if found["lower"] is None or found["upper"] is None:
                continue
            bounded += 1
            if not found["lower"] <= truth[found["name"]] <= found["upper"]:
                missed.append((seed, found["name"], document["determined"]))
    # intervals that still say something: bounded, and some stages narrow enough to be determined
    assert missed == [] and bounded >= 50 and determined >= 2, (missed, bounded, determined)

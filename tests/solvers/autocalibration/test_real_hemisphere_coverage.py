"""What a stratified autocalibration's `determined` promises on real cameras (issue 37): 20 of
the Middlebury dino's 363 ground-truth cameras over a hemisphere (f = 3310 px), moved to a random
projective frame with 0.1 px of noise, autocalibrated with the defaults (the focal range widened
to hold the truth). Of 12 such subsets (seeds 10 to 21) 10 metric stages are `determined`, and one
of them (seed 16: f = 3347 px) holds neither the true focal length nor the principal point's u
(missed by 1.59 and 1.23 of the intervals' half-widths, no warning); at 0.5 px the same subsets'
intervals miss by the same share of their widths (seed 11 too), so the shortfall scales with the
noise. The plane at infinity's family (the modulus cost walked to its level) gives most of the
focal interval's width there (22 px of 23), so it is that family's extent which falls short.
The cause, measured (docs/kinds.md): the reference view's noise is common to every modulus and
DIAC residual, moving the estimate without raising the cost, so a level from the residuals' own
variance misses it (the estimate's spread over noise draws is twice the stated one in f); a
delete-one-view jackknife measures it. Not fixed: a strict xfail, so that a fix shows."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers import datasets
from geocert.solvers.autocalibration import scenes

BENCH_DATA = Path(os.environ.get("GEOCERT_BENCH_DATA") or Path(__file__).resolve().parents[4] / "bench-data")


def hemisphere() -> datasets.CalibratedViews:
    folder = BENCH_DATA / "middlebury_dino_cameras"
    if not folder.exists():
        pytest.skip(f"{folder} is absent (the Middlebury dino's cameras: `python -m bench.fetch_photo_sets "
                    "--sets dinoCameras` fetches them; GEOCERT_BENCH_DATA names the folder)")
    return datasets.load_middlebury(folder)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="issue 37: seed 16's determined metric stage misses the true focal length "
                                       "(the reference view's noise, common to every residual, is not in the "
                                       "level: the plane family's extent falls short on real hemisphere subsets)")
def test_a_determined_metric_stage_holds_the_truth():
    views = hemisphere()
    K = views.K[0] / views.K[0][2, 2]
    truth = {"focal_x": K[0, 0], "focal_y": K[1, 1], "skew": K[0, 1], "principal_u": K[0, 2], "principal_v": K[1, 2]}
    determined, missed = 0, []
    for seed in range(10, 22):
        chosen = views.subset(np.random.default_rng(seed).choice(363, 20, replace=False))
        scene = scenes.from_cameras(chosen.cameras, chosen.box, 0.1, seed=seed, image_size=chosen.image_size)
        result = solve_job({"kind": "autocalibration", "data": scene.job_data(),
                            "options": {"time_limit_s": 10, "intrinsics": {"focal": [1000.0, 6000.0]}}})
        document = result["stages"][1]["determinacy"]
        if not document["determined"]:
            continue
        determined += 1
        missed += [(seed, i["name"]) for i in document["intervals"]
                   if not i["lower"] <= truth[i["name"]] <= i["upper"]]
    assert determined >= 8 and missed == [], (determined, missed)

"""A genuine run whose principal point lies outside the images' middle half, with camera_model
"full": the registration holds the principal point at the images' centre (its free fit lies
outside the middle half: pipeline._registration_principal_point), so the calibration certificate
is built in the centred model, while the full model's adjustment frees the principal point and
keeps every observation (the returned cameras 226 px^2 on the ~1,600 shared observations of the
8-view, 200-track synthetic scene, 0.3 px noise). The verifier holds the certificate to the
returned reconstruction re-adjusted in the centred model by least squares over all the shared
observations (calibration_tie._centred_reference, CENTRED_REFERENCE), and refuses it twice over:

- the pixel test: the registration's robust fit and the verifier's least-squares fit of a model
  the tracks do not fit lie up to 4.2 to 7.1 px apart (median 0.6), against 10 times the returned
  cameras' RMS error (3.8 to 3.9 px), though the centred model's own RMS error there is 1.6 to
  1.9 px;
- the fit test: the certificate costs 5,586 / 7,612 / 7,983 px^2 at shifts (0, +135) / (+161, 0)
  / (+165, 0), the centred model's least-squares reconstruction 4,217 / 5,682 / 5,925, and the
  allowance's room for the model's misfit is capped at the returned cameras' cost (226), where
  the certificate needs about 0.35 of the misfit.

With camera_model "simple" (tests/verify/test_forgeries_review29.py) the adjustment holds the
principal point at the centre too and drops the observations the centred model misfits (1,328
shared), so the certificate (1,148 px^2) stays within the room (1,231). Widening either test for
the centred reference widens what a certificate re-posed at another focal length may claim there;
not done without measuring that (xfail, strict: it passes once fixed)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.verify.checks import verify_any
from tests.support import stage as _stage
from tests.verify.test_forgeries_review18 import _scene_job


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="the centred reference's tie refuses a genuine full-model run (docstring)")
@pytest.mark.parametrize("shift", [(0.0, 135.0), (161.0, 0.0), (-200.0, 20.0)])
def test_a_genuine_full_model_run_held_at_the_centre_verifies(shift):
    result = solve_job(_scene_job({"camera_model": "full"}, points=200, shift=np.tile(shift, (8, 1))))
    record = _stage(result, "projective")["principal_point"]
    assert record["estimated"] is False and record["inside_middle_half"] is False
    report = verify_any(json.loads(json.dumps(result)))
    assert report.valid, report.first_failure

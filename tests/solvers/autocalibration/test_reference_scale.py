"""A homogeneous camera is the same camera at any scale, and the reference camera's scale used to
set the problem's frame (frames.UNIT_REFERENCE): the stored stratified scene with its reference
camera times 2^20 moved K by 0.34 px, times 2^24 the metric stage ended at its clock 250 px off,
times 2^28 it certified a K 4,250 px off, each a true certificate of a scale-dependent problem.
Today the reference is brought to unit scale first, and a proof states that form."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.autocalibration import frames
from geocert.solvers.autocalibration import problem as autocalibration_problem
from geocert.core.strict import Invalid
from geocert.verify.autocalibration import _stated_unit_frame
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored

# Powers of two give the very same numbers after the scaling; the others the same to rounding.
FACTORS = [2.0 ** 20, 2.0 ** 24, 2.0 ** 28, 1000.0, 1.0 / 3.0]


def _solve(name: str, factor: float = 1.0) -> dict:
    certificate = stored(name)["certificate"]
    data = dict(certificate["data"])
    cameras = np.asarray(data["cameras"], dtype=float)
    intrinsics = dict(certificate["options"]["intrinsics"] or {})
    reference = autocalibration_problem.prepare(cameras, None, data.get("image_size"), intrinsics).norm.reference
    cameras[reference] *= factor
    data["cameras"] = cameras.tolist()
    return solve_job({"kind": "autocalibration", "data": data, "options": certificate["options"]})


@pytest.fixture(scope="module")
def as_given() -> dict:
    return {name: _solve(name) for name in ("autocalibration_stratified", "autocalibration_direct")}


def _calibration(result: dict) -> np.ndarray:
    return np.asarray(result["K"] if result.get("K") is not None else result["Ks"], dtype=float)


@pytest.mark.parametrize("factor", FACTORS)
@pytest.mark.parametrize("name", ["autocalibration_stratified", "autocalibration_direct"])
def test_the_reference_camera_at_any_scale_poses_the_same_problem(as_given, name, factor):
    result = _solve(name, factor)
    assert [stage["status"] for stage in result["stages"]] == [stage["status"] for stage in as_given[name]["stages"]]
    assert np.allclose(_calibration(result), _calibration(as_given[name]), rtol=1e-7, atol=1e-6)
    assert verify_any(result).valid


def test_a_proof_states_its_frame_and_a_wrong_statement_is_refused(as_given):
    result = as_given["autocalibration_stratified"]
    proofs = [item["proof"] for item in result["certificate"]["items"]]
    assert all(proof[frames.REFERENCE_SCALE] == frames.UNIT_REFERENCE for proof in proofs)
    assert verify_any(result).valid
    forged = copy.deepcopy(result)
    forged["certificate"]["items"][1]["proof"][frames.REFERENCE_SCALE] = "as given"
    report = verify_any(forged)
    assert not report.valid and frames.REFERENCE_SCALE in str(report.first_failure)


def test_stages_posed_in_two_forms_of_frame_are_refused(as_given):
    """Each stage's answer is read in one frame: an affine proof of the earlier form beside a metric
    proof of today's is not one result."""
    forged = copy.deepcopy(as_given["autocalibration_stratified"])
    del forged["certificate"]["items"][0]["proof"][frames.REFERENCE_SCALE]
    assert not verify_any(forged).valid  # its affine stage no longer holds in the frame it now names
    with pytest.raises(Invalid, match="two forms of frame"):  # nor would the result be read in one frame
        _stated_unit_frame(forged["certificate"]["items"])


def test_earlier_proofs_are_read_in_the_frame_they_were_posed_in():
    """The stored documents were written with the reference as given: they verify there, and the
    report's scope says which items were read so."""
    for name in ("autocalibration_stratified", "autocalibration_direct"):
        document = stored(name)
        assert all(frames.REFERENCE_SCALE not in item["proof"] for item in document["certificate"]["items"])
        report = verify_any(document)
        assert report.valid
        assert report.scope["reference_scale_as_given"]["items"] == list(range(len(document["certificate"]["items"])))

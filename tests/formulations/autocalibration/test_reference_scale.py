"""A projective camera is homogeneous: the reference camera times s is the same input. The
stratified method's frame once moved with it (T0 built from the reference as given scales the
plane at infinity's coordinates by s), and on the stored stratified scene its reference times
2^20 moved K 0.34 px, times 2^24 left the metric stage 250 px off at its clock, and times 2^28
(entries about 0.75 * 2^28, inside the range frames.unit_scaled leaves as given) had a K 4,250 px
off certified and verified. The stratified method now builds its frame from the reference brought
to unit scale by a power of two (frames.unit_reference_scale), which its proofs state as
``reference_scale`` and the verifier recomputes from the data."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored

TRUTH = np.array([[1000.0, 0.0, 500.0], [0.0, 1000.0, 500.0], [0.0, 0.0, 1.0]])  # examples/generate.py's scene
POWERS = [2.0 ** 20, 2.0 ** 24, 2.0 ** 28]  # the very same frame: the same answer to its last digits
OTHERS = [1000.0, 1.0 / 3.0]  # a frame at most a factor 2 away: the same optimum, another path to it


def _data(factor: float = 1.0) -> tuple[dict, dict]:
    certificate = stored("autocalibration_stratified")["certificate"]
    data = copy.deepcopy(certificate["data"])
    cameras = np.asarray(data["cameras"], dtype=float)
    # the camera moved to [I | 0] (its conditioning, preconditioned, does not depend on its scale)
    reference = autocalibration_problem.prepare(cameras, None, tuple(data["image_size"]),
                                                dict(certificate["options"].get("intrinsics") or {})).norm.reference
    cameras[reference] *= factor
    data["cameras"] = cameras.tolist()
    return data, certificate["options"]


def _solve(factor: float = 1.0) -> dict:
    data, options = _data(factor)
    return solve_job({"kind": "autocalibration", "data": data, "options": options})


@pytest.fixture(scope="module")
def as_given() -> dict:
    return _solve()


def _checked(result: dict) -> np.ndarray:
    K = np.asarray(result["K"], dtype=float)
    assert np.abs(K - TRUTH).max() < 0.01  # 0.1% noise: the optimum is 2e-4 px from the truth
    assert [stage["status"] for stage in result["stages"]] == ["optimal", "optimal"]
    assert all(stage["certified"] for stage in result["stages"])
    assert verify_any(result).valid
    for stage in result["certificate"]["items"]:
        assert type(stage["proof"]["reference_scale"]) is float
    return K


def test_the_reference_as_given_is_solved_near_the_truth(as_given):
    _checked(as_given)


@pytest.mark.parametrize("factor", POWERS, ids=["2^20", "2^24", "2^28"])
def test_the_reference_times_a_power_of_two_gives_the_same_K(as_given, factor):
    assert np.abs(_checked(_solve(factor)) - np.asarray(as_given["K"])).max() < 1e-6


@pytest.mark.parametrize("factor", OTHERS, ids=["1000", "1/3"])
def test_the_reference_times_another_factor_gives_the_same_K(as_given, factor):
    assert np.abs(_checked(_solve(factor)) - np.asarray(as_given["K"])).max() < 1e-4  # measured 3e-6


@pytest.mark.parametrize("factor", POWERS + OTHERS)
def test_the_frame_is_the_unit_references(factor):
    """The reference brought to [0.5, 1) by a power of two before T0 is built: the same T0 for the
    camera times any power of two, and the stated scale the data's own."""
    data, options = _data(factor)
    problem = autocalibration_problem.prepare(np.asarray(data["cameras"]), np.asarray(data["points"]),
                                              tuple(data["image_size"]), dict(options.get("intrinsics") or {}))
    scale = problem.norm.reference_scale
    assert np.frexp(scale)[0] == 0.5  # a power of two
    reference = np.linalg.solve(problem.K0, frames.unit_scaled(np.asarray(data["cameras"]))[problem.norm.reference])
    assert 0.5 <= np.abs(reference * scale).max() < 1.0
    given, _ = _data()
    unscaled = autocalibration_problem.prepare(np.asarray(given["cameras"]), np.asarray(given["points"]),
                                               tuple(given["image_size"]), dict(options.get("intrinsics") or {}))
    if factor in POWERS:
        assert np.array_equal(problem.norm.T0, unscaled.norm.T0)


def test_a_stated_scale_other_than_the_datas_is_refused(as_given):
    """The verifier recomputes the scale and only compares: a document's number is never used."""
    for value in (as_given["certificate"]["items"][0]["proof"]["reference_scale"] * 2, 1.0, 5e-324, "1"):
        forged = copy.deepcopy(as_given)
        for item in forged["certificate"]["items"]:
            item["proof"]["reference_scale"] = value
        assert not verify_any(forged).valid


def test_one_stage_stating_the_scale_and_one_not_is_refused(as_given):
    forged = copy.deepcopy(as_given)
    del forged["certificate"]["items"][1]["proof"]["reference_scale"]
    assert not verify_any(forged).valid


def test_a_direct_proof_stating_a_scale_is_refused():
    result = stored("autocalibration_direct")
    assert verify_any(result).valid
    forged = copy.deepcopy(result)
    forged["certificate"]["items"][0]["proof"]["reference_scale"] = 1.0
    assert not verify_any(forged).valid


def test_a_stated_world_scale_fits_only_where_it_brings_the_datas_ratio_into_its_octave():
    """frames.world_scale_fits: the data's power of two, or its neighbour only where the ratio lies
    within WORLD_SCALE_TOLERANCE of the octave's edge; never a number that is not a power of two."""
    assert frames.WORLD_EXPONENT == -5  # the octave [2^-6, 2^-5)
    ratio = 3.0  # world_unit_scale: 2^-7 (3 / 128 = 0.0234 in [0.0156, 0.03125))
    assert frames.world_unit_scale(ratio) == 2.0 ** -7 and frames.world_scale_fits(2.0 ** -7, ratio)
    assert not any(frames.world_scale_fits(scale, ratio)
                   for scale in (2.0 ** -6, 2.0 ** -8, 0.3 * 2.0 ** -6, 0.0, -2.0 ** -7, np.inf, np.nan))
    edge = 4.0 * (1.0 - 1e-12)  # a hair below 4: 2^-8 takes it a hair below 2^-6, 2^-7 a hair below 2^-5
    assert frames.world_scale_fits(2.0 ** -7, edge) and frames.world_scale_fits(2.0 ** -8, edge)
    assert not frames.world_scale_fits(2.0 ** -6, edge)

"""Cameras and points are homogeneous: scaled by any factor they are the same data, and the
autocalibration kinds answer the same (frames.unit_scaled). At 2^-30 and 2^60 the stratified solve
failed, at 2^600 and 1e-310 it stopped at scipy's ValueError; the direct method's K overflowed to
NaN at 2^600 and its document was refused."""

from __future__ import annotations

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.formulations.autocalibration import frames
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored

FACTORS = [2.0 ** -30, 2.0 ** 60, 2.0 ** 600]  # powers of two: the very same data


def _solve(name: str, camera_factor: float = 1.0, point_factor: float = 1.0) -> dict:
    certificate = stored(name)["certificate"]
    data = dict(certificate["data"])
    data["cameras"] = (np.asarray(data["cameras"]) * camera_factor).tolist()
    if data.get("points") is not None:
        data["points"] = (np.asarray(data["points"]) * point_factor).tolist()
    return solve_job({"kind": "autocalibration", "data": data, "options": certificate["options"]})


@pytest.fixture(scope="module")
def as_given() -> dict:
    return {name: _solve(name) for name in ("autocalibration_stratified", "autocalibration_direct")}


def _calibration(result: dict) -> np.ndarray:
    return np.asarray(result["K"] if result.get("K") is not None else result["Ks"], dtype=float)


@pytest.mark.parametrize("name", ["autocalibration_stratified", "autocalibration_direct"])
@pytest.mark.parametrize("factor", FACTORS)
def test_cameras_at_any_scale_give_the_same_calibration(as_given, name, factor):
    result = _solve(name, factor)
    assert [stage["status"] for stage in result["stages"]] == [stage["status"] for stage in as_given[name]["stages"]]
    assert np.allclose(_calibration(result), _calibration(as_given[name]), rtol=1e-6, atol=1e-6)
    assert verify_any(result).valid


@pytest.mark.parametrize("name", ["autocalibration_stratified", "autocalibration_direct"])
def test_subnormal_cameras_are_solved_and_verify(as_given, name):
    """Times 1e-310 the entries are subnormal and keep 24 to 44 of their bits: other data, close to
    the given, and the same answer within what those bits move (the direct method's flat cost moves
    its Ks by 3e-4 of themselves)."""
    result = _solve(name, 1e-310)
    assert [stage["status"] for stage in result["stages"]] == [stage["status"] for stage in as_given[name]["stages"]]
    assert np.allclose(_calibration(result), _calibration(as_given[name]), rtol=1e-2, atol=1e-3)
    assert verify_any(result).valid


def test_points_at_extreme_scales_give_the_same_calibration(as_given):
    result = _solve("autocalibration_stratified", 2.0 ** 60, 2.0 ** -700)
    assert [stage["status"] for stage in result["stages"]] == ["optimal", "optimal"]
    assert np.allclose(_calibration(result), _calibration(as_given["autocalibration_stratified"]), rtol=1e-6)
    assert verify_any(result).valid


def test_unit_scaled_is_exact_and_leaves_ordinary_scales_alone():
    rng = np.random.default_rng(0)
    cameras = rng.normal(size=(4, 3, 4))
    cameras[1] *= 1e6  # pixel cameras: as given
    cameras[2] *= 2.0 ** 300
    cameras[3] *= 2.0 ** -40
    scaled = frames.unit_scaled(cameras)
    assert np.array_equal(scaled[:2], cameras[:2])
    for k in (2, 3):
        ratio = scaled[k] / cameras[k]
        assert np.all(ratio == ratio.flat[0]) and np.frexp(ratio.flat[0])[0] == 0.5  # one power of two
        assert 0.5 <= np.abs(scaled[k]).max() < 1.0

"""A resection or a triangulation in any world unit, from 1e-300 m up to what the inputs take, has
the certified answer of the same data in metres, scaled (issue 33's open item): the solvers work
in normalised units and map back. Review 58's resection, its source times 1e-162, came back
not_certified with an all-zero camera and inf residuals, and times 1e-300 with a camera costing
2.2e5 where 15 is the optimum; a triangulation in a unit of 1e-162 m failed in its DLT's SVD. The
causes: lengths whose squares underflow (charts.normaliser's spread, the camera frame's spread,
the framed cameras' rows) and a camera's norm whose squares overflow (maps.unit_frobenius).

Larger units are refused by the inputs' own limits (a source coordinate above
geometry.COORDINATE_LIMIT, a camera whose translation column dwarfs the rest as rank-deficient):
1e8 is the largest tried here."""

from __future__ import annotations

import json

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.verify.checks import verify_any
from tests.support import seed, triangulation_job

pytestmark = pytest.mark.filterwarnings("ignore")

UNITS = [1e-300, 1e-162, 1e-20, 1.0, 1e8]


def _verified(result: dict) -> bool:
    return verify_any(json.loads(json.dumps(result, allow_nan=False))).valid


@pytest.fixture(scope="module")
def resection() -> dict:
    """Review 58's resection job (tests/verify/test_forgeries_review58.py), its second camera."""
    from tests.formulations.fractional.test_resection_proven import resection_job

    rng = np.random.default_rng(seed("resection proven", "forged"))
    job, _ = resection_job(rng, 12, 1.0, maps=2)
    job["data"]["maps"] = job["data"]["maps"][1:]
    return job


def _source_in(job: dict, unit: float) -> dict:
    job = json.loads(json.dumps(job))
    for entry in job["data"]["maps"]:
        entry["source"] = (np.array(entry["source"]) * unit).tolist()
    return job


@pytest.mark.parametrize("unit", UNITS)
def test_a_source_in_any_world_unit_is_the_metre_answer_scaled(resection, unit):
    metres = solve_job(resection)["maps"][0]
    result = solve_job(_source_in(resection, unit))
    found = result["maps"][0]
    assert metres["certified"] and found["certified"] and found["status"] == "optimal"
    assert found["cost"] == pytest.approx(metres["cost"], rel=1e-9)
    assert found["lower_bound"] <= found["cost"]
    M, M0 = np.array(found["matrix"]), np.array(metres["matrix"])
    centre, centre0 = -np.linalg.solve(M[:, :3], M[:, 3]), -np.linalg.solve(M0[:, :3], M0[:, 3])
    assert np.allclose(centre / unit, centre0, rtol=1e-9, atol=1e-9 * np.abs(centre0).max())
    assert np.all(np.isfinite(found["residuals"]))
    assert _verified(result)


@pytest.fixture(scope="module")
def tracks() -> dict:
    rng = np.random.default_rng(seed("finite62", "tri"))
    return triangulation_job(rng, 4, 3, "L2L2")


def _tracks_in(job: dict, unit: float, norm: str) -> dict:
    """The same scene with its world coordinates times ``unit``: the cameras' translation columns
    times ``unit`` see the point ``unit`` X where the originals saw X."""
    job = json.loads(json.dumps(job))
    cameras = np.array(job["data"]["cameras"])
    cameras[:, :, 3] *= unit
    job["data"]["cameras"] = cameras.tolist()
    job["options"]["norm"] = norm
    return job


@pytest.mark.parametrize("norm", ["L2L2", "L1L1"])
@pytest.mark.parametrize("unit", UNITS)
def test_a_triangulation_in_any_world_unit_is_the_metre_answer_scaled(tracks, unit, norm):
    metres = solve_job(_tracks_in(tracks, 1.0, norm))["tracks"]
    result = solve_job(_tracks_in(tracks, unit, norm))
    for found, at_metres in zip(result["tracks"], metres):
        assert at_metres["certified"] and found["certified"] and found["status"] == "optimal"
        assert found["cost"] == pytest.approx(at_metres["cost"], rel=1e-9)
        X, X0 = np.array(found["point"]), np.array(at_metres["point"])
        # local refinements stop within their own tolerances: 1e-9 of the point's size apart
        assert np.abs(X / unit - X0).max() <= 1e-7 * np.abs(X0).max()
    assert _verified(result)


def test_a_resection_whose_camera_the_floats_cannot_hold_is_not_certified_with_its_reason(resection):
    """Source coordinates near the smallest normal float (x1e-307: some are subnormal): the camera
    in those units would span more than the floats do. The item says so (no matrix, a reason);
    the solver's residuals once raised a ValueError on its NaN entries."""
    from geocert.solvers.fractional.maps import UNREPRESENTABLE

    result = solve_job(_source_in(resection, 1e-307))
    found = result["maps"][0]
    assert (found["status"], found["certified"], found["matrix"], found["reason"]) == (
        "not_certified", False, None, UNREPRESENTABLE)
    json.dumps(result, allow_nan=False)
    from geocert.jobs.runner import result_json
    from geocert.kinds import get_kind

    assert result_json(get_kind("resection"), result) is not None  # the schema takes it as it is


@pytest.mark.parametrize("kind", ["homography2", "homography3"])
@pytest.mark.parametrize("unit", UNITS)
def test_a_homography_from_any_source_unit_is_the_metre_answer_scaled(kind, unit):
    """The same for homographies (their source times ``unit``): at 1e-162 both dimensions wrote
    inf, at 1e-300 they returned wrong uncertified maps (costs 3e5 where 17 is the optimum)."""
    from geocert.core.geometry import unit_frobenius
    from tests.support import map_job

    job = map_job(np.random.default_rng(seed("finite62", kind, "L2L2")), kind, 12, "L2L2", maps=2)
    metres = solve_job(job)["maps"]
    result = solve_job(_source_in(job, unit))
    for found, at_metres in zip(result["maps"], metres):
        assert (found["status"], found["certified"]) == (at_metres["status"], at_metres["certified"])
        assert found["cost"] == pytest.approx(at_metres["cost"], rel=1e-9)
        n = len(found["matrix"][0]) - 1
        H = unit_frobenius(np.array(found["matrix"]) @ np.diag([unit] * n + [1.0]))
        H0 = np.array(at_metres["matrix"])
        assert np.abs(H * np.sign(np.sum(H * H0)) - H0).max() <= 1e-9
    assert any(m["certified"] for m in metres) and _verified(result)

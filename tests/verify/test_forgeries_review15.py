"""A fifteenth hostile review of the verifier (issue 33). DOCSTRING-PLACEHOLDER"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.core.geometry import norm_cost
from geocert.verify.checks import verify_any

from tests.support import map_job, seed, triangulation_job


def _verifies(result: dict) -> None:
    report = verify_any(result)
    assert report.valid, report.first_failure


def _refused(result: dict) -> dict:
    report = verify_any(result)
    assert not report.valid
    return report.first_failure


# --- a search's root region stated for every point of the scope ---------------------------------

@pytest.fixture(scope="module")
def searched_track() -> dict:
    """A triangulation job under L1L1 (every track searched), solved genuinely."""
    result = solve_job(triangulation_job(np.random.default_rng(seed("review15", "root region")), 2, 4, "L1L1"))
    _verifies(result)
    assert all(track["certified"] and track["certificate"]["root_region"] is not None for track in result["tracks"])
    return result


@pytest.fixture(scope="module")
def searched_map() -> dict:
    """A homography job under L2L2 (a search, not the resection's sublevel bound), solved genuinely."""
    result = solve_job(map_job(np.random.default_rng(seed("review15", "map root region")), "homography2", 12, "L2L2",
                               maps=1))
    _verifies(result)
    assert result["maps"][0]["certified"] and result["maps"][0]["certificate"]["root_region"] is not None
    return result


def _scope_point_outside(result: dict, index: int, rng) -> tuple[np.ndarray, float]:
    """A point in front of every camera of track ``index`` outside its stated root region, and
    its cost."""
    data = result["certificate"]["data"]
    track = data["tracks"][index]
    cameras = np.asarray(data["cameras"], dtype=float)[track["views"]]
    observed = np.asarray(track["points"], dtype=float)
    region = result["tracks"][index]["certificate"]["root_region"]
    F, d = np.asarray(region["functionals"]), np.asarray(region["denominator"])
    lower, upper = np.asarray(region["lower"]), np.asarray(region["upper"])
    X0 = np.append(result["tracks"][index]["point"], 1.0)
    for spread in (0.01, 0.1, 0.3, 1.0):
        for _ in range(400):
            X = X0.copy()
            X[:3] += rng.normal(size=3) * spread
            projected = cameras @ X
            if not np.all(projected[:, 2] > 0) or d @ X <= 0:
                continue
            ratio = F @ X / (d @ X)
            if np.any(ratio < lower) or np.any(ratio > upper):
                cost = norm_cost(projected[:, :2] / projected[:, 2:3] - observed,
                                 result["certificate"]["options"]["norm"])
                return X, cost
    raise AssertionError("no point of the scope found outside the root region")


class TestRootRegionStatedForTheWholeScope:
    """A certified search's summary ``root_region`` said "lower <= (F X) / (d . X) <= upper for
    every point X of the scope" (a map's: "for the last row l of every map in the scope"). The
    proof's root box holds only the points that could beat the bound (every residual within the
    gamma the claimed lower bound allows, then tightened at caps at least that bound): a point in
    front of every camera a tenth of a unit from the returned one already lies outside it. Every
    verified genuine search result stated that falsehood (the verifier reads ``meaning`` as
    informational text; review 9 tied a map's numbers to its proof, not the words). Fixed in the
    writer (kinds.triangulation.track_document, kinds.resection_homography.map_document): the
    words now say for which points the box holds. The box's numbers are unchanged, and a stored
    certificate with the old words still verifies (the words are not checked)."""

    def test_a_point_of_the_scope_outside_the_region_costs_at_least_the_bound(self, searched_track):
        rng = np.random.default_rng(seed("review15", "outside"))
        for index, track in enumerate(searched_track["tracks"]):
            _, cost = _scope_point_outside(searched_track, index, rng)
            assert cost >= track["lower_bound"] * (1 - 1e-9)

    def test_the_tracks_region_says_for_which_points_it_holds(self, searched_track):
        rng = np.random.default_rng(seed("review15", "outside", "words"))
        for index, track in enumerate(searched_track["tracks"]):
            _scope_point_outside(searched_track, index, rng)  # the region is not the whole scope's
            meaning = track["certificate"]["root_region"]["meaning"]
            assert "every point X of the scope," not in meaning
            assert "costing less than" in meaning and "lower_bound" in meaning

    def test_the_maps_region_says_for_which_maps_it_holds(self, searched_map):
        meaning = searched_map["maps"][0]["certificate"]["root_region"]["meaning"]
        assert "every map in the scope," not in meaning
        assert "costing less than" in meaning and "lower_bound" in meaning

    def test_a_map_of_the_scope_lies_outside_the_region(self, searched_map):
        """The map's region is not the scope's: a map with every point in front of it (the
        returned map with its last row moved) is outside it."""
        data = searched_map["certificate"]["data"]["maps"][0]
        source = np.asarray(data["source"], dtype=float)
        region = searched_map["maps"][0]["certificate"]["root_region"]
        F, d = np.asarray(region["functionals"]), np.asarray(region["denominator"])
        lower, upper = np.asarray(region["lower"]), np.asarray(region["upper"])
        last = np.asarray(searched_map["maps"][0]["matrix"], dtype=float)[-1]
        homogeneous = np.hstack([source, np.ones((len(source), 1))])
        rng = np.random.default_rng(seed("review15", "map outside"))
        found = False
        for _ in range(2000):
            moved = last + rng.normal(size=last.shape) * 0.3 * np.abs(last).max()
            if np.all(homogeneous @ moved > 0) and d @ moved > 0:
                ratio = F @ moved / (d @ moved)
                if np.any(ratio < lower) or np.any(ratio > upper):
                    found = True
                    break
        assert found


# --- a direct proof's programs no check reads ---------------------------------------------------

def _stored(name: str) -> dict:
    import json
    from pathlib import Path

    return json.loads((Path(__file__).resolve().parents[1] / "data" / "certificates" / f"{name}.json").read_text())


def _rehash(document: dict) -> None:
    from geocert.kinds import get_kind
    from geocert.solvers.core.certificates import data_hash, problem_hash

    names = getattr(get_kind(document["kind"]).verification, "claim_options", None)
    document["data_sha256"] = data_hash(document["kind"], document["data"])
    document["problem_sha256"] = problem_hash(document["kind"], document["data"], document["options"], names)


class TestDirectProgramsUnread:
    """A direct_moment proof's ``programs`` were read only where their delta matched an
    orientation the verifier bounds: a program of an excluded orientation, or of a delta no
    orientation has ("x", 7.0), verified with any ``z`` (a list, an int, text that is no base64),
    any ``cuts`` ("bad") and any ``bound`` (1e300), though docs/certificate.md says a proof record
    has the fields it lists, each unread field null or of its type, and every dual vector base64
    of finite float64. (A boolean delta true was also read as the orientation +1.) Fixed in
    direct.check_proof: every program is one of an orientation left to bound, its delta a number
    (null for "centers" and "none"), and is read there."""

    @pytest.mark.parametrize("extra", [
        {"delta": 7.0, "z": "not base64 at all!!", "bound": 1.0},
        {"delta": "x", "z": [1, 2], "bound": 1e300, "cuts": "bad"},
    ])
    def test_a_program_of_no_orientation_is_refused(self, extra):
        result = _stored("autocalibration_direct")
        _verifies(result)
        result["certificate"]["items"][0]["proof"]["programs"].append(extra)
        _rehash(result["certificate"])
        assert _refused(result)["check"] == "format"

    def test_a_program_of_an_excluded_orientation_is_refused(self):
        result = _stored("autocalibration_direct_points")
        _verifies(result)
        proof = result["certificate"]["items"][0]["proof"]
        assert [item["delta"] for item in proof["excluded"]] == [-1.0]
        proof["programs"].append({"delta": -1.0, "z": "garbage", "bound": 2.0})
        _rehash(result["certificate"])
        assert _refused(result)["check"] == "format"

    def test_a_boolean_delta_is_refused_and_an_integer_one_read(self):
        result = _stored("autocalibration_direct_points")
        forged = copy.deepcopy(result)
        forged["certificate"]["items"][0]["proof"]["programs"][0]["delta"] = True
        _rehash(forged["certificate"])
        assert _refused(forged)["check"] == "format"
        result["certificate"]["items"][0]["proof"]["programs"][0]["delta"] = 1
        _rehash(result["certificate"])
        _verifies(result)

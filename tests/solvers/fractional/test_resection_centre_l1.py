"""Proven intervals of an L1 resection's camera centre (fractional.resection_centre_l1), stated
beside the depth row its leaves prove (proof.sublevel.centre) at the same level: every camera of
the scope costing at most the returned camera's cost plus cost_increase has its centre in them.
Checked against the truth of synthetic scenes, against cameras a local search finds within the
level, and by the verifier, which recomputes them from the stated radius, rounds and multipliers
and refuses a narrower interval (and multipliers outside the dual norm's unit ball, which would
prove a bound the set does not hold)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job

from tests.solvers.fractional.test_resection_leaves import costs_at, local_search, resection
from tests.support import forged_sublevel, refusal, seed

NORMS = ("L1L1", "L2L1")
CENTRE = ["centre_x", "centre_y", "centre_z"]


def centre_of(cameras: np.ndarray) -> np.ndarray:
    """The centres (s, 3) of cameras (s, 3, 4)."""
    null = np.linalg.svd(cameras)[2][:, -1]
    return null[:, :3] / null[:, 3:]


def centre_intervals(document) -> np.ndarray:
    found = [i for i in document["proven_intervals"]["intervals"] if i["name"].startswith("centre_")]
    assert [i["name"] for i in found] == CENTRE
    return np.array([[i["lower"], i["upper"]] for i in found])


@pytest.mark.parametrize("norm", NORMS)
def test_a_genuine_l1_resection_proves_its_centre_and_verifies(norm):
    """A 20-point camera with 0.5 px of noise, certificate full: the verifier passes its proven
    interval (depth row and centre), the result says proven with the centre's intervals, and they
    hold the true centre. (On the code before, the result states the depth row alone.)"""
    rng = np.random.default_rng(seed("resection centre l1", norm))
    job, (truth,) = resection(rng, 20, norm, noise=0.5)
    result = solve_job(job)
    item = result["maps"][0]
    assert item["certified"] and item["determinacy"]["proven"] is True
    assert "centre" in result["certificate"]["items"][0]["proof"]["sublevel"]
    intervals = centre_intervals(item["determinacy"])
    true_centre = centre_of(truth[None])[0]
    assert np.all(intervals[:, 0] <= true_centre) and np.all(true_centre <= intervals[:, 1])
    assert refusal(result) is None


@pytest.mark.parametrize("norm", NORMS)
def test_every_camera_a_local_search_finds_within_the_increase_has_its_centre_inside(norm):
    """Cameras costing at most cost + cost_increase (tests/.../test_resection_leaves.local_search:
    along rays of depth rows, the cheapest first two rows) have their centres in the intervals."""
    rng = np.random.default_rng(seed("resection centre l1", "search", norm))
    job, _ = resection(rng, 16, norm, noise=1.0)
    result = solve_job(job)
    item = result["maps"][0]
    intervals = centre_intervals(item["determinacy"])
    source, target = (np.array(job["data"]["maps"][0][key]) for key in ("source", "target"))
    reference = result["certificate"]["items"][0]["proof"]["sublevel"]["reference"]
    level = item["cost"] + item["determinacy"]["proven_intervals"]["cost_increase"]
    cameras = local_search(rng, source, target, np.array(item["matrix"]), norm, level, reference)
    assert len(cameras) >= 20 and np.all(costs_at(source, target, cameras, norm) <= level)
    centres = centre_of(cameras)
    assert np.all(intervals[:, 0] <= centres) and np.all(centres <= intervals[:, 1])


def test_the_true_centre_lies_in_the_intervals():
    """8 synthetic cameras (12 to 40 points, 0.5 px), the two norms in turn: every camera proves a
    centre interval, and each holds the true centre (measured: 8 of 8 here; 40 of 40 on the 20
    seeds of bench.determinacy --resection-l1-synthetic, docs/benchmarks.md)."""
    rng = np.random.default_rng(seed("resection centre l1", "truth"))
    covered = 0
    for k in range(8):
        job, (truth,) = resection(rng, int(rng.integers(12, 41)), NORMS[k % 2], noise=0.5)
        item = solve_job(job)["maps"][0]
        intervals = centre_intervals(item["determinacy"])
        true_centre = centre_of(truth[None])[0]
        covered += bool(np.all(intervals[:, 0] <= true_centre) and np.all(true_centre <= intervals[:, 1]))
    assert covered == 8


@pytest.fixture(scope="module")
def proven() -> dict:
    """A full result of two certified L2L1 cameras, each with a proven centre."""
    rng = np.random.default_rng(seed("resection centre l1", "forged"))
    job, _ = resection(rng, 20, "L2L1", noise=0.5, maps=2)
    result = solve_job(job)
    assert all("centre" in item["proof"]["sublevel"] for item in result["certificate"]["items"])
    assert refusal(result) is None
    return result


def _centre(result: dict, **changes) -> dict:
    centre = copy.deepcopy(result["certificate"]["items"][1]["proof"]["sublevel"]["centre"])
    centre.update(changes)
    return centre


class TestForgedCentre:
    @pytest.mark.parametrize("coordinate", [0, 1, 2])
    @pytest.mark.parametrize("end,change", [(0, 1e-3), (1, -1e-3), (0, 0.3), (1, -0.3)])
    def test_a_narrowed_interval_is_refused(self, proven, coordinate, end, change):
        """(On the code before, the certificate's sublevel has no centre: it is refused as an
        unknown member, a format refusal, not this one.)"""
        intervals = _centre(proven)["intervals"]
        intervals[coordinate][end] += change * (intervals[coordinate][1] - intervals[coordinate][0])
        first = refusal(forged_sublevel(proven, centre=_centre(proven, intervals=intervals)))
        assert first["check"] == "proven_interval" and first["item"] == 1 and "narrower" in first["detail"]

    def test_a_wider_interval_is_a_weaker_truth_and_passes(self, proven):
        intervals = _centre(proven)["intervals"]
        intervals[2][1] += 1.0
        assert refusal(forged_sublevel(proven, centre=_centre(proven, intervals=intervals))) is None

    def test_multipliers_outside_the_unit_ball_are_not_read(self, proven):
        """y scaled by 1.5 would bound l . theta by less than the set reaches; the checker ignores
        them (the ball's bound instead), so the stated intervals are then narrower than proven."""
        duals = _centre(proven)["duals"]
        for pair in duals:
            for side in pair:
                if side is not None:
                    side["y"] = (np.array(side["y"]) * 1.5).tolist()
        first = refusal(forged_sublevel(proven, centre=_centre(proven, duals=duals)))
        assert first["check"] == "proven_interval" and "narrower" in first["detail"]

    def test_a_result_stating_a_narrower_centre_than_its_certificate_is_refused(self, proven):
        result = copy.deepcopy(proven)
        entry = next(i for i in result["maps"][1]["determinacy"]["proven_intervals"]["intervals"]
                     if i["name"] == "centre_x")
        entry["lower"] += 0.25 * (entry["upper"] - entry["lower"])
        first = refusal(result)
        assert first["check"] == "returned" and "proven_intervals" in first["detail"]

    def test_a_smaller_radius_is_refused(self, proven):
        centre = _centre(proven)
        first = refusal(forged_sublevel(proven, centre=_centre(proven, radius=centre["radius"] * 0.5)))
        assert first["check"] == "proven_interval" and "radius" in first["detail"]

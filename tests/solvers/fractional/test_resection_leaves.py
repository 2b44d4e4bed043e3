"""Proven intervals of an L1 resection's depth row (fractional.resection_leaves), read off the
leaves of a search at the stated level: every camera of the scope costing at most the returned
camera's cost plus cost_increase has its depth row (last row over the reference point's depth) in
them. Checked against cameras a dense local search finds within the level, against the truth of
synthetic scenes with known noise, and by the verifier, which recomputes them from the leaves it
checks and refuses a narrower interval, a level its proofs do not hold at, and a result saying
proven without the leaves."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy.optimize import linprog

from geocert.jobs.runner import solve_job
from geocert.verify.checks import verify_any

from tests.support import scene, seed, forged_sublevel, refusal

NORMS = ("L1L1", "L2L1")


def costs_at(source, target, cameras, norm):
    """The costs of cameras (s, 3, 4) under ``norm``; inf outside the scope (a depth <= 0)."""
    proj = np.einsum("sij,kj->ski", cameras, np.hstack([source, np.ones((len(source), 1))]))
    r = proj[..., :2] / proj[..., 2:3] - target
    cost = np.abs(r).sum(axis=(1, 2)) if norm == "L1L1" else np.sqrt((r * r).sum(axis=2)).sum(axis=1)
    return np.where(np.all(proj[..., 2] > 0, axis=1), cost, np.inf)


def depth_rows(cameras, source, reference):
    last = cameras[:, 2]
    return last / (last @ np.append(source[reference], 1.0))[:, None]


def solved(rng, count, norm, noise=1.0):
    job, _ = resection(rng, count, norm, noise)
    return job, solve_job(job)


def intervals_of(document):
    found = document["proven_intervals"]["intervals"][:4]  # then the centre's (test_resection_centre_l1.py)
    assert [i["name"] for i in found] == ["depth_x", "depth_y", "depth_z", "depth_0"]
    return np.array([i["lower"] for i in found]), np.array([i["upper"] for i in found])


def cheapest_rows(source, target, row):
    """The camera of depth row ``row`` whose first two rows cost least under L1L1 (a linear
    program: with the depths fixed each residual is linear in those rows); None where a depth is
    not positive. Its L2L1 cost is at most its L1L1 one, so it serves both norms' searches."""
    Xh = np.hstack([source, np.ones((len(source), 1))])
    depth = Xh @ row
    if np.any(depth <= 0):
        return None
    k = len(source)
    A = np.zeros((2 * k, 8))
    A[0::2, :4] = Xh / depth[:, None]
    A[1::2, 4:] = Xh / depth[:, None]
    eye = np.eye(2 * k)
    found = linprog(np.concatenate([np.zeros(8), np.ones(2 * k)]), A_ub=np.block([[A, -eye], [-A, -eye]]),
                    b_ub=np.concatenate([target.ravel(), -target.ravel()]),
                    bounds=[(None, None)] * 8 + [(0, None)] * (2 * k), method="highs")
    return np.vstack([found.x[:4], found.x[4:8], row])[None] if found.status == 0 else None


def local_search(rng, source, target, P, norm, level, reference):
    """Cameras costing at most ``level`` found about P: along rays of depth rows from P's (each
    entry's direction of steepest growth, both signs, and 16 random ones, in the rows whose
    reference depth is 1), the farthest row bisection finds whose cheapest camera (cheapest_rows)
    costs at most the level, with that camera."""
    start = depth_rows(P[None], source, reference)[0]
    basis = np.linalg.svd(np.append(source[reference], 1.0)[None])[2][1:].T  # rows of reference depth 1
    directions = [sign * basis @ basis[e] for e in range(4) for sign in (1.0, -1.0)]
    directions += [basis @ u for u in rng.normal(size=(16, 3))]
    found = []

    def within(t, u):
        camera = cheapest_rows(source, target, start + t * u)
        return camera is not None and costs_at(source, target, camera, norm)[0] <= level, camera

    for u in directions:
        u = u / np.linalg.norm(u)
        inside, outside = 0.0, 1e-3
        while within(outside, u)[0] and outside < 1e3:
            inside, outside = outside, 2 * outside
        for _ in range(20):
            middle = 0.5 * (inside + outside)
            inside, outside = (middle, outside) if within(middle, u)[0] else (inside, middle)
        ok, camera = within(inside, u)
        if ok:
            found.append(camera)
    return np.concatenate(found)


@pytest.mark.parametrize("norm", NORMS)
@pytest.mark.parametrize("count", [12, 40])
def test_every_camera_a_local_search_finds_within_the_increase_is_inside(norm, count):
    """Every camera found costing at most cost + cost_increase has its depth row in the proven
    intervals, and the cameras found span at least 40% of each interval (a narrowed interval would
    miss some; they are not vacuously wide either: 54% to 70% measured with random rays alone)."""
    rng = np.random.default_rng(seed("resection leaves", norm, str(count)))
    job, result = solved(rng, count, norm)
    item = result["maps"][0]
    document = item["determinacy"]
    assert item["certified"] and document["proven"] is True
    lower, upper = intervals_of(document)
    source, target = (np.array(job["data"]["maps"][0][key]) for key in ("source", "target"))
    P = np.array(item["matrix"])
    reference = result["certificate"]["items"][0]["proof"]["sublevel"]["reference"]
    level = item["cost"] + document["proven_intervals"]["cost_increase"]
    cameras = local_search(rng, source, target, P, norm, level, reference)
    assert len(cameras) >= 20
    assert np.all(costs_at(source, target, cameras, norm) <= level)
    rows = depth_rows(cameras, source, reference)
    assert np.all(lower <= rows) and np.all(rows <= upper)
    reached = rows.max(axis=0) - rows.min(axis=0)
    assert np.all(reached > 0.4 * (upper - lower)), (reached, upper - lower)


def resection(rng, count: int, norm: str, noise: float = 1.0, maps: int = 1, **options) -> tuple[dict, list]:
    """A resection job of ``maps`` cameras looking at ``count`` points with Gaussian pixel noise
    (tests.support.scene), and the true cameras."""
    entries, truths = [], []
    for _ in range(maps):
        M, source, target = scene(rng, "resection", count)
        entries.append({"source": source.tolist(), "target": (target + rng.normal(size=target.shape) * noise).tolist()})
        truths.append(M)
    return {"kind": "resection", "data": {"maps": entries},
            "options": {"norm": norm, "certificate": "full", "detail": "full", **options}}, truths


def test_the_true_camera_lies_in_the_intervals():
    """16 synthetic cameras (12 to 40 points, 1 px noise), the two norms in turn: the true camera's
    depth row lies in the intervals proven at the noise level (l1_cost_increase), every entry
    (measured: 64 of 64 entries here; 96 of 96 on 24 cameras of 12 to 60 points, searched with 120
    boxes)."""
    rng = np.random.default_rng(seed("resection leaves", "truth"))
    covered = total = 0
    for k in range(16):
        job, (truth,) = resection(rng, int(rng.integers(12, 41)), NORMS[k % 2])
        result = solve_job(job)
        item = result["maps"][0]
        assert item["certified"] and item["determinacy"]["proven"] is True
        lower, upper = intervals_of(item["determinacy"])
        source = np.array(job["data"]["maps"][0]["source"])
        reference = result["certificate"]["items"][0]["proof"]["sublevel"]["reference"]
        row = depth_rows(truth[None], source, reference)[0]
        covered += int(np.sum((lower <= row) & (row <= upper)))
        total += 4
    assert covered == total


@pytest.fixture(scope="module")
def proven() -> dict:
    """A full result of two certified L1L1 cameras, each with proven intervals."""
    rng = np.random.default_rng(seed("resection leaves", "forged"))
    job, _ = resection(rng, 20, "L1L1", maps=2)
    result = solve_job(job)
    assert all("sublevel" in item["proof"] for item in result["certificate"]["items"])
    report = verify_any(result)
    assert report.valid and {"name": "proven_interval", "passed": 2, "failed": 0} in report.checks
    return result


class TestForgedIntervals:
    @pytest.mark.parametrize("entry", [0, 1, 2, 3])
    @pytest.mark.parametrize("end,change", [(0, 1e-3), (1, -1e-3), (0, 0.5), (1, -0.5)])
    def test_a_narrowed_interval_is_refused(self, proven, entry, end, change):
        intervals = copy.deepcopy(proven["certificate"]["items"][1]["proof"]["sublevel"]["intervals"])
        width = intervals[entry][1] - intervals[entry][0]
        intervals[entry][end] += change * width
        first = refusal(forged_sublevel(proven, intervals=intervals))
        assert first["check"] == "proven_interval" and first["item"] == 1 and "narrower" in first["detail"]

    def test_a_wider_interval_is_a_weaker_truth_and_passes(self, proven):
        intervals = copy.deepcopy(proven["certificate"]["items"][1]["proof"]["sublevel"]["intervals"])
        intervals[0][0] -= 1.0
        assert refusal(forged_sublevel(proven, intervals=intervals)) is None

    def test_a_higher_level_than_the_leaves_were_proven_at_is_refused(self, proven):
        """Its parts (root region, tightening, leaves) hold for the cameras costing at most the
        level the solver searched at: a higher one asks more than they prove."""
        increase = proven["certificate"]["items"][1]["proof"]["sublevel"]["cost_increase"] * 2
        first = refusal(forged_sublevel(proven, cost_increase=increase))
        assert first["check"] in ("root_region", "tightening", "leaf_bounds")

    def test_a_result_saying_proven_at_a_level_below_its_own_is_refused(self, proven):
        """The certificate holds true at a lower level (the same leaves prove it), but the result
        states its intervals below the map's own level (l1_cost_increase)."""
        result = copy.deepcopy(proven)
        sublevel = result["certificate"]["items"][1]["proof"]["sublevel"]
        sublevel["cost_increase"] *= 0.5
        assert refusal(result["certificate"]) is None
        result["maps"][1]["determinacy"]["proven_intervals"]["cost_increase"] = sublevel["cost_increase"]
        first = refusal(result)
        assert first["check"] == "returned" and "below" in first["detail"]

    def test_a_dropped_leaf_is_refused(self, proven):
        search = copy.deepcopy(proven["certificate"]["items"][1]["proof"]["sublevel"]["search"])
        search["leaves"] = search["leaves"][1:]
        assert refusal(forged_sublevel(proven, search=search))["check"] == "coverage"

    def test_a_leaf_claiming_a_higher_bound_is_refused(self, proven):
        search = copy.deepcopy(proven["certificate"]["items"][1]["proof"]["sublevel"]["search"])
        dual = next(p for p in search["proofs"] if p["kind"] == "dual")
        dual["bound"] *= 10
        assert refusal(forged_sublevel(proven, search=search))["check"] == "leaf_bounds"

    @pytest.mark.parametrize("change", [{"search": None}, {"search": {"type": "trivial"}}, {"reference": -1},
                                        {"cost_increase": -1.0}, {"note": 1.0}])
    def test_a_malformed_sublevel_is_refused(self, proven, change):
        assert refusal(forged_sublevel(proven, **change))["check"] in ("proven_interval", "format")

    def test_a_result_saying_proven_without_the_leaves_is_refused(self, proven):
        result = copy.deepcopy(proven)
        del result["certificate"]["items"][0]["proof"]["sublevel"]
        assert verify_any(result["certificate"]).valid  # the certificate alone proves its bound
        assert refusal(result)["check"] == "returned"
        result["maps"][0]["determinacy"]["proven_intervals"] = None
        assert refusal(result)["check"] == "returned"  # proven: true with nothing proven

    def test_a_result_with_other_intervals_than_its_leaves_is_refused(self, proven):
        result = copy.deepcopy(proven)
        result["maps"][0]["determinacy"]["proven_intervals"]["intervals"][3]["lower"] += 1e-3
        assert refusal(result)["check"] == "returned"


@pytest.mark.parametrize("norm", NORMS)
def test_a_brief_certificate_proves_no_interval(norm):
    """No leaves are returned with it: its determinacy is an estimate (proven false)."""
    rng = np.random.default_rng(seed("resection leaves", "brief", norm))
    job, _ = resection(rng, 15, norm, certificate="summary")
    result = solve_job(job)
    document = result["maps"][0]["determinacy"]
    assert document["proven"] is False and document["proven_intervals"] is None
    assert "proof" not in result["maps"][0]["certificate"]


@pytest.mark.parametrize("norm", NORMS)
def test_a_second_search_stopped_by_its_clock_proves_wider_intervals_that_verify(norm, monkeypatch):
    """With no time left after the solve (no tightening round, one box bounded), the root region
    alone bounds the set: wider intervals, still holding the ones a full second search proves, and
    accepted by the verifier."""
    from geocert.solvers.fractional import maps

    rng = np.random.default_rng(seed("resection leaves", "clock", norm))
    job, (truth,) = resection(rng, 15, norm)
    full = solve_job(copy.deepcopy(job))
    monkeypatch.setattr(maps, "LEAVES_MIN_S", 0.0)
    monkeypatch.setattr(maps, "LEAVES_SHARE", 0.0)
    stopped = solve_job(job)
    assert verify_any(stopped).valid
    lower, upper = intervals_of(stopped["maps"][0]["determinacy"])
    full_lower, full_upper = intervals_of(full["maps"][0]["determinacy"])
    assert np.all(lower <= full_lower) and np.all(full_upper <= upper) and np.any(upper - lower > full_upper - full_lower)
    reference = stopped["certificate"]["items"][0]["proof"]["sublevel"]["reference"]
    row = depth_rows(truth[None], np.array(job["data"]["maps"][0]["source"]), reference)[0]
    assert np.all((lower <= row) & (row <= upper))

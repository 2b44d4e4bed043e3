"""Proven intervals of a triangulated point (fractional.convexity.sublevel_radii): every point of
the scope costing at most the optimum plus the stated cost increase lies in them. Checked
against the points themselves (walked along many rays from the solution), against the truth of
synthetic and real-camera scenes, and by the verifier, which refuses an interval it does not
recompute, a radius its enclosure test does not pass, and a result saying proven without it."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.solvers.fractional.many_tracks import triangulate_many
from geocert.formulations.fractional.convexity import ball_intervals
from geocert.formulations.fractional.determinacy import tracks_many
from geocert.solvers.fractional.triangulation import TriangulationOptions
from geocert.verify.checks import verify_any

from tests.verify.test_soundness import readme_job
from tests.support import every_track_searched, noisy_track, random_cameras, seed, refusal


def scene(rng, tracks: int, views: tuple[int, int], noise: float, cameras: int = 12):
    cams = random_cameras(rng, cameras)
    out, truth = [], []
    for _ in range(tracks):
        k = int(rng.integers(views[0], views[1] + 1))
        chosen = sorted(rng.choice(cameras, size=k, replace=False).tolist())
        X, points = noisy_track(rng, cams[chosen], noise_px=noise)
        out.append((chosen, points))
        truth.append(np.asarray(X, dtype=float)[:3])
    return cams, out, np.array(truth)


def solved(cams, tracks, norm: str = "L2L2"):
    results = triangulate_many(cams, tracks, TriangulationOptions(norm=norm, certificate="full"))
    return results, tracks_many(cams, tracks, results)


def costs_at(cams, points, X, norm: str = "L2L2"):
    """The costs of points X (s, 3); inf outside the scope (not in front of every camera)."""
    proj = np.einsum("vij,sj->svi", cams[:, :, :3], X) + cams[:, :, 3]
    r = proj[..., :2] / proj[..., 2:3] - points
    cost = {"L2L2": (r * r).sum(axis=(1, 2)), "L2L1": np.sqrt((r * r).sum(axis=2)).sum(axis=1),
            "L1L1": np.abs(r).sum(axis=(1, 2))}[norm]
    return np.where(np.all(proj[..., 2] > 0, axis=1), cost, np.inf)


def check_rays(rng, cams, tracks, results, documents, norm: str = "L2L2") -> int:
    """Along 40 rays from each solution (random directions and each camera's ray through it,
    where the set is longest), every point costing at most cost + cost_increase is inside the
    proven intervals; the number of tracks with proven intervals."""
    proven = 0
    for (chosen, points), result, document in zip(tracks, results, documents):
        found = document["proven_intervals"]
        if found is None:
            continue
        proven += 1
        assert document["proven"] is True
        x = np.array(result.point)
        lower = np.array([i["lower"] for i in found["intervals"]])
        upper = np.array([i["upper"] for i in found["intervals"]])
        assert np.all(lower <= x) and np.all(x <= upper)
        level = result.cost + found["cost_increase"]
        centres = [-np.linalg.solve(cams[v][:, :3], cams[v][:, 3]) for v in chosen]
        directions = [u / np.linalg.norm(u) for u in rng.normal(size=(40 - len(chosen), 3))]
        directions += [(x - c) / np.linalg.norm(x - c) for c in centres]
        steps = np.geomspace(1e-4, 1e4, 400) * np.linalg.norm(x)
        for u in directions:
            for sign in (1.0, -1.0):
                X = x + sign * steps[:, None] * u
                within = X[costs_at(cams[chosen], points, X, norm) <= level]
                assert np.all(lower <= within) and np.all(within <= upper), found
    return proven


@pytest.mark.parametrize("views,noise", [((2, 2), 1.0), ((3, 6), 0.5), ((3, 6), 3.0)])
def test_every_point_within_the_increase_lies_in_the_proven_intervals(views, noise):
    rng = np.random.default_rng(seed("proven", str(views), str(noise)))
    cams, tracks, _ = scene(rng, 40, views, noise)
    results, documents = solved(cams, tracks)
    assert check_rays(rng, cams, tracks, results, documents) >= 0.9 * len(tracks)


@pytest.mark.parametrize("norm", ["L2L2", "L2L1", "L1L1"])
def test_tracks_certified_by_a_search_have_proven_intervals_too(norm):
    """Whatever proved the bound, the enclosure test at the level cost + cost_increase (under
    the L1 norms every residual's length is at most the cost) proves the intervals."""
    rng = np.random.default_rng(seed("proven", "searched", norm))
    cams, tracks, _ = scene(rng, 8, (2, 4), 1.0)
    with every_track_searched():
        results, documents = solved(cams, tracks, norm)
    assert all(r.certified and r.certificate.proof["type"] == "branch_and_bound" for r in results)
    assert check_rays(rng, cams, tracks, results, documents, norm) == len(tracks)


def test_the_proven_intervals_hold_the_truth_on_most_tracks():
    """At 3 standard errors the set holds the true point on about 97% of tracks (chi-square, 3
    degrees of freedom): the proven box, which holds the set, does on at least as many."""
    rng = np.random.default_rng(seed("proven", "truth"))
    cams, tracks, truth = scene(rng, 400, (2, 8), 1.0)
    _, documents = solved(cams, tracks)
    held = [all(i["lower"] <= t[k] <= i["upper"] for k, i in enumerate(d["proven_intervals"]["intervals"]))
            for t, d in zip(truth, documents) if d["proven_intervals"] is not None]
    assert len(held) >= 360
    assert np.mean(held) >= 0.93


def test_the_terms_moved_to_a_level_are_the_ones_computed_at_it():
    """The convexity path reuses its terms at the sublevel's level (at_level): the radii are those
    of the terms computed afresh at it, bit for bit, so the verifier's recomputation agrees."""
    from geocert.core.geometry import normalised_cameras
    from geocert.formulations.fractional.convexity import at_level, convexity_terms, sublevel_radii
    from geocert.formulations.fractional.flat import FlatTracks, linear, refine

    rng = np.random.default_rng(seed("proven", "at level"))
    cams, tracks, _ = scene(rng, 200, (2, 10), 1.0)
    flat = FlatTracks.build(normalised_cameras(cams), tracks)
    x, _ = refine(flat, linear(flat)[0])
    with np.errstate(all="ignore"):
        terms = convexity_terms(flat, x)
        increase = np.where(np.arange(len(tracks)) % 5 == 0, np.nan, 9 * terms.c * rng.uniform(0.1, 3, len(tracks)))
        moved, fresh = at_level(flat, terms, increase), convexity_terms(flat, x, increase)
        for name in ("rho", "e", "usable"):
            assert np.array_equal(getattr(moved, name), getattr(fresh, name), equal_nan=name != "usable")
        reused = sublevel_radii(flat, x, increase, strictness=2.0, terms=terms)
    assert np.array_equal(reused, sublevel_radii(flat, x, increase, strictness=2.0), equal_nan=True)
    assert np.isfinite(reused).sum() >= 100


@pytest.fixture(scope="module")
def convexity() -> dict:
    """A full result of a track certified by its convexity, with a proven interval (among twelve
    alike: a job's intervals are proven at the noise pooled over its tracks, which one 2-view
    track estimates from one degree of freedom, too loosely to prove any interval)."""
    job = readme_job(mode="full")
    job["data"]["tracks"] = [{"views": [0, 1], "points": [[330 + 0.3 * k, 250], [251.5, 253 - 0.2 * k]]}
                             for k in range(12)]
    result = solve_job(job)
    proof = result["certificate"]["items"][0]["proof"]
    assert proof["type"] == "convexity" and "sublevel" in proof
    report = verify_any(result)
    assert report.valid and {"name": "proven_interval", "passed": 12, "failed": 0} in report.checks
    return result


def forged(convexity, **changes) -> dict:
    doc = copy.deepcopy(convexity["certificate"])
    doc["items"][0]["proof"]["sublevel"].update(changes)
    return doc


class TestForgedIntervals:
    @pytest.mark.parametrize("coordinate", [0, 1, 2])
    @pytest.mark.parametrize("end,change", [(0, 1e-9), (1, -1e-9), (0, -1e-9), (1, 1e-9), (0, 0.5), (1, -0.5)])
    def test_a_narrowed_or_widened_interval_is_refused(self, convexity, coordinate, end, change):
        intervals = copy.deepcopy(convexity["certificate"]["items"][0]["proof"]["sublevel"]["intervals"])
        intervals[coordinate][end] += change * max(abs(intervals[coordinate][end]), 1.0)
        assert refusal(forged(convexity, intervals=intervals))["check"] == "proven_interval"

    @pytest.mark.parametrize("factor", [0.5, 0.9])
    def test_a_smaller_ball_is_refused_though_its_intervals_agree(self, convexity, factor):
        sublevel = convexity["certificate"]["items"][0]["proof"]["sublevel"]
        point = convexity["certificate"]["items"][0]["point"]
        radius = sublevel["radius"] * factor
        first = refusal(forged(convexity, radius=radius, intervals=ball_intervals(point, radius)))
        assert first["check"] == "proven_interval" and "not proven" in first["detail"]

    @pytest.mark.parametrize("factor", [3.0, 100.0])
    def test_a_larger_cost_increase_at_the_same_radius_is_refused(self, convexity, factor):
        increase = convexity["certificate"]["items"][0]["proof"]["sublevel"]["cost_increase"] * factor
        assert refusal(forged(convexity, cost_increase=increase))["check"] == "proven_interval"

    @pytest.mark.parametrize("increase", [-1.0, 1e300, 5e-324])
    def test_a_negative_huge_or_subnormal_cost_increase_is_refused(self, convexity, increase):
        assert refusal(forged(convexity, cost_increase=increase))["check"] == "proven_interval"

    def test_a_field_it_does_not_have_is_refused(self, convexity):
        assert refusal(forged(convexity, note=1.0))["check"] == "format"

    def test_a_result_saying_proven_with_other_intervals_is_refused(self, convexity):
        result = copy.deepcopy(convexity)
        result["tracks"][0]["determinacy"]["proven_intervals"]["intervals"][2]["lower"] += 1.0
        assert refusal(result)["check"] == "returned"

    def test_a_result_saying_proven_without_a_proof_of_it_is_refused(self, convexity):
        result = copy.deepcopy(convexity)
        del result["certificate"]["items"][0]["proof"]["sublevel"]
        assert verify_any(result["certificate"]).valid  # the certificate alone proves its bound
        assert refusal(result)["check"] == "returned"
        result["tracks"][0]["determinacy"]["proven_intervals"] = None
        assert refusal(result)["check"] == "returned"  # proven: true with nothing proven


@pytest.fixture(scope="module")
def searched() -> dict:
    """A full result of six tracks certified by a search (the stacked verifier's usual path),
    each with a proven interval."""
    rng = np.random.default_rng(seed("proven", "forged search"))
    cams, tracks, _ = scene(rng, 6, (2, 4), 1.0)
    job = {"kind": "triangulation", "options": {"certificate": "full"},
           "data": {"cameras": cams.tolist(), "tracks": [{"views": v, "points": p.tolist()} for v, p in tracks]}}
    with every_track_searched():
        result = solve_job(job)
    assert all(item["proof"]["type"] == "branch_and_bound" and "sublevel" in item["proof"]
               for item in result["certificate"]["items"])
    report = verify_any(result)
    assert report.valid and {"name": "proven_interval", "passed": 6, "failed": 0} in report.checks
    return result


class TestForgedIntervalsOfASearch:
    """The stacked verifier (many searches proven at once) reads no interval: the adapter checks
    each stated one, and leaves a claim whose interval fails to the per-item check, which
    refuses it."""

    @pytest.mark.parametrize("end,change", [(0, 1e-6), (1, -1e-6), (0, -1e-6)])
    def test_a_narrowed_or_widened_interval_is_refused(self, searched, end, change):
        doc = copy.deepcopy(searched["certificate"])
        intervals = doc["items"][3]["proof"]["sublevel"]["intervals"]
        intervals[2][end] += change * max(abs(intervals[2][end]), 1.0)
        first = refusal(doc)
        assert first["check"] == "proven_interval" and first["item"] == 3

    def test_a_smaller_ball_is_refused(self, searched):
        doc = copy.deepcopy(searched["certificate"])
        item = doc["items"][2]
        radius = item["proof"]["sublevel"]["radius"] * 0.5
        item["proof"]["sublevel"].update(radius=radius, intervals=ball_intervals(item["point"], radius))
        assert refusal(doc)["check"] == "proven_interval"

    def test_a_map_proof_stating_an_interval_is_refused(self, searched, monkeypatch):
        from geocert.solvers.fractional import maps
        from tests.verify.test_certificates import map_job

        monkeypatch.setattr(maps, "_sublevel_certified", lambda *args: None)  # a search's proof, not the bound's

        document = solve_job(map_job(np.random.default_rng(5), "resection", 7, "L2L2", maps=1,
                                     noise=3.0))["certificate"]
        assert document["items"][0]["proof"]["type"] == "branch_and_bound"
        document["items"][0]["proof"]["sublevel"] = searched["certificate"]["items"][0]["proof"]["sublevel"]
        assert refusal(document)["check"] == "format"


def test_one_two_view_track_alone_proves_no_interval_at_its_level():
    """A job of one 2-view track estimates its noise from one degree of freedom: its estimate is
    read at Student's quantile (about 236^2 times the residual variance), where the enclosure test
    proves no bounded set; the result says not proven rather than stating an interval of a level
    below its estimate's, and verifies."""
    job = readme_job(mode="full", detail="full")
    job["data"]["tracks"][0]["points"] = [[330, 250], [251.5, 253]]
    result = solve_job(job)
    determinacy = result["tracks"][0]["determinacy"]
    assert determinacy["cost_increase"] > 200 ** 2 * result["tracks"][0]["cost"]
    assert determinacy["proven"] is False and determinacy["proven_intervals"] is None
    assert "sublevel" not in result["certificate"]["items"][0]["proof"]
    assert verify_any(result).valid


def test_a_track_decertified_after_its_search_states_no_proven_interval():
    """A search may prove a track's interval and the track then lose its claim (a point near a
    camera's centre: its depth is round-off, the search's bound is not the data's problem's). The
    verifier reads a proven interval only from a certified claim's proof, so the writer states
    none for it: such tracks said "proven" and were refused on their writer's own machine."""
    from tests.verify.test_depth_across_kernels import _near_centre_job

    result = solve_job(_near_centre_job(1))
    decertified = [track for track in result["tracks"] if not track["certified"]
                   and track["certificate"]["leaves"] >= 1]
    assert decertified, "the premise: a searched track left uncertified"
    assert all(track["determinacy"]["proven"] is False for track in decertified)
    assert verify_any(result).valid, verify_any(result).first_failure

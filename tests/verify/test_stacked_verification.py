"""The verifier's stacked path (geocert/formulations/fractional/stacked.py): it rebuilds the per-item
path's charts and relaxations exactly, proves every track of the common shape, reports what the
per-item path reports, and never proves a claim the per-item path refuses."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from geocert.jobs.runner import solve_job
from geocert.core.bnb import Box
from geocert.core.certificates import pack, unpack
from geocert.core.geometry import normalised_cameras
from geocert.core.strict import Invalid
from geocert.formulations.fractional import stacked
from geocert.formulations.fractional.charts import Chart
from geocert.formulations.fractional.items import TrackItem
from geocert.verify.fractional import TrackItems
from geocert.formulations.fractional.relaxation import Relaxation
from geocert.verify.checks import checked_options, verify_any, verify_item

from tests.support import every_track_searched, project, random_cameras

NORMS = ("L2L2", "L2L1", "L1L1")


def scene_job(norm: str, tracks: int = 40, seed: int = 3) -> dict:
    """Eight cameras around the origin; tracks of 2 to 6 views with 1.5 px of noise (most need a search)."""
    rng = np.random.default_rng(seed)
    cameras = random_cameras(rng, 8)
    entries = []
    for _ in range(tracks):
        views = sorted(rng.choice(8, size=int(rng.integers(2, 7)), replace=False).tolist())
        points = project(cameras[views], np.append(rng.normal(size=3), 1.0)) + rng.normal(size=(len(views), 2)) * 1.5
        entries.append({"views": views, "points": points.tolist()})
    return {"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": entries},
            "options": {"norm": norm, "certificate": "full"}}


@pytest.fixture(scope="module", autouse=True)
def searched_only():
    """Every track searched, none certified by its convexity (L2L2's usual path): these tests
    are of the stacked verifier's check of a search's proof."""
    with every_track_searched():
        yield


@pytest.fixture(scope="module")
def documents() -> dict:
    return {norm: solve_job(scene_job(norm))["certificate"] for norm in NORMS}


def common_shape(claim: dict) -> bool:
    proof = claim.get("proof", {})
    return (claim["certified"] and proof.get("type") == "branch_and_bound" and proof["tightening"] == []
            and len(proof["leaves"]) <= stacked.MAX_LEAVES and all(p["kind"] == "dual" for p in proof["proofs"])
            and all(leaf[2] is not None for leaf in proof["leaves"]))


def proven(document: dict) -> set[int]:
    options = checked_options("triangulation", document["options"])
    return stacked.proven_tracks(document["data"], options, document["items"], 1000)


def track_arrays(document: dict, index: int):
    track = document["data"]["tracks"][index]
    cameras = np.array(document["data"]["cameras"], dtype=float)
    return normalised_cameras(cameras[track["views"]]), np.array(track["points"], dtype=float)


class TestCharts:
    def test_the_stacked_charts_are_the_per_item_charts(self, documents):
        document = documents["L2L2"]
        for n in range(2, 7):
            indices = [i for i, t in enumerate(document["data"]["tracks"]) if len(t["views"]) == n]
            cams = np.array([track_arrays(document, i)[0] for i in indices])
            points = np.array([track_arrays(document, i)[1] for i in indices])
            num, den, T, reference, ok = stacked.chart_arrays(cams, points)
            assert ok.all()
            for g, i in enumerate(indices):
                chart = Chart.build(cams[g], points[g], "L2L2")
                assert reference[g] == chart.reference
                np.testing.assert_allclose(num[g], chart.program.num, rtol=1e-12, atol=1e-12)
                np.testing.assert_allclose(den[g], chart.program.den, rtol=1e-12, atol=1e-12)
                np.testing.assert_allclose(T[g], chart.T, rtol=1e-12, atol=1e-12)

    def test_a_depth_row_parallel_to_the_references_is_left_to_the_per_item_path(self):
        # Both cameras' depth rows are (0, 0, 1, 0): the per-item path compares them exactly.
        cams = np.array([[[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]],
                          [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]]], dtype=float)
        points = np.array([[[330.0, 250.0], [250.0, 251.0]]])
        assert not stacked.chart_arrays(cams, points)[4][0]


class TestLeafRelaxations:
    @pytest.mark.parametrize("norm", NORMS)
    def test_rows_bounds_and_cones_are_conic_datas(self, documents, norm):
        document = documents[norm]
        compared = 0
        for index, claim in enumerate(document["items"]):
            if not common_shape(claim):
                continue
            proof = claim["proof"]
            item = TrackItem(track_arrays(document, index), norm)
            program = item.program
            program.rescale(proof["scale"])
            F = np.array(proof["root"]["functionals"])
            bounds = np.array(proof["root"]["bounds"])
            k = len(proof["search_box"][0])
            relaxation = Relaxation(program, F[:k], (bounds[0, k:], bounds[1, k:]), F)
            for leaf in proof["proofs"]:
                box, ub = np.array(leaf["box"]), leaf["upper_bound"]
                data = relaxation.conic_data(Box(box[0], box[1]), ub)
                E, cones, q, lower, upper, transform, built = stacked.leaf_relaxations(
                    program.num[None], program.den[None], program.linear[None], F[None], k, bounds[None], box[None],
                    np.array([ub]), norm, np.array([item.chart.reference]))
                assert built[0] and cones == data.cones
                np.testing.assert_allclose(E[0, :, :-1], -np.asarray(data.A), rtol=1e-13, atol=0)
                np.testing.assert_allclose(E[0, :, -1], data.b, rtol=1e-13, atol=0)
                np.testing.assert_array_equal(q, data.q)
                np.testing.assert_allclose(lower[0], data.lower, rtol=1e-13, atol=0)
                np.testing.assert_allclose(upper[0], data.upper, rtol=1e-13, atol=0)
                np.testing.assert_allclose(transform[0], data.transform, rtol=1e-13, atol=0)
                compared += 1
        assert compared >= 100


class TestProvenTogether:
    @pytest.mark.parametrize("norm", NORMS)
    def test_every_claim_of_the_common_shape_is_proven(self, documents, norm):
        document = documents[norm]
        expected = {i for i, claim in enumerate(document["items"]) if common_shape(claim)}
        assert len(expected) >= 35
        assert sum(len(document["items"][i]["proof"]["leaves"]) > 1 for i in expected) >= 20
        assert proven(document) == expected

    def test_leaves_that_do_not_cover_or_stray_from_their_proofs_are_not_proven(self, documents):
        document = copy.deepcopy(documents["L2L2"])
        branched = [i for i, claim in enumerate(document["items"]) if len(claim["proof"]["leaves"]) > 2]
        gap, stray, shuffled = branched[:3]
        del document["items"][gap]["proof"]["leaves"][1]  # a part of the box no leaf covers
        leaves = document["items"][stray]["proof"]["leaves"]
        leaves[0][2] = (leaves[0][2] + 1) % len(document["items"][stray]["proof"]["proofs"])  # another proof's box
        document["items"][shuffled]["proof"]["leaves"].reverse()  # the same cover, in another order
        result = proven(document)
        assert gap not in result and stray not in result and shuffled in result

    @pytest.mark.parametrize("norm", NORMS)
    def test_the_report_is_the_per_item_paths(self, documents, norm, monkeypatch):
        together = verify_any(copy.deepcopy(documents[norm])).as_dict()
        monkeypatch.setattr(TrackItems, "proven_together", lambda self, data, options, claims: (set(), ()))
        alone = verify_any(copy.deepcopy(documents[norm])).as_dict()
        assert together["valid"] and together == alone

    def test_a_program_differing_from_the_data_is_not_proven(self, documents, monkeypatch):
        document = documents["L2L2"]
        assert proven(document)
        original = stacked.chart_arrays

        def negated(cams, points):  # a varying view's numerator and depth negated: residuals unchanged
            num, den, T, reference, ok = original(cams, points)
            varying = (reference + 1) % cams.shape[1]
            num[np.arange(len(num)), varying] *= -1
            den[np.arange(len(den)), varying] *= -1
            return num, den, T, reference, ok

        monkeypatch.setattr(stacked, "chart_arrays", negated)
        assert proven(document) == set()


def _number_paths(value, path=()):
    if isinstance(value, bool):
        return []
    if isinstance(value, (int, float)):
        return [path]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in _number_paths(v, path + (i,))]
    if isinstance(value, dict):
        return [p for key, v in value.items() for p in _number_paths(v, path + (key,))]
    return []


def _dual_paths(proof: dict):
    return ([("root", "duals", i) for i in range(len(proof["root"]["duals"]))]
            + [("proofs", i, "z") for i in range(len(proof["proofs"]))])


@settings(max_examples=200, deadline=None)
@given(norm=st.sampled_from(NORMS), pick=st.integers(0, 10**6), how=st.integers(0, 4),
       amount=st.floats(1e-7, 0.5), section=st.sampled_from(["proof", "claim", "dual", "data"]))
def test_a_claim_the_per_item_path_refuses_is_never_proven(documents, norm, pick, how, amount, section):
    document = copy.deepcopy(documents[norm])
    positions = sorted(proven(document))
    position = positions[pick % len(positions)]
    claim = document["items"][position]
    if section == "dual":
        paths = _dual_paths(claim["proof"])
        *where, last = paths[pick % len(paths)]
        target = claim["proof"]
        for key in where:
            target = target[key]
        z = unpack(target[last]).copy()
        j = (pick // len(paths)) % len(z)
        z[j] = z[j] * (1 + amount) if how else -z[j] - amount
        target[last] = pack(z)
    else:
        root = {"proof": claim["proof"], "claim": {key: claim[key] for key in ("cost", "lower_bound", "gap", "point")},
                "data": document["data"]["tracks"][position]}[section]
        paths = _number_paths(root)
        path = paths[pick % len(paths)]
        target = root
        for key in path[:-1]:
            target = target[key]
        old = target[path[-1]]
        target[path[-1]] = [old * (1 + amount), old + amount, -old, old * 1e6 + 1, 0.0][how]
        if section == "claim":
            claim.update(root)
    if position not in proven(document):
        return
    options = checked_options("triangulation", document["options"])
    try:
        verify_item("triangulation", document["data"], options, claim)
    except Invalid as exc:
        pytest.fail(f"proven together, refused alone ({exc.check}: {exc.detail}): {section} {how} {amount}")

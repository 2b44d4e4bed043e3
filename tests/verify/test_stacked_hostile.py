"""Hostile documents against the verifier's stacked path (geocert/formulations/fractional/stacked.py):
each is refused by the per-item path, and must not be proven together either; or costs the stacked
path far more than the per-item path would."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from geocert.jobs.runner import solve_job
from geocert.core.certificates import pack
from geocert.formulations.fractional import stacked
from geocert.verify.fractional import TrackItems
from geocert.verify.checks import checked_options, verify_any

from tests.verify.test_stacked_verification import scene_job
from tests.support import every_track_searched, project, random_cameras

NORMS = ("L2L2", "L2L1", "L1L1")


@pytest.fixture(scope="module", autouse=True)
def searched_only():
    """Every track searched, none certified by its convexity (L2L2's usual path): these tests
    are of the stacked verifier's check of a search's proof."""
    with every_track_searched():
        yield


@pytest.fixture(scope="module")
def results() -> dict:
    return {norm: solve_job(scene_job(norm)) for norm in NORMS}


@pytest.fixture(scope="module")
def documents(results) -> dict:
    return {norm: results[norm]["certificate"] for norm in NORMS}


def proven(document: dict) -> set[int]:
    options = checked_options("triangulation", document["options"])
    return stacked.proven_tracks(document["data"], options, document["items"], 1000)


def reports(document: dict, monkeypatch) -> tuple[dict, dict]:
    """verify_any's report with the stacked path, and without it (the per-item path alone)."""
    together = verify_any(copy.deepcopy(document)).as_dict()
    with monkeypatch.context() as m:
        m.setattr(TrackItems, "proven_together", lambda self, data, options, claims: (set(), ()))
        alone = verify_any(copy.deepcopy(document)).as_dict()
    return together, alone


class TestIndex:
    def test_an_index_that_is_not_an_int_is_not_proven(self, documents, monkeypatch):
        # 1.0 == 1, so the verifier's "index is its position" test passes it; the per-item path
        # then fails reading data/tracks[1.0] (a TypeError, reported as format). The stacked path
        # read the track at the claim's position and proved it: the document was valid with the
        # stacked path, invalid without.
        document = copy.deepcopy(documents["L2L2"])
        assert 1 in proven(document)
        document["items"][1]["index"] = 1.0
        assert 1 not in proven(document)
        together, alone = reports(document, monkeypatch)
        assert not alone["valid"] and not together["valid"]
        assert together == alone
        # Refused by name: an index must be an integer (it was a TypeError reading the data).
        assert alone["first_failure"] == {"check": "format", "item": 1,
                                          "detail": "each item must be an object whose index is its position"}


def forged_track(n: int, norm: str, leaves: int = 1) -> tuple[dict, dict, list]:
    """A document of one n-view track whose claim has the common proof's shape (every field of
    the right type and size, its numbers nonsense), for the stacked path's cost."""
    rng = np.random.default_rng(2)
    cameras = random_cameras(rng, n, spread=20.0)
    points = project(cameras, np.array([0.1, 0.0, 0.2, 1.0]))
    box = [[-1.0] * 3, [1.0] * 3]
    claim = {"index": 0, "certified": True, "status": "optimal", "at_infinity": False, "cost": 0.0, "gap": 0.0,
             "lower_bound": 0.0, "point": [0.1, 0.0, 0.2],
             "proof": {"type": "branch_and_bound", "scale": 1.0, "search_box": box, "tightening": [],
                       "root": {"gamma": 1.0, "functionals": np.eye(3).tolist(), "claim": box, "bounds": box,
                                "duals": [pack(np.zeros(1 + 3 * n))] * 6},
                       "leaves": [[box[0], box[1], i] for i in range(leaves)],
                       "proofs": [{"kind": "dual", "box": box, "upper_bound": 1.0, "bound": 0.0, "z": "AAAA"}] * leaves}}
    data = {"cameras": cameras.tolist(), "tracks": [{"views": list(range(n)), "points": points.tolist()}]}
    options = {"norm": norm, "rel_gap": 1e-3, "abs_gap": 1e-7, "max_residual": None}
    return data, options, [claim]


class TestSize:
    def test_a_track_too_large_for_a_chunk_is_left_to_the_per_item_path(self, documents, monkeypatch):
        # A chunk holds MAX_ENTRIES entries of dense relaxation matrices; a track whose one
        # relaxation exceeds that was still checked alone, densely (see the test below).
        document = documents["L2L2"]
        entries = {}
        for i, track in enumerate(document["data"]["tracks"]):
            proof = document["items"][i].get("proof") or {}
            if proof.get("type") == "branch_and_bound":
                rows, cols = stacked._relaxation_size(len(track["views"]), len(proof["search_box"][0]), "L2L2")
                entries[i] = len(proof["proofs"]) * rows * cols
        everything = proven(document)
        limit = 1000
        small = {i for i in everything if entries[i] <= limit}
        assert small and small != everything
        monkeypatch.setattr(stacked, "MAX_ENTRIES", limit)
        assert proven(document) == small
        together, alone = reports(document, monkeypatch)
        assert together["valid"] and together == alone

    @pytest.mark.parametrize("views, leaves", [(600, 1), (100, 64)])
    def test_a_hostile_track_costs_no_dense_relaxation_beyond_a_chunk(self, views, leaves):
        # 600 views (about 0.2 MB of document, nothing in it true): the stacked path built the
        # dense 9000 x 1800 relaxation, peaking at 260 MB (measured; 1.1 GB for 1000 views,
        # L1L1), before any check could refuse it. The per-item path's relaxations are sparse.
        # 100 views and 64 leaves, each with its own proof: 64 relaxations of 1500 x 300 in one
        # chunk (a chunk holds at least one track, whatever its proofs).
        import tracemalloc

        data, options, claims = forged_track(views, "L2L2", leaves)
        tracemalloc.start()
        try:
            result = stacked.proven_tracks(data, options, claims, 1000)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert result == set()
        assert peak < 40e6


def _shrunk(box: list, factor: float) -> list:
    lo, hi = np.array(box[0]), np.array(box[1])
    middle, half = (lo + hi) / 2, (hi - lo) / 2 * factor
    return [(middle - half).tolist(), (middle + half).tolist()]


def _proof_box(claim: dict) -> None:
    leaf = claim["proof"]["proofs"][0]
    leaf["box"] = _shrunk(leaf["box"], 0.25)


def _leaf(claim: dict) -> None:
    leaf = claim["proof"]["leaves"][0]
    leaf[0], leaf[1] = _shrunk(leaf[:2], 0.25)


def _search_box(claim: dict) -> None:
    claim["proof"]["search_box"] = _shrunk(claim["proof"]["search_box"], 0.99)


class TestBoxes:
    """The boxes only the containment checks tie together: the leaf's proof box (the relaxation's),
    the leaf, the searched box and the root's proven box. Each forgery is refused by the per-item
    path; with the stacked path's containment check removed, it was proven together: a proof box
    shrunk to a quarter still proves its claim on some tracks (a smaller box, a larger bound), and
    a leaf or searched box is read for nothing else."""

    @pytest.mark.parametrize("forge, check", [(_proof_box, "leaf_bounds"), (_leaf, "coverage"),
                                              (_search_box, "tightening")])
    @pytest.mark.parametrize("norm", ["L2L2", "L1L1"])
    def test_a_box_outside_the_one_it_must_contain_is_refused(self, documents, monkeypatch, forge, check, norm):
        document = copy.deepcopy(documents[norm])
        positions = proven(document)
        assert len(positions) >= 15
        for position in positions:
            forge(document["items"][position])
        assert proven(document) == set()
        together, alone = reports(document, monkeypatch)
        assert not together["valid"] and together == alone
        assert together["first_failure"]["check"] == check
        failed = {c["name"]: c["failed"] for c in together["checks"]}
        assert failed[check] == len(positions)


class TestNestingOfAResult:
    def test_a_certificate_nesting_too_deep_inside_its_result_is_refused(self, results):
        # A result holding its certificate is walked once (the result): the certificate's own
        # walk is skipped, and the result's must still find what nests in the certificate.
        result = copy.deepcopy(results["L2L2"])
        assert verify_any(copy.deepcopy(result)).valid
        nested: list = []
        for _ in range(70):
            nested = [nested]
        result["certificate"]["note"] = nested  # nothing hashes or reads it
        report = verify_any(result).as_dict()
        assert not report["valid"] and report["first_failure"]["check"] == "format"
        assert "nests deeper" in report["first_failure"]["detail"]


def _leaves_name_the_last_proof(proof: dict) -> None:
    for leaf in proof["leaves"]:
        leaf[2] = len(proof["proofs"]) - 1


def _a_leaf_dropped(proof: dict) -> None:
    proof["leaves"].pop(0)


def _an_unnamed_proof_that_fails(proof: dict) -> None:
    extra = copy.deepcopy(proof["proofs"][0])
    extra["bound"] = extra["bound"] * 2 + 1.0  # more than its dual proves
    proof["proofs"].append(extra)


class TestLeaves:
    """Tracks of several leaves: each leaf inside the box of the proof it names, the leaves
    covering the searched box, every proof holding (named or not). Each forgery of every proven
    track of several leaves is refused by the per-item path and not proven together; with the
    stacked check removed it was (the leaves' bounds are the last proof's, or the smallest of the
    leaves left, or the failing proof is never read)."""

    @pytest.mark.parametrize("forge, check", [(_leaves_name_the_last_proof, "leaf_bounds"),
                                              (_a_leaf_dropped, "coverage"),
                                              (_an_unnamed_proof_that_fails, "leaf_bounds")])
    @pytest.mark.parametrize("norm", ["L2L2", "L1L1"])
    def test_leaves_and_proofs_that_do_not_fit_are_refused(self, documents, monkeypatch, forge, check, norm):
        document = copy.deepcopy(documents[norm])
        positions = {i for i in proven(document) if len(document["items"][i]["proof"]["leaves"]) > 1}
        assert len(positions) >= 5
        for position in positions:
            forge(document["items"][position]["proof"])
        assert proven(document) & positions == set()
        together, alone = reports(document, monkeypatch)
        assert not together["valid"] and together == alone
        failed = {c["name"]: c["failed"] for c in together["checks"]}
        assert failed[check] == len(positions)

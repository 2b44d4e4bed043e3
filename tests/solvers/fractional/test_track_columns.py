"""Many tracks' results as columns (geocert/formulations/fractional/columns.py): triangulate_many keeps
the tracks its convexity path certifies as arrays, makes a TrackResult for one only when it is
asked for, and what it makes is the certified result the verifier accepts; the triangulation
kind's documents and determinacy read the columns and say what the objects would."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from geocert.kinds.triangulation import track_document, track_documents
from geocert.core.geometry import norm_cost, reprojection_residuals
from geocert.formulations.fractional import determinacy
from geocert.solvers.fractional.many_tracks import triangulate_many
from geocert.formulations.fractional.columns import TrackResults, solutions
from geocert.formulations.fractional.results import LocalCertificate, claim_of
from geocert.solvers.fractional.triangulation import TriangulationOptions
from geocert.verify.checks import verify_arrays

from tests.support import dinosaur_sample

pytestmark = pytest.mark.shared_data("oxford_dinosaur")


@pytest.fixture(scope="module")
def dinosaur():
    return dinosaur_sample(25)  # 200 tracks


def test_the_convexity_paths_tracks_stay_columns_until_asked_for_and_then_verify(dinosaur):
    cameras, tracks = dinosaur
    options = TriangulationOptions(norm="L2L2", rel_gap=1e-3, certificate="full")
    results = triangulate_many(cameras, tracks, options)
    columns = results.in_columns()
    assert columns.sum() >= 0.99 * len(tracks)
    assert set(results.objects) == set(np.flatnonzero(~columns).tolist())  # no object made for a row
    count = results.certified_count()
    run = dataclasses.asdict(options)
    for i in np.flatnonzero(columns).tolist():
        result = results[i]
        views, points = tracks[i]
        assert result.certified and result.status == "optimal" and result.nodes == 0
        assert isinstance(result.certificate, LocalCertificate) and result.certificate.proof["type"] == "convexity"
        residuals = reprojection_residuals(cameras[views], np.append(result.point, 1.0), points)
        assert np.allclose(result.residuals, residuals, rtol=0, atol=1e-9)
        assert abs(result.cost - norm_cost(residuals, "L2L2")) <= 1e-9 * result.cost
        assert result.gap == result.cost - result.lower_bound <= max(options.abs_gap, options.rel_gap * result.cost)
        claim = claim_of(result, point=result.point, at_infinity=result.at_infinity)
        verify_arrays("triangulation", (cameras[views], np.asarray(points, dtype=float)), run, claim)  # raises
    assert not results.in_columns().any()  # every row asked for is now its object
    assert count == results.certified_count() == sum(r.certified for r in results)


def test_a_row_made_into_an_object_is_that_object_from_then_on(dinosaur):
    cameras, tracks = dinosaur
    results = triangulate_many(cameras, tracks[:30], TriangulationOptions(norm="L2L2"))
    first = results[0]
    first.elapsed_s = -1.0
    assert results[0] is first and results[0].elapsed_s == -1.0
    assert results[-1] is results[29] and results[2:5] == [results[2], results[3], results[4]]
    with pytest.raises(IndexError):
        results[30]
    # solutions reads the columns and the objects alike: as from the objects themselves.
    point, finite, cost, lower = solutions(results)
    objects = list(results)
    again = solutions(objects)
    for mine, theirs in zip((point, finite, cost, lower), again):
        assert np.array_equal(mine, theirs)
    assert np.array_equal(point, np.array([r.point for r in objects]))


@pytest.mark.parametrize("detail", ["full", "brief"])
@pytest.mark.parametrize("certificate", ["summary", "full"])
def test_documents_from_the_columns_are_the_objects_documents(dinosaur, detail, certificate):
    """track_documents and determinacy.tracks_many on the columns: the documents (to the byte)
    that track_document and tracks_many give for the TrackResults made from them."""
    cameras, tracks = dinosaur
    options = TriangulationOptions(norm="L2L2", detail=detail, certificate=certificate)
    results = triangulate_many(cameras, tracks, options)
    assert results.in_columns().sum() >= 0.99 * len(tracks)
    documents = track_documents(results, detail, certificate == "full")
    found = determinacy.tracks_many(cameras, tracks, results)
    objects = [results[i] for i in range(len(results))]
    assert not results.in_columns().any()
    assert json.dumps(documents) == json.dumps([track_document(r, detail, certificate == "full") for r in objects])
    assert json.dumps(found) == json.dumps(determinacy.tracks_many(cameras, tracks, objects))
    assert json.dumps(track_documents(results, detail, certificate == "full")) == json.dumps(documents)


def test_an_empty_sequence_of_results():
    results = TrackResults(3)
    assert results.unsolved() == [0, 1, 2] and results.certified_count() == 0 and list(results) == [None] * 3

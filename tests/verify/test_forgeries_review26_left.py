"""Issue 33: what review 26 found and the stop after it left open, each refused at its cause.

- A principal-point record (stages.projective.principal_point, and the adjustment's) saying
  ``estimated: false`` beside its own chi2 above the threshold and a free fit inside the middle
  half: the pipeline writes ``estimated`` exactly when both hold, and on the projective record
  the contradiction chose the centred reading of the calibration tie (the certificate's cameras
  at the images' centre, that reference's room). Refused, as is an ``inside_middle_half`` that
  K_free does not give or a threshold not the test's.
- ``nodes`` (an item's, the job's) accepted any integer (10**400), and ``stats.nodes`` was not the
  items' sum. Refused: a count at most 2^53 - 1, and the job's the items' sum.
- A track's chart chose its reference from views^2 centre-view pairs outside the work budget
  (30 tracks of 1,000 views, 1.6 MB: 2.4 s of CPU). Paid from it now (charts.reference_work).
- Deleting every determinacy interval's tolerance made a current result read as an older one
  ("determined" then means bounded). The estimates' form is now declared through the problem hash
  (core.determinacy.ESTIMATES_FORM): a document so hashed states every tolerance or is refused.
- Autocalibration's interval ends and cost_increase were untied: every stage's intervals must
  hold their value, and a stratified stage's level is its writer's from the document's figures.

Each test below marked "Found" failed on main (run against main's geocert/).
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.verify.checks import verify_any
from tests.support import stage as _stage
from tests.verify.test_forgeries import stored
from tests.verify.test_registration_record_form import centred_forgery, off_centre  # noqa: F401 (fixtures)


def _verify(document: dict):
    return verify_any(json.loads(json.dumps(document)))


# 1. The principal-point record contradicting itself

def _with_record(forged: dict, genuine: dict, **edits) -> dict:
    forged = copy.deepcopy(forged)
    record = copy.deepcopy(_stage(genuine, "projective")["principal_point"])
    record.update(edits)
    _stage(forged, "projective")["principal_point"] = record
    return forged


def test_the_genuine_records_test_passes(off_centre):  # noqa: F811
    record = _stage(off_centre, "projective")["principal_point"]
    assert record["estimated"] is True and record["chi2"] > record["threshold"] and record["inside_middle_half"]
    assert _verify(off_centre).valid


def test_a_record_saying_not_estimated_beside_a_passing_test_is_refused(off_centre, centred_forgery):  # noqa: F811
    """Found (verified on main): the centred certificate (1.03 times the focal length) beside the
    genuine record with ``estimated`` flipped to false, chi2 and inside_middle_half as written."""
    report = _verify(_with_record(centred_forgery, off_centre, estimated=False))
    assert not report.valid
    assert "principal_point/estimated is False, and its test passes" in report.first_failure["detail"], \
        report.first_failure


@pytest.mark.parametrize("edits, words", [
    ({"estimated": False, "inside_middle_half": False}, "principal_point/inside_middle_half is False"),
    ({"estimated": False, "threshold": 1e9}, "principal_point/threshold is 1000000000.0"),
], ids=["said outside the middle half", "threshold raised"])
def test_the_contradiction_cannot_be_hidden_in_the_records_other_figures(off_centre, centred_forgery, edits,  # noqa: F811
                                                                         words):
    """Found (verified on main): the same forgery with inside_middle_half set false (K_free's
    principal point lies inside) or the threshold raised above the chi2."""
    report = _verify(_with_record(centred_forgery, off_centre, **edits))
    assert not report.valid and words in report.first_failure["detail"], report.first_failure


@pytest.mark.parametrize("chi2", [1.0, -1243.0, 13.8])
def test_a_not_estimated_record_below_its_threshold_gives_no_centred_room(off_centre, centred_forgery, chi2):  # noqa: F811
    """Found (review 28; verified on main, then a documented limit): the chi2 edited below the
    threshold, which the verifier cannot recompute (the adjustment's fits), made the record
    consistent and chose the centred reading's room. A record saying its test ran and did not
    pass now gives a certificate built at the centre no room (calibration_tie._centred_reference): it
    is held to the returned reconstruction re-adjusted with its principal point free, and the
    centred forgery (1.03 times the focal length, the tracks' principal point 36 px off) is not
    these tracks' reconstruction."""
    forged = _with_record(centred_forgery, off_centre, estimated=False, chi2=chi2)
    report = _verify(forged)
    assert not report.valid
    # a negative chi2 is written by no fit, refused before the tie reads the record (review 30)
    words = "principal_point/chi2 is" if chi2 < 0 else "calibration certificate"
    assert words in report.first_failure["detail"], report.first_failure


@pytest.mark.slow
@pytest.mark.parametrize("shift", [0.0, 2.0])
def test_a_genuine_run_whose_test_did_not_pass_verifies_without_the_centred_room(shift):
    """What the reading above asks of genuine runs: the scene's principal point at the centre or
    2 px off (the registration's chi2 0.4 and 10.5, below 13.8: its cameras built at the centre)
    verifies held to the reconstruction re-adjusted with the principal point free (measured: the
    certificate's cost 227.3 and 228.2 px^2, 258.1 and 259.1 allowed, the returned 227.4 and
    228.2)."""
    from geocert.jobs.runner import solve_job
    from geocert.formulations.reconstruction import calibration_tie
    from tests.verify.test_forgeries_review18 import _scene_job

    result = solve_job(_scene_job({}, points=200, shift=np.tile([shift, -shift * 2 / 3], (8, 1))))
    record = _stage(result, "projective")["principal_point"]
    assert record["estimated"] is False and record["chi2"] < record["threshold"] and record["inside_middle_half"]
    report = _verify(result)
    assert report.valid, report.first_failure
    assert report.scope["calibration_tie"]["reference"] == calibration_tie.CENTRED_HELD


def test_a_record_of_too_few_observations_gives_no_centred_room(off_centre, centred_forgery):  # noqa: F811
    """The same forgery beside a record in the other shape its writer has (the test not run, 19
    observations: consistent, the count not recomputed either): no room, refused."""
    record = _stage(off_centre, "projective")["principal_point"]
    forged = copy.deepcopy(centred_forgery)
    _stage(forged, "projective")["principal_point"] = {
        "estimated": False, "observations": 19, "K_free": record["K_free"], "reason": "too few observations to test"}
    report = _verify(forged)
    assert not report.valid
    assert "calibration certificate" in report.first_failure["detail"], report.first_failure


# 4. nodes

COUNTED = {"triangulation_l2l2": "tracks", "resection_l1l1": "maps", "homography3_l2l1": "maps",
           "bilinear_l1l1": "frames", "autocalibration_five_views": "stages", "autocalibration_direct": "stages",
           "reconstruction": "points"}


@pytest.mark.parametrize("name", list(COUNTED))
def test_the_stored_jobs_nodes_are_their_items_sum(name):
    result = stored(name)
    assert result["stats"]["nodes"] == sum(item["nodes"] for item in result[COUNTED[name]])
    assert _verify(result).valid


@pytest.mark.parametrize("name", list(COUNTED))
def test_the_jobs_nodes_other_than_its_items_sum_are_refused(name):
    """Found (verified on main): stats.nodes one more than the items' nodes."""
    result = stored(name)
    result["stats"]["nodes"] += 1
    report = _verify(result)
    assert not report.valid and "stats/nodes" in report.first_failure["detail"], report.first_failure


@pytest.mark.parametrize("where", ["item", "stats"])
@pytest.mark.parametrize("name", ["triangulation_l2l2", "autocalibration_five_views"])
def test_nodes_beyond_any_count_are_refused(name, where):
    """Found (verified on main): 10**400 nodes, an item's and (with the items' sum edited alike)
    the job's."""
    result = stored(name)
    items = result[COUNTED[name]]
    if where == "item":
        items[0]["nodes"] = 10 ** 400
    else:
        items[0]["nodes"] += 10 ** 400
        result["stats"]["nodes"] += 10 ** 400
    report = _verify(result)
    assert not report.valid and "nodes must be null or a count" in report.first_failure["detail"], \
        report.first_failure


# 3. A long track's chart reference, paid from the work budget

def _long_tracks(tracks: int, views: int) -> dict:
    """A certificate of ``tracks`` tracks of ``views`` views each, every one claiming
    "infeasible" with no point (which the verifier tests by building its chart), as a forger
    asks for views^2 work with 3 numbers a view."""
    from testing.jobs import random_cameras
    from tests.verify.test_forgeries import rehash

    rng = np.random.default_rng(33)
    cameras = random_cameras(rng, views)
    data = {"cameras": cameras.tolist(),
            "tracks": [{"views": list(range(views)), "points": rng.uniform(0, 640, (views, 2)).tolist()}
                       for _ in range(tracks)]}
    options = {"norm": "L2L2", "max_residual": None, "rel_gap": 1e-3, "abs_gap": 1e-7}
    claims = [{"index": i, "status": "infeasible", "certified": False, "cost": None, "lower_bound": None,
               "gap": None, "point": None, "at_infinity": False, "proof": None} for i in range(tracks)]
    return rehash({"format": "geocert-certificate", "version": 2, "kind": "triangulation", "options": options,
                   "data": data, "data_sha256": "", "problem_sha256": "", "items": claims})


def test_a_long_tracks_chart_reference_is_paid_from_the_work_budget(monkeypatch):
    """Found (review 26): tracks of up to 1,000 views cost views^2 pairs each in choosing their
    chart's reference, outside the budget: 30 such tracks (1.6 MB) took 2.4 s of CPU, 4 times a
    genuine document's per MB. With the budget's base set aside (WORK_BASE 0, so that a small
    document shows it), the pairs projected stay within PAIRS_PER_UNIT times the budget, and the
    tracks beyond it are refused for the work they ask for; on main all 5 tracks' 5 million pairs
    were projected."""
    from geocert.core import strict
    from geocert.formulations.fractional import charts
    from geocert.verify import checks

    document = _long_tracks(5, 1000)
    monkeypatch.setattr(checks, "WORK_BASE", 0)
    projected = []
    choose = charts._choose_reference

    def counted(cameras, points, centres):
        reference = choose(cameras, points, centres)  # (refused before any pair when the budget is spent)
        projected.append(len(cameras) ** 2)
        return reference

    monkeypatch.setattr(charts, "_choose_reference", counted)
    report = _verify(document)
    assert not report.valid
    budget = strict.WORK_PER_UNIT * strict.document_size(json.loads(json.dumps(document)))
    assert 0 < sum(projected) <= getattr(charts, "PAIRS_PER_UNIT", 0) * budget, (sum(projected), budget)
    # the tracks not charted were refused for the work they ask for (check format)
    assert next(c["failed"] for c in report.checks if c["name"] == "format") == 5 - len(projected) > 0, report.checks


def test_a_genuine_document_of_long_tracks_pays_for_its_references(monkeypatch):
    """Genuine tracks of 150 views (below the 190 whose own data pay for their pairs) verify
    with no base budget at all."""
    from geocert.jobs.runner import solve_job
    from geocert.verify import checks
    from testing.jobs import noisy_track, random_cameras

    rng = np.random.default_rng(7)
    cameras = random_cameras(rng, 150)
    tracks = [{"views": list(range(150)), "points": noisy_track(rng, cameras, noise_px=1.0)[1].tolist()}
              for _ in range(3)]
    result = solve_job({"kind": "triangulation", "data": {"cameras": cameras.tolist(), "tracks": tracks},
                        "options": {"norm": "L2L2", "certificate": "full"}})
    monkeypatch.setattr(checks, "WORK_BASE", 0)
    report = _verify(result)
    assert report.valid, report.first_failure


# 2. The estimates' form, declared through the problem hash

MARKED = {"triangulation_l2l2": "tracks", "resection_l1l1": "maps", "homography2_l2l2": "maps",
          "bilinear_l2l2": "frames", "autocalibration_stratified": "stages"}


@pytest.fixture(scope="module")
def fresh_tracks() -> dict:
    from geocert.jobs.runner import solve_job
    from tests.support import seed, triangulation_job

    return solve_job(triangulation_job(np.random.default_rng(seed("review26", "left")), 4, 4, "L2L2"))


def _strip_tolerances(result: dict, key: str) -> dict:
    result = copy.deepcopy(result)
    for item in result[key]:
        for interval in (item.get("determinacy") or {}).get("intervals") or []:
            interval.pop("tolerance", None)
    return result


def test_a_fresh_document_is_of_the_marked_form(fresh_tracks):
    report = _verify(fresh_tracks)
    assert report.valid, report.first_failure
    assert "problem_sha256" not in report.scope  # the current form
    assert all("tolerance" in i for t in fresh_tracks["tracks"] for i in t["determinacy"]["intervals"])


def test_a_fresh_document_with_its_tolerances_deleted_is_refused(fresh_tracks):
    """Found (verified on main): every interval's tolerance deleted, the document was read as one
    written before intervals stated one (determined meaning bounded)."""
    report = _verify(_strip_tolerances(fresh_tracks, "tracks"))
    assert not report.valid and "states no tolerance" in report.first_failure["detail"], report.first_failure


def test_restated_in_the_unmarked_form_it_verifies_only_saying_so(fresh_tracks):
    """The known limit (as the reconstruction's earlier hash forms): the same edit hashed without
    the mark verifies as a stored document of that form does, and the report's scope says the
    hash is of the earlier form, which a user hashing their own request in today's form finds
    is not theirs."""
    from tests.verify.test_forgeries import rehash

    forged = _strip_tolerances(fresh_tracks, "tracks")
    rehash(forged["certificate"], earlier=True)
    report = _verify(forged)
    assert report.valid, report.first_failure
    assert report.scope["problem_sha256"].startswith("the earlier form")


@pytest.mark.parametrize("name", list(MARKED))
def test_the_stored_documents_of_the_unmarked_form_verify_saying_so(name):
    report = _verify(stored(name))
    assert report.valid, report.first_failure
    assert "determined meaning every interval bounded" in report.scope["problem_sha256"]


@pytest.mark.parametrize("name", list(MARKED))
def test_a_stored_document_restated_in_the_marked_form_without_tolerances_is_refused(name):
    """Found (verified on main): a document hashed as today's (the mark) whose intervals state no
    tolerance was read in the older way."""
    from tests.verify.test_forgeries import rehash

    result = stored(name)
    rehash(result["certificate"], form=1)  # the first marked form: only the tolerances differ from the stored one's
    report = _verify(result)
    assert not report.valid and "states no tolerance" in report.first_failure["detail"], report.first_failure


# 5. Autocalibration's estimates tied where the document allows

def _beside(interval: dict) -> None:
    """The interval moved wholly above its value (its width kept)."""
    width = interval["upper"] - interval["lower"]
    interval["lower"] = interval["value"] + width
    interval["upper"] = interval["value"] + 2 * width


@pytest.mark.parametrize("name, stage", [("autocalibration_stratified", 0), ("autocalibration_stratified", 1),
                                         ("autocalibration_five_views", 0), ("autocalibration_five_views", 1),
                                         ("autocalibration_direct", 0)])
def test_an_autocalibration_interval_beside_its_value_is_refused(name, stage):
    """Found (verified on main): an interval moved off the value it is about (its width, and so
    determined, unchanged)."""
    result = stored(name)
    _beside(result["stages"][stage]["determinacy"]["intervals"][0])
    report = _verify(result)
    assert not report.valid and "does not hold its value" in report.first_failure["detail"], report.first_failure


@pytest.mark.parametrize("factor", [1e3, 1e-3])
@pytest.mark.parametrize("name, stage", [("autocalibration_stratified", 0), ("autocalibration_stratified", 1),
                                         ("autocalibration_five_views", 0), ("autocalibration_five_views", 1)])
def test_a_stratified_stages_level_not_its_writers_is_refused(name, stage, factor):
    """Found (verified on main): a stage's cost_increase a thousand times larger or smaller. It
    is the writer's level from the stage's cost, redundancy and certified gap."""
    result = stored(name)
    determinacy = result["stages"][stage]["determinacy"]
    determinacy["cost_increase"] *= factor
    report = _verify(result)
    assert not report.valid and "cost_increase" in report.first_failure["detail"], report.first_failure

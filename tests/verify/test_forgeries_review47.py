"""Review 47: a hostile review of the hashes of the numbers' values (certificates.hashed_numbers,
data_hash, problem_hash, checks._check_hashes), of the triangulation, resection, homography and
bilinear certificates, and of the verifier's cost.

Found (a test below for each, marked xfail while the class stands):

1. A genuine document holding an integer literal no float holds exactly (the job's data as the
   user sent it: a camera entry 922337203685477580801) is refused once re-serialised by
   JavaScript, Go or any reader of JSON numbers as doubles: the hash keeps such an integer exact
   (hashed_numbers: "an integer no float holds exactly kept"), while every other reader, and the
   solver and verifier themselves (geometry.number_array: np.array(value, dtype=float)), read it
   as its nearest float. JSON.parse then JSON.stringify writes 922337203685477600000, whose value
   hashes as the float; the document, read the same, is refused "data_hash". The docs promise a
   document re-serialised by another writer keeps its hashes.
   Where: core/certificates.py, hashed_numbers, the ``int`` arm keeping ``value`` where
   ``int(as_float) != value``. Suggested fix: hash every number as the float the readers take it
   for (float(value) for an int within float range), since no field the hash covers reads an
   integer beyond 2**53 exactly (views are indices below the camera count; the data's numbers
   are read as floats); keep beyond-range integers as written (refused by the readers anyway).

2. A triangulation, resection or homography document's data may hold members no solver takes
   and no check reads (a track's "weights", a map's "inliers", a top-level member beside
   "cameras"/"tracks" or "maps"): they are hashed with the data and the document verifies. The
   API and the CLI refuse them in a job (the kind's request_model, kinds.schema.Strict:
   extra="forbid", a 422 naming the member), so no genuine document holds one, and a reader of the document takes "weights": [1, 1000] for part
   of the problem the claims are about (a weighted cost) while the verifier checked the
   unweighted one. Bilinear (verify/bilinear.py) and autocalibration (autocalibration.read_data)
   refuse an unknown data member by name ("data/weights: unknown field"), and every other part
   of a document (options, proof records, result members) is closed to the names its writer
   writes for the same reason.
   Where: verify/fractional.py, TrackItems.read and MapItems.read (only the known members are
   read; the others are neither refused nor checked), and checks._check_item_count.
   Suggested fix: refuse a data member outside the kind's schema ({"cameras", "tracks"} and
   {"views", "points"}; {"maps"} and {"source", "target"}), check "data", naming it, as
   autocalibration.read_data does.

3. A certificate carried in its result (the form every stored document and every full result
   has) may hold top-level members beyond its format's (checks.CERTIFICATE_MEMBERS): a
   ``"certified": true``, a ``"max_residual": 1.0`` beside ``options``, a second ``"claims"``
   list: the result verifies. The same certificate on its own is refused ("a certificate (it has
   'format') has no member 'certified'"), and every other record of a result is closed to its
   writer's members (check_members: "a member no check reads claims nothing, so it is
   refused"). Triangulation, resection, homography and bilinear alike.
   Where: verify/checks.py, _verify: ``extra = ... if returned is None else []`` tests the
   members only of a bare certificate; check_members' kinds' ``members`` do not name the
   result's ``certificate``. Suggested fix: test ``set(document) - CERTIFICATE_MEMBERS`` for the
   carried certificate too (for a bare one only the message differs).

4. Cost, quadratic: a triangulation result's track whose determinacy states a level pooled over
   the job's tracks (``pooled_tracks``, checked by fractional._check_pooled) makes the verifier
   normalise every camera of the document (normalised_cameras(data["cameras"])) and sum the
   residuals of every track of its pool, once per distinct pool, uncharged (no strict.charge).
   A document giving each track its own pool (``[[i, i + 1]]``, or ``[[0, i], [i, n]]`` to pool
   every track) does tracks x cameras (and tracks x tracks) of work before any refusal: 1,000
   uncertified tracks beside 40,000 unused cameras (a 2.9 MB result) took 51 s of CPU to refuse
   (at the estimates' check that follows), 21 ms a track; 1,000 such tracks each pooling every
   track (``[[0, i], [i, 1006]]``, no extra camera: 1.75 MB) took 20.9 s; a 32 MB document of the same shape
   (ten times the tracks and cameras) would take about 100 times that, well over an hour.
   docs/certificate.md: "a document cannot ask for work out of proportion to its size: time and
   memory are linear in it". Where: verify/fractional.py, _check_pooled: ``floors`` caches a
   pool's floor by its runs, but the cameras are normalised inside the miss, once per key, and
   each key sums its tracks anew. Suggested fix: normalise the cameras once a document (or take
   them from TrackItems._read_cameras), compute each track's squared residuals once (a list by
   index), and charge each pool its tracks (strict.charge) or refuse pools other than the
   writer's one partition of the job's tracks (pool_runs of the batch: every track states the
   same runs or is its own pool's only member).

5. Cost, memory: the values hash (certificates.hashed_numbers, called once by _check_hashes)
   builds a copy of the whole data, every list anew and every int as a new float, before the
   canonical text is written: hashing a 0.82 MB triangulation whose data hold 25,000 unused
   cameras of small integers peaks at 20.4 MB (25 times its text; a canonical text of the data
   as parsed: 3.5 MB). A 28 MB such document (880,000 cameras, a valid certificate) took 31 s of
   CPU and 1.2 GB of resident memory to verify, 770 MB of it beyond its parse, on top of the
   25-times parse docs/certificate.md allows for (two verifications at once in an API process).
   Where: core/certificates.py, hashed_numbers (a recursive copy) and data_hash/problem_hash
   (canonical_json of that copy). Suggested fix: write the canonical text without the copy: a
   JSON encoder that writes each int as float(int)'s repr (or the int where no float holds it)
   and -0.0 as 0.0 as it goes (json's C encoder takes no hook for ints; an iterative writer
   feeding hashlib in chunks, or float conversion of the numeric leaf lists only, in place in a
   scratch structure freed as written), and hash the data's text once for every problem form
   (the forms differ only in their options and marks: hash a prefix and the data's text).
"""

from __future__ import annotations

import copy
import json

import pytest

from geocert.jobs.runner import solve_job
from geocert.kinds import get_kind
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import rehash, stored


def _as_a_double_reader_writes(value):
    """What JSON.parse then JSON.stringify make of a document: every number read as a double,
    written as an integer where it is integral below 1e21 (-0.0 as 0)."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, (int, float)):
        as_float = float(value)
        return int(as_float) if as_float.is_integer() and abs(as_float) < 1e21 else as_float
    if isinstance(value, list):
        return [_as_a_double_reader_writes(item) for item in value]
    return {key: _as_a_double_reader_writes(item) for key, item in value.items()}


# Class 1: a genuine document with an integer no float holds, re-serialised by a double reader

@pytest.fixture(scope="module")
def huge_integer_result() -> dict:
    """A genuine triangulation: camera 0 scaled by 2**60, each entry written as the integer one
    above (no float holds it; the solver reads its nearest float, as every reader does)."""
    example = get_kind("triangulation").example
    data = copy.deepcopy(example["data"])
    data["cameras"][0] = [[int(v * 2 ** 60) + 1 if v != 0 else 0 for v in row] for row in data["cameras"][0]]
    job = {**example, "data": data, "options": {**example.get("options", {}), "certificate": "full"}}
    return json.loads(json.dumps(solve_job(job)))


def test_the_huge_integer_result_is_genuine_and_verifies_as_written(huge_integer_result):
    certificate = huge_integer_result["certificate"]
    assert [item["certified"] for item in certificate["items"]] == [True, True]
    assert certificate["data"]["cameras"][0][0][0] == 922337203685477580801  # as sent: no float holds it
    report = verify_any(huge_integer_result)
    assert report.valid, report.first_failure


def test_the_huge_integer_result_as_javascript_writes_it_verifies(huge_integer_result):
    rewritten = json.loads(json.dumps(_as_a_double_reader_writes(huge_integer_result)))
    assert rewritten["certificate"]["data"]["cameras"][0][0][0] == 922337203685477580800  # the same double
    report = verify_any(rewritten)
    assert report.valid, report.first_failure


# Class 2: data members no solver takes and no check reads

UNKNOWN_MEMBERS = [
    ("triangulation_l2l2", ("weights",), [1.0, 1000.0]),
    ("triangulation_l2l2", ("tracks", 0, "weights"), [1.0, 1000.0]),
    ("resection_l2l2", ("maps", 0, "inliers"), [0, 1, 2]),
    ("resection_l2l2", ("undistorted",), False),
    ("homography2_l2l2", ("maps", 0, "weights"), [1000.0, 1.0, 1.0, 1.0]),
]


def _with_member(name: str, path: tuple, value) -> dict:
    result = stored(name)
    assert verify_any(result).valid
    place = result["certificate"]["data"]
    for step in path[:-1]:
        place = place[step]
    place[path[-1]] = value
    rehash(result["certificate"])
    return result


@pytest.mark.parametrize("name, path, value", UNKNOWN_MEMBERS)
def test_a_data_member_no_solver_takes_is_refused(name, path, value):
    report = verify_any(_with_member(name, path, value))
    assert not report.valid and report.first_failure["check"] == "data", report.first_failure
    named = "data/" + "/".join(map(str, path))
    assert report.first_failure["detail"].startswith(f"{named}: unknown field"), report.first_failure


@pytest.mark.parametrize("kind", ["triangulation", "resection", "homography"])
@pytest.mark.parametrize("where", ["data", "item"])
def test_the_request_model_refuses_such_a_member(kind, where):
    """The premise of class 2: the API refuses such a member (kinds.schema.Strict, a 422 naming
    it), so no genuine document holds one."""
    from pydantic import ValidationError

    example = copy.deepcopy(get_kind(kind).example)
    model = get_kind(kind).request_model
    model.model_validate(example)
    place = example["data"] if where == "data" else example["data"][get_kind(kind).item_key][0]
    place["weights"] = [1.0, 1000.0]
    with pytest.raises(ValidationError, match="weights"):
        model.model_validate(example)


# Class 3: a carried certificate's top-level members beyond its format's

EXTRA_CERTIFICATE_MEMBERS = [("certified", True), ("max_residual", 1.0),
                             ("claims", [{"index": 0, "cost": 0.0, "certified": True}])]


@pytest.mark.parametrize("name", ["triangulation_l2l2", "resection_l2l2", "homography2_l2l2", "bilinear_l2l2"])
@pytest.mark.parametrize("member, value", EXTRA_CERTIFICATE_MEMBERS)
def test_a_carried_certificate_with_a_member_beyond_its_format_is_refused(name, member, value):
    result = stored(name)
    result["certificate"][member] = value
    report = verify_any(result)
    assert not report.valid and report.first_failure["check"] == "format", report.first_failure


@pytest.mark.parametrize("name", ["triangulation_l2l2", "bilinear_l2l2"])
def test_a_bare_certificate_with_a_member_beyond_its_format_is_refused(name):
    """What class 3 compares with: the bare certificate is refused for the member."""
    certificate = stored(name)["certificate"]
    certificate["certified"] = True
    report = verify_any(certificate)
    assert not report.valid and report.first_failure["check"] == "format"
    assert "no member 'certified'" in report.first_failure["detail"]


# Class 4: a pooled level's check reads every camera once per track (and every pooled track)

def _pooled_document(tracks: int, cameras: int, spanning: bool = False) -> dict:
    """The stored triangulation with ``cameras`` more cameras (no track's) and ``tracks`` more
    tracks (track 0's data, claim uncertified), each stating a level pooled over its own run of
    tracks (``spanning``: every track, split at its own index): one pool per track."""
    from geocert.formulations.fractional.determinacy import pooled_level

    result = stored("triangulation_l2l2")
    certificate = result["certificate"]
    certificate["data"]["cameras"] += [[[1, 2, 3, 4], [5, 6, 7, 8], [9, 1, 2, 3]] for _ in range(cameras)]
    track, claim, returned = certificate["data"]["tracks"][0], certificate["items"][0], result["tracks"][0]
    first = len(certificate["items"])
    total = first + tracks
    for index in range(first, total):
        certificate["data"]["tracks"].append(copy.deepcopy(track))
        certificate["items"].append({**copy.deepcopy(claim), "index": index, "status": "not_certified",
                                     "certified": False, "lower_bound": None, "gap": None, "proof": None})
        entry = {**copy.deepcopy(returned), "status": "not_certified", "certified": False, "lower_bound": None,
                 "gap": None, "certificate": None, "reason": "node_limit", "nodes": 0}
        entry["determinacy"].update(level=pooled_level((1.0, 1)), cost_increase=1e300,
                                    pooled_tracks=[[0, index], [index, total]] if spanning else [[index, index + 1]])
        result["tracks"].append(entry)
    result["stats"]["items"] += tracks
    result["stats"]["statuses"]["not_certified"] = tracks
    # each level states the most degrees of freedom its pool may give (review 49 refuses a figure
    # beyond its pool's), so that what is measured here is the pools' cost, not that refusal
    from geocert.verify.fractional import _Pools

    pools = _Pools(result, certificate)
    for entry in result["tracks"][first:]:
        bounds = pools.bounds(entry["determinacy"]["pooled_tracks"])
        entry["determinacy"]["level"] = pooled_level((1.0, 1 if bounds is None else bounds[2]))
    rehash(certificate)
    return json.loads(json.dumps(result))


def _counting(monkeypatch, module, name: str, size) -> list:
    counted = [0]
    original = getattr(module, name)

    def counting(*args):
        counted[0] += size(*args)
        return original(*args)

    monkeypatch.setattr(module, name, counting)
    return counted


def test_pooled_levels_read_the_cameras_a_bounded_number_of_times(monkeypatch):
    from geocert.verify import fractional

    document = _pooled_document(tracks=40, cameras=2000)
    cameras = len(document["certificate"]["data"]["cameras"])
    read = _counting(monkeypatch, fractional, "normalised_cameras", lambda c: len(c))
    report = verify_any(document)
    assert not report.valid  # the levels stated are refused, once their pools are read
    assert read[0] <= 4 * cameras, f"{read[0]} cameras normalised for a document of {cameras}"


def test_pooled_levels_sum_each_tracks_residuals_a_bounded_number_of_times(monkeypatch):
    from geocert.verify import fractional

    document = _pooled_document(tracks=40, cameras=0, spanning=True)
    tracks = len(document["certificate"]["data"]["tracks"])
    summed = _counting(monkeypatch, fractional, "squared_residuals", lambda *args: 1)
    report = verify_any(document)
    assert not report.valid
    assert summed[0] <= 4 * tracks, f"{summed[0]} residual sums for a document of {tracks} tracks"


def test_pooled_levels_are_paid_from_the_work_budget():
    """What each pool stated anew still costs (its tracks gathered, pooled_floor over them) is
    charged, a unit a track: a document stating more pools than its size pays for is refused."""
    from geocert.core.strict import Invalid, work_budget
    from geocert.verify import fractional

    document = _pooled_document(tracks=40, cameras=0, spanning=True)
    pools = fractional._Pools(document, document["certificate"])
    with work_budget(100), pytest.raises(Invalid, match="more work than its size pays for"):
        for index, track in enumerate(document["tracks"]):
            fractional._check_pooled(index, track["determinacy"], document, pools)


def test_a_pool_stated_by_every_track_is_paid_once():
    """The writer's pools (every track of a batch states the same runs) cost a unit a track once."""
    from geocert.core.strict import _WORK, work_budget
    from geocert.verify import fractional

    document = _pooled_document(tracks=40, cameras=0)
    tracks = len(document["tracks"])
    from geocert.formulations.fractional.determinacy import pooled_level

    most = fractional._Pools(document, document["certificate"]).bounds([[0, tracks]])[2]  # the level's figure
    for track in document["tracks"]:
        if "pooled_tracks" in track["determinacy"]:
            track["determinacy"].update(pooled_tracks=[[0, tracks]], level=pooled_level((1.0, most)))
    # the pool's cost: a unit a track, and its quantiles (pooled_floor.charge_quantiles, review 52)
    once = fractional._Pools(document, document["certificate"])
    with work_budget(10 ** 9):
        once.bounds([[0, tracks]])
        cost = 10 ** 9 - _WORK.get()[0]
    assert cost >= tracks
    pools = fractional._Pools(document, document["certificate"])
    with work_budget(cost):  # short of paying for a second pool of them all (a unit a track again)
        for index, track in enumerate(document["tracks"]):
            fractional._check_pooled(index, track["determinacy"], document, pools)
    assert list(pools.pooled) == [((0, tracks),)]


# Class 5: the values hash copies the data

def test_the_hashes_take_memory_in_proportion_to_the_text():
    import tracemalloc

    from geocert.verify.checks import _check_hashes, checked_options

    result = stored("triangulation_l2l2")
    certificate = result["certificate"]
    certificate["data"]["cameras"] += [[[1, 2, 3, 4], [5, 6, 7, 8], [9, 1, 2, 3]] for _ in range(25_000)]
    rehash(certificate)
    text = json.dumps(certificate, separators=(",", ":"))
    document = json.loads(text)
    options = checked_options(document["kind"], document["options"])
    tracemalloc.start()
    try:
        _check_hashes(document, options)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    # one canonical text of the data, and its bytes: about 4 times the text (3.5 MB here)
    assert peak <= 8 * len(text), f"{peak / 1e6:.1f} MB to hash a document of {len(text) / 1e6:.2f} MB"


def test_the_document_with_unused_cameras_verifies():
    """The premise of class 5: cameras no track uses are data a job may send."""
    result = stored("triangulation_l2l2")
    result["certificate"]["data"]["cameras"] += [[[1, 2, 3, 4], [5, 6, 7, 8], [9, 1, 2, 3]] for _ in range(100)]
    rehash(result["certificate"])
    report = verify_any(result)
    assert report.valid, report.first_failure


# What held (plain tests): a bare certificate with a member beyond its format, and a bilinear
# document's data member no solver takes, are refused; the value hashes themselves are injective
# on the values every reader reads (an int and a float hash alike only where they are equal,
# -0.0 as 0.0 only where no reader tells them apart: no check of these kinds reads a sign of
# zero; booleans, strings and null keep their types; integers beyond float range are kept as
# written and refused by the readers); a document of the earlier (text) form is read only where
# its data hash so, and that form distinguishes more, not less.

@pytest.mark.parametrize("path", [("weights",), ("frames", 0, "weights")])
def test_a_bilinear_data_member_no_solver_takes_is_refused(path):
    result = _with_member("bilinear_l2l2", path, [1.0, 1000.0])
    report = verify_any(result)
    assert not report.valid and report.first_failure["check"] == "data"
    assert "unknown field" in report.first_failure["detail"]


@pytest.mark.parametrize("name", ["triangulation_l2l2", "resection_l2l2", "homography2_l2l2", "bilinear_l2l2"])
@pytest.mark.parametrize("option, value, valid", [("abs_gap", -0.0, True), ("abs_gap", 5e-324, True),
                                                  ("rel_gap", -0.0, False), ("max_residual", 5e-324, False)])
def test_options_at_float_extremes_are_read_as_their_values(name, option, value, valid):
    """A stricter abs_gap (-0.0 is 0) leaves the claims true (rel_gap certifies them); a rel_gap of
    -0.0 leaves their gaps beyond the tolerance; a max_residual of the least subnormal puts every
    solution beyond the scope."""
    result = stored(name)
    if option not in result["certificate"]["options"]:
        pytest.skip(f"{name} states no {option}")
    result["certificate"]["options"][option] = value
    rehash(result["certificate"])
    report = verify_any(result)
    assert report.valid is valid, report.first_failure

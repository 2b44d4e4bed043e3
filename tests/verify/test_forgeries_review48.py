"""Review 48: a hostile review of the hashes written from the data's text (certificates.data_digest,
_VALUE_TOKENS, the three forms checks._check_hashes reads), of the carried certificate's members
(checks.CERTIFICATE_MEMBERS), of the data members a kind takes (Verification.check_data), of the
pooled levels' cache and charge (fractional._Pools) and of the varying calibration.K
(calibration_claim.stated_camera).

Found (a test below for each, marked xfail while the class stands):

1. A reconstruction certificate's data may hold members no writer writes and no check reads: a
   top-level ``"radial_distortion": {"k1": -0.2}`` (the observations then read as distorted
   pixels) or ``"weights"``, a track's ``"weights"`` beside its views and points. Hashed with the
   data (the document rehashed in today's form), the result verifies: no "earlier form" in the
   report's scope, nothing refused. The triangulation kind refuses the very same track member
   (fractional.refuse_unknown_members, review 47 class 2), and a reconstruction's own camera
   certificate (a resection) refuses ``data/maps/0/weights``; the reconstruction's certificate,
   whose points are triangulations of the same tracks, opted out (``check_data = None``).
   The writer's data are exactly {cameras, views, tracks, input_labels} (kinds.reconstruction.
   certificate_data), each track {views, points}, and input_labels {view_names, image_sizes,
   track_numbers} (already closed: _check_labels).
   Where: verify/reconstruction.py, ReconstructionItems.check_data = None. Suggested fix: a
   check_data refusing what certificate_data does not write (top level: cameras, views, tracks
   and input_labels, which documents written before labels lack; a track: views, points).

2. A genuine document of the form written before review 45 (Python's text hashed:
   canonical_json({"kind", "data", "options", "form"}), its claimed options as floats) is
   refused "data_hash" when its data's text has no integer and no -0.0 (a homography's or a
   resection's coordinates all floats, as most clients write them) and an option it hashes is
   -0.0 (``"abs_gap": -0.0`` or ``"rel_gap": -0.0``, which the options take: >= 0 holds), or
   holds an integer inside a member (an autocalibration's ``"intrinsics": {"focal": [400,
   4000]}``, the most natural way to write a range, beside its cameras, points and an image size
   written as floats; ``{"skew": [-0.0, 0.0]}`` alike). Its
   data_sha256 matches the values' form too (the two texts are the same bytes), so
   _check_hashes reads the document as of the values' form and hashes its options as values
   (0.0, 400.0), never trying Python's text (-0.0, 400) it was written in: "problem_sha256 is ..., but the
   kind, data and options hash to ...". The same document with "abs_gap": 0.0 verifies; docs
   and _check_hashes promise documents hashed before are read in their form.
   Where: verify/checks.py, _check_hashes: ``values`` is decided by the data hash alone (the
   first form it matches: values, then exact integers, then Python's text), and every problem
   hash after it (marked, unmarked, earlier forms) is tried in that one form only. Suggested
   fix: try the problem hash in every form the data hash matched (the values' form, the exact
   integers', Python's text), taking the first that matches, each with its own digest.

3. Cost, memory: the values hash's scan of the data's text (certificates._VALUE_TOKENS, run by
   data_digest twice when the values' form does not match: values, then exact integers) matches
   a string with ``"(?:[^"\\]|\\.)*"``, a group repeated once a character, for which Python's
   regular expression engine keeps a backtracking mark each time: about 150 bytes of memory per
   character of a string (tracemalloc: 303 MB for a 2 MB string; a data text of integers, 3.2
   times its size), and as the canonical text writes a non-ASCII character as its escape (6 or
   12 characters), about 380 bytes per byte of a document's UTF-8 text of "\u00e9" or an emoji
   (a 1 MB string of "\u00e9": 380 MB). docs/certificate.md says the hashes take "about 4 times the data's text in
   memory". The hash runs before any check reads the data (check_data refuses an unknown member
   after it; a reconstruction's data are not closed at all, class 1), so any document can carry
   one long string: a 5 MB triangulation certificate whose data hold a member "note" of 5
   million characters peaked at 639 MB (from 51) to be refused "data_hash", a 20 MB one at 2.4 GB
   (6.2 s of CPU); the API takes bodies up to 32 MiB (GEOCERT_MAX_BODY_BYTES) and runs two
   verifications at once: some 8 GB for two such bodies of ASCII, 20 GB or more of accented text, which review 47 class 5 (1.2 GB for 28
   MB) was fixed to avoid.
   Where: core/certificates.py, _VALUE_TOKENS' string alternative. Suggested fix: the unrolled
   loop ``"[^"\\]*(?:\\.[^"\\]*)*"`` (a single-character class repeated: no mark a character),
   the same tokens: a 10 MB string scanned in 0.05 s with no memory beyond the text, against 0.9
   s and 1.15 GB today (Python 3.11).

Held (plain tests below, each able to fail):

- The text hashed is canonical_json(hashed_numbers(data)) to the byte for strings, keys and
  escapes built to look like numbers ("-0.0", "1", '\\"1', "\\\\", a key "0", unicode escapes
  next to digits, numbers beside strings ending in backslashes), every float form Python writes
  (1e+20, 1e-05, -0.05, 10.0, 5e-324) and integers at and beyond 2**53 and the float range.
- The three accepted forms (values, exact integers, Python's text) coincide only on data the
  verifier reads alike: an integer read exactly (reconstruction track numbers, type int) is
  bounded by summary.tracks, which counts the points, so a 2**53 + 1 / 2**53 pair that hashes
  alike is refused; view indices as floats are refused (review 46).
- Every stored certificate and result (tests/data/certificates, earlier/ included, which is
  refused for its over-claim as before) verifies as it did; a genuine varying reconstruction
  verifies as written and as JavaScript re-writes it (640.0 as 640).
- A varying calibration.K after the sanity layer drops a camera (six views, the dropped one above
  the middle focal length): the writer picks again among the five returned
  (pipeline._stated_K) and the verifier agrees, as written and as JavaScript re-writes it; the
  six cameras' middle restated is refused. With a principal point per view (simple model,
  principal_point "per_view", eight views, each its own centre) the middle principal point's
  camera is stated and verifies, re-written too; points_used beside the calibration
  certificate is its count.
- A carried reconstruction's camera and calibration certificates with a member beyond the
  format's are refused (the bare certificate's rule).
- Note, not a class: geocert.jobs.runner.solve_job (the library's entry; its docstring calls it
  the CLI's path) solves a job whose data hold an unknown member ("note") without validating it
  and writes a certificate the verifier refuses ("data/note: unknown field"); the CLI and the API
  validate the request model first, so neither writes one.
- _Pools' cache key is the runs' tuple of ints (type int, increasing, disjoint): two different
  pools cannot share a key.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math

import numpy as np
import pytest

from geocert.core.certificates import canonical_json, data_digest, data_hash, hashed_numbers
from geocert.jobs.runner import solve_job
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import rehash
from tests.verify.test_forgeries_review46 import _varying_job
from tests.verify.test_forgeries_review47 import _as_a_double_reader_writes


@pytest.fixture(scope="module")
def varying() -> dict:
    """A genuine reconstruction (six views, a focal length each) of today's form."""
    return json.loads(json.dumps(solve_job(_varying_job())))


# Class 1: a reconstruction's data members beyond the writer's verify

def test_the_genuine_reconstruction_verifies_as_written_and_as_javascript_writes_it(varying):
    assert set(varying["certificate"]["data"]) == {"cameras", "views", "tracks", "input_labels"}
    report = verify_any(varying)
    assert report.valid, report.first_failure
    rewritten = json.loads(json.dumps(_as_a_double_reader_writes(varying)))
    report = verify_any(rewritten)
    assert report.valid, report.first_failure


def _with_member(result: dict, where: str) -> dict:
    forged = copy.deepcopy(result)
    data = forged["certificate"]["data"]
    if where == "top distortion":
        data["radial_distortion"] = {"k1": -0.2}
    elif where == "top weights":
        data["weights"] = [1000.0] + [1.0] * (len(data["tracks"]) - 1)
    else:
        data["tracks"][0]["weights"] = [1000.0] + [1.0] * (len(data["tracks"][0]["views"]) - 1)
    rehash(forged["certificate"], marked=True)  # today's form: the report's scope says nothing of an earlier one
    return forged


@pytest.mark.parametrize("where", ["top distortion", "top weights", "track weights"])
def test_a_reconstruction_data_member_no_writer_writes_is_refused(varying, where):
    report = verify_any(_with_member(varying, where))
    assert not report.valid
    assert report.first_failure["check"] == "data"


def test_the_same_member_in_a_reconstructions_camera_certificate_is_refused(varying):
    forged = copy.deepcopy(varying)
    forged["camera_certificate"]["data"]["maps"][0]["weights"] = [1.0]
    rehash(forged["camera_certificate"], marked=True)
    report = verify_any(forged)
    assert not report.valid and "weights" in report.first_failure["detail"]


# Held: the hashed text is canonical_json(hashed_numbers(data)), to the byte

ADVERSARIAL = [
    {"a": "-0.0", "b": -0.0, "c": "1", "d": 1, "0": [0, -0.0, "0"]},
    {"x\\": 1, "y": "\\", "z": ["\\\"1", 2, "\"", 3, "\\\\", -4]},
    {"\u00e9": "\u00e91\u00e9", "k": ["\u20ac-0.0", -0.0, "\ud800", 7]},
    {"f": [1e20, 1e-05, -0.05, 10.0, 5e-324, -1e-300, 123456789.0, 0.0, 100]},
    {"i": [2 ** 53, 2 ** 53 + 1, -(2 ** 53) - 1, 10 ** 22, 10 ** 400, -(10 ** 400)]},
    {"nested": [[[-0.0, [0]], {"1e5": 1, "-1": "-1", "": ""}]], "t": [True, False, None]},
    {"s": "a\"b\\\"c\\\\\"-0.0", "n": -0.0},
    {"ctrl": "\n\t\u0001-0.0\b", "after": [-0.0, 3]},
]


@pytest.mark.parametrize("data", ADVERSARIAL)
def test_the_text_hashed_is_the_values_text_to_the_byte(data):
    expected = hashlib.sha256(b'{"data":' + canonical_json(hashed_numbers(data)) + b",").hexdigest()
    assert data_digest(data).hexdigest() == expected
    # the form of the documents written before: Python's text of the data as it is
    assert data_digest(data, values=False).hexdigest() == hashlib.sha256(
        b'{"data":' + canonical_json(data) + b",").hexdigest()


def test_strings_that_look_like_numbers_hash_apart_from_the_numbers():
    assert data_hash("triangulation", {"a": "1"}) != data_hash("triangulation", {"a": 1})
    assert data_hash("triangulation", {"a": "-0.0"}) != data_hash("triangulation", {"a": "0.0"})
    assert data_hash("triangulation", {"a": -0.0}) == data_hash("triangulation", {"a": 0})


# Held: track numbers are the only integers of a reconstruction's data read exactly, and they are bounded

def test_track_numbers_beyond_the_floats_are_refused_though_they_hash_alike(varying):
    documents = []
    for number in (2 ** 53 + 1, 2 ** 53):
        forged = copy.deepcopy(varying)
        forged["certificate"]["data"]["input_labels"]["track_numbers"][0] = number
        forged["points"][0]["track"] = number
        rehash(forged["certificate"], marked=True)
        documents.append(forged)
    assert documents[0]["certificate"]["data_sha256"] == documents[1]["certificate"]["data_sha256"]
    for forged in documents:
        report = verify_any(forged)
        assert not report.valid


# Held: the varying calibration.K picked again after the sanity layer drops a camera

@pytest.fixture(scope="module")
def varying_dropped() -> dict:
    """The six-view varying job with view 4 (940 px, above the middle) observed at 6 px of noise
    and options.threshold_px 2: the sanity layer drops it after the adjustment, and the middle
    focal length of the five cameras returned is another camera's than the six's."""
    job = _varying_job()
    rng = np.random.default_rng(3)
    for track in job["data"]["tracks"]:
        track["points"][4] = (np.array(track["points"][4]) + rng.normal(0, 6.0, 2)).tolist()
    job["options"]["threshold_px"] = 2.0
    return json.loads(json.dumps(solve_job(job)))


def test_a_varying_result_with_a_camera_dropped_states_the_middle_of_those_returned(varying_dropped):
    cameras = varying_dropped["cameras"]
    assert cameras[4]["registered"] is False and cameras[4]["reason"].startswith("dropped")
    focals = sorted(c["K"][0][0] for c in cameras if c["registered"])
    assert len(focals) == 5
    assert varying_dropped["summary"]["calibration"]["K"][0][0] == focals[2]
    for document in (varying_dropped, json.loads(json.dumps(_as_a_double_reader_writes(varying_dropped)))):
        report = verify_any(document)
        assert report.valid, report.first_failure


def test_a_varying_result_with_a_camera_dropped_refuses_the_six_cameras_middle(varying_dropped):
    forged = copy.deepcopy(varying_dropped)
    registered = sorted((c for c in forged["cameras"] if c["registered"]), key=lambda c: c["K"][0][0])
    other = registered[3]["K"]  # the middle of the six before the drop: the writer's pick before _stated_K
    forged["summary"]["calibration"]["K"] = other
    for stage in forged["stages"]:
        if stage["name"] == "bundle_adjustment" and "K" in stage:
            stage["K"] = other
    depth = forged["summary"].get("depth_reversal")
    if isinstance(depth, dict) and "focal_px" in depth:
        depth["focal_px"] = other[0][0]
    report = verify_any(forged)
    assert not report.valid and "summary/calibration/K" in report.first_failure["detail"], report.first_failure


# Class 2: a document hashed before review 45 whose data text is the same in both forms, an option -0.0

def _floats(value):
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    if isinstance(value, (int, float)):
        return float(value)
    if isinstance(value, list):
        return [_floats(item) for item in value]
    return {key: _floats(item) for key, item in value.items()}


def _hashed_before_review_45(certificate: dict) -> dict:
    """The hashes as the writer before review 45 wrote them (certificates at 10f9a4fd^): Python's
    text of {"kind", "data"} and of {"kind", "data", "options", "form"}, the claimed options as
    floats."""
    from geocert.core.certificates import CLAIM_OPTIONS
    from geocert.kinds import get_kind

    verification = get_kind(certificate["kind"]).verification
    names = getattr(verification, "claim_options", None) or CLAIM_OPTIONS
    claimed = {name: certificate["options"].get(name) for name in names}
    claimed = {name: float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else value
               for name, value in claimed.items()}
    hashed = {"kind": certificate["kind"], "data": certificate["data"], "options": claimed}
    if getattr(verification, "hash_marks", None):
        hashed["form"] = verification.hash_marks
    certificate["data_sha256"] = hashlib.sha256(
        canonical_json({"kind": certificate["kind"], "data": certificate["data"]})).hexdigest()
    certificate["problem_sha256"] = hashlib.sha256(canonical_json(hashed)).hexdigest()
    return certificate


def _map_result(kind: str, option: str, value: float) -> dict:
    from geocert.kinds import get_kind

    example = get_kind(kind).example
    job = {**example, "data": _floats(example["data"]),
           "options": {**example.get("options", {}), "certificate": "full", option: value}}
    result = json.loads(json.dumps(solve_job(job)))
    _hashed_before_review_45(result["certificate"])
    return result


@pytest.mark.parametrize("kind", ["homography", "resection"])
def test_a_document_hashed_before_review_45_verifies(kind):
    report = verify_any(_map_result(kind, "abs_gap", 0.0))
    assert report.valid, report.first_failure


@pytest.mark.parametrize("kind,option", [("homography", "abs_gap"), ("resection", "rel_gap")])
def test_a_document_hashed_before_review_45_with_an_option_minus_zero_verifies(kind, option):
    result = _map_result(kind, option, -0.0)
    certificate = result["certificate"]
    assert math.copysign(1.0, certificate["options"][option]) == -1.0  # as the user sent it, kept by the writer
    assert data_hash(kind, certificate["data"]) == certificate["data_sha256"]  # the data's two texts the same
    report = verify_any(result)
    assert report.valid, report.first_failure


@pytest.mark.parametrize("intrinsics", [{"focal": [400, 4000]}, {"skew": [-0.0, 0.0]}])
def test_an_autocalibration_hashed_before_review_45_with_integer_ranges_verifies(intrinsics):
    from geocert.kinds import get_kind

    example = get_kind("autocalibration").example
    job = {**example, "data": _floats(example["data"]),
           "options": {**example.get("options", {}), "certificate": "full", "intrinsics": intrinsics}}
    result = json.loads(json.dumps(solve_job(job)))
    assert result["certificate"]["options"]["intrinsics"] == intrinsics  # kept as sent
    assert verify_any(result).valid  # as today's writer hashes it
    certificate = _hashed_before_review_45(result["certificate"])
    assert data_hash("autocalibration", certificate["data"]) == certificate["data_sha256"]
    report = verify_any(result)
    assert report.valid, report.first_failure


def test_an_autocalibration_hashed_before_review_45_with_float_ranges_verifies():
    from geocert.kinds import get_kind

    example = get_kind("autocalibration").example
    job = {**example, "data": _floats(example["data"]),
           "options": {**example.get("options", {}), "certificate": "full", "intrinsics": {"focal": [400.0, 4000.0]}}}
    result = json.loads(json.dumps(solve_job(job)))
    _hashed_before_review_45(result["certificate"])
    report = verify_any(result)
    assert report.valid, report.first_failure


# Class 3: the scan of a long string takes memory ~150 times its length

def _peak(data) -> float:
    import tracemalloc

    size = len(canonical_json(data))
    tracemalloc.start()
    try:
        data_digest(data)
        data_digest(data, exact_integers=True)
        return tracemalloc.get_traced_memory()[1] / size
    finally:
        tracemalloc.stop()


def test_hashing_a_long_string_takes_memory_in_proportion_to_the_text():
    assert _peak({"cameras": [], "note": "a" * 1_000_000}) < 8


def test_hashing_integers_takes_memory_in_proportion_to_the_text():
    assert _peak({"cameras": list(range(200_000)), "note": "short"}) < 8


# Held: a principal point per view, the middle principal point's camera stated

@pytest.fixture(scope="module")
def per_view() -> dict:
    """Eight views of one focal length (800 px), each its own principal point (25 px apart), 0.3 px
    of noise, principal_point "per_view": the test keeps a principal point per view."""
    from geocert.solvers.autocalibration import scenes

    rng = np.random.default_rng(11)
    X = rng.uniform(-1, 1, size=(150, 3))
    cameras = []
    for _ in range(8):
        polar, azimuth = np.radians(50) * np.sqrt(rng.uniform()), rng.uniform(0, 2 * np.pi)
        centre = 6 * np.array([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), -np.cos(polar)])
        R = scenes.look_at(centre, 0.3 * rng.normal(size=3), rng, up=rng.normal(size=3))
        K = np.array([[800.0, 0, 320.0 + 25 * rng.normal()], [0, 800.0, 240.0 + 25 * rng.normal()], [0, 0, 1]])
        cameras.append(K @ np.hstack([R, (-R @ centre)[:, None]]))
    tracks = []
    for x in X:
        images = [P @ np.append(x, 1.0) for P in cameras]
        tracks.append({"views": list(range(8)),
                       "points": [(p[:2] / p[2] + rng.normal(0, 0.3, 2)).tolist() for p in images]})
    return json.loads(json.dumps(solve_job({
        "kind": "reconstruction", "options": {"certificate": "full", "principal_point": "per_view"},
        "data": {"views": [{"name": f"v{i}", "image_size": [640, 480]} for i in range(8)], "tracks": tracks}})))


def test_a_principal_point_per_view_states_the_middle_principal_points_camera(per_view):
    from geocert.formulations.reconstruction import calibration_claim

    stage = next(s for s in per_view["stages"] if s["name"] == "bundle_adjustment")
    assert stage["principal_point_per_view"]["estimated"] is True
    Ks = [c["K"] for c in per_view["cameras"] if c["registered"]]
    centres = {(K[0][2], K[1][2]) for K in Ks}
    assert len(centres) == 8 and len({K[0][0] for K in Ks}) == 1
    claim = per_view["summary"]["calibration"]
    assert claim["model"] == "varying"
    assert claim["K"] == Ks[calibration_claim.middle_centre([[K[0][2], K[1][2]] for K in Ks])]
    for document in (per_view, json.loads(json.dumps(_as_a_double_reader_writes(per_view)))):
        report = verify_any(document)
        assert report.valid, report.first_failure


def test_a_principal_point_per_view_with_another_cameras_K_is_refused(per_view):
    forged = copy.deepcopy(per_view)
    stated = forged["summary"]["calibration"]["K"]
    other = next(c["K"] for c in forged["cameras"] if c["registered"] and c["K"] != stated)
    forged["summary"]["calibration"]["K"] = other
    for stage in forged["stages"]:
        if stage["name"] == "bundle_adjustment" and stage.get("K") == stated:
            stage["K"] = other
    report = verify_any(forged)
    assert not report.valid and "summary/calibration/K" in report.first_failure["detail"], report.first_failure

"""Review 61: a hostile review of the certificates for issue 33, where review 59 left off: the map
estimates read in normalised coordinates (fractional.normalisation, determinacy.map_, the
verifier's width slack MAP_WIDTH_SLACK + spread), the proof checks' floating-point hygiene
(stratified, direct, bilinear) and result fields or embedded certificates no check ties.

Tried (each forgery built from a genuine document, its hashes made again where the data moved,
verify_any run):

- Map estimates in other units and far off the origin (review 58's resection fixture, its second
  map uncertified and restated by its writers, restated_map): targets in pixels of 1 to 1e-200
  (36 scalings, the widths compared with the unit pixel's); the world in units of 1e-100 to
  1e-315 (31 scalings); targets the exact projections of the source (no noise) or with 1e-9 to
  1e-4 px of noise, moved 1e3 to 5e8 off the origin, the world x1, x10 or x1e-3 (31 documents),
  each interval collapsed to a thousandth of its width one at a time and all at once, and all
  narrowed by 0.2% to 50% (9 shares each). Degenerate sources (all but two points coincident, all
  but three within 1e-9, collinear, planar, each exact and with 1e-6 of noise off it: 18
  documents of the stored 3-D homography and resections). The stored 3-D and 2-D homographies with
  the source or the targets in units of 1e-280 to 1e-305 (16). Homographies solved with 400 and
  2,000 matches 1e6 and 1e8 px off the origin, 0.5 to 300 px of noise (4 documents, 8 shares of
  narrowing each). Bilinear frames with their points and camera in units of 1e-100 to 1e-305 (28)
  and triangulation tracks in world units of 1e-100 to 1e-302 (12 documents, 30 estimates).
  Resection jobs solved with the world x1e-150, x1e-300, x1e6 or moved 1e8 off (6, their proven
  intervals probed with 6,000 cameras each: none within the level outside them).
- Proof numbers (autocalibration_stratified, autocalibration_direct, bilinear_l2l2; in a second
  run autocalibration_five_views, autocalibration_world_scale, autocalibration_direct_points,
  bilinear_l1l1): up to 60 numbers drawn from each certified item's proof, each set to 5e-324,
  -5e-324, 0, -0.0, 1e308, 1e-300, the smallest normal, negated, doubled or halved; each dual
  vector (base64) scaled by 1e300, 1e-300 or 2^-1000, negated, every nonzero entry set to the
  smallest normal, or times 1 + 1e-3 (2,806 forgeries in the first run, 4,436 in the second).
  Accepted only: a recorded bound lowered (informational, at most what the vector proves), a cap
  raised, a proof's box edited where its leaves still lie inside it, 0 and -0.0 exchanged, a dual
  vector times 1 + 1e-3 where the bound it still proves suffices (any vector's safe bound is a
  bound), and edits of proofs whose claim is the trivial 0 (the stored stratified affine stage:
  its leaves' corners widened to 1e308, its regions' frame, rows and unit edited; the direct
  method's with chirality points, its vector negated or flushed to the smallest normal).
- Result fields (7 stored documents of bilinear, autocalibration, triangulation, resection and
  homography: every field outside the certificate, determinacy and residuals, each number times
  1 + 1e-6, negated or 5e-324, each boolean flipped, each string edited, 2,065 forgeries; the
  residuals of 6 documents, 278; the autocalibration results' cameras, points, upgrade, quadric,
  plane, K and baseline moved by 1e-6 to 10%, 126; the stored reconstruction's camera and point
  fields, 153): accepted only edits within the stated rounding (1e-6 of the largest entry, 1e-9
  of a residual's terms), timings, and in the reconstruction reason words beside a certified
  camera (another helper's class). Item summaries (``certificate`` of tracks, maps, frames and
  stages of 12 stored documents: every number times 2 plus 1, minus it less 1, 1e6, 5e-324, times
  1 + 1e-9, each string edited: 1,535 forgeries): accepted only the 1e-9 edits (the documented
  rounding) and the direct stage's conic_status text (documented as informational).
- Embedded certificates swapped (12 stored documents of triangulation, resection, homography and
  bilinear: each item's summary, determinacy and proof swapped with another item's of the same
  document and of another document of the kind, whole certificates swapped, options swapped and
  the hashes made again: 236 forgeries): accepted only where the options swapped were equal but
  for job_time_limit_s (no claim moves).

Found (a test below for each, failing on the code before its fix):

1. A resection's determinacy ends are compared with the verifier's as absolute numbers, with the
   value's floor (estimates._map_value_floor: 8 eps of the source's largest coordinate) and
   MAP_VALUE_ROUNDING of the value added to each end's slack, not as offsets from the value as a
   track's and a far homography's are (review 37 classes 2 and 3). Where the data fit well (an exact
   projection, 1e-6 px of noise) the centre's intervals are a few ulps of the data's offset wide:
   review 58's camera 1e8 off the origin, targets projected exactly, gives widths 4.2e-7, 3.1e-7 and
   1.5e-6 beside a floor of 1.8e-7, and its centre_x and centre_y intervals collapsed to a
   thousandth of their width, centre_z 20% narrower, verify beside determined true. Every interval
   narrowed by 30% verifies there, by 10% with 1e-6 px of noise, by 30% 5e6 off the origin
   (UTM-like coordinates, exact fit: widths 1.5e-8 beside a floor of 8.9e-9). At fault:
   verify.estimates._check_maps (the resection's _compare call without offsets); the writer
   states each end as value -+ a half-width it computes in normalised coordinates, so the ends'
   offsets from the value are the quantities to compare. Fixed so: each end is read as its
   offset from the value (to the width's slack and END_OFFSET_ULPS of the end), as a track's.
2. A resection's centre in a tiny world unit gets zero-width intervals: the writer's estimate
   (fractional.determinacy.map_ -> core.determinacy.information_intervals) squares the centre's
   gradient in the world's units, which underflows below about 1e-154: review 58's second map with
   its source x1e-160 states widths 3% narrower than the same data in metres (scaled), x1e-162 to
   x1e-302 widths of exactly 0, tolerance 0 and determined true, for data with 1 px of noise whose
   centre interval is 0.57 of the world unit wide. The verifier recomputes the same underflowed
   estimate and accepts it (verify.estimates._check_maps). Every coordinate is a normal float
   within COORDINATE_LIMIT. The homography (its centroid image, target units), bilinear frames and
   triangulation tracks at the same scales fail safe (unbounded, not determined). (The service
   itself, solving such a job, states inf residuals at x1e-162 and no matrix at x1e-300, so the
   document is made by hand: the true camera in those units, its cost and estimate its writers'.)
   Fixed at the causes: a gradient is scaled by its largest entry before it is squared
   (core.determinacy.information_intervals, for every estimate); the centre's distance, the
   tolerance's scale, is math.hypot's; and the normaliser reads a spread below 1e-150 at a
   power of two (fractional.normalisation: a spread of 1e-180 had read as 0, putting
   the centre at the centroid with widths of 0 beside determined true, from 1e-180 to 1e-280).
   The widths now scale with the unit from 1 to 1e-300 (a test below); at 1e-305 the centre is
   left unbounded.

Held: every dual vector edit, every proof number edit that would change a claim, the item summaries
and embedded certificates swapped, the homographies far off (narrowing beyond 2e-3 refused, the far
path reading ends as offsets, taken even with 300 px of noise), map estimates with targets in tiny
pixels (unbounded where J'J underflows).
"""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from geocert.formulations.fractional.fixed_order import mul
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import refused_naming, rehash, stored
from tests.verify.test_forgeries_review58 import _rescaled, resections, restated_map  # noqa: F401  (the fixture)

pytestmark = pytest.mark.filterwarnings("ignore")


def _valid(document: dict) -> bool:
    return verify_any(json.loads(json.dumps(document))).valid


def _exact_far(result: dict, shift: float) -> dict:
    """The second map's source moved by ``shift`` (along (1, -1/2, 1/3)), the camera restated to
    match, and its targets the source's exact projections through it (no noise), with the cost,
    residuals and estimate its writers state (review 58's ``restated_map``)."""
    data = result["certificate"]["data"]["maps"][1]
    offset = shift * np.array([1.0, -0.5, 1 / 3])
    source = np.array(data["source"]) + offset
    undo = np.eye(4)
    undo[:3, 3] = -offset
    M = mul(np.array(result["certificate"]["items"][1]["matrix"]), undo)  # the same floats under every kernel
    image = mul(np.hstack([source, np.ones((len(source), 1))]), M.T)
    return _current(restated_map(result, source, image[:, :2] / image[:, 2:], M))


def _current(document: dict) -> dict:
    """The document's problem hash of today's form (its estimates' form marked): read as today's
    writer's, never as an earlier form's."""
    rehash(document["certificate"], marked=True)
    return document


def _intervals(document: dict) -> list:
    return document["maps"][1]["determinacy"]["intervals"]


# 1. A resection's ends are read as absolute numbers, each with the value's floor

def test_a_resection_fitting_exactly_far_off_narrowed_is_refused(resections):
    """Review 58's second camera 1e8 off the origin, its targets the exact projections: the
    centre's intervals are 4e-7 to 1.5e-6 wide beside a value floor of 1.8e-7 (8 eps of 1e8), and
    centre_x and centre_y collapsed to a thousandth of their width, centre_z 20% narrower, verified
    (determined true). Fixed: a resection's ends are read as offsets from its value
    (estimates._check_maps)."""
    genuine = _exact_far(resections, 1e8)
    assert _valid(genuine)
    assert genuine["maps"][1]["determinacy"]["determined"] is True
    forged = copy.deepcopy(genuine)
    for found, share in zip(_intervals(forged), (0.999, 0.999, 0.2)):
        half = (1 - share) * (found["upper"] - found["lower"]) / 2
        found["lower"], found["upper"] = found["value"] - half, found["value"] + half
    refused_naming(forged, "returned", "maps/1/determinacy/intervals/")


# 2. A centre in a tiny world unit: its gradient's square underflows, the intervals collapse

def test_a_resection_centre_in_a_tiny_world_unit_stated_exact_is_refused(resections):
    """Review 58's second map with its source x1e-300 (normal floats, 1 px of noise, the centre
    interval 0.57e-300 wide at the same data in metres, scaled): every centre interval stated as
    its value alone, width 0, tolerance 0 and determined true (what the writer states today, its
    gradient's square underflowing), verified."""
    genuine = _current(_rescaled(resections, 1e-300, 1.0))
    assert _valid(genuine)
    forged = copy.deepcopy(genuine)
    for found in _intervals(forged):
        found.update(lower=found["value"], upper=found["value"], tolerance=0.0)
    forged["maps"][1]["determinacy"].update(determined=True, warnings=[])
    refused_naming(forged, "returned", "maps/1/determinacy/")


@pytest.mark.parametrize("unit", [1e-150, 1e-180, 1e-250, 1e-300])
def test_a_resection_centre_in_a_tiny_world_unit_is_scaled(resections, unit):
    """What the class above reads against: the same data in metres (x1) state widths that, scaled
    by the unit, are the ones the writer states in that unit (to 1e-6), the tolerance alike, and
    the document verifies."""
    at_metres, small = _current(_rescaled(resections, 1.0, 1.0)), _current(_rescaled(resections, unit, 1.0))
    widths = [np.array([f["upper"] - f["lower"] for f in _intervals(d)]) for d in (at_metres, small)]
    assert np.all(widths[0] > 0)
    assert np.allclose(widths[1] / unit, widths[0], rtol=1e-6)
    tolerances = [np.array([f["tolerance"] for f in _intervals(d)]) for d in (at_metres, small)]
    assert np.allclose(tolerances[1] / unit, tolerances[0], rtol=1e-6)
    assert _valid(small)


# Held: embedded certificates and summaries swapped between items

@pytest.mark.parametrize("member", ["certificate", "determinacy"])
def test_a_tracks_summary_or_estimate_swapped_with_anothers_is_refused(member):
    genuine = stored("triangulation_l2l2")
    assert _valid(genuine)
    forged = copy.deepcopy(genuine)
    forged["tracks"][0][member] = copy.deepcopy(genuine["tracks"][1][member])
    assert not _valid(forged)


def test_a_tracks_proof_swapped_with_anothers_is_refused():
    genuine = stored("triangulation_l2l2")
    forged = copy.deepcopy(genuine)
    forged["certificate"]["items"][0]["proof"] = copy.deepcopy(genuine["certificate"]["items"][1]["proof"])
    assert not _valid(forged)


# Held: a dual vector rescaled, negated or flushed toward the smallest normal proves nothing

SMALLEST_NORMAL = 2.2250738585072014e-308
RESCALED = {
    "times 2^-1000": lambda z: np.ldexp(z, -1000),
    "times 2^600": lambda z: np.ldexp(z, 600),
    "negated": lambda z: -z,
    "every nonzero entry the smallest normal": lambda z: np.where(z != 0, np.sign(z) * SMALLEST_NORMAL, 0.0),
}


@pytest.mark.parametrize("name,path", [("autocalibration_direct", ("programs", 0, "z")),
                                       ("bilinear_l2l2", ("tightening", 0, "duals", 0))])
@pytest.mark.parametrize("edit", sorted(RESCALED))
def test_a_dual_vector_rescaled_is_refused(name, path, edit):
    from geocert.core.certificates import unpack
    from tests.verify.test_forgeries import raw_pack

    genuine = stored(name)
    forged = copy.deepcopy(genuine)
    holder = forged["certificate"]["items"][0]["proof"]
    for key in path[:-1]:
        holder = holder[key]
    holder[path[-1]] = raw_pack(RESCALED[edit](unpack(holder[path[-1]])))
    assert not _valid(forged)

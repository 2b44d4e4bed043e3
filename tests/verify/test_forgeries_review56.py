"""Review 56: a hostile review of the certificates for issue 33, where reviews 1 to 55 had not
looked: the proven intervals read off a search's leaves (the stratified metric stage's
`sublevel`), the cost of verifying every kind's lists, and proof records' numbers and types.

Tried:

- Proven intervals of the stratified metric stage (tests/data/certificates/
  autocalibration_world_scale.json, the one stored document stating `proven: true`): 250 random
  edits of the sublevel's numbers (its intervals, cost_increase, tightening boxes and caps, the
  proofs' boxes, caps, axes and recorded bounds, the leaves' corners), each set to 5e-324,
  -5e-324, 0, -0.0, 1e300, 1e-300, 10**300, negated, the next float up or down, nudged by 1e-7 or
  times 1e6, the result's proven intervals restated to match where the edit was to the
  intervals or the level.
- Cost of verifying: every list of eight stored documents (direct with chirality points, direct,
  stratified, triangulation L2L2, resection L1L1, homography, bilinear L2L2, reconstruction; one
  list per structural path, 390 lists) repeated until the document grew by about 100,000 units
  of size, each verification timed (CPU).
- Types: an orientation's `delta` written `true` (Python reads true == 1.0) in a stratified
  proof's regions and exclusions and in a direct proof's exclusions; None there.

Found (a test below for each, which failed while the class stood):

1. The direct method's `excluded` list was unbounded: each entry is an exact test (Gordan's
   alternative in rational arithmetic, over chirality rows rebuilt from the data) that no charge
   paid for, and a genuine exclusion repeated verified. The stored direct document with chirality
   points, its one exclusion repeated 20,000 times (0.96 MB), took 9.5 s of CPU to verify
   (valid): about 60 microseconds a unit of size, some 5 minutes for a 32 MB body, every other
   list of the stored documents 0 to 7. Fixed: one exclusion an orientation
   (direct.check_proof), as the stratified proofs have (proofs.check_regions): refused in 0.24 s.
2. A stratified proof's `cut` record stating a `bound` above its cap verified (21,970 beside a
   cap of 0.022 in the proven interval's search): the verifier holds a cut's leaves to its cap
   and the writer records the cap, but the record was read as informational only, the class
   review 41 closed for dual proofs ("a record no proof backs"). Fixed: proofs.check_leaves
   holds a cut's record to its cap, as a dual's to its vector's bound.
3. An orientation's `delta` written `true` in a stratified proof's regions (the affine stage's
   and the plane sublevel's, proofs.check_regions) verified (true == 1.0 in Python's sorted list
   compared with [-1.0, 1.0]), and None there was refused with Python's TypeError as the detail.
   A boolean is never a number in a document (docs/certificate.md). Fixed: each delta must be a
   number before the orientations are compared; direct.check_proof's exclusions alike.

Held (refused, or accepted only where the claim stays true):

- The sublevel's intervals: only a wider interval verified (a lower end set to 5e-324: a weaker
  true statement); every narrowing, shift, or level raised was refused. Its other edits that
  verified left the leaves covering the box with each bound recomputed: leaf corners moved within
  overlaps, proof boxes moved by an ulp or set to 0 where the leaf still lies inside, a cut's cap
  lowered (its leaves kept in the hull: wider, not narrower), recorded bounds lowered.
- Repeating any other list: refused, or accepted where each repeated entry is itself checked
  and claims nothing new (a proof's leaves or proofs repeated, a region's rows, a
  reconstruction's motion warnings and informational figures: focal rounds, the initial pair
  search's views, the certificate summary's conic_status), at 0 to 7 microseconds a unit of
  size.

Found, not fixed: none.
"""

from __future__ import annotations

import copy
import json

import pytest

from geocert.formulations.autocalibration import frames
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import refused_naming, stored

pytestmark = pytest.mark.filterwarnings("ignore")


def _valid(document: dict) -> bool:
    return verify_any(json.loads(json.dumps(document))).valid


# 1. The direct method's exclusions: one an orientation, and no more exact tests than orientations

def test_direct_exclusions_are_one_an_orientation_and_pay_no_repeated_exact_test(monkeypatch):
    document = stored("autocalibration_direct_points")
    assert _valid(document)
    proof = document["certificate"]["items"][0]["proof"]
    assert len(proof["excluded"]) == 1
    calls = []
    exact = frames.exact_gordan

    def counted(rows, chosen):
        calls.append(1)
        return exact(rows, chosen)

    monkeypatch.setattr(frames, "exact_gordan", counted)
    forged = copy.deepcopy(document)
    forged["certificate"]["items"][0]["proof"]["excluded"] = proof["excluded"] * 1000
    report = verify_any(json.loads(json.dumps(forged)))
    # whatever the list's length, at most one exact test an orientation (two orientations)
    assert len(calls) <= 2, len(calls)
    assert not report.valid
    assert report.first_failure["check"] == "format" and "excluded" in report.first_failure["detail"]


# 2. A cut's recorded bound is at most its cap (the bound its leaves are held to)

@pytest.mark.parametrize("name", ["autocalibration_world_scale", "autocalibration_five_views"])
def test_a_cut_recording_a_bound_above_its_cap_is_refused(name):
    document = stored(name)
    holders = []
    for claim in document["certificate"]["items"]:
        proof = claim.get("proof") or {}
        holders += ([proof] + list(proof.get("regions") or [])
                    + ([proof["sublevel"]] if isinstance(proof.get("sublevel"), dict) else []))
    cuts = [(holder, i) for holder in holders for i, item in enumerate(holder.get("proofs") or [])
            if item.get("kind") == "cut"]
    assert cuts, "the stored document has cut proofs"
    holder, i = cuts[0]
    cut = holder["proofs"][i]
    assert cut["bound"] == cut["upper_bound"]  # the writer records the cap
    cut["bound"] = cut["upper_bound"] * 1e6
    # the bound a cut's leaves are held to, its cap, not a dual vector's
    refused_naming(document, "leaf_bounds", f"proofs/{i}/bound", "(the cap)")


def test_a_cut_recording_its_cap_or_less_verifies():
    document = stored("autocalibration_world_scale")
    sublevel = document["certificate"]["items"][1]["proof"]["sublevel"]
    cut = next(item for item in sublevel["proofs"] if item["kind"] == "cut")
    cut["bound"] = cut["upper_bound"] / 2  # a weaker record: true
    assert _valid(document)


# 3. An orientation's delta is a number, never a boolean

@pytest.mark.parametrize("value", [True, None, "1"])
def test_a_stratified_orientation_stated_as_a_boolean_or_not_a_number_is_refused(value):
    document = stored("autocalibration_stratified")
    proof = document["certificate"]["items"][0]["proof"]
    region = next(r for r in proof["regions"] if r["delta"] == 1.0)
    region["delta"] = value
    refused_naming(document, "root_region", "orientation")

"""Review 44: a hostile review of summary notes (and, on the branch of the autocalibration frame
form it also attacked, of that form: the change was not kept, so its tests are not here).

Found (a test below, which failed while the forgery was accepted; fixed: an uncertified item's
note is checked against no proof, and the writers state none for one):

1. A summary's note on an uncertified item is read from a proof nobody checked. The verifier
   recomputes a certified item's note from its proof (core.summary_notes.note_of) and refuses other
   words; it does the same for an uncertified item (verify/checks.py, _check_summaries calls
   _check_note before it tells certified from uncertified), but an uncertified item's proof is
   never checked (uncertified_claim checks its status, cost, lower_bound and gap; it lets a
   ``proof`` member through). So the stored triangulation's first track made uncertified
   (node_limit, its cost 13.8 kept), its proof replaced by ``{"type": "trivial"}`` and its
   summary's note "the incumbent's cost is within abs_gap of the trivial bound 0" verifies (valid:
   true): a note saying a cost of 13.8 is within abs_gap (1e-9) of 0. ``{"type": "convexity",
   "radius": 1e6}`` with the convexity note ("the cost is convex on the ball of radius 1e6 about the
   solution, which holds every point of the scope costing as little") verifies too. Without a proof
   the same note is refused, as it should be.
   Where: verify/checks.py, _check_summaries (the note of an uncertified item) with
   uncertified_claim (a proof member allowed on an item whose proof is not checked).
   Suggested fix, at the cause: an uncertified item's note is None (no checked proof has words),
   i.e. call _check_note with proof None where the claim is not certified; and better, refuse a
   ``proof`` member on an uncertified claim in uncertified_claim (or read it as absent everywhere),
   since every reading of an unchecked proof (notes, the frame _stated_reference once took from an
   uncertified affine stage, review 36) is a claim nothing backs.


What held (plain tests below): an uncertified item's note without a proof is refused, and the
uncertified item without a note verifies.
"""

from __future__ import annotations

import copy
import json


from geocert.core import summary_notes
from geocert.verify.checks import verify_any
from tests.verify.test_forgeries import stored


def _report(document: dict):
    return verify_any(json.loads(json.dumps(document)))


def _uncertified_track(proof, note) -> dict:
    """The stored triangulation with its first track made uncertified (node_limit, its solution and
    cost kept, no bound or gap) and the stats restated to agree; the claim's proof is ``proof``
    (None: no proof member's content) and its summary's note ``note``."""
    forged = copy.deepcopy(stored("triangulation_l2l2"))
    item, track = forged["certificate"]["items"][0], forged["tracks"][0]
    item.update(certified=False, status="node_limit", lower_bound=None, gap=None, proof=proof)
    track.update(certified=False, status="node_limit", lower_bound=None, gap=None)
    track["certificate"].update(note=note, tolerance_met=False)
    stats = forged["stats"]
    stats["certified"] -= 1
    stats["statuses"] = {"optimal": stats["statuses"]["optimal"] - 1, "node_limit": 1}
    return forged


# Class 1: an uncertified item's note read from its unchecked proof

def test_the_uncertified_track_without_a_note_verifies():
    """The premise: the track restated uncertified (its proof kept, no note) is a valid document, and
    its cost is far from the trivial bound 0."""
    forged = _uncertified_track(stored("triangulation_l2l2")["certificate"]["items"][0]["proof"], None)
    assert _report(forged).valid
    assert forged["tracks"][0]["cost"] > 1.0 > forged["certificate"]["options"]["abs_gap"]


def test_an_uncertified_items_note_without_a_proof_is_refused():
    report = _report(_uncertified_track(None, summary_notes.TRIVIAL))
    assert not report.valid and "note" in str(report.first_failure)


def test_the_trivial_bounds_note_on_an_uncertified_item_is_refused():
    assert not _report(_uncertified_track({"type": "trivial"}, summary_notes.TRIVIAL)).valid


def test_a_convexity_note_on_an_uncertified_item_is_refused():
    radius = 1e6
    assert not _report(_uncertified_track({"type": summary_notes.CONVEXITY, "radius": radius},
                                          summary_notes.convexity(radius))).valid

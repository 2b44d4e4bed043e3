"""What a certified item's certificate summary says, in words, of how its bound was proven (its
``note``). The words are a function of the proof alone, written here once: the writers
(kinds.documents, kinds.bilinear, solvers.fractional.maps) state them and the verifier
(verify.checks._check_summaries) recomputes them from the proof it has checked and refuses any
other text, so that a note cannot claim what no proof shows (review 42: a searched frame costing
1.6 stating the trivial proof's note, a map stating that every other map costs twice as much).

The words have not changed since each was first written (the trivial bound's, the convexity
bound's, the sublevel bound's), so the documents stored before this check state them as they
are here: there is no list of earlier wordings to accept."""

from __future__ import annotations

from typing import Any

TRIVIAL = "the incumbent's cost is within abs_gap of the trivial bound 0"
# The proof types bounded with no search, as their proofs name them (fractional.resection_bound.TYPE
# is this one; tests/verify/test_forgeries_review42.py solves one of each).
CONVEXITY, SUBLEVEL_BOUND = "convexity", "sublevel_bound"


def convexity(radius: float) -> str:
    """A bound proven by the convexity of the cost on a ball about the solution."""
    return (f"no search: the cost is convex on the ball of radius {radius!r} about the solution, which "
            "holds every point of the scope costing as little (convexity bound)")


def sublevel(radius: float, rounds: int) -> str:
    """A resection's bound proven by a quadratic bound over a ball holding its sublevel set."""
    return (f"no search: every camera of the scope costing as little lies in a ball (radius {radius!r}, "
            f"{rounds} rounds, whitened coordinates) over which the cost is bounded below by a quadratic "
            "(sublevel bound, fractional.resection_bound)")


def note_of(proof: Any) -> str | None:
    """The note a certified item's summary states for ``proof`` (the proof its certificate
    document carries): a bound proven with no search says how; a search states none (None)."""
    kind = proof.get("type") if isinstance(proof, dict) else None
    if kind == "trivial":
        return TRIVIAL
    if kind == CONVEXITY:
        return convexity(proof.get("radius"))
    if kind == SUBLEVEL_BOUND:
        return sublevel(proof.get("radius"), proof.get("rounds"))
    return None

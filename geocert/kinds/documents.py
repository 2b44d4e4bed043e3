"""The parts of an item's result document that every fractional kind shares: its outcome (cost,
bounds, status) and its certificate summary (with the proof, when a full certificate was asked
for, until the job's certificate document takes it)."""

from __future__ import annotations

import math

from geocert.solvers.fractional.results import ItemResult, LocalCertificate, proof_of


def finite_or_none(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None


def certificate_summary(result: ItemResult, region: dict, meaning: str, scope: str) -> dict | None:
    """An item's certificate summary (its ``certificate`` member): the search's certificate (when
    there was one), or the note that the incumbent met the trivial bound 0. With a full
    certificate, ``proof`` too (moved into the job's certificate document when the result is
    assembled). Glossary: docs/certificate.md."""
    c = result.certificate
    proof = proof_of(result)
    extra = {"proof": proof} if proof is not None else {}
    if isinstance(c, LocalCertificate):
        return local_summary(c.scope, c.tolerance, c.radius, c.tolerance_met and result.certified, extra)
    if c is not None:
        return {**extra,
                "scope": c.scope,
                "root_region": {**region, "functionals": c.functionals, "denominator": c.denominator,
                                "lower": c.lower, "upper": c.upper, "meaning": meaning},
                "tolerance": finite_or_none(c.tolerance),
                # A search that met its tolerance and was not certified (the verifier would refuse
                # its solution) has met nothing it can show: the summary says so.
                "tolerance_met": c.tolerance_met and result.certified,
                "leaves": c.leaves}
    if result.certified:
        return {"scope": scope, "root_region": None, "tolerance": 0.0, "tolerance_met": True, "leaves": 0,
                "note": "the incumbent's cost is within abs_gap of the trivial bound 0", **extra}
    return None


def local_summary(scope: str, tolerance: float, radius: float, tolerance_met: bool, extra: dict) -> dict:
    """The certificate summary of an item certified by the convexity bound (no search)."""
    return {"scope": scope, "root_region": None, "tolerance": finite_or_none(tolerance),
            "tolerance_met": tolerance_met, "leaves": 0,
            "note": f"no search: the cost is convex on the ball of radius {radius!r} about the solution, which "
                    "holds every point of the scope costing as little (convexity bound)", **extra}


def brief_certificate(result: ItemResult, full: bool) -> dict | None:
    """An item's ``certificate`` member with ``options.detail = "brief"``: nothing, or with a full
    certificate (``full``) only the proof, which the job's certificate document then takes
    (leaving None). A trivial bound's proof exists in every mode: only a full certificate keeps it."""
    proof = proof_of(result) if full else None
    return {"proof": proof} if proof is not None else None


def outcome_document(result: ItemResult) -> dict:
    """The fields every item (track, map, frame) reports about its solve. An item not certified
    states no lower bound or gap: no proof the verifier checks backs the bound its search reached
    (verify.uncertified_claim)."""
    return {
        "cost": finite_or_none(result.cost),
        "lower_bound": finite_or_none(result.lower_bound) if result.certified else None,
        "gap": finite_or_none(result.gap) if result.certified else None,
        "status": result.status,
        "certified": result.certified,
        "nodes": result.nodes,
        "elapsed_s": result.elapsed_s,
        "reason": result.reason,
    }

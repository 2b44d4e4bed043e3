"""The parts of an item's result document that every fractional kind shares: its outcome (cost,
bounds, status) and its certificate summary (with the proof, when a full certificate was asked
for, until the job's certificate document takes it); and a kind's certificate document, built
from its items (the job runner's, and a reconstruction's embedded ones)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from geocert.core import summary_notes
from geocert.core.certificates import FORMAT, VERSION, data_digest, data_hash, problem_hash
from geocert.formulations.fractional.results import ItemResult, LocalCertificate, proof_of


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
        summary = local_summary(c.scope, c.tolerance, c.radius, c.tolerance_met and result.certified, extra, c.note)
        # A note says how a bound was proven: an item not certified proves none (verify.checks refuses one)
        return summary if result.certified else {**summary, "note": None}
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
                "note": summary_notes.TRIVIAL, **extra}
    return None


def local_summary(scope: str, tolerance: float, radius: float, tolerance_met: bool, extra: dict,
                  note: str | None = None) -> dict:
    """The certificate summary of an item certified with no search: by the convexity bound, or
    as ``note`` says."""
    note = note or summary_notes.convexity(radius)
    return {"scope": scope, "root_region": None, "tolerance": finite_or_none(tolerance),
            "tolerance_met": tolerance_met, "leaves": 0, "note": note, **extra}


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


def certificate_document(kind, data: Any, options, items: list[dict]) -> dict:
    """The certificate document (docs/certificate.md): the problem data and its hash, the options,
    and each item's claim (solution, cost, gap) with its proof, taken out of the item's
    certificate summary."""
    claims = []
    data = kind.certificate_data(data, items)  # the data the claims are about (the job's, for most kinds)
    # A kind may prove several claims per item (autocalibration: one per stage).
    claimed = kind.claimed_items(items)
    for index, item in enumerate(claimed):
        proof = (item.get("certificate") or {}).pop("proof", None)
        if item.get("certificate") == {}:  # a brief item's member held the proof alone
            item["certificate"] = None
        solution = {key: item[key] for key in kind.solution_fields if key in item}
        claims.append({"index": index, "status": item["status"], "certified": item["certified"] and proof is not None,
                       "cost": item["cost"], "lower_bound": item["lower_bound"], "gap": item["gap"],
                       **solution, "proof": proof})
    options = dataclasses.asdict(options)
    # Both hashes begin with the data's text: written and hashed once (a reconstruction's data are
    # its photos, megabytes of base64), each hash going on from a copy.
    digest = data_digest(data)
    return {"format": FORMAT, "version": VERSION, "kind": kind.name, "options": options,
            "data": data, "data_sha256": data_hash(kind.name, data, digest=digest),
            "problem_sha256": problem_hash(kind.name, data, options, getattr(kind.verification, "claim_options", None),
                                           getattr(kind.verification, "hash_marks", None), digest=digest),
            "items": claims}

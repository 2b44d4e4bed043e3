"""What one stage of an autocalibration result says (the stratified method's affine and metric
stages, the direct method's one stage: kinds/autocalibration.py and direct_autocalibration.py),
and the self-check every certified stage passes before it is returned."""

from __future__ import annotations

import dataclasses

from geocert.core import proven_reasons
from geocert.kinds.documents import finite_or_none
from geocert.formulations.autocalibration import problem
from geocert.core.strict import Invalid
from geocert.core.self_check import SelfCheckFailed
from geocert.verify.checks import verify_arrays

# The stages' determinacy analyses run until this many seconds past the job's time limit in all
# (its stages' limits), then stop (determinacy.within): a job whose stages ran to their limits
# still says how well its data fix its answer (a critical motion, often why it is not certified),
# and ends within a few seconds of its limit however many views it has (the analyses of 200 views
# took some 0.7 s of CPU, outside any clock). One number with the proven reasons' bound on the
# seconds they state (the verifier reads it there).
ANALYSIS_GRACE_S = proven_reasons.ANALYSIS_GRACE_S


def unproven(full: bool, certified: bool, proof: dict | None, status: str) -> str | None:
    """Why a stage's intervals asked to be proven cannot be (None: they may be): a proof is read
    off a full certificate of a certified stage."""
    if not full:
        return proven_reasons.reason("not_full")
    if not certified or proof is None:
        return proven_reasons.reason("not_certified", status=status)
    return None


def stage_document(name: str, status: str, certified: bool, cost: float, lower: float, nodes: int, elapsed: float,
                   reason: str | None, rel_gap: float, abs_gap: float, scope: str, proof: dict | None) -> dict:
    """A stage's figures as the result states them: certified only when its gap as returned meets
    its tolerance, its lower bound the cost less that gap; an uncertified stage states none."""
    cost_out, lower_out = finite_or_none(cost), finite_or_none(lower)
    gap = None if cost_out is None or lower_out is None else max(0.0, cost_out - lower_out)
    if certified and gap is not None and not gap <= max(abs_gap, rel_gap * abs(cost_out)) * (1 + 1e-12):
        certified, status, reason = False, "not_certified", "the gap at the solution as returned exceeds the tolerance"
    if certified and gap is not None:
        lower_out = cost_out - gap
    if not certified:  # no proof the verifier checks backs the bound reached (verify.uncertified_claim)
        lower_out = gap = None
    summary = {"scope": scope, "tolerance": max(abs_gap, rel_gap * abs(cost_out)) if cost_out is not None else None,
               "tolerance_met": certified}
    if proof is not None:
        summary["proof"] = proof
    return {"name": name, "cost": cost_out, "lower_bound": lower_out, "gap": gap, "status": status,
            "certified": certified, "nodes": nodes, "elapsed_s": elapsed, "reason": reason, "certificate": summary}


def self_check_stages(parsed, options: problem.AutocalibrationOptions, stages: list[dict]) -> None:
    """Every certified stage checked by the verifier before it is returned (GEOCERT_SELF_VERIFY=1),
    as the other kinds' items are; the proofs are dropped afterwards unless asked for."""
    arrays = (parsed.cameras, parsed.points, parsed.image_size)
    for index, stage in enumerate(stages):
        proof = (stage.get("certificate") or {}).get("proof")
        if stage["certified"]:
            claim = {"index": index, **{key: stage.get(key) for key in (
                "status", "certified", "cost", "lower_bound", "gap", "plane_at_infinity", "K", "dual_absolute_quadric")},
                "proof": proof}
            try:
                verify_arrays("autocalibration", arrays, dataclasses.asdict(options), claim)
            except Invalid as exc:
                raise SelfCheckFailed(f"autocalibration stage {index}: check {exc.check} failed: {exc.detail}") from exc
        if options.certificate != "full" and proof is not None:
            del stage["certificate"]["proof"]

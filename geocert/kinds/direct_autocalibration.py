"""The autocalibration kind's result document for options.method = "direct" (kinds/autocalibration
dispatches here): one stage, "direct", and the fields the stratified method returns. It is wire
contract, built from the estimators in solvers/autocalibration, so it lives with the kind."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from geocert.core import proven_reasons
from geocert.kinds.autocalibration_stages import ANALYSIS_GRACE_S, self_check_stages, stage_document, unproven
from geocert.formulations.autocalibration import direct
from geocert.formulations.autocalibration import direct_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem

SCOPE = ("every absolute dual quadric Q (trace 1 in the program's frame) positive semidefinite of rank 3 "
         "whose views' DIACs w = P Q P' keep (w11 + w22) / w33 within what the intrinsics ranges allow "
         "(their combination (1 + aspect^2) focal^2 + skew^2 + u^2 + v^2 between its least and greatest over "
         "the ranges, preconditioned; each intrinsic is not held to its own range) and that the chirality "
         "option allows (its chosen rows strictly on one side of its null plane, none on it: an orientation "
         "excluded by Gordan's alternative holds no such plane)")


def returned_quadric(setup: direct.DirectSetup, Q: np.ndarray) -> tuple[list, float]:
    """Q in the input frame as the result states it (JSON floats), and its cost recomputed from
    that, as the verifier does."""
    Q_in = setup.to_input(Q).tolist()
    return Q_in, direct_relaxation.cost(setup.cameras, setup.from_input(np.array(Q_in)))


def solve_document(parsed, options: autocalibration_problem.AutocalibrationOptions, callback) -> dict:
    from geocert.solvers.autocalibration import direct_solve
    from geocert.solvers.autocalibration.stratified import announce
    from geocert.core.bnb import asks_to_stop
    from geocert.core.self_check import enabled as self_check_enabled

    began = time.perf_counter()
    # The job's time limit in all (its one stage), and the determinacy analysis's grace past it.
    deadline = time.monotonic() + options.time_limit_s + ANALYSIS_GRACE_S

    def check() -> None:
        """Between programs and interior-point iterations: a cancel, or the stage's time limit."""
        elapsed = time.perf_counter() - began
        if asks_to_stop(callback, autocalibration_problem.StageProgress(0, 0, -math.inf, math.inf, math.inf, math.inf,
                                                                        elapsed, stage="direct")):
            raise direct_solve.Stopped("cancelled", "the job was cancelled")
        if elapsed > options.time_limit_s:
            raise direct_solve.Stopped("time_limit", f"stopped at options.time_limit_s ({options.time_limit_s:g} s)")

    # the reference as given (prepare's unit_reference is the stratified method's frame): the direct
    # method's trace-one normalisation moves with the world's scale too, and its answers were
    # established in this frame
    problem = autocalibration_problem.prepare(parsed.cameras, parsed.points, parsed.image_size, options.intrinsics,
                                              unit_reference=False)
    setup = direct.setup_for(problem, options.chirality)
    checking = self_check_enabled()
    full = options.certificate == "full" or checking
    document: dict = {"method": "direct", "intrinsics": problem.ranges, "plane_at_infinity": None, "K": None,
                      "Ks": None, "dual_absolute_quadric": None, "upgrade": None, "cameras": None, "points": None,
                      "baseline": None}
    if announce(callback, "direct"):
        result = direct_solve.DirectStage("cancelled", False, None, math.inf, -math.inf, options.relaxation_order,
                                          reason="the job was cancelled")
    else:
        result = direct_solve.solve_direct(setup, options, full, check)
    cost = math.inf
    if result.Q is not None:
        Q_in, cost = returned_quadric(setup, result.Q)
        excluded = tuple(item["delta"] for item in setup.excluded)
        if result.certified and not direct.in_domain(setup, setup.from_input(np.array(Q_in)), excluded):
            result.certified, result.status = False, "not_certified"
            result.reason = "the quadric as returned (input frame, rounded) left the domain (rank 3, PSD, chirality)"
        try:
            document.update(direct.derived(parsed.cameras, parsed.points, np.array(Q_in), options.varying_focal))
        except (np.linalg.LinAlgError, ValueError) as exc:
            result.certified, result.status, result.reason = False, "not_certified", f"no metric upgrade: {exc}"
    stage = stage_document("direct", result.status, result.certified, cost, result.lower_bound, 0, result.elapsed_s,
                           result.reason, options.metric_rel_gap, options.abs_gap, SCOPE,
                           {**result.proof, "reference": problem.norm.reference} if full and result.certified else None)
    stage["certificate"].update({"order": result.order, "moment_rank": result.rank,
                                 "eigenvalue_ratio": result.eigenvalue_ratio, "conic_status": result.conic_status})
    for key in ("plane_at_infinity", "K", "dual_absolute_quadric"):
        stage[key] = document[key]
    if document["plane_at_infinity"] is not None and (document["Ks"] is not None or document["K"] is not None):
        # How well the data fix the plane and K (one focal length a view: each view's), read with the
        # stratified costs' curvature (the moment relaxation has no local parametrisation of its own).
        from geocert.formulations.autocalibration import determinacy
        from geocert.core.determinacy import safely, within

        p = autocalibration_problem.plane_from_input(problem, np.array(document["plane_at_infinity"]))
        centres = None if document["cameras"] is None else np.array([c["center"] for c in document["cameras"]])
        why = (f"the job's time limit (options.time_limit_s, {options.time_limit_s:g} s) had passed, and "
               f"{ANALYSIS_GRACE_S:g} s more")
        # the motion judged at the returned K (one K's DIAC; with Ks the best fit's), stated even
        # where the analysis stops or fails
        judged = None if p is None else safely(determinacy.judged_motion, problem, p,
                                               None if document["Ks"] is not None else np.array(document["K"]), centres)
        if p is not None and document["Ks"] is not None:
            stage["determinacy"] = within(deadline, "the direct stage's determinacy", why,
                                          determinacy.varying_focal_stage, problem, p, document["Ks"], centres)
        elif p is not None:
            stage["determinacy"] = within(deadline, "the direct stage's determinacy", why, determinacy.metric_stage,
                                          problem, p, np.array(document["K"]), None, None, centres, True)
        if p is not None:
            stage["determinacy"] = determinacy.with_motion(stage["determinacy"], judged, "the direct stage's determinacy")
        proof = stage["certificate"].get("proof")
        asked = options.prove_focal_interval or options.prove_intrinsics_intervals
        if p is not None and asked and isinstance(stage["determinacy"], dict):
            # every null proven_intervals asked for says why (issue 37 F5: a proof the deadline
            # stopped left it null with no word)
            why_not = unproven(options.certificate == "full", stage["certified"], proof, stage["status"])
            if why_not is None:
                why_not = _prove_focal(setup, result, stage, proof, deadline, options.varying_focal,
                                       options.prove_intrinsics_intervals and not options.varying_focal)
            if why_not is not None:
                stage["determinacy"]["proven_reason"] = why_not
    stages = [stage]
    if checking:
        self_check_stages(parsed, dataclasses.replace(options), stages)
    return {**document, "stages": stages, "status": stage["status"], "certified": stage["certified"], "nodes": 0,
            "elapsed_s": result.elapsed_s, "cost": stage["cost"], "lower_bound": stage["lower_bound"]}


def _prove_focal(setup: direct.DirectSetup, result, stage: dict, proof: dict, deadline: float,
                 varying_focal: bool, intrinsics: bool = False) -> str | None:
    """The focal length's proven interval (direct_sublevel; each view's with ``varying_focal``) at
    the cost increase direct_sublevel.cost_increase states: into the stage's proof (``sublevel``)
    and its determinacy (``proven_intervals``), when the search ends before the job's deadline.
    ``intrinsics``: the other intrinsics' too (direct_intrinsics), over the same set, those the
    deadline leaves unproven stated null. Returns why nothing was proven (None: proven)."""
    from geocert.solvers.autocalibration import direct_solve
    from geocert.formulations.autocalibration import direct_intrinsics, direct_sublevel

    increase = direct_sublevel.cost_increase(stage["cost"], stage["lower_bound"], len(setup.cameras))

    def check() -> None:
        if time.monotonic() > deadline:
            raise direct_solve.Stopped("time_limit", "the job's deadline")

    prove = direct_solve.prove_focal_lengths if varying_focal else direct_solve.prove_focal
    what = proven_reasons.WHAT[1] if varying_focal else proven_reasons.WHAT[0]
    after = proven_reasons.AFTER[1] if intrinsics else proven_reasons.AFTER[0]
    started = time.monotonic()
    if started > deadline:
        return proven_reasons.reason("direct_late", what=what, after=after)
    try:
        found = prove(setup, result.Q, stage["cost"], increase, check)
    except direct_solve.Stopped:
        # where the limit ran out (the deadline, the job's limit and the grace past its start), not
        # where a check noticed it: a number the verifier can bound by the options
        return proven_reasons.reason("direct_stopped", seconds=deadline - started, what=what, after=after)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
        return proven_reasons.reason("direct_failed", error=proven_reasons.error_name(exc), what=what, after=after)
    if found is None:
        return proven_reasons.reason("direct_none", what=what, after=after)
    if intrinsics:
        found["intrinsics"] = direct_solve.prove_intrinsics(setup, result.Q, stage["cost"], increase, check)
    proof["sublevel"] = found
    read = direct_sublevel.proven_views_document if varying_focal else direct_intrinsics.proven_document
    stage["determinacy"]["proven_intervals"] = read(found)
    stage["determinacy"]["proven"] = True
    return None

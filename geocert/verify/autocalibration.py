"""The verifier's adapter for autocalibration (geocert.verify.checks reads claims through it):
numpy only. The certificate's items are the stages: item 0 the affine stage's claim, item 1 the
metric stage's (conditional on the plane at infinity it states)."""

from __future__ import annotations

import dataclasses
import math
import sys

from typing import Any

import numpy as np

from geocert.formulations.autocalibration import metric_relaxation
from geocert.formulations.autocalibration import problem as autocalibration_problem
from geocert.formulations.autocalibration import plane_sublevel, proofs
from geocert.core import proven_reasons
from geocert.core.certificates import OBJECTIVE_TOLERANCE
from geocert.core.determinacy import ESTIMATES_FORM, image_scale, proven_document
from geocert.core.geometry import InputError, is_number, number_array
from geocert.core.strict import Invalid, charge, number as _number, numbers as _numbers, same, same_counts
from geocert.verify import autocalibration_estimates, cost_rounding, estimates, residual_claims, structure_check
from geocert.verify.verification import Verification

STAGE_NAMES = {"stratified": ["affine", "metric"], "direct": ["direct"]}
# The optional proofs a job asks for by option (each costs several times the solve) that the
# verifier holds a document to, read strictly (true or false, absent false) and not hashed into
# problem_sha256: none is a premise of a claim (prove_focal_interval's direct proof predates its
# option, so documents carry it either way).
ASKED_PROOFS = ("prove_intervals_over_planes", "prove_intrinsics_intervals")
CLAIM_OPTIONS = ("method", "intrinsics", "rel_gap", "metric_rel_gap", "abs_gap", "chirality", "varying_focal",
                 "relaxation_order")
# Sizes served (the parser's and the verifier's, checked before anything is built): the stages
# build programs of a few rows a camera and one chirality row a point, and a result's upgrade is
# judged on every point in every camera.
MAX_CAMERAS = 1000
MAX_POINTS = 100_000
MAX_OBSERVATIONS = 2_000_000  # cameras times points
# What each certified stage's summary says its proof covers, in the kind's words (geocert.kinds
# writes them; tests/verify/test_forgeries_review15.py checks the two agree): a stage's words are
# the result's own statement of its scope, so a certified stage states these or none.
STAGE_SCOPES = {
    "affine": "every plane at infinity chirality allows",
    "metric": "every K within the intrinsics ranges, for the plane at infinity stated",
    "direct": ("every absolute dual quadric Q (trace 1 in the program's frame) positive semidefinite of rank 3 "
               "whose views' DIACs w = P Q P' keep (w11 + w22) / w33 within what the intrinsics ranges allow "
               "(their combination (1 + aspect^2) focal^2 + skew^2 + u^2 + v^2 between its least and greatest over "
               "the ranges, preconditioned; each intrinsic is not held to its own range) and that the chirality "
               "option allows (its chosen rows strictly on one side of its null plane, none on it: an orientation "
               "excluded by Gordan's alternative holds no such plane)"),
}


def read_data(data: Any) -> tuple[np.ndarray, np.ndarray | None, tuple[float, float] | None]:
    """cameras, points, image_size, read strictly (InputError names the field)."""
    from geocert.formulations.autocalibration.frames import check_reconstruction

    if not isinstance(data, dict):
        raise InputError("data", "must be an object with 'cameras' (and optional 'points', 'image_size')")
    for key in data:
        if key not in ("cameras", "points", "image_size"):
            raise InputError(f"data/{key}", "unknown field (known: cameras, points, image_size)")
    if "cameras" not in data:
        raise InputError("data/cameras", "is required")
    counts = [len(data[name]) if isinstance(data.get(name), list) else 0 for name in ("cameras", "points")]
    for name, count, limit in (("cameras", counts[0], MAX_CAMERAS), ("points", counts[1], MAX_POINTS)):
        if count > limit:
            raise InputError(f"data/{name}", f"{count} {name} exceed the limit of {limit:,}")
    if counts[0] * counts[1] > MAX_OBSERVATIONS:
        raise InputError("data/points", f"{counts[0]} cameras times {counts[1]} points exceed the limit of "
                                        f"{MAX_OBSERVATIONS:,}")
    cameras = number_array(data["cameras"], "data/cameras", "a list of 3x4 numeric matrices", 3)
    check_reconstruction(cameras)
    points = None
    if data.get("points") is not None:
        points = number_array(data["points"], "data/points", "a list of [X, Y, Z, W] points", 2)
        if points.ndim != 2 or points.shape[1] != 4 or len(points) == 0:
            raise InputError("data/points", "must be a non-empty list of homogeneous [X, Y, Z, W] points")
        zero = np.flatnonzero(~np.any(points != 0, axis=1))
        if len(zero):
            raise InputError(f"data/points/{zero[0]}", "is the zero vector (not a point)")
    image_size = None
    if data.get("image_size") is not None:
        size = number_array(data["image_size"], "data/image_size", "[width, height]", 1)
        if size.shape != (2,) or not np.all(size > 0):
            raise InputError("data/image_size", "must be [width, height], both positive")
        image_size = (float(size[0]), float(size[1]))
    return cameras, points, image_size


class AutocalibrationVerification(Verification):
    claim_options = CLAIM_OPTIONS
    hash_marks = ESTIMATES_FORM  # its determinacy estimates state their tolerances (Verification.hash_marks)
    option_names = tuple(entry.name for entry in dataclasses.fields(autocalibration_problem.AutocalibrationOptions))
    proofs: dict = {}
    # A stage that found no solution (no plane, K or quadric) says "failed": a word about the
    # solver, not the data (verify.uncertified_claim).
    uncertified_statuses = ("not_certified", "node_limit", "time_limit", "cancelled", "failed")
    domain = "every plane at infinity chirality allows, then every K within the intrinsics ranges"

    @staticmethod
    def job_outcomes(result: dict) -> list:
        """One item, certified when every stage is, its status the first uncertified stage's
        ("optimal" when every stage is certified), as the kind writes the job's item."""
        stages = result.get("stages") or []
        if not all(isinstance(s, dict) for s in stages):
            raise Invalid("returned", "each stage must be an object")
        pending = next((stage for stage in stages if stage.get("certified") is not True), None)
        status = None if not stages else "optimal" if pending is None else pending.get("status")
        return [(status, bool(stages) and pending is None)]

    @staticmethod
    def rel_gap_of(options: dict, index: int) -> float:
        """A stage's tolerance: the affine stage's rel_gap, the metric or direct stage's metric_rel_gap."""
        return options["rel_gap"] if index == 0 and options.get("method") != "direct" else options["metric_rel_gap"]

    def checked_options(self, options: dict) -> dict:
        checked = {name: options.get(name) for name in CLAIM_OPTIONS}
        for name in ("rel_gap", "metric_rel_gap", "abs_gap"):
            checked[name] = _number(checked[name], f"options/{name}", "options")
        defaults = autocalibration_problem.AutocalibrationOptions()
        for name in ("chirality", "varying_focal", "relaxation_order"):  # documents made before the direct method
            if checked[name] is None and checked["method"] == "stratified":
                checked[name] = getattr(defaults, name)
        try:
            # the run-control options stated too (not hashed: a node limit of 0 states a run that never was)
            run = residual_claims.run_control_values(autocalibration_problem.AutocalibrationOptions, options)
            asked = {name: options.get(name, False) for name in ASKED_PROOFS}
            autocalibration_problem.AutocalibrationOptions(
                **{**checked, "intrinsics": dict(checked["intrinsics"] or {}), **run, **asked}).check()
        except (InputError, TypeError) as exc:
            raise Invalid("options", str(exc)) from exc
        # not hashed (no claim's premise: each proof is checked in full wherever carried), but a
        # document carries only the proofs its options asked for
        return {**checked, **asked}

    def scope_statement(self, options: dict) -> dict:
        if options["method"] == "direct":
            return {"kind": "autocalibration", "method": "direct", "intrinsics": options["intrinsics"],
                    "chirality": options["chirality"], "relaxation_order": options["relaxation_order"],
                    "metric_rel_gap": options["metric_rel_gap"], "abs_gap": options["abs_gap"],
                    "statement": "stage 0 (direct): no absolute dual quadric Q positive semidefinite of rank 3 whose "
                                 "views' DIACs w = P Q P' keep (w11 + w22) / w33 within what the intrinsics ranges "
                                 "allow (a combination of the ranges, not each intrinsic in its own) and allowed by "
                                 "the chirality option (its chosen rows strictly on one side of Q's null plane, "
                                 "none on it; in the program's frame, trace 1) costs less than "
                                 "lower_bound in (7.12); the quadric returned is one of them and costs cost"}
        return {"kind": "autocalibration", "method": options["method"], "intrinsics": options["intrinsics"],
                "rel_gap": options["rel_gap"], "metric_rel_gap": options["metric_rel_gap"],
                "abs_gap": options["abs_gap"],
                # the direct method's option, which the stratified stages do not read (their planes are
                # those their own rows allow): stated "none" beside a stratified proof, hashed, it read
                # as every plane searched (review 51); the kind refuses a stratified job asking one
                # (kinds.autocalibration.METHOD_OPTIONS), an earlier document may state it
                "chirality": f"not read by the stratified method (options/chirality {options.get('chirality')!r:.20} "
                             "is the direct method's): its affine stage searches the planes at infinity its own "
                             "chirality rows allow, the camera centres' and the points' given "
                             "(frames.chirality_rows), whatever that option states",
                # the same of the direct method's varying_focal: stated true beside a stratified
                # proof, hashed, it verified with nothing saying the one K returned is every view's
                # (review 52); refused at submission since review 50, an earlier writer served it
                "varying_focal": f"not read by the stratified method (options/varying_focal "
                                 f"{options.get('varying_focal')!r:.20} is the direct method's): its metric stage "
                                 "certifies one K for every view (K), whatever that option states",
                "statement": "stage 0 (affine): no plane at infinity chirality allows (scope.chirality) has a "
                             "modulus cost below "
                             "lower_bound; stage 1 (metric), for the plane at infinity it states: no "
                             "calibration K within the intrinsics ranges gives a DIAC K K^T costing less than "
                             "lower_bound; each solution returned is in its scope and costs cost"}

    @staticmethod
    def data_scope(data: dict, options: dict, items: list) -> dict:
        """The camera whose frame the claims are posed in (frames.reference_camera: the
        lowest-indexed of the best conditioned), or, where a camera's conditioning lies on the tie's
        edge, the cameras any machine may take for it; and the certified items whose proofs name no
        reference (written before proofs named it), where the data leave more than one frame they may
        be posed in. {} where the data cannot be read (the claims' checks say why)."""
        try:
            cameras, _, image_size = read_data(data)
            intrinsics = dict(options.get("intrinsics") or {})
            candidates = autocalibration_problem.reference_candidates(cameras, image_size, intrinsics)
            earlier = autocalibration_problem.earlier_references(cameras, image_size, intrinsics)
        except (InputError, TypeError, ValueError, AttributeError, np.linalg.LinAlgError):
            return {}
        named = {item["proof"]["reference"] for item in items if isinstance(item, dict)
                 and item.get("certified") is True and isinstance(item.get("proof"), dict)
                 and type(item["proof"].get("reference")) is int}
        if len(candidates) == 1:
            scope: dict = {"reference_camera": candidates[0]}
        elif len(named) == 1:  # check_claims refuses proofs naming two
            scope = {"reference_camera": min(named), "reference_cameras_tied": candidates,
                     "reference_note": "these cameras' conditioning lies within the rounding of the tie's edge "
                                       "(frames.REFERENCE_TIE), so which of them is the reference camera is a "
                                       "machine's rounding's choice: the claims' proofs name reference_camera and are "
                                       "checked in its frame, so each claim is about the problem posed with it as the "
                                       "reference (on noisy data another of these cameras poses another problem)"}
        else:
            scope = {"reference_cameras_tied": candidates,
                     "reference_note": "these cameras' conditioning lies within the rounding of the tie's edge "
                                       "(frames.REFERENCE_TIE), so which of them is the reference camera is a "
                                       "machine's rounding's choice, and on noisy data each poses its own problem"}
        cameras_unnamed = sorted(earlier)
        unnamed = [position for position, item in enumerate(items) if isinstance(item, dict)
                   and item.get("certified") is True and isinstance(item.get("proof"), dict)
                   and "reference" not in item["proof"]]
        if unnamed and len(cameras_unnamed) > 1:
            scope["reference_unnamed"] = {
                "items": unnamed, "cameras": cameras_unnamed,
                "note": "these items' proofs name no reference camera (written before proofs named it), and these "
                        "cameras are conditioned alike within frames.EARLIER_TIE (the rounding that chose the "
                        "best conditioned for such a writer): each item is checked in the "
                        "frame of whichever of them it holds in, which this report does not name; on noisy data "
                        "each frame poses its own problem, so such an item is a claim about the problem posed "
                        "with one of these cameras as the reference, not necessarily the one this scope names"}
        return scope

    def check_claims(self, items: list, options: dict) -> None:
        """The metric stage's claim is about the plane the affine stage returns (the direct method
        has one stage, "direct": nothing ties it to another)."""
        if options.get("method") == "direct":
            if len(items) != 1:
                raise Invalid("format", "the direct method certifies one stage: direct")
            return
        if len(items) != 2:
            raise Invalid("format", "autocalibration certifies two stages: affine, then metric")
        stage_proofs = [item.get("proof") for item in items if isinstance(item, dict) and item.get("certified") is True
                        and isinstance(item.get("proof"), dict)]
        named = {repr(proof.get("reference")) for proof in stage_proofs}
        # an uncertified stage's proof that names a frame names the certified stages' too: the
        # returned fields are read in the frame the proofs name (_stated_reference)
        named |= {repr(item["proof"]["reference"]) for item in items if isinstance(item, dict)
                  and isinstance(item.get("proof"), dict) and "reference" in item["proof"]}
        if len(named) > 1:
            # the current writer names the frame in every proof, an earlier one in none: stages posed
            # in two frames would claim a plane and a K of two different problems
            raise Invalid("claim", "the stages' proofs name different reference cameras (or one names none): both "
                                   "stages are posed in one frame")
        scaled = {"reference_scale" in item["proof"] for item in items if isinstance(item, dict)
                  and isinstance(item.get("proof"), dict)}
        if len(scaled) > 1:
            # one stage in the unit reference frame, the other in the reference as given: a plane and
            # a K of two problems
            raise Invalid("claim", "one stage's proof states reference_scale and the other's does not: both stages "
                                   "are posed in one frame")
        worlds = {repr(item["proof"].get("world_scale", "none")) for item in items if isinstance(item, dict)
                  and isinstance(item.get("proof"), dict)}
        if len(worlds) > 1:
            # the world at two scales: a plane and a K of two problems
            raise Invalid("claim", "the stages' proofs state different world_scale (or one states none): both stages "
                                   "are posed in one frame")
        planes = [item.get("plane_at_infinity") for item in items]
        if planes[1] != planes[0]:
            raise Invalid("claim", "the metric stage states another plane at infinity than the affine stage")
        if items[0].get("K") is not None:
            raise Invalid("claim", "the affine stage states no calibration")

    def check_returned(self, result: dict, certificate: dict, earlier_estimates: bool = True) -> None:
        """The result's own status and reason are what its stages give (outcome: a result written
        before they were stated has neither); its headline fields are the claims' (plane, K), and
        what follows from them (upgrade, quadric, cameras, points, ranges, baseline) recomputed
        from the data."""
        if "status" in result or "reason" in result:
            expected = outcome(result)
            for name, value in expected.items():
                if result.get(name) != value:
                    raise Invalid("returned", f"{name} is {result.get(name)!r:.80}, its stages give {value!r:.80}")
        claims = certificate["items"]
        direct = certificate["options"].get("method") == "direct"
        # each stage is the one its position names: its cost and bound are read as that stage's
        names = STAGE_NAMES["direct" if direct else "stratified"]
        stages = result.get("stages")
        if not isinstance(stages, list) or [s.get("name") if isinstance(s, dict) else None for s in stages] != names:
            raise Invalid("returned", f"stages must be named {', '.join(names)}, in that order")
        for index, (stage, claim) in enumerate(zip(stages, claims)):
            # every stage's estimate, analysed or stopped, certified or not, in its writer's words
            estimates.check_stage_words(stage.get("determinacy"), f"stages/{index}/determinacy")
            estimates.check_defeated(stage.get("determinacy"), f"stages/{index}/determinacy")
            # why proven intervals asked for are null: the stage the writer proves (the metric or
            # the direct one), when the options asked, in its words (removed by estimates_of)
            options = certificate["options"]
            asked = (bool(options.get("prove_focal_interval") or options.get("prove_intrinsics_intervals")) if direct
                     else options.get("certificate") == "full") and names[index] in ("metric", "direct")
            estimates.check_proven_reason(
                stage.get("determinacy"), f"stages/{index}/determinacy", asked,
                proven_reasons.DIRECT if direct else proven_reasons.STRATIFIED, options.get("certificate") == "full",
                claim.get("certified") is True and isinstance(claim.get("proof"), dict), stage.get("status"),
                _reason_fields(options, stage, direct))
            summary = stage.get("certificate")
            if claim.get("certified") is True and isinstance(summary, dict) and "scope" in summary \
                    and summary["scope"] != STAGE_SCOPES[names[index]]:
                raise Invalid("returned", f"stages/{index}/certificate/scope is {summary['scope']!r:.120}, the scope its "
                                          f"proof covers is {STAGE_SCOPES[names[index]]!r:.120}")
            if claim.get("certified") is not True and isinstance(summary, dict):
                _check_uncertified_summary(summary, names[index], f"stages/{index}/certificate")
        _check_calibration_forms(result)
        if direct:
            if result.get("baseline") is not None:  # the direct method has no linear estimate
                raise Invalid("returned", "baseline: the direct method states no linear estimate")
            return _check_returned_direct(result, certificate, earlier_estimates)
        _check_nothing_direct(result, stages)
        if result.get("plane_at_infinity") != claims[0].get("plane_at_infinity"):
            raise Invalid("returned", "plane_at_infinity differs from the affine stage's claim")
        if result.get("K") != claims[1].get("K"):
            raise Invalid("returned", "K differs from the metric stage's claim")
        try:
            cameras, points, image_size = read_data(certificate["data"])
            options = certificate["options"]
            intrinsics = dict(options.get("intrinsics") or {})
            problem = autocalibration_problem.prepare(cameras, points, image_size, intrinsics,
                                                      _stated_reference(claims, cameras, image_size, intrinsics),
                                                      **_stated_frame(claims))
        except (InputError, TypeError, ValueError) as exc:
            raise Invalid("returned", f"the data cannot be read again: {exc}") from exc
        if result.get("method") != options.get("method") or not _ranges_stated(result, problem):
            raise Invalid("returned", "method or intrinsics differ from what the options give")
        derived = {"upgrade": None, "dual_absolute_quadric": None, "cameras": None, "points": None}
        H = p = None
        if result.get("plane_at_infinity") is not None:
            p = autocalibration_problem.plane_from_input(problem, _numbers(result["plane_at_infinity"],
                                                                           "plane_at_infinity", (4,), "returned"))
        if p is not None and result.get("K") is not None:
            K = _numbers(result["K"], "K", (3, 3), "returned")
            H = autocalibration_problem.upgrade(problem, p, np.linalg.solve(problem.K0, K))
            derived = {"upgrade": H.tolist(),
                       "dual_absolute_quadric": autocalibration_problem.dual_absolute_quadric(H).tolist(),
                       "cameras": autocalibration_problem.metric_cameras(cameras, H),
                       "points": autocalibration_problem.metric_points(H, points)}
        for name, expected in derived.items():
            if not _derived_close(name, result.get(name), expected, cameras, points, H):
                raise Invalid("returned", f"{name} is not what the plane at infinity and K give")
        _check_baseline(result.get("baseline"), problem, p)
        _check_proven_intervals(stages[1], claims[1], stages[0])
        estimates.check_plane(stages[0].get("determinacy"), stages[0].get("plane_at_infinity"), "stages/0/determinacy")
        estimates.check_intrinsics(stages[1].get("determinacy"), result.get("K"), "stages/1/determinacy",
                                   image_scale(problem.image_size, problem.ranges["principal_point"]))
        estimates.check_redundancy(stages[0].get("determinacy"), len(cameras) - 4, "stages/0/determinacy")
        estimates.check_redundancy(stages[1].get("determinacy"), 5 * len(cameras) - 10, "stages/1/determinacy")
        # the affine stage's modulus constraints, and the metric stage's plane (that fit)
        estimates.check_no_redundancy(stages[0].get("determinacy"), len(cameras) - 4, "stages/0/determinacy")
        estimates.check_no_redundancy(stages[1].get("determinacy"), len(cameras) - 4, "stages/1/determinacy")
        for number, stage in enumerate(stages[:2]):
            estimates.check_contains(stage.get("determinacy"), f"stages/{number}/determinacy")
            estimates.check_stage_level(stage.get("determinacy"), stage.get("cost"), stage.get("lower_bound"),
                                        f"stages/{number}/determinacy")
        autocalibration_estimates.check_stratified(problem, p, result.get("K"), stages, _centres(derived["cameras"]),
                                                   earlier_estimates)

    @staticmethod
    def estimates_of(result: dict, certificate: dict) -> dict:
        """What of the result must be estimates only (verify._check_estimates): all of it but the
        metric stage's proven intervals, which check_returned has checked against its proof."""
        stages = result.get("stages")
        if isinstance(stages, list):  # each stage's proven_reason: checked by check_returned (check_proven_reason)
            stages = [{**stage, "determinacy": {k: v for k, v in stage["determinacy"].items() if k != "proven_reason"}}
                      if isinstance(stage, dict) and isinstance(stage.get("determinacy"), dict) else stage
                      for stage in stages]
            result = {**result, "stages": stages}
        if certificate.get("options", {}).get("method") == "direct":  # its one stage's interval (direct_sublevel)
            proof = (certificate["items"][0].get("proof") if len(certificate.get("items") or []) == 1
                     and isinstance(certificate["items"][0], dict) and certificate["items"][0].get("certified") is True
                     else None)
            if not (isinstance(stages, list) and len(stages) == 1 and isinstance(stages[0], dict)
                    and isinstance(stages[0].get("determinacy"), dict) and isinstance(proof, dict)
                    and "sublevel" in proof):
                return result
            determinacy = {k: v for k, v in stages[0]["determinacy"].items() if k not in ("proven", "proven_intervals")}
            return {**result, "stages": [{**stages[0], "determinacy": determinacy}]}
        proof = (certificate["items"][1].get("proof") if len(certificate.get("items") or []) == 2
                 and isinstance(certificate["items"][1], dict) and certificate["items"][1].get("certified") is True
                 else None)
        if not (isinstance(stages, list) and len(stages) == 2 and isinstance(stages[1], dict)
                and isinstance(stages[1].get("determinacy"), dict) and isinstance(proof, dict) and "sublevel" in proof):
            return result
        determinacy = {k: v for k, v in stages[1]["determinacy"].items()
                       if k not in ("proven", "proven_intervals", "proven_over_planes")}
        return {**result, "stages": [stages[0], {**stages[1], "determinacy": determinacy}]}

    def solution_cost(self, data: dict, claim: dict, options: dict) -> tuple[float, float] | None:
        """What an uncertified stage's solution costs (the affine stage's plane, the metric
        stage's K for its plane, the direct stage's quadric), with the allowance a certified
        stage's has; None when the stage returns none."""
        direct = options["method"] == "direct"
        # An uncertified stage carries no proof to state its frame: the stratified stages' costs are
        # read in the unit frame (the current writer's) and, where that is not the cost stated, in
        # the earlier writers' (FRAMES); the direct method has the frame as given.
        costs = [self._solution_cost_in(data, claim, options, frame) for frame in ((GIVEN_FRAME,) if direct else FRAMES)]
        if costs[0] is None or len(costs) == 1:
            return costs[0]
        stated = claim.get("cost")
        if isinstance(stated, (int, float)) and not isinstance(stated, bool):
            return next((cost for cost in costs if cost is not None and abs(stated - cost[0]) <= cost[1]), costs[0])
        return costs[0]

    @staticmethod
    def _solution_cost_in(data: dict, claim: dict, options: dict, frame: dict) -> tuple[float, float] | None:
        try:
            cameras, points, image_size = read_data(data)
            problem = autocalibration_problem.prepare(cameras, points, image_size, dict(options["intrinsics"] or {}),
                                                      **frame)
        except InputError as exc:
            raise Invalid("data", f"{exc.field}: {exc.reason}") from exc
        with np.errstate(all="ignore"):
            if options["method"] == "direct":
                if claim.get("dual_absolute_quadric") is None:
                    return None
                Q = _numbers(claim["dual_absolute_quadric"], "dual_absolute_quadric", (4, 4), "claim")
                setup = _direct_setup(problem, options)
                cost, rounding = _direct_cost(setup, setup.from_input(Q))
            else:
                if claim.get("plane_at_infinity") is None or (claim["index"] == 1 and claim.get("K") is None):
                    return None
                p = autocalibration_problem.plane_from_input(problem, _numbers(claim["plane_at_infinity"],
                                                                               "plane_at_infinity", (4,), "claim"))
                if p is None:
                    return None  # a plane through the reference camera's centre costs nothing: none is stated
                if claim["index"] == 0:
                    cost, rounding = _affine_cost(problem, p)
                else:
                    setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p,
                                                        problem.unit_ranges)
                    cost, rounding = _metric_cost(
                        setup, autocalibration_problem.w_of_K(problem, _numbers(claim["K"], "K", (3, 3), "claim")))
        if not (np.isfinite(cost) and np.isfinite(rounding)):
            raise Invalid("objective", "the stage's solution has no finite cost")
        # A certified stage's allowance (_check_cost), rounding included: the stage's cost as
        # another machine's kernels computed it differs from this one in its last digits, and a
        # near-exact fit's in its leading ones.
        return cost, OBJECTIVE_TOLERANCE * abs(cost) + rounding + 1e-300

    def read(self, data: dict, index: int):
        if index not in (0, 1):
            raise Invalid("format", f"stage {index}: autocalibration has stages 0 (affine) and 1 (metric)")
        try:
            return read_data(data)
        except InputError as exc:
            raise Invalid("data", f"{exc.field}: {exc.reason}") from exc

    def check_claim(self, arrays, options: dict, claim: dict, claimed: float, lower_claimed: float,
                    passed: list) -> tuple[float, float]:
        """The claim in the frame of the reference camera (frames.reference_camera: the lowest-indexed
        of the cameras tied for the best conditioning), the one frame the data give unless a camera
        lies on the tie's edge, where any machine's choice is tried (each in full, within the
        document's budget) and the report's scope says so (data_scope)."""
        cameras, points, image_size = arrays
        intrinsics = dict(options["intrinsics"] or {})
        try:
            references = autocalibration_problem.reference_candidates(cameras, image_size, intrinsics)
            earlier = autocalibration_problem.earlier_references(cameras, image_size, intrinsics)
        except InputError as exc:
            raise Invalid("options", f"{exc.field}: {exc.reason}") from exc
        proof = claim.get("proof")
        if isinstance(proof, dict) and "reference" in proof:
            if proof["reference"] not in references or type(proof["reference"]) is not int:
                raise Invalid("scope", f"proof/reference is {proof['reference']!r:.40}: these data's claims are posed "
                                       f"in the frame of camera {' or '.join(map(str, references))} (the "
                                       "lowest-indexed of the best conditioned, frames.reference_camera)")
            references = [proof["reference"]]
        else:  # an earlier proof names no frame: those its writer's rounding may have taken (data_scope says so)
            references = earlier
        frame = _proof_frame(proof, options["method"] == "direct")
        first = None
        for reference in references:
            tried = list(passed)
            try:
                problem = autocalibration_problem.prepare(cameras, points, image_size, intrinsics, reference, **frame)
                out = self._check_claim_in(problem, arrays, options, claim, claimed, lower_claimed, tried)
            except Invalid as exc:
                first = first or exc
                continue
            passed[:] = tried
            return out
        raise first

    def _check_claim_in(self, problem, arrays, options: dict, claim: dict, claimed: float, lower_claimed: float,
                        passed: list) -> tuple[float, float]:
        if options["method"] == "direct":
            return _check_direct(problem, arrays, options, claim, claimed, lower_claimed, passed), options["metric_rel_gap"]
        plane = _numbers(claim.get("plane_at_infinity"), "plane_at_infinity", (4,), "claim")
        p = autocalibration_problem.plane_from_input(problem, plane)
        if p is None:
            raise Invalid("objective", "the plane at infinity passes through the reference camera's centre")
        proof = claim.get("proof")
        if not isinstance(proof, dict):
            raise Invalid("format", "a certified stage needs a proof")
        if claim["index"] == 0:
            if proof.get("type") != "stratified_affine":
                raise Invalid("format", "stage 0 takes a stratified_affine proof")
            cost, rounding = _affine_cost(problem, p)
            rounding = _check_cost(cost, claimed, rounding, _tolerance(options, options["rel_gap"], claimed))
            passed.append("objective")
            if not autocalibration_problem.allowed_by_chirality(problem, p):
                raise Invalid("scope", "the plane at infinity returned is not one chirality allows")
            _check_data_gap(cost, rounding, lower_claimed, _tolerance(options, options["rel_gap"], claimed))
            passed.append("scope")
            return proofs.check_affine(problem, proof, lower_claimed, claimed, passed), options["rel_gap"]
        if proof.get("type") != "stratified_metric":
            raise Invalid("format", "stage 1 takes a stratified_metric proof")
        K = _numbers(claim.get("K"), "K", (3, 3), "claim")
        if not (K[1, 0] == 0 and K[2, 0] == 0 and K[2, 1] == 0 and K[2, 2] == 1 and K[0, 0] > 0 and K[1, 1] > 0):
            # the proof is about K K^T, whose one upper-triangular root with a positive diagonal is
            # the K the intrinsics ranges (checked on K K^T by in_domain) are about
            raise Invalid("claim", "K must be upper triangular with K[2][2] = 1 and a positive diagonal")
        w = autocalibration_problem.w_of_K(problem, K)
        setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
        lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
        cost, rounding = _metric_cost(setup, w)
        rounding = _check_cost(cost, claimed, rounding, _tolerance(options, options["metric_rel_gap"], claimed))
        passed.append("objective")
        if not metric_relaxation.in_domain(setup, w, lo, hi):
            raise Invalid("scope", "the DIAC returned is outside the domain (box, PSD, or a view's scale range)")
        _check_data_gap(cost, rounding, lower_claimed, _tolerance(options, options["metric_rel_gap"], claimed))
        passed.append("scope")
        bound = proofs.check_metric(problem, p, proof, lower_claimed, claimed, passed, cost)
        if "plane_sublevel" in proof:  # K proven over the plane's own uncertainty too
            if options.get("prove_intervals_over_planes") is not True:
                raise Invalid("format", "proof/plane_sublevel is carried, and options/prove_intervals_over_planes "
                                        "is not true (only a job asking for it carries it)")
            plane_sublevel.check(problem, p, proof["plane_sublevel"], max(claimed, cost))
            if "proven_interval" not in passed:
                passed.append("proven_interval")
        return bound, options["metric_rel_gap"]


# The frames a stratified document may be posed in (autocalibration_problem.prepare's arguments):
# the current writer's (the reference and the world brought to unit scale, proofs stating
# reference_scale and world_scale), an earlier one's (the reference only, stating reference_scale),
# and the earliest (both as given, stating neither; the direct method's frame).
UNIT_FRAME = {"unit_reference": True, "world": True}
UNIT_REFERENCE_FRAME = {"unit_reference": True, "world": False}
GIVEN_FRAME = {"unit_reference": False, "world": False}
FRAMES = (UNIT_FRAME, UNIT_REFERENCE_FRAME, GIVEN_FRAME)


def _proof_frame(proof: Any, direct: bool) -> dict:
    """The frame a certified stage's proof is posed in (prepare's arguments), from the members it
    states: reference_scale (the unit reference frame: the stratified writer's) and world_scale (the
    world brought to unit scale as well: the current stratified writer's), neither (the reference
    and world as given: the direct method's, and a stratified proof written before proofs stated
    them). A stated reference_scale is only compared with the one the data give
    (proofs.check_reference); a stated world_scale is the frame's power of two, which
    proofs.check_reference holds to the data's."""
    if not isinstance(proof, dict) or not ({"reference_scale", "world_scale"} & proof.keys()):
        return GIVEN_FRAME
    if direct:
        raise Invalid("scope", "proof/reference_scale or proof/world_scale is stated: the direct method's frame "
                               "takes the reference camera and the world as given (neither stated)")
    if "world_scale" not in proof:
        return UNIT_REFERENCE_FRAME
    if "reference_scale" not in proof:
        raise Invalid("scope", "proof/world_scale is stated without proof/reference_scale: the world is brought "
                               "to unit scale only in the unit reference frame")
    stated = proof["world_scale"]
    # (an int beyond the largest float, which JSON may carry, is no float: refused here, not at float())
    if type(stated) not in (float, int) or not 0.0 < stated <= sys.float_info.max:
        raise Invalid("scope", f"proof/world_scale is {stated!r:.40}: a positive power of two (frames.world_unit_scale)")
    return {"unit_reference": True, "world": float(stated)}


def _stated_frame(claims: list) -> dict:
    """The frame the returned fields are read in: the one the proof _stated_reference reads states
    (check_claims refuses stages whose proofs state two); the current writer's, UNIT_FRAME, where
    no stage carries a proof."""
    proofs = [(item.get("certified") is True, item["proof"]) for item in claims
              if isinstance(item, dict) and isinstance(item.get("proof"), dict)]
    proof = next((proof for certified, proof in proofs if certified), proofs[0][1] if proofs else None)
    return UNIT_FRAME if proof is None else _proof_frame(proof, False)


def _stated_reference(claims: list, cameras: np.ndarray, image_size, intrinsics: dict) -> int | None:
    """The frame the returned fields are read in: the one the claims' proofs name where it is one
    of the data's (a camera on the tie's edge leaves two); where a certified proof names none (an
    earlier writer's), the best-conditioned camera that writer took (check_claim reads its proofs
    there first); None, the data's own choice, otherwise (check_claim refuses any other). A
    certified stage's proof is read first: an uncertified one proves nothing of the frame (review
    36 read the fields in the frame an uncertified affine stage's proof named)."""
    proofs = [(item.get("certified") is True, item["proof"]) for item in claims
              if isinstance(item, dict) and isinstance(item.get("proof"), dict)]
    proof = next((proof for certified, proof in proofs if certified), proofs[0][1] if proofs else None)
    if not isinstance(proof, dict):
        return None
    if "reference" not in proof:
        return autocalibration_problem.earlier_references(cameras, image_size, intrinsics)[0]
    stated = proof["reference"]
    candidates = autocalibration_problem.reference_candidates(cameras, image_size, intrinsics)
    return stated if type(stated) is int and stated in candidates else None


def _check_proven_intervals(stage: dict, claim: dict, affine: Any = None) -> None:
    """A metric stage's determinacy saying proven states exactly its proof's sublevel intervals
    (proofs.check_sublevel checked them: the claim is certified, so its proof was checked), at no
    lower a cost increase than its estimate's; and its ``proven_over_planes`` exactly its proof's
    plane_sublevel's (plane_sublevel.check checked them), at no lower increases than the metric
    and affine (``affine``: that stage) estimates'."""
    expected = _stated_proven(stage, claim, "stages/1", "metric", proven_metric)
    over = stage.get("determinacy", {}).get("proven_over_planes") if isinstance(stage, dict) and isinstance(
        stage.get("determinacy"), dict) else None
    if expected is None:
        if over is not None:
            raise Invalid("returned", "stages/1/determinacy states proven_over_planes and is not proven")
        return
    estimate = stage["determinacy"].get("cost_increase")
    if isinstance(estimate, (int, float)) and not expected["cost_increase"] >= estimate * (1 - 1e-9):
        raise Invalid("returned", "stages/1/determinacy: the proven intervals' cost_increase is below its "
                                  "estimate's (a lower level proves a smaller set)")
    if over is None:
        return
    sublevel = claim["proof"].get("plane_sublevel")
    try:
        stated = plane_sublevel.proven_document(sublevel)
    except (KeyError, TypeError, ValueError) as exc:
        raise Invalid("returned", "stages/1/determinacy/proven_over_planes: no proof/plane_sublevel carries "
                                  "them") from exc
    if over != stated:
        raise Invalid("returned", "stages/1/determinacy/proven_over_planes are not its proof's plane_sublevel")
    affine_estimate = (affine.get("determinacy") or {}).get("cost_increase") if isinstance(affine, dict) else None
    for name, least in (("cost_increase", estimate), ("affine_increase", affine_estimate)):
        if not isinstance(least, (int, float)) or not stated[name] >= least * (1 - 1e-9):
            raise Invalid("returned", f"stages/1/determinacy/proven_over_planes: its {name} is below the "
                                      "estimate's, or the estimate states none (a lower level proves a smaller set)")


def _stated_proven(stage, claim: dict, where: str, name: str, read) -> dict | None:
    """The proven intervals a stage's determinacy states, None when it states none: exactly what
    ``read`` gives from its certified claim's proof's ``sublevel`` (checked with the claim), else
    the stage is refused."""
    determinacy = stage.get("determinacy") if isinstance(stage, dict) else None
    if not isinstance(determinacy, dict):
        return None
    # by identity: 0 == False, and a number where the boolean belongs is refused below
    if (determinacy.get("proven") is None or determinacy.get("proven") is False) \
            and determinacy.get("proven_intervals") is None:
        return None
    proof = claim.get("proof")
    sublevel = proof.get("sublevel") if isinstance(proof, dict) else None
    if not isinstance(sublevel, dict) or claim.get("certified") is not True or determinacy.get("proven") is not True:
        raise Invalid("returned", f"{where}/determinacy says proven, and no proof of its intervals is carried (a "
                                  f"certified {name} claim's proof/sublevel)")
    try:
        expected = read(sublevel)
    except (KeyError, TypeError, ValueError) as exc:
        raise Invalid("returned", f"{where}: its proof's sublevel states no intervals") from exc
    if determinacy.get("proven_intervals") != expected:
        raise Invalid("returned", f"{where}/determinacy/proven_intervals are not its proof's sublevel")
    return expected


def proven_metric(sublevel: dict) -> dict:
    """The proven intervals a metric stage's determinacy states from its proof's ``sublevel``."""
    return proven_document(sublevel["cost_increase"], ("focal_x", "focal_y", "skew", "principal_u", "principal_v"),
                           sublevel["intervals"], "for the plane at infinity the stage states: the hull, over the "
                           "leaves of a search at that level not excluded by a safe bound above it, of each "
                           "intrinsic's range on the leaf (pixels)")


def outcome(item: dict) -> dict:
    """The result's own ``status`` and ``reason``, where a reader looks first: a job that found no
    metric upgrade says so here, not only in its stages (the kind writes them, the verifier asks
    them)."""
    pending = next((stage for stage in item["stages"] if not stage["certified"]), None)
    if pending is None:
        return {"status": "optimal", "reason": None}
    said = f"the {pending['name']} stage ended {pending['status']}" + (f": {pending['reason']}" if pending.get("reason")
                                                                        else "")
    if item.get("dual_absolute_quadric") is None:  # no K, no quadric: nothing solved
        return {"status": "cancelled" if pending["status"] == "cancelled" else "failed",
                "reason": f"no metric upgrade was found ({said})"}
    return {"status": pending["status"], "reason": f"not certified: {said}"}


# The linear baseline is recomputed here; a least-squares solution's rounding differs from one
# machine's BLAS to another's by far less than this (relative to K's largest entry, and the cost).
BASELINE_TOLERANCE = 1e-6


def _check_baseline(given: Any, problem, p) -> None:
    """``baseline``, when stated, is the thesis's linear estimate (6.30, 6.31) for the plane at
    infinity returned: its K (None when the estimate is not a DIAC) and its cost what its DIAC
    costs."""
    if given is None:
        return  # a result may leave the baseline out; one it states must be the estimate's
    setup = None
    if p is not None:
        try:
            setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
        except (ValueError, np.linalg.LinAlgError):
            setup = None
    if setup is None or not np.all(setup.q_lower > 0):
        raise Invalid("returned", "baseline: no linear estimate exists without a metric stage to fit it for")
    if not isinstance(given, dict) or set(given) != {"method", "K", "psd", "cost"} or given["method"] != "linear" \
            or not isinstance(given["psd"], bool):
        raise Invalid("returned", "baseline must be the linear estimate: method, K, psd, cost")
    with np.errstate(all="ignore"):
        w, psd = metric_relaxation.linear_baseline(setup)
        omega = metric_relaxation.omega_of(w)
        expected_cost = metric_relaxation.cost(setup, w)
    expected_K = None
    if np.linalg.eigvalsh(omega)[0] > 0:
        K = problem.K0 @ autocalibration_problem.upper_triangular_root(omega)
        expected_K = K / K[2, 2]
    if given["psd"] != psd or (given["K"] is None) != (expected_K is None):
        raise Invalid("returned", "baseline: psd or K is not what the linear estimate gives")
    cost = _number(given["cost"], "baseline/cost", "returned")
    if expected_K is not None:
        K = _numbers(given["K"], "baseline/K", (3, 3), "returned")
        own = metric_relaxation.cost(setup, autocalibration_problem.w_of_K(problem, K))
        if not (np.all(np.abs(K - expected_K) <= BASELINE_TOLERANCE * float(np.max(np.abs(expected_K))))
                and abs(cost - own) <= BASELINE_TOLERANCE * max(abs(own), 1e-12)):
            raise Invalid("returned", "baseline: K is not the linear estimate, or its cost not what K costs")
    if not abs(cost - expected_cost) <= BASELINE_TOLERANCE * max(abs(expected_cost), 1e-12):
        raise Invalid("returned", f"baseline/cost is not the linear estimate's ({expected_cost!r})")


def _direct_setup(problem, options: dict):
    from geocert.formulations.autocalibration import direct

    try:
        points = 0 if problem.norm.points is None else len(problem.norm.points)
        direct.check_size(len(problem.norm.cameras), points, options["chirality"])
        charge(direct.chirality_pair_count(len(problem.norm.cameras), points, options["chirality"]), "chirality pairs")
        return direct.setup_for(problem, options["chirality"], exclude=False)
    except InputError as exc:
        raise Invalid("options", f"{exc.field}: {exc.reason}") from exc


def _check_direct(problem, arrays, options: dict, claim: dict, claimed: float, lower_claimed: float,
                  passed: list) -> float:
    """The direct stage: the quadric's cost and scope, what it gives, and the moment proof."""
    from geocert.formulations.autocalibration import direct
    from geocert.formulations.autocalibration import direct_relaxation

    if claim["index"] != 0:
        raise Invalid("format", "the direct method has one stage (0)")
    proof = claim.get("proof")
    if not isinstance(proof, dict) or proof.get("type") != "direct_moment":
        raise Invalid("format", "the direct stage takes a direct_moment proof")
    Q_in = _numbers(claim.get("dual_absolute_quadric"), "dual_absolute_quadric", (4, 4), "claim")
    if not np.array_equal(Q_in, Q_in.T) or not abs(np.trace(Q_in)) > 0:
        raise Invalid("claim", "dual_absolute_quadric must be symmetric with a nonzero trace")
    proofs.check_reference(problem, proof)
    setup = _direct_setup(problem, options)
    Q = setup.from_input(Q_in)
    cost, rounding = _direct_cost(setup, Q)
    rounding = _check_cost(cost, claimed, rounding, _tolerance(options, options["metric_rel_gap"], claimed))
    passed.append("objective")
    bound, excluded = direct.check_proof(setup, proof, options["relaxation_order"])
    if not direct.in_domain(setup, Q, excluded):
        raise Invalid("scope", "the quadric returned is not PSD of rank 3, or breaks a view's focal range, or is not "
                               "allowed by chirality")
    _check_data_gap(cost, rounding, lower_claimed, _tolerance(options, options["metric_rel_gap"], claimed))
    if "sublevel" in proof and options["varying_focal"]:  # each view's focal length's proven interval
        _check_direct_views_sublevel(setup, proof["sublevel"], excluded, claimed, Q)
        passed.append("proven_interval")
    elif "sublevel" in proof:  # the focal length's proven interval (direct_sublevel), at the claimed cost or above
        from geocert.formulations.autocalibration import direct_sublevel

        if isinstance(proof["sublevel"], dict) and "intrinsics" in proof["sublevel"] \
                and options.get("prove_intrinsics_intervals") is not True:
            raise Invalid("format", "proof/sublevel/intrinsics is carried, and options/prove_intrinsics_intervals "
                                    "did not ask for it")
        at = max(claimed, direct_relaxation.cost(setup.cameras, Q))
        direct_sublevel.check(setup, proof["sublevel"], excluded, at)
        if "intrinsics" in proof["sublevel"]:  # the other intrinsics' (one K), over the same set
            from geocert.formulations.autocalibration import direct_intrinsics

            direct_intrinsics.check(setup, proof["sublevel"], excluded, at)
        passed.append("proven_interval")
    cameras, points, _ = arrays
    try:
        given = direct.derived(cameras, points, Q_in, bool(options["varying_focal"]))
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise Invalid("scope", f"the quadric gives no metric upgrade: {exc}") from exc
    for name in ("plane_at_infinity", "K"):
        if not _close(claim.get(name), given[name]):
            raise Invalid("claim", f"{name} is not what the quadric gives")
    passed += ["scope", "program", "root_region", "leaf_bounds"]
    return bound


def _check_direct_views_sublevel(setup, sublevel, excluded: tuple, claimed: float, Q: np.ndarray) -> None:
    """A varying-focal direct proof's ``sublevel``: each view's focal length's proven interval
    (direct_sublevel.check_views), at the claimed cost or the quadric's, whichever is higher."""
    from geocert.formulations.autocalibration import direct_relaxation, direct_sublevel

    direct_sublevel.check_views(setup, sublevel, excluded, max(claimed, direct_relaxation.cost(setup.cameras, Q)))


def _ranges_stated(result: dict, problem) -> bool:
    """The result states the intrinsics ranges the options and data give; a job stopped before any
    stage started (a cancel, or the job's clock: every stage cancelled or time_limit, with no node
    and no cost) resolved none and states {} (its item is written without the data)."""
    if result.get("intrinsics") == problem.ranges:
        return True
    stages = result.get("stages") or []
    never_started = all(isinstance(s, dict) and s.get("status") in ("cancelled", "time_limit") and not s.get("nodes")
                        and s.get("cost") is None and s.get("lower_bound") is None for s in stages)
    return never_started and result.get("intrinsics") == {}


# What only the direct method writes: its relaxation's figures in its stage's summary (the kind's
# stage summary record, records.STAGE_SUMMARY, is both methods'), read by _check_relaxation_figures
# against the direct proof; and a K a view (Ks, options.varying_focal).
DIRECT_SUMMARY = ("order", "moment_rank", "eigenvalue_ratio", "conic_status")


def _check_nothing_direct(result: dict, stages: list) -> None:
    """A stratified result states none of what only the direct method writes (DIRECT_SUMMARY, Ks):
    beside a stratified stage, moment_rank 1 read as a moment relaxation solved exactly and Ks as
    each camera calibrated on its own, and no check read them (review 52)."""
    for index, stage in enumerate(stages):
        summary = stage.get("certificate")
        stated = [name for name in DIRECT_SUMMARY if isinstance(summary, dict) and summary.get(name) is not None]
        if stated:
            raise Invalid("returned", f"stages/{index}/certificate/{stated[0]} is stated: it is the direct method's "
                                      "relaxation's figure, and the stratified stages solve no moment relaxation")
    if result.get("Ks") is not None:
        raise Invalid("returned", "Ks is stated: the stratified method returns one K (K), a K a view only the direct "
                                  "method's options.varying_focal writes")


def _check_uncertified_summary(summary: dict, name: str, where: str) -> None:
    """An uncertified stage's summary says what its search covered in its writer's words (the
    stage's scope, or none: "" where the metric stage never ran, kinds.autocalibration) and its
    tolerance is null or a number at least 0, as an uncertified track's or map's (docs/certificate.md):
    "every plane at infinity chirality allows (proven)" and a tolerance of -1 verified on a stage
    no proof backs (review 64 class 6)."""
    if "scope" in summary and summary["scope"] not in (STAGE_SCOPES[name], ""):
        raise Invalid("returned", f"{where}/scope is {summary['scope']!r:.120}: an uncertified stage states its "
                                  f"search's words, {STAGE_SCOPES[name]!r:.80}, or none")
    tolerance = summary.get("tolerance")
    if tolerance is not None and not (is_number(tolerance) and tolerance >= 0):
        raise Invalid("returned", f"{where}/tolerance is {tolerance!r:.40}: null or a number at least 0")


def _reason_fields(options: dict, stage: dict, direct: bool) -> dict:
    """What a stage's proof reason may say (estimates.check_reason_fields), from the options and the
    stage as its writer reads them (kinds.direct_autocalibration._prove_focal: what and after;
    kinds.autocalibration._prove_intervals: the level)."""
    limit = options.get("time_limit_s")
    limit = float(limit) if is_number(limit) and limit >= 0 else math.inf
    if direct:
        varying = bool(options.get("varying_focal"))
        return {"what": proven_reasons.WHAT[1] if varying else proven_reasons.WHAT[0],
                "after": proven_reasons.AFTER[1] if options.get("prove_intrinsics_intervals") and not varying
                else proven_reasons.AFTER[0],
                "seconds": limit + proven_reasons.ANALYSIS_GRACE_S}
    determinacy = stage.get("determinacy") if isinstance(stage, dict) else None
    return {"seconds": min(limit, proven_reasons.METRIC_PROOF_S),
            "level": isinstance(determinacy, dict) and is_number(stage.get("cost"))
            and is_number(determinacy.get("cost_increase"))}


def _check_calibration_forms(result: dict) -> None:
    """Every K the result returns (K, each of Ks, each metric camera's) is a calibration matrix as
    its writer makes one: 0 below the diagonal and K[2][2] 1, exactly (upper_triangular_root and
    the cameras' RQ write them so; -0.0 is 0). Read only within rounding of the recomputed K, a
    subnormal or 1e-300 there verified (review 53): a K no camera has, claimed returned."""
    stated = [("K", result.get("K"))]
    if isinstance(result.get("Ks"), list):
        stated += [(f"Ks/{i}", K) for i, K in enumerate(result["Ks"]) if K is not None]
    if isinstance(result.get("cameras"), list):
        stated += [(f"cameras/{i}/K", c.get("K")) for i, c in enumerate(result["cameras"])
                   if isinstance(c, dict) and c.get("K") is not None]
    for where, K in stated:
        if K is None:
            continue
        K = _numbers(K, where, (3, 3), "returned")
        if not (K[1, 0] == K[2, 0] == K[2, 1] == 0 and K[2, 2] == 1):
            raise Invalid("returned", f"{where} must be a calibration matrix: exactly 0 below the diagonal and "
                                      "K[2][2] = 1, as its writer makes it")


def _check_returned_direct(result: dict, certificate: dict, earlier_estimates: bool = True) -> None:
    from geocert.formulations.autocalibration import direct

    claim = certificate["items"][0]
    options = certificate["options"]
    try:
        cameras, points, image_size = read_data(certificate["data"])
        intrinsics = dict(options.get("intrinsics") or {})
        problem = autocalibration_problem.prepare(cameras, points, image_size, intrinsics,
                                                  _stated_reference(certificate["items"], cameras, image_size, intrinsics),
                                                  unit_reference=False)  # the direct method's frame
    except (InputError, TypeError, ValueError) as exc:
        raise Invalid("returned", f"the data cannot be read again: {exc}") from exc
    if result.get("method") != "direct" or not _ranges_stated(result, problem):
        raise Invalid("returned", "method or intrinsics differ from what the options give")
    if result.get("dual_absolute_quadric") != claim.get("dual_absolute_quadric"):
        raise Invalid("returned", "dual_absolute_quadric differs from the direct stage's claim")
    _check_relaxation_figures(result, claim, options)
    if claim.get("dual_absolute_quadric") is None:  # a stage that found no quadric (not certified)
        for name in ("plane_at_infinity", "K", "Ks", "upgrade", "cameras", "points"):
            if result.get(name) is not None:
                raise Invalid("returned", f"{name} is given, but the direct stage claims no quadric")
        return
    Q_in = _numbers(claim.get("dual_absolute_quadric"), "dual_absolute_quadric", (4, 4), "returned")
    expected = direct.derived(cameras, points, Q_in, bool(options.get("varying_focal")))
    H = np.asarray(expected["upgrade"], dtype=float)
    for name, value in expected.items():
        if not _derived_close(name, result.get(name), value, cameras, points, H):
            raise Invalid("returned", f"{name} is not what the quadric gives")
    _check_direct_proven(result["stages"][0], claim, len(cameras), per_view=bool(options.get("varying_focal")))
    if result.get("Ks") is None:  # one K
        estimates.check_intrinsics(result["stages"][0].get("determinacy"), result.get("K"), "stages/0/determinacy",
                                   image_scale(problem.image_size, problem.ranges["principal_point"]))
        estimates.check_redundancy(result["stages"][0].get("determinacy"), 5 * len(cameras) - 10,
                                   "stages/0/determinacy")
        # its plane's share: the modulus constraints (autocalibration.determinacy.metric_stage)
        estimates.check_no_redundancy(result["stages"][0].get("determinacy"), len(cameras) - 4,
                                      "stages/0/determinacy")
        _check_direct_level(problem, result, result["stages"][0].get("determinacy"), "stages/0/determinacy")
    else:  # varying focal lengths: an estimate of each view's, of Ks
        estimates.check_focal_lengths(result["stages"][0].get("determinacy"), result["Ks"], "stages/0/determinacy")
        estimates.check_no_redundancy(result["stages"][0].get("determinacy"),
                                      5 * (len(cameras) - 1) - (len(cameras) + 3), "stages/0/determinacy")
        _check_direct_level(problem, result, result["stages"][0].get("determinacy"), "stages/0/determinacy")
    estimates.check_contains(result["stages"][0].get("determinacy"), "stages/0/determinacy")
    p = autocalibration_problem.plane_from_input(problem, np.asarray(result["plane_at_infinity"], dtype=float)) \
        if result.get("plane_at_infinity") is not None else None
    autocalibration_estimates.check_direct(problem, p, result.get("K"), result.get("Ks"), result["stages"][0],
                                           _centres(expected.get("cameras")), earlier_estimates)


def _centres(cameras: Any) -> np.ndarray | None:
    """The derived metric cameras' centres (None when there are none), as the writer reads them."""
    return None if cameras is None else np.array([c["center"] for c in cameras])


# What the direct stage's level may differ by besides NUMBER_SLACK of itself: each metric residual
# (preconditioned omega entries, of order 1) as another machine's sums round it, allowed 1e-12 of
# a unit, a bound chosen far above a few ulps (not measured across kernels: the stored direct
# documents verify under Haswell's and Prescott's); a near-exact scene's level is that noise.
DIRECT_RESIDUAL_ROUNDING = 1e-12


def _check_direct_level(problem, result: dict, determinacy: Any, where: str) -> None:
    """The direct stage's ``cost_increase`` is its writer's (autocalibration.determinacy.
    metric_stage, or varying_focal_stage with one focal length a view: SIGMAS^2 times the
    residuals' cost at the returned plane and K (or Ks) over their redundancy; no certified gap,
    the stage's certified cost being another cost). Unread, a level of 1e6, -1 or null verified
    (review 41), and with it intervals said to hold every quadric within it."""
    from geocert.formulations.autocalibration.determinacy import varying_focal_residuals
    from geocert.formulations.autocalibration.problem import w_of_K
    from geocert.core.determinacy import cost_increase

    if not isinstance(determinacy, dict) or estimates.stopped(determinacy):
        return
    redundancy = determinacy.get("redundancy")
    p = autocalibration_problem.plane_from_input(problem, np.asarray(result["plane_at_infinity"], dtype=float))
    if p is None or type(redundancy) is not int:
        return  # no estimate written (the writer's condition), or typed by check_redundancy
    with np.errstate(all="ignore"):
        if result.get("Ks") is None:  # metric_stage's residuals
            setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
            informative = np.concatenate([np.arange(5) + 6 * j for j in range(len(setup.H))])
            r = metric_relaxation.residuals(setup, w_of_K(problem, np.asarray(result["K"], dtype=float)))[informative]
        else:  # varying_focal_stage's, at each view's focal length over the preconditioner's
            f0 = float(problem.K0[0, 0])
            a = np.array([float(np.asarray(K, dtype=float)[0, 0]) / f0 for K in result["Ks"]])
            r = varying_focal_residuals(problem, np.concatenate([a, p]))
        expected = cost_increase(float(r @ r), redundancy)
        spread = cost_increase(float(np.sum(2 * np.abs(r) * DIRECT_RESIDUAL_ROUNDING + DIRECT_RESIDUAL_ROUNDING ** 2)),
                               redundancy)
    stated = determinacy.get("cost_increase")
    if not (math.isfinite(expected) and is_number(stated)
            and abs(float(stated) - expected) <= estimates.NUMBER_SLACK * abs(expected) + spread):
        raise Invalid("returned", f"{where}/cost_increase is {stated!r:.30}; the metric residuals' cost at the "
                                  f"returned plane and K over its redundancy {redundancy}, times the sigmas squared, "
                                  f"gives {expected!r:.30}")


def _check_direct_proven(stage: dict, claim: dict, views: int, per_view: bool) -> None:
    """A direct stage's determinacy saying proven states exactly its proof's sublevel interval, or
    with varying focal lengths its intervals focal[0] .. focal[m-1] (direct_sublevel.check or
    check_views checked them: the claim is certified, so its proof was checked), at no lower a
    cost increase than direct_sublevel.cost_increase gives for the stage's cost and bound."""
    from geocert.formulations.autocalibration import direct_sublevel

    from geocert.formulations.autocalibration import direct_intrinsics

    reader = direct_sublevel.proven_views_document if per_view else direct_intrinsics.proven_document
    expected = _stated_proven(stage, claim, "stages/0", "direct", reader)
    if expected is None:
        return
    cost, lower = stage.get("cost"), stage.get("lower_bound")
    if isinstance(cost, (int, float)) and isinstance(lower, (int, float)):
        least = direct_sublevel.cost_increase(float(cost), float(lower), views)
        if not expected["cost_increase"] >= least * (1 - 1e-9):
            what = "intervals'" if per_view else "interval's"
            raise Invalid("returned", f"stages/0/determinacy: the proven {what} cost_increase is below "
                                      f"{least!r} (direct_sublevel.cost_increase: a lower level proves a smaller set)")


def _check_relaxation_figures(result: dict, claim: dict, options: dict) -> None:
    """The direct stage's summary states the relaxation it solved: its order is the options'
    relaxation_order (the one the verifier builds the proof's programs at), its moment_rank and
    eigenvalue_ratio the proof's when the stage is certified (the proof's are checked with it:
    direct.check_rank), and otherwise figures a moment matrix of that order can have."""
    from geocert.formulations.autocalibration import direct

    stage = result["stages"][0]
    summary = stage.get("certificate") if isinstance(stage, dict) else None
    if not isinstance(summary, dict):
        return
    where = "stages/0/certificate"
    order = options.get("relaxation_order")
    if "order" in summary and not same_counts(summary["order"], order):
        raise Invalid("returned", f"{where}/order is {summary['order']!r:.40}: the relaxation solved is of the options' "
                                  f"relaxation_order {order!r}")
    proof = claim.get("proof") if claim.get("certified") is True and isinstance(claim.get("proof"), dict) else None
    if proof is not None:
        for name in ("moment_rank", "eigenvalue_ratio"):
            if name in summary and not same(summary[name], proof.get(name)):
                raise Invalid("returned", f"{where}/{name} is {summary[name]!r:.40}, its proof states "
                                          f"{proof.get(name)!r:.40}")
    try:
        direct.check_rank(summary.get("moment_rank"), summary.get("eigenvalue_ratio"), order, where)
    except Invalid as exc:
        raise Invalid("returned", exc.detail) from exc


def _derived_close(name: str, value: Any, expected: Any, cameras: np.ndarray, points: np.ndarray | None,
                   H: np.ndarray | None) -> bool:
    """A derived field of the result against its recomputation: the cameras and points each
    record at its own scale (structure_check), the other fields (one matrix or vector each) by
    _close."""
    if name in ("cameras", "points") and H is not None:
        check = structure_check.cameras_close if name == "cameras" else structure_check.points_close
        return check(value, expected, cameras if name == "cameras" else points, H)
    return _close(value, expected)


def _close(value: Any, expected: Any, scale: float | None = None) -> bool:
    """Equal structure, numbers within 1e-9 of their array's scale (recomputed on another
    machine). An array's scale is its largest entry (a list of records': each field's largest
    over the records, so that a camera centre at the origin is read at the layout's scale): no
    absolute floor, which a document could choose its world's size to fall under (centres and
    points 1e-8 across, read within 1e-9, moved by half their size and verified). A recomputed
    number or scale that is not finite matches nothing."""
    if expected is None or value is None:
        return value is None and expected is None
    if isinstance(expected, dict):
        return isinstance(value, dict) and value.keys() == expected.keys() and all(
            _close(value[key], expected[key], scale if scale is not None else _largest(expected[key]))
            for key in expected)
    if isinstance(expected, list):
        if not (isinstance(value, list) and len(value) == len(expected)):
            return False
        if expected and all(isinstance(e, dict) for e in expected):  # records: each field at its own scale
            keys = set().union(*(e.keys() for e in expected))
            scales = {key: max(_largest(e.get(key)) for e in expected) for key in keys}
            return all(isinstance(v, dict) and v.keys() == e.keys() and all(
                _close(v[key], e[key], scales[key]) for key in e) for v, e in zip(value, expected))
        scale = scale if scale is not None else _largest(expected)
        return all(_close(v, e, scale) for v, e in zip(value, expected))
    if isinstance(expected, float) or isinstance(expected, int):
        scale = scale if scale is not None else abs(expected)
        if not (math.isfinite(expected) and math.isfinite(scale)):
            return False  # |value - inf| <= 1e-9 * inf holds for any value: an overflowed recomputation proves nothing
        return isinstance(value, (int, float)) and not isinstance(value, bool) and abs(value - expected) <= (
            1e-9 * max(scale, abs(expected)))
    return value == expected


def _largest(expected: Any) -> float:
    """The largest magnitude of the numbers in ``expected`` (0 when none)."""
    if isinstance(expected, dict):
        return max((_largest(v) for v in expected.values()), default=0.0)
    if isinstance(expected, list):
        return max((_largest(v) for v in expected), default=0.0)
    if isinstance(expected, (int, float)) and not isinstance(expected, bool) and math.isfinite(expected):
        return abs(float(expected))
    return 0.0


def _affine_cost(problem, p: np.ndarray) -> tuple[float, float]:
    """The affine stage's cost at plane p (problem.affine_cost's sum) and its rounding."""
    from geocert.formulations.autocalibration import frames

    coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
    residuals = frames.modulus_residuals(coef, p)
    return float(residuals @ residuals), cost_rounding.squares_rounding(
        residuals, cost_rounding.affine_magnitudes(problem.norm.cameras, problem.norm.reference, p))


def _metric_cost(setup, w: np.ndarray) -> tuple[float, float]:
    """The metric stage's cost at w (metric_relaxation.cost's sum, computed once) and its rounding."""
    residuals = metric_relaxation.residuals(setup, w)
    return float(residuals @ residuals), cost_rounding.squares_rounding(
        residuals, cost_rounding.metric_magnitudes(setup.H, metric_relaxation.omega_of(w), metric_relaxation.WEIGHTS,
                                                   metric_relaxation._ROWS, metric_relaxation._COLUMNS))


def _direct_cost(setup, Q: np.ndarray) -> tuple[float, float]:
    """The direct stage's cost at quadric Q (program frame) and its rounding."""
    from geocert.formulations.autocalibration import direct_relaxation

    return float(direct_relaxation.cost(setup.cameras, Q)), cost_rounding.squares_rounding(
        cost_rounding.direct_residuals(setup.cameras, Q), cost_rounding.direct_magnitudes(setup.cameras, Q))


def _tolerance(options: dict, rel_gap: float, claimed: float) -> float:
    return max(options.get("abs_gap") or 0.0, rel_gap * abs(claimed))


def _check_cost(cost: float, claimed: float, rounding: float, tolerance: float) -> float:
    """The claimed cost is the solution's, to OBJECTIVE_TOLERANCE of it and the two evaluations'
    rounding (cost_rounding: a near-exact fit's cost differs in its leading digits between BLAS
    kernels), a rounding within the gap's tolerance (a solution whose cost the data determine no
    better, e.g. a plane far out, is refused). Returns the rounding, for _check_data_gap."""
    if not rounding <= tolerance:
        raise Invalid("objective", f"the data determine the solution's cost only to within {rounding!r}, more than "
                                   f"the tolerance {tolerance!r}")
    if not cost_rounding.within(cost, claimed, OBJECTIVE_TOLERANCE, rounding):
        raise Invalid("objective", f"the solution costs {cost!r}, the certificate claims {claimed!r}")
    return rounding


def _check_data_gap(cost: float, rounding: float, lower_claimed: float, tolerance: float) -> None:
    """The gap read from the verifier's evaluation and its rounding, not the claim, is within the
    tolerance: a claim may round its cost, never its gap (a solution whose cost the data do not
    determine, e.g. a plane far out, gains nothing from its wide rounding)."""
    if not (cost + rounding) - lower_claimed <= tolerance * (1 + 1e-12) + OBJECTIVE_TOLERANCE * abs(cost):
        raise Invalid("objective", f"the solution costs {cost!r} (to within {rounding!r}), more than the "
                                   f"tolerance {tolerance!r} above lower_bound {lower_claimed!r}")


STAGES = AutocalibrationVerification()

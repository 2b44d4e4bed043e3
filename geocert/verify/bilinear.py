"""The verifier's adapter for bilinear fitting (geocert.verify.checks reads claims through it):
numpy only (its relaxations' matrices are core.csc's), no conic solver. An item is a frame; its claim is the camera and
coefficients, their cost recomputed from the raw data, and a proof: ``trivial`` (cost within
abs_gap of 0) or ``bilinear_bnb`` (the camera box of the scope, the root's bound-tightening
rounds, the leaves covering the searched box and each leaf's safe bound), docs/certificate.md."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from geocert.formulations.bilinear import problem
from geocert.formulations.bilinear.options import BilinearOptions
from geocert.formulations.bilinear.relaxation import Relaxation, tightening_objective, with_cost_cap
from geocert.core.bnb import Box
from geocert.core.certificates import BOUND_TOLERANCE, OBJECTIVE_TOLERANCE
from geocert.core.cones import proves_infeasible, safe_lower_bound
from geocert.core.coverage import extended, uncovered_part, widened
from geocert.core.csc import CscMatrix
from geocert.core.determinacy import ESTIMATES_FORM
from geocert.core.geometry import InputError, is_number
from geocert.verify import cost_rounding
from geocert.core.strict import (Invalid, charge, dual_vector, informational, number as _number,
                                 numbers as _numbers, record as _record)
from geocert.verify import residual_claims
from geocert.verify.verification import Verification

CLAIM_OPTIONS = ("norm", "coefficients", "camera", "coefficient_bound", "camera_bound", "rel_gap", "abs_gap")
MAX_ROUNDS = 64  # the solver's half rounds (search.TIGHTENING_ROUNDS) with room
LEAF_CLAIM_TOLERANCE = 1e-6  # as the fractional kinds' (fractional.proof): the recomputed bound counts


# What a certified frame's summary says its proof covers, in the kind's words (geocert.kinds.bilinear
# writes them; tests/verify/test_forgeries_review15.py checks the two agree).
FRAME_SCOPES = {"searched": "every affine camera whose 2x3 part lies in the camera box (any translation), every "
                            "coefficient vector allowed",
                "trivial": "every camera and coefficient vector"}
# What a frame's root region means, in the kind's words (geocert.kinds.bilinear writes these): a
# stated region's meaning must be them (review 42: rewritten to say every camera and coefficient
# vector is covered, it verified). Unchanged since the kind was first written: no earlier words.
FRAME_REGION_MEANING = (
    "camera_lower <= M <= camera_upper entrywise for the camera's 2x3 part M; any translation "
    "(a point costing less than the incumbent has its translation within a range its "
    "observations bound); coefficients: sum 1 and, convex: >= 0, affine: within "
    "coefficient_bound")


class BilinearVerification(Verification):
    claim_options = CLAIM_OPTIONS
    hash_marks = ESTIMATES_FORM  # its determinacy estimates state their tolerances (Verification.hash_marks)
    option_names = tuple(entry.name for entry in dataclasses.fields(BilinearOptions))
    proofs: dict = {}
    data_items = "frames"  # the certificate has one item per frame (verify._check_item_count)
    domain = ("every affine camera [M | t] whose 2x3 part M lies in the item's camera box (any translation t), "
              "with every coefficient vector of the coefficient set")

    def checked_options(self, options: dict) -> dict:
        checked = {name: options.get(name) for name in CLAIM_OPTIONS}
        for name in ("rel_gap", "abs_gap", "coefficient_bound"):
            checked[name] = _number(checked[name], f"options/{name}", "options")
        if checked["camera_bound"] is not None:
            checked["camera_bound"] = _number(checked["camera_bound"], "options/camera_bound", "options")
        for name in ("norm", "coefficients", "camera"):
            if not isinstance(checked[name], str):
                raise Invalid("options", f"options/{name} must be a string")
        try:
            # the run-control options stated too (not hashed: a node limit of 0 states a run that never was)
            BilinearOptions(**checked, **residual_claims.run_control_values(BilinearOptions, options)).check()
        except (InputError, TypeError) as exc:
            raise Invalid("options", str(exc)) from exc
        return checked

    def scope_statement(self, options: dict) -> dict:
        coefficients = ("alpha >= 0, sum alpha = 1" if options["coefficients"] == "convex" else
                        f"sum alpha = 1, |alpha_i| <= {options['coefficient_bound']!r}")
        box = ("|M_rk| <= " + repr(options["camera_bound"]) if options["camera_bound"] is not None
               else "the camera box its proof states (camera_boxes below, raw units)")
        return {"kind": "bilinear", "norm": options["norm"], "coefficients": options["coefficients"],
                "coefficient_bound": options["coefficient_bound"], "camera_bound": options["camera_bound"],
                "rel_gap": options["rel_gap"], "abs_gap": options["abs_gap"],
                "statement": f"for each certified frame: no affine camera [M | t] with M within {box} (any "
                             f"translation t) and coefficients alpha with {coefficients} images the basis's "
                             f"combination at a cost below lower_bound * (1 - {BOUND_TOLERANCE:g}); the camera "
                             f"and coefficients returned are in that scope and cost cost (within a relative "
                             f"{OBJECTIVE_TOLERANCE:g})"}

    def __init__(self):
        # The basis of the document being verified (its list, kept alive so that its identity is
        # not reused, and its array): every frame shares it, so it is read once, not once a frame
        # (the verifier forgets it at the start and end of each document, as TrackItems does).
        self._basis: tuple[object, np.ndarray] | None = None

    def forget(self) -> None:
        self._basis = None

    def read(self, data: Any, index: int):
        if not isinstance(data, dict) or not isinstance(index, int):
            raise Invalid("data", "data must be an object with basis and frames")
        frames = data.get("frames")
        if not isinstance(frames, list) or not 0 <= index < len(frames):
            raise Invalid("format", f"item {index} is not a frame of the data")
        try:
            remembered = self._basis
            if remembered is None or remembered[0] is not data.get("basis"):
                basis, _ = problem.read_data(data, range(0))
                basis.setflags(write=False)
                self._basis = remembered = (data.get("basis"), basis)
            basis = remembered[1]
            return basis, problem.read_frame(frames[index], index, basis.shape[1], basis.shape[0])
        except InputError as exc:
            raise Invalid("data", f"{exc.field}: {exc.reason}") from exc

    def check_claim(self, arrays, options: dict, claim: dict, claimed: float, lower_claimed: float,
                    passed: list) -> tuple[float, float]:
        basis, points = arrays
        K = basis.shape[0]
        camera = _numbers(claim.get("camera"), "camera", (2, 4), "claim")
        alpha = _numbers(claim.get("coefficients"), "coefficients", (K,), "claim")
        residuals = problem.residuals(basis, points, camera, alpha)
        cost = problem.cost(residuals, options["norm"])
        seen = ~np.isnan(residuals[:, 0])
        magnitudes = cost_rounding.bilinear_magnitudes(basis, points, camera, alpha)[seen]
        # L1L1 sums |r|: each term moves by its own rounding (counted for both evaluations)
        rounding = (2.0 * cost_rounding.RELATIVE * float(np.sum(magnitudes)) if options["norm"] == "L1L1"
                    else cost_rounding.squares_rounding(residuals[seen], magnitudes))
        if not cost_rounding.within(cost, claimed, OBJECTIVE_TOLERANCE, rounding):
            raise Invalid("objective", f"the solution costs {cost!r}, the certificate claims {claimed!r}")
        # a claim may round its cost, never its gap: the gap read from this evaluation and its rounding
        tolerance = max(options["abs_gap"], options["rel_gap"] * abs(claimed))
        if not (cost + rounding) - lower_claimed <= tolerance * (1 + 1e-12) + OBJECTIVE_TOLERANCE * abs(cost):
            raise Invalid("objective", f"the solution costs {cost!r} (to within {rounding!r}), more than the "
                                       f"tolerance {tolerance!r} above lower_bound {lower_claimed!r}")
        passed.append("objective")
        if not problem.feasible_coefficients(alpha, options["coefficients"], options["coefficient_bound"]):
            raise Invalid("scope", "the coefficients are not in the coefficient set (sum 1 within 1e-12 per "
                                   "coefficient; convex: non-negative; affine: within coefficient_bound)")
        proof = claim.get("proof")
        if not isinstance(proof, dict):
            raise Invalid("format", "a certified item needs a proof")
        if proof.get("type") == "trivial":  # every cost is a sum of non-negative terms
            _record(proof, "proof", ("type",))
            passed.append("scope")
            return 0.0, options["rel_gap"]
        if proof.get("type") != "bilinear_bnb":
            raise Invalid("format", f"proof type {proof.get('type')!r} is not one bilinear takes")
        return check_search(basis, points, camera, options, proof, lower_claimed, passed), options["rel_gap"]

    def solution_cost(self, data: Any, claim: dict, options: dict) -> tuple[float, float] | None:
        """What an uncertified frame's camera and coefficients cost on its points (and the
        allowance for rounding, as a certified claim's); None when it returns no camera."""
        if claim.get("camera") is None or claim.get("coefficients") is None:
            return None
        basis, points = self.read(data, claim["index"])
        camera = _numbers(claim["camera"], "camera", (2, 4), "claim")
        alpha = _numbers(claim["coefficients"], "coefficients", (basis.shape[0],), "claim")
        with np.errstate(all="ignore"):
            cost = float(problem.cost(problem.residuals(basis, points, camera, alpha), options["norm"]))
        if not np.isfinite(cost):
            raise Invalid("objective", "the camera returned has no finite cost on its points")
        return cost, OBJECTIVE_TOLERANCE * abs(cost) + 1e-300

    @staticmethod
    def scope_of_items(claims: list) -> dict:
        """Each certified frame's camera box (raw units), as its proof states it: the scope."""
        boxes = []
        for claim in claims:
            proof = claim.get("proof") if claim.get("certified") is True else None
            if isinstance(proof, dict) and proof.get("type") == "bilinear_bnb":
                lo, hi = proof["camera_box"]
                boxes.append({"item": claim["index"], "camera_lower": [lo[:3], lo[3:]], "camera_upper": [hi[:3], hi[3:]]})
        return {"camera_boxes": boxes}

    def check_returned(self, result: dict, certificate: dict, earlier_estimates: bool = True) -> None:
        """Each frame's shape and residuals are what its camera and coefficients give, and a
        certified frame's summary states the camera box its proof covers (the scope); a root
        region, certified or not, means what the kind's words say (FRAME_REGION_MEANING)."""
        for claim, item in zip(certificate["items"], result["frames"]):
            proof = claim.get("proof")
            if not isinstance(item, dict):
                continue
            summary = item.get("certificate")
            region = summary.get("root_region") if isinstance(summary, dict) else None
            if region is not None and not (isinstance(region, dict) and region.get("meaning") == FRAME_REGION_MEANING):
                raise Invalid("returned", f"frames/{claim['index']}/certificate/root_region/meaning is not the kind's "
                                          "words for a camera box (bilinear.FRAME_REGION_MEANING)")
            if claim.get("certified") is not True:
                continue
            searched = isinstance(proof, dict) and proof.get("type") == "bilinear_bnb"
            words = FRAME_SCOPES["searched" if searched else "trivial"]
            if isinstance(summary, dict) and "scope" in summary and summary["scope"] != words:
                raise Invalid("returned", f"frames/{claim['index']}/certificate/scope is {summary['scope']!r:.120}, the "
                                          f"scope its proof covers is {words!r}")
            if isinstance(proof, dict) and proof.get("type") == "bilinear_bnb":
                lo, hi = proof["camera_box"]
                expected = {"camera_lower": [lo[:3], lo[3:]], "camera_upper": [hi[:3], hi[3:]],
                            "coefficients": certificate["options"].get("coefficients"), "translation": "any"}
                if not isinstance(region, dict) or any(region.get(k) != v for k, v in expected.items()):
                    raise Invalid("returned", f"frames/{claim['index']}/certificate/root_region is not the camera box its "
                                              "proof covers (the scope)")
        try:
            basis, frames = problem.read_data(certificate["data"])
        except InputError as exc:
            raise Invalid("returned", f"the data cannot be read again: {exc}") from exc
        if result.get("coefficients") != certificate["options"].get("coefficients"):
            raise Invalid("returned", "the result's coefficient set differs from its certificate's")
        for index, (item, points) in enumerate(zip(result["frames"], frames)):
            if item.get("baseline") is not None:
                _check_baseline(index, item["baseline"], basis, points, certificate["options"])
            if item.get("camera") is None or item.get("coefficients") is None:
                # what derives from the solution is not stated without it (nor half a solution)
                stated = [name for name in ("camera", "coefficients", "shape", "residuals")
                          if item.get(name) not in (None, [])]
                if stated:
                    raise Invalid("returned", f"frames/{index}: {', '.join(stated)} given without the camera and "
                                              "coefficients they belong to")
                continue
            camera = _numbers(item["camera"], f"frames/{index}/camera", (2, 4), "returned")
            alpha = _numbers(item["coefficients"], f"frames/{index}/coefficients", (basis.shape[0],), "returned")
            shape = _numbers(item.get("shape"), f"frames/{index}/shape", (basis.shape[1], 3), "returned")
            # Each number within RETURNED_TOLERANCE of the size of the terms it sums (the data's own
            # scale, whatever it is), not of an absolute floor: with floors (1e-12 for the shape,
            # 1e-9 for residuals) data scaled small let residuals of 5e-13 be stated 0 and a shape
            # of 1e-19 be stated at the origin (review 42). Writer and verifier evaluate the same
            # sums; their orders differ by a few ulps of the terms, far below this.
            with np.errstate(all="ignore"):
                terms = np.einsum("i,ijk->jk", np.abs(alpha), np.abs(basis))  # the shape's terms
                if not np.all(np.abs(shape - problem.shape_of(basis, alpha)) <= RETURNED_TOLERANCE * terms):
                    raise Invalid("returned", f"frames/{index}/shape is not the coefficients' combination of the basis")
                r = problem.residuals(basis, points, camera, alpha)
                allowed = RETURNED_TOLERANCE * (np.abs(points) + terms @ np.abs(camera[:, :3]).T + np.abs(camera[:, 3]))
            given = item.get("residuals")
            if not isinstance(given, list) or len(given) != len(r) or any(
                    (g is None) != bool(np.isnan(row[0])) or (g is not None and not (
                        isinstance(g, list) and len(g) == 2 and all(is_number(x) for x in g)
                        and np.all(np.abs(np.array(g, dtype=float) - row) <= tolerance)))
                    for g, row, tolerance in zip(given, r, allowed)):
                raise Invalid("returned", f"frames/{index}/residuals are not the camera's")


# The linear baseline is recomputed here; a least-squares and SVD solution's rounding differs from
# one machine's BLAS to another's by far less than this (relative to the camera's largest entry,
# and to the cost).
BASELINE_TOLERANCE = 1e-6
# A frame's returned shape and residuals, relative to the size of the terms each sums (check_returned).
RETURNED_TOLERANCE = 1e-9


def _check_baseline(index: int, given: Any, basis: np.ndarray, points: np.ndarray, options: dict) -> None:
    """A frame's ``baseline``, when stated (a result may leave it out), is the linear estimate
    (thesis 8.3.3) for its data, and its cost is what its own camera and coefficients cost."""
    where = f"frames/{index}/baseline"
    if not isinstance(given, dict) or set(given) != {"method", "camera", "coefficients", "cost"} \
            or given["method"] != "linear":
        raise Invalid("returned", f"{where} must be the linear estimate: method, camera, coefficients, cost")
    camera = _numbers(given["camera"], f"{where}/camera", (2, 4), "returned")
    alpha = _numbers(given["coefficients"], f"{where}/coefficients", (basis.shape[0],), "returned")
    cost = _number(given["cost"], f"{where}/cost", "returned")
    frame = problem.normalise(basis, points)
    # The tolerances are relative to the data's own scales (normalise's powers of two: the image's
    # spread, the basis's, and the camera's M that maps one to the other), never to an absolute
    # floor: with max(size, 1) the camera's 2x3 part (2^20 for the basis 2^-60 times the points'
    # scale 2^-40) set the translation's allowance too, and a translation moved 1e8 times the
    # image's extent, its cost restated to match, verified (review 42). The cost's floor is that
    # of the image's spread in the norm's units (cost_unit), times the tolerance.
    floor = BASELINE_TOLERANCE * problem.cost_unit(frame, options["norm"])
    own = problem.cost(problem.residuals(basis, points, camera, alpha), options["norm"])
    if not abs(cost - own) <= 1e-9 * max(abs(own), floor):
        raise Invalid("returned", f"{where}/cost is not what its camera and coefficients cost ({own!r})")
    with np.errstate(all="ignore"):
        M, a, t = problem.linear_baseline(frame.X, frame.u, options["norm"], options["coefficients"],
                                          options["coefficient_bound"])
    expected = problem.to_raw(frame, M, t)
    expected_cost = problem.cost(problem.residuals(basis, points, expected, a), options["norm"])
    camera_scale = max(float(np.max(np.abs(expected[:, :3]))), frame.image_scale / frame.shape_scale)
    translation_scale = max(float(np.max(np.abs(expected[:, 3]))), frame.image_scale)
    if not (np.all(np.abs(camera[:, :3] - expected[:, :3]) <= BASELINE_TOLERANCE * camera_scale)
            and np.all(np.abs(camera[:, 3] - expected[:, 3]) <= BASELINE_TOLERANCE * translation_scale)
            and np.all(np.abs(alpha - a) <= BASELINE_TOLERANCE * max(float(np.max(np.abs(a))), 1.0))
            and abs(cost - expected_cost) <= BASELINE_TOLERANCE * max(abs(expected_cost), floor)):
        raise Invalid("returned", f"{where} is not the linear estimate for this frame's data")


def check_search(basis: np.ndarray, points: np.ndarray, camera: np.ndarray, options: dict, proof: dict,
                 lower_claimed: float, passed: list) -> float:
    """The lower bound (caller's units) a bilinear_bnb proof establishes."""
    norm, K = options["norm"], basis.shape[0]
    _record(proof, "proof", ("type", "camera_box", "tightening", "node_tightening", "proofs", "leaves"))
    frame = problem.normalise(basis, points)
    unit = problem.cost_unit(frame, norm)
    # Only points costing less than the claimed lower bound need excluding (as for the other kinds).
    cap = max(0.0, lower_claimed / unit * (1 - BOUND_TOLERANCE))
    scale = frame.camera_scale
    scope_lo, scope_hi = _numbers(proof.get("camera_box"), "proof/camera_box", (2, 6), "scope")
    scope_lo, scope_hi = scope_lo / scale, scope_hi / scale  # powers of two: exact
    M = camera[:, :3].ravel() / scale
    # without camera_bound, the box the options give is the default box of the camera returned
    bound = problem.default_half_width(M) if options["camera_bound"] is None else options["camera_bound"] / scale
    if not (np.all(scope_lo <= -bound) and np.all(scope_hi >= bound)):
        raise Invalid("scope", "the camera box does not contain the box camera_bound states" if
                      options["camera_bound"] is not None else "the camera box does not contain the default box of "
                      f"the camera returned (|M| <= {bound * scale!r}: camera_bound null)")
    if not (np.all(scope_lo <= M) and np.all(M <= scope_hi)):
        raise Invalid("scope", "the camera returned is outside the camera box of the scope")
    # The scope the options state (the report's statement: "the camera and coefficients returned
    # are in that scope") holds the camera returned too, not only the proof's larger box.
    if options["camera_bound"] is not None and not np.all(np.abs(M) <= bound):
        raise Invalid("scope", f"the camera returned is outside the scope's camera box (|M_rk| <= camera_bound "
                               f"{options['camera_bound']!r})")
    passed.append("scope")
    relaxation = Relaxation(frame.X, frame.u, norm, options["coefficients"], options["coefficient_bound"],
                            matrix=CscMatrix)
    size = frame.X.shape[0] * frame.X.shape[1]  # basis shapes times points seen: a relaxation's rows
    passed.append("program")

    box_lo = np.concatenate([scope_lo, np.full(K, relaxation.alpha_range[0])])
    box_hi = np.concatenate([scope_hi, np.full(K, relaxation.alpha_range[1])])
    rounds = proof.get("tightening")
    if not isinstance(rounds, list) or len(rounds) > MAX_ROUNDS:
        raise Invalid("format", f"proof/tightening must be a list of at most {MAX_ROUNDS} rounds")
    # Each round's box as claimed (what the next must start from) and as proven (the claimed one
    # widened to its sides' proven values: coverage.widened), on which the next is built.
    proven = (box_lo, box_hi)
    for number, round_ in enumerate(rounds):
        charge(size, f"tightening round {number}")
        (box_lo, box_hi), proven = _check_round(relaxation, round_, (box_lo, box_hi), proven, cap, number)
    search, alpha_lo, alpha_hi = Box(box_lo[:6], box_hi[:6]), proven[0][6:], proven[1][6:]
    searched = Box(proven[0][:6], proven[1][:6])
    root_alpha = (box_lo[6:], box_hi[6:])  # the coefficients' box as claimed

    leaves, proofs = proof.get("leaves"), proof.get("proofs")
    if not isinstance(leaves, list) or not leaves or not isinstance(proofs, list):
        raise Invalid("format", "proof/leaves and proof/proofs must be lists, leaves not empty")
    for number, leaf in enumerate(leaves):
        if not (isinstance(leaf, list) and len(leaf) == 3 and (leaf[2] is None or (
                type(leaf[2]) is int and 0 <= leaf[2] < len(proofs)))):
            raise Invalid("format", f"leaf {number} must be [lower corner, upper corner, proof index or null]")
    leaf_lo = _numbers([leaf[0] for leaf in leaves], "proof/leaves (lower corners)", (len(leaves), 6))
    leaf_hi = _numbers([leaf[1] for leaf in leaves], "proof/leaves (upper corners)", (len(leaves), 6))
    gap = uncovered_part(search, leaf_lo, leaf_hi)
    if gap is not None:
        raise Invalid("coverage", f"no leaf covers the box {gap[0].tolist()} .. {gap[1].tolist()}")
    passed.append("coverage")

    nodes = _check_node_tightening(relaxation, proof.get("node_tightening"), (search, searched), root_alpha,
                                   (alpha_lo, alpha_hi), cap)
    passed.append("tightening")

    proven, boxes = [], []
    for number, record in enumerate(proofs):
        _record(record, f"proofs/{number}", ("box", "upper_bound", "kind", "z", "bound", "alpha_from"))
        informational(record.get("bound"), f"proofs/{number}/bound")  # read for a dual proof only
        informational(record.get("z"), f"proofs/{number}/z", "text")  # read with a vector only
        # Boxes on the searched box's faces reach its proven faces (coverage.extended).
        lo, hi = extended(*_numbers(record.get("box"), f"proofs/{number}/box", (2, 6)), search, searched)
        boxes.append((lo, hi))
        ub = _number(record.get("upper_bound"), f"proofs/{number}/upper_bound")
        if not ub >= cap:
            raise Invalid("leaf_bounds", f"proof {number} assumed a cost cap below the claimed lower bound")
        source = record.get("alpha_from")
        if source is None:
            within, a_lo, a_hi = (searched.lo, searched.hi), alpha_lo, alpha_hi
        elif type(source) is int and 0 <= source < len(nodes):
            within, a_lo, a_hi = nodes[source]
        else:
            raise Invalid("format", f"proof {number}: alpha_from must be null or a node tightening record's index")
        if not (np.all(within[0] <= lo) and np.all(hi <= within[1])):
            raise Invalid("leaf_bounds", f"proof {number}: its box is not inside the box its coefficients' range "
                                         "was proven for")
        kind = record.get("kind")
        charge(size, f"proof {number}")
        if kind == "alpha_empty":  # the tightening proved that no coefficient vector fits within the cap
            if np.all(a_lo <= a_hi):
                raise Invalid("leaf_bounds", f"proof {number}: its coefficients' range is not empty")
            proven.append(ub)
            continue
        if not np.all(a_lo <= a_hi):
            raise Invalid("leaf_bounds", f"proof {number}: an empty coefficients' range needs kind alpha_empty")
        data = relaxation.conic_data(lo, hi, ub, a_lo, a_hi)
        if kind == "empty":  # no translation fits every observation within the cap
            if data is not None:
                raise Invalid("leaf_bounds", f"proof {number}: its box is not empty of points costing at most its cap")
            proven.append(ub)
            continue
        if data is None:
            raise Invalid("leaf_bounds", f"proof {number}: no relaxation on a box empty of points within its cap")
        z = dual_vector(record.get("z"), len(data.b))
        if kind == "farkas":
            if not proves_infeasible(data.A, data.b, data.cones, z, data.lower, data.upper):
                raise Invalid("leaf_bounds", f"proof {number}: its Farkas vector does not prove infeasibility")
            proven.append(ub)
            continue
        if kind != "dual":
            raise Invalid("format", f"proof {number}: unknown kind {kind!r}")
        bound = relaxation.bound(data, z)
        claimed = _number(record.get("bound"), f"proofs/{number}/bound")
        if not bound >= claimed - LEAF_CLAIM_TOLERANCE * (abs(claimed) + abs(bound)):
            raise Invalid("leaf_bounds", f"proof {number}: its dual proves {bound!r}, it claims {claimed!r}")
        proven.append(min(bound, ub))  # points costing more than the cap are bounded by it
    bounds = []
    leaf_lo, leaf_hi = extended(leaf_lo, leaf_hi, search, searched)
    for number, leaf in enumerate(leaves):
        if leaf[2] is None:
            bounds.append(0.0)
            continue
        lo, hi = boxes[leaf[2]]
        if not (np.all(lo <= leaf_lo[number]) and np.all(hi >= leaf_hi[number])):
            raise Invalid("leaf_bounds", f"leaf {number} is not inside the box of its proof {leaf[2]}")
        bounds.append(proven[leaf[2]])
    passed.append("leaf_bounds")
    return min(bounds) * unit


def _check_node_tightening(relaxation: Relaxation, records: Any, search: tuple[Box, Box], root_alpha: tuple,
                           alpha: tuple, cap: float) -> list:
    """The node tightening records, in order: each over a camera box inside its parent's (the
    root's searched box for parent null, ``search`` as claimed and as proven), starting from the
    coefficients' box its parent proved (the root's: ``root_alpha`` as claimed, ``alpha`` as
    proven), and proving its own coefficients' box (2K dual vectors,
    the camera box unchanged). Returns per record (camera box, coefficients' lower, upper) as
    proven: a camera box on the searched box's faces reaches its proven faces, and each side
    is widened to its proven value (coverage.extended, widened)."""
    if records is None:
        records = []
    if not isinstance(records, list):
        raise Invalid("format", "proof/node_tightening must be a list")
    K = relaxation.K
    claimed, proven = search
    out: list = []
    records_alpha: list = []  # each record's coefficients' box as claimed
    for number, record in enumerate(records):
        _record(record, f"node_tightening/{number}", ("parent", "upper_bound", "box_in", "box_out", "duals"))
        parent = record.get("parent")
        if parent is None:
            within, (a_lo, a_hi) = (proven.lo, proven.hi), alpha
        elif type(parent) is int and 0 <= parent < number:
            within, a_lo, a_hi = out[parent]
        else:
            raise Invalid("format", f"node tightening {number}: parent must be null or an earlier record")
        d = 6 + K
        lo_in, hi_in = _numbers(record.get("box_in"), f"node_tightening/{number}/box_in", (2, d))
        lo_out, hi_out = _numbers(record.get("box_out"), f"node_tightening/{number}/box_out", (2, d))
        if not (np.array_equal(lo_out[:6], lo_in[:6]) and np.array_equal(hi_out[:6], hi_in[:6])):
            raise Invalid("tightening", f"node tightening {number} moves the camera box")
        camera = extended(lo_in[:6], hi_in[:6], claimed, proven)
        if not (np.all(within[0] <= camera[0]) and np.all(camera[1] <= within[1])):
            raise Invalid("tightening", f"node tightening {number}: its camera box is not inside its parent's")
        parent_claimed = root_alpha if parent is None else records_alpha[parent]
        if not (np.array_equal(lo_in[6:], parent_claimed[0]) and np.array_equal(hi_in[6:], parent_claimed[1])):
            raise Invalid("tightening", f"node tightening {number} does not start from its parent's coefficients' box")
        if not np.all(a_lo <= a_hi):
            raise Invalid("tightening", f"node tightening {number}: its parent left no coefficient")
        ub = _number(record.get("upper_bound"), f"node_tightening/{number}/upper_bound")
        if not ub >= cap:
            raise Invalid("tightening", f"node tightening {number} assumed a cost cap below the claimed lower bound")
        duals = record.get("duals")
        if not isinstance(duals, list) or len(duals) != 2 * K:
            raise Invalid("tightening", f"node tightening {number}: {K} coefficients need {2 * K} dual vectors")
        charge(relaxation.X.shape[0] * relaxation.X.shape[1], f"node tightening {number}")
        data = relaxation.conic_data(camera[0], camera[1], ub, a_lo, a_hi)
        if data is None:
            raise Invalid("tightening", f"node tightening {number}: its box holds no point within its cap")
        lo_proven = np.concatenate([camera[0], a_lo])
        hi_proven = np.concatenate([camera[1], a_hi])
        sides = _check_sides(relaxation, with_cost_cap(relaxation, data, ub), range(6, d), lo_proven, hi_proven,
                             lo_out, hi_out, duals, f"node tightening {number}")
        out.append((camera, sides[0][6:], sides[1][6:]))
        records_alpha.append((lo_out[6:], hi_out[6:]))
    return out


def _check_round(relaxation: Relaxation, round_: Any, box: tuple, proven: tuple, cap: float,
                 number: int) -> tuple[tuple, tuple]:
    """One round of bound tightening: over box_in (the previous box: ``box`` as claimed, built on
    ``proven``, as proven), every point costing at most upper_bound has (M, alpha) within box_out;
    each side moved is the safe bound of its dual vector. Returns box_out as claimed and as
    proven (coverage.widened)."""
    _record(round_, f"tightening/{number}", ("upper_bound", "box_in", "box_out", "duals"))
    box_lo, box_hi = box
    d = len(box_lo)
    ub = _number(round_.get("upper_bound"), f"tightening/{number}/upper_bound")
    lo_in, hi_in = _numbers(round_.get("box_in"), f"tightening/{number}/box_in", (2, d))
    lo_out, hi_out = _numbers(round_.get("box_out"), f"tightening/{number}/box_out", (2, d))
    if not (np.array_equal(lo_in, box_lo) and np.array_equal(hi_in, box_hi)):
        raise Invalid("tightening", f"round {number} starts from a box that is not the previous one")
    if not ub >= cap:
        raise Invalid("tightening", f"round {number} assumed a cost cap below the claimed lower bound")
    duals = round_.get("duals")
    if not isinstance(duals, list) or len(duals) != 2 * d:
        raise Invalid("tightening", f"round {number}: {d} variables need {2 * d} dual vectors (or null)")
    data = relaxation.conic_data(proven[0][:6], proven[1][:6], ub, proven[0][6:], proven[1][6:])
    if data is None:
        raise Invalid("tightening", f"round {number}: its box holds no point within its cap")
    sides = _check_sides(relaxation, with_cost_cap(relaxation, data, ub), range(d), proven[0], proven[1], lo_out,
                         hi_out, duals, f"round {number}")
    if not np.all(lo_out <= hi_out):
        raise Invalid("tightening", f"round {number} leaves an empty box (the solver never does: its incumbent is in it)")
    return (lo_out, hi_out), sides


def _check_sides(relaxation: Relaxation, data, entries: range, lo_in: np.ndarray, hi_in: np.ndarray,
                 lo_out: np.ndarray, hi_out: np.ndarray, duals: list, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Each side of box_out over ``entries`` (index into the (M, alpha) box; duals 2 per entry,
    counted from the first) is no tighter than max(side in, safe bound of its dual), but for
    rounding: ``data`` is the relaxation with its cost cap (the tightening's feasible set) over
    the box in as proven (lo_in, hi_in). Returns box_out with those entries as proven (each
    claimed side widened to the proven one: coverage.widened), the others as box_in's."""
    proven_lo, proven_hi = lo_in.copy(), hi_in.copy()
    for n, entry in enumerate(entries):
        for side, sign in ((0, 1.0), (1, -1.0)):
            z = duals[2 * n + side]
            if z is None:
                continue
            q = tightening_objective(relaxation, entry, sign)
            value = sign * safe_lower_bound(q, data.A, data.b, data.cones, dual_vector(z, len(data.b)),
                                            data.lower, data.upper)
            if sign > 0:
                proven_lo[entry] = max(proven_lo[entry], value)
            else:
                proven_hi[entry] = min(proven_hi[entry], value)
    chosen = np.asarray(entries)
    sides = widened(lo_out[chosen], hi_out[chosen], proven_lo[chosen], proven_hi[chosen])
    if sides is None:
        raise Invalid("tightening", f"{where}: sides {lo_out[chosen].tolist()}, {hi_out[chosen].tolist()} are beyond "
                                    f"the proven {proven_lo[chosen].tolist()}, {proven_hi[chosen].tolist()}")
    out_lo, out_hi = lo_in.copy(), hi_in.copy()
    out_lo[chosen], out_hi[chosen] = sides
    return out_lo, out_hi


FRAMES = BilinearVerification()

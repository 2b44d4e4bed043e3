"""Check a full certificate with linear algebra only (no conic solver is imported here).

For each certified item the verifier rebuilds the fractional program from the problem data
(solvers.charts), then checks: the objective at the returned solution; the root region's bounds
from their dual vectors; each bound-tightening round; that the leaves cover the searched box;
each leaf's safe lower bound from its dual vector (or its infeasibility or depth proof); and that
the smallest leaf bound reaches ``upper_bound - gap``. docs/certificate.md explains each step.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .bnb import Box
from .certificates import FORMAT, VERSION, data_hash, unpack
from .charts import Chart, MapChart
from .cones import proves_infeasible, safe_lower_bound
from .geometry import norm_cost
from .relaxation import (NORMS, Relaxation, cost_unit, gamma_for, residual_region, root_bounds, tightening_objective,
                         with_cost_cap)

# A bound the verifier recomputes may fall below the one the solver claimed by this much, times
# max(1, |claimed|), in the program's scaled units (where the incumbent costs about 1): what
# rebuilding the data on another machine (other BLAS, other rounding) can change.
BOUND_TOLERANCE = 1e-9
# The recomputed objective may differ from the claimed one by this much, relatively.
OBJECTIVE_TOLERANCE = 1e-9
CHECKS = ("format", "data_hash", "data", "objective", "program", "root_region", "tightening", "coverage",
          "leaf_bounds", "lower_bound", "gap")


class Invalid(Exception):
    """A check failed: ``check`` names it, the message says why."""

    def __init__(self, check: str, detail: str):
        super().__init__(detail)
        self.check, self.detail = check, detail


@dataclass
class Report:
    """``checks``: each check in order with how many items passed it, and its first failure."""

    valid: bool
    checks: list[dict] = field(default_factory=list)
    first_failure: dict | None = None
    items_checked: int = 0
    items_skipped: int = 0

    def as_dict(self) -> dict:
        return {"valid": self.valid, "checks": self.checks, "first_failure": self.first_failure,
                "items_checked": self.items_checked, "items_skipped": self.items_skipped}


def _array(value: Any, shape_hint: str) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise Invalid("data", f"{shape_hint}: not numeric") from exc
    if not np.all(np.isfinite(array)):
        raise Invalid("data", f"{shape_hint}: non-finite number")
    return array


def _item_data(kind: str, data: dict, index: int) -> tuple:
    """The raw arrays of one item of the problem data."""
    try:
        if kind == "triangulation":
            cameras = _array(data["cameras"], "data/cameras")
            track = data["tracks"][index]
            views = [int(v) for v in track["views"]]
            if cameras.ndim != 3 or cameras.shape[1:] != (3, 4) or min(views) < 0:
                raise Invalid("data", f"data/tracks/{index}: cameras or views malformed")
            points = _array(track["points"], f"data/tracks/{index}/points")
            return cameras[views], points.reshape(len(views), 2)
        if kind in ("resection", "homography"):
            entry = data["maps"][index]
            return _array(entry["source"], f"data/maps/{index}/source"), _array(entry["target"], f"data/maps/{index}/target")
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise Invalid("data", f"item {index}: {type(exc).__name__}: {exc}") from exc
    raise Invalid("format", f"unknown kind {kind!r}")


class _Item:
    """One item's program and the maps between its solution and the program's variables."""

    def __init__(self, kind: str, arrays: tuple, norm: str):
        self.kind, self.norm = kind, norm
        if kind == "triangulation":
            self.cameras, self.points = arrays
            self.chart = Chart.build(self.cameras, self.points, norm)
        else:
            self.source, self.target = arrays
            self.chart = MapChart.build(self.source, self.target, norm)
        self.program = self.chart.program

    def raw_residuals(self, solution) -> tuple[np.ndarray, np.ndarray]:
        """Residuals and depths of the caller's solution, from the raw data only."""
        numerators, depths = self.raw_parts(solution)
        return numerators / depths[:, None], depths

    def raw_parts(self, solution) -> tuple[np.ndarray, np.ndarray]:
        """Each residual as numerator / depth, from the raw data only."""
        if self.kind == "triangulation":
            proj = self.cameras @ solution
            return proj[:, :2] - self.points * proj[:, 2:3], proj[:, 2]
        homogeneous = np.hstack([self.source, np.ones((len(self.source), 1))])
        proj = homogeneous @ solution.T
        return self.target * proj[:, -1:] - proj[:, :-1], proj[:, -1]

    def solution(self, claim: dict):
        """The caller's solution from the claim (homogeneous point, or matrix), sign-normalised."""
        if self.kind == "triangulation":
            point = _array(claim.get("point"), "point")
            X = point if point.shape == (4,) else np.append(point, 1.0) if point.shape == (3,) else None
            if X is None:
                raise Invalid("objective", "point must have 3 or 4 coordinates")
            return X if X[3] >= 0 else -X
        M = _array(claim.get("matrix"), "matrix")
        if M.shape != (self.target.shape[1] + 1, self.source.shape[1] + 1):
            raise Invalid("objective", f"matrix has shape {list(M.shape)}")
        return M

    def to_program(self, solution) -> np.ndarray | None:
        if self.kind == "triangulation":
            w = np.linalg.solve(self.chart.T, solution)
            return w[:3] / w[3] if w[3] > 0 else None
        v = self.chart.from_matrix(solution)
        return v if v is not None else self.chart.from_matrix(-solution)

    def from_program(self, v: np.ndarray):
        return self.chart.T @ np.append(v, 1.0) if self.kind == "triangulation" else self.chart.matrix(v)


def verify_document(document: Any) -> Report:
    """Check a certificate document (the ``certificate`` member of a result with
    ``options.certificate = "full"``)."""
    report = Report(valid=True)
    tallies = {name: [0, 0] for name in CHECKS}  # passed, failed
    first: dict | None = None

    def fail(check: str, item: int | None, detail: str) -> None:
        nonlocal first
        tallies[check][1] += 1
        if first is None:
            first = {"check": check, "item": item, "detail": detail}

    try:
        items = _document_items(document)
        tallies["format"][0] += 1
        expected = data_hash(document["kind"], document["data"])
        if expected != document.get("data_sha256"):
            raise Invalid("data_hash", f"data_sha256 is {document.get('data_sha256')!r}, the data hash to {expected}")
        tallies["data_hash"][0] += 1
    except Invalid as exc:
        fail(exc.check, None, exc.detail)
        items = []
    except (TypeError, ValueError) as exc:  # e.g. NaN in the data: not canonical JSON
        fail("data_hash", None, f"the data cannot be hashed: {exc}")
        items = []
    options = document.get("options", {}) if isinstance(document, dict) else {}
    for claim in items:
        index = claim.get("index") if isinstance(claim, dict) else None
        index = index if isinstance(index, int) and not isinstance(index, bool) else None
        if not isinstance(claim, dict):
            fail("format", None, "each item must be an object")
            continue
        if not claim.get("certified"):
            report.items_skipped += 1
            continue
        report.items_checked += 1
        try:
            for name in verify_item(document["kind"], document["data"], options, claim):
                tallies[name][0] += 1
        except Invalid as exc:
            fail(exc.check, index, exc.detail)
        except Exception as exc:  # a malformed document is invalid, never a crash
            fail("format", index, f"{type(exc).__name__}: {exc}")
    report.first_failure = first
    report.valid = first is None and report.items_checked > 0
    if first is None and report.items_checked == 0:
        report.first_failure = {"check": "format", "item": None, "detail": "no certified item to check"}
    report.checks = [{"name": name, "passed": passed, "failed": failed}
                     for name, (passed, failed) in tallies.items() if passed or failed]
    return report


def _document_items(document: Any) -> list[dict]:
    if not isinstance(document, dict) or document.get("format") != FORMAT:
        raise Invalid("format", f"not a {FORMAT} document")
    if document.get("version") != VERSION:
        raise Invalid("format", f"version {document.get('version')!r} is not {VERSION}")
    for key in ("kind", "data", "options", "items", "data_sha256"):
        if key not in document:
            raise Invalid("format", f"missing {key!r}")
    if not isinstance(document["items"], list):
        raise Invalid("format", "items must be a list")
    return document["items"]


def verify_item(kind: str, data: dict, options: dict, claim: dict) -> list[str]:
    """Every check of one certified item, in order; raises Invalid at the first failure and
    returns the names of the checks passed."""
    arrays = _item_data(kind, data, claim["index"])
    return ["data"] + verify_arrays(kind, arrays, options, claim)[0]


def verify_arrays(kind: str, arrays: tuple, options: dict, claim: dict) -> tuple[list[str], float]:
    """verify_item on one item's raw arrays: (cameras of the views, points) for triangulation,
    (source, target) for maps. Also returns the lower bound the proof establishes (caller's
    units)."""
    norm = options.get("norm")
    if norm not in NORMS:
        raise Invalid("format", f"options.norm {norm!r} is not one of {NORMS}")
    item = _Item(kind, arrays, norm)
    passed: list[str] = []
    solution = item.solution(claim)
    residuals, depths = item.raw_residuals(solution)
    same_sign = np.all(depths > 0) or (kind != "triangulation" and np.all(depths < 0))
    if not same_sign:
        raise Invalid("objective", "the solution puts a point at non-positive depth")
    cost = norm_cost(residuals, norm)
    claimed = float(claim["cost"])
    if not abs(cost - claimed) <= OBJECTIVE_TOLERANCE * max(1.0, abs(cost)):
        raise Invalid("objective", f"the solution costs {cost!r}, the certificate claims {claimed!r}")
    passed.append("objective")
    lower_claimed = claimed - float(claim["gap"])
    proof = claim.get("proof")
    if not isinstance(proof, dict):
        raise Invalid("format", "a certified item needs a proof")
    if proof.get("type") == "trivial":  # every cost is a sum of norms, so 0 bounds it
        bound = 0.0
    elif proof.get("type") == "branch_and_bound":
        bound = _verify_search(item, options, proof, claimed, lower_claimed, solution, passed)
    else:
        raise Invalid("format", f"unknown proof type {proof.get('type')!r}")
    if not bound >= lower_claimed - BOUND_TOLERANCE * max(1.0, abs(lower_claimed)):
        raise Invalid("lower_bound", f"the leaves prove {bound!r}, less than upper_bound - gap = {lower_claimed!r}")
    passed.append("lower_bound")
    tolerance = max(float(options.get("abs_gap", 0.0)), float(options.get("rel_gap", 0.0)) * abs(claimed))
    if not (0 <= float(claim["gap"]) <= tolerance * (1 + 1e-12) + 1e-300):
        raise Invalid("gap", f"gap {claim['gap']!r} exceeds the tolerance {tolerance!r} (abs_gap, rel_gap)")
    passed.append("gap")
    return passed, bound


def _verify_search(item: _Item, options: dict, proof: dict, cost: float, lower_claimed: float, solution,
                   passed: list[str]) -> float:
    """The lower bound (caller's units) the search's proof establishes."""
    program, norm = item.program, item.norm
    scale = float(proof["scale"])
    if not (math.isfinite(scale) and scale > 0):
        raise Invalid("program", "scale must be positive")
    program.rescale(scale)
    unit = cost_unit(scale, norm)
    # Only points costing less than the claimed lower bound need excluding: every proof must
    # hold for them, so its cost cap may be anything not below that bound (less the tolerance).
    claimed = lower_claimed * unit
    cap = max(0.0, claimed - BOUND_TOLERANCE * max(1.0, abs(claimed)))
    _check_program(item, solution, scale)
    passed.append("program")

    max_residual = options.get("max_residual")
    user_gamma = float(max_residual) * scale if max_residual is not None else None
    needed = gamma_for(cap, norm) if user_gamma is None else min(gamma_for(cap, norm), user_gamma)
    root = proof["root"]
    F = np.asarray(root["functionals"], dtype=float)
    d = program.dim
    search_box = Box(*(np.asarray(side, dtype=float) for side in proof["search_box"]))
    k = len(search_box.lo)
    if F.shape != (d, d) or not 0 < k <= d or np.linalg.cond(F) > 1e12:
        raise Invalid("root_region", "functionals must be an invertible d x d matrix")
    lower, upper = (np.asarray(side, dtype=float) for side in root["bounds"])
    _check_root(program, F, float(root["gamma"]), needed, root, lower, upper)
    passed.append("root_region")

    box = Box(lower[:k], upper[:k])
    relaxation = Relaxation(program, F[:k], user_gamma, (lower[k:], upper[k:]), F)
    for number, round_ in enumerate(proof["tightening"]):
        box = _check_round(relaxation, round_, box, cap, number)
    if not (np.all(search_box.lo <= box.lo) and np.all(search_box.hi >= box.hi)):
        raise Invalid("tightening", "the searched box does not contain the proven root box")
    passed.append("tightening")

    leaves = proof["leaves"]
    leaf_lo = np.array([leaf[0] for leaf in leaves], dtype=float).reshape(len(leaves), k)
    leaf_hi = np.array([leaf[1] for leaf in leaves], dtype=float).reshape(len(leaves), k)
    gap = uncovered_part(search_box, leaf_lo, leaf_hi)
    if gap is not None:
        raise Invalid("coverage", f"no leaf covers the box {gap[0].tolist()} .. {gap[1].tolist()}")
    passed.append("coverage")

    bounds = _check_leaf_proofs(relaxation, proof["proofs"], leaves, leaf_lo, leaf_hi, cap)
    passed.append("leaf_bounds")
    return min(bounds) / unit if bounds else math.inf


@functools.lru_cache(maxsize=32)
def _sample_steps(d: int) -> tuple[np.ndarray, ...]:
    """Eight fixed pseudo-random steps (scales 1e-4 to 1) for the points the program is compared
    at: the same on every machine and every run."""
    rng = np.random.default_rng(0)
    return tuple(rng.normal(size=d) * 10.0 ** rng.uniform(-4, 0) for _ in range(8))


def _check_program(item: _Item, solution, scale: float) -> None:
    """The program rebuilt from the data is the data's problem: at the solution and at points
    around it, its residuals and depth signs are the raw data's. A program is a ratio of affine
    maps, so agreement at generic points means agreement everywhere."""
    v0 = item.to_program(solution)
    if v0 is None:
        raise Invalid("program", "the solution lies outside the program's chart")
    samples = [v0] + [v0 + step * (1 + np.abs(v0)) for step in _sample_steps(len(v0))]
    for v in samples:
        numerators, depths = item.raw_parts(item.from_program(v))
        V = np.append(v, 1.0)
        ours, ours_depth = (item.program.num @ V) / scale, item.program.den @ V
        # Where a point is (nearly) on a camera's centre, numerator and depth are both round-off:
        # such observations are compared at the other points.
        clear = np.abs(depths) > 1e-6 * np.max(np.abs(depths))
        theirs, ours = numerators[clear] / depths[clear, None], ours[clear] / ours_depth[clear, None]
        # np.allclose's test, |ours - theirs| <= atol + rtol |theirs|, without its overhead.
        tolerance = 1e-9 * (1 + np.max(np.abs(theirs), initial=0)) + 1e-6 * np.abs(theirs)
        if not (np.abs(ours - theirs) <= tolerance).all():
            raise Invalid("program", "the program's residuals differ from the data's")
        varying = ~item.program.exact & clear
        relative = np.sign(ours_depth[varying]) * np.sign(depths[varying])
        if relative.size and not (np.all(relative > 0) or (item.kind != "triangulation" and np.all(relative < 0))):
            raise Invalid("program", "the program's depth signs differ from the data's")


def _check_root(program, F: np.ndarray, gamma: float, needed: float, root: dict, lower, upper) -> None:
    if not gamma >= needed:
        raise Invalid("root_region", f"gamma {gamma!r} is below the residual bound {needed!r} of the claimed lower bound")
    region = residual_region(program, gamma)
    claim_lo, claim_hi = (np.asarray(side, dtype=float) for side in root["claim"])
    if len(root["duals"]) != 2 * len(F):
        raise Invalid("root_region", f"{len(root['duals'])} dual vectors for {len(F)} functionals")
    duals = [_dual(text, len(region[1])) for text in root["duals"]]
    proven_lower, proven_upper = root_bounds(region, F, duals, claim_lo, claim_hi)
    for j, (low, high) in enumerate(zip(proven_lower, proven_upper)):
        if not (claim_lo[j] < low and high < claim_hi[j]):
            raise Invalid("root_region", f"functional {j}: proven range [{low}, {high}] not inside the claimed box")
        if not (lower[j] <= low and upper[j] >= high):
            raise Invalid("root_region", f"functional {j}: bounds [{lower[j]}, {upper[j]}] are tighter than "
                                         f"the proven [{low}, {high}]")


def _dual(text: str | None, rows: int) -> np.ndarray:
    z = unpack(text)
    if z is None or z.shape != (rows,):
        raise Invalid("format", f"a dual vector must have {rows} entries")
    return z


def _check_round(relaxation: Relaxation, round_: dict, box: Box, cap: float, number: int) -> Box:
    ub = float(round_["upper_bound"])
    box_in = Box(*(np.asarray(side, dtype=float) for side in round_["box_in"]))
    box_out = Box(*(np.asarray(side, dtype=float) for side in round_["box_out"]))
    if not (np.array_equal(box_in.lo, box.lo) and np.array_equal(box_in.hi, box.hi)):
        raise Invalid("tightening", f"round {number} starts from a box that is not the previous one")
    if not ub >= cap:
        raise Invalid("tightening", f"round {number} assumed a cost cap below the claimed lower bound")
    data = relaxation.conic_data(box_in, ub, envelope=False)
    if data is None:
        raise Invalid("tightening", f"round {number}: no depth is positive on its box")
    data = with_cost_cap(data, ub)
    duals = round_["duals"]
    if len(duals) != 2 * len(box.lo):
        raise Invalid("tightening", f"round {number}: {len(duals)} dual vectors for {len(box.lo)} functionals")
    for i in range(len(box.lo)):
        for side, sign in ((0, 1.0), (1, -1.0)):
            z = duals[2 * i + side]
            proven = box_in.lo[i] if sign > 0 else box_in.hi[i]
            if z is not None:
                objective = tightening_objective(data, relaxation.B[i], sign)
                value = sign * safe_lower_bound(objective, data.A, data.b, data.cones, _dual(z, len(data.b)),
                                                data.lower, data.upper, data.transform)
                proven = max(proven, value) if sign > 0 else min(proven, value)
            claimed = box_out.lo[i] if sign > 0 else box_out.hi[i]
            if (sign > 0 and claimed > proven) or (sign < 0 and claimed < proven):
                raise Invalid("tightening", f"round {number}, functional {i}: side {claimed!r} is beyond "
                                            f"the proven {proven!r}")
    return box_out


def _check_leaf_proofs(relaxation: Relaxation, proofs: list, leaves: list, leaf_lo, leaf_hi,
                       cap: float) -> list[float]:
    """Each proof's bound, recomputed; each leaf's box inside its proof's box."""
    proven: list[float] = []
    for number, proof in enumerate(proofs):
        box = Box(*(np.asarray(side, dtype=float) for side in proof["box"]))
        ub = float(proof["upper_bound"])
        if not ub >= cap:
            raise Invalid("leaf_bounds", f"proof {number} assumed a cost cap below the claimed lower bound")
        data = relaxation.conic_data(box, ub)
        kind = proof["kind"]
        if kind == "depth":
            if data is not None:
                raise Invalid("leaf_bounds", f"proof {number}: the depths are not all negative on its box")
            proven.append(math.inf)
            continue
        if data is None:
            raise Invalid("leaf_bounds", f"proof {number}: no relaxation on a box without positive depths")
        z = _dual(proof["z"], len(data.b))
        if kind == "farkas":
            if not proves_infeasible(data.A, data.b, data.cones, z, data.lower, data.upper, data.transform):
                raise Invalid("leaf_bounds", f"proof {number}: its Farkas vector does not prove infeasibility")
            proven.append(math.inf)
            continue
        if kind != "dual":
            raise Invalid("format", f"proof {number}: unknown kind {kind!r}")
        bound = safe_lower_bound(data.q, data.A, data.b, data.cones, z, data.lower, data.upper, data.transform)
        claimed = float(proof["bound"])
        if not bound >= claimed - BOUND_TOLERANCE * max(1.0, abs(claimed)):
            raise Invalid("leaf_bounds", f"proof {number}: its dual proves {bound!r}, it claims {claimed!r}")
        proven.append(bound)
    bounds = []
    for number, leaf in enumerate(leaves):
        index = leaf[2]
        if index is None:
            bounds.append(0.0)  # the trivial bound: every cost is a sum of norms
            continue
        box = proofs[index]["box"]
        if not (np.all(np.asarray(box[0]) <= leaf_lo[number]) and np.all(np.asarray(box[1]) >= leaf_hi[number])):
            raise Invalid("leaf_bounds", f"leaf {number} is not inside the box of its proof {index}")
        bounds.append(proven[index])
    return bounds


def uncovered_part(root: Box, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """A part of ``root`` that no box (lo[i], hi[i]) covers, or None when they cover it all.

    Exact (no tolerance): subtract each closed box from the closed pieces still uncovered; what
    a subtraction leaves are slabs reaching strictly beyond the box, so nothing is lost.
    """
    pieces = [(root.lo.copy(), root.hi.copy())]
    order = np.lexsort(lo.T[::-1])  # a sweep: neighbours follow each other
    for i in order:
        remaining = []
        for p_lo, p_hi in pieces:
            if np.any(lo[i] > p_hi) or np.any(hi[i] < p_lo):
                remaining.append((p_lo, p_hi))
                continue
            p_lo, p_hi = p_lo.copy(), p_hi.copy()
            for axis in range(len(p_lo)):
                if p_lo[axis] < lo[i][axis]:
                    slab_hi = p_hi.copy()
                    slab_hi[axis] = lo[i][axis]
                    remaining.append((p_lo.copy(), slab_hi))
                    p_lo[axis] = lo[i][axis]
                if p_hi[axis] > hi[i][axis]:
                    slab_lo = p_lo.copy()
                    slab_lo[axis] = hi[i][axis]
                    remaining.append((slab_lo, p_hi.copy()))
                    p_hi[axis] = hi[i][axis]
        pieces = remaining
        if not pieces:
            return None
    return pieces[0] if pieces else None


class SelfCheckFailed(AssertionError):
    """A certified result its own certificate does not prove (GEOCERT_SELF_VERIFY=1)."""


def self_check_enabled() -> bool:
    """GEOCERT_SELF_VERIFY=1: every certified result is checked by this module before it is
    returned (the test suites run so; an operator may too, at about twice the solve time)."""
    return os.environ.get("GEOCERT_SELF_VERIFY") == "1"


def self_check(kind: str, arrays: tuple, options: dict, claim: dict) -> None:
    try:
        verify_arrays(kind, arrays, options, claim)
    except Invalid as exc:
        raise SelfCheckFailed(f"{kind}: check {exc.check} failed: {exc.detail}") from exc


def proof_of(result) -> dict | None:
    """The proof member of a solved item: its search's, or the trivial bound's."""
    if result.certificate is not None and result.certificate.proof is not None:
        return result.certificate.proof
    return {"type": "trivial"} if result.certified and result.certificate is None else None


def claim_of(result, **solution) -> dict:
    """What a certificate document says of one item (index 0), from a solver's result."""
    return {"index": 0, "status": result.status, "certified": result.certified, "cost": result.cost,
            "lower_bound": result.lower_bound, "gap": result.gap, **solution, "proof": proof_of(result)}


def checked_solve(kind: str, arrays: tuple, options, solve: Callable, solution: Callable) -> Any:
    """``solve(options)``, self-checked when GEOCERT_SELF_VERIFY=1: then it runs with a full
    certificate and the verifier checks a certified result (``solution(result)`` gives the
    claim's solution fields); the proof is kept only when the caller asked for it."""
    checking = self_check_enabled()
    run = dataclasses.replace(options, certificate="full") if checking else options
    result = solve(run)
    if checking and result.certified:
        self_check(kind, arrays, dataclasses.asdict(run), claim_of(result, **solution(result)))
    if options.certificate != "full" and result.certificate is not None:
        result.certificate.proof = None
    return result

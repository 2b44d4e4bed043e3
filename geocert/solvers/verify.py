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

from geocert.solvers.core.bnb import Box
from geocert.solvers.core.certificates import FORMAT, VERSION, data_hash, problem_hash, unpack
from geocert.solvers.fractional.charts import Chart, MapChart
from geocert.solvers.core.cones import proves_infeasible, safe_lower_bound
from geocert.solvers.core.geometry import norm_cost, normalised_cameras
from geocert.solvers.fractional.relaxation import (NORMS, Relaxation, cost_unit, gamma_for, residual_region, root_bounds, tightening_objective,
                         with_cost_cap)

# Every tolerance is relative, with no absolute floor a document could exploit (docs/certificate.md,
# "Trust model"). A bound the verifier recomputes may fall below the one claimed by this fraction
# of it: what rebuilding the data on another machine (other BLAS, other rounding) can change. The
# same fraction applies to cost caps, to the objective and to the claimed lower bound.
BOUND_TOLERANCE = 1e-9
OBJECTIVE_TOLERANCE = 1e-9
# What the service serves, and nothing else: (source, target) dimensions per map kind, the most
# views in a track, points in a map, leaves in a search and the nesting of a document.
MAP_DIMENSIONS = {"resection": {(3, 2)}, "homography": {(2, 2), (3, 3)}}
MAX_VIEWS = 1000  # views in a track (the parser's limit too)
MAX_POINTS = 1_000_000
MAX_DEPTH = 64
MAX_PIECES = 5_000
MAX_ROUNDS = 16  # bound-tightening rounds (the solver makes at most 4)
MAX_WORK = 200_000  # leaf-piece tests when leaves are subtracted one by one
SCALE_RANGE = (1e-15, 1e3)  # the solver's residual factor lies in it (fractional.MAX_SCALE above)
CHECKS = ("format", "data_hash", "options", "data", "claim", "objective", "scope", "program", "root_region",
          "tightening", "coverage", "leaf_bounds", "lower_bound", "gap", "returned")


class Invalid(Exception):
    """A check failed: ``check`` names it, the message says why."""

    def __init__(self, check: str, detail: str):
        super().__init__(detail)
        self.check, self.detail = check, detail


@dataclass
class Report:
    """``checks``: each check in order with how many items passed it, and its first failure;
    ``scope``: what a valid document proves, and for which problem."""

    valid: bool
    checks: list[dict] = field(default_factory=list)
    first_failure: dict | None = None
    items_checked: int = 0
    items_skipped: int = 0
    scope: dict | None = None

    def as_dict(self) -> dict:
        return {"valid": self.valid, "checks": self.checks, "first_failure": self.first_failure,
                "items_checked": self.items_checked, "items_skipped": self.items_skipped, "scope": self.scope}


# --- strict readers: JSON numbers only (no strings, booleans, null or non-finite values) -------

def _number(value: Any, name: str, check: str = "format") -> float:
    if type(value) is float:
        if math.isfinite(value):
            return value
    elif type(value) is int and abs(value) < 2**1023:
        return float(value)
    raise Invalid(check, f"{name} must be a finite JSON number, got {value!r:.40}")


def _numbers(value: Any, name: str, shape: tuple[int | None, ...], check: str = "format") -> np.ndarray:
    """Nested lists of finite JSON numbers of the given shape (None: any length)."""
    def walk(v, level: int, where: str):
        if level == len(shape):
            return _number(v, where, check)
        if not isinstance(v, list) or (shape[level] is not None and len(v) != shape[level]):
            size = "a list" if shape[level] is None else f"a list of {shape[level]}"
            raise Invalid(check, f"{where} must be {size}")
        return [walk(x, level + 1, f"{where}/{i}") for i, x in enumerate(v)]
    rows = walk(value, 0, name)
    try:
        array = np.array(rows, dtype=float)
    except ValueError as exc:
        raise Invalid(check, f"{name}: rows of different lengths") from exc
    if array.ndim != len(shape):
        raise Invalid(check, f"{name}: rows of different lengths")
    return array


def _box(value: Any, name: str, k: int) -> Box:
    lo, hi = _numbers(value, name, (2, k))
    return Box(lo, hi)


def _nesting_depth(value: Any) -> int:
    """How deeply lists and objects nest (iterative: a hostile document cannot overflow a stack)."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, (list, dict)):
            deepest = max(deepest, depth)
            if depth > MAX_DEPTH:
                return depth
            stack.extend((x, depth + 1) for x in (v.values() if isinstance(v, dict) else v))
    return deepest


# --- the problem: options, data, one item ---------------------------------------------------

def checked_options(options: Any) -> dict:
    """The options a claim depends on, validated as the solver validates them: the norm, the
    scope (max_residual: every residual's pixel distance within it) and the gap tolerances."""
    if not isinstance(options, dict):
        raise Invalid("options", "options must be an object")
    norm = options.get("norm")
    if norm not in NORMS:
        raise Invalid("options", f"norm {norm!r} is not one of {NORMS}")
    checked = {"norm": norm}
    for name in ("rel_gap", "abs_gap"):
        value = _number(options.get(name), f"options/{name}", "options")
        if value < 0:
            raise Invalid("options", f"options/{name} must be >= 0")
        checked[name] = value
    max_residual = options.get("max_residual")
    if max_residual is not None:
        max_residual = _number(max_residual, "options/max_residual", "options")
        if not max_residual > 0:
            raise Invalid("options", "options/max_residual must be > 0")
    checked["max_residual"] = max_residual
    return checked


def scope_statement(kind: str, options: dict) -> dict:
    """What a valid certificate of this kind proves, in words and numbers."""
    domain = ("every point in front of every camera (positive depth in every view, last homogeneous "
              "coordinate >= 0)" if kind == "triangulation" else "every map that puts every point at positive depth")
    if options["max_residual"] is not None:
        domain += f" with every residual's length (pixel distance) at most {options['max_residual']!r}"
    return {"kind": kind, "norm": options["norm"], "max_residual": options["max_residual"],
            "rel_gap": options["rel_gap"], "abs_gap": options["abs_gap"],
            "statement": f"for each certified item: no solution in the scope ({domain}) costs less than "
                         f"lower_bound * (1 - {BOUND_TOLERANCE:g}); the solution returned is in the scope and "
                         f"costs cost (within a relative {OBJECTIVE_TOLERANCE:g})"}


def _item_data(kind: str, data: dict, index: int) -> tuple:
    """The raw arrays of one item of the problem data, refused unless the service serves them."""
    if not isinstance(data, dict):
        raise Invalid("data", "data must be an object")
    if kind == "triangulation":
        cameras = _numbers(data.get("cameras"), "data/cameras", (None, 3, 4), "data")
        tracks = data.get("tracks")
        if not isinstance(tracks, list) or not 0 <= index < len(tracks) or not isinstance(tracks[index], dict):
            raise Invalid("data", f"data/tracks/{index}: no such track")
        track = tracks[index]
        views = track.get("views")
        if (not isinstance(views, list) or not 2 <= len(views) <= MAX_VIEWS
                or not all(type(v) is int and 0 <= v < len(cameras) for v in views) or len(set(views)) != len(views)):
            raise Invalid("data", f"data/tracks/{index}/views: 2 or more distinct camera indices")
        points = _numbers(track.get("points"), f"data/tracks/{index}/points", (len(views), 2), "data")
        return normalised_cameras(cameras[views]), points
    if kind in MAP_DIMENSIONS:
        maps = data.get("maps")
        if not isinstance(maps, list) or not 0 <= index < len(maps) or not isinstance(maps[index], dict):
            raise Invalid("data", f"data/maps/{index}: no such map")
        entry = maps[index]
        source = _numbers(entry.get("source"), f"data/maps/{index}/source", (None, None), "data")
        target = _numbers(entry.get("target"), f"data/maps/{index}/target", (len(source), None), "data")
        dims = (source.shape[1], target.shape[1])
        if dims not in MAP_DIMENSIONS[kind] or not 1 <= len(source) <= MAX_POINTS:
            raise Invalid("data", f"data/maps/{index}: {dims[0]}D -> {dims[1]}D is not served for {kind}")
        return source, target
    raise Invalid("format", f"kind {kind!r} is not served (served: triangulation, resection, homography)")


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

    def raw_residuals(self, solution) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Residuals and depths of the caller's solution, from the raw data only, computed as the
        solver computes them (projection minus observation); and a bound on each residual
        coordinate's rounding error (a few thousand units in the last place of the larger of the
        two), which is all an honest recomputation can differ by."""
        if self.kind == "triangulation":
            proj = self.cameras @ solution
            image = proj[:, :2] / proj[:, 2:3]
            residuals, observed, depths = image - self.points, self.points, proj[:, 2]
        else:
            proj = np.hstack([self.source, np.ones((len(self.source), 1))]) @ solution.T
            image = proj[:, :-1] / proj[:, -1:]
            residuals, observed, depths = self.target - image, self.target, proj[:, -1]
        rounding = 1e-12 * (np.abs(image) + np.abs(observed))
        return residuals, depths, rounding

    def raw_parts(self, solution) -> tuple[np.ndarray, np.ndarray]:
        """Each residual as numerator / depth, from the raw data only."""
        if self.kind == "triangulation":
            proj = self.cameras @ solution
            return proj[:, :2] - self.points * proj[:, 2:3], proj[:, 2]
        homogeneous = np.hstack([self.source, np.ones((len(self.source), 1))])
        proj = homogeneous @ solution.T
        return self.target * proj[:, -1:] - proj[:, :-1], proj[:, -1]

    def solution(self, claim: dict):
        """The caller's solution from the claim: a finite point [x, y, z], a point at infinity
        (a 4-vector with last coordinate exactly 0, signed so that its depths are positive), or a
        matrix."""
        if self.kind == "triangulation":
            point = claim.get("point")
            at_infinity = claim.get("at_infinity")
            if at_infinity is True:
                X = _numbers(point, "point", (4,))
                if X[3] != 0:
                    raise Invalid("claim", "a point at infinity must have last coordinate 0")
                return X
            if at_infinity is not False:
                raise Invalid("claim", "at_infinity must be true or false")
            return np.append(_numbers(point, "point", (3,)), 1.0)
        return _numbers(claim.get("matrix"), "matrix", (self.target.shape[1] + 1, self.source.shape[1] + 1))

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
    return _verify(document, None)


def find_certificate(document: Any) -> tuple[dict, dict | None] | None:
    """(certificate, the result that returns it or None) from a certificate, result or job
    document; None when the document carries no certificate."""
    if not isinstance(document, dict):
        return None
    if document.get("format") is not None:
        return document, None
    if isinstance(document.get("result"), dict):  # a job document
        document = document["result"]
    if isinstance(document.get("certificate"), dict):  # a result document
        return document["certificate"], document
    return None


def verify_any(document: Any) -> Report:
    """Check what ``geocert verify`` and ``POST /v1/certificates/verify`` take: a certificate
    document, a result document carrying one, or a job document carrying such a result. For a
    result or job, every item it returns must also equal the item its certificate proves."""
    found = find_certificate(document)
    if found is None:
        report = Report(valid=False, first_failure={
            "check": "format", "item": None,
            "detail": "no certificate in this document (a job or result solved with options.certificate = \"full\" "
                      "carries one)"})
        report.checks = [{"name": "format", "passed": 0, "failed": 1}]
        return report
    return _verify(*found)


def _verify(document: Any, returned: dict | None) -> Report:
    report = Report(valid=True)
    tallies = {name: [0, 0] for name in CHECKS}  # passed, failed
    first: dict | None = None

    def fail(check: str, item: int | None, detail: str) -> None:
        nonlocal first
        tallies[check][1] += 1
        if first is None:
            first = {"check": check, "item": item, "detail": detail}

    items: list = []
    options: dict = {}
    try:
        if _nesting_depth(document) > MAX_DEPTH or (returned is not None and _nesting_depth(returned) > MAX_DEPTH):
            raise Invalid("format", f"the document nests deeper than {MAX_DEPTH} levels")
        items = _document_items(document)
        tallies["format"][0] += 1
        options = checked_options(document["options"])
        tallies["options"][0] += 1
        _check_hashes(document, options)
        tallies["data_hash"][0] += 1
        report.scope = scope_statement(document["kind"], options)
    except Invalid as exc:
        fail(exc.check, None, exc.detail)
        items = []
    except (TypeError, ValueError, RecursionError) as exc:  # e.g. NaN in the data: not canonical JSON
        fail("data_hash", None, f"the data cannot be hashed: {type(exc).__name__}: {exc}")
        items = []
    for position, claim in enumerate(items):
        if not isinstance(claim, dict) or claim.get("index") != position:
            fail("format", position, "each item must be an object whose index is its position")
            continue
        certified = claim.get("certified")
        if certified is not True:
            if certified is not False:
                fail("claim", position, "certified must be true or false")
            report.items_skipped += 1
            continue
        report.items_checked += 1
        try:
            for name in verify_item(document["kind"], document["data"], options, claim):
                tallies[name][0] += 1
        except Invalid as exc:
            fail(exc.check, position, exc.detail)
        except Exception as exc:  # a malformed document is invalid, never a crash
            fail("format", position, f"{type(exc).__name__}: {exc}")
    if returned is not None and first is None:
        try:
            _check_returned(returned, document)
            tallies["returned"][0] += 1
        except Invalid as exc:
            fail(exc.check, None, exc.detail)
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
    for key in ("kind", "data", "options", "items", "data_sha256", "problem_sha256"):
        if key not in document:
            raise Invalid("format", f"missing {key!r}")
    if document["kind"] not in ("triangulation", *MAP_DIMENSIONS):
        raise Invalid("format", f"kind {document['kind']!r} is not served (served: triangulation, resection, homography)")
    if not isinstance(document["items"], list):
        raise Invalid("format", "items must be a list")
    return document["items"]


def _check_hashes(document: dict, options: dict) -> None:
    expected = data_hash(document["kind"], document["data"])
    if expected != document["data_sha256"]:
        raise Invalid("data_hash", f"data_sha256 is {document['data_sha256']!r}, but the data hash to {expected!r}")
    expected = problem_hash(document["kind"], document["data"], options)
    if expected != document["problem_sha256"]:
        raise Invalid("data_hash", f"problem_sha256 is {document['problem_sha256']!r}, but the kind, data and "
                                   f"options (norm, max_residual, rel_gap, abs_gap) hash to {expected!r}")


# What a result returns of each item, which must equal what its certificate proves.
RETURNED_FIELDS = ("status", "certified", "cost", "lower_bound", "gap", "point", "at_infinity", "matrix")


def _check_returned(result: dict, certificate: dict) -> None:
    key = "tracks" if certificate["kind"] == "triangulation" else "maps"
    if result.get("kind") != certificate["kind"] or result.get("norm") != certificate["options"].get("norm"):
        raise Invalid("returned", "the result's kind or norm differs from its certificate's")
    items = result.get(key)
    if not isinstance(items, list) or len(items) != len(certificate["items"]):
        raise Invalid("returned", f"the result's {key} are not the certificate's items")
    for index, (item, claim) in enumerate(zip(items, certificate["items"])):
        if not isinstance(item, dict):
            raise Invalid("returned", f"{key}/{index} must be an object")
        for name in RETURNED_FIELDS:
            if (name in item or name in claim) and item.get(name) != claim.get(name):
                raise Invalid("returned", f"{key}/{index}/{name} is {item.get(name)!r}, its certificate proves "
                                          f"{claim.get(name)!r}")


def verify_item(kind: str, data: dict, options: dict, claim: dict) -> list[str]:
    """Every check of one certified item, in order; raises Invalid at the first failure and
    returns the names of the checks passed."""
    arrays = _item_data(kind, data, claim["index"])
    return ["data"] + verify_arrays(kind, arrays, options, claim)[0]


def verify_arrays(kind: str, arrays: tuple, options: dict, claim: dict) -> tuple[list[str], float]:
    """verify_item on one item's raw arrays: (cameras of the views, points) for triangulation,
    (source, target) for maps. Also returns the lower bound the proof establishes (caller's
    units)."""
    options = checked_options(options)
    norm = options["norm"]
    item = _Item(kind, arrays, norm)
    passed: list[str] = []
    if claim.get("status") != "optimal" or claim.get("certified") is not True:
        raise Invalid("claim", "a certified item has status 'optimal' and certified true")
    claimed = _number(claim.get("cost"), "cost", "claim")
    gap = _number(claim.get("gap"), "gap", "claim")
    lower_claimed = _number(claim.get("lower_bound"), "lower_bound", "claim")
    if not (0 <= gap and lower_claimed <= claimed
            and abs((claimed - gap) - lower_claimed) <= 1e-12 * max(abs(claimed), abs(lower_claimed))):
        raise Invalid("claim", f"lower_bound {lower_claimed!r}, cost {claimed!r} and gap {gap!r} disagree "
                               "(lower_bound = cost - gap, gap >= 0)")
    passed.append("claim")
    solution = item.solution(claim)
    residuals, depths, rounding = item.raw_residuals(solution)
    same_sign = np.all(depths > 0) or (kind != "triangulation" and np.all(depths < 0))
    if not same_sign:
        raise Invalid("objective", "the solution puts a point at non-positive depth")
    cost = norm_cost(residuals, norm)
    if not abs(cost - claimed) <= OBJECTIVE_TOLERANCE * abs(cost) + _cost_rounding(residuals, rounding, norm):
        raise Invalid("objective", f"the solution costs {cost!r}, the certificate claims {claimed!r}")
    passed.append("objective")
    if options["max_residual"] is not None:
        longest = float(np.max(np.sqrt((residuals * residuals).sum(axis=1))))
        if not longest <= options["max_residual"]:
            raise Invalid("scope", f"the solution has a residual of length {longest!r}, beyond max_residual "
                                   f"{options['max_residual']!r}")
    passed.append("scope")
    proof = claim.get("proof")
    if not isinstance(proof, dict):
        raise Invalid("format", "a certified item needs a proof")
    if proof.get("type") == "trivial":  # every cost is a sum of norms, so 0 bounds it
        bound = 0.0
    elif proof.get("type") == "branch_and_bound":
        bound = _verify_search(item, options, proof, lower_claimed, solution, passed)
    else:
        raise Invalid("format", f"unknown proof type {proof.get('type')!r}")
    if not bound >= lower_claimed - BOUND_TOLERANCE * abs(lower_claimed):
        raise Invalid("lower_bound", f"the proof establishes {bound!r}, less than lower_bound {lower_claimed!r}")
    passed.append("lower_bound")
    tolerance = max(options["abs_gap"], options["rel_gap"] * abs(claimed))
    if not gap <= tolerance * (1 + 1e-12):
        raise Invalid("gap", f"gap {gap!r} exceeds the tolerance {tolerance!r} (abs_gap, rel_gap)")
    passed.append("gap")
    return passed, bound


def _cost_rounding(residuals: np.ndarray, rounding: np.ndarray, norm: str) -> float:
    """How much the cost can change when each residual coordinate moves by its rounding bound:
    the only slack beside the relative OBJECTIVE_TOLERANCE, tied to the data, not the document."""
    if norm == "L2L2":
        return float(np.sum(2 * np.abs(residuals) * rounding + rounding * rounding))
    if norm == "L2L1":
        return float(np.sum(np.sqrt((rounding * rounding).sum(axis=1))))
    return float(np.sum(rounding))


def _verify_search(item: _Item, options: dict, proof: dict, lower_claimed: float, solution,
                   passed: list[str]) -> float:
    """The lower bound (caller's units) the search's proof establishes."""
    program, norm = item.program, item.norm
    scale = _number(proof.get("scale"), "proof/scale")
    if not SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]:
        raise Invalid("program", f"scale must lie in {SCALE_RANGE}")
    program.max_residual = options["max_residual"]
    program.rescale(scale)
    unit = cost_unit(scale, norm)
    # Only points costing less than the claimed lower bound need excluding: every proof must
    # hold for them, so its cost cap may be anything not below that bound (less the relative
    # tolerance: a cap of 0 would prove nothing of a positive bound, whatever the scale).
    cap = max(0.0, lower_claimed * unit * (1 - BOUND_TOLERANCE))
    _check_program(item, solution, scale)
    passed.append("program")

    root = proof.get("root")
    if not isinstance(root, dict):
        raise Invalid("format", "proof/root must be an object")
    d = program.dim
    F = _numbers(root.get("functionals"), "proof/root/functionals", (d, d))
    search_box_raw = proof.get("search_box")
    k = len(search_box_raw[0]) if isinstance(search_box_raw, list) and search_box_raw and \
        isinstance(search_box_raw[0], list) else 0
    if not 0 < k <= min(d, 3) or not np.linalg.cond(F) <= 1e6:
        raise Invalid("root_region", "functionals must be an invertible d x d matrix, at most 3 of them branched")
    search_box = _box(search_box_raw, "proof/search_box", k)
    lower, upper = _numbers(root.get("bounds"), "proof/root/bounds", (2, d))
    gamma = _number(root.get("gamma"), "proof/root/gamma")
    needed = gamma_for(cap, norm)
    if program.max_residual is not None:
        needed = min(needed, program.max_residual)
    _check_root(program, F, gamma, needed, root, lower, upper, item.to_program(solution))
    passed.append("root_region")

    box = Box(lower[:k], upper[:k])
    relaxation = Relaxation(program, F[:k], (lower[k:], upper[k:]), F)
    rounds = proof.get("tightening")
    if not isinstance(rounds, list):
        raise Invalid("format", "proof/tightening must be a list")
    if len(rounds) > MAX_ROUNDS:
        raise Invalid("tightening", f"{len(rounds)} tightening rounds: at most {MAX_ROUNDS}")
    for number, round_ in enumerate(rounds):
        box = _check_round(relaxation, round_, box, cap, number)
    if not (np.all(search_box.lo <= box.lo) and np.all(search_box.hi >= box.hi)):
        raise Invalid("tightening", "the searched box does not contain the proven root box")
    passed.append("tightening")

    leaves, proofs = proof.get("leaves"), proof.get("proofs")
    if not isinstance(leaves, list) or not leaves or not isinstance(proofs, list):
        raise Invalid("format", "proof/leaves and proof/proofs must be lists, leaves not empty")
    for number, leaf in enumerate(leaves):
        if not (isinstance(leaf, list) and len(leaf) == 3 and (leaf[2] is None or
                                                               (type(leaf[2]) is int and 0 <= leaf[2] < len(proofs)))):
            raise Invalid("format", f"leaf {number} must be [lower corner, upper corner, proof index or null]")
    leaf_lo = _numbers([leaf[0] for leaf in leaves], "proof/leaves (lower corners)", (len(leaves), k))
    leaf_hi = _numbers([leaf[1] for leaf in leaves], "proof/leaves (upper corners)", (len(leaves), k))
    gap = uncovered_part(search_box, leaf_lo, leaf_hi)
    if gap is not None:
        raise Invalid("coverage", f"no leaf covers the box {gap[0].tolist()} .. {gap[1].tolist()}")
    passed.append("coverage")

    bounds = _check_leaf_proofs(relaxation, proofs, leaves, leaf_lo, leaf_hi, cap, k)
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


def _check_root(program, F: np.ndarray, gamma: float, needed: float, root: dict, lower, upper,
                witness: np.ndarray) -> None:
    """The root region's bounds. Dual bounds hold on R ∩ claim; they hold on all of R (R convex)
    only when R meets the inside of ``claim``: the returned solution (``witness``, in the
    program's variables) must be a point of R well inside ``claim``."""
    if not gamma >= needed:
        raise Invalid("root_region", f"gamma {gamma!r} is below the residual bound {needed!r} of the claimed lower bound")
    region = residual_region(program, gamma)
    claim_lo, claim_hi = _numbers(root.get("claim"), "proof/root/claim", (2, len(F)))
    V = np.append(witness, 1.0)
    numerators, depths = program.num @ V, program.den @ V
    linear = program.linear @ V
    inside_region = (np.all(np.sqrt((numerators * numerators).sum(axis=1)) <= gamma * depths)
                     and np.all(linear >= -1e-12 * np.abs(program.linear) @ np.abs(V)))
    y = F @ witness
    margin = 1e-9 * (1 + np.abs(claim_lo) + np.abs(claim_hi))
    if not (inside_region and np.all(claim_lo + margin < y) and np.all(y < claim_hi - margin)):
        raise Invalid("root_region", "the solution is not a point of the residual region inside the claimed box: "
                                     "the region's bounds may be vacuous")
    texts = root.get("duals")
    if not isinstance(texts, list) or len(texts) != 2 * len(F):
        raise Invalid("root_region", f"{len(F)} functionals need {2 * len(F)} dual vectors")
    duals = [_dual(text, len(region[1])) for text in texts]
    proven_lower, proven_upper = root_bounds(region, F, duals, claim_lo, claim_hi)
    for j, (low, high) in enumerate(zip(proven_lower, proven_upper)):
        if not (claim_lo[j] < low <= high < claim_hi[j]):
            raise Invalid("root_region", f"functional {j}: proven range [{low}, {high}] not inside the claimed box")
        if not (lower[j] <= low and upper[j] >= high):
            raise Invalid("root_region", f"functional {j}: bounds [{lower[j]}, {upper[j]}] are tighter than "
                                         f"the proven [{low}, {high}]")


def _dual(text: Any, rows: int) -> np.ndarray:
    if not isinstance(text, str):
        raise Invalid("format", "a dual vector must be a base64 string")
    try:
        z = unpack(text)
    except ValueError as exc:
        raise Invalid("format", f"a dual vector is not base64 of float64: {exc}") from exc
    if z is None or z.shape != (rows,) or not np.all(np.isfinite(z)):
        raise Invalid("format", f"a dual vector must have {rows} finite entries")
    return z


def _finite_bounds(data, where: str) -> None:
    """Every variable of a relaxation bounded on both sides: no term of a safe bound is dropped."""
    if not (np.all(np.isfinite(data.lower)) and np.all(np.isfinite(data.upper))):
        raise Invalid("leaf_bounds", f"{where}: a relaxation variable has an infinite bound")


def _check_round(relaxation: Relaxation, round_: Any, box: Box, cap: float, number: int) -> Box:
    if not isinstance(round_, dict):
        raise Invalid("format", f"tightening round {number} must be an object")
    k = len(box.lo)
    ub = _number(round_.get("upper_bound"), f"tightening/{number}/upper_bound")
    box_in = _box(round_.get("box_in"), f"tightening/{number}/box_in", k)
    box_out = _box(round_.get("box_out"), f"tightening/{number}/box_out", k)
    if not (np.array_equal(box_in.lo, box.lo) and np.array_equal(box_in.hi, box.hi)):
        raise Invalid("tightening", f"round {number} starts from a box that is not the previous one")
    if not ub >= cap:
        raise Invalid("tightening", f"round {number} assumed a cost cap below the claimed lower bound")
    duals = round_.get("duals")
    if not isinstance(duals, list) or len(duals) != 2 * k:
        raise Invalid("tightening", f"round {number}: {k} functionals need {2 * k} dual vectors")
    if all(z is None for z in duals):  # nothing proven: every side must stay as it was
        if not (np.array_equal(box_out.lo, box_in.lo) and np.array_equal(box_out.hi, box_in.hi)):
            raise Invalid("tightening", f"round {number}: sides moved without a dual vector")
        return box_out
    data = relaxation.conic_data(box_in, ub, envelope=False)
    if data is None:
        raise Invalid("tightening", f"round {number}: no depth is positive on its box")
    _finite_bounds(data, f"tightening round {number}")
    data = with_cost_cap(data, ub)
    for i in range(k):
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
                       cap: float, k: int) -> list[float]:
    """Each proof's bound, recomputed; each leaf's box inside its proof's box."""
    proven: list[float] = []
    boxes: list[Box] = []
    for number, proof in enumerate(proofs):
        if not isinstance(proof, dict):
            raise Invalid("format", f"proof {number} must be an object")
        box = _box(proof.get("box"), f"proofs/{number}/box", k)
        boxes.append(box)
        ub = _number(proof.get("upper_bound"), f"proofs/{number}/upper_bound")
        if not ub >= cap:
            raise Invalid("leaf_bounds", f"proof {number} assumed a cost cap below the claimed lower bound")
        kind = proof.get("kind")
        if kind == "depth":  # the depth ranges alone decide it (what conic_data tests first)
            if not np.any(relaxation.depth_range(box)[1] <= 0):
                raise Invalid("leaf_bounds", f"proof {number}: the depths are not all negative on its box")
            proven.append(math.inf)
            continue
        data = relaxation.conic_data(box, ub)
        if data is None:
            raise Invalid("leaf_bounds", f"proof {number}: no relaxation on a box without positive depths")
        _finite_bounds(data, f"proof {number}")
        z = _dual(proof.get("z"), len(data.b))
        if kind == "farkas":
            if not proves_infeasible(data.A, data.b, data.cones, z, data.lower, data.upper, data.transform):
                raise Invalid("leaf_bounds", f"proof {number}: its Farkas vector does not prove infeasibility")
            proven.append(math.inf)
            continue
        if kind != "dual":
            raise Invalid("format", f"proof {number}: unknown kind {kind!r}")
        bound = safe_lower_bound(data.q, data.A, data.b, data.cones, z, data.lower, data.upper, data.transform)
        claimed = _number(proof.get("bound"), f"proofs/{number}/bound")
        if not bound >= claimed - BOUND_TOLERANCE * abs(claimed):
            raise Invalid("leaf_bounds", f"proof {number}: its dual proves {bound!r}, it claims {claimed!r}")
        proven.append(bound)
    bounds = []
    for number, leaf in enumerate(leaves):
        index = leaf[2]
        if index is None:
            bounds.append(0.0)  # the trivial bound: every cost is a sum of norms
            continue
        box = boxes[index]
        if not (np.all(box.lo <= leaf_lo[number]) and np.all(box.hi >= leaf_hi[number])):
            raise Invalid("leaf_bounds", f"leaf {number} is not inside the box of its proof {index}")
        bounds.append(proven[index])
    return bounds


def uncovered_part(root: Box, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """A part of ``root`` that no box (lo[i], hi[i]) covers, or None when they cover it all.

    Exact (no tolerance). A branch-and-bound tree's leaves are a guillotine partition: some
    axis-aligned plane crosses no leaf. So the boxes are split along every such plane of one
    axis at once, and each slab is checked the same way: n log n per level, whatever the
    leaves. A slab with no leaf, or a gap between the leaves along an axis, is uncovered. Where
    no plane separates the leaves (not a tree's partition), the slab's leaves are subtracted one
    by one, within a budget. Boxes are closed; leaves of zero volume cover nothing a positive
    volume does not (the union of closed boxes covering a box's interior covers the box).
    """
    if not np.all(root.hi > root.lo):
        return _subtracted(root.lo, root.hi, lo, hi)
    stack = [(root.lo, root.hi, np.arange(len(lo)))]
    while stack:
        box_lo, box_hi, index = stack.pop()
        L = np.maximum(lo[index], box_lo)
        H = np.minimum(hi[index], box_hi)
        inside = np.all(L < H, axis=1)
        index, L, H = index[inside], L[inside], H[inside]
        if not len(index):
            return box_lo, box_hi
        if np.any(np.all(L == box_lo, axis=1) & np.all(H == box_hi, axis=1)):
            continue
        for axis in range(len(box_lo)):
            order = np.argsort(L[:, axis], kind="stable")
            starts, ends = L[order, axis], np.maximum.accumulate(H[order, axis])
            if starts[0] > box_lo[axis]:
                return _slab(box_lo, box_hi, axis, box_lo[axis], starts[0])
            if ends[-1] < box_hi[axis]:
                return _slab(box_lo, box_hi, axis, ends[-1], box_hi[axis])
            gaps = np.flatnonzero(ends[:-1] < starts[1:])
            if len(gaps):
                return _slab(box_lo, box_hi, axis, ends[gaps[0]], starts[gaps[0] + 1])
            cuts = np.flatnonzero(ends[:-1] <= starts[1:]) + 1  # planes that cross no leaf
            if len(cuts):
                bounds = np.concatenate([[box_lo[axis]], starts[cuts], [box_hi[axis]]])
                for group, (a, b) in zip(np.split(order, cuts), zip(bounds[:-1], bounds[1:])):
                    slab_lo, slab_hi = box_lo.copy(), box_hi.copy()
                    slab_lo[axis], slab_hi[axis] = a, b
                    stack.append((slab_lo, slab_hi, index[group]))
                break
        else:  # no separating plane: not a tree's partition
            gap = _subtracted(box_lo, box_hi, L, H)
            if gap is not None:
                return gap
    return None


def _slab(box_lo, box_hi, axis: int, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    slab_lo, slab_hi = box_lo.copy(), box_hi.copy()
    slab_lo[axis], slab_hi[axis] = a, b
    return slab_lo, slab_hi


def _subtracted(root_lo: np.ndarray, root_hi: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """uncovered_part by subtracting each closed box from the closed pieces still uncovered
    (what a subtraction leaves are slabs reaching strictly beyond the box, so nothing is lost);
    past MAX_PIECES pieces or MAX_WORK leaf-piece tests the box is reported as not shown covered."""
    pieces = [(root_lo.copy(), root_hi.copy())]
    order = np.lexsort(lo.T[::-1])  # a sweep: neighbours follow each other
    work = 0
    for i in order:
        work += len(pieces)
        if work > MAX_WORK:
            return root_lo, root_hi
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
        if len(pieces) > MAX_PIECES:
            return root_lo, root_hi
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

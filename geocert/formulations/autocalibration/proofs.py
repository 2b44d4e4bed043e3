"""Stratified autocalibration's proofs: their JSON form, and their check with numpy alone.

Affine stage ("stratified_affine"): for each orientation of chirality, either an exact proof that
no plane is positive on all its rows (Gordan, rational arithmetic), or a region: the frame G, the
box on v with each side proved by three chirality rows in rational arithmetic (so the box holds
every plane chirality allows), and the branch-and-bound leaves covering the box, each with a dual
vector whose safe bound the verifier recomputes from the relaxation it rebuilds (affine_relaxation).

Metric stage ("stratified_metric"), for the plane at infinity it states: the root box of omega
from the intrinsics ranges (interval arithmetic, recomputed), rounds of bound tightening (each
side a safe dual bound over the relaxation with the cost capped), and leaves covering the last
round's box, each with its dual vector; optionally its ``sublevel`` (metric_sublevel): proven
intervals of the intrinsics, from rounds and leaves of a search at the cost level they are for
(check_sublevel).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from geocert.formulations.autocalibration import affine_relaxation as arelax
from geocert.formulations.autocalibration import frames
from geocert.formulations.autocalibration import metric_relaxation
from geocert.core.bnb import Box
from geocert.core.certificates import pack
from geocert.core.cones import SMALLEST_NORMAL, proves_infeasible, safe_lower_bound
from geocert.core.strict import (Invalid, charge, dual_vector, informational, is_number, number as _number,
                                 numbers as _numbers, record)
from geocert.core.coverage import SIDE_TOLERANCE, extended, uncovered_part, widened
from geocert.formulations.fractional.proof import LEAF_CLAIM_TOLERANCE  # the record's allowance, as the fractional kinds'

MAX_LEAVES = 200_000
# Tightening rounds of a metric proof (metric.tighten makes at most 12). Each builds a program
# whatever its duals: 57,000 rounds with every dual null (32 MB) took some 6 minutes.
MAX_ROUNDS = 16


def _box(lo: np.ndarray, hi: np.ndarray) -> list:
    return [np.asarray(lo, float).tolist(), np.asarray(hi, float).tolist()]


def encode_leaves(leaves: list) -> tuple[list, list]:
    proofs, index, out = [], {}, []
    for box, leaf in leaves:
        if leaf is not None and id(leaf) not in index:
            index[id(leaf)] = len(proofs)
            proofs.append({"box": _box(leaf.box.lo, leaf.box.hi), "upper_bound": leaf.upper_bound, "kind": leaf.kind,
                           "z": pack(leaf.z), "bound": leaf.bound if math.isfinite(leaf.bound) else None,
                           **({"axis": leaf.axis, "sign": leaf.sign} if leaf.kind == "cut" else {})})
        out.append(_box(box.lo, box.hi) + [index[id(leaf)] if leaf is not None else None])
    return proofs, out


def _frame(norm) -> dict:
    """The frame a proof is posed in: the reference camera, the power of two it was brought to
    unit scale by (frames.unit_reference_scale; none stated: the reference as given, an earlier
    writer's frame), and the power of two the fourth coordinate was scaled by (frames.world_unit_scale;
    none stated: the world as given, an earlier writer's)."""
    return {"reference": int(norm.reference),
            **({} if norm.reference_scale is None else {"reference_scale": norm.reference_scale}),
            **({} if norm.world_scale is None else {"world_scale": norm.world_scale})}


def encode_affine(stage, norm) -> dict:
    """The affine stage's proof, posed in the problem's frame ``norm`` (frames.Normalised)."""
    regions = []
    for region in stage.regions:
        proofs, leaves = encode_leaves(region.leaves)
        regions.append({"delta": region.delta, "frame": region.G.tolist(), "rows": region.rows,
                        "box": _box(region.lo, region.hi), "basis": region.basis, "unit": region.setup.unit,
                        "proofs": proofs, "leaves": leaves})
    return {"type": "stratified_affine", **_frame(norm), "regions": regions,
            "excluded": [{"delta": item["delta"], "rows": item["rows"]} for item in stage.excluded]}


def _rounds(rounds: list) -> list:
    return [{"cap": r.cap, "box_in": _box(r.lo_in, r.hi_in), "box_out": _box(r.lo_out, r.hi_out),
             "duals": [pack(z) for z in r.duals]} for r in rounds]


def encode_metric(stage, norm) -> dict:
    """The metric stage's proof, posed in the problem's frame ``norm`` (frames.Normalised)."""
    proofs, leaves = encode_leaves(stage.leaves)
    return {"type": "stratified_metric", **_frame(norm), "unit": stage.unit, "tightening": _rounds(stage.rounds),
            "search_box": _box(stage.search_lo, stage.search_hi), "proofs": proofs, "leaves": leaves}


def encode_sublevel(sublevel: dict) -> dict:
    proofs, leaves = encode_leaves(sublevel["leaves"])
    return {"cost_increase": sublevel["cost_increase"], "tightening": _rounds(sublevel["rounds"]),
            "search_box": _box(sublevel["search_lo"], sublevel["search_hi"]), "proofs": proofs, "leaves": leaves,
            "intervals": np.asarray(sublevel["intervals"], float).tolist()}


# --- checks -----------------------------------------------------------------------------------

def _int_list(value: Any, where: str, length: int | None = None) -> list[int]:
    if not isinstance(value, list) or not all(isinstance(x, int) and not isinstance(x, bool) for x in value):
        raise Invalid("format", f"{where} must be a list of integers")
    if length is not None and len(value) != length:
        raise Invalid("format", f"{where} must have {length} entries")
    return value


def _read_box(value: Any, where: str, d: int) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(value, list) or len(value) != 2:
        raise Invalid("format", f"{where} must be [lower corner, upper corner]")
    lo, hi = _numbers(value[0], f"{where}/0", (d,)), _numbers(value[1], f"{where}/1", (d,))
    if not np.all(lo <= hi):
        raise Invalid("format", f"{where} is empty")
    return lo, hi


def check_leaves(proof: dict, root_lo: np.ndarray, root_hi: np.ndarray, build, unit: float, d: int,
                 build_capped=None, proven: Box | None = None, size: int = 1, read: list | None = None) -> float:
    """The smallest bound the leaves prove over the root box, in cost units: they must cover it,
    and each leaf's proof is rebuilt and rechecked. ``build(lo, hi, cap)`` gives the leaf's
    program (or None: no point of the domain in that box); ``build_capped`` the same with the
    cost capped, for "cut" proofs (a box's tightening: no point of it costing at most the cap
    lies beyond ``value`` along ``axis``, so the leaves beyond it are closed at the cap).
    ``proven``: the root box as its tightening proves it (the claimed one widened by rounding),
    to whose faces the boxes on the claimed root box's faces reach (coverage.extended). ``size``:
    the work a program costs (strict.charge: its views and rows), paid before each is built. A leaf
    beyond its cut but for the cut's rounding (within coverage.SIDE_TOLERANCE of the root box's
    size: certificates written before the cut counted it) is read as ending at the cut's value,
    and the boxes on its inner face are extended over the sliver (_moved_faces). ``read``, when
    given, receives the leaves as read (lower corners, upper corners) and each one's bound."""
    claimed = Box(root_lo, root_hi)
    proven = claimed if proven is None else proven
    proofs, leaves = proof.get("proofs"), proof.get("leaves")
    if not isinstance(proofs, list) or not isinstance(leaves, list) or not leaves or len(leaves) > MAX_LEAVES:
        raise Invalid("format", f"proofs and leaves must be lists (1 to {MAX_LEAVES} leaves)")
    boxes, caps = [], []
    for i, item in enumerate(proofs):
        record(item, f"proofs/{i}", ("box", "upper_bound", "kind", "z", "bound"),
               ("axis", "sign") if isinstance(item, dict) and item.get("kind") == "cut" else ())
        # Not read: a leaf's bound is recomputed, a box without the domain needs no vector.
        informational(item.get("bound"), f"proofs/{i}/bound")
        informational(item.get("z"), f"proofs/{i}/z", "text")
        boxes.append(extended(*_read_box(item.get("box"), f"proofs/{i}/box", d), claimed, proven))
        caps.append(_number(item.get("upper_bound"), f"proofs/{i}/upper_bound", "format"))
    for i, leaf in enumerate(leaves):
        if not isinstance(leaf, list) or len(leaf) != 3:
            raise Invalid("format", f"leaves/{i} must be [lower corner, upper corner, proof index or null]")
        index = leaf[2]
        if index is not None and (not isinstance(index, int) or isinstance(index, bool)
                                  or not 0 <= index < len(proofs)):
            raise Invalid("format", f"leaves/{i}: no proof {index!r}")
    # All corners read at once (a leaf at a time took 70 microseconds: 200,000 leaves, 14 s).
    leaf_lo = _numbers([leaf[0] for leaf in leaves], "leaves (lower corners)", (len(leaves), d))
    leaf_hi = _numbers([leaf[1] for leaf in leaves], "leaves (upper corners)", (len(leaves), d))
    empty = np.flatnonzero(~np.all(leaf_lo <= leaf_hi, axis=1))
    if len(empty):
        raise Invalid("format", f"leaves/{empty[0]} is empty")
    leaf_lo, leaf_hi = extended(leaf_lo, leaf_hi, claimed, proven)
    charge(size * len(proofs), "the leaves' programs")
    tolerance = SIDE_TOLERANCE * float(np.max(np.abs(np.concatenate([proven.lo, proven.hi, proven.hi - proven.lo]))))

    def cut_value(i: int, box: tuple) -> tuple[int, float, float]:
        return _cut_value(proofs[i], box, caps[i], d, build_capped)

    def pay(count: int) -> None:
        charge(size * count, "the cuts' programs over the slivers")

    boxes, leaf_lo, leaf_hi, cuts = _moved_faces(leaves, proofs, cut_value, pay, boxes, leaf_lo, leaf_hi, tolerance)
    proven_bounds = []
    for i, item in enumerate(proofs):
        lo, hi = boxes[i]
        cap = caps[i]
        kind = item.get("kind")
        if kind == "cut":
            # Its leaves are held to the cap (no point of them costs at most it), and the writer
            # records the cap: a record above it is a bound no proof backs (21,970 over a cap of
            # 0.022 verified), as a dual proof's record above its vector's bound would be.
            check_recorded_bound(item.get("bound"), cap, f"proofs/{i}", proven_by="its leaves are held to (the cap)")
            proven_bounds.append(cap)
            continue
        if kind == "no_domain":
            if build(lo, hi, cap) is not None:
                raise Invalid("leaf_bounds", f"proofs/{i}: the box holds points of the domain")
            proven_bounds.append(cap)  # no point at all: nothing below the cap either
            continue
        program = build(lo, hi, cap)
        if program is None:
            proven_bounds.append(cap)
            continue
        z = dual_vector(item.get("z"), len(program.b), f"proofs/{i}/z", "leaf_bounds")
        if kind == "dual":
            bound = safe_lower_bound(program.q, program.A, program.b, program.cones, z, program.lower,
                                     program.upper) / unit
        elif kind == "farkas":
            if not proves_infeasible(program.A, program.b, program.cones, z, program.lower, program.upper):
                raise Invalid("leaf_bounds", f"proofs/{i}: the Farkas vector does not prove infeasibility")
            bound = math.inf
        else:
            raise Invalid("format", f"proofs/{i}/kind must be dual, farkas or no_domain")
        check_recorded_bound(item.get("bound"), bound, f"proofs/{i}")
        # No point of the box costing at most cap costs less than bound: so none costs less than
        # min(bound, cap).
        proven_bounds.append(min(bound, cap))
    bounds = []
    for i, leaf in enumerate(leaves):
        index = leaf[2]
        if index is None:
            bounds.append(0.0)  # every cost is a sum of squares
            continue
        plo, phi = boxes[index]
        if not (np.all(plo <= leaf_lo[i]) and np.all(phi >= leaf_hi[i])):
            raise Invalid("leaf_bounds", f"leaves/{i} is not inside the box of its proof {index}")
        if index in cuts:  # the leaf must lie beyond its cut (its face on it: covered by others too)
            axis, sign, value = cuts[index]
            beyond = leaf_hi[i][axis] <= value if sign > 0 else leaf_lo[i][axis] >= -value
            if not (value == value and beyond):
                raise Invalid("leaf_bounds", f"leaves/{i} is not beyond the cut of its proof {index}")
        bounds.append(proven_bounds[index])
    # The leaves as the bounds above hold over them (extended to the proven box's faces, moved to
    # their cuts): read as claimed, a cut leaf moved off its side left a sliver no bound holds
    # over, the whole box where a coordinate's range is narrower than the tolerance.
    if uncovered_part(proven, leaf_lo, leaf_hi) is not None:
        raise Invalid("coverage", "the leaves do not cover the box searched")
    if not all(value == value for value in bounds):
        raise Invalid("leaf_bounds", "a leaf's bound is not a number")
    if read is not None:
        read += [leaf_lo, leaf_hi, np.array(bounds, dtype=float)]
    return float(min(bounds))


def check_recorded_bound(recorded: Any, bound: float, where: str,
                         tolerance: float = LEAF_CLAIM_TOLERANCE, proven_by: str = "its vector proves") -> None:
    """A leaf's or program's recorded ``bound`` (informational: the verifier uses its own) is at
    most the bound ``proven_by`` (its dual vector, or a cut's cap), to ``tolerance`` of their size:
    unread, a record of 1e308 over a proven 2.2e-12 verified (review 41), a statement no proof
    backs."""
    if recorded is None or not isinstance(recorded, (int, float)) or isinstance(recorded, bool):
        return  # null, or typed by informational
    if not bound >= recorded - tolerance * (abs(recorded) + abs(bound)):
        raise Invalid("leaf_bounds", f"{where}/bound records {recorded!r}, above the bound {proven_by}, "
                                     f"{bound!r}")


def _cut_value(item: dict, box: tuple, cap: float, d: int, build_capped) -> tuple[int, float, float]:
    """(axis, sign, value) of a cut proof: no point of its box costing at most its cap has
    ``sign * w[axis]`` below value (inf: no point of the domain in the box)."""
    if build_capped is None:
        raise Invalid("format", "this stage takes no cut")
    axis, sign = item.get("axis"), item.get("sign")
    if not (isinstance(axis, int) and not isinstance(axis, bool) and 0 <= axis < d and sign in (1.0, -1.0)):
        raise Invalid("format", f"a cut needs an axis (0-{d - 1}) and a sign (1.0 or -1.0)")
    program = build_capped(box[0], box[1], cap)
    if program is None:
        return axis, sign, math.inf
    q = np.zeros_like(program.q)
    q[axis] = sign
    value = safe_lower_bound(q, program.A, program.b, program.cones,
                             dual_vector(item.get("z"), len(program.b), "a cut's z", "leaf_bounds"), program.lower,
                             program.upper)
    return axis, sign, value


MOVE_ROUNDS = 64  # rounds of moved cut leaves: each cut extended over a sliver may move its own leaves


def _moved_faces(leaves: list, proofs: list, cut_value, pay, boxes: list, leaf_lo: np.ndarray, leaf_hi: np.ndarray,
                 tolerance: float):
    """The proofs' boxes, the leaves and the cuts' (axis, sign, value) as the checks read them.

    A leaf beyond its cut but for at most ``tolerance`` (the cut's rounding, which certificates
    written before the cut counted it did not) is read as ending at the cut's value, and every
    leaf with a side on its face, meeting it, is extended to there over the sliver (a cut splits
    a box, and the leaves of the part it keeps cover its face), its proof's box grown to hold it.
    A cut whose box grows is recomputed over it (``cut_value(i, box)``, paid for by
    ``pay(count)``), which may move its own leaves in a next round. Nothing here is trusted: the
    leaves as read must cover the box, lie in their proofs' boxes and beyond their cuts
    (check_leaves), and every bound is computed over the boxes as read. Time: linear in the leaves
    per round, plus the tests of moved leaves against the leaves on their faces (charged)."""
    n, d = leaf_lo.shape
    leaf_lo, leaf_hi = leaf_lo.copy(), leaf_hi.copy()
    box_lo = np.array([lo for lo, _ in boxes]).reshape(-1, d)
    box_hi = np.array([hi for _, hi in boxes]).reshape(-1, d)
    cuts = {i: cut_value(i, (box_lo[i], box_hi[i])) for i, item in enumerate(proofs)
            if isinstance(item, dict) and item.get("kind") == "cut"}
    index = np.array([-1 if leaf[2] is None else leaf[2] for leaf in leaves], dtype=np.int64)
    rows = np.arange(n)
    for _ in range(MOVE_ROUNDS):
        # Each leaf's cut: (axis, sign, value); sign 0 for a leaf closed otherwise.
        axis, sign, value = np.zeros(len(proofs) + 1, np.int64), np.zeros(len(proofs) + 1), np.zeros(len(proofs) + 1)
        for i, (a, s, v) in cuts.items():
            axis[i], sign[i], value[i] = a, s, v
        a, s, v = axis[index], sign[index], value[index]  # index -1: the last, no cut
        with np.errstate(invalid="ignore"):
            up = (s > 0) & (v < leaf_hi[rows, a]) & (leaf_hi[rows, a] <= v + tolerance)
            down = (s < 0) & (-v > leaf_lo[rows, a]) & (leaf_lo[rows, a] >= -v - tolerance)
        moved = np.flatnonzero(up | down)
        if not len(moved):
            return [(box_lo[i], box_hi[i]) for i in range(len(proofs))], leaf_lo, leaf_hi, cuts
        was_lo, was_hi = leaf_lo.copy(), leaf_hi.copy()
        leaf_hi[up, a[up]] = v[up]
        leaf_lo[down, a[down]] = -v[down]
        _extend_over_slivers(moved, up, a, was_lo, was_hi, leaf_lo, leaf_hi)
        # Each proof's box grown to hold its leaves as now read.
        changed = np.flatnonzero(np.any((leaf_lo != was_lo) | (leaf_hi != was_hi), axis=1) & (index >= 0))
        old_lo, old_hi = box_lo.copy(), box_hi.copy()
        np.minimum.at(box_lo, index[changed], leaf_lo[changed])
        np.maximum.at(box_hi, index[changed], leaf_hi[changed])
        grown = np.any((box_lo != old_lo) | (box_hi != old_hi), axis=1)
        stale = [i for i in cuts if grown[i]]
        pay(len(stale))
        cuts.update({i: cut_value(i, (box_lo[i], box_hi[i])) for i in stale})
    raise Invalid("leaf_bounds", f"cut leaves moved over their cuts' rounding in more than {MOVE_ROUNDS} rounds")


def _extend_over_slivers(moved: np.ndarray, up: np.ndarray, axis: np.ndarray, was_lo: np.ndarray, was_hi: np.ndarray,
                         leaf_lo: np.ndarray, leaf_hi: np.ndarray) -> None:
    """Each leaf with a side on a moved leaf's face (as it was), meeting that leaf, extended to
    the moved leaf's side as now read; the leaves on a face are found by sorting."""
    d = leaf_lo.shape[1]
    for k in range(d):
        for upper, ends, moved_side, face_side in ((True, was_lo, leaf_hi, was_hi), (False, was_hi, leaf_lo, was_lo)):
            mine = moved[(axis[moved] == k) & (up[moved] == upper)]
            if not len(mine):
                continue
            order = np.argsort(ends[:, k], kind="stable")
            sorted_ends = ends[order, k]
            first = np.searchsorted(sorted_ends, face_side[mine, k], "left")
            last = np.searchsorted(sorted_ends, face_side[mine, k], "right")
            charge(len(mine) + int(np.sum(last - first)), "the leaves on the moved faces")  # a unit a test
            others = np.arange(d) != k
            target = leaf_lo if upper else leaf_hi
            for i, start, stop in zip(mine, first, last):
                on_face = order[start:stop]
                meets = np.all((was_lo[on_face][:, others] <= was_hi[i, others])
                               & (was_hi[on_face][:, others] >= was_lo[i, others]), axis=1)
                on_face = on_face[meets & (on_face != i)]
                target[on_face, k] = moved_side[i, k]


def check_regions(problem, regions: Any, excluded: Any, fields: tuple[str, ...], where: str = "") -> list:
    """Each orientation's region of planes (its frame, and a box whose sides its rows prove in
    exact arithmetic) or its exclusion (Gordan's alternative, exactly), as an affine proof states
    them (``fields``: a region's keys): (delta, G, a, b, lo, hi) of each region, a v + b >= 0 its
    chirality rows in the frame."""
    if not isinstance(regions, list) or not isinstance(excluded, list):
        raise Invalid("format", f"{where}regions and {where}excluded must be lists")
    deltas = ([r.get("delta") for r in regions if isinstance(r, dict)]
              + [e.get("delta") for e in excluded if isinstance(e, dict)])
    # numbers, never booleans (true == 1.0 in Python), before sorting (None and a string do not sort)
    if not all(is_number(delta) for delta in deltas) or sorted(deltas) != [-1.0, 1.0]:
        raise Invalid("root_region", "each orientation (delta = +1 and -1) needs a region or an exclusion")
    for i, item in enumerate(excluded):
        record(item, f"{where}excluded/{i}", ("delta", "rows"))
        rows = frames.chirality_rows(problem.norm, float(item["delta"]))
        if not frames.exact_gordan(rows, _int_list(item.get("rows"), f"{where}excluded/rows")):
            raise Invalid("root_region", f"orientation {item['delta']:+g}: the rows do not exclude it")
    out = []
    for i, region in enumerate(regions):
        record(region, f"{where}regions/{i}", fields)
        delta = float(region["delta"])
        G = _numbers(region.get("frame"), f"{where}regions/{i}/frame", (4, 4))
        if not np.linalg.cond(G) < 1e12:
            raise Invalid("root_region", f"{where}regions/{i}: the frame is not invertible")
        rows = frames.chirality_rows(problem.norm, delta)
        a, b = frames.frame_rows(G, rows)
        lo, hi = _read_box(region.get("box"), f"{where}regions/{i}/box", 3)
        basis = region.get("basis")
        if not isinstance(basis, list) or len(basis) != 6:
            raise Invalid("format", f"{where}regions/{i}/basis must give three rows for each of the six sides")
        chosen_rows = [_int_list(chosen, f"{where}regions/{i}/basis/{side}", 3) for side, chosen in enumerate(basis)]
        proven = [frames.exact_side(a, b, side // 2, side % 2 == 1, chosen) for side, chosen in enumerate(chosen_rows)]
        # each axis' reach is the polytope's the rows prove, not the box stated's: a side stated far
        # out must not buy slack for another, nor a stretched axis for the others
        reaches = np.array([max((abs(v) for v in proven[2 * j:2 * j + 2] if v is not None and math.isfinite(v)),
                                default=0.0) for j in range(3)])
        magnitudes = np.abs(rows) @ np.abs(G).T
        for side, (chosen, value) in enumerate(zip(chosen_rows, proven)):
            axis, upper = side // 2, side % 2 == 1
            # the side as another machine's rows prove it may lie its rows' rounding away
            slack = 0.0 if value is None else frames.side_slack(a, magnitudes, chosen, axis, reaches)
            if value is None or (value > hi[axis] + slack if upper else value < lo[axis] - slack):
                raise Invalid("root_region", f"{where}regions/{i}: side {side} of the box is not proved by its rows")
        # Every plane positive on the rows is G^T (v, 1) times a positive number for some v of
        # the polytope only if the polytope is bounded (the sides above) and not "inside out":
        # a plane with a negative last coordinate in this frame would need the proved lower
        # bounds above the upper ones on every axis (e.g. a frame with its last row negated).
        if not all(proven[2 * k] < proven[2 * k + 1] for k in range(3)):
            raise Invalid("root_region", f"{where}regions/{i}: the proved sides leave no plane in the frame's polytope")
        out.append((delta, G, a, b, lo, hi))
    return out


def check_reference(problem, proof: dict) -> None:
    """A proof stating the camera whose frame it is posed in is checked in that frame only (an
    earlier proof states none: the verifier's check_claim tries the frames it may be posed in)."""
    if "reference" in proof and (type(proof["reference"]) is not int or proof["reference"] != problem.norm.reference):
        raise Invalid("scope", f"proof/reference is {proof['reference']!r:.40}: this problem is posed in the frame "
                               f"of camera {problem.norm.reference}")
    # The scale is the data's (frames.unit_reference_scale), recomputed: a document's own number is
    # never multiplied into the frame, only compared with the one the data give.
    stated = proof.get("reference_scale")
    # a number (JavaScript writes 512.0 as 512), never a boolean (True == 1.0)
    if stated != problem.norm.reference_scale or (stated is not None and type(stated) not in (float, int)):
        raise Invalid("scope", f"proof/reference_scale is {stated!r:.40}: this problem is posed with its reference "
                               f"camera scaled by {problem.norm.reference_scale!r} (frames.unit_reference_scale; "
                               "none: as given, a proof written before proofs stated it)")
    # The world's scale likewise (frames.world_unit_scale): prepared with the stated power of two,
    # which must be the one the data give, up to another machine's rounding of their ratio.
    stated = proof.get("world_scale")
    if stated is None and "world_scale" not in proof and problem.norm.world_scale is None:
        return
    if type(stated) not in (float, int) or stated != problem.norm.world_scale \
            or not frames.world_scale_fits(float(stated), problem.norm.world_ratio):
        raise Invalid("scope", f"proof/world_scale is {stated!r:.40}: this problem's cameras lie a median "
                               f"{problem.norm.world_ratio:.6g} from the reference in its frame, which the power of "
                               f"two {frames.world_unit_scale(problem.norm.world_ratio)!r} brings into "
                               f"[2^{frames.WORLD_EXPONENT - 1}, 2^{frames.WORLD_EXPONENT}) "
                               "(frames.world_unit_scale; none: the world as given, a proof written before proofs "
                               "stated it)")
    if not frames.world_frame_bounded(problem.norm):
        raise Invalid("scope", f"proof/world_scale is {stated!r:.40}: in that frame the farthest camera lies "
                               f"{problem.norm.world_scale * problem.norm.world_ratio_highest:.6g} from the reference, "
                               f"beyond 2^{frames.EARLIER_WORLD_HIGHEST} (the other cameras' median is "
                               f"{problem.norm.world_ratio:.6g}): the stratified frame is refused for these data "
                               "(frames.world_frame_bounded)")


def check_earlier_frame(problem, proof: dict) -> None:
    """A stratified proof stating no reference_scale (an earlier writer's: the reference camera as
    given) is read in that frame only where it is well scaled (frames.earlier_frame_readable):
    beyond, the frame's own failure could be certified there (the reference times 2^28 had a K
    4,250 px off certified and verified), and the current writer states the scale."""
    if "reference_scale" not in proof and problem.norm.reference_scale is None \
            and not frames.earlier_frame_readable(problem.norm):
        largest = -int(np.log2(problem.norm.reference_unit_scale))  # the entry lies in [2^(largest-1), 2^largest)
        raise Invalid("scope", f"proof/reference_scale is not stated (a proof posed in the reference camera as given, "
                               f"written before proofs stated it): that frame is read only where the preconditioned "
                               f"reference's largest entry is below 2^{frames.EARLIER_FRAME_EXPONENT}, and camera "
                               f"{problem.norm.reference}'s is at least 2^{largest - 1} (solve again: the current writer "
                               "poses the stratified stages in the unit reference frame and states reference_scale)")
    if "world_scale" not in proof and problem.norm.world_scale is None and not frames.earlier_world_readable(problem.norm):
        raise Invalid("scope", f"proof/world_scale is not stated (a proof posed in the world as given, written before "
                               f"proofs stated it): that frame is read only where the other cameras lie a median "
                               f"between 2^{frames.EARLIER_WORLD_LOWEST} and 2^{frames.EARLIER_WORLD_HIGHEST} from "
                               f"the reference in its frame, every one below 2^{frames.EARLIER_WORLD_HIGHEST}, and these lie a median "
                               f"{problem.norm.world_ratio:.6g}, the farthest {problem.norm.world_ratio_highest:.6g} (solve again: "
                               "the current writer brings the world to unit scale and states world_scale)")


def check_affine(problem, proof: dict, lower_claimed: float, claimed_cost: float, passed: list) -> float:
    """The bound an affine proof establishes over every plane chirality allows."""
    coef, _ = frames.modulus_coefficients(problem.norm.cameras, problem.norm.reference)
    record(proof, "proof", ("type", "regions", "excluded"), ("reference", "reference_scale", "world_scale"))
    check_reference(problem, proof)
    check_earlier_frame(problem, proof)
    regions, excluded = proof.get("regions"), proof.get("excluded")
    if not isinstance(regions, list) or not isinstance(excluded, list):
        raise Invalid("format", "an affine proof has regions and excluded")
    checked = check_regions(problem, regions, excluded, ("delta", "frame", "rows", "box", "basis", "unit", "proofs",
                                                         "leaves"))
    bound = math.inf
    for i, (region, (delta, G, a, b, lo, hi)) in enumerate(zip(regions, checked)):
        used = _int_list(region.get("rows"), f"regions/{i}/rows")
        if not used or not all(0 <= k < len(a) for k in used):
            raise Invalid("format", f"regions/{i}/rows: no such rows")
        unit = checked_unit(region.get("unit"), f"regions/{i}/unit", claimed_cost)
        setup = arelax.AffineSetup(coef, frames.plane_map(G, delta), a[used], b[used], unit)
        bound = min(bound, check_leaves(region, lo, hi, lambda l, h, c: arelax.build(setup, l, h, c), unit, 3,
                                        lambda l, h, c: arelax.build(setup, l, h, c, cap_row=True),
                                        size=len(problem.norm.cameras) + len(used)))
    passed += ["root_region", "coverage", "leaf_bounds"]
    return bound


def check_metric(problem, p: np.ndarray, proof: dict, lower_claimed: float, claimed_cost: float, passed: list,
                 cost: float | None = None) -> float:
    """The bound a metric proof establishes over every omega of the domain, for the plane p;
    with its ``sublevel``, the proven intervals too (``cost``: the claimed K's recomputed cost).
    Its ``plane_sublevel`` is plane_sublevel.check's (the verifier calls it beside this)."""
    record(proof, "proof", ("type", "unit", "tightening", "search_box", "proofs", "leaves"),
           ("reference", "reference_scale", "world_scale", "sublevel", "plane_sublevel"))
    check_reference(problem, proof)
    check_earlier_frame(problem, proof)
    setup = metric_relaxation.setup_for(problem.norm.cameras, problem.norm.reference, p, problem.unit_ranges)
    setup.unit = checked_unit(proof.get("unit"), "unit", claimed_cost)
    lo, hi, proven_lo, proven_hi = _check_rounds(problem, setup, proof, lower_claimed, "tightening", "its cap is "
                                                 "below the lower bound claimed")
    passed += ["root_region", "tightening"]
    bound = check_leaves(proof, lo, hi, lambda l, h, c: metric_relaxation.build(setup, l, h, c), setup.unit, 5,
                         lambda l, h, c: metric_relaxation.build(setup, l, h, c, cap_row=True),
                         Box(proven_lo, proven_hi), len(problem.norm.cameras))
    passed += ["coverage", "leaf_bounds"]
    if "sublevel" in proof:
        check_sublevel(problem, setup, proof["sublevel"], max(claimed_cost, claimed_cost if cost is None else cost))
        passed.append("proven_interval")
    return bound


def _check_rounds(problem, setup, proof: dict, floor: float, check: str, below: str):
    """The tightening rounds of ``proof`` from the ranges' root box, each cap at least ``floor``:
    (the last box claimed, the last box proven: the claimed one widened by rounding); ``check``
    names the check a failure fails, ``below`` what a cap under the floor is."""
    lo, hi = metric_relaxation.omega_box(problem.unit_ranges)
    proven_lo, proven_hi = lo, hi  # each round's box as proven: the claimed one widened by rounding
    rounds = proof.get("tightening")
    if not isinstance(rounds, list) or len(rounds) > MAX_ROUNDS:
        raise Invalid("format", f"tightening must be a list of at most {MAX_ROUNDS} rounds")
    for n, round_ in enumerate(rounds):
        record(round_, f"tightening/{n}", ("cap", "box_in", "box_out", "duals"))
        lo_in, hi_in = _read_box(round_.get("box_in"), f"tightening/{n}/box_in", 5)
        if not (np.array_equal(lo_in, lo) and np.array_equal(hi_in, hi)):
            raise Invalid(check, f"tightening/{n} does not start from the box before it")
        cap = _number(round_.get("cap"), f"tightening/{n}/cap", check)
        if not cap >= floor:
            raise Invalid(check, f"tightening/{n}: {below}")
        lo_out, hi_out = _read_box(round_.get("box_out"), f"tightening/{n}/box_out", 5)
        charge(len(problem.norm.cameras), f"tightening/{n}")
        program = metric_relaxation.build(setup, proven_lo, proven_hi, cap, cap_row=True)
        duals = round_.get("duals")
        if program is None or not isinstance(duals, list) or len(duals) != 10:
            raise Invalid(check, f"tightening/{n}: ten duals (or null) are needed over a box of the domain")
        side_lo, side_hi = proven_lo.copy(), proven_hi.copy()
        for side, text in enumerate(duals):
            k, sign = side // 2, (1.0 if side % 2 == 0 else -1.0)
            if text is None:
                before, target = (lo_in[k], lo_out[k]) if sign > 0 else (hi_in[k], hi_out[k])
                if target != before:
                    raise Invalid(check, f"tightening/{n}: side {side} moved without a proof")
                continue
            q = np.zeros_like(program.q)
            q[k] = sign
            value = sign * safe_lower_bound(q, program.A, program.b, program.cones,
                                            dual_vector(text, len(program.b), f"tightening/{n}/duals/{side}",
                                                        "leaf_bounds"), program.lower, program.upper)
            if sign > 0:  # the points lie in the box in as well
                side_lo[k] = max(side_lo[k], value)
            else:
                side_hi[k] = min(side_hi[k], value)
        sides = widened(lo_out, hi_out, side_lo, side_hi)
        if sides is None:
            raise Invalid(check, f"tightening/{n}: sides {lo_out.tolist()}, {hi_out.tolist()} are beyond the "
                                 f"proven {side_lo.tolist()}, {side_hi.tolist()}")
        lo, hi = lo_out, hi_out
        proven_lo, proven_hi = sides
    search_lo, search_hi = _read_box(proof.get("search_box"), "search_box", 5)
    if not (np.array_equal(search_lo, lo) and np.array_equal(search_hi, hi)):
        raise Invalid("root_region" if check == "tightening" else check, "the box searched is not the last "
                                                                          "tightening's")
    return lo, hi, proven_lo, proven_hi


# A metric proof's sublevel (metric_sublevel): U is the claimed K's cost (the larger of the claim
# and its recomputation) times (1 + SUBLEVEL_SLACK) plus the increase, rounded up.
SUBLEVEL_SLACK = 1e-9
SMALLEST_INCREASE, LARGEST_INCREASE = 2.0 ** -128, 2.0 ** 128


def sublevel_level(cost: float, increase: float) -> float:
    return (cost * (1 + SUBLEVEL_SLACK) + increase) * (1 + 4 * 2.0 ** -52)


def sublevel_hull(problem, setup, sublevel: dict, cost: float, margin: float = 0.0) -> np.ndarray:
    """What a metric proof's ``sublevel`` proves (metric_sublevel): (fx, fy, skew, u, v) in pixels
    (5 x 2) of every K of the ranges costing at most U = sublevel_level(cost, cost_increase) for
    the stated plane. Its rounds (each cap at least U) and the leaves covering their box are
    checked as a metric proof's, and the hull is taken, over the leaves as check_leaves reads them
    (extended to the proven box's faces, moved to their cuts) whose recomputed bound is not above
    U (1 + ``margin``), of each intrinsic's range on the leaf (metric_relaxation.intrinsics_ranges).
    The verifier's hull (margin 0); the solver states its intervals from this same function (at a
    small margin, so that another machine's rounding of a bound near U narrows nothing)."""
    increase = _number(sublevel.get("cost_increase"), "proof/sublevel/cost_increase", "proven_interval")
    if not (increase == 0 or SMALLEST_INCREASE <= increase <= LARGEST_INCREASE):
        raise Invalid("proven_interval", "proof/sublevel/cost_increase must be 0 or within 2^-128 .. 2^128")
    U = sublevel_level(cost, increase)
    lo, hi, proven_lo, proven_hi = _check_rounds(problem, setup, sublevel, U, "proven_interval",
                                                 "its cap is below the level proven")
    read: list = []
    check_leaves(sublevel, lo, hi, lambda l, h, c: metric_relaxation.build(setup, l, h, c), setup.unit, 5,
                 lambda l, h, c: metric_relaxation.build(setup, l, h, c, cap_row=True), Box(proven_lo, proven_hi),
                 len(problem.norm.cameras), read)
    leaf_lo, leaf_hi, bounds = read
    found = [r for r in (metric_relaxation.intrinsics_ranges(problem.unit_ranges, leaf_lo[i], leaf_hi[i])
                         for i in np.flatnonzero(~(bounds > U * (1 + margin)))) if r is not None]
    if not found:
        raise Invalid("proven_interval", "every leaf is excluded: not even the returned K costs that little")
    stacked = np.array(found)
    return metric_relaxation.pixel_intervals(
        problem.K0, np.stack([stacked[:, :, 0].min(axis=0), stacked[:, :, 1].max(axis=0)], axis=1))


def check_sublevel(problem, setup, sublevel: Any, cost: float) -> np.ndarray:
    """A metric stage's proven intervals (metric_sublevel): every K of the ranges whose cost for
    the stated plane is at most the optimum plus ``cost_increase`` has (fx, fy, skew, u, v) in
    pixels within them. The stated intervals must hold what its leaves prove (sublevel_hull); a
    wider one is a weaker true statement, a narrower one is refused. Returns the hull proven."""
    record(sublevel, "proof/sublevel", ("cost_increase", "tightening", "search_box", "proofs", "leaves", "intervals"))
    stated = _numbers(sublevel.get("intervals"), "proof/sublevel/intervals", (5, 2))
    proven = sublevel_hull(problem, setup, sublevel, cost)
    if not np.all((stated[:, 0] <= proven[:, 0]) & (proven[:, 1] <= stated[:, 1])):
        raise Invalid("proven_interval", "proof/sublevel/intervals are narrower than what its leaves prove "
                                         f"({proven.tolist()})")
    return proven


# The programs' objective is unit times the cost, unit = 1 / the first incumbent's cost (about 1
# at the incumbent: the conic solver's accuracy), or 1 when that cost is 0. A unit the document
# chooses must be a normal number that puts the claimed cost between UNIT_RANGE's ends (the
# solver's within 1e-9 of 1 on the stored certificates; a search whose incumbent improved a
# millionfold would still be within it): bounds are divided by it, and a subnormal unit turned
# a program bound of one rounding error into any bound at all.
UNIT_RANGE = (1e-9, 1e3)
# A unit of order 1 is accepted whatever the cost claimed: dividing a safe bound by it enlarges the
# bound's rounding by at most PLAIN_UNITS[1]. On exact data the first incumbent costs about 1 and
# the claim a rounding error (1e-31): the solver's unit is then near 1 and the cost far below it.
PLAIN_UNITS = (1e-3, 1e3)


def checked_unit(value: Any, where: str, claimed_cost: float) -> float:
    unit = _number(value, where, "format")
    ok = PLAIN_UNITS[0] <= unit <= PLAIN_UNITS[1]
    if claimed_cost > 0 and not ok:
        scaled = unit * claimed_cost
        ok = unit >= SMALLEST_NORMAL and UNIT_RANGE[0] <= scaled <= UNIT_RANGE[1]
    if not ok:
        raise Invalid("program", f"{where} {unit!r} must be within {PLAIN_UNITS} or put the claimed cost "
                                 f"{claimed_cost!r} within {UNIT_RANGE} in the programs' units")
    return unit
